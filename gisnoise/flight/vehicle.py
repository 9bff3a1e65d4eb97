"""The vehicle power model: electric power of a lift+cruise eVTOL UAV in hover, climb, transition
and wing-borne flight (SI units).

Rotors by momentum theory, ``P = (T^1.5 / (FM sqrt(2 rho A)) + T w+ + T w-/2) / eta_motor``
for thrust ``T`` and climb rate ``w``; wing-borne ``P = (D v + m a v + m g w) / eta_prop``
with drag ``D = q S (CD0 + CL^2 / (pi e AR))`` and lift ``n f m g`` (load factor
``n = 1/cos bank``); in transition the wing carries the fraction ``f = (v / v_transition)^2``
of the weight and the rotors the rest; plus a constant systems power.  The defaults give
a 35 kg cargo eVTOL about 2.5 kW in cruise at 25 m/s and 7.8 kW in hover: the vehicle of the sample
campaign the bundled demo cards were fitted on (its scenario's hover power, 2.6 x the 3000 W reference
power; a rotor figure of merit of 0.47), so that routes without a vehicle of their own fly those cards
at the powers they were fitted at.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from gisnoise.errors import InputError

__all__ = ["VehicleModel", "GRAVITY"]

GRAVITY = 9.80665


@dataclass(frozen=True)
class VehicleModel:
    """Performance and power model of a lift+cruise eVTOL UAV (SI units).

    The defaults describe a 35 kg cargo eVTOL with four 0.75 m lift rotors and a
    1.5 m^2 wing.  See the module docstring for the equations.

    Examples
    --------
    >>> v = VehicleModel()
    >>> round(v.hover_power_w())
    7800
    >>> round(float(v.power_w(25.0, 0.0, 0.0, 0.0)))
    2547
    """

    mass_kg: float = 35.0
    air_density_kg_m3: float = 1.225
    rotor_disk_area_m2: float = 1.767
    figure_of_merit: float = 0.47
    motor_efficiency: float = 0.85
    wing_area_m2: float = 1.5
    aspect_ratio: float = 12.0
    oswald_efficiency: float = 0.8
    cd0: float = 0.08
    propulsive_efficiency: float = 0.55
    systems_power_w: float = 150.0
    cruise_speed_m_s: float = 25.0
    transition_speed_m_s: float = 18.0
    climb_rate_m_s: float = 3.0
    sink_rate_m_s: float = 2.0
    multicopter_speed_m_s: float = 5.0
    max_bank_deg: float = 30.0
    acceleration_m_s2: float = 1.5
    vertical_acceleration_m_s2: float = 1.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise InputError(f"vehicle: field '{f.name}' must be a positive number, got {v!r}",
                                 field=f"vehicle.{f.name}")
        if not 0 < self.max_bank_deg < 80:
            raise InputError(f"vehicle: field 'max_bank_deg' must be in (0, 80), got {self.max_bank_deg}",
                             field="vehicle.max_bank_deg")
        for name in ("figure_of_merit", "motor_efficiency", "propulsive_efficiency"):
            if getattr(self, name) > 1:
                raise InputError(f"vehicle: field '{name}' must be <= 1, got {getattr(self, name)}",
                                 field=f"vehicle.{name}")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> VehicleModel:
        if d is None:
            return cls()
        if not isinstance(d, Mapping):
            raise InputError("vehicle: must be an object of field -> number", field="vehicle")
        known = {f.name for f in fields(cls)}
        extra = [k for k in d if k not in known and k not in ("name", "reference_power_w")]
        if extra:
            raise InputError(f"vehicle: unknown field {extra[0]!r}; known: {', '.join(sorted(known))}",
                             field=f"vehicle.{extra[0]}")
        return cls(**{k: v for k, v in d.items() if k in known})

    @property
    def weight_n(self) -> float:
        return self.mass_kg * GRAVITY

    def rotor_power_w(self, thrust_n: Any, climb_m_s: Any = 0.0) -> np.ndarray:
        """Electric power of the lift rotors for thrust ``T`` (N) and climb rate ``w`` (m/s), W."""
        t = np.maximum(np.asarray(thrust_n, dtype=float), 0.0)
        w = np.asarray(climb_m_s, dtype=float)
        induced = t ** 1.5 / (self.figure_of_merit * math.sqrt(2.0 * self.air_density_kg_m3 * self.rotor_disk_area_m2))
        p = induced + t * np.maximum(w, 0.0) + 0.5 * t * np.minimum(w, 0.0)
        return np.maximum(p, 0.3 * induced) / self.motor_efficiency

    def hover_power_w(self) -> float:
        """Electric power in hover, W."""
        return float(self.rotor_power_w(self.weight_n)) + self.systems_power_w

    def power_w(self, speed_m_s: Any, climb_m_s: Any, bank_rad: Any, accel_m_s2: Any,
                wing_fraction: Any = 1.0) -> np.ndarray:
        """Electric power in forward flight, W; arrays broadcast.

        Parameters
        ----------
        speed_m_s : airspeed along the path (no wind), m/s.
        climb_m_s : vertical speed, m/s.
        bank_rad : bank angle, rad.
        accel_m_s2 : longitudinal acceleration, m/s^2.
        wing_fraction : share of the weight the wing carries (1 wing-borne, 0 hover).
        """
        v = np.maximum(np.asarray(speed_m_s, dtype=float), 0.0)
        w = np.asarray(climb_m_s, dtype=float)
        f = np.clip(np.asarray(wing_fraction, dtype=float), 0.0, 1.0)
        n = 1.0 / np.cos(np.asarray(bank_rad, dtype=float))
        q = 0.5 * self.air_density_kg_m3 * v * v
        qs = q * self.wing_area_m2
        lift = n * f * self.weight_n
        with np.errstate(divide="ignore", invalid="ignore"):
            induced = np.where(qs > 0, lift * lift / np.where(qs > 0, qs, 1.0)
                               / (math.pi * self.oswald_efficiency * self.aspect_ratio), 0.0)
        drag = qs * self.cd0 + induced
        wing = (drag * v + self.mass_kg * np.asarray(accel_m_s2, dtype=float) * v
                + self.weight_n * w * (f > 0)) / self.propulsive_efficiency
        rotors = np.where(f < 1.0, self.rotor_power_w((1.0 - f) * self.weight_n, np.where(f > 0, 0.0, w)), 0.0)
        return np.maximum(wing, 0.0) + rotors + self.systems_power_w

    def wing_fraction(self, speed_m_s: Any) -> np.ndarray:
        """Share of the weight on the wing at ``speed_m_s``: ``min(1, (v / v_transition)^2)``."""
        return np.clip((np.asarray(speed_m_s, dtype=float) / self.transition_speed_m_s) ** 2, 0.0, 1.0)
