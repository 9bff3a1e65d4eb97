"""Metadata as a prior and several effects at once: the candidates' estimated inputs and forward selection.

:func:`metadata_overrides` runs the estimates of :mod:`gisnoise.diagnose.metadata`
and, where the data contradict the campaign's metadata, gives the candidate the
estimated inputs (microphone heights for ``ground_reflection``) or form (one clock
offset per microphone for ``emission_time``) with the sentence the report shows.

:func:`forward_selection` adds effects one at a time: after the verdict's first
effect, the model extended by it becomes the baseline, the remaining candidates
that were significant alone are fitted again on top of it, scored on held-out
data against it, and the best qualifying one is added; until none qualifies.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from gisnoise.diagnose.bandtests import absorption_band_holdout
from gisnoise.diagnose.candidates import CancelFn, _Candidate, _Context, _fit_candidates
from gisnoise.diagnose.events import residual_events
from gisnoise.diagnose.metadata import (
    clock_note,
    clocks_disagree,
    estimate_clock_offsets,
    estimate_mic_heights,
    mic_clock_effect,
)
from gisnoise.diagnose.verdict import _block_test, _choose, _gate, _rms, _score
from gisnoise.measure import Samples
from gisnoise.model import Ansatz, mic_height_agl
from gisnoise.model import effects as _effects

__all__ = ["MAX_EFFECTS", "STEP_IMPROVEMENT_FACTOR", "forward_selection", "metadata_overrides"]

MAX_EFFECTS = 4
"""Most effects forward selection adds."""
STEP_IMPROVEMENT_FACTOR = 2.0
"""An effect added after the first needs this multiple of the smallest held-out improvement of a verdict."""

Override = tuple[_effects.Effect, dict[str, Any], list[str], dict[str, Any]]


def metadata_overrides(s: Samples, x: Mapping[str, Any], base: Ansatz, p_base: np.ndarray,
                       names: Sequence[str], fold: np.ndarray,
                       block: np.ndarray, *, background_db: float | None = None,
                       exclude: np.ndarray | None = None) -> tuple[dict[str, Override], dict[str, Any]]:
    """Candidates to test with inputs estimated from the data, and the ``metadata`` section of the report.

    Returns
    -------
    overrides : dict
        ``name -> (effect, extra_inputs, sentences)`` for :func:`~gisnoise.diagnose.candidates._fit_candidates`.
    doc : dict
        ``{"microphone_heights": {...}, "clock_offsets": {...}, "contradictions": [sentence, ...]}``.
    """
    overrides: dict[str, Override] = {}
    doc: dict[str, Any] = {"contradictions": []}
    if "ground_reflection" in names:
        heights = estimate_mic_heights(s, x, fold)
        doc["microphone_heights"] = {m: {k: v for k, v in h.items() if k not in ("rows", "err0", "err1")}
                                     for m, h in heights.items()}
        contra = {m: h for m, h in heights.items() if h["contradicts"]}
        if contra:
            listed = mic_height_agl(x)
            agl = np.zeros(len(s)) if listed is None else np.nan_to_num(np.asarray(listed, dtype=float))
            mics = s.mic.astype(str)
            for m, h in contra.items():
                agl[mics == m] = h["height_m"]
            notes = [h["sentence"] for h in contra.values()]
            rows = np.concatenate([h["rows"] for h in contra.values()])
            err0 = np.concatenate([h["err0"] for h in contra.values()])
            err1 = np.concatenate([h["err1"] for h in contra.values()])
            imp, p_band = _block_test(err0, err1, block[rows])
            band = {"improvement_db2": imp, "p_value": p_band, "rms_db_baseline": _rms(err0),
                    "rms_db_extended": _rms(err1), "shrinkage_pct": 100.0 * (1.0 - _rms(err1) / _rms(err0)),
                    "what": "centred band levels of the microphones whose metadata the comb contradicts, "
                            "comb fitted on the other fold"}
            overrides["ground_reflection"] = (_effects.get_effect("ground_reflection"), {"mic_agl": agl}, notes,
                                              {"band_holdout": band})
            doc["contradictions"] += notes
    if "atmospheric_absorption" in names:
        abs_band = absorption_band_holdout(s, x, fold, block, background_db=background_db, exclude=exclude)
        if abs_band is not None:
            doc["absorption_bands"] = {k: abs_band[k] for k in ("iso_multiple", "iso_multiple_std", "n_rows",
                                                                "n_bands")}
            overrides["atmospheric_absorption"] = (_effects.get_effect("atmospheric_absorption"), {}, [],
                                                   {"band_holdout": abs_band})
    if "emission_time" in names and "t_e" in x:
        clocks = estimate_clock_offsets(s, x, base, p_base)
        doc["clock_offsets"] = clocks
        odd = clocks_disagree(clocks)
        if odd:
            notes = [clock_note(m, clocks) for m in odd]
            start = {m: float(v["offset_s"]) for m, v in clocks.items()}
            eff = mic_clock_effect(s, x, sorted(clocks), start, base)
            overrides["emission_time"] = (eff, {}, notes, {})
            doc["contradictions"] += notes
    return overrides, doc


def _entry(c: _Candidate, oof_ref: np.ndarray, oof_base: np.ndarray) -> dict[str, Any]:
    """One ``verdict.effects`` entry: the effect with its held-out shrinkage against the model before it."""
    assert c.oof is not None
    e: dict[str, Any] = {
        "effect": c.name,
        "holdout_shrinkage_pct": 100.0 * (1.0 - _rms(c.oof) / _rms(oof_ref)) if _rms(oof_ref) > 0 else 0.0,
        "cumulative_shrinkage_pct": 100.0 * (1.0 - _rms(c.oof) / _rms(oof_base)) if _rms(oof_base) > 0 else 0.0,
        "holdout_improvement_db2": c.summary.get("holdout_improvement_db2"),
        "p_value": c.summary.get("p_value"),
        "evidence": (c.summary.get("evidence") or {}).get("summary"),
        "parameters": c.summary.get("parameters", {}),
    }
    if c.summary.get("metadata_contradicted"):
        e["metadata_contradicted"] = c.summary["metadata_contradicted"]
    return e


def _worth_trying(c: _Candidate) -> bool:
    """Whether a candidate is tried on top of the effects chosen.

    When it was significant, or its band-level test was, or it improved held-out data significantly (a fit
    that ends on a bound while another effect is unmodelled has no Wald test, yet it may hold an effect).
    """
    sm = c.summary
    held_out = (sm.get("holdout_improvement_db2") or 0.0) > 0.0 and (sm.get("p_holdout") or 1.0) < 0.05
    return bool(sm.get("significant") or sm.get("significant_bands") or held_out)


def _step_score(c: _Candidate) -> dict[str, Any]:
    """What forward selection saw of one candidate in one step."""
    sm = c.summary
    return {"effect": c.name, "p_value": sm.get("p_value"), "significant": sm.get("significant"),
            "holdout_improvement_db2": sm.get("holdout_improvement_db2"), "p_holdout": sm.get("p_holdout"),
            "p_bands": (sm.get("band_holdout") or {}).get("p_value"),
            "evidence_supports": (sm.get("evidence") or {}).get("supports"),
            "evidence": (sm.get("evidence") or {}).get("summary"),
            "reason": (f"fit failed: {c.error}" if c.error else c.reason) or None}


def forward_selection(first: _Candidate, cands: Sequence[_Candidate], ctx: _Context, level: np.ndarray,
                      ev_win: np.ndarray, oof_base: np.ndarray, fold: np.ndarray, block: np.ndarray,
                      noise: Mapping[str, float], *, level_alpha: float, min_improvement_db2: float,
                      overrides: Mapping[str, Override], cancel: CancelFn | None, bias_z: float,
                      max_effects: int = MAX_EFFECTS,
                      steps: list[dict[str, Any]] | None = None,
                      final: list[_Candidate] | None = None) -> list[dict[str, Any]]:
    """The effects in the order forward selection adds them, each with its held-out shrinkage.

    Candidates that showed nothing alone (no significant test, band-level test or held-out
    improvement) are not tried again (an effect too weak to show alone is not looked for under
    another).  ``steps``, when given, receives one entry per step after the first: the candidates
    tried on top of the model so far with their scores, and the one added (or None); ``final``, when
    given, receives the candidates added, in order (the last one's fit is the model the selection ends with).
    """
    chosen = [_entry(first, oof_base, oof_base)]
    chain = [first]
    names = [c.name for c in cands if c.name != first.name and c.fit is not None and _worth_trying(c)]
    cur = first
    noop: Callable[[str], None] = lambda _name: None  # noqa: E731
    # the levels of added sound are nuisance parameters, one per window: held at their values once chosen
    held: dict[str, float] = {}

    def hold_events(c: _Candidate, base_params: Sequence[str]) -> None:
        if c.name == "background_event" and c.fit is not None and c.inner is not None:
            held.update({k: float(c.fit.params[k]) for k in c.inner.params if k not in base_params})

    hold_events(first, ctx.base_model.params)
    while names and len(chosen) < max_effects:
        assert cur.model is not None and cur.fit is not None and cur.oof is not None and cur.x is not None
        assert cur.inner is not None
        xcur = dict(cur.x)  # with the event windows when the model so far has added sound
        # the model so far without the level offsets (if any) is what the next candidates extend; they carry the
        # offsets on top again (its parameters come first in the fit's, the offsets' last)
        p_inner = cur.fit.p[:cur.inner.n_params]
        ctx2 = replace(ctx, x=xcur, base_model=cur.inner, p_base=p_inner, resid_base=cur.fit.residuals)
        x_ev = dict(xcur, event_window=ev_win)
        if "background_event" in names:
            # windows of added sound are looked for again in what the effects chosen so far leave unexplained
            l_uav = np.broadcast_to(cur.inner.level_uav(p_inner, xcur), level.shape)
            bg = np.full(len(level), ctx.background_db if ctx.background_db is not None else -np.inf)
            if ctx.offsets:  # a level offset raises the UAV and the background a microphone hears alike
                shift = cur.model.level(cur.fit.p, xcur) - cur.inner.level(p_inner, xcur)
                l_uav, bg = l_uav + shift, bg + shift
            win, wins = residual_events(ctx.s, cur.fit.residuals, noise, l_uav, bg)
            ctx2 = replace(ctx2, event_windows=wins)
            x_ev = dict(xcur, event_window=win)
        step = _fit_candidates(names, ctx2, level, xcur, x_ev, cur.fit, cur.oof, fold, cancel=cancel,
                               bias_z=bias_z, tick=noop, overrides=overrides, screen_alpha=level_alpha,
                               base_fixed={**dict(cur.fit.fixed), **held}, screen_min_db2=min_improvement_db2)
        tried = step
        step = [c for c in step if c.oof is not None]
        _score(step, ctx2, cur.oof, block, noise, level_alpha)
        ranked = sorted([c for c in step if c.oof is not None and c.fit is not None],
                        key=lambda c: -c.summary.get("holdout_improvement_db2", -np.inf))
        # after the first effect the residual holds what the imperfect forms of the chosen effects leave, and
        # every candidate is tested again at each step: twice the smallest improvement, and the held-out test
        # at the Bonferroni level of the Wald tests
        nxt = _choose(ranked, STEP_IMPROVEMENT_FACTOR * min_improvement_db2, p_holdout_max=level_alpha)
        gated = _gate(nxt) if nxt is not None else None
        if steps is not None:
            steps.append({"on_top_of": [e["effect"] for e in chosen],
                          "added": None if nxt is None or gated else nxt.name,
                          "reason": gated,
                          "tried": [_step_score(c) for c in tried]})
        if nxt is None or gated is not None:
            break
        chosen.append(_entry(nxt, cur.oof, oof_base))
        hold_events(nxt, cur.inner.params)
        names = [c.name for c in ranked if c.name != nxt.name and _worth_trying(c)]
        cur = nxt
        chain.append(nxt)
    if final is not None:
        final.extend(chain)
    return chosen
