"""The study of the paper's Fig. 18: the optimum objective swept over displacement limits and altitude ranges."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from gisnoise.design.designmodel import DesignModel
from gisnoise.design.optimizer import optimize
from gisnoise.design.plan import CancelFn, Design, Plan, Progress

__all__ = ["StudyPoint", "study"]


@dataclass(frozen=True)
class StudyPoint:
    """One optimization of the study: objective value for a displacement limit and an altitude range."""

    objective: str
    max_shift_m: float
    altitude_range_m: tuple[float, float]
    value: float
    max_abs_corr: float
    log_det_fisher: float
    altitudes_m: tuple[float, ...]
    shifts_m: tuple[tuple[float, float], ...]
    correlation: tuple[tuple[float, ...], ...]
    at_shift_limit: bool
    altitudes_at_bounds: bool

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["altitude_range_m"] = list(self.altitude_range_m)
        d["altitudes_m"] = list(self.altitudes_m)
        d["shifts_m"] = [list(s) for s in self.shifts_m]
        d["correlation"] = [list(r) for r in self.correlation]
        return d


def study(plan: Plan, *, objectives: Sequence[str] | None = None, displacements_m: Sequence[float] | None = None,
          altitude_ranges_m: Sequence[Sequence[float]] | None = None, maxiter: int | None = None,
          popsize: int | None = None, progress: Progress | None = None, cancel: CancelFn | None = None,
          model: DesignModel | None = None) -> list[StudyPoint]:
    """Optimum objective against the allowed displacement for several altitude ranges (paper Fig. 18).

    Every microphone gets the same displacement limit in both directions and every
    repetition the same altitude range.  Each run starts from the best design found
    for a range inside its own (a smaller displacement or a narrower altitude range),
    so the curves cannot rise where the feasible sets are nested.

    Defaults come from the plan's ``study`` section.
    """
    st = plan.doc["study"] or {}
    objectives = list(objectives if objectives is not None else st.get("objectives", ["paper"]))
    disps = sorted(float(x) for x in (displacements_m if displacements_m is not None
                                      else st.get("displacements_m", [0.0, 50.0, 200.0])))
    ranges = [tuple(float(v) for v in r) for r in (altitude_ranges_m if altitude_ranges_m is not None
                                                   else st.get("altitude_ranges_m", [[60.0, 60.0]]))]
    maxiter = int(maxiter if maxiter is not None else st.get("maxiter", 60))
    popsize = int(popsize if popsize is not None else st.get("popsize", plan.doc["optimizer"]["popsize"]))
    if model is None:
        model = DesignModel.build(plan)
    runs = [(o, r, s) for o in objectives for r in ranges for s in disps]
    out: list[StudyPoint] = []
    done: list[tuple[str, float, tuple[float, float], Design, float]] = []
    for i, (obj, rng, shift) in enumerate(runs):
        sub_plan = plan.with_limits(max_shift_m=shift, altitude_range_m=rng)
        sub = dataclasses.replace(model, plan=sub_plan)
        # warm start: the best earlier design whose limits lie inside these
        inner = [(val, d) for o, s, r, d, val in done
                 if o == obj and s <= shift and r[0] >= rng[0] and r[1] <= rng[1]]
        x0 = min(inner, key=lambda t: t[0])[1] if inner else None

        def sub_progress(f: float, i: int = i) -> None:
            if progress is not None:
                progress((i + f) / len(runs))

        res = optimize(sub, obj, x0=x0, maxiter=maxiter, popsize=popsize, progress=sub_progress, cancel=cancel)
        done.append((obj, shift, (rng[0], rng[1]), res.design, res.value))
        ev = res.evaluation
        sh = tuple((float(ev.design.mic_e[j] - plan.base.mic_e[j]), float(ev.design.mic_n[j] - plan.base.mic_n[j]))
                   for j in range(plan.n_mics))
        out.append(StudyPoint(objective=obj, max_shift_m=shift, altitude_range_m=(rng[0], rng[1]), value=res.value,
                              max_abs_corr=ev.max_abs_corr, log_det_fisher=ev.log_det_fisher,
                              altitudes_m=tuple(float(a) for a in ev.design.altitudes), shifts_m=sh,
                              correlation=tuple(tuple(float(c) for c in row) for row in ev.correlation),
                              at_shift_limit=any(res.at_shift_limit.values()),
                              altitudes_at_bounds=all(a in ("min", "max", "fixed") for a in res.at_altitude_bound)))
    return out
