"""Candidate effects: each fitted as an extension of the card's ansatz, on all data and in two held-out folds.

Every candidate of the effect library (:mod:`gisnoise.model.effects`) that the
data can test is fitted with the output-error fitter (:func:`gisnoise.identify.fit_arrays`)
on all data and in a two-fold cross-validation (:func:`fold_labels`: folds are whole
flights, or alternating time blocks when there is one flight), so that every
sample gets a prediction from a model not fitted to it.  The fit on all data gives
the Wald statistic of the extension parameters (covariance corrected for residual
autocorrelation) and the base parameters the effect had biased.

When the diagnosis has named level offsets of flights or microphones (:mod:`gisnoise.diagnose.offsets`),
the baseline and every candidate carry them (:func:`~gisnoise.diagnose.offsets.with_offsets` of the
extended ansatz: one parameter per offset, fitted with the rest), so that an offset's residual does not
weigh on every candidate's held-out score; the offsets the folds cannot tell (a flight's, the folds being
flights, and a microphone's heard in one fold only) are held at their values on all data there.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from gisnoise.diagnose._offset_model import with_offsets
from gisnoise.diagnose._rows import _rows_of
from gisnoise.errors import Cancelled, FitError, GisnoiseError, NotIdentifiableError
from gisnoise.identify import FitResult, fit_arrays
from gisnoise.measure import Samples, series_key
from gisnoise.model import Ansatz
from gisnoise.model import effects as _effects

__all__ = ["fold_labels"]

CancelFn = Callable[[], bool]
FIT_TOL = 1e-9
"""Relative cost tolerance of the refits (a fit still creeping after 300 iterations is used as it stands)."""


def fold_labels(s: Samples, *, block_s: float = 30.0) -> tuple[np.ndarray, np.ndarray, str]:
    """Two cross-validation folds and the time blocks of the paired held-out test.

    With two or more flights the flights alternate between the folds; with one
    flight, consecutive ``block_s`` blocks of emission time alternate (the same
    block of every microphone goes to the same fold).

    Parameters
    ----------
    s : Samples
        The samples.
    block_s : float
        Time block, s.

    Returns
    -------
    fold : ndarray of int
        Fold 0 or 1 per sample.
    block : ndarray of int
        Block label per sample: one per microphone, flight and time block.
    how : str
        ``"flights"`` or ``"time blocks"``.
    """
    flights = sorted(set(s.flight.astype(str).tolist()))
    tb = np.floor(s.t_e / block_s).astype(int)
    block_key = np.char.add(np.char.add(np.char.add(s.flight.astype(str), "\x00"), s.mic.astype(str)),
                            np.char.add("\x00", tb.astype(str)))
    block = np.unique(block_key, return_inverse=True)[1].ravel()
    if len(flights) >= 2:
        idx = {f: i % 2 for i, f in enumerate(flights)}
        return np.array([idx[f] for f in s.flight.astype(str)], dtype=int), block, "flights"
    t0 = float(np.min(s.t_e)) if len(s) else 0.0
    fold = (np.floor((s.t_e - t0) / block_s).astype(int) % 2).astype(int)
    return fold, block, "time blocks"


@dataclass
class _Context:
    """What every candidate and evidence check sees: samples, model inputs, regimes, baseline refit, events.

    ``base_model`` is the model the candidates extend and ``p_base`` its parameters; ``offsets`` are the
    groups of the level offsets every fit carries on top (:func:`~gisnoise.diagnose.offsets.with_offsets`,
    none by default), and ``hold_in_folds`` the offset parameters the fold fits hold at their values on all
    data.
    """

    s: Samples
    x: dict[str, Any]
    regimes: np.ndarray
    resid_base: np.ndarray
    base_model: Ansatz
    p_base: np.ndarray
    background_db: float | None
    event_windows: list[dict[str, Any]]
    offsets: tuple[tuple[str, str], ...] = ()
    hold_in_folds: tuple[str, ...] = ()


@dataclass
class _Candidate:
    """One candidate effect: whether it is testable, its fits, out-of-fold predictions and summary.

    ``model`` is the model fitted (with the context's level offsets, if any); ``inner`` the same without them
    (the base extended by the effect, which forward selection extends further); ``tested`` the parameters
    of its significance test.
    """

    name: str
    effect: _effects.Effect | None = None
    model: Ansatz | None = None
    inner: Ansatz | None = None
    testable: bool = True
    reason: str = ""
    fit: FitResult | None = None
    oof: np.ndarray | None = None
    error: str = ""
    summary: dict[str, Any] = field(default_factory=dict)
    x: dict[str, Any] | None = None
    tested: tuple[str, ...] = ()


def _fit(level: np.ndarray, x: Mapping[str, Any], model: Ansatz, s: Samples, rows: np.ndarray, *,
         p0: Any = None, fixed: Mapping[str, float] | None = None, bounds: Mapping[str, Any] | None = None,
         cancel: CancelFn | None = None) -> FitResult:
    """Output-error fit of ``model`` to the rows ``rows`` (one series per microphone and flight)."""
    sub = _rows_of(x, rows, len(s))
    mic = s.mic[rows].astype(str)
    series = series_key(mic, s.flight[rows])
    res = fit_arrays(level[rows], sub, model, mic=mic, series=series, time=s.t_e[rows], p0=p0, fixed=fixed,
                     bounds=bounds, cancel=cancel, reference_power_w=1.0, max_iter=300, tol=FIT_TOL,
                     raise_on_failure=False)
    if not res.success and not (np.isfinite(res.cost) and "did not converge" in res.message
                                and res.iterations >= 300):
        raise FitError(f"fit did not converge: {res.message}", field="fit")
    return res


def _predict(model: Ansatz, p: np.ndarray, x: Mapping[str, Any], rows: np.ndarray, n: int) -> np.ndarray:
    """Level of ``model`` at parameters ``p`` on the rows ``rows`` of the ``n``-row inputs ``x``."""
    sub = _rows_of(x, rows, n)
    return np.broadcast_to(model.level(p, sub), (len(rows),))


def _wald(res: FitResult, names: Sequence[str]) -> tuple[float, int]:
    """Wald statistic of the free parameters ``names`` against zero, and its degrees of freedom."""
    idx = [res.param_names.index(k) for k in names if k not in res.fixed and k not in res.at_bounds]
    if not idx:
        return 0.0, len(names)
    q = res.p[idx]
    c = res.cov_corrected[np.ix_(idx, idx)]
    try:
        w = float(q @ np.linalg.solve(c, q))
    except np.linalg.LinAlgError:
        w = float(q @ np.linalg.pinv(c) @ q)
    return max(w, 0.0), len(idx)



def _fit_candidates(names: Sequence[str], ctx: _Context, level: np.ndarray, x: dict[str, Any],
                    x_ev: dict[str, Any], base_fit: FitResult, oof_base: np.ndarray, fold: np.ndarray, *,
                    cancel: CancelFn | None, bias_z: float, tick: Callable[[str], None],
                    overrides: Mapping[str, tuple[_effects.Effect, dict[str, Any], list[str], dict[str, Any]]]
                    | None = None, screen_alpha: float | None = None,
                    base_fixed: Mapping[str, float] | None = None,
                    screen_min_db2: float | None = None) -> list[_Candidate]:
    """Each named candidate: untestable with its reason, or fitted on all data and in the folds.

    ``x_ev`` are the inputs with the event windows (``event_window``) for ``background_event``;
    ``overrides[name] = (effect, extra_inputs, notes, summary)`` tests a candidate in another form or with
    inputs estimated from the data instead of the campaign's metadata (the notes say why; ``summary``
    adds evidence computed with the estimate, e.g. the band-level held-out test);
    a candidate whose fit fails keeps the error; one the base ansatz holds already is not testable;
    ``tick(name)`` follows each candidate.  With
    ``screen_alpha``, a candidate whose Wald test on all data does not reach it is not refitted in the
    folds (it cannot qualify; forward selection uses this to save time).  ``base_fixed`` are parameters of
    the base model held at their values (those an earlier effect of forward selection held, e.g. a reference
    rpm).  With ``screen_min_db2``, a candidate whose in-sample improvement of the mean squared residual is
    below half of it is not refitted in the folds either.
    """
    ev_list = ctx.event_windows
    cands: list[_Candidate] = []
    for nme in names:
        eff = _effects.get_effect(nme)
        xe = x_ev if nme == "background_event" else x
        notes: list[str] = []
        more: dict[str, Any] = {}
        if overrides and nme in overrides:
            eff, extra, notes, more = overrides[nme]
            xe = {**xe, **extra}
        cand = _Candidate(nme, eff, x=xe)
        if notes:
            cand.summary["metadata_contradicted"] = list(notes)
        cand.summary.update(more)
        cands.append(cand)
        ok, why = _effects.check_testable(eff, xe)
        if nme == "background_event" and ok and not ev_list:
            ok, why = True, ""
        if nme in ctx.base_model.name.split("+")[1:]:  # the baseline fits it already: nothing to add
            ok, why = False, f"already in the card's ansatz {ctx.base_model.name!r}"
        if not ok:
            cand.testable, cand.reason = False, why
            tick(nme)
            continue
        if nme == "background_event" and not ev_list:
            cand.reason = "no window of added sound found: the extension is the baseline"
            cand.oof = oof_base.copy()
            cand.summary["rms_db_fit"] = base_fit.rms_db
            tick(nme)
            continue
        try:
            _attribute(cand, ctx, level, xe, base_fit, fold, cancel, bias_z, screen_alpha, base_fixed,
                       screen_min_db2)
        except GisnoiseError as exc:
            if isinstance(exc, Cancelled):
                raise
            cand.error = str(exc)
        tick(nme)
    return cands


def _attribute(cand: _Candidate, ctx: _Context, level: np.ndarray, x: dict[str, Any], base_fit: FitResult,
               fold: np.ndarray, cancel: CancelFn | None, bias_z: float, screen_alpha: float | None = None,
               base_fixed: Mapping[str, float] | None = None, screen_min_db2: float | None = None) -> None:
    """Fit one candidate on all data and in the two folds; fill its summary."""
    s = ctx.s
    n = len(s)
    assert cand.effect is not None
    eff = _effects.bind(cand.effect, x)
    inner = _effects.extend(ctx.base_model, eff)
    model = with_offsets(inner, ctx.offsets) if ctx.offsets else inner
    cand.model, cand.inner = model, inner
    nb = ctx.base_model.n_params
    # the baseline's parameters (the level offsets' too) by name, the extension's at their start values
    start = dict(zip(base_fit.param_names, np.asarray(base_fit.p, dtype=float), strict=True))
    start.update(zip(eff.params, np.asarray(eff.start, dtype=float), strict=True))
    fixed = {**dict(base_fixed or {}), **(dict(eff.fixed(x)) if eff.fixed is not None else {})}
    trials = 1
    if eff.initial is not None:
        init = dict(eff.initial(x, base_fit.residuals))
        trials = int(init.pop("__trials__", 1))
        start.update(init)
    bounds = {k: b for k, b in zip(eff.params, eff.bounds, strict=True)}
    if cand.name == "background_event":
        win = np.asarray(x["event_window"], dtype=int)
        for j, k in enumerate(eff.params):
            m = win == j
            excess = np.mean(10.0 ** (level[m] / 10.0)) - np.mean(10.0 ** ((level[m] - base_fit.residuals[m]) / 10.0))
            start[k] = float(10.0 * np.log10(max(excess, 1e-2)))
    start.update(fixed)
    rows_all = np.arange(n)
    tested = eff.tested if eff.tested is not None else tuple(k for k in eff.params if k not in fixed)
    cand.tested = tuple(tested)
    def fit_ext(rows: np.ndarray, p0: dict[str, float], fx: dict[str, float]) -> FitResult:
        try:
            return _fit(level, x, model, s, rows, p0=p0, fixed=fx or None, bounds=bounds, cancel=cancel)
        except NotIdentifiableError:
            # a vanishing effect leaves its shape parameters undetermined: hold them at their start values
            shape = {k: float(p0[k]) for k in eff.params if k not in tested and k not in fx}
            if not shape:
                raise
            cand.reason = f"{', '.join(shape)} held at the start value(s) where not identifiable"
            return _fit(level, x, model, s, rows, p0=p0, fixed={**fx, **shape}, bounds=bounds, cancel=cancel)

    full = fit_ext(rows_all, start, fixed)
    cand.fit = full
    if screen_alpha is not None and cand.name != "background_event" and "band_holdout" not in cand.summary:
        w, dof = _wald(full, tested)
        if min(1.0, trials * float(stats.chi2.sf(w, dof))) >= screen_alpha:
            cand.reason = "not significant on all data: not refitted in the folds"
            return
    if screen_min_db2 is not None and "band_holdout" not in cand.summary:
        # held-out improvement rarely beats the in-sample one: far below the minimum, the folds cannot reach it
        gain = float(np.mean(base_fit.residuals ** 2) - np.mean(full.residuals ** 2))
        if gain < 0.5 * screen_min_db2:
            cand.reason = (f"in-sample improvement {gain:.4f} dB^2 is below half the smallest held-out improvement "
                           "a verdict needs: not refitted in the folds")
            return
    oof = np.empty(n)
    for f in (0, 1):
        tr, te = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        fx = dict(fixed)
        fx.update({k: float(full.params[k]) for k in ctx.hold_in_folds})
        if cand.name == "background_event":
            win = np.asarray(x["event_window"], dtype=int)
            present = set(np.unique(win[tr]).tolist())
            for j, k in enumerate(eff.params):
                if j not in present:
                    fx[k] = float(full.params[k])  # window only in held-out data: its level is a nuisance
        p0 = {k: v for k, v in full.params.items()}
        p0.update(fx)
        r = fit_ext(tr, p0, fx)
        oof[te] = level[te] - _predict(model, r.p, x, te, n)
    cand.oof = oof
    summ = cand.summary
    summ["rms_db_fit"] = full.rms_db
    summ["lr"] = 2.0 * (base_fit.cost - full.cost)
    summ["delta_aic"] = full.aic - base_fit.aic
    summ["delta_bic"] = full.bic - base_fit.bic
    if cand.name == "background_event":
        zs = [w["z"] for w in ctx.event_windows if w.get("z") is not None]
        n_scan = max(1.0, n / 8.0)
        zmax = max(zs) if zs else 0.0
        summ["p_value"] = float(min(1.0, n_scan * stats.norm.sf(zmax))) if zs else 1.0
        summ["test"] = "scan statistic of the strongest window against white measurement noise (Bonferroni)"
    else:
        w, dof = _wald(full, tested)
        summ["wald"] = w
        summ["wald_dof"] = dof
        summ["look_elsewhere_trials"] = trials
        summ["test"] = "Wald test of " + ", ".join(tested) + " with autocorrelation-corrected covariance" + (
            f", p-value times {trials} start values searched" if trials > 1 else "")
    std = full.std_corrected
    summ["parameters"] = {k: {"value": full.params[k], "std": std[k]} for k in eff.params}
    biased = []
    for k in ctx.base_model.params[:nb]:
        sd = std[k]
        dv = full.params[k] - base_fit.params[k]
        if sd > 0 and abs(dv) / sd > bias_z:
            biased.append({"name": k, "baseline": base_fit.params[k], "extended": full.params[k],
                           "shift_in_std": dv / sd})
    summ["biased_parameters"] = biased
    summ["at_bounds"] = list(full.at_bounds)
