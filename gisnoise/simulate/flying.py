"""Flying a scenario's flights: patterns into the true state at the simulation rate, and the flight log.

The flight is flown at ``output.sim_rate_hz`` from its patterns
(:mod:`gisnoise.flight.patterns`): vertical climb and sink, hover with slow yaw,
transitions, racetrack loops and fly-bys joined by Dubins paths.  Turns are
coordinated: bank ``atan(v^2 / (g R))`` with ground speed ``v`` and radius ``R``.
Yaw follows the air-relative velocity (crab angle in wind), pitch is
``vehicle.pitch_deg`` plus the flight-path angle, electric power follows a
parasitic + induced + climb power law with a slow random part, and propeller
speed follows power (``rpm ~ P^(1/3)``) with a slow random part of its own.
The flight log (``output.log_rate_hz``) is the true state sampled, with the log
noise of ``vehicle.log_noise`` added (and the clock offset of the ``emission_time``
effect).

Examples
--------
>>> round(float(np.degrees(coordinated_bank(24.0, 80.0))), 2)
36.29
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gisnoise.flight import G, PathBuilder
from gisnoise.geo import wrap_angle
from gisnoise.simulate._random import ou_process, seeded_rng
from gisnoise.simulate.scenario import Scenario

__all__ = ["coordinated_bank"]

_MAX_CLIMB_ANGLE = math.radians(6.0)
"""Steepest flight-path angle of wing-borne height changes, rad."""


def coordinated_bank(speed_m_s: Any, radius_m: Any) -> np.ndarray:
    """Bank angle of a coordinated turn, ``atan(v^2 / (g R))``, rad.

    Parameters
    ----------
    speed_m_s : float or array_like
        Speed, m/s.
    radius_m : float or array_like
        Turn radius, m (``inf`` on a straight gives 0).
    """
    v = np.asarray(speed_m_s, dtype=float)
    return np.arctan(v * v / (G * np.asarray(radius_m, dtype=float)))


def _interp_angle(t: np.ndarray, tp: np.ndarray, a_rad: np.ndarray) -> np.ndarray:
    """Angles (rad) at times ``t`` interpolated on the circle from samples ``a_rad`` at ``tp``."""
    return np.arctan2(np.interp(t, tp, np.sin(a_rad)), np.interp(t, tp, np.cos(a_rad)))


def _fly(fl: Mapping[str, Any], dt: float) -> PathBuilder:
    st = fl["start"]
    b = PathBuilder(e=st["e"], n=st["n"], u=st["height_m"], heading=math.radians(st["heading_deg"]), dt=dt)
    for p in fl["patterns"]:
        t = p["type"]
        if t in ("climb", "sink"):
            if b.speed > 0:
                b.transition(max(2.0, b.speed / 3.0), 0.0)
            b.vertical(p["to_height_m"], p["rate_m_s"], math.radians(p["yaw_rate_deg_s"]))
        elif t == "hover":
            if b.speed > 0:
                b.transition(max(2.0, b.speed / 3.0), 0.0)
            b.hover(p["duration_s"], math.radians(p["yaw_rate_deg_s"]))
        elif t == "transition":
            b.transition(p["duration_s"], p["to_speed_m_s"])
        else:
            if b.speed < 1.0:  # leaving multicopter flight: accelerate first
                b.transition(8.0, p["speed_m_s"])
            if t == "racetrack":
                b.racetrack(np.array(p["centre"]), math.radians(p["heading_deg"]), p["straight_m"], p["radius_m"],
                            p["heights_m"], p["laps"], p["speed_m_s"], 1 if p["turn"] == "right" else -1,
                            _MAX_CLIMB_ANGLE)
            elif t == "flyby":
                b.flyby(np.array(p["through"]), math.radians(p["heading_deg"]), p["length_m"], p["radius_m"],
                        p["height_m"], p["speed_m_s"], _MAX_CLIMB_ANGLE)
            else:
                h = None if p["heading_deg"] is None else math.radians(p["heading_deg"])
                b.approach(np.array(p["to"]), h, p["radius_m"], p["speed_m_s"], p["height_m"], _MAX_CLIMB_ANGLE)
    return b


@dataclass
class _Flight:
    """One simulated flight: the true state at the simulation rate and the log."""

    id: str
    start_utc: str
    true: dict[str, np.ndarray]
    log: dict[str, np.ndarray]
    turns: list[tuple[float, float, float, float]]
    phases: list[tuple[float, float, str]]
    events: list[dict[str, Any]] = field(default_factory=list)


def _state(sc: Scenario, fl: Mapping[str, Any], index: int) -> _Flight:
    """Fly one flight and derive attitude, airspeed, power and rpm; sample the log."""
    doc = sc.doc
    veh = doc["vehicle"]
    b = _fly(fl, 1.0 / doc["output"]["sim_rate_hz"])
    p = b.finish()
    t = p["t"]
    n = len(t)
    w = doc["weather"]
    to = math.radians(w["wind_from_deg"]) + math.pi
    wind = w["wind_speed_m_s"] * np.array([math.sin(to), math.cos(to)])
    vg = np.stack([p["speed"] * np.sin(p["track"]), p["speed"] * np.cos(p["track"])], axis=1)
    va = vg - wind
    airspeed = np.hypot(va[:, 0], va[:, 1])
    phase = p["phase"]
    wing = (phase == "horizontal") | (phase == "transition")
    # the nose points along the air-relative velocity in wing-borne flight (crab angle in wind), along the
    # track in transitions, and where the pattern sets it (hover, vertical flight)
    yaw = np.where(np.isnan(p["yaw"]), np.where(phase == "horizontal", np.arctan2(va[:, 0], va[:, 1]), p["track"]),
                   p["yaw"])
    bank = np.where(np.isfinite(p["radius"]), np.sign(p["radius"]) * coordinated_bank(p["speed"], np.abs(p["radius"])),
                    0.0)
    gamma = np.arctan2(p["vz"], np.maximum(p["speed"], 1e-9))
    pitch = np.where(wing, math.radians(veh["pitch_deg"]) + gamma, 0.0)
    # electric power: parasitic ~ V^3, induced ~ n^2 / V, climb m g vz / eta; hover/vertical from hover power
    pw = veh["power"]
    vr = np.maximum(airspeed, 0.3 * veh["cruise_speed_m_s"]) / veh["cruise_speed_m_s"]
    nload2 = 1.0 / np.cos(bank) ** 2
    # climbing costs m g vz / efficiency; descending gives back only part of m g |vz| (throttle reduced)
    climb_w = veh["mass_kg"] * G * p["vz"] * np.where(p["vz"] > 0, 1.0 / pw["efficiency"], 0.5 * pw["efficiency"])
    cruise = pw["cruise_w"] * (pw["parasitic_fraction"] * vr ** 3 + (1 - pw["parasitic_fraction"]) * nload2 / vr)
    vert = pw["hover_w"] + climb_w
    frac = np.clip(p["speed"] / veh["cruise_speed_m_s"], 0.0, 1.0)
    power = np.select([phase == "horizontal", phase == "transition"],
                      [cruise + climb_w, frac * (cruise + climb_w) + (1 - frac) * pw["hover_w"]], vert)
    rng = seeded_rng(sc.seed, index, 1)
    power = power * np.exp(ou_process(rng, t, pw["jitter_pct"] / 100.0, pw["jitter_tau_s"]))
    power = np.maximum(power, 0.05 * pw["cruise_w"])
    rp = veh["rpm"]
    rpm_p = np.where(wing, rp["cruise_rpm"] * (power / pw["cruise_w"]) ** (1 / 3),
                     rp["hover_rpm"] * (power / pw["hover_w"]) ** (1 / 3))
    rpm = rpm_p * np.exp(ou_process(rng, t, rp["jitter_pct"] / 100.0, rp["jitter_tau_s"]))
    vel = np.stack([vg[:, 0], vg[:, 1], p["vz"]], axis=1)
    true = {"t": t, "e": p["e"], "n": p["n"], "u": p["u"], "yaw": wrap_angle(yaw), "pitch": pitch, "roll": bank,
            "power_w": power, "rpm": rpm, "rpm_p": rpm_p, "airspeed_m_s": airspeed, "phase": phase, "vel": vel,
            "turn": p["turn"]}
    if "bank_angle" in doc["effects"]:
        ef = doc["effects"]["bank_angle"]
        true["bank_fluct"] = ou_process(seeded_rng(sc.seed, index, 2), t, 1.0, ef["fluctuation_tau_s"])
    # ---- the flight log
    lr = doc["output"]["log_rate_hz"]
    tl = np.arange(0.0, t[-1], 1.0 / lr)
    if t[-1] - tl[-1] > 1e-9:
        tl = np.append(tl, t[-1])
    lrng = seeded_rng(sc.seed, index, 3)
    ln = veh["log_noise"]
    m = len(tl)
    log = {"t": tl.copy()}
    for k in ("e", "n", "u"):
        log[k] = np.interp(tl, t, true[k]) + lrng.normal(0.0, ln["position_m"], m)
    for k in ("yaw", "pitch", "roll"):
        log[k] = _interp_angle(tl, t, true[k]) + lrng.normal(0.0, math.radians(ln["attitude_deg"]), m)
    log["power_w"] = np.interp(tl, t, power) * (1.0 + lrng.normal(0.0, ln["power_pct"] / 100.0, m))
    log["power_w"] = np.maximum(log["power_w"], 1.0)
    log["rpm"] = np.interp(tl, t, rpm)
    log["airspeed_m_s"] = np.interp(tl, t, airspeed)
    idx = np.clip(np.searchsorted(t, tl, side="right") - 1, 0, n - 1)
    log["phase"] = phase[idx]
    if "emission_time" in doc["effects"]:
        log["t"] = log["t"] + doc["effects"]["emission_time"]["offset_s"]
    return _Flight(id=fl["id"], start_utc=fl["start_utc"], true=true, log=log, turns=list(b.turns),
                   phases=list(b.phases))

