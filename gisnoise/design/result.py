"""The outcome of a design run (:class:`DesignResult`) and its document, schema ``gisnoise/design-result/1``."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise import __version__
from gisnoise.design.designmodel import DesignModel
from gisnoise.design.objectives import Evaluation, _in_exclusion
from gisnoise.design.optimizer import Optimum
from gisnoise.design.plan import Plan
from gisnoise.design.sweep import StudyPoint
from gisnoise.design.verification import VerifyResult

__all__ = ["RESULT_SCHEMA", "DesignResult", "deaf_microphones", "design_warnings"]

RESULT_SCHEMA = "gisnoise/design-result/1"


@dataclass(frozen=True, eq=False)
class DesignResult:
    """Outcome of :func:`gisnoise.design.run.run_design`: base evaluation, optima, study and verification."""

    plan: Plan
    model: DesignModel
    base: Evaluation
    optima: dict[str, Optimum]
    study: list[StudyPoint]
    verify: VerifyResult | None

    @property
    def warnings(self) -> list[str]:
        """What a reader of the designs must know (:func:`design_warnings`)."""
        return design_warnings(self.plan, self.base, self.optima)

    def to_dict(self) -> dict[str, Any]:
        plan = self.plan
        return {
            "schema": RESULT_SCHEMA, "software": f"gisnoise {__version__}", "plan": plan.doc["name"],
            "warnings": self.warnings,
            "card": {"id": plan.card.id, "ansatz": plan.card.ansatz, "parameters": dict(plan.card.parameters),
                     "reference_power_w": plan.card.reference_power_w},
            "origin": dict(plan.doc["origin"]),
            "snr": {"background_db": plan.background_db, "margin_db": plan.margin_db,
                    "max_distance_m": plan.max_distance_m},
            "pattern": dict(plan.doc["pattern"]), "duration_s": self.model.duration_s,
            "evaluation": dict(plan.doc["evaluation"]),
            "variables": {"names": plan.variable_names(), "lower": plan.bounds()[0].tolist(),
                          "upper": plan.bounds()[1].tolist()},
            "base": self.base.to_dict(plan),
            "optima": {k: o.to_dict(plan) for k, o in self.optima.items()},
            "study": [p.to_dict() for p in self.study],
            "verify": None if self.verify is None else self.verify.to_dict(),
        }


def deaf_microphones(plan: Plan, evaluation: Evaluation) -> list[str]:
    """The microphones of a design with no sample within the signal-to-noise distance (they hear nothing)."""
    return [mid for mid in plan.mic_ids if evaluation.n_usable_per_mic.get(mid, 0) == 0]


def design_warnings(plan: Plan, base: Evaluation, optima: Mapping[str, Optimum]) -> list[str]:
    """One sentence per fact that changes how the designs read; empty when there is none.

    * A repetition's base altitude outside its own range: the base is evaluated as given (``feasible`` false)
      and the optimizer starts from it clipped into the range, so the optimum is compared with a design it
      could not take.
    * A base microphone inside an exclusion polygon.
    * A microphone of the base or of an optimum with no sample within the signal-to-noise distance: it hears
      nothing of the pattern, and the design's objectives rest on the other microphones alone.
    """
    out = []
    for k, (h, (lo, hi)) in enumerate(zip(plan.base.altitudes, plan.altitude_range, strict=True)):
        if not lo <= h <= hi:
            side, lim = ("below", "min_m") if h < lo else ("above", "max_m")
            bound = lo if h < lo else hi
            out.append(f"altitudes[{k}].base_m ({h:g} m) is {side} altitudes[{k}].{lim} ({bound:g} m): the base design "
                       f"flies outside the range the optima may use; it is evaluated as given (feasible: false) and "
                       f"the optimizer starts from it moved to {bound:g} m")
    inside = _in_exclusion(plan, plan.base)
    for k in np.flatnonzero(inside).tolist():
        out.append(f"microphone {plan.mic_ids[k]!r} of the base design stands inside an exclusion polygon "
                   "(feasible: false)")
    designs = [("the base design", base)] + [(f"the {k} optimum", o.evaluation) for k, o in optima.items()]
    for label, ev in designs:
        for mid in deaf_microphones(plan, ev):
            i = plan.mic_ids.index(mid)
            e, n = float(ev.design.mic_e[i]), float(ev.design.mic_n[i])
            out.append(f"{label} has microphone {mid!r} at e {e:.0f} m, n {n:.0f} m, farther than the signal-to-noise "
                       f"distance ({plan.max_distance_m:.0f} m) from the whole pattern: it records no usable sample, "
                       f"and the design's objectives rest on the other microphones; check microphones[{i}] (its "
                       "position and max_shift_m)")
    return out
