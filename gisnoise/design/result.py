"""The outcome of a design run (:class:`DesignResult`) and its document, schema ``gisnoise/design-result/1``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from gisnoise import __version__
from gisnoise.design.designmodel import DesignModel
from gisnoise.design.objectives import Evaluation
from gisnoise.design.optimizer import Optimum
from gisnoise.design.plan import Plan
from gisnoise.design.sweep import StudyPoint
from gisnoise.design.verification import VerifyResult

__all__ = ["RESULT_SCHEMA", "DesignResult"]

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

    def to_dict(self) -> dict[str, Any]:
        plan = self.plan
        return {
            "schema": RESULT_SCHEMA, "software": f"gisnoise {__version__}", "plan": plan.doc["name"],
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
