"""The optimizer: microphone positions and altitudes that minimize one objective within the plan's limits.

:func:`scipy.optimize.differential_evolution` (seeded, ``workers=1``, reproducible).
Displacement limits and altitude ranges are the variables' bounds (the evolution
never leaves them); exclusion polygons are nonlinear *constraints*, the signed
distance of each microphone to the union of the polygons (positive outside), which
scipy handles with Lampinen's feasibility rules (a feasible design always beats an
infeasible one; infeasible ones compare by violation).  No penalty is added to the
objective.  The base design is put into the initial population, so the optimum is
never worse than the base.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.design.designmodel import DesignModel
from gisnoise.design.objectives import Evaluation, _objective_batch, evaluate
from gisnoise.design.plan import CancelFn, Design, Plan, Progress
from gisnoise.errors import Cancelled

__all__ = ["Optimum", "optimize"]


@dataclass(frozen=True, eq=False)
class Optimum:
    """Result of :func:`optimize`.

    Attributes
    ----------
    objective : str
    design : Design
    evaluation, base : Evaluation
        The optimum and the base design, each with both objectives.
    value, base_value : float
        The minimized value at the optimum and at the base (``max |corr|`` or ``-log det``).
    at_shift_limit : dict
        Microphone id -> True when it ended within 1 % of a displacement limit.
    at_altitude_bound : list of str
        Per repetition ``"min"``, ``"max"`` or ``""`` (within 1 % of the range from a bound).
    nit, nfev : int
        Generations and objective evaluations.
    success : bool
    message : str
    settings : dict
        Optimizer settings used (seed, popsize, maxiter, tol, constraint handling).
    """

    objective: str
    design: Design
    evaluation: Evaluation
    base: Evaluation
    value: float
    base_value: float
    at_shift_limit: dict[str, bool]
    at_altitude_bound: list[str]
    nit: int
    nfev: int
    success: bool
    message: str
    settings: dict[str, Any]

    def to_dict(self, plan: Plan) -> dict[str, Any]:
        return {"objective": self.objective, "value": self.value, "base_value": self.base_value,
                "design": self.evaluation.to_dict(plan), "at_shift_limit": dict(self.at_shift_limit),
                "at_altitude_bound": list(self.at_altitude_bound), "nit": self.nit, "nfev": self.nfev,
                "success": self.success, "message": self.message, "settings": dict(self.settings)}


def _limits(plan: Plan, design: Design, tol: float = 0.01) -> tuple[dict[str, bool], list[str]]:
    sh = np.column_stack([design.mic_e - plan.base.mic_e, design.mic_n - plan.base.mic_n])
    at_shift = {mid: bool(np.any((plan.max_shift[i] > 0) & (np.abs(sh[i]) >= (1 - tol) * plan.max_shift[i])))
                for i, mid in enumerate(plan.mic_ids)}
    at_alt = []
    for k, h in enumerate(design.altitudes):
        lo, hi = plan.altitude_range[k]
        span = hi - lo
        if span <= 0:
            at_alt.append("fixed")
        elif h <= lo + tol * span:
            at_alt.append("min")
        elif h >= hi - tol * span:
            at_alt.append("max")
        else:
            at_alt.append("")
    return at_shift, at_alt


def optimize(model: DesignModel, objective: str = "paper", *, x0: Design | None = None,
             maxiter: int | None = None, popsize: int | None = None, seed: int | None = None,
             tol: float | None = None, progress: Progress | None = None, cancel: CancelFn | None = None) -> Optimum:
    """Optimize the microphone positions and altitudes of ``model.plan`` for one objective.

    Parameters
    ----------
    model : DesignModel
        The plan's pattern flown once (:meth:`DesignModel.build`).
    objective : {"paper", "d-optimal"}
    x0 : Design, optional
        A design put into the initial population (default the plan's base design,
        clipped into the bounds); the optimum is never worse than it if it is feasible.
    maxiter, popsize, seed, tol : optional
        Override the plan's ``optimizer`` settings; the evolution stops when the
        objective values of its population spread (standard deviation) less than ``tol``
        (absolute: correlation units or log det units) or after ``maxiter`` generations.
    progress : callable, optional
        Called with the fraction of ``maxiter`` generations done.
    cancel : callable, optional
        Polled every generation; returning True raises :class:`~gisnoise.errors.Cancelled`.

    Returns
    -------
    Optimum
    """
    from scipy.optimize import NonlinearConstraint, differential_evolution

    plan = model.plan
    f_batch = _objective_batch(model, objective)
    opt = plan.doc["optimizer"]
    maxiter = int(opt["maxiter"] if maxiter is None else maxiter)
    popsize = int(opt["popsize"] if popsize is None else popsize)
    seed = int(opt["seed"] if seed is None else seed)
    tol = float(opt["tol"] if tol is None else tol)
    lo, hi = plan.bounds()
    free = hi > lo
    start = (plan.base if x0 is None else x0).vector(plan.base)
    start = np.clip(start, lo, hi)
    fixed_v = start.copy()

    def design_of(x: np.ndarray) -> Design:
        v = fixed_v.copy()
        v[free] = x
        return Design.from_vector(v, plan.base)

    def designs_of(xs: np.ndarray) -> list[Design]:
        xs = np.asarray(xs, dtype=float)
        return [design_of(xs)] if xs.ndim == 1 else [design_of(xs[:, i]) for i in range(xs.shape[1])]

    n_eval = [0]

    def energy(xs: np.ndarray) -> Any:
        # vectorized: xs has shape (n_free, S); the polish step sends one vector (n_free,)
        ds = designs_of(xs)
        n_eval[0] += len(ds)
        v = f_batch(ds)
        return float(v[0]) if np.ndim(xs) == 1 else v

    base_eval = evaluate(model)
    base_value = base_eval.objective(objective)
    settings = {"method": "scipy.optimize.differential_evolution", "strategy": "best1bin", "seed": seed,
                "popsize": popsize, "maxiter": maxiter, "tol": tol, "polish": bool(opt["polish"]), "workers": 1,
                "limits": "bounds of the variables (displacement box, altitude range)",
                "exclusions": ("nonlinear constraints: signed distance of each microphone to the exclusion polygons "
                               ">= 0 (Lampinen's feasibility rules, no penalty)") if plan.exclusions else "none",
                "free_variables": [n for n, f in zip(plan.variable_names(), free, strict=True) if f]}
    if not free.any():
        ev = evaluate(model, design_of(np.zeros(0)))
        at_shift, at_alt = _limits(plan, ev.design)
        return Optimum(objective=objective, design=ev.design, evaluation=ev, base=base_eval,
                       value=ev.objective(objective), base_value=base_value, at_shift_limit=at_shift,
                       at_altitude_bound=at_alt, nit=0, nfev=1, success=True,
                       message="no free variable: every displacement limit is 0 and every altitude range a point",
                       settings=settings)

    constraints: Any = ()
    if plan.exclusions:
        from gisnoise.geo import shapes as shapely

        union = shapely.union_all(list(plan.exclusions))
        shapely.prepare(union)
        boundary = union.boundary
        shapely.prepare(boundary)
        # only microphones whose box reaches an exclusion constrain anything
        near = []
        for i in range(plan.n_mics):
            box = shapely.box(plan.base.mic_e[i] - plan.max_shift[i, 0], plan.base.mic_n[i] - plan.max_shift[i, 1],
                              plan.base.mic_e[i] + plan.max_shift[i, 0], plan.base.mic_n[i] + plan.max_shift[i, 1])
            if box.intersects(union):
                near.append(i)
        if near:
            near_a = np.array(near)

            def signed_distance(x: np.ndarray) -> np.ndarray:
                ds = designs_of(x)
                e = np.array([d.mic_e[near_a] for d in ds]).T  # (n_near, S)
                n = np.array([d.mic_n[near_a] for d in ds]).T
                dist = shapely.distance(boundary, shapely.points(e, n))
                val = np.where(shapely.contains_xy(union, e, n), -dist, dist)
                return val[:, 0] if np.ndim(x) == 1 else val

            constraints = NonlinearConstraint(signed_distance, 0.0, np.inf)

    gen = [0]

    def callback(xk: np.ndarray, convergence: float = 0.0) -> bool:
        gen[0] += 1
        if progress is not None:
            progress(min(1.0, gen[0] / maxiter))
        if cancel is not None and cancel():
            raise Cancelled("design optimization cancelled", field="cancel")
        return False

    kw: dict[str, Any] = {}
    if "rng" in inspect.signature(differential_evolution).parameters:
        kw["rng"] = seed
    else:  # scipy < 1.15
        kw["seed"] = seed
    with np.errstate(all="ignore"):
        res = differential_evolution(energy, list(zip(lo[free], hi[free], strict=True)),
                                     maxiter=maxiter, popsize=popsize, tol=0.0, atol=tol, polish=bool(opt["polish"]),
                                     callback=callback, x0=start[free], constraints=constraints, workers=1,
                                     updating="deferred", vectorized=True, init="latinhypercube", **kw)
    if progress is not None:
        progress(1.0)
    design = design_of(np.asarray(res.x, dtype=float))
    ev = evaluate(model, design)
    at_shift, at_alt = _limits(plan, design)
    return Optimum(objective=objective, design=design, evaluation=ev, base=base_eval, value=ev.objective(objective),
                   base_value=base_value, at_shift_limit=at_shift, at_altitude_bound=at_alt, nit=int(res.nit),
                   nfev=int(n_eval[0]), success=bool(res.success), message=str(res.message), settings=settings)
