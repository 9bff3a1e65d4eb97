"""The effect type: one unmodelled physical effect as an extension of an ansatz, bound to a data set.

An :class:`Effect` carries its own parameters and an analytic Jacobian; extended
by it, a base :class:`~gisnoise.model.ansatz.Ansatz` becomes another ansatz
(named ``"<base>+<effect>"``), so the fitter, the evaluator and the diagnosis
use the same definition.  The library of effects and the lookup by name are in
:mod:`gisnoise.model.effects`.

Each effect declares the inputs it needs (``needs``: input key and, in words,
what the user lacks when it is missing) and, optionally, a further check of the
data (``check``).  :func:`check_testable` turns both into ``(True, "")`` or
``(False, reason)``; a candidate that cannot be tested is reported, never a crash.

Effects whose extension needs per-row facts that are not in a single row of the
inputs (time derivatives along a series, detected event windows) compute them
once per data set with ``covariates``; :func:`bind` returns an effect with the
covariates attached to the rows (looked up by emission time and geometry), so
the fitter may pass any subset of the same rows.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.model.ansatz import Ansatz

__all__ = ["Effect", "additive", "check_testable", "bind"]


# apply(base_kernel, p_base, q, x, d_ref, want_jac) -> (L_uav, J_base or None, J_q or None)
Apply = Callable[..., tuple[np.ndarray, np.ndarray | None, np.ndarray | None]]
# term(q, x, d_ref, want_jac) -> (dL, dL/dq or None)
Term = Callable[[np.ndarray, Mapping[str, Any], float, bool], tuple[np.ndarray, np.ndarray | None]]


@dataclass(frozen=True)
class Effect:
    """One candidate effect: an extension of a base ansatz.

    Parameters
    ----------
    name : str
        Registry name (one of the SPEC effect names, or a new one).
    params : tuple of str
        Extension parameter names, appended after the base parameters.
    units : tuple of str
        Unit of each extension parameter.
    start : tuple of float
        Start values; the effect vanishes at these values.
    bounds : tuple of (float, float)
        Physical bounds of each extension parameter.
    needs : tuple of (str, str)
        Inputs the effect needs to be testable and, for each, what is missing in
        words (e.g. ``("rpm", "no rpm column in the flight logs")``).
    reads : tuple of str
        Per-row numeric inputs the extension term reads (they become part of the
        extended ansatz's ``inputs``; covariates attached by :func:`bind` and the
        ``meta`` mapping are not listed).
    apply : callable
        ``apply(base_kernel, p_base, q, x, d_ref, want_jac) -> (L_uav, J_base, J_q)``.
        Use :func:`additive` for an additive term.
    description : str
        One line for listings and reports.
    check : callable, optional
        ``check(x) -> reason or None``: further conditions for the effect to be
        testable on these data (e.g. the rpm column varies).
    covariates : callable, optional
        ``covariates(x) -> dict`` of per-row arrays computed once per data set
        (see :func:`bind`).
    fixed : callable, optional
        ``fixed(x) -> {param: value}``: data-dependent constants a refit holds fixed.
    initial : callable, optional
        ``initial(x, residual_db) -> {param: value}``: start values from the data
        (``residual_db`` is measured minus base model); a grid search adds
        ``"__trials__"``, the number of alternatives it tried (the significance
        test pays for them).
    tested : tuple of str, optional
        Parameters whose joint null value means "no effect" (the significance
        test is on these); default all parameters not held ``fixed``.
    dynamic : (str, float, float), optional
        For effects whose parameter list depends on the data (``covariates``
        returns ``"__params__"``): unit, lower and upper bound of each parameter.
    """

    name: str
    params: tuple[str, ...]
    units: tuple[str, ...]
    start: tuple[float, ...]
    bounds: tuple[tuple[float, float], ...]
    needs: tuple[tuple[str, str], ...]
    reads: tuple[str, ...]
    apply: Apply = field(repr=False)
    description: str = ""
    check: Callable[[Mapping[str, Any]], str | None] | None = field(default=None, repr=False)
    covariates: Callable[[Mapping[str, Any]], dict[str, np.ndarray]] | None = field(default=None, repr=False)
    fixed: Callable[[Mapping[str, Any]], dict[str, float]] | None = field(default=None, repr=False)
    initial: Callable[[Mapping[str, Any], np.ndarray], dict[str, float]] | None = field(default=None, repr=False)
    tested: tuple[str, ...] | None = None
    dynamic: tuple[str, float, float] | None = None
    bound_rows: _RowTable | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        k = len(self.params)
        for name in ("units", "start", "bounds"):
            if len(getattr(self, name)) != k:
                raise InputError(f"effect {self.name!r}: '{name}' must have {k} entries", field=name)

    @property
    def n_params(self) -> int:
        return len(self.params)




def check_testable(effect: Effect, x: Mapping[str, Any]) -> tuple[bool, str]:
    """Whether the data ``x`` hold what ``effect`` needs: ``(True, "")`` or ``(False, reason)``."""
    for key, what in effect.needs:
        v = x.get(key)
        if v is None:
            return False, what
    if effect.check is not None:
        reason = effect.check(x)
        if reason:
            return False, reason
    return True, ""


def _extended(base: Ansatz, eff: Effect) -> Ansatz:
    """The ansatz ``base`` extended by one effect: parameters appended, named ``"<base>+<effect>"``."""
    clash = set(base.params) & set(eff.params)
    if clash:
        raise InputError(f"effect {eff.name!r} parameters {sorted(clash)} clash with {base.name!r}", field="effect")
    return Ansatz(
        name=f"{base.name}+{eff.name}",
        params=base.params + eff.params,
        inputs=base.inputs + tuple(k for k in eff.reads if k not in base.inputs),
        kernel=_extended_kernel(base, eff),
        background=base.background,
        description=f"{base.description or base.name}; + {eff.description}",
        units=base.units + tuple(u or "-" for u in eff.units) if len(base.units) == base.n_params else (),
    )


def _extended_kernel(base: Ansatz, eff: Effect) -> Callable[..., tuple[np.ndarray, np.ndarray | None]]:
    nb = base.n_params

    def kernel(p: np.ndarray, x: Mapping[str, Any], d_ref: float, want_jac: bool):
        p = np.asarray(p, dtype=float)
        xb = eff.bound_rows.attach(x) if eff.bound_rows is not None else x
        l_uav, jb, jq = eff.apply(base.kernel, p[:nb], p[nb:], xb, d_ref, want_jac)
        if not want_jac:
            return l_uav, None
        assert jb is not None
        n = l_uav.shape
        jq = np.zeros(n + (0,)) if jq is None else np.broadcast_to(jq, n + (eff.n_params,))
        return l_uav, np.concatenate([np.broadcast_to(jb, n + (nb,)), jq], axis=-1)

    return kernel


def additive(term: Term) -> Apply:
    """Wrap ``term(q, x, d_ref, want_jac) -> (dL, dL/dq)`` as an additive extension of ``L_UAV``."""

    def apply(base_kernel, p_base, q, x, d_ref, want_jac):
        l_uav, jb = base_kernel(p_base, x, d_ref, want_jac)
        dl, jq = term(q, x, d_ref, want_jac)
        shape = np.broadcast_shapes(l_uav.shape, np.shape(dl))
        return np.broadcast_to(l_uav + dl, shape).astype(float), jb, jq

    return apply


# --------------------------------------------------------------------------- rows and covariates


def _row_keys(x: Mapping[str, Any]) -> np.ndarray:
    """One byte key per row from emission time, microphone and UAV position."""
    t = np.asarray(x["t_e"], dtype=float).reshape(-1, 1)
    m = np.asarray(x["mic_enu"], dtype=float).reshape(len(t), -1)
    u = np.asarray(x["uav_enu"], dtype=float).reshape(len(t), -1)
    k = np.ascontiguousarray(np.hstack([t, m, u]))
    return k.view(np.dtype((np.void, k.dtype.itemsize * k.shape[1]))).ravel()


class _RowTable:
    """Per-row covariates of one data set, found again for any subset of its rows."""

    def __init__(self, x: Mapping[str, Any], values: dict[str, np.ndarray]) -> None:
        keys = _row_keys(x)
        order = np.argsort(keys, kind="stable")
        self._keys = keys[order]
        self._order = order
        self._values = {k: np.asarray(v) for k, v in values.items()}
        self._cache: tuple[Any, dict[str, Any]] | None = None

    def attach(self, x: Mapping[str, Any]) -> Mapping[str, Any]:
        t = x.get("t_e")
        if t is None:
            raise InputError("bound effect needs input t_e (and mic_enu, uav_enu) to find its rows", field="t_e")
        if self._cache is not None and self._cache[0] is t:
            extra = self._cache[1]
        else:
            keys = _row_keys(x)
            pos = np.searchsorted(self._keys, keys)
            pos = np.clip(pos, 0, len(self._keys) - 1)
            if len(self._keys) == 0 or not np.all(self._keys[pos] == keys):
                raise InputError("bound effect: the samples are not rows of the data set it was bound to",
                                 field="samples")
            idx = self._order[pos]
            extra = {k: v[idx] for k, v in self._values.items()}
            self._cache = (t, extra)
        return {**x, **extra}


def bind(effect: Effect, x: Mapping[str, Any]) -> Effect:
    """Attach the data-dependent covariates of ``effect`` computed on the data set ``x``.

    Returns ``effect`` itself when it has no covariates.  The returned effect
    finds its covariates for any subset of the rows of ``x`` (by emission time,
    microphone and UAV position), so it can be handed to the fitter.
    """
    if effect.covariates is None:
        return effect
    values = effect.covariates(x)
    params = values.pop("__params__", None)
    table = _RowTable(x, values)
    if params is not None:
        k = len(params)
        u, lo, hi = effect.dynamic or ("", -np.inf, np.inf)
        return replace(effect, params=tuple(params), units=(u,) * k, start=(0.0,) * k, bounds=((lo, hi),) * k,
                       bound_rows=table)
    return replace(effect, bound_rows=table)

