"""Private kernels of the output-error maximum-likelihood fit.

Pure array functions, no knowledge of samples, cards or ansatz names:

* :func:`levenberg_marquardt` minimises ``0.5 * sum(w * r(q)**2)`` for fixed
  weights with Gauss-Newton steps, Levenberg-Marquardt damping (Marquardt's
  diagonal scaling, Nielsen's damping update) and simple bounds (the step is
  projected onto the box; variables held at a bound by the gradient are taken
  out of the step).
* :func:`relaxation` is the maximum-likelihood estimator with unknown diagonal
  measurement-noise covariance ``R`` (one variance per group, i.e. per
  microphone): it alternates ``R`` from the residuals with a converged
  Levenberg-Marquardt solve for the parameters (the relaxation strategy of the
  output-error method) until the negative log-likelihood stops changing.
* :func:`null_directions` and :func:`hac_covariance` serve the identifiability
  check and the residual-autocorrelation correction of the Cramer-Rao bounds.

``fun(q) -> (r, J)`` returns the residual ``model - measured`` (dB) and its
Jacobian ``dr/dq`` with shape ``(n, k)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gisnoise.errors import Cancelled

__all__ = ["LMResult", "levenberg_marquardt", "relaxation", "null_directions", "hac_covariance",
           "group_variances", "VARIANCE_FLOOR_DB2"]

ResidualFun = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

VARIANCE_FLOOR_DB2 = 1e-12
"""Smallest noise variance (dB^2) a group may get: keeps weights finite on noise-free data."""

RESIDUAL_FLOOR_DB = 1e-9
"""Residuals this small (dB) count as zero in the convergence tests (noise-free data)."""

HAC_WINDOW_FACTOR = 2
"""The Bartlett window of the autocorrelation correction reaches lag HAC_WINDOW_FACTOR * K."""

_LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass
class LMResult:
    """Outcome of one weighted least-squares solve or of the whole relaxation."""

    q: np.ndarray
    r: np.ndarray
    jac: np.ndarray
    cost: float
    """``0.5 * sum(w r^2)`` for the weights of the last solve."""
    iterations: int
    nfev: int
    converged: bool
    message: str
    variances: np.ndarray | None = None
    """Per-group noise variance (dB^2), relaxation only."""
    nll: float | None = None
    """Negative log-likelihood with those variances, relaxation only."""
    cycles: int = 0


def _check_cancel(cancel: Callable[[], bool] | None) -> None:
    if cancel is not None and cancel():
        raise Cancelled("fit cancelled", field="cancel")


def _active_set(q: np.ndarray, g: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """True for variables held at a bound by the gradient (the descent direction leaves the box)."""
    at_lo = (q <= lower) & (g > 0.0)
    at_hi = (q >= upper) & (g < 0.0)
    return at_lo | at_hi


def levenberg_marquardt(
    fun: ResidualFun,
    q0: np.ndarray,
    w: np.ndarray,
    *,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
    max_iter: int = 100,
    tol: float = 1e-10,
    callback: Callable[[int, float], None] | None = None,
    cancel: Callable[[], bool] | None = None,
    first: tuple[np.ndarray, np.ndarray] | None = None,
) -> LMResult:
    """Minimise ``0.5 * sum(w * r(q)**2)`` by bounded Levenberg-Marquardt.

    Parameters
    ----------
    fun : callable
        ``fun(q) -> (r, J)``, residuals (n,) and Jacobian (n, k).
    q0 : ndarray, shape (k,)
        Start, inside the bounds (it is clipped onto them).
    w : ndarray, shape (n,)
        Weights (inverse variances, 1/dB^2).
    lower, upper : ndarray, shape (k,), optional
        Bounds; ``-inf``/``inf`` for none.
    max_iter : int
        Maximum number of Gauss-Newton iterations (Jacobian evaluations).
    tol : float
        Converged when the Gauss-Newton predicted decrease of the cost, or the
        achieved decrease of an accepted step, is below ``tol * cost``.
    callback : callable, optional
        ``callback(iteration, cost)`` after every iteration.
    cancel : callable, optional
        Returns True to stop; raises :class:`gisnoise.errors.Cancelled`.
    first : (r, J), optional
        Residuals and Jacobian at ``q0`` when the caller has them already.
    """
    k = len(q0)
    lower = np.full(k, -np.inf) if lower is None else np.asarray(lower, dtype=float)
    upper = np.full(k, np.inf) if upper is None else np.asarray(upper, dtype=float)
    q = np.clip(np.asarray(q0, dtype=float), lower, upper)
    if first is None:
        r, jac = fun(q)
        nfev = 1
    else:
        r, jac = first
        nfev = 0
    cost = 0.5 * float(np.sum(w * r * r))
    if not np.isfinite(cost):
        return LMResult(q, r, jac, cost, 0, nfev, False, "the model is not finite at the start values")
    lam, nu = 1e-3, 2.0
    # residuals of RESIDUAL_FLOOR_DB are numerically zero: below this cost nothing is left to gain
    floor = 0.5 * float(np.sum(w)) * RESIDUAL_FLOOR_DB ** 2
    it = 0
    while True:
        _check_cancel(cancel)
        wj = jac * w[:, None]
        g = wj.T @ r
        h = wj.T @ jac
        active = _active_set(q, g, lower, upper)
        free = ~active
        gf, hf = g[free], h[np.ix_(free, free)]
        diag = np.diag(hf).copy()
        diag = np.maximum(diag, 1e-12 * max(float(diag.max(initial=0.0)), 1e-300))
        # Gauss-Newton predicted decrease (Newton decrement), scale-invariant
        try:
            dgn = np.linalg.lstsq(hf / np.sqrt(np.outer(diag, diag)), -gf / np.sqrt(diag), rcond=None)[0] / np.sqrt(diag)
            decrement = -0.5 * float(gf @ dgn)
        except np.linalg.LinAlgError:
            decrement = np.inf
        if not free.any() or decrement <= tol * cost + floor:
            return LMResult(q, r, jac, cost, it, nfev, True,
                            f"converged: predicted relative decrease {decrement / max(cost, floor):.1e} <= tol {tol:g}")
        if it >= max_iter:
            return LMResult(q, r, jac, cost, it, nfev, False,
                            f"did not converge in {max_iter} iterations (predicted relative decrease "
                            f"{decrement / max(cost, floor):.1e} > tol {tol:g})")
        it += 1
        accepted = False
        while not accepted:
            a = hf + lam * np.diag(diag)
            try:
                step = np.linalg.solve(a, -gf)
            except np.linalg.LinAlgError:
                lam *= nu
                nu *= 2.0
                if lam > 1e20:
                    break
                continue
            dq = np.zeros(k)
            dq[free] = step
            q_new = np.clip(q + dq, lower, upper)
            dq = q_new - q
            predicted = -(g @ dq + 0.5 * dq @ h @ dq)
            r_new, jac_new = fun(q_new)
            nfev += 1
            cost_new = 0.5 * float(np.sum(w * r_new * r_new))
            if np.isfinite(cost_new) and cost_new < cost:
                rho = (cost - cost_new) / predicted if predicted > 0 else 1.0
                lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                lam = max(lam, 1e-12)
                nu = 2.0
                accepted = True
            else:
                lam *= nu
                nu *= 2.0
                if lam > 1e20 or not np.any(dq):
                    break
        if not accepted:
            ok = decrement <= 1e-6 * cost + floor
            msg = ("converged: no downhill step left (cost at its numerical minimum)" if ok else
                   f"stopped: no step reduces the cost (predicted relative decrease {decrement / max(cost, floor):.1e})")
            return LMResult(q, r, jac, cost, it, nfev, ok, msg)
        decrease = cost - cost_new
        q, r, jac, cost = q_new, r_new, jac_new, cost_new
        if callback is not None:
            callback(it, cost)
        if decrease <= tol * cost + floor and predicted <= 10.0 * tol * cost + floor:
            return LMResult(q, r, jac, cost, it, nfev, True,
                            f"converged: relative cost decrease {decrease / max(cost, floor):.1e} <= tol {tol:g}")


def group_variances(r: np.ndarray, groups: np.ndarray, n_groups: int) -> np.ndarray:
    """Maximum-likelihood variance of ``r`` per group (mean square), floored at :data:`VARIANCE_FLOOR_DB2`."""
    counts = np.bincount(groups, minlength=n_groups)
    ss = np.bincount(groups, weights=r * r, minlength=n_groups)
    return np.maximum(ss / np.maximum(counts, 1), VARIANCE_FLOOR_DB2)


def negative_log_likelihood(r: np.ndarray, var: np.ndarray, groups: np.ndarray) -> float:
    """``0.5 * sum(r^2 / var + ln(2 pi var))`` with ``var`` per group."""
    v = var[groups]
    return 0.5 * float(np.sum(r * r / v + np.log(v) + _LOG_2PI))


def relaxation(
    fun: ResidualFun,
    q0: np.ndarray,
    groups: np.ndarray,
    n_groups: int,
    *,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
    max_iter: int = 100,
    tol: float = 1e-10,
    max_cycles: int = 50,
    progress: Callable[[int, float], None] | None = None,
    cancel: Callable[[], bool] | None = None,
) -> LMResult:
    """Maximum likelihood with unknown per-group noise variance, by relaxation.

    Each cycle estimates the variances from the current residuals, then
    minimises the weighted cost for the parameters.  Stops when a cycle changes
    the negative log-likelihood per sample by less than ``tol`` and its solve
    converged.  ``max_iter`` bounds the Gauss-Newton iterations of all cycles
    together; ``progress(iteration, nll)`` is called after each of them.
    """
    r, jac = fun(np.asarray(q0, dtype=float))
    nfev = 1
    n = len(r)
    q = np.asarray(q0, dtype=float)
    var = group_variances(r, groups, n_groups)
    nll = negative_log_likelihood(r, var, groups)
    used = 0
    log_det = 0.5 * float(np.sum(np.log(var[groups]) + _LOG_2PI))
    for cycle in range(1, max_cycles + 1):
        def cb(i: int, c: float, _base: int = used, _ld: float = log_det) -> None:
            if progress is not None:
                progress(_base + i, c + _ld)

        res = levenberg_marquardt(fun, q, 1.0 / var[groups], lower=lower, upper=upper,
                                  max_iter=max_iter - used, tol=tol, callback=cb, cancel=cancel,
                                  first=(r, jac))
        used += res.iterations
        nfev += res.nfev
        q, r, jac = res.q, res.r, res.jac
        if not res.converged:
            msg = res.message
            if msg.startswith("did not converge in"):
                msg = f"did not converge in {max_iter} iterations" + msg[msg.index(" iterations") + 11:]
            return LMResult(q, r, jac, res.cost, used, nfev, False,
                            f"{msg}; {cycle} relaxation cycle(s)",
                            variances=var, nll=negative_log_likelihood(r, var, groups), cycles=cycle)
        var_new = group_variances(r, groups, n_groups)
        nll_new = negative_log_likelihood(r, var_new, groups)
        change = abs(nll - nll_new) / n
        var, nll = var_new, nll_new
        log_det = 0.5 * float(np.sum(np.log(var[groups]) + _LOG_2PI))
        if change <= tol and (cycle > 1 or res.iterations == 0):
            cost = 0.5 * float(np.sum(r * r / var[groups]))
            return LMResult(q, r, jac, cost, used, nfev, True,
                            f"converged in {cycle} relaxation cycle(s): negative log-likelihood change "
                            f"{change:.1e} per sample <= tol {tol:g}",
                            variances=var, nll=nll, cycles=cycle)
    cost = 0.5 * float(np.sum(r * r / var[groups]))
    return LMResult(q, r, jac, cost, used, nfev, False,
                    f"noise variances did not settle in {max_cycles} relaxation cycles", variances=var,
                    nll=nll, cycles=max_cycles)


def null_directions(jw: np.ndarray, rcond: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Near-null directions of a weighted Jacobian with columns scaled to unit norm.

    Returns ``(s, v, ratio)``: the singular values (descending) relative to the
    largest, the right singular vectors (rows) in the scaled parameter space, and
    the smallest ratio.  Directions with ``s < rcond`` are the ones the data
    cannot resolve; a zero column counts as a null direction on its own.
    """
    gram = jw.T @ jw
    norms = np.sqrt(np.clip(np.diag(gram), 0.0, None))
    scale = np.where(norms > 0, norms, 1.0)
    gs = gram / np.outer(scale, scale)
    gs[norms == 0, :] = 0.0
    gs[:, norms == 0] = 0.0
    # singular values of the scaled Jacobian from its k x k Gram matrix (ratios down to ~1e-7 are exact enough)
    ev, vecs = np.linalg.eigh(gs)
    s = np.sqrt(np.clip(ev[::-1], 0.0, None))
    vt = vecs[:, ::-1].T
    s_rel = s / s[0] if s[0] > 0 else np.zeros_like(s)
    return s_rel, vt, float(s_rel[-1])


def first_zero_crossing(rho: np.ndarray) -> int:
    """Largest lag ``K`` with ``rho[1..K] > 0`` (0 when ``rho[1] <= 0``)."""
    neg = np.nonzero(rho[1:] <= 0.0)[0]
    return int(neg[0]) if len(neg) else len(rho) - 1


def _convolve_columns(a: np.ndarray, kern: np.ndarray) -> np.ndarray:
    """Full linear convolution of each column of ``a`` with ``kern`` (FFT)."""
    n_out = a.shape[0] + len(kern) - 1
    nfft = 1 << (n_out - 1).bit_length()
    fa = np.fft.rfft(a, nfft, axis=0)
    fk = np.fft.rfft(kern, nfft)
    return np.fft.irfft(fa * fk[:, None], nfft, axis=0)[:n_out]


def hac_covariance(
    jac: np.ndarray, r: np.ndarray, w: np.ndarray, series: list[np.ndarray], *, max_lag: int = 5000
) -> tuple[np.ndarray, int]:
    """Cramer-Rao covariance corrected for residual autocorrelation (Morelli & Klein 1997).

    ``Cov = M^-1 [sum_i sum_j g_i R(i-j) g_j^T] M^-1`` with ``M = J^T W J``,
    ``g_i = w_i J_i`` and ``R(k)`` the residual autocovariance of each series
    (a microphone's samples of one flight, in time order).  The lag sum uses a
    Bartlett window reaching lag ``2 K``, ``K`` the first zero crossing of the
    pooled residual autocorrelation (the window keeps the matrix positive
    semi-definite); white residuals give ``K = 0`` and the Cramer-Rao bound with
    the variance of each series.

    Returns ``(covariance, K)``.
    """
    g = jac * w[:, None]
    m = jac.T @ g
    n_lag = max_lag + 1
    acc = np.zeros(n_lag)
    autocov = []
    for idx in series:
        z = r[idx]
        nz = len(z)
        f = np.fft.rfft(z, 2 * nz)
        ac = np.fft.irfft(f * np.conj(f), 2 * nz)[: min(n_lag, nz)] / nz
        autocov.append(ac)
        acc[: len(ac)] += ac * nz * w[idx[0]]
    kz = first_zero_crossing(acc / acc[0]) if acc[0] > 0 else 0
    bw = HAC_WINDOW_FACTOR * kz + 1
    middle = np.zeros((jac.shape[1], jac.shape[1]))
    for idx, ac in zip(series, autocov, strict=True):
        gi = g[idx]
        if bw == 1 or len(idx) == 1:
            middle += ac[0] * (gi.T @ gi)
            continue
        lags = np.arange(min(bw, len(ac)))
        h = ac[: len(lags)] * (1.0 - lags / bw)
        kern = np.concatenate([h[:0:-1], h])  # symmetric, centre at len(h) - 1
        tg = _convolve_columns(gi, kern)[len(h) - 1: len(h) - 1 + len(idx)]
        middle += gi.T @ tg
    minv = np.linalg.inv(m)
    cov = minv @ middle @ minv
    return 0.5 * (cov + cov.T), kz
