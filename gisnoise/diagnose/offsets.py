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
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.diagnose.candidates import CancelFn, _fit
from gisnoise.errors import Cancelled, GisnoiseError
from gisnoise.identify import FitResult
from gisnoise.identify.fit import SYSTEMATIC_MIN_DB, SYSTEMATIC_WINDOW_S, misfit_microphones, systematic_residuals
from gisnoise.measure import Samples
from gisnoise.model import Ansatz

__all__ = ["OFFSET_Z", "level_offsets", "with_offsets"]

OFFSET_Z = 3.0
"""Standard deviations a flight's or a microphone's level offset must exceed to be called one."""
_BOUND_DB = 30.0  # a level offset beyond this is no calibration error


def with_offsets(model: Ansatz, groups: Sequence[tuple[str, str]]) -> Ansatz:
    """``model``'s level at the observer (background included) plus a level offset for each group.

    A group ``(key, value)`` is the rows whose input ``key`` (``"flight"``, ``"mic"``) is ``value``;
    its parameter ``<key>_offset_<value>`` (dB) follows the model's own.  The offset is added to
    the total level, as a calibration error is: it raises the background a microphone hears as
    much as the UAV.  Level and Jacobian are ``model``'s own (one definition); the result has no
    background parameter of its own (the model's is inside the kernel).

    >>> from gisnoise.model import get_ansatz
    >>> m = with_offsets(get_ansatz("paper-offset"), [("flight", "f2")])
    >>> x = {"d": np.array([40.0, 40.0]), "phi": 0.0, "theta": -1.0, "p_el": 1.0, "flight": np.array(["f1", "f2"])}
    >>> p = [60.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 2.0]  # background p7 0 dB, far below the UAV
    >>> np.round(m.level(p, x), 2).tolist(), m.params[-1]
    ([60.0, 62.0], 'flight_offset_f2')
    """
    groups = list(groups)
    nb = model.n_params

    def indicator(x: Mapping[str, Any]) -> np.ndarray:
        return np.stack([np.asarray(x[k]).astype(str) == v for k, v in groups], axis=-1).astype(float)

    def kernel(p: np.ndarray, x: Mapping[str, Any], d_ref: float, want_jac: bool) -> tuple[np.ndarray, Any]:
        ind = indicator(x)
        if not want_jac:
            return model.level(p[:nb], x, d_ref=d_ref) + ind @ p[nb:], None
        total, jac = model.level_and_jacobian(p[:nb], x, d_ref=d_ref)
        n = np.broadcast_shapes(np.shape(total), ind.shape[:1])
        return (np.broadcast_to(total, n) + ind @ p[nb:],
                np.concatenate([np.broadcast_to(jac, n + (nb,)), ind], axis=-1))

    units = model.units + ("dB",) * len(groups) if len(model.units) == nb else ()
    return Ansatz(name=f"{model.name}+level_offsets", params=model.params + tuple(f"{k}_offset_{v}" for k, v in groups),
                  inputs=model.inputs, kernel=kernel, background=None,
                  description=f"{model.description or model.name}; + a level offset per flight or microphone",
                  units=units)


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
    groups = [("flight", f) for f in flights[1:]] + [("mic", m) for m in named]
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
            vec[i, idx[f"flight_offset_{f}"]] = 1.0
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
        k = f"mic_offset_{m}"
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
