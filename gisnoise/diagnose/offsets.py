"""Level offsets that no effect explains: one microphone, or one flight, heard louder or quieter throughout.

A microphone whose calibration is off by 3 dB, or a flight after which every
microphone was recalibrated, leaves a residual that is a constant: none of the
library's effects (:mod:`gisnoise.model.effects`) has that shape, so the verdict is
rightly null, yet the residual is not noise.  This module says so, on the model the
diagnosis ends with (the baseline refit, or the baseline extended by the verdict's
effects).

Which microphones
    The rule of ``gisnoise fit``'s warning (:func:`gisnoise.identify.fit.misfit_microphones`):
    the part of a microphone's residual that stays the same over 2 s exceeds 0.5 dB and
    three times the median of the other microphones'.
How large
    The model is refitted with one level offset per flight but the first and one per
    microphone so named (:func:`with_offsets`, added to the level heard, background included), every other
    parameter free: a parameter that had taken up part of an offset gives it back.  The
    offset's standard deviation is the fit's, corrected for residual autocorrelation.
    A flight's offset is taken against the mean of the other flights' (with two flights:
    the second against the first); it is named when it exceeds :data:`OFFSET_Z` standard
    deviations and :data:`~gisnoise.identify.fit.SYSTEMATIC_MIN_DB` (the smallest systematic
    residual the microphone rule names).  A named microphone's offset is called a level
    offset under the same two conditions; otherwise the model misses it in another way
    (its position, its height).
The candidates with them
    The offsets so named (:func:`offset_groups`) go into the baseline and every candidate
    effect, which the diagnosis then fits and judges again (:mod:`gisnoise.diagnose.candidates`);
    :func:`judged_with` says so in the verdict.  An offset that takes up an effect the diagnosis
    chose (:func:`competing_effects`: with it, the effect's test no longer rejects "no effect";
    a constant at the one microphone above a reflecting ground and the reflection there, say) is
    not carried: the data cannot tell the two apart, and the candidates are judged without it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy import stats

from gisnoise.diagnose._offset_model import offset_parameter, with_offsets
from gisnoise.diagnose.candidates import CancelFn, _fit, _wald
from gisnoise.errors import Cancelled, GisnoiseError
from gisnoise.identify import FitResult
from gisnoise.identify.fit import SYSTEMATIC_MIN_DB, SYSTEMATIC_WINDOW_S, misfit_microphones, systematic_residuals
from gisnoise.measure import Samples
from gisnoise.model import Ansatz

__all__ = ["OFFSET_Z", "competing_effects", "judged_with", "level_offsets", "offset_groups", "with_offsets"]

OFFSET_Z = 3.0
"""Standard deviations a flight's or a microphone's level offset must exceed to be called one."""
_BOUND_DB = 30.0  # a level offset beyond this is no calibration error


def level_offsets(s: Samples, level: np.ndarray, x: Mapping[str, Any], model: Ansatz, fit: FitResult, *,
                  cancel: CancelFn | None = None) -> dict[str, Any]:
    """Microphones and flights whose residual is a level offset that no effect explains.

    Parameters
    ----------
    s : Samples
        The samples diagnosed.
    level : ndarray
        Their measured levels, dB.
    x : mapping
        The model inputs of ``model`` (with ``mic`` and ``flight``).
    model : Ansatz
        The model the diagnosis ends with.
    fit : FitResult
        Its fit to all samples.
    cancel : callable, optional
        Polled inside the refit.

    Returns
    -------
    dict
        ``{"microphones": {mic: {"rms_db", "systematic_db", "named", "offset_db", "std_db"}},
        "flights": {flight: {"offset_db", "std_db", "named"}}, "findings": [sentence, ...]}``
        (offsets of microphones the rule does not name are not estimated: None).
    """
    parts = systematic_residuals(s, fit.residuals)
    named = misfit_microphones(parts)
    mics: dict[str, Any] = {m: {"rms_db": v[0], "systematic_db": v[1], "named": m in named, "offset_db": None,
                                "std_db": None} for m, v in parts.items()}
    flights = sorted(set(s.flight.astype(str).tolist()))
    groups: list[tuple[str, str]] = [("flight", f) for f in flights[1:]] + [("mic", m) for m in named]
    out: dict[str, Any] = {"microphones": mics, "flights": {}, "findings": []}
    if not groups:
        return out
    ext = with_offsets(model, groups)
    names = ext.params[model.n_params:]
    start = {**dict(zip(model.params, np.asarray(fit.p, dtype=float), strict=True)), **dict.fromkeys(names, 0.0)}
    fixed = dict(fit.fixed) or None
    try:
        res = _fit(np.asarray(level, dtype=float), {**x, "mic": s.mic.astype(str), "flight": s.flight.astype(str)},
                   ext, s, np.arange(len(s)), p0=start, fixed=fixed, cancel=cancel)
    except GisnoiseError as exc:
        if isinstance(exc, Cancelled):
            raise
        out["error"] = f"the refit with level offsets failed: {exc}"
        return out
    idx = {k: ext.params.index(k) for k in names}
    cov = np.asarray(res.cov_corrected, dtype=float)
    if len(flights) >= 2:
        vec = np.zeros((len(flights), len(ext.params)))  # o_flight as a combination of the parameters
        for i, f in enumerate(flights[1:], start=1):
            vec[i, idx[offset_parameter("flight", f)]] = 1.0
        for i, f in enumerate(flights):
            a = vec[i] - np.mean(np.delete(vec, i, axis=0), axis=0)
            off, sd = float(a @ res.p), float(math.sqrt(max(float(a @ cov @ a), 0.0)))
            out["flights"][f] = {"offset_db": off, "std_db": sd, "named": _is_offset(off, sd)}
        if len(flights) == 2:  # one difference, given for the second flight
            out["flights"][flights[0]]["named"] = False
        for f in flights:
            e = out["flights"][f]
            if e["named"]:
                against = f"flight '{flights[0]}'" if len(flights) == 2 else "the other flights"
                out["findings"].append(
                    f"flight '{f}': every microphone hears it {abs(e['offset_db']):.2f} dB (+/- {e['std_db']:.2f} dB) "
                    f"{'louder' if e['offset_db'] > 0 else 'quieter'} than {against}: a level offset between flights "
                    "that no effect of the library explains; a calibration changed between them, or the conditions "
                    "(temperature, wind, background) or the vehicle (mass, battery, propellers) differed")
    for m, ref in named.items():
        k = offset_parameter("mic", m)
        off, sd = float(res.params[k]), float(res.std_corrected[k])
        e = mics[m]
        e.update(offset_db=off, std_db=sd)
        head = (f"microphone '{m}': {e['systematic_db']:.2f} dB of its {e['rms_db']:.2f} dB rms residual is "
                f"systematic (steady over {SYSTEMATIC_WINDOW_S:g} s) against a median {ref:.2f} dB for the others")
        if _is_offset(off, sd):
            out["findings"].append(
                f"{head}; its level lies {abs(off):.2f} dB (+/- {sd:.2f} dB) {'above' if off > 0 else 'below'} what "
                "the model and the other microphones say, throughout: a level offset (calibration, mount or "
                "position) that no effect of the library explains; check its calibration")
        else:
            out["findings"].append(
                f"{head}, while its mean level agrees with theirs ({off:+.2f} dB, +/- {sd:.2f} dB): the model misses "
                "this microphone alone, not by a level offset; check its position and height")
    return out


def _is_offset(off: float, sd: float) -> bool:
    """Whether an estimated offset (dB) with its standard deviation counts as a level offset."""
    return bool(math.isfinite(off) and abs(off) > OFFSET_Z * sd and abs(off) >= SYSTEMATIC_MIN_DB)


def competing_effects(s: Samples, level: np.ndarray, x: Mapping[str, Any], model: Ansatz, fit: FitResult,
                      group: tuple[str, str], tests: Mapping[str, tuple[Sequence[str], int]], alpha: float, *,
                      cancel: CancelFn | None = None) -> list[dict[str, Any]]:
    """The effects the level offset of ``group`` takes up: no longer significant once the offset is added.

    ``model`` is fitted with the one offset added (:func:`with_offsets`), every parameter free but those
    ``fit`` held, and each effect's Wald test (autocorrelation-corrected covariance, p-value times its
    look-elsewhere trials) is repeated at ``alpha``.

    Parameters
    ----------
    s, level, x
        The samples, their levels (dB) and the model inputs (with ``mic`` and ``flight``).
    model : Ansatz
        The model the diagnosis ended with, without offsets.
    fit : FitResult
        Its fit to all samples.
    group : (str, str)
        The offset's group (``("mic", "m4")``, ``("flight", "f2")``).
    tests : mapping
        Effect name -> (the parameters of its test, look-elsewhere trials).
    alpha : float
        The level of each test.
    cancel : callable, optional
        Polled inside the refit.

    Returns
    -------
    list of dict
        ``[{"effect", "p_value", "p_value_without"}]`` for each effect whose test no longer rejects "no
        effect" with the offset; empty when the offset and the effects are told apart.  A failed refit
        raises its :class:`~gisnoise.errors.FitError`.
    """
    if not tests:
        return []
    ext = with_offsets(model, [group])
    start = {**dict(zip(model.params, np.asarray(fit.p, dtype=float), strict=True)),
             **dict.fromkeys(ext.params[model.n_params:], 0.0)}
    res = _fit(np.asarray(level, dtype=float), {**x, "mic": s.mic.astype(str), "flight": s.flight.astype(str)},
               ext, s, np.arange(len(s)), p0=start, fixed=dict(fit.fixed) or None, cancel=cancel)
    lost = []
    for name, (tested, trials) in tests.items():
        p_with, p_without = (min(1.0, trials * float(stats.chi2.sf(*_wald(r, tested)))) for r in (res, fit))
        if p_with >= alpha:
            lost.append({"effect": name, "p_value": p_with, "p_value_without": p_without})
    return lost


def offset_groups(offsets: Mapping[str, Any]) -> list[tuple[str, str]]:
    """The level offsets :func:`level_offsets` named, as groups of :func:`with_offsets`.

    Every flight named, then every microphone named whose offset counts as a level offset (a microphone the
    model misses in another way, its position or height, gets none: a constant would not describe it).

    >>> offset_groups({"flights": {"f1": {"named": False}, "f2": {"named": True}},
    ...                "microphones": {"m2": {"named": True, "offset_db": 3.0, "std_db": 0.02},
    ...                                "m3": {"named": True, "offset_db": 0.1, "std_db": 0.02}}})
    [('flight', 'f2'), ('mic', 'm2')]
    """
    flights = [("flight", f) for f, e in (offsets.get("flights") or {}).items() if e.get("named")]
    mics = [("mic", m) for m, e in (offsets.get("microphones") or {}).items()
            if e.get("named") and e.get("offset_db") is not None and e.get("std_db") is not None
            and _is_offset(float(e["offset_db"]), float(e["std_db"]))]
    return flights + mics


def judged_with(fit: FitResult | None, groups: Sequence[tuple[str, str]], held: Sequence[str],
                not_carried: Sequence[dict[str, Any]] = ()) -> dict[str, Any]:
    """What the verdict says of the level offsets the candidates were fitted and judged with.

    Parameters
    ----------
    fit : FitResult or None
        The model the candidates' verdict ends with, carrying the offsets (:func:`with_offsets` of the card's
        ansatz, extended by the verdict's effects if any), fitted to all samples; None when ``groups`` is empty.
    groups : sequence of (str, str)
        The offsets' groups (:func:`offset_groups`) the candidates carried.
    held : sequence of str
        The offset parameters held at their values on all data in the cross-validation folds.
    not_carried : sequence of dict
        The offsets named but not carried: ``{"group", "id", "competes_with": [...]}`` (the effects
        :func:`competing_effects` found), or with ``"reason"`` instead.

    Returns
    -------
    dict
        ``{"level_offsets": [{"group", "id", "parameter", "offset_db", "std_db", "held_in_folds"}],
        "not_carried": [...], "sentence"}`` (offsets against the rows of no group: with two flights, the second
        against the first; the sentence None when no offset was named).
    """
    entries = []
    for key, value in groups:
        assert fit is not None
        k = offset_parameter(key, value)
        entries.append({"group": "microphone" if key == "mic" else key, "id": value, "parameter": k,
                        "offset_db": float(fit.params[k]), "std_db": float(fit.std_corrected[k]),
                        "held_in_folds": k in held})
    sentences = []
    if entries:
        parts = [f"{e['group']} '{e['id']}' ({e['offset_db']:+.2f} dB, +/- {e['std_db']:.2f} dB)" for e in entries]
        what = parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
        sentence = (f"the candidates were fitted and judged on held-out data with the level offset"
                    f"{'s' if len(entries) > 1 else ''} of {what} that the diagnosis names, one parameter each in "
                    "the baseline and in every candidate")
        held_out = [f"{e['group']} '{e['id']}'" for e in entries if e["held_in_folds"]]
        if held_out:
            one = len(held_out) == 1
            sentence += (f"; the offset{'' if one else 's'} of {', '.join(held_out)} {'is' if one else 'are'} held at "
                         f"{'its value' if one else 'their values'} on all data in the cross-validation folds, since a "
                         "fold that leaves out a flight (or a microphone heard in one fold only) cannot tell its offset")
        sentences.append(sentence)
    for n in not_carried:
        head = f"the level offset of {n['group']} '{n['id']}' is not carried into the candidates"
        lost = n.get("competes_with") or []
        if lost:
            effs = "; ".join(f"{c['effect']} is no longer significant (p {c['p_value']:.1e}, against "
                             f"{c['p_value_without']:.1e} without it)" for c in lost)
            sentences.append(f"{head}: with it, {effs}; the data cannot tell the offset from "
                             f"{'that effect' if len(lost) == 1 else 'those effects'}, so the candidates were judged "
                             "without it")
        else:
            sentences.append(f"{head}: {n.get('reason', 'no reason given')}")
    return {"level_offsets": entries, "not_carried": [dict(n) for n in not_carried],
            "sentence": "; ".join(sentences) if sentences else None}
