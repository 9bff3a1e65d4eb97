"""Effects of how the UAV flies: turning flight (bank angle), convective amplification (Doppler), propeller speed.

Each is an :class:`~gisnoise.model.effect.Effect` with an additive term ``dL``
(dB) on ``L_UAV``; :mod:`gisnoise.model.effects` registers them in the library.
"""

from __future__ import annotations

import numpy as np

from gisnoise.model._inputs import sound_speed_of, speed_of_sound, unit_to_mic
from gisnoise.model.effect import Effect, additive

__all__ = ["BANK_ANGLE", "DOPPLER", "RPM", "mach_towards"]

_LN10 = float(np.log(10.0))

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

# --------------------------------------------------------------------------- Doppler


def mach_towards(x):
    """Mach number ``M_r`` of the UAV velocity towards the microphone, per row (needs the speed of sound)."""
    e, _ = unit_to_mic(x)
    v = np.asarray(x["vel_enu"], dtype=float)
    return np.sum(v * e, axis=-1) / sound_speed_of(x)


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

# --------------------------------------------------------------------------- propeller speed


def _rpm_term(q, x, d_ref, want_jac):
    rpm = np.maximum(np.asarray(x["rpm"], dtype=float), 1e-9)
    s = 20.0 * np.log10(rpm / q[1])
    if not want_jac:
        return q[0] * s, None
    return q[0] * s, np.stack([s, np.full_like(s, -20.0 * q[0] / (_LN10 * q[1]))], axis=-1)


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
