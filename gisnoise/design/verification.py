"""Closing the loop: campaigns simulated with each design and refitted, the scatter of the estimates compared."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.design.designmodel import DesignModel
from gisnoise.design.objectives import evaluate
from gisnoise.design.plan import CancelFn, Design, Progress, _scenario_doc
from gisnoise.errors import Cancelled, FitError, InputError

__all__ = ["VerifyResult", "campaign_scenario", "verify"]


@dataclass(frozen=True, eq=False)
class VerifyResult:
    """Closing the loop: campaigns simulated with each design and refitted (see :func:`verify`).

    Attributes
    ----------
    param_names : tuple of str
    truth : ndarray
        The card's parameters (the simulation's truth).
    estimates : dict
        Design name -> array (n_ok, n_params) of fitted parameters.
    empirical_std : dict
        Design name -> standard deviation of the estimates over the seeds.
    rms_error : dict
        Design name -> root mean square of ``estimate - truth`` over the seeds.
    expected_std : dict
        Design name -> Cramer-Rao standard deviation expected by the design model.
    mean_cr_std : dict
        Design name -> mean Cramer-Rao standard deviation reported by the fits.
    n_samples : dict
        Design name -> mean number of fitted samples.
    failures : dict
        Design name -> list of ``"seed: reason"`` of fits that failed.
    seeds : list of int
    duration_s : dict
        Design name -> flight time of the simulated campaign, s.
    background : str or None
        Name of the background parameter (its estimate is far from Gaussian where the UAV
        is loud everywhere; summaries are also given without it).
    """

    param_names: tuple[str, ...]
    truth: np.ndarray
    estimates: dict[str, np.ndarray]
    empirical_std: dict[str, np.ndarray]
    rms_error: dict[str, np.ndarray]
    expected_std: dict[str, np.ndarray]
    mean_cr_std: dict[str, np.ndarray]
    n_samples: dict[str, float]
    failures: dict[str, list[str]]
    seeds: list[int]
    duration_s: dict[str, float]
    background: str | None = None

    def ratio(self, design: str, reference: str = "base", *, what: str = "empirical_std") -> np.ndarray:
        """Per-parameter ratio of ``what`` (``empirical_std``, ``rms_error``, ``expected_std``) design / reference."""
        a = getattr(self, what)
        return np.asarray(a[design]) / np.asarray(a[reference])

    def geometric_mean_ratio(self, design: str, reference: str = "base", *, what: str = "empirical_std",
                             exclude: Sequence[str] = ()) -> float:
        """Geometric mean over the parameters (but ``exclude``) of :meth:`ratio`: the factor by which a
        typical deviation shrinks."""
        keep = np.array([k not in exclude for k in self.param_names])
        return float(np.exp(np.mean(np.log(self.ratio(design, reference, what=what)[keep]))))

    def to_dict(self) -> dict[str, Any]:
        designs = list(self.estimates)
        out: dict[str, Any] = {"param_names": list(self.param_names), "truth": self.truth.tolist(),
                               "seeds": list(self.seeds), "designs": {}}
        for d in designs:
            out["designs"][d] = {
                "n_fits": int(len(self.estimates[d])), "failures": list(self.failures[d]),
                "empirical_std": self.empirical_std[d].tolist(), "rms_error": self.rms_error[d].tolist(),
                "expected_std": self.expected_std[d].tolist(), "mean_cr_std": self.mean_cr_std[d].tolist(),
                "n_samples": self.n_samples[d], "duration_s": self.duration_s[d]}
            if d != "base" and "base" in self.estimates:
                out["designs"][d]["empirical_std_ratio_to_base"] = self.ratio(d).tolist()
                out["designs"][d]["geometric_mean_empirical_std_ratio"] = self.geometric_mean_ratio(d)
                out["designs"][d]["geometric_mean_rms_error_ratio"] = self.geometric_mean_ratio(d, what="rms_error")
                out["designs"][d]["geometric_mean_expected_std_ratio"] = self.geometric_mean_ratio(
                    d, what="expected_std")
                if self.background is not None:
                    out["designs"][d]["geometric_mean_empirical_std_ratio_without_background"] = (
                        self.geometric_mean_ratio(d, exclude=(self.background,)))
        return out


def campaign_scenario(model: DesignModel, design: Design, seed: int) -> dict[str, Any]:
    """Simulator scenario of a campaign flown with ``design`` (the plan's noise and background, no effects)."""
    plan = model.plan
    return _scenario_doc(plan.doc, plan.card, design, plan.doc["microphones"], seed=seed, start=model.start_en)


def verify(model: DesignModel, designs: Mapping[str, Design], seeds: Sequence[int], *,
           progress: Progress | None = None, cancel: CancelFn | None = None) -> VerifyResult:
    """Simulate a campaign with each design and seed, refit it, and compare the scatter of the estimates.

    Every campaign flies the same pattern (the same flight time; the climbs between
    repetitions happen inside the laps) with the same microphone noise and background
    (:func:`gisnoise.simulate.simulate_samples`, the card as truth, no injected effects).
    The horizontal samples within the signal-to-noise distance (selected by the logged
    geometry, not by the measured level, so the selection does not bias the fit) are
    fitted with :func:`gisnoise.identify.fit.fit` (the card's ansatz, one noise variance per
    microphone).  Seeds whose fit fails are listed, not hidden.
    """
    from gisnoise.identify import usable_rows
    from gisnoise.identify.fit import fit
    from gisnoise.simulate import run, simulate_samples

    plan = model.plan
    card = plan.card
    names = card.model.params
    truth = card.p
    est: dict[str, list[np.ndarray]] = {k: [] for k in designs}
    crs: dict[str, list[np.ndarray]] = {k: [] for k in designs}
    nsamp: dict[str, list[int]] = {k: [] for k in designs}
    fails: dict[str, list[str]] = {k: [] for k in designs}
    dur: dict[str, float] = {}
    total = len(designs) * len(seeds)
    done = 0
    for name, design in designs.items():
        for seed in seeds:
            if cancel is not None and cancel():
                raise Cancelled("design verification cancelled", field="cancel")
            sim = run(campaign_scenario(model, design, int(seed)))
            dur[name] = float(sim.flights[0].true["t"][-1])
            s = simulate_samples(sim)
            rows = usable_rows(s, "horizontal")
            rows = rows.select(rows.d <= plan.max_distance_m)
            try:
                res = fit(rows, card.ansatz, reference_power_w=card.reference_power_w, p0=card)
            except (FitError, InputError) as exc:
                fails[name].append(f"{seed}: {exc}")
            else:
                est[name].append(res.p)
                crs[name].append(res.std_array)
                nsamp[name].append(len(rows))
            done += 1
            if progress is not None:
                progress(done / total)
    expected = {k: np.array([evaluate(model, d).expected_std[p] for p in names]) for k, d in designs.items()}
    e_arr = {k: np.array(v).reshape(-1, len(names)) for k, v in est.items()}
    emp = {k: (a.std(axis=0, ddof=1) if len(a) > 1 else np.full(len(names), np.nan)) for k, a in e_arr.items()}
    rms = {k: (np.sqrt(np.mean((a - truth) ** 2, axis=0)) if len(a) else np.full(len(names), np.nan))
           for k, a in e_arr.items()}
    mcr = {k: (np.mean(np.array(v), axis=0) if v else np.full(len(names), np.nan)) for k, v in crs.items()}
    return VerifyResult(param_names=tuple(names), truth=truth, estimates=e_arr, empirical_std=emp, rms_error=rms,
                        expected_std=expected, mean_cr_std=mcr,
                        n_samples={k: float(np.mean(v)) if v else 0.0 for k, v in nsamp.items()}, failures=fails,
                        seeds=[int(s) for s in seeds], duration_s=dur, background=card.model.background)
