"""The diagnosis of the sim-to-real gap: where the model misses, which effect explains it, how far it shrinks.

Given measured samples and a model card, :func:`diagnose` answers three questions
(paper sections 5.3.1-5.3.3, done there by hand):

Localization (:mod:`gisnoise.diagnose.localization`)
    The card's residual (measured minus model, dB) is smoothed per microphone
    and flight over a window of ``window_s`` seconds; where the smoothed residual
    is larger than the measurement noise explains (``z`` standard errors of a
    window mean, estimated from differences of adjacent window means so that
    coloured noise counts with its correlation), the samples are flagged and
    joined into segments.  The measurement noise per microphone is the robust
    spread of first differences of the residual (``1.4826 MAD / sqrt 2``): fast
    scatter is noise, slow structure is model error.  Each segment carries its
    regime (turn, straight, climb, sink, hover, transition), range (near, far)
    and microphone; statistics are given by regime, microphone and geometry bins.

Attribution (:mod:`gisnoise.diagnose.candidates`, :mod:`gisnoise.diagnose.verdict`)
    Every candidate of the effect library (:mod:`gisnoise.model.effects`) that the
    data can test is fitted as an extension of the card's ansatz with the
    output-error fitter (:func:`gisnoise.identify.fit_arrays`) on all data and in a
    two-fold cross-validation (folds are whole flights, or alternating time
    blocks when there is one flight).  A candidate is *significant* when the
    Wald statistic of its extension parameters, with the covariance corrected
    for residual autocorrelation (Morelli & Klein), rejects "no effect" at
    ``alpha`` divided by the number of candidates tested (Bonferroni).
    Candidates are ranked by their held-out improvement of the mean squared
    residual; the verdict names the best significant candidate whose held-out
    improvement reaches :data:`~gisnoise.diagnose.verdict.MIN_IMPROVEMENT_DB2` and is
    significant in a paired test over time blocks, with physical evidence
    (:mod:`gisnoise.diagnose.evidence`: turn excess, band slopes, comb pattern,
    fore/aft asymmetry, ...) breaking near ties.  Otherwise the verdict is null.
    Transient sound from other sources is found in the residual first
    (:mod:`gisnoise.diagnose.events`) and tested as the ``background_event`` candidate.

Level offsets (:mod:`gisnoise.diagnose.offsets`)
    A microphone or a flight heard louder or quieter throughout (a calibration error, a
    recalibration between flights) is a constant no effect has the shape of: it is named
    with its offset, measured by refitting the final model with one offset per flight and
    per microphone that ``gisnoise fit``'s rule names.  When offsets are named, the baseline
    and the candidates are fitted and judged once more, each carrying those offsets (one
    parameter each, :func:`~gisnoise.diagnose.offsets.with_offsets` of the same ansatz), so that
    an offset's residual does not stay in every candidate's held-out score; the verdict says so
    (``verdict.candidates_judged_with``).

Shrinkage
    Baseline and extended RMS residual on the fitted data and on held-out data
    (out-of-fold predictions: every sample is predicted by a model not fitted to
    it), overall and per segment; the base parameters each effect had biased are
    named (shift larger than ``bias_z`` corrected standard deviations).

The output is a JSON-able dict in the shape of the product specification,
section 6 (``baseline``, ``segments``, ``effects``, ``verdict``) with more detail;
:func:`write_diagnosis` writes it as ``diagnosis.json``, the one format of every face.
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.diagnose.candidates import CancelFn, _Context, _fit, _fit_candidates, _predict, fold_labels
from gisnoise.diagnose.events import residual_events
from gisnoise.diagnose.localization import _statistics, localize, measurement_noise, sample_regimes
from gisnoise.diagnose.offsets import competing_effects, judged_with, level_offsets, offset_groups, with_offsets
from gisnoise.diagnose.positions import (
    POSITION_RADIUS_M,
    correct_positions,
    exclusion_sentence,
    far_off_microphones,
    refuse_too_few,
)
from gisnoise.diagnose.samples import load_samples
from gisnoise.diagnose.selection import forward_selection, metadata_overrides
from gisnoise.diagnose.verdict import MIN_IMPROVEMENT_DB2, _judge, _rms
from gisnoise.errors import Cancelled, FitError, InputError, NotIdentifiableError
from gisnoise.jsonio import to_jsonable, write_json
from gisnoise.measure import Samples, series_ids
from gisnoise.model import Ansatz, HemisphereCard, ModelCard
from gisnoise.model import effects as _effects

__all__ = ["SCHEMA", "DIAGNOSIS_FILE", "Diagnosis", "check_diagnosable", "diagnose", "run_diagnosis",
           "write_diagnosis"]

SCHEMA = "gisnoise/diagnosis/1"
"""Schema name of the diagnosis document."""
DIAGNOSIS_FILE = "diagnosis.json"
"""File name of the diagnosis document in an output folder."""
ProgressFn = Callable[[int, int, str], None]


@dataclass
class Diagnosis:
    """Result of :func:`run_diagnosis`: the JSON document and the per-sample arrays behind it.

    Attributes
    ----------
    result : dict
        The diagnosis document (see :func:`diagnose`).
    samples : Samples
        The rows diagnosed.
    arrays : dict
        Per-sample arrays: ``resid_card``, ``resid_baseline`` (in-sample refit),
        ``oof_baseline`` and ``oof/<effect>`` (held-out residuals), ``flagged``,
        ``regime``, ``fold``, ``event_window``.  The baseline arrays are the one the
        candidates were judged against: with the level offsets named, when there are any
        (then ``resid_baseline_without_offsets`` and ``oof_baseline_without_offsets`` are
        the card's ansatz alone).
    """

    result: dict[str, Any]
    samples: Samples
    arrays: dict[str, np.ndarray]

    def to_dict(self) -> dict[str, Any]:
        """The diagnosis document."""
        return self.result


def diagnose(campaign_or_samples: Any, card: ModelCard, *, progress: ProgressFn | None = None,
             cancel: CancelFn | None = None, **kw: Any) -> dict[str, Any]:
    """Where the card misses the measurements, which effect explains it, how far the gap shrinks.

    Parameters
    ----------
    campaign_or_samples : path, Campaign or Samples
        The measurements (a campaign folder is read with :func:`gisnoise.measure.campaign.read_campaign`).
    card : ModelCard
        The model card to diagnose; its ansatz is the base of every extension and
        only samples of the phases it serves are used.
    progress : callable, optional
        ``progress(done, total, what)`` after each step.
    cancel : callable, optional
        Polled between steps and inside fits; True raises :class:`gisnoise.errors.Cancelled`.
    **kw
        See :func:`run_diagnosis`.

    Returns
    -------
    dict
        ``{"schema", "card", "data", "noise_std_db", "baseline": {"rms_db", ...},
        "segments": [...], "statistics": {...}, "event_windows": [...],
        "effects": [{"name", "rank", "testable", "significant", "rms_db_fit",
        "rms_db_holdout", "shrinkage_pct", ...}], "metadata": {..., "level_offsets"},
        "verdict": {"effect", "holdout_shrinkage_pct", "level_offsets", "candidates_judged_with", ...}}``.
        ``baseline`` is the card's ansatz refitted; with level offsets named, ``baseline.with_level_offsets``
        is the baseline the candidates were judged against, and ``verdict.candidates_judged_with`` lists the
        offsets with a sentence (``{"level_offsets": [], "sentence": None}`` when none is named).
    """
    return run_diagnosis(campaign_or_samples, card, progress=progress, cancel=cancel, **kw).result


def check_diagnosable(card: Any) -> None:
    """Refuse a card a diagnosis cannot extend (before any campaign is read): not a card, or a measured hemisphere
    (:class:`~gisnoise.model.HemisphereCard`: a table of levels, no parameters); :class:`InputError` on ``card``."""
    if not isinstance(card, ModelCard):
        raise InputError(f"card must be a ModelCard, got {type(card).__name__}", field="card")
    if isinstance(card, HemisphereCard):
        raise InputError(f"card {card.id!r} is a measured hemisphere: it has no parameters to extend; diagnose a "
                         "parametric card (gisnoise card fit-hemisphere makes one from it)", field="card")


def run_diagnosis(
    campaign_or_samples: Any,
    card: ModelCard,
    *,
    candidates: Sequence[str] | None = None,
    alpha: float = 0.01,
    window_s: float = 2.0,
    z: float = 4.0,
    block_s: float = 30.0,
    bias_z: float = 3.0,
    include_events: bool = True,
    min_improvement_db2: float = MIN_IMPROVEMENT_DB2,
    position_radius_m: float = POSITION_RADIUS_M,
    progress: ProgressFn | None = None,
    cancel: CancelFn | None = None,
) -> Diagnosis:
    """The diagnosis with its per-sample arrays (for reports); see :func:`diagnose`.

    Parameters
    ----------
    candidates : sequence of str, optional
        Effect names to test (default: the whole library).
    alpha : float
        Family-wise significance level of the extension tests (Bonferroni over candidates).
    window_s, z : float
        Localization window (s) and threshold (standard errors).
    block_s : float
        Time block of the cross-validation with one flight and of the paired held-out test, s.
    bias_z : float
        A base parameter counts as biased by an effect when the extension moves it
        by more than this many corrected standard deviations.
    include_events : bool
        Diagnose samples the campaign reader masked as ``event`` too (they are
        part of the gap and the evidence for ``background_event``).
    min_improvement_db2 : float
        Smallest held-out improvement of the mean squared residual a verdict needs, dB^2.
    position_radius_m : float
        The stated radius around its listed position within which each microphone's position is
        estimated from the data, m (:mod:`gisnoise.diagnose.positions`); 0 takes the positions as listed.
    """
    check_diagnosable(card)
    if not (0.0 < alpha < 1.0):
        raise InputError(f"alpha must be in (0, 1), got {alpha!r}", field="alpha")
    for name, v in (("window_s", window_s), ("z", z), ("block_s", block_s), ("bias_z", bias_z),
                    ("min_improvement_db2", min_improvement_db2)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"{name} must be a positive number, got {v!r}", field=name)
    if not (isinstance(position_radius_m, (int, float)) and math.isfinite(position_radius_m)
            and 0 <= position_radius_m <= 500):
        raise InputError(f"position_radius_m must be a number in [0, 500] m, got {position_radius_m!r}",
                         field="position_radius_m")
    names = list(_effects.effect_names() if candidates is None else candidates)
    for nme in names:
        _effects.get_effect(nme)

    def check_cancel() -> None:
        if cancel is not None and cancel():
            raise Cancelled("diagnosis cancelled", field="cancel")

    total = 3 + len(names)
    step = 0

    def tick(what: str) -> None:
        nonlocal step
        step += 1
        if progress is not None:
            progress(step, total, what)
        check_cancel()

    all_s = load_samples(campaign_or_samples)
    # a microphone listed far beyond the position search (its levels against spherical spreading, the rule of
    # campaign check, every phase): no effect explains it, so it is left out, and said so
    far, far_notes = far_off_microphones(all_s)
    if far:
        refuse_too_few(far, sorted(set(all_s.mic.astype(str).tolist())))
    use = np.isin(all_s.phase.astype(str), list(card.served_phases))
    keep = all_s.valid | (all_s.mask_reason.astype(str) == "event") if include_events else all_s.valid.copy()
    s = all_s.select(use & keep & ~np.isin(all_s.mic.astype(str), list(far)))
    if len(s) < 20:
        have = sorted(set(all_s.phase[all_s.valid].astype(str).tolist()))
        raise InputError(f"diagnosis needs usable samples of the card's phase(s) {', '.join(card.served_phases)}; "
                         f"found {len(s)} (phases with usable samples: {', '.join(have) or 'none'})", field="phase")
    n = len(s)
    ref = float(card.reference_power_w)
    base = card.model
    level = np.asarray(s.level, dtype=float)
    rows_all = np.arange(n)

    def inputs(smp: Samples) -> dict[str, Any]:
        xx: dict[str, Any] = dict(smp.inputs(ref))
        xx["mic"] = smp.mic.astype(str)
        xx["flight"] = smp.flight.astype(str)
        return xx

    def refit(xx: dict[str, Any], smp: Samples) -> Any:
        try:
            return _fit(level, xx, base, smp, rows_all, p0=card.p, cancel=cancel)
        except FitError as exc:
            if isinstance(exc, NotIdentifiableError):
                raise FitError(_not_identifiable(exc, base, level, xx, smp, cancel), field="card") from None
            raise FitError(f"diagnosis: the card's ansatz {base.name!r} cannot be refitted to these data: {exc}",
                           field="card") from None

    x = inputs(s)
    # ---------------------------------------------------------------- microphone positions (metadata as a prior)
    base_fit = refit(x, s)
    positions: dict[str, Any] = {}
    position_notes: list[str] = []
    if position_radius_m > 0:
        s, positions, position_notes = correct_positions(s, x, base, base_fit.p, radius_m=position_radius_m)
        if position_notes:
            x = inputs(s)
            base_fit = refit(x, s)

    # ---------------------------------------------------------------- localization on the card's residual
    pred_card = np.broadcast_to(base.level(card.p, x, d_ref=card.reference_distance_m), (n,))
    resid_card = level - pred_card
    sid = series_ids(s.mic, s.flight)
    noise = measurement_noise(resid_card, sid, s.t_e, s.mic.astype(str))
    reg = sample_regimes(s)
    segments, flagged = localize(s, resid_card, noise, window_s=window_s, z=z, regimes=reg)
    statistics = _statistics(s, resid_card, flagged, reg)
    tick("localization")

    # ---------------------------------------------------------------- baseline (refitted above), folds
    resid_base = base_fit.residuals
    fold, block, how = fold_labels(s, block_s=block_s)
    if len(np.unique(fold)) < 2:
        raise InputError(f"diagnosis needs data in two cross-validation folds; the data span less than "
                         f"2 x block_s = {2 * block_s:g} s", field="block_s")
    oof_base = np.empty(n)
    for f in (0, 1):
        tr, te = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        r = _fit(level, x, base, s, tr, p0=base_fit.p, cancel=cancel)
        oof_base[te] = level[te] - _predict(base, r.p, x, te, n)
    tick("baseline")

    # ---------------------------------------------------------------- events
    l_uav_card = np.broadcast_to(base.level_uav(card.p, x, d_ref=card.reference_distance_m), (n,))
    bg_rows = np.full(n, card.background_db if card.background_db is not None else -np.inf)
    ev_win, ev_list = residual_events(s, resid_card, noise, l_uav_card, bg_rows)
    x_ev = dict(x, event_window=ev_win)

    bg = card.background_db

    # ---------------------------------------------------------------- the metadata as a prior, candidates
    overrides, metadata = metadata_overrides(s, x, base, base_fit.p, names, fold, block,
                                             background_db=card.background_db,
                                             exclude=(ev_win >= 0) | (s.mask_reason.astype(str) == "event"))
    if positions:
        metadata["microphone_positions"] = positions
        metadata["contradictions"] = position_notes + metadata["contradictions"]
    metadata["contradictions"] = ([exclusion_sentence(far)] if far else []) + far_notes + metadata["contradictions"]
    segments_found = copy.deepcopy(segments)

    def attribution(groups: tuple[tuple[str, str], ...], segs: list[dict[str, Any]],
                    tick_fn: Callable[[str], None]) -> _Round:
        """Candidates, verdict and forward selection against the baseline with the level offsets ``groups``."""
        fit_b, oof_b = base_fit, oof_base
        hold: tuple[str, ...] = ()
        if groups:
            model_b = with_offsets(base, groups)
            offs = model_b.params[base.n_params:]
            fit_b = _fit(level, x, model_b, s, rows_all, p0={**base_fit.params, **dict.fromkeys(offs, 0.0)},
                         fixed=dict(base_fit.fixed) or None, cancel=cancel)
            hold = _held_in_folds(groups, offs, s, fold)
            oof_b = np.empty(n)
            for f in (0, 1):
                tr, te = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
                fx = {k: float(fit_b.params[k]) for k in hold}
                r = _fit(level, x, model_b, s, tr, p0={**fit_b.params, **fx}, fixed=fx or None, cancel=cancel)
                oof_b[te] = level[te] - _predict(model_b, r.p, x, te, n)
        ctx = _Context(s=s, x=x, regimes=reg, resid_base=fit_b.residuals, base_model=base,
                       p_base=fit_b.p[:base.n_params], background_db=bg, event_windows=ev_list, offsets=groups,
                       hold_in_folds=hold)
        cands = _fit_candidates(names, ctx, level, x, x_ev, fit_b, oof_b, fold, cancel=cancel, bias_z=bias_z,
                                tick=tick_fn, overrides=overrides)
        verdict, effects_out, level_alpha = _judge(cands, ctx, segs, oof_b, block, noise, fit_b, alpha=alpha,
                                                   min_improvement_db2=min_improvement_db2)
        first = next((c for c in cands if c.name == verdict["effect"]), None)
        steps: list[dict[str, Any]] = []
        last: list[Any] = []
        verdict["effects"] = [] if first is None else forward_selection(
            first, cands, ctx, level, ev_win, oof_b, fold, block, noise, level_alpha=level_alpha,
            min_improvement_db2=min_improvement_db2, overrides=overrides, cancel=cancel, bias_z=bias_z, steps=steps,
            final=last)
        verdict["selection_steps"] = steps
        return _Round(fit_b, oof_b, hold, cands, verdict, effects_out, level_alpha, last[-1] if last else None, last)

    def offsets_of(final: Any) -> dict[str, Any]:
        """Level offsets of one microphone or one flight, in what the model the diagnosis ends with leaves."""
        if final is None or final.fit is None or final.inner is None or final.x is None:
            return level_offsets(s, level, x, base, base_fit, cancel=cancel)
        fit = final.fit
        if final.inner is not final.model:  # the final model without the offsets it was judged with, refitted
            keep = final.inner.params
            fit = _fit(level, final.x, final.inner, s, rows_all, p0={k: fit.params[k] for k in keep},
                       fixed={k: v for k, v in fit.fixed.items() if k in keep} or None, cancel=cancel)
        return level_offsets(s, level, final.x, final.inner, fit, cancel=cancel)

    rnd = attribution((), segments, tick)
    offsets = offsets_of(rnd.final)
    groups, not_carried = _separable(offset_groups(offsets), rnd, s, level, cancel)
    without = rnd
    judged = judged_with(None, (), (), not_carried)
    if groups:
        # the candidates once more, each with the offsets named: an offset's residual would otherwise stay in every
        # candidate's held-out score and weaken or hide the effect
        segs = copy.deepcopy(segments_found)
        try:
            rnd = attribution(groups, segs, lambda _name: check_cancel())
        except FitError as exc:
            groups = ()
            judged["error"] = f"the baseline with the level offsets could not be fitted ({exc}): judged without them"
        else:
            segments = segs
            judged = judged_with(rnd.final.fit if rnd.final is not None else rnd.fit, groups, rnd.hold, not_carried)
            if _chosen(rnd) != _chosen(without):  # the offsets again, on the model the diagnosis now ends with
                try:
                    offsets = offsets_of(rnd.final)
                except FitError as exc:
                    judged["error"] = (f"the final model could not be refitted without the offsets ({exc}): the "
                                       "offsets are those measured before the candidates were judged with them")
    verdict = rnd.verdict
    metadata["level_offsets"] = {k: offsets[k] for k in ("microphones", "flights")}
    verdict["level_offsets"] = offsets["findings"]
    verdict["candidates_judged_with"] = judged
    base_fit_doc: dict[str, Any] = {}
    if groups:
        base_fit_doc["with_level_offsets"] = {"rms_db_fit": rnd.fit.rms_db, "rms_db_holdout": _rms(rnd.oof),
                                              "parameters": rnd.fit.params, "std_corrected": rnd.fit.std_corrected}
    effects_out, level_alpha, cands = rnd.effects, rnd.level_alpha, rnd.cands

    result = {
        "schema": SCHEMA,
        "card": {"id": card.id, "ansatz": card.ansatz, "phase": card.phase, "phases": list(card.served_phases)},
        "data": {"n_samples": n, "flights": sorted(set(s.flight.astype(str).tolist())),
                 "microphones": sorted(set(s.mic.astype(str).tolist())),
                 "excluded_microphones": far,
                 "n_reader_events": int(np.sum(s.mask_reason.astype(str) == "event")),
                 "holdout": how, "block_s": block_s, "window_s": window_s},
        "noise_std_db": noise,
        "baseline": {"rms_db": base_fit.rms_db, "rms_db_card": _rms(resid_card),
                     "rms_db_fit": base_fit.rms_db, "rms_db_holdout": _rms(oof_base),
                     "noise_std_db_fit": dict(base_fit.noise_std), "parameters": base_fit.params,
                     "std_corrected": base_fit.std_corrected, "aic": base_fit.aic, "bic": base_fit.bic,
                     **base_fit_doc},
        "segments": segments,
        "statistics": statistics,
        "event_windows": ev_list,
        "effects": effects_out,
        "alpha": alpha,
        "alpha_per_test": level_alpha,
        "metadata": metadata,
        "verdict": verdict,
    }
    arrays = {"resid_card": resid_card, "resid_baseline": rnd.fit.residuals, "oof_baseline": rnd.oof,
              "flagged": flagged, "regime": reg, "fold": fold, "event_window": ev_win, "fitted_card": pred_card}
    if groups:
        arrays["resid_baseline_without_offsets"] = resid_base
        arrays["oof_baseline_without_offsets"] = oof_base
    for c in cands:
        if c.oof is not None and c.fit is not None:
            arrays[f"oof/{c.name}"] = c.oof
            arrays[f"fit/{c.name}"] = c.fit.residuals
    tick("verdict")
    return Diagnosis(result=to_jsonable(result), samples=s, arrays=arrays)


@dataclass
class _Round:
    """One pass of attribution: the baseline it judged against (fit, out-of-fold residual, offsets held in the
    folds), the candidates, the verdict with forward selection, the effects table and the last effect chosen."""

    fit: Any
    oof: np.ndarray
    hold: tuple[str, ...]
    cands: list[Any]
    verdict: dict[str, Any]
    effects: list[dict[str, Any]]
    level_alpha: float
    final: Any
    chain: list[Any]


def _separable(groups: Sequence[tuple[str, str]], rnd: _Round, s: Samples, level: np.ndarray,
               cancel: CancelFn | None) -> tuple[tuple[tuple[str, str], ...], list[dict[str, Any]]]:
    """The offsets the candidates can carry, and those they cannot with the reason.

    An offset that takes up an effect the first pass chose (:func:`~gisnoise.diagnose.offsets.competing_effects`)
    is not carried; nor is one whose test could not be refitted.  Windows of added sound are not tested: a
    constant does not take up a transient.
    """
    final = rnd.final
    tests = {c.name: (c.tested, int(c.summary.get("look_elsewhere_trials", 1))) for c in rnd.chain
             if c.name != "background_event" and c.tested}
    if not groups or final is None or not tests:
        return tuple(groups), []
    carried, dropped = [], []
    for g in groups:
        entry: dict[str, Any] = {"group": "microphone" if g[0] == "mic" else g[0], "id": g[1]}
        try:
            lost = competing_effects(s, level, final.x, final.inner, final.fit, g, tests, rnd.level_alpha,
                                     cancel=cancel)
        except FitError as exc:
            dropped.append({**entry, "reason": f"the refit that tests it against the effects failed ({exc})"})
            continue
        if lost:
            dropped.append({**entry, "competes_with": lost})
        else:
            carried.append(g)
    return tuple(carried), dropped


def _held_in_folds(groups: Sequence[tuple[str, str]], names: Sequence[str], s: Samples,
                   fold: np.ndarray) -> tuple[str, ...]:
    """The offset parameters ``names`` (of ``groups``) a fold's fit holds at their values on all data.

    A flight's, when the folds are flights (the fold that holds a flight out cannot tell its offset, and the one
    with that flight alone cannot tell it from the level), and a microphone's heard in one fold only.
    """
    held = []
    for (key, value), k in zip(groups, names, strict=True):
        rows = np.asarray(s.flight if key == "flight" else s.mic).astype(str) == value
        if key == "flight" or len(np.unique(fold[rows])) < 2:
            held.append(k)
    return tuple(held)


def _chosen(rnd: _Round) -> list[str]:
    """The effects a pass of attribution chose, in order."""
    return [e["effect"] for e in rnd.verdict["effects"]]


def _not_identifiable(exc: NotIdentifiableError, base: Ansatz, level: np.ndarray, x: dict[str, Any], s: Samples,
                      cancel: CancelFn | None) -> str:
    """Why the card's ansatz cannot be refitted: the data, or an ansatz without the level offset the data need.

    An ansatz without ``p0`` (``paper``) makes ``p1 log10(P_el)`` the whole level; when the same ansatz with
    the offset (``paper-offset``) fits the data with ``p0`` more than 3 corrected standard deviations from 0,
    the data need the offset, and the message says so.  Otherwise it names both possibilities.
    """
    head = f"diagnosis: the card's ansatz {base.name!r} cannot be refitted to these data: {exc}"
    first, *chain = base.name.split("+")
    if "p0" in base.params:
        return head
    offset_name = "+".join([f"{first}-offset", *chain])
    try:
        off = _effects.get_ansatz(offset_name)
        if "p0" not in off.params:
            raise InputError(f"ansatz {offset_name!r} has no p0", field="ansatz")
        res = _fit(level, x, off, s, np.arange(len(s)), cancel=cancel)
    except Cancelled:
        raise
    except (FitError, InputError):
        return (f"{head}; or the ansatz lacks a term these data need (a level offset p0, say, which "
                f"{offset_name!r} would add)")
    p0, sd = float(res.params["p0"]), float(res.std_corrected["p0"])
    if not abs(p0) > 3.0 * sd:
        return (f"{head}; or the ansatz lacks a term these data need ({offset_name!r}, with a level offset, fits "
                f"them, but its p0 = {p0:.2f} dB (+/- {sd:.2f} dB) is not clearly needed)")
    return (f"diagnosis: the card's ansatz {base.name!r} has no level offset p0, and these data need one: the same "
            f"ansatz with it, {offset_name!r}, fits them with p0 = {p0:.2f} dB (+/- {sd:.2f} dB); without it "
            f"p1 log10(P_el) must carry the whole level and the refit cannot tell {', '.join(exc.parameters)} apart. "
            f"Diagnose a card of ansatz {offset_name!r} (gisnoise fit CAMPAIGN --ansatz {offset_name} writes one)")


def write_diagnosis(diagnosis: Diagnosis, path: str | os.PathLike[str], *, campaign: str) -> Path:
    """Write the diagnosis document, the one format of ``diagnosis.json`` for every face.

    Strict JSON (non-finite numbers as null) with an indent of 2, written to a
    temporary file and moved into place, so that a reader never sees half a file.

    Parameters
    ----------
    diagnosis : Diagnosis
        The result of :func:`run_diagnosis`.
    path : path
        The file to write, or an existing folder to write :data:`DIAGNOSIS_FILE` in.
    campaign : str
        What the document names as its campaign (``"campaign"``): the folder as the
        user gave it, or a description where a path would mean nothing to the reader.

    Returns
    -------
    Path
        The file written.
    """
    target = Path(path)
    if target.is_dir():
        target = target / DIAGNOSIS_FILE
    doc = dict(diagnosis.result)
    doc["campaign"] = campaign
    return write_json(doc, target, indent=2)
