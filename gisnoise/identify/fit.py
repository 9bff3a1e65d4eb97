"""Fits of measured samples and of one phase of a campaign, and the rows such a fit uses.

:func:`fit` fits an ansatz to a :class:`~gisnoise.measure.Samples` table and
:func:`fit_campaign` to one phase of a measurement campaign, both with the
estimator of :func:`gisnoise.identify.estimate.fit_arrays` (output-error maximum
likelihood, see there); :func:`usable_rows` says which rows a fit takes.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from gisnoise.errors import Cancelled, GisnoiseError, InputError, NotIdentifiableError
from gisnoise.identify.estimate import fit_arrays
from gisnoise.identify.result import FitResult
from gisnoise.measure import Samples, read_campaign, series_key
from gisnoise.model import PHASES, POWER_RANGE_DEX, Ansatz, check_testable, get_ansatz, get_effect

__all__ = ["fit", "fit_campaign", "usable_rows", "identifiable_form", "STEADY_POWER_DEX", "P7_MAX_STD_DB",
           "BACKGROUND_DOMINATED_DB", "background_dominated_rows", "systematic_residuals", "misfit_microphones",
           "misfit_warnings",
           "SYSTEMATIC_WINDOW_S", "SYSTEMATIC_MIN_DB", "SYSTEMATIC_RATIO"]


def fit(
    samples: Samples,
    ansatz: str | Ansatz = "paper-offset",
    *,
    reference_power_w: float,
    **options: Any,
) -> FitResult:
    """Output-error maximum-likelihood fit of an ansatz to measured samples.

    Parameters
    ----------
    samples : Samples
        Measured levels at emission time; rows with ``valid`` false are left out.
        Pass ``samples.usable(phase)`` to fit one phase.
    ansatz : str or Ansatz
        Registry name (``"paper-offset"``, ``"paper"``, extended ones) or the object.
    reference_power_w : float
        Electric power that nondimensionalises ``P_el``, W.
    **options
        The options of the solve, passed to :func:`~gisnoise.identify.estimate.fit_arrays`
        (documented there): ``p0``, ``bounds``, ``fixed``, ``per_mic_noise``,
        ``max_iter``, ``tol``, ``rcond``, ``progress``, ``cancel``, ``raise_on_failure``.
        The samples give the microphones (one noise variance each), the time series
        (one microphone, one flight: :func:`gisnoise.measure.series_key`) and their times.

    Returns
    -------
    FitResult

    Raises
    ------
    InputError
        Bad samples or arguments (the field is named).
    NotIdentifiableError
        The data cannot tell some parameters apart (they are named).
    FitError
        No convergence.
    Cancelled
        ``cancel()`` returned True.
    """
    if not isinstance(samples, Samples):
        raise InputError(f"samples must be a gisnoise.measure.samples.Samples, got {type(samples).__name__}",
                         field="samples")
    try:
        ref = float(reference_power_w)
    except (TypeError, ValueError):
        raise InputError(f"reference_power_w must be a number, got {reference_power_w!r}",
                         field="reference_power_w") from None
    if not (math.isfinite(ref) and ref > 0):
        raise InputError(f"reference_power_w must be a positive number of W, got {reference_power_w!r}",
                         field="reference_power_w")
    s = samples if bool(np.all(samples.valid)) else samples.select(samples.valid)
    if len(s) == 0:
        raise InputError("no valid samples to fit", field="samples")
    x = s.inputs(ref)
    x.setdefault("mic", s.mic)   # microphone ids: effects match per-microphone facts (height above ground)
    _check_effects(ansatz, x)
    return fit_arrays(s.level, x, ansatz, mic=s.mic, series=series_key(s.mic, s.flight), time=s.t_r,
                      reference_power_w=ref, samples=s, phase=None, **options)


def _check_effects(ansatz: str | Ansatz, x: Mapping[str, Any]) -> None:
    """Refuse, in one line, an extended ansatz whose effect the data cannot support (missing inputs)."""
    name = ansatz if isinstance(ansatz, str) else ansatz.name
    for eff_name in name.split("+")[1:]:
        try:
            eff = get_effect(eff_name)
        except GisnoiseError:
            continue   # the registry's own message follows from fit_arrays
        ok, why = check_testable(eff, x)
        if not ok:
            raise InputError(f"ansatz {name!r}: effect {eff_name!r} cannot be fitted to these data: {why}",
                             field="ansatz")


def fit_campaign(
    campaign: Any,
    phase: str,
    ansatz: str | Ansatz = "paper-offset",
    *,
    reference_power_w: float | None = None,
    include_low_snr: bool = True,
    read_kw: Mapping[str, Any] | None = None,
    **kw: Any,
) -> FitResult:
    """Read a campaign (folder or campaign object of :func:`gisnoise.measure.read_campaign`) and fit one phase.

    Rows masked ``low_snr`` are fitted too (unless ``include_low_snr=False``): the
    model has the background term (Eq. 8, 11), and dropping rows because their
    *measured* level is low truncates the noise distribution and biases the
    estimate (on a synthetic campaign with 7 % of rows below background + 3 dB,
    dropping them moved ``p7`` by about 20 standard deviations).  Every other mask
    (``event``, ``excluded``, ``outside_flight``, ...) is respected.

    Parameters
    ----------
    campaign : path or Campaign
        Measurement campaign (SPEC section 3).
    phase : str
        Flight phase whose usable samples are fitted.
    ansatz : str or Ansatz
        Ansatz to fit.
    reference_power_w : float, optional
        Defaults to the campaign vehicle's ``reference_power_w``.
    include_low_snr : bool
        Fit rows masked only as ``low_snr`` (see above).
    read_kw : mapping, optional
        Passed to :func:`gisnoise.measure.read_campaign` (``absorption``, ``exclusions``, ...).
    **kw
        Passed to :func:`fit` (``p0``, ``bounds``, ``fixed``, ``progress``, ``cancel``, ...).
    """
    if phase not in PHASES:
        raise InputError(f"phase must be one of {', '.join(PHASES)}, got {phase!r}", field="phase")
    source = None
    if isinstance(campaign, (str, os.PathLike)):
        source = os.fspath(campaign)
        rk = dict(read_kw or {})
        cancel = kw.get("cancel")
        if cancel is not None and "progress" not in rk:
            def _reading(done: float, total: float) -> None:
                if cancel():
                    raise Cancelled("fit cancelled while reading the campaign", field="cancel")

            rk["progress"] = _reading
        camp = read_campaign(campaign, **rk)
    else:
        camp = campaign
    all_samples = camp.samples()
    vehicle = _vehicle_facts(camp, all_samples)
    ref = reference_power_w if reference_power_w is not None else vehicle.get("reference_power_w")
    if ref is None:
        raise InputError("the campaign states no vehicle reference_power_w; pass reference_power_w",
                         field="reference_power_w")
    s = usable_rows(all_samples, phase, include_low_snr=include_low_snr)
    if len(s) == 0:
        have = sorted(set(np.unique(usable_rows(all_samples, None, include_low_snr=include_low_snr).phase).tolist()))
        raise InputError(f"no usable samples of phase {phase!r} in the campaign (phases with usable samples: "
                         f"{', '.join(have) or 'none'})", field="phase")
    if ref is not None and np.isfinite(float(ref)) and float(ref) > 0:   # effects the data cannot support, first
        _check_effects(ansatz, {**s.inputs(float(ref)), "mic": s.mic})
    fixed, held = identifiable_form(s, ansatz, kw.pop("fixed", None))
    model = get_ansatz(ansatz) if isinstance(ansatz, str) else ansatz
    bg = model.background
    try:
        res = fit(s, ansatz, reference_power_w=float(ref), fixed=fixed or None, **kw)
        weak_bg = bg is not None and bg not in fixed and (bg in res.at_bounds or res.std.get(bg, 0.0) > P7_MAX_STD_DB)
        why = (f"{bg} = {res.params.get(bg, float('nan')):.1f} +- {res.std.get(bg, 0.0):.2g} dB(A) from the data"
               + (" (on a bound)" if bg in res.at_bounds else "")) if bg is not None else ""
    except NotIdentifiableError as exc:
        if bg is None or bg in fixed or bg not in exc.parameters:
            raise
        weak_bg, why = True, f"{bg} not identifiable from the data"
    if weak_bg:   # too few background-dominated rows to fit p7: hold it at the campaign's background
        level_bg = _campaign_background(s)
        if level_bg is None:
            raise InputError(f"the data cannot fit the background {bg} (too few background-dominated rows) and the "
                             "campaign states none; give microphones[].background_db or --fix "
                             f"{bg}=LEVEL", field=str(bg))
        fixed[str(bg)] = level_bg
        n_bg = background_dominated_rows(s)
        rows = "" if n_bg is None else f", {n_bg} rows within {BACKGROUND_DOMINATED_DB:g} dB of their background"
        held[str(bg)] = (f"too few background-dominated rows to fit it ({why}{rows}); held at the campaign's "
                         f"background {level_bg:.1f} dB(A)")
        res = fit(s, ansatz, reference_power_w=float(ref), fixed=fixed, **kw)
    info: dict[str, Any] = {
        "data": {
            "campaign": source if source is not None else str(getattr(camp, "folder", getattr(camp, "path", ""))),
            "phase": phase,
            "flights": sorted(set(np.unique(s.flight).tolist())),
            "microphones": sorted(set(np.unique(s.mic).tolist())),
            "n_samples": int(len(s)),
            "low_snr_rows_fitted": int(np.sum(s.mask_reason == "low_snr")) if include_low_snr else 0,
        },
    }
    if vehicle.get("name"):
        info["vehicle"] = vehicle["name"]
    if held:
        info["held_parameters"] = held
    info["warnings"] = misfit_warnings(res)
    res.info.update(info)
    return res


SYSTEMATIC_WINDOW_S = 2.0
"""Reception time over which a microphone's residual is averaged to find its systematic part, s (16 blocks of
0.125 s: measurement noise averages down by 4, a geometry error changes slowly along the track)."""
SYSTEMATIC_MIN_DB = 0.5
"""Systematic residual rms (dB) below which a microphone is not named, whatever the others'."""
SYSTEMATIC_RATIO = 3.0
"""How many times the median of the other microphones' systematic residual one microphone's must exceed."""


def systematic_residuals(samples: Samples, residuals: Any,
                         window_s: float = SYSTEMATIC_WINDOW_S) -> dict[str, tuple[float, float]]:
    """Per microphone: noise std and the systematic part of it, dB.

    Within each series (microphone and flight) the residual is averaged over ``window_s``
    of reception time centred on each row (the rows the fit used).  The rms of that
    running mean, less the white noise it lets through (the variance of the residual
    about it over the count averaged), is what stays the same over seconds: a wrong
    position, height or a reflection seen by that microphone, not its signal-to-noise
    ratio, which only scales the white part.

    Returns
    -------
    dict
        ``mic -> (noise std, systematic rms)`` in dB.
    """
    r = np.asarray(residuals, dtype=float)
    out: dict[str, tuple[float, float]] = {}
    sid = series_key(samples.mic, samples.flight)
    for mic in dict.fromkeys(samples.mic.tolist()):
        sm_sq, white, n_all = 0.0, 0.0, 0
        for key in np.unique(sid[samples.mic == mic]):
            rows = np.flatnonzero(sid == key)
            rows = rows[np.argsort(samples.t_r[rows], kind="stable")]
            t, x = np.asarray(samples.t_r[rows], float), r[rows]
            c = np.concatenate([[0.0], np.cumsum(x)])
            lo = np.searchsorted(t, t - window_s / 2.0, side="left")
            hi = np.searchsorted(t, t + window_s / 2.0, side="right")
            k = (hi - lo).astype(float)
            mean = (c[hi] - c[lo]) / k
            fast = float(np.mean((x - mean) ** 2)) if x.size > 1 else 0.0
            sm_sq += float(np.sum(mean ** 2))
            white += float(np.sum(fast / k))
            n_all += x.size
        if n_all:
            sys_db = math.sqrt(max(sm_sq - white, 0.0) / n_all)
            out[str(mic)] = (float(np.sqrt(np.mean(r[samples.mic == mic] ** 2))), sys_db)
    return out


def misfit_microphones(parts: Mapping[str, tuple[float, float]]) -> dict[str, float]:
    """The microphones the model misses alone, each with the median systematic residual of the others, dB.

    ``parts`` is :func:`systematic_residuals`' ``mic -> (noise std, systematic rms)``.  A microphone is
    named when its systematic part exceeds :data:`SYSTEMATIC_MIN_DB` and :data:`SYSTEMATIC_RATIO` times
    the median of the other microphones' (the one rule of ``gisnoise fit``'s warning and of
    ``gisnoise diagnose``).

    >>> misfit_microphones({"a": (1.1, 0.2), "b": (3.1, 2.9), "c": (1.0, 0.2)})
    {'b': 0.2}
    """
    if len(parts) < 2:
        return {}
    out = {}
    for mic, (_std, sys_db) in parts.items():
        ref = float(np.median([v[1] for m, v in parts.items() if m != mic]))
        if sys_db > SYSTEMATIC_MIN_DB and sys_db > SYSTEMATIC_RATIO * ref:
            out[mic] = ref
    return out


def misfit_warnings(res: FitResult) -> list[str]:
    """One line per microphone the fit misses alone (``gisnoise fit`` prints them, the result's ``info['warnings']``).

    A microphone is named when its systematic residual (:func:`systematic_residuals`) exceeds
    :data:`SYSTEMATIC_MIN_DB` and :data:`SYSTEMATIC_RATIO` times the median of the other
    microphones'.  Its noise std alone is no test: microphones of unequal signal-to-noise
    ratio differ in it by a factor of two in clean campaigns, and over thousands of
    autocorrelated residuals an F-test of the variance ratio is significant at any ratio;
    measurement noise averages out over :data:`SYSTEMATIC_WINDOW_S`, what the model misses
    at one microphone only (its position, height, a reflection) does not.
    """
    parts = systematic_residuals(res.samples, res.residuals)
    out = []
    for mic, ref in misfit_microphones(parts).items():
        std, sys_db = parts[mic]
        stds = [res.noise_std.get(m, v[0]) for m, v in parts.items() if m != mic]
        span = f"{min(stds):.2f}" if len(stds) == 1 else f"{min(stds):.2f}-{max(stds):.2f}"
        out.append(f"microphone '{mic}': noise std {res.noise_std.get(mic, std):.2f} dB against "
                   f"{span} for the other{'s' if len(stds) > 1 else ''}, {sys_db:.2f} dB of it systematic "
                   f"(steady over {SYSTEMATIC_WINDOW_S:g} s) against a median {ref:.2f} for the others: the "
                   "model misses this microphone alone; check its position, height and calibration "
                   "(gisnoise diagnose searches its position and measures its level offset)")
    return out


STEADY_POWER_DEX = POWER_RANGE_DEX
"""Spread of log10(P_el) over the fitted rows below which the power term p1 cannot be identified
(a power varying by less than about 5 %); maps accept a card without power term within as much
of its power range (:mod:`gisnoise.model.power_range`)."""
BACKGROUND_DOMINATED_DB = 3.0
"""A row is background-dominated when its level lies within this many dB of its microphone's background
(the background holds at least half the sound energy)."""
P7_MAX_STD_DB = 1.0
"""Standard deviation of a fitted background p7 above which the data do not support it, dB."""


def background_dominated_rows(samples: Samples) -> int | None:
    """Rows whose level lies within :data:`BACKGROUND_DOMINATED_DB` of their background (None: no background known)."""
    if samples.background_db is None:
        return None
    b = np.asarray(samples.background_db, dtype=float)
    ok = np.isfinite(b)
    if not ok.any():
        return None
    return int(np.sum(ok & (np.asarray(samples.level, dtype=float) - b <= BACKGROUND_DOMINATED_DB)))


def _campaign_background(samples: Samples) -> float | None:
    """The campaign's background level (stated per microphone, else measured from the recordings), dB(A)."""
    if samples.background_db is None:
        return None
    b = np.asarray(samples.background_db, dtype=float)
    b = b[np.isfinite(b)]
    return float(np.median(b)) if b.size else None


def identifiable_form(samples: Samples, ansatz: str | Ansatz,
                      fixed: Mapping[str, float] | None) -> tuple[dict[str, float], dict[str, str]]:
    """The parameters the data cannot support, held at values the data state, and why.

    * Steady power (log10 P_el spreads less than :data:`STEADY_POWER_DEX`): with a level offset
      ``p0`` in the ansatz, ``p1 log10(P_el)`` is a constant the offset absorbs, so ``p1`` is held
      at 0: the card is a level offset without power term, valid at the power flown (the card's
      ``statistics.power_range_w``).  Checked again after the user's ``fixed``: with ``p0`` fixed
      and ``p1`` free, or with an ansatz without ``p0`` (``paper``: ``p1`` would scale the whole
      level), ``p1`` is not identifiable as a power slope and
      :class:`~gisnoise.errors.NotIdentifiableError` names it and the way out.
    The background ``p7`` is judged by :func:`fit_campaign` after a first fit: when it ends on
    a bound, is not identifiable or has a standard deviation above :data:`P7_MAX_STD_DB` (then a
    stated or measured background knows it better), the data hold too few background-dominated
    rows, and it is held at the campaign's background (stated, or measured from the
    recordings); the card's reason gives the fitted value and the count of rows within
    :data:`BACKGROUND_DOMINATED_DB` of their background.

    Parameters the user fixed are left alone.  Returns the fixed values and, per held
    parameter, the reason (the card's provenance states it).
    """
    model = get_ansatz(ansatz) if isinstance(ansatz, str) else ansatz
    out = dict(fixed or {})
    held: dict[str, str] = {}
    pw = np.asarray(samples.power_w, dtype=float)
    pw = pw[np.isfinite(pw) & (pw > 0)]
    steady = bool(pw.size) and float(np.log10(pw.max() / pw.min())) < STEADY_POWER_DEX
    if not steady or "p1" not in model.params or "p1" in out:
        return out, held
    what = f"steady power ({pw.min():.4g}-{pw.max():.4g} W): the data hold no power information"
    if "p0" not in model.params:
        base = model.name.split("+", 1)[0]
        offset = model.name.replace(base, f"{base}-offset", 1) if base == "paper" else "paper-offset"
        raise NotIdentifiableError(f"{what}, and ansatz {model.name!r} makes p1 log10(P_el) its whole level, so p1 "
                                   f"would be a level scale, not a power slope; use --ansatz {offset} (a level offset "
                                   f"valid at the power flown) or fix p1", field="p1", parameters=("p1",))
    if "p0" in out:
        raise NotIdentifiableError(f"{what}: the level p0 + p1 log10(P_el) is one number; with p0 fixed, p1 would "
                                   f"only absorb the offset, not a power slope; fix p1 too, or leave p0 free (p1 is "
                                   f"then held at 0)", field="p1", parameters=("p1", "p0"))
    out["p1"] = 0.0
    held["p1"] = (f"steady power ({pw.min():.4g}-{pw.max():.4g} W): no power information; held at 0, the card "
                  f"is a level offset p0 valid at the power flown")
    return out, held


def usable_rows(samples: Samples, phase: str | None, *, include_low_snr: bool = True) -> Samples:
    """The rows a fit uses: valid ones (and, by default, those masked only ``low_snr``) of ``phase``."""
    if not include_low_snr:
        return samples.usable(phase)
    m = samples.valid | (samples.mask_reason == "low_snr")
    if phase is not None:
        m = m & (samples.phase == phase)
    return samples.select(m).with_(valid=np.ones(int(m.sum()), dtype=bool))


def _vehicle_facts(camp: Any, samples: Samples) -> dict[str, Any]:
    v = getattr(camp, "vehicle", None)
    out: dict[str, Any] = {}
    if isinstance(v, Mapping):
        out.update(v)
    elif v is not None:
        for k in ("name", "reference_power_w"):
            if hasattr(v, k):
                out[k] = getattr(v, k)
    meta = samples.meta or {}
    if "reference_power_w" not in out and "reference_power_w" in meta:
        out["reference_power_w"] = meta["reference_power_w"]
    if "name" not in out and isinstance(meta.get("vehicle"), Mapping):
        out["name"] = meta["vehicle"].get("name")
    return out
