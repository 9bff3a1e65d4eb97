"""The effect library: the candidate effects by name, and ansatzes extended by them by name.

An effect (:class:`~gisnoise.model.effect.Effect`) is one unmodelled physical
effect written as an extension of a base ansatz with its own parameters and an
analytic Jacobian.  This module holds the registry of effects: the eight of the
SPEC are registered at import, in library order (:data:`EFFECT_NAMES`), and with
each the single-effect extension of every base ansatz registered so far
(``"paper-offset+bank_angle"`` and so on).  :func:`extend` builds (and
registers) any other combination, and :func:`get_ansatz` looks an ansatz up by
name, building a chain ``"base+e1+e2"`` from its parts on demand.

The effects themselves are defined by physics: the way the UAV flies
(``bank_angle``, ``doppler``, ``rpm``), the sound path
(``atmospheric_absorption``, ``ground_reflection``, ``wind``) and time
(``emission_time``, ``background_event``).

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

from gisnoise.errors import InputError
from gisnoise.model._flight_effects import BANK_ANGLE, DOPPLER, RPM, mach_towards
from gisnoise.model._inputs import mic_height_agl, series_ids, speed_of_sound
from gisnoise.model._propagation_effects import (
    ATMOSPHERIC_ABSORPTION,
    GROUND_REFLECTION,
    MIN_REFLECTION_HEIGHT_M,
    THIRD_OCTAVE,
    WIND,
    band_cos,
    reflection_delay,
)
from gisnoise.model._time_effects import BACKGROUND_EVENT, EMISSION_TIME, emission_covariates, shifted_inputs
from gisnoise.model.ansatz import _REGISTRY, Ansatz, ansatz_names, register_ansatz
from gisnoise.model.effect import Effect, _extended, additive, bind, check_testable

__all__ = [
    "Effect",
    "register_effect",
    "get_effect",
    "effect_names",
    "extend",
    "get_ansatz",
    "bind",
    "check_testable",
    "additive",
    "speed_of_sound",
    "mic_height_agl",
    "series_ids",
    "reflection_delay",
    "band_cos",
    "mach_towards",
    "emission_covariates",
    "shifted_inputs",
    "THIRD_OCTAVE",
    "MIN_REFLECTION_HEIGHT_M",
    "EFFECT_NAMES",
    "BANK_ANGLE",
    "ATMOSPHERIC_ABSORPTION",
    "GROUND_REFLECTION",
    "DOPPLER",
    "EMISSION_TIME",
    "WIND",
    "RPM",
    "BACKGROUND_EVENT",
]

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
    a = get_ansatz(base) if isinstance(base, str) else base
    for e in effects:
        a = _extended(a, get_effect(e) if isinstance(e, str) else e)
    if register:
        register_ansatz(a, replace=True)
    return a


def get_ansatz(name: str) -> Ansatz:
    """Look an ansatz up by name; a chain ``"base+e1+e2"`` of registered effects is built on demand.

    The error lists the known names.

    Examples
    --------
    >>> get_ansatz("paper-offset+rpm+wind").params[-4:]
    ('k_rpm', 'rpm_ref', 'w_east', 'w_north')
    """
    if name not in _REGISTRY:
        base, *chain = name.split("+")
        if chain and base in _REGISTRY:
            try:
                extend(base, *chain, register=True)
            except InputError as exc:
                raise InputError(f"unknown ansatz {name!r}: {exc}", field="ansatz") from None
    try:
        return _REGISTRY[name]
    except KeyError:
        raise InputError(
            f"unknown ansatz {name!r}; known: {', '.join(sorted(_REGISTRY))}", field="ansatz"
        ) from None


for _e in (BANK_ANGLE, ATMOSPHERIC_ABSORPTION, GROUND_REFLECTION, DOPPLER, EMISSION_TIME, WIND, RPM,
           BACKGROUND_EVENT):
    register_effect(_e)

EFFECT_NAMES = tuple(_EFFECTS)
"""The SPEC's effect names, in library order."""
