"""The whole design run: the base design, the optimum of each objective, the study and the verification."""

from __future__ import annotations

from collections.abc import Sequence

from gisnoise.design.designmodel import DesignModel
from gisnoise.design.objectives import evaluate
from gisnoise.design.optimizer import optimize
from gisnoise.design.plan import OBJECTIVES, CancelFn, Plan, Progress
from gisnoise.design.result import DesignResult
from gisnoise.design.sweep import study
from gisnoise.design.verification import verify
from gisnoise.errors import DesignError, InputError

__all__ = ["run_design"]


def run_design(plan: Plan, *, objectives: Sequence[str] | None = None, with_study: bool = True,
               verify_seeds: int | None = None, progress: Progress | None = None,
               cancel: CancelFn | None = None) -> DesignResult:
    """Evaluate the base design, optimize it for each objective, run the study and the verification.

    Parameters
    ----------
    plan : Plan
    objectives : sequence of str, optional
        Default the plan's ``objectives``.
    with_study : bool
        Run the plan's ``study`` (Fig. 18) when it has one.
    verify_seeds : int, optional
        Seeds of the closing-the-loop verification (default the plan's ``verify.seeds``;
        0 skips it).  Needs the ``d-optimal`` optimum.
    progress : callable, optional
        Called with the fraction done.
    """
    objectives = list(objectives if objectives is not None else plan.doc["objectives"])
    for o in objectives:
        if o not in OBJECTIVES:
            raise InputError(f"objective must be one of {', '.join(OBJECTIVES)}, got {o!r}", field="objective")
    n_verify = int(plan.doc["verify"]["seeds"] if verify_seeds is None else verify_seeds)
    st = plan.doc["study"] if with_study else None
    # work units: generations of each optimization, one per verification campaign
    w_opt = [float(plan.doc["optimizer"]["maxiter"])] * len(objectives)
    n_study = (len(st["objectives"]) * len(st["displacements_m"]) * len(st["altitude_ranges_m"])) if st else 0
    w_study = float(n_study * st["maxiter"]) if st else 0.0
    w_verify = (1.0 + len(objectives)) * n_verify * 10.0
    total = sum(w_opt) + w_study + w_verify
    done = [0.0]

    def stage(weight: float) -> Progress | None:
        if progress is None:
            return None
        start = done[0]
        done[0] += weight
        return lambda f: progress(min(1.0, (start + weight * f) / total))

    model = DesignModel.build(plan)
    base = evaluate(model)
    if base.n_usable < plan.card.model.n_params:
        raise DesignError(f"plan: field 'snr': the base design has {base.n_usable} samples within the "
                          f"signal-to-noise distance {plan.max_distance_m:.0f} m; the pattern does not come close "
                          f"enough to the microphones", field="snr")
    optima = {}
    for o, w in zip(objectives, w_opt, strict=True):
        optima[o] = optimize(model, o, progress=stage(w), cancel=cancel)
    pts = study(plan, model=model, progress=stage(w_study), cancel=cancel) if st else []
    ver = None
    if n_verify > 0:
        if "d-optimal" not in optima:
            raise InputError("verification compares the d-optimal design with the base: add 'd-optimal' to the "
                             "objectives", field="verify")
        first = int(plan.doc["verify"]["first_seed"])
        designs = {"base": plan.base, **{k: o.design for k, o in optima.items()}}
        ver = verify(model, designs, list(range(first, first + n_verify)), progress=stage(w_verify), cancel=cancel)
    if progress is not None:
        progress(1.0)
    return DesignResult(plan=plan, model=model, base=base, optima=optima, study=pts, verify=ver)
