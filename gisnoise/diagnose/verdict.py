"""The verdict: candidates scored on held-out data, ranked, and the one effect that explains the gap named.

A candidate is *significant* when its test (Wald statistic of its extension
parameters, or the scan statistic of the strongest event window) rejects "no
effect" at ``alpha`` divided by the number of candidates tested (Bonferroni).
Candidates are ranked by their held-out improvement of the mean squared residual;
the verdict names the best significant candidate whose held-out improvement reaches
:data:`MIN_IMPROVEMENT_DB2` and is significant in a paired test over time blocks,
with physical evidence (:mod:`gisnoise.diagnose.evidence`) breaking near ties.
Otherwise the verdict is null.  The shrinkage of the residual is given overall and
per segment.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy import stats

from gisnoise.diagnose.candidates import _Candidate, _Context
from gisnoise.diagnose.evidence import _EVIDENCE
from gisnoise.errors import GisnoiseError
from gisnoise.identify import FitResult

__all__ = ["MIN_IMPROVEMENT_DB2"]

MIN_IMPROVEMENT_DB2 = 0.005
"""Smallest held-out improvement of the mean squared residual (dB^2) a verdict needs: an effect
whose removal takes less (an RMS contribution below about 0.07 dB) does not matter in practice."""


def _block_test(e0: np.ndarray, e1: np.ndarray, block: np.ndarray) -> tuple[float, float]:
    """Mean held-out improvement of the squared residual (dB^2) and its one-sided p-value over blocks."""
    dlt = e0 * e0 - e1 * e1
    _, inv = np.unique(block, return_inverse=True)
    cnt = np.bincount(inv)
    means = np.bincount(inv, weights=dlt) / np.maximum(cnt, 1)
    means = means[cnt > 0]
    mean = float(np.mean(dlt))
    if len(means) < 3 or np.std(means) == 0:
        return mean, (0.0 if mean > 0 and np.std(means) == 0 else 1.0)
    t = float(np.mean(means) / (np.std(means, ddof=1) / math.sqrt(len(means))))
    return mean, float(stats.t.sf(t, len(means) - 1))


def _rms(v: np.ndarray) -> float:
    """Root mean square, NaN of nothing."""
    return float(np.sqrt(np.mean(v * v))) if len(v) else float("nan")


def _judge(
    cands: Sequence[_Candidate],
    ctx: _Context,
    segments: list[dict[str, Any]],
    oof_base: np.ndarray,
    block: np.ndarray,
    noise: Mapping[str, float],
    base_fit: FitResult,
    *,
    alpha: float,
    min_improvement_db2: float,
) -> tuple[dict[str, Any], list[dict[str, Any]], float]:
    """Score, rank and judge the candidates; add the held-out shrinkage to each segment (in place).

    Returns
    -------
    verdict : dict
        The verdict document.
    effects : list of dict
        One entry per candidate, in rank order (untested ones last, by name).
    alpha_per_test : float
        ``alpha`` over the number of candidates tested.
    """
    n_tests = max(len([c for c in cands if c.testable]), 1)
    level_alpha = alpha / n_tests
    _score(cands, ctx, oof_base, block, noise, level_alpha)
    ranked = sorted([c for c in cands if c.oof is not None],
                    key=lambda c: -c.summary.get("holdout_improvement_db2", -np.inf))
    for i, c in enumerate(ranked):
        c.summary["rank"] = i + 1
    verdict_c = _choose(ranked, min_improvement_db2)
    gated = _gate(verdict_c) if verdict_c is not None else None
    _segment_shrinkage(segments, ctx, oof_base, verdict_c or (ranked[0] if ranked else None))
    if gated is not None:
        verdict_c = None
    tested = any(c.testable and c.fit is not None for c in cands)
    doc = _verdict(verdict_c, tested, level_alpha, oof_base, base_fit)
    if gated is not None:
        doc["reason"] = gated
    return doc, _effects_table(cands), level_alpha


def _gate(c: _Candidate) -> str | None:
    """Why the evidence stops ``c`` from being named (its physical evidence contradicts it), or None."""
    ev = c.summary.get("evidence") or {}
    if ev.get("supports") is False:
        return (f"the leading candidate {c.name} fits but its physical evidence contradicts it "
                f"({ev.get('summary', 'no summary')}): no effect is named")
    return None


def _score(cands: Sequence[_Candidate], ctx: _Context, oof_base: np.ndarray, block: np.ndarray,
           noise: Mapping[str, float], level_alpha: float) -> None:
    """Held-out improvement, shrinkage, p-value, significance and physical evidence of each fitted candidate."""
    mse0 = float(np.mean(oof_base ** 2))
    sig2 = float(np.mean([noise.get(m, 0.0) ** 2 for m in ctx.s.mic.astype(str)]))
    for c in cands:
        if c.oof is None:
            continue
        imp, p_ho = _block_test(oof_base, c.oof, block)
        c.summary["holdout_improvement_db2"] = imp
        c.summary["p_holdout"] = p_ho
        c.summary["rms_db_holdout"] = _rms(c.oof)
        c.summary["shrinkage_pct"] = 100.0 * (1.0 - _rms(c.oof) / _rms(oof_base)) if mse0 > 0 else 0.0
        c.summary["excess_explained_pct"] = (100.0 * imp / (mse0 - sig2)) if mse0 - sig2 > 1e-12 else None
        if c.fit is not None and c.name != "background_event":
            w, dof = c.summary.get("wald", 0.0), c.summary.get("wald_dof", 1)
            trials = c.summary.get("look_elsewhere_trials", 1)
            c.summary["p_value"] = float(min(1.0, trials * stats.chi2.sf(w, dof))) if dof else 1.0
        c.summary["significant"] = bool(c.summary.get("p_value", 1.0) < level_alpha)
        band = c.summary.get("band_holdout")
        if band is not None:  # evidence in the band levels (estimated inputs): its own held-out test
            c.summary["significant_bands"] = bool(band["p_value"] < level_alpha)
        check = _EVIDENCE.get(c.name)
        if check is not None:
            try:
                c.summary["evidence"] = check(ctx, c)
            except (GisnoiseError, ValueError, np.linalg.LinAlgError) as exc:
                c.summary["evidence"] = {"supports": None, "summary": f"not computed: {exc}"}


def _choose(ranked: Sequence[_Candidate], min_improvement_db2: float, p_holdout_max: float = 0.05) -> _Candidate | None:
    """The verdict's candidate among the ranked ones, or None.

    The first significant candidate whose held-out improvement is large enough and
    significant in the paired block test (p below ``p_holdout_max``); a runner-up within 20 % of its
    improvement takes its place when the evidence contradicts the leader and supports the runner-up.
    """
    eligible = [c for c in ranked if (c.summary["significant"] and c.summary["holdout_improvement_db2"] >= min_improvement_db2
                and c.summary["p_holdout"] < p_holdout_max) or _band_qualifies(c, min_improvement_db2)]
    if not eligible:
        return None
    verdict_c = eligible[0]
    sup = (verdict_c.summary.get("evidence") or {}).get("supports")
    for other in eligible[1:]:
        close = other.summary["holdout_improvement_db2"] >= 0.8 * verdict_c.summary["holdout_improvement_db2"]
        if close and sup is False and (other.summary.get("evidence") or {}).get("supports") is True:
            return other
    return verdict_c


def _band_qualifies(c: _Candidate, min_improvement_db2: float) -> bool:
    """Whether ``c`` qualifies on its band-level held-out test (significant, large enough, not worse in LA)."""
    band = c.summary.get("band_holdout")
    return bool(band is not None and c.summary.get("significant_bands") and band["improvement_db2"] >= min_improvement_db2
                and c.summary.get("holdout_improvement_db2", 0.0) > -min_improvement_db2)


def _segment_shrinkage(segments: list[dict[str, Any]], ctx: _Context, oof_base: np.ndarray,
                       top: _Candidate | None) -> None:
    """Held-out RMS of each segment before and after the candidate ``top`` (in place)."""
    s = ctx.s
    for seg in segments:
        m = (s.flight.astype(str) == seg["flight"]) & (s.mic.astype(str) == seg["mic"]) & \
            (s.t_e >= seg["t0"]) & (s.t_e <= seg["t1"])
        seg["rms_db_holdout_baseline"] = _rms(oof_base[m])
        if top is not None and top.oof is not None:
            seg["effect"] = top.name
            seg["rms_db_holdout_extended"] = _rms(top.oof[m])
            b = seg["rms_db_holdout_baseline"]
            seg["shrinkage_pct"] = 100.0 * (1.0 - seg["rms_db_holdout_extended"] / b) if b > 0 else 0.0


def _effects_table(cands: Sequence[_Candidate]) -> list[dict[str, Any]]:
    """The ``effects`` entries: every candidate in rank order with its summary, or why it was not tested."""
    effects_out = []
    for c in sorted(cands, key=lambda c: (c.summary.get("rank", 10 ** 6), c.name)):
        e: dict[str, Any] = {"name": c.name, "rank": c.summary.get("rank"), "testable": c.testable,
                             "description": c.effect.description if c.effect else ""}
        if not c.testable:
            e.update(significant=False, reason=c.reason)
        elif c.error:
            e.update(significant=False, reason=f"fit failed: {c.error}")
        else:
            if c.reason:
                e["reason"] = c.reason
            e.update({k: v for k, v in c.summary.items()})
        effects_out.append(e)
    return effects_out


def _verdict(verdict_c: _Candidate | None, tested: bool, level_alpha: float, oof_base: np.ndarray,
             base_fit: FitResult) -> dict[str, Any]:
    """The ``verdict`` document: the effect named with its shrinkage and evidence, or why none is."""
    if verdict_c is None:
        why = ("no candidate is significant with a held-out improvement" if tested else
               "no candidate could be tested")
        return {"effect": None, "holdout_shrinkage_pct": 0.0, "reason": why,
                "rms_db_holdout_baseline": _rms(oof_base)}
    evidence = verdict_c.summary.get("evidence") or {}
    extra: dict[str, Any] = {k: verdict_c.summary[k] for k in ("metadata_contradicted", "band_holdout")
                             if verdict_c.summary.get(k)}
    return {**extra, "effect": verdict_c.name, "parameters": verdict_c.summary.get("parameters", {}), "holdout_shrinkage_pct": verdict_c.summary["shrinkage_pct"],
            "rms_db_holdout_baseline": _rms(oof_base),
            "rms_db_holdout_extended": verdict_c.summary["rms_db_holdout"],
            "rms_db_fit_baseline": base_fit.rms_db,
            "rms_db_fit_extended": verdict_c.summary.get("rms_db_fit"),
            "p_value": verdict_c.summary.get("p_value"),
            "biased_parameters": verdict_c.summary.get("biased_parameters", []),
            "evidence": evidence.get("summary"),
            "reason": _reason(verdict_c, level_alpha)}


def _reason(c: _Candidate, level_alpha: float) -> str:
    """Why ``c`` is the verdict, in one sentence."""
    band = c.summary.get("band_holdout")
    la = (f"held-out improvement of the overall level {c.summary['holdout_improvement_db2']:.3f} dB^2, paired-block p "
          f"{c.summary['p_holdout']:.1e}")
    if band is not None and c.summary.get("significant_bands"):
        return (f"its pattern in the band levels predicts held-out data better at p {band['p_value']:.1e} < "
                f"{level_alpha:.1e} ({band['improvement_db2']:.3f} dB^2, {band['shrinkage_pct']:.0f} % lower RMS); "
                f"{la}")
    return f"significant at {level_alpha:.1e} and the largest {la}"

