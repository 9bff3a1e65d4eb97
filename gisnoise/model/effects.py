"""Candidate effects: physically motivated extensions of an ansatz.

An :class:`Effect` is one unmodelled physical effect written as an extension of
a base ansatz with its own parameters and an analytic Jacobian.  The extended
model is itself an :class:`~gisnoise.model.ansatz.Ansatz` (named ``"<base>+<effect>"``),
so the fitter, the evaluator and the diagnosis use the same definition.  The
single-effect extensions of every base ansatz registered at import time are
registered here (``"paper-offset+bank_angle"`` and so on); :func:`extend`
builds (and registers) any other combination.

Each effect declares the inputs it needs (``needs``: input key and, in words,
what the user lacks when it is missing) and, optionally, a further check of the
data (``check``).  :func:`check_testable` turns both into ``(True, "")`` or
``(False, reason)``; a candidate that cannot be tested is reported, never a crash.

Effects whose extension needs per-row facts that are not in a single row of the
inputs (time derivatives along a series, detected event windows) compute them
once per data set with ``covariates``; :func:`bind` returns an effect with the
covariates attached to the rows (looked up by emission time and geometry), so
the fitter may pass any subset of the same rows.

The extension terms (``dL`` in dB added to ``L_UAV`` unless stated):

``bank_angle``
    Interaction noise in turning flight (paper 5.3.1): ``k_bank |sin(bank)|``.
``atmospheric_absorption``
    Molecular absorption left in the A-weighted level, linear in the path
    length: ``-a_abs (d - d_ref) / 1000`` (``a_abs`` dB/km).  Needs band levels:
    only they can tell absorption (frequency-selective, ISO 9613-1) from other
    distance-dependent errors.
``ground_reflection``
    Interference of the direct and the ground-reflected path at an elevated
    microphone: ``10 log10(1 + R^2 + 2 R C(f_g tau))`` with ``tau`` the delay of
    the reflected path and ``C`` the cosine averaged over a one-third-octave band
    about ``f_g``.  Needs microphone heights above ground.
``doppler``
    Convective amplification of a moving source: ``-q_doppler 10 log10(1 - M_r)``
    with ``M_r`` the Mach number of the UAV velocity towards the observer.
``emission_time``
    Misaligned time bases: the model evaluated at ``t_e + dt_clock + k_delay d/c``
    (clock offset and error of the propagation delay), to first order along the
    time derivative of the inputs.
``wind``
    Refraction and convection by wind: ``(d / 100 m) (w_east e_east + w_north e_north)``
    with ``e`` the horizontal unit vector of propagation (UAV -> microphone).
``rpm``
    Propeller speed beyond electric power: ``k_rpm 20 log10(rpm / rpm_ref)``.
``background_event``
    Transient sound from other sources: in each detected window ``j`` the level
    is the energetic sum of the model and an event level ``ev_j`` (dB).

Examples
--------
>>> import numpy as np
>>> from gisnoise.model.ansatz import get_ansatz
>>> a = get_ansatz("paper-offset+bank_angle")
>>> a.params[-1]
'k_bank'
>>> p = np.r_[60.0, 13.4, 0.18, -0.28, -0.37, 1.05, 0.94, 40.4, 3.0]
>>> x = {"d": 40.0, "phi": 0.0, "theta": -0.5, "p_el": 1.0, "bank": np.radians(30.0)}
>>> base = get_ansatz("paper-offset").level_uav(p[:-1], x)
>>> round(float(a.level_uav(p, x) - base), 3)  # 3 dB * sin(30 deg)
1.5
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.model.ansatz import _REGISTRY, Ansatz, ansatz_names, register_ansatz

__all__ = [
    "Effect",
    "register_effect",
    "get_effect",
    "effect_names",
    "extend",
    "bind",
    "check_testable",
    "speed_of_sound",
    "mic_height_agl",
    "series_ids",
    "EFFECT_NAMES",
]

LN10 = float(np.log(10.0))
THIRD_OCTAVE = (2.0 ** (-1.0 / 6.0), 2.0 ** (1.0 / 6.0))
"""Band edges of a one-third octave relative to its centre (base 2)."""

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


# --------------------------------------------------------------------------- registry

_EFFECTS: dict[str, Effect] = {}


def register_effect(effect: Effect, *, replace_existing: bool = False) -> Effect:
    """Add an effect to the library and register its single-effect extensions.

    The extension of every base ansatz registered so far (names without ``+``)
    becomes ``"<base>+<effect>"`` in the ansatz registry, unless the effect's
    parameters depend on the data (``covariates`` without ``params``).
    """
    if effect.name in _EFFECTS and not replace_existing:
        raise InputError(f"effect {effect.name!r} is already registered", field="effect")
    if "+" in effect.name:
        raise InputError(f"effect name must not contain '+': {effect.name!r}", field="effect")
    _EFFECTS[effect.name] = effect
    if effect.params:
        for base in [n for n in ansatz_names() if "+" not in n]:
            extend(_REGISTRY[base], effect, register=True)
    return effect


def get_effect(name: str) -> Effect:
    """An effect by name; the error lists the known names."""
    try:
        return _EFFECTS[name]
    except KeyError:
        raise InputError(f"unknown effect {name!r}; known: {', '.join(_EFFECTS)}", field="effect") from None


def effect_names() -> list[str]:
    """Names of all registered effects, in registration order."""
    return list(_EFFECTS)


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


def extend(base: Ansatz | str, *effects: Effect | str, register: bool = False) -> Ansatz:
    """The ansatz ``base`` extended by ``effects`` (in order), named ``base+e1+e2``.

    Parameters
    ----------
    base : Ansatz or str
        Base ansatz or its registry name.
    *effects : Effect or str
        Effects or their names.
    register : bool
        Also put the result into the ansatz registry (replacing an earlier one
        of the same name).

    Returns
    -------
    Ansatz
        Parameters: the base's, then each effect's.  Background parameter: the base's.
    """
    from gisnoise.model.ansatz import get_ansatz

    a = get_ansatz(base) if isinstance(base, str) else base
    for e in effects:
        eff = get_effect(e) if isinstance(e, str) else e
        clash = set(a.params) & set(eff.params)
        if clash:
            raise InputError(f"effect {eff.name!r} parameters {sorted(clash)} clash with {a.name!r}", field="effect")
        a = Ansatz(
            name=f"{a.name}+{eff.name}",
            params=a.params + eff.params,
            inputs=a.inputs + tuple(k for k in eff.reads if k not in a.inputs),
            kernel=_extended_kernel(a, eff),
            background=a.background,
            description=f"{a.description or a.name}; + {eff.description}",
        )
    if register:
        register_ansatz(a, replace=True)
    return a


def _extended_kernel(base: Ansatz, eff: Effect) -> Callable[..., tuple[np.ndarray, np.ndarray | None]]:
    nb = base.n_params

    def kernel(p: np.ndarray, x: Mapping[str, Any], d_ref: float, want_jac: bool):
        p = np.asarray(p, dtype=float)
        xb = eff.bound_rows.attach(x) if eff.bound_rows is not None else x
        l_uav, jb, jq = eff.apply(base.kernel, p[:nb], p[nb:], xb, d_ref, want_jac)
        if not want_jac:
            return l_uav, None
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


# --------------------------------------------------------------------------- shared helpers


def speed_of_sound(meta: Mapping[str, Any] | None) -> float | None:
    """Speed of sound (m/s) from the campaign facts, or None when they do not tell.

    ``speed_of_sound_m_s`` when given, else ``331.3 sqrt(1 + T/273.15)`` from
    ``weather.temperature_c``.

    >>> round(speed_of_sound({"weather": {"temperature_c": 20.0}}), 2)
    343.21
    """
    if not meta:
        return None
    c = meta.get("speed_of_sound_m_s")
    if c is not None and np.isfinite(c) and c > 0:
        return float(c)
    w = meta.get("weather") or {}
    t = w.get("temperature_c", meta.get("temperature_c"))
    if t is None or not np.isfinite(t):
        return None
    return float(331.3 * np.sqrt(1.0 + float(t) / 273.15))


def _c(x: Mapping[str, Any]) -> float:
    c = speed_of_sound(x.get("meta"))
    if c is None:
        raise InputError("speed of sound unknown: give meta speed_of_sound_m_s or weather temperature_c",
                         field="meta")
    return c


def _unit_to_mic(x: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors UAV -> microphone (n, 3) and path lengths (n,), from the ENU positions."""
    r = np.asarray(x["mic_enu"], dtype=float) - np.asarray(x["uav_enu"], dtype=float)
    d = np.linalg.norm(r, axis=-1)
    return r / np.maximum(d, 1e-9)[..., None], d


def mic_height_agl(x: Mapping[str, Any]) -> np.ndarray | None:
    """Microphone height above ground per row (m), or None when the data do not tell.

    From the input ``mic_agl`` when given, else from ``meta["microphones"]`` (a
    list of objects with ``id``, or a mapping id -> object) with ``height_agl_m``
    (or ``mount == "ground_plate"``: 0 m), matched to the rows by the input
    ``mic`` (ids) or else by microphone position (``enu``).
    """
    v = x.get("mic_agl")
    if v is not None:
        return np.asarray(v, dtype=float)
    meta = x.get("meta") or {}
    mics = meta.get("microphones")
    if not mics or "mic_enu" not in x:
        return None
    mic_enu = np.asarray(x["mic_enu"], dtype=float)
    h = np.full(len(mic_enu), np.nan)
    ids = x.get("mic")
    if isinstance(mics, Mapping):
        mics = [{"id": k, **v} for k, v in mics.items()]
    for m in mics:
        hm = m.get("height_agl_m", m.get("height_m"))
        if hm is None and m.get("mount") == "ground_plate":
            hm = 0.0
        if hm is None:
            continue
        if ids is not None and "id" in m:
            h[np.asarray(ids) == m["id"]] = float(hm)
        elif "enu" in m:
            h[np.all(np.isclose(mic_enu, np.asarray(m["enu"], dtype=float), atol=0.01), axis=-1)] = float(hm)
    return None if np.all(np.isnan(h)) else h


def series_ids(x: Mapping[str, Any]) -> np.ndarray:
    """Id of the time series (one microphone, one flight) of each row.

    From the inputs ``mic`` and ``flight`` when given; else consecutive rows
    form a series while the microphone position stays and the emission time
    increases by at most 2 s.
    """
    t = np.asarray(x["t_e"], dtype=float)
    if x.get("mic") is not None and x.get("flight") is not None:
        key = np.char.add(np.char.add(np.asarray(x["mic"], dtype=str), "\x00"), np.asarray(x["flight"], dtype=str))
        return np.unique(key, return_inverse=True)[1].ravel()
    m = np.asarray(x["mic_enu"], dtype=float)
    new = np.ones(len(t), dtype=bool)
    new[1:] = np.any(m[1:] != m[:-1], axis=-1) | (np.diff(t) <= 0.0) | (np.diff(t) > 2.0)
    return np.cumsum(new) - 1


def _series_gradient(v: np.ndarray, t: np.ndarray, sid: np.ndarray) -> np.ndarray:
    """d v / d t along each series (rows sorted by time within a series), 0 for single rows."""
    out = np.zeros_like(v, dtype=float)
    order = np.lexsort((t, sid))
    s, ts, vs = sid[order], t[order], v[order]
    cuts = np.flatnonzero(np.diff(s)) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(s)], strict=True):
        if b - a >= 2:
            tt = ts[a:b]
            if np.all(np.diff(tt) > 0):
                out[order[a:b]] = np.gradient(vs[a:b], tt)
    return out


# --------------------------------------------------------------------------- bank angle


def _bank_term(q, x, d_ref, want_jac):
    s = np.abs(np.sin(np.asarray(x["bank"], dtype=float)))
    return q[0] * s, (s[..., None] if want_jac else None)


def _bank_check(x):
    b = np.abs(np.asarray(x["bank"], dtype=float))
    if not np.any(b > np.radians(5.0)):
        return "no bank angle above 5 deg in the data (no turning flight)"
    return None


BANK_ANGLE = Effect(
    name="bank_angle",
    params=("k_bank",),
    units=("dB",),
    start=(0.0,),
    bounds=((-20.0, 40.0),),
    needs=(("bank", "no roll angle in the flight logs"),),
    reads=("bank",),
    apply=additive(_bank_term),
    description="interaction noise in turning flight: k_bank |sin(bank)| (paper 5.3.1)",
    check=_bank_check,
)

# --------------------------------------------------------------------------- atmospheric absorption


def _absorption_term(q, x, d_ref, want_jac):
    s = -(np.asarray(x["d"], dtype=float) - d_ref) / 1000.0
    return q[0] * s, (s[..., None] if want_jac else None)


def _absorption_check(x):
    bands = x.get("bands")
    f = x.get("band_f")
    if bands is None or f is None:
        return "no one-third-octave band levels in the microphone files"
    b = np.asarray(bands, dtype=float)
    hi = np.asarray(f, dtype=float) >= 1000.0
    if b.ndim != 2 or not np.any(hi) or not np.any(np.isfinite(b[:, hi])):
        return "no band levels at or above 1 kHz, where absorption acts"
    return None


ATMOSPHERIC_ABSORPTION = Effect(
    name="atmospheric_absorption",
    params=("a_abs",),
    units=("dB/km",),
    start=(0.0,),
    bounds=((0.0, 100.0),),
    needs=(("d", "no distance"), ("bands", "no one-third-octave band levels in the microphone files")),
    reads=("d",),
    apply=additive(_absorption_term),
    description="uncorrected atmospheric absorption: -a_abs (d - d_ref)/1000 dB (paper 5.3.3, ISO 9613-1)",
    check=_absorption_check,
)

# --------------------------------------------------------------------------- ground reflection


def band_cos(u, want_deriv):
    """Cosine ``cos(u)`` averaged over a one-third-octave band about ``u`` (relative band edges).

    Returns ``C(u)`` and ``dC/du``; exact series near ``u = 0``.
    """
    a1, a2 = THIRD_OCTAVE
    u = np.asarray(u, dtype=float)
    small = np.abs(u) < 1e-3
    us = np.where(small, 1.0, u)
    num = np.sin(a2 * us) - np.sin(a1 * us)
    c = np.where(small, 1.0 - (a1 * a1 + a1 * a2 + a2 * a2) * u * u / 6.0, num / ((a2 - a1) * us))
    if not want_deriv:
        return c, None
    dnum = a2 * np.cos(a2 * us) - a1 * np.cos(a1 * us)
    dc = np.where(small, -(a1 * a1 + a1 * a2 + a2 * a2) * u / 3.0, (dnum * us - num) / ((a2 - a1) * us * us))
    return c, dc


def reflection_delay(x):
    """Delay of the ground-reflected path behind the direct one, s (flat ground under the microphone)."""
    h_m = mic_height_agl(x)
    if h_m is None:
        raise InputError("microphone heights above ground unknown: give input mic_agl or meta microphones "
                         "height_agl_m", field="mic_agl")
    c = _c(x)
    mic = np.asarray(x["mic_enu"], dtype=float)
    uav = np.asarray(x["uav_enu"], dtype=float)
    ground = mic[..., 2] - h_m
    h_s = np.maximum(uav[..., 2] - ground, 0.0)
    r_h2 = np.sum((uav[..., :2] - mic[..., :2]) ** 2, axis=-1)
    direct = np.sqrt(r_h2 + (h_s - h_m) ** 2)
    reflected = np.sqrt(r_h2 + (h_s + h_m) ** 2)
    tau = (reflected - direct) / c
    # on the ground (plate) the reflection is the pressure doubling the mount correction removes
    return np.where(h_m >= MIN_REFLECTION_HEIGHT_M, tau, np.nan)


MIN_REFLECTION_HEIGHT_M = 0.3
"""Microphones lower than this (m) count as on the ground: no interference term."""


def _ground_term(q, x, d_ref, want_jac):
    r, f = q[0], q[1]
    tau = np.asarray(x["tau_ground"], dtype=float) if "tau_ground" in x else reflection_delay(x)
    off = np.isnan(tau)
    tau = np.where(off, 0.0, tau)
    u = 2.0 * np.pi * f * tau
    cb, dcb = band_cos(u, want_jac)
    g = 1.0 + r * r + 2.0 * r * cb
    dl = np.where(off, 0.0, 10.0 * np.log10(g))
    if not want_jac:
        return dl, None
    k = np.where(off, 0.0, 10.0 / (LN10 * g))
    return dl, np.stack([k * (2.0 * r + 2.0 * cb), k * 2.0 * r * dcb * 2.0 * np.pi * tau], axis=-1)


def _ground_check(x):
    if speed_of_sound(x.get("meta")) is None:
        return "speed of sound unknown (campaign gives neither speed_of_sound_m_s nor temperature)"
    h = mic_height_agl(x)
    if h is None or np.any(np.isnan(h)):
        return "microphone heights above ground unknown"
    if not np.any(h >= MIN_REFLECTION_HEIGHT_M):
        return (f"all microphones on the ground (below {MIN_REFLECTION_HEIGHT_M:g} m): the mount correction "
                "covers the reflection")
    return None


def _ground_initial(x, resid):
    """Grid search of (R, f_g) on the residual (the offset is free), best least-squares match."""
    tau = reflection_delay(x)
    ok = np.isfinite(resid) & np.isfinite(tau)
    best, arg = np.inf, (0.0, 200.0)
    for f in np.geomspace(40.0, 4000.0, 90):
        cb, _ = band_cos(2.0 * np.pi * f * tau[ok], False)
        for r in (0.3, 0.6, 0.9):
            z = 10.0 * np.log10(1.0 + r * r + 2.0 * r * cb)
            z = z - z.mean()
            rr = resid[ok] - resid[ok].mean()
            s = float(np.sum((rr - z) ** 2))
            if s < best:
                best, arg = s, (r, f)
    return {"r_ground": arg[0], "f_ground": arg[1], "__trials__": 90}


GROUND_REFLECTION = Effect(
    name="ground_reflection",
    params=("r_ground", "f_ground"),
    units=("", "Hz"),
    start=(0.0, 200.0),
    bounds=((0.0, 1.0), (20.0, 8000.0)),
    needs=(("mic_enu", "no microphone positions"), ("uav_enu", "no UAV positions"),
           ("meta", "no campaign facts (weather, microphone heights)")),
    reads=("mic_enu", "uav_enu"),
    apply=additive(_ground_term),
    description="ground reflection at elevated microphones: 10 log10(1 + R^2 + 2R C(f_g tau)), comb in tau",
    check=_ground_check,
    initial=_ground_initial,
    tested=("r_ground",),
)

# --------------------------------------------------------------------------- Doppler


def mach_towards(x):
    e, _ = _unit_to_mic(x)
    v = np.asarray(x["vel_enu"], dtype=float)
    return np.sum(v * e, axis=-1) / _c(x)


def _doppler_term(q, x, d_ref, want_jac):
    m = np.asarray(x["mach_r"], dtype=float) if "mach_r" in x else mach_towards(x)
    s = -10.0 * np.log10(1.0 - m)
    return q[0] * s, (s[..., None] if want_jac else None)


def _doppler_check(x):
    if speed_of_sound(x.get("meta")) is None:
        return "speed of sound unknown (campaign gives neither speed_of_sound_m_s nor temperature)"
    v = np.linalg.norm(np.asarray(x["vel_enu"], dtype=float), axis=-1)
    if not np.any(v > 3.0):
        return "the UAV never moves faster than 3 m/s: no convective amplification to see"
    return None


DOPPLER = Effect(
    name="doppler",
    params=("q_doppler",),
    units=("",),
    start=(0.0,),
    bounds=((0.0, 20.0),),
    needs=(("vel_enu", "no UAV velocity"), ("uav_enu", "no UAV positions"), ("mic_enu", "no microphone positions"),
           ("meta", "no campaign facts (speed of sound)")),
    reads=("vel_enu", "uav_enu", "mic_enu"),
    apply=additive(_doppler_term),
    description="convective (Doppler) amplification: -q_doppler 10 log10(1 - M_r)",
    check=_doppler_check,
)

# --------------------------------------------------------------------------- emission time

_SHIFTED = ("d", "phi", "theta", "p_el")


def emission_covariates(x):
    sid = series_ids(x)
    t = np.asarray(x["t_e"], dtype=float)
    out = {}
    for k in _SHIFTED:
        v = np.broadcast_to(np.asarray(x[k], dtype=float), t.shape)
        if k == "phi":
            v = _unwrap_series(v, t, sid)
        out[f"rate_{k}"] = _series_gradient(v, t, sid)
    out["t_prop"] = np.broadcast_to(np.asarray(x["d"], dtype=float), t.shape) / _c(x)
    return out


def _unwrap_series(v, t, sid):
    out = v.copy()
    order = np.lexsort((t, sid))
    s = sid[order]
    cuts = np.flatnonzero(np.diff(s)) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(s)], strict=True):
        out[order[a:b]] = np.unwrap(v[order[a:b]])
    return out


def shifted_inputs(x, delta):
    xs = dict(x)
    xs["d"] = np.maximum(np.asarray(x["d"], dtype=float) + delta * x["rate_d"], 0.1)
    xs["phi"] = np.asarray(x["phi"], dtype=float) + delta * x["rate_phi"]
    xs["theta"] = np.clip(np.asarray(x["theta"], dtype=float) + delta * x["rate_theta"], -np.pi / 2, np.pi / 2)
    xs["p_el"] = np.maximum(np.asarray(x["p_el"], dtype=float) + delta * x["rate_p_el"], 1e-6)
    return xs


_DT = 1e-3  # s, step of the central difference along the time derivative of the inputs


def _emission_apply(base_kernel, p_base, q, x, d_ref, want_jac):
    if "rate_d" not in x:
        x = {**x, **emission_covariates(x)}
    tprop = np.asarray(x["t_prop"], dtype=float)
    delta = q[0] + q[1] * tprop
    l_uav, jb = base_kernel(p_base, shifted_inputs(x, delta), d_ref, want_jac)
    if not want_jac:
        return l_uav, None, None
    lp, _ = base_kernel(p_base, shifted_inputs(x, delta + _DT), d_ref, False)
    lm, _ = base_kernel(p_base, shifted_inputs(x, delta - _DT), d_ref, False)
    dl = (lp - lm) / (2.0 * _DT)
    return l_uav, jb, np.stack([dl, dl * tprop], axis=-1)


def _emission_check(x):
    if speed_of_sound(x.get("meta")) is None:
        return "speed of sound unknown (campaign gives neither speed_of_sound_m_s nor temperature)"
    if len(np.atleast_1d(x["t_e"])) < 10:
        return "fewer than 10 samples: no time series to shift"
    return None


EMISSION_TIME = Effect(
    name="emission_time",
    params=("dt_clock", "k_delay"),
    units=("s", ""),
    start=(0.0, 0.0),
    bounds=((-5.0, 5.0), (-2.0, 2.0)),
    needs=(("t_e", "no emission times"), ("mic_enu", "no microphone positions"), ("uav_enu", "no UAV positions"),
           ("meta", "no campaign facts (speed of sound)")),
    reads=("t_e", "mic_enu", "uav_enu"),
    apply=_emission_apply,
    description="time-base error: model at t_e + dt_clock + k_delay d/c (first order in the input rates)",
    check=_emission_check,
    covariates=emission_covariates,
)

# --------------------------------------------------------------------------- wind


def _wind_term(q, x, d_ref, want_jac):
    mic = np.asarray(x["mic_enu"], dtype=float)
    uav = np.asarray(x["uav_enu"], dtype=float)
    h = mic[..., :2] - uav[..., :2]
    rh = np.linalg.norm(h, axis=-1)
    e = h / np.maximum(rh, 1.0)[..., None]
    s = np.asarray(x["d"], dtype=float)[..., None] / 100.0 * e
    return s @ q, (s if want_jac else None)


def _wind_check(x):
    mic = np.asarray(x["mic_enu"], dtype=float)
    uav = np.asarray(x["uav_enu"], dtype=float)
    az = np.arctan2(mic[..., 0] - uav[..., 0], mic[..., 1] - uav[..., 1])
    r = np.hypot(np.mean(np.cos(az)), np.mean(np.sin(az)))
    if r > 0.95:
        return "sound travels in one direction only: wind direction not separable from the level offset"
    return None


WIND = Effect(
    name="wind",
    params=("w_east", "w_north"),
    units=("dB/100 m", "dB/100 m"),
    start=(0.0, 0.0),
    bounds=((-30.0, 30.0), (-30.0, 30.0)),
    needs=(("mic_enu", "no microphone positions"), ("uav_enu", "no UAV positions")),
    reads=("mic_enu", "uav_enu"),
    apply=additive(_wind_term),
    description="wind refraction and convection: (d/100 m) (w_east e_east + w_north e_north)",
    check=_wind_check,
)

# --------------------------------------------------------------------------- propeller speed


def _rpm_term(q, x, d_ref, want_jac):
    rpm = np.maximum(np.asarray(x["rpm"], dtype=float), 1e-9)
    s = 20.0 * np.log10(rpm / q[1])
    if not want_jac:
        return q[0] * s, None
    return q[0] * s, np.stack([s, np.full_like(s, -20.0 * q[0] / (LN10 * q[1]))], axis=-1)


def _rpm_check(x):
    rpm = np.asarray(x["rpm"], dtype=float)
    ok = np.isfinite(rpm) & (rpm > 0)
    if not np.any(ok):
        return "the rpm column has no positive values"
    if not np.all(ok):
        return "the rpm column has gaps (NaN or non-positive values)"
    if np.std(np.log(rpm)) < 1e-3:
        return "the propeller speed does not vary"
    return None


def _rpm_fixed(x):
    return {"rpm_ref": float(np.median(np.asarray(x["rpm"], dtype=float)))}


RPM = Effect(
    name="rpm",
    params=("k_rpm", "rpm_ref"),
    units=("", "1/min"),
    start=(0.0, 3000.0),
    bounds=((-10.0, 10.0), (1.0, 1e6)),
    needs=(("rpm", "no rpm column in the flight logs"),),
    reads=("rpm",),
    apply=additive(_rpm_term),
    description="propeller speed beyond power: k_rpm 20 log10(rpm / rpm_ref) (rpm_ref held fixed)",
    check=_rpm_check,
    fixed=_rpm_fixed,
    tested=("k_rpm",),
)

# --------------------------------------------------------------------------- background events


def _event_apply(base_kernel, p_base, q, x, d_ref, want_jac):
    l_uav, jb = base_kernel(p_base, x, d_ref, want_jac)
    win = np.asarray(x["event_window"], dtype=int)
    inside = win >= 0
    ev = np.full(l_uav.shape, -np.inf)
    if len(q):
        ev[inside] = np.asarray(q, dtype=float)[win[inside]]
    hi = np.maximum(l_uav, ev)
    total = np.where(inside, hi + 10.0 * np.log10(10.0 ** ((l_uav - hi) / 10.0) + 10.0 ** ((ev - hi) / 10.0)), l_uav)
    if not want_jac:
        return total, None, None
    w_ev = np.where(inside, 10.0 ** ((ev - total) / 10.0), 0.0)
    jb = jb * (1.0 - w_ev)[..., None]
    jq = np.zeros(l_uav.shape + (len(q),))
    if len(q):
        rows = np.flatnonzero(inside)
        jq[rows, win[inside]] = w_ev[inside]
    return total, jb, jq


def _event_covariates(x):
    """Event windows from the rows marked by the detector (input ``event_window``) or by the reader."""
    win = x.get("event_window")
    if win is None:
        raise InputError("background_event needs the input 'event_window' (window index per row, -1 outside)",
                         field="event_window")
    win = np.asarray(win, dtype=int)
    k = int(win.max()) + 1 if win.size and win.max() >= 0 else 0
    return {"event_window": win, "__params__": tuple(f"ev{j + 1}" for j in range(k))}


BACKGROUND_EVENT = Effect(
    name="background_event",
    params=(),
    units=(),
    start=(),
    bounds=(),
    needs=(("event_window", "no event windows detected"),),
    reads=("t_e", "mic_enu", "uav_enu"),
    apply=_event_apply,
    description="transient background events: model energetically summed with a level ev_j in window j",
    covariates=_event_covariates,
    dynamic=("dB", -20.0, 140.0),
)

for _e in (BANK_ANGLE, ATMOSPHERIC_ABSORPTION, GROUND_REFLECTION, DOPPLER, EMISSION_TIME, WIND, RPM,
           BACKGROUND_EVENT):
    register_effect(_e)

EFFECT_NAMES = tuple(_EFFECTS)
"""The SPEC's effect names, in library order."""
