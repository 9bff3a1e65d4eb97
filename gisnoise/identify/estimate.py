"""The output-error maximum-likelihood estimate of an ansatz from arrays of levels and model inputs.

The output-error method (paper section 2.2) fits the model response to the
measured A-weighted levels.  The estimator is maximum likelihood with an
unknown diagonal measurement-noise covariance ``R``, one variance per
microphone: the relaxation strategy alternates ``R`` from the residuals with a
Gauss-Newton / Levenberg-Marquardt solve for the parameters using the ansatz's
analytic Jacobian (:meth:`gisnoise.model.Ansatz.level_and_jacobian`: the one
model definition).  The negative log-likelihood minimised is

    J(p, R) = 1/2 sum_i [ r_i^2 / sigma_m(i)^2 + ln(2 pi sigma_m(i)^2) ],
    r_i = L_measured,i - L_model,i(p),

whose minimum over ``R`` is ``sigma_m^2 = mean(r_i^2)`` over microphone ``m``.

Uncertainty: the Cramer-Rao bound ``(J^T R^-1 J)^-1`` assumes white residuals;
flight-test residuals are coloured (model error lasting seconds), so the
covariance is also given corrected for the residual autocorrelation with the
method of Morelli & Klein (1997), see :func:`gisnoise.identify._oem.hac_covariance`.

Where the solve ends, the weighted Jacobian with unit-norm columns is checked by
its singular values: when the smallest relative to the largest falls below
``rcond`` the fit is refused with :class:`NotIdentifiableError` naming the
parameters of the near-null direction (data at one distance only cannot tell
the level offset from the spreading exponent, data at one power cannot tell
the offset from the power slope, ...).

Directivity canonical form: ``(p2, p3)`` and ``(-p2, p3 + pi)`` give the same
model (likewise ``(p4, p5)``); results are returned with ``p3, p5`` in
``(-pi/2, pi/2]``, the form of the paper's Table 1.

Examples
--------
A noise-free check on a handful of synthetic samples:

>>> import numpy as np
>>> from gisnoise.model import get_ansatz
>>> rng = np.random.default_rng(1)
>>> n = 400
>>> x = {"d": rng.uniform(20, 400, n), "phi": rng.uniform(-np.pi, np.pi, n),
...      "theta": rng.uniform(-1.5, 0.2, n), "p_el": rng.uniform(0.8, 1.5, n)}
>>> truth = np.array([64.0, 20.0, 0.1, -0.28, -0.2, 1.05, 1.0, 40.0])
>>> level = get_ansatz("paper-offset").level(truth, x) + rng.normal(0.0, 0.5, n)
>>> res = fit_arrays(level, x, mic=np.where(np.arange(n) % 2, "m1", "m2"))
>>> bool(res.success), bool(np.all(np.abs(res.p - truth) < 4 * res.std_array))
(True, True)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, overload

import numpy as np

from gisnoise.errors import FitError, InputError, NotIdentifiableError
from gisnoise.identify import _oem
from gisnoise.identify.result import FitResult
from gisnoise.measure import Samples
from gisnoise.model import Ansatz, ModelCard, get_ansatz

__all__ = ["fit_arrays", "start_values", "DEFAULT_BOUNDS", "DEFAULT_RCOND", "MIN_DIRECTIVITY_FACTOR", "ProgressFn",
           "CancelFn"]

MIN_DIRECTIVITY_FACTOR = 0.05
"""Smallest value Eq. 9's directivity factors may take anywhere on the emission sphere."""

DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {
    "p2": (-(1.0 - MIN_DIRECTIVITY_FACTOR) / math.pi, (1.0 - MIN_DIRECTIVITY_FACTOR) / math.pi),
    "p4": (-(1.0 - MIN_DIRECTIVITY_FACTOR), 1.0 - MIN_DIRECTIVITY_FACTOR),
    "p6": (0.5, 2.0),
    "p7": (0.0, 150.0),
}
"""Bounds applied unless overridden (each a physical limit): the spreading exponent ``p6`` between
cylindrical (0.5) and twice spherical (2) spreading, the background ``p7`` a plausible A-weighted level,
and the directivity amplitudes that keep Eq. 9's factors positive over the whole sphere, at least
:data:`MIN_DIRECTIVITY_FACTOR`: ``1 + p2 sin(phi - p3)(theta + pi/2)`` reaches ``1 - |p2| pi`` (the
product ``sin(.)(theta + pi/2)`` spans ``[-pi, pi]``), so ``|p2| <= 0.95 / pi``;
``1 + p4 sin(theta - p5)`` reaches ``1 - |p4|`` for some ``p5``, so ``|p4| <= 0.95``.  The bounds are
symmetric, so the sign convention of ``p3``, ``p5`` (:func:`_canonical`) still applies.  A card that
still leaves the plausible level range is refused by the plausibility guard
(:mod:`gisnoise.model.plausibility`) before it is written."""

DEFAULT_RCOND = 1e-3
"""Smallest relative singular value of the column-scaled weighted Jacobian accepted as identifiable."""

ProgressFn = Callable[[int, float], None]
CancelFn = Callable[[], bool]

_DIRECTIVITY_PAIRS = (("p2", "p3"), ("p4", "p5"))


# --------------------------------------------------------------------------- inputs


def _as_ansatz(ansatz: str | Ansatz) -> Ansatz:
    if isinstance(ansatz, Ansatz):
        return ansatz
    if not isinstance(ansatz, str):
        raise InputError(f"ansatz must be a registry name or an Ansatz, got {type(ansatz).__name__}", field="ansatz")
    return get_ansatz(ansatz)


def _check_inputs(level: np.ndarray, x: Mapping[str, Any], model: Ansatz) -> None:
    bad = ~np.isfinite(level)
    if bad.any():
        raise InputError(f"level: {int(bad.sum())} non-finite value(s), first at row {int(np.argmax(bad))}",
                         field="level")
    n = len(level)
    for name in model.inputs:
        v = np.asarray(x[name], dtype=float)
        if v.ndim and len(v) != n:
            raise InputError(f"input '{name}' has {len(v)} rows, expected {n}", field=name)
        bad = ~np.isfinite(v)
        if bad.any():
            raise InputError(f"input '{name}': {int(bad.sum())} non-finite value(s)", field=name)
    for name, what in (("d", "distance"), ("p_el", "power")):
        if name in x:
            v = np.asarray(x[name], dtype=float)
            if np.any(v <= 0):
                raise InputError(f"input '{name}' ({what}) must be > 0, got {float(v.min()):g}", field=name)


def _resolve_vector(model: Ansatz, value: Any, what: str) -> dict[str, float]:
    """A (partial) name -> value mapping from a card, mapping or full vector."""
    if value is None:
        return {}
    if isinstance(value, ModelCard):
        if value.ansatz != model.name:
            common = {k: float(v) for k, v in value.parameters.items() if k in model.params}
            return common
        return {k: float(v) for k, v in value.parameters.items()}
    if isinstance(value, Mapping):
        unknown = [k for k in value if k not in model.params]
        if unknown:
            raise InputError(f"{what}: unknown parameter(s) {', '.join(map(str, unknown))} for ansatz "
                             f"{model.name!r} ({', '.join(model.params)})", field=what)
        out = {}
        for k, v in value.items():
            fv = float(v)
            if not math.isfinite(fv):
                raise InputError(f"{what}: parameter {k} must be finite, got {v!r}", field=f"{what}.{k}")
            out[k] = fv
        return out
    arr = np.asarray(value, dtype=float)
    if arr.shape != (model.n_params,):
        raise InputError(f"{what}: expected {model.n_params} values {model.params}, got shape {arr.shape}",
                         field=what)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{what}: values must be finite", field=what)
    return dict(zip(model.params, arr.tolist(), strict=True))


def _resolve_bounds(model: Ansatz, bounds: Any, *, defaults: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bound per parameter: ``bounds`` merged over :data:`DEFAULT_BOUNDS` (without them when
    ``defaults`` is false)."""
    lo = np.full(model.n_params, -np.inf)
    hi = np.full(model.n_params, np.inf)
    merged: dict[str, tuple[float, float]] = \
        {k: v for k, v in DEFAULT_BOUNDS.items() if k in model.params} if defaults else {}
    if bounds is not None:
        if isinstance(bounds, Mapping):
            unknown = [k for k in bounds if k not in model.params]
            if unknown:
                raise InputError(f"bounds: unknown parameter(s) {', '.join(map(str, unknown))}", field="bounds")
            for k, v in bounds.items():
                if v is None:
                    merged.pop(k, None)
                    continue
                try:
                    a, b = (float(u) for u in v)
                except (TypeError, ValueError):
                    raise InputError(f"bounds: {k} must be a (lower, upper) pair, got {v!r}",
                                     field=f"bounds.{k}") from None
                merged[k] = (a, b)
        else:
            try:
                lower, upper = bounds
                lower = np.broadcast_to(np.asarray(lower, dtype=float), (model.n_params,))
                upper = np.broadcast_to(np.asarray(upper, dtype=float), (model.n_params,))
            except (TypeError, ValueError):
                raise InputError("bounds must be a mapping name -> (lower, upper) or a pair of arrays",
                                 field="bounds") from None
            merged = {k: (float(lower[i]), float(upper[i])) for i, k in enumerate(model.params)}
    for k, (a, b) in merged.items():
        if math.isnan(a) or math.isnan(b) or a >= b:
            raise InputError(f"bounds: {k} needs lower < upper, got ({a:g}, {b:g})", field=f"bounds.{k}")
        i = model.params.index(k)
        lo[i], hi[i] = a, b
    return lo, hi


# --------------------------------------------------------------------------- start values


@overload
def _canonical(names: Sequence[str], p: np.ndarray, cov: None = None,
               skip: Sequence[str] = ()) -> tuple[np.ndarray, None]: ...


@overload
def _canonical(names: Sequence[str], p: np.ndarray, cov: np.ndarray,
               skip: Sequence[str] = ()) -> tuple[np.ndarray, np.ndarray]: ...


def _canonical(names: Sequence[str], p: np.ndarray, cov: np.ndarray | None = None,
               skip: Sequence[str] = ()) -> tuple[np.ndarray, np.ndarray | None]:
    """Put ``p3``, ``p5`` into (-pi/2, pi/2] flipping the sign of ``p2``, ``p4`` (same model)."""
    p = p.copy()
    cov = None if cov is None else cov.copy()
    for amp, ph in _DIRECTIVITY_PAIRS:
        if amp not in names or ph not in names or amp in skip or ph in skip:
            continue
        ia, ip = names.index(amp), names.index(ph)
        a = math.remainder(p[ip], 2 * math.pi)  # (-pi, pi]
        flip = a > math.pi / 2 or a <= -math.pi / 2
        if flip:
            a = a - math.pi if a > 0 else a + math.pi
            p[ia] = -p[ia]
            if cov is not None:
                cov[ia, :] *= -1.0
                cov[:, ia] *= -1.0
        p[ip] = a
    return p, cov


def start_values(level: np.ndarray, x: Mapping[str, Any], model: Ansatz,
                 fixed: Mapping[str, float] | None = None) -> dict[str, float]:
    """Start values from the data for the paper parameters of ``model``.

    ``p7`` (background) is the 5th percentile of the levels; ``p0``, ``p1``,
    ``p6`` come from linear least squares of ``L = p0 + p1 log10(P_el) + p6 l_s``
    together with the linearised directivity terms (amplitude-phase form of
    ``p2 sin(phi - p3)(theta + pi/2)`` and ``p4 sin(theta - p5)``), on the samples
    at least 10 dB above that background.  Parameters the ansatz adds beyond
    ``p0..p7`` start at 0.  Fixed parameters keep their values.

    Returns
    -------
    dict
        Parameter name -> start value.
    """
    fixed = dict(fixed or {})
    names = model.params
    out = {k: 0.0 for k in names}
    out.update({"p2": 0.05, "p3": 0.0, "p4": 0.05, "p5": 0.0, "p6": 1.0})
    out = {k: v for k, v in out.items() if k in names}
    y = np.asarray(level, dtype=float)
    n = len(y)
    bg = float(np.percentile(y, 5.0))
    if "p7" in names:
        out["p7"] = bg
    p7 = fixed.get("p7", bg)
    sel = y > p7 + 10.0
    if sel.sum() < max(30, 4 * len(names)):
        sel = y > np.median(y)
    if sel.sum() < 8:
        sel = np.ones(n, dtype=bool)
    bcast = lambda v: np.broadcast_to(np.asarray(v, dtype=float), (n,))[sel]  # noqa: E731
    d = bcast(x["d"])
    lg = np.log10(bcast(x["p_el"]))
    phi, theta = bcast(x["phi"]), bcast(x["theta"])
    ls = -20.0 * np.log10(d / 40.0)
    ys = y[sel].copy()
    base = {"p0": np.ones_like(ys), "p1": lg, "p6": ls}
    cols, keys = [], []
    for k, c in base.items():
        if k not in names:
            continue
        if k in fixed:
            ys -= fixed[k] * c
        else:
            cols.append(c)
            keys.append(k)
    if not cols:
        out.update(fixed)
        return out
    a = np.column_stack(cols)
    coef = np.linalg.lstsq(a, ys, rcond=None)[0]
    g0 = np.zeros_like(ys)
    for k, c in zip(keys, coef, strict=True):
        out[k] = float(c)
    g0 = out.get("p0", fixed.get("p0", 0.0)) + out.get("p1", fixed.get("p1", 0.0)) * lg
    directivity = [k for k in ("p2", "p3", "p4", "p5") if k in names]
    if len(directivity) == 4 and not any(k in fixed for k in directivity) and np.all(np.abs(g0) > 1e-9):
        th = theta + np.pi / 2
        dcols = [g0 * th * np.sin(phi), g0 * th * np.cos(phi), g0 * np.sin(theta), g0 * np.cos(theta)]
        a2 = np.column_stack(cols + dcols)
        coef2 = np.linalg.lstsq(a2, ys, rcond=None)[0]
        c1, c2, c3, c4 = coef2[len(cols):]
        gain = {k: float(c) for k, c in zip(keys, coef2[: len(cols)], strict=True)}
        # l_dt ~ g (1 + p2 th sin(phi - p3) + p4 sin(theta - p5)); cos-theta absorbs part of the offset
        amp2, amp4 = math.hypot(c1, c2), math.hypot(c3, c4)
        if amp2 > 1e-6 and amp4 > 1e-6 and all(math.isfinite(v) for v in gain.values()):
            out.update(gain)
            out["p2"], out["p3"] = amp2, math.atan2(-c2, c1)
            out["p4"], out["p5"] = amp4, math.atan2(-c4, c3)
    out.update(fixed)
    return out


# --------------------------------------------------------------------------- fit


def _identifiability(jac_w: np.ndarray, names: Sequence[str], rcond: float, where: str) -> float:
    s, vt, ratio = _oem.null_directions(jac_w, rcond)
    if ratio >= rcond:
        return ratio
    bad = np.nonzero(s < rcond)[0]
    parts = []
    involved: list[str] = []
    for j in bad:
        v = vt[j]
        big = np.argsort(-np.abs(v))
        comp = [i for i in big if abs(v[i]) >= 0.2]
        involved += [names[i] for i in comp if names[i] not in involved]
        parts.append(" ".join(f"{v[i]:+.2f} {names[i]}" for i in comp))
    what = (f"parameter {involved[0]} cannot be determined from" if len(involved) == 1 else
            f"parameters {', '.join(involved)} cannot be told apart by")
    msg = (f"{what} these data ({where}: relative singular "
           f"value {ratio:.1e} < rcond {rcond:g}; near-null direction(s) of the scaled Jacobian: "
           f"{'; '.join(parts)}); add data that vary what they depend on (distances, powers, emission angles) "
           f"or fix some of them")
    raise NotIdentifiableError(msg, field=involved[0] if involved else "parameters", parameters=tuple(involved))


def fit_arrays(
    level: Any,
    x: Mapping[str, Any],
    ansatz: str | Ansatz = "paper-offset",
    *,
    mic: Any = None,
    series: Any = None,
    time: Any = None,
    p0: Any = None,
    bounds: Any = None,
    fixed: Mapping[str, float] | None = None,
    per_mic_noise: bool = True,
    max_iter: int = 100,
    tol: float = 1e-10,
    rcond: float = DEFAULT_RCOND,
    progress: ProgressFn | None = None,
    cancel: CancelFn | None = None,
    raise_on_failure: bool = True,
    reference_power_w: float = 1.0,
    samples: Samples | None = None,
    phase: str | None = None,
) -> FitResult:
    """Fit an ansatz to levels and model inputs given as arrays.

    The estimator behind :func:`gisnoise.identify.fit.fit` (samples) and
    :func:`gisnoise.identify.fit.fit_campaign` (a campaign's phase).

    Parameters
    ----------
    level : array_like, shape (n,)
        Measured levels, dB.
    x : mapping
        Model inputs (``d`` m, ``phi``, ``theta`` rad, ``p_el``, extras), arrays of length n.
    ansatz : str or Ansatz
        Registry name (``"paper-offset"``, ``"paper"``, extended ones) or the object.
    mic : array_like of str, optional
        Microphone of each sample (noise-variance groups); one group when omitted.
    series : array_like, optional
        Label of the contiguous time series each sample belongs to (e.g. mic + flight)
        for the autocorrelation correction; defaults to ``mic``.
    time : array_like, optional
        Time of each sample, s, ordering samples inside a series; row order when omitted.
    p0 : array_like, mapping or ModelCard, optional
        Start values (a mapping may be partial; a card of another ansatz gives its
        common parameters).  Default: from the data, see :func:`start_values`.
    bounds : mapping name -> (lower, upper) or (lower array, upper array), optional
        Parameter bounds, merged over :data:`DEFAULT_BOUNDS` (``None`` for a name drops its default).
    fixed : mapping name -> value, optional
        Parameters held at given values.
    per_mic_noise : bool
        One noise variance per microphone (True) or one for all.
    max_iter : int
        Maximum number of Gauss-Newton iterations over all relaxation cycles.
    tol : float
        Relative convergence tolerance on the cost (per-sample negative
        log-likelihood change for the noise variances).
    rcond : float
        Identifiability threshold, see the module docstring.
    progress : callable, optional
        ``progress(iteration, cost)`` after each iteration (cost: negative log-likelihood).
    cancel : callable, optional
        Polled every iteration; returning True raises :class:`gisnoise.errors.Cancelled`.
    raise_on_failure : bool
        Raise :class:`FitError` (with the result as ``.result``) when the solve does
        not converge; with False the unsuccessful result is returned.
    reference_power_w : float
        Electric power that nondimensionalised ``P_el``, W (recorded in the result).
    samples : Samples, optional
        The rows the arrays come from (kept in the result for reports).
    phase : str, optional
        Phase recorded in the result; default the samples' phase when they share one.

    Returns
    -------
    FitResult

    Raises
    ------
    InputError
        Bad arrays or arguments (the field is named).
    NotIdentifiableError
        The data cannot tell some parameters apart (they are named).
    FitError
        No convergence.
    Cancelled
        ``cancel()`` returned True.
    """
    model = _as_ansatz(ansatz)
    y = np.asarray(level, dtype=float)
    if y.ndim != 1 or len(y) == 0:
        raise InputError(f"level must be a non-empty 1-d array, got shape {y.shape}", field="level")
    _check_inputs(y, x, model)
    n = len(y)
    if not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise InputError(f"max_iter must be a positive integer, got {max_iter!r}", field="max_iter")
    if not (isinstance(tol, (int, float)) and 0 < tol < 1):
        raise InputError(f"tol must be in (0, 1), got {tol!r}", field="tol")
    mic_arr = np.full(n, "all") if mic is None else np.asarray(mic).astype(str)
    if len(mic_arr) != n:
        raise InputError(f"mic has {len(mic_arr)} rows, expected {n}", field="mic")
    mic_names, groups = np.unique(mic_arr, return_inverse=True)
    groups = groups.ravel()
    noise_groups = groups if per_mic_noise else np.zeros(n, dtype=int)
    n_noise = len(mic_names) if per_mic_noise else 1
    counts = np.bincount(noise_groups, minlength=n_noise)
    if per_mic_noise and counts.min() < 2:
        m = mic_names[int(np.argmin(counts))]
        raise InputError(f"microphone {m!r} has {int(counts.min())} usable sample(s); its noise variance needs at "
                         f"least 2 (drop it or use per_mic_noise=False)", field="mic")

    names = list(model.params)
    fixed_d = _resolve_vector(model, fixed, "fixed")
    free = np.array([k not in fixed_d for k in names])
    k_free = int(free.sum())
    if k_free == 0:
        raise InputError("all parameters are fixed; nothing to fit", field="fixed")
    if n <= k_free + n_noise:
        raise NotIdentifiableError(f"{n} samples cannot determine {k_free} parameters and {n_noise} noise "
                                   f"variance(s)", field="samples")
    lo, hi = _resolve_bounds(model, bounds)

    start = start_values(y, x, model, fixed_d)
    start.update(_resolve_vector(model, p0, "p0"))
    start.update(fixed_d)
    p_start = np.array([start[k] for k in names], dtype=float)
    # keep the user's sign convention when they fix or bound a directivity parameter (the default bounds of
    # p2, p4 are symmetric: they hold whatever the sign convention)
    user_lo, user_hi = _resolve_bounds(model, bounds, defaults=False)
    constrained = any(k in fixed_d or np.isfinite(user_lo[names.index(k)]) or np.isfinite(user_hi[names.index(k)])
                      for k in ("p2", "p3", "p4", "p5") if k in names)
    skip = ("p2", "p3", "p4", "p5") if constrained else ()
    p_start, _ = _canonical(names, p_start, skip=skip)
    p_start = np.where(free, np.clip(p_start, lo, hi), p_start)

    def full(q: np.ndarray) -> np.ndarray:
        p = p_start.copy()
        p[free] = q
        return p

    def fun(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(all="ignore"):
            lvl, jac = model.level_and_jacobian(full(q), x)
        lvl = np.broadcast_to(lvl, (n,))
        return lvl - y, np.broadcast_to(jac, (n, len(names)))[:, free]

    # identifiability is judged where the fit ends: at the start a parameter may be idle only
    # because of the start values (p3 when p2 starts at 0), which the solve repairs
    q0 = p_start[free]
    r0, j0 = fun(q0)
    if not (np.all(np.isfinite(r0)) and np.all(np.isfinite(j0))):
        raise FitError("the model is not finite at the start values; give p0", field="p0")
    var0 = _oem.group_variances(r0, noise_groups, n_noise)
    free_names = [k for k in names if k not in fixed_d]

    res = _oem.relaxation(fun, q0, noise_groups, n_noise, lower=lo[free], upper=hi[free], max_iter=int(max_iter),
                          tol=float(tol), progress=progress, cancel=cancel)
    p_hat = full(res.q)
    var = res.variances if res.variances is not None else var0
    w = 1.0 / var[noise_groups]
    jw = res.jac * np.sqrt(w)[:, None]
    if res.converged:
        ratio = _identifiability(jw, free_names, rcond, "at the optimum")
    else:  # an ill-posed problem is the likelier reason; say so rather than only "no convergence"
        try:
            ratio = _identifiability(jw, free_names, rcond, f"where the fit stopped ({res.message})")
        except NotIdentifiableError:
            if raise_on_failure:
                raise
            ratio = float("nan")

    kf = len(free_names)
    cov = np.zeros((len(names), len(names)))
    cov_c = np.zeros_like(cov)
    lag = 0
    if res.converged:
        m = res.jac.T @ (res.jac * w[:, None])
        cov_free = np.linalg.inv(m)
        cov_free = 0.5 * (cov_free + cov_free.T)
        ser = mic_arr if series is None else np.asarray(series).astype(str)
        tt = np.arange(n, dtype=float) if time is None else np.asarray(time, dtype=float)
        order = np.lexsort((tt, ser))
        ser_sorted = ser[order]
        cuts = np.nonzero(ser_sorted[1:] != ser_sorted[:-1])[0] + 1
        chunks = np.split(order, cuts)
        cov_c_free, lag = _oem.hac_covariance(res.jac, res.r, w, chunks)
        ix = np.ix_(free, free)
        cov[ix] = cov_free
        cov_c[ix] = cov_c_free
    _, cov_c = _canonical(names, p_hat, cov_c, skip=skip)
    p_hat, cov = _canonical(names, p_hat, cov, skip=skip)

    at_bounds = tuple(k for i, k in enumerate(names)
                      if free[i] and (p_hat[i] <= lo[i] or p_hat[i] >= hi[i]))
    message = res.message
    if at_bounds:
        message += f"; parameter(s) {', '.join(at_bounds)} on a bound (their standard deviations are not meaningful)"
    r_meas = -res.r  # measured - model
    sig = np.sqrt(var)
    noise_std = {str(mn): float(sig[i if per_mic_noise else 0]) for i, mn in enumerate(mic_names)}
    nll = float(res.nll if res.nll is not None else 0.0)
    k_total = kf + n_noise
    ph = phase
    if ph is None and samples is not None and len(samples):
        u = np.unique(samples.phase)
        ph = str(u[0]) if len(u) == 1 else None
    result = FitResult(
        ansatz=model.name, param_names=tuple(names), p=p_hat, cov=cov, cov_corrected=cov_c, cost=nll,
        noise_std=noise_std, residuals=r_meas, fitted=y - r_meas, measured=y, n=n, n_free=kf,
        aic=2.0 * nll + 2.0 * k_total, bic=2.0 * nll + k_total * math.log(n), iterations=res.iterations,
        nfev=res.nfev, cycles=res.cycles, success=bool(res.converged), message=message, autocorr_lag=int(lag),
        rcond=ratio, at_bounds=at_bounds, fixed=dict(fixed_d), start=p_start, reference_power_w=float(reference_power_w),
        phase=ph, samples=samples if samples is not None else _empty_samples(), info={},
    )
    if not result.success and raise_on_failure:
        err = FitError(f"fit did not converge: {message}", field="fit")
        err.result = result  # type: ignore[attr-defined]
        raise err
    return result


def _empty_samples() -> Samples:
    e = np.array([])
    s = np.array([], dtype=str)
    z3 = np.zeros((0, 3))
    return Samples(mic=s, flight=s, t_r=e, t_e=e, level=e, d=e, phi=e, theta=e, power_w=e, phase=s, roll=e,
                   pitch=e, yaw=e, uav_enu=z3, mic_enu=z3, vel_enu=z3, valid=np.array([], dtype=bool), mask_reason=s)

