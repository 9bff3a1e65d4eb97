"""The design model: the plan's pattern flown once by the simulator, giving the samples of any design.

The pattern is flown by the simulator (:func:`gisnoise.simulate.run`, seeded by the
plan) with every repetition at the first base altitude; this gives the horizontal
track, heading, coordinated-turn bank, ground speed, level-flight pitch and electric
power at the simulator's rate.  Heights follow the pattern's own climb rule: the
racetrack climbs linearly along the first straight and turn of each later repetition,
so the height and vertical speed of every sample are linear in the altitudes,
``u = W h``, ``vz = W' h``; ``W`` and ``W'`` come from flying the pattern
(:class:`gisnoise.flight.PathBuilder`) with unit altitudes.  A design's pitch adds
the flight-path angle ``atan2(vz, v)`` to the level pitch, and its power adds the
power per m/s of climb or sink times the vertical speed; these slopes are measured on
two more simulator flights climbing and sinking between repetitions, so climbs cost
power exactly as in the simulator (the same random draws for the same seed).  Samples
are taken every ``1 / evaluation.rate_hz`` s per microphone at emission time; a sample
counts when the source-microphone distance is at most the signal-to-noise distance
(:func:`gisnoise.design.snr.snr_distance`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gisnoise.design.plan import Design, Plan, _renamed, _scenario_doc
from gisnoise.errors import ScenarioError
from gisnoise.flight import PathBuilder, fwd, right
from gisnoise.geo import emission_angles

__all__ = ["DesignModel"]

_TRANSITION_S = 8.0  # the simulator accelerates for 8 s before a horizontal pattern flown from rest


@dataclass(frozen=True, eq=False)
class DesignModel:
    """The pattern flown by the simulator, ready to give the samples of any design (see the module docstring).

    Attributes
    ----------
    plan : Plan
    t : ndarray, shape (n,)
        Sample times since the start of the pattern, s (emission time).
    e, n : ndarray, shape (n,)
        Horizontal UAV position, m.
    weights : ndarray, shape (n, k)
        Height of each sample is ``weights @ altitudes`` (m).
    vz_weights : ndarray, shape (n, k)
        Vertical speed of each sample is ``vz_weights @ altitudes`` (m/s).
    yaw, roll : ndarray, shape (n,)
        Heading and bank, rad (the same at every altitude).
    pitch_level : ndarray, shape (n,)
        Pitch in level flight, rad; a design adds its flight-path angle ``atan2(vz, v)``.
    power_level_w : ndarray, shape (n,)
        Electric power in level flight, W.
    power_per_climb, power_per_sink : ndarray, shape (n,)
        Change of electric power per m/s of climb and of sink, W s/m, measured on the
        simulator by flying the pattern climbing and sinking between repetitions.
    speed_m_s : ndarray, shape (n,)
        Horizontal ground speed, m/s.
    vel_en : ndarray, shape (n, 2)
        Horizontal ground velocity (east, north), m/s.
    repetition : ndarray of int, shape (n,)
        Repetition of the pattern each sample belongs to.
    track : dict of ndarray
        ``t``, ``e``, ``n``, ``weights`` at the simulator's rate, for drawing the track.
    start_en : ndarray, shape (2,)
        Where the simulated flight starts (it accelerates for 8 s into the pattern's entry), m.
    duration_s : float
        Duration of the pattern (all repetitions), s.
    speed_of_sound_m_s : float
        Of the plan's weather (as the simulator takes it), m/s; for ansatz extensions that need it.
    """

    plan: Plan
    t: np.ndarray
    e: np.ndarray
    n: np.ndarray
    weights: np.ndarray
    vz_weights: np.ndarray
    yaw: np.ndarray
    roll: np.ndarray
    pitch_level: np.ndarray
    power_level_w: np.ndarray
    power_per_climb: np.ndarray
    power_per_sink: np.ndarray
    speed_m_s: np.ndarray
    vel_en: np.ndarray
    repetition: np.ndarray
    track: dict[str, np.ndarray] = field(repr=False)
    start_en: np.ndarray = field(repr=False)
    duration_s: float = 0.0
    speed_of_sound_m_s: float = 340.0

    @classmethod
    def build(cls, plan: Plan, *, calibration_step_m: float = 50.0) -> DesignModel:
        """Fly the plan's pattern with the simulator and derive the height weights.

        Three flights of the simulator: every repetition at the first base altitude
        (level flight), and climbing and sinking by ``calibration_step_m`` between
        repetitions; the power change over the vertical speed gives the power per m/s
        of climb and of sink at every sample (the simulator's power law and its slow
        random part, the same draws for the same seed), so a design's power follows
        its climbs without a second statement of the power law.
        """
        from gisnoise.simulate import run

        pat = plan.doc["pattern"]
        heading = math.radians(pat["heading_deg"])
        turn = 1 if pat["turn"] == "right" else -1
        v, radius, straight = pat["speed_m_s"], pat["radius_m"], pat["straight_m"]
        centre = np.array(pat["centre"], dtype=float)
        entry = centre - 0.5 * straight * fwd(heading) - turn * radius * right(heading)
        # the simulator accelerates from rest for 8 s along the heading before a horizontal pattern:
        # start that far before the entry so the pattern is flown from its entry, without a joining path
        start = entry - 0.5 * v * _TRANSITION_S * fwd(heading)
        k_reps = plan.n_reps
        h0 = float(plan.base.altitudes[0])
        mics = plan.doc["microphones"]

        def fly(heights: np.ndarray) -> dict[str, np.ndarray]:
            d = Design(plan.base.mic_e, plan.base.mic_n, heights)
            try:
                res = run(_scenario_doc(plan.doc, plan.card, d, mics, seed=plan.seed, start=start, noise=False))
            except ScenarioError as exc:
                raise _renamed(exc) from None
            tr = res.flights[0].true
            i0 = int(np.argmax(tr["phase"] == "horizontal"))
            out = {k: np.asarray(tr[k])[i0:] for k in ("t", "e", "n", "u", "yaw", "pitch", "roll", "power_w")}
            out["vel"] = np.asarray(tr["vel"][i0:], dtype=float)
            out["t"] = out["t"] - out["t"][0]
            out["dt"] = np.array(1.0 / float(res.scenario.doc["output"]["sim_rate_hz"]))
            out["c"] = np.array(res.scenario.c)
            return out

        sim = fly(np.full(k_reps, h0))
        dt = float(sim["dt"])
        cols, vcols = [], []
        for k in range(k_reps):
            unit = [1.0 if j == k else 0.0 for j in range(k_reps)]
            b = PathBuilder(e=float(entry[0]), n=float(entry[1]), u=unit[0], heading=heading, dt=dt, speed=v)
            b.racetrack(centre, heading, straight, radius, unit, pat["laps"], v, turn, math.radians(6.0))
            p = b.finish()
            cols.append(p["u"])
            vcols.append(p["vz"])
        w, wv = np.column_stack(cols), np.column_stack(vcols)
        if (len(w) != len(sim["t"]) or np.max(np.abs(p["e"] - sim["e"])) > 1e-6
                or np.max(np.abs(p["n"] - sim["n"])) > 1e-6 or np.max(np.abs(w.sum(axis=1) - 1.0)) > 1e-9):
            raise RuntimeError("design model: the pattern flown by the simulator and by the path builder differ")
        per_climb = np.zeros(len(w))
        per_sink = np.zeros(len(w))
        if k_reps > 1:
            step = calibration_step_m * np.arange(k_reps)
            for heights, out in ((h0 + step, per_climb), (h0 + step[::-1], per_sink)):
                f = fly(heights)
                vz = wv @ heights
                moving = np.abs(vz) > 1e-6
                out[moving] = (f["power_w"][moving] - sim["power_w"][moving]) / vz[moving]
        rep_s = pat["laps"] * (2.0 * straight + 2.0 * math.pi * radius) / v
        step_i = max(1, int(round(1.0 / (plan.doc["evaluation"]["rate_hz"] * dt))))
        idx = np.arange(0, len(sim["t"]), step_i)
        t = sim["t"][idx]
        rep = np.minimum((t / rep_s).astype(int), k_reps - 1)
        vel = sim["vel"][idx]
        return cls(plan=plan, t=t, e=sim["e"][idx], n=sim["n"][idx], weights=w[idx], vz_weights=wv[idx],
                   yaw=sim["yaw"][idx], roll=sim["roll"][idx], pitch_level=sim["pitch"][idx],
                   power_level_w=sim["power_w"][idx], power_per_climb=per_climb[idx], power_per_sink=per_sink[idx],
                   speed_m_s=np.hypot(vel[:, 0], vel[:, 1]), vel_en=vel[:, :2], repetition=rep,
                   track={"t": sim["t"], "e": sim["e"], "n": sim["n"], "weights": w}, start_en=start,
                   duration_s=float(sim["t"][-1]), speed_of_sound_m_s=float(sim["c"]))

    @property
    def rate_hz(self) -> float:
        return float(self.plan.doc["evaluation"]["rate_hz"])

    def state(self, altitudes: np.ndarray) -> dict[str, np.ndarray]:
        """Height ``u`` (m), vertical speed ``vz`` (m/s), ``pitch`` (rad) and ``power_w`` (W) of the
        pattern flown at ``altitudes`` (shape (S, k)), each of shape (S, n)."""
        h = np.asarray(altitudes, dtype=float)
        u = h @ self.weights.T
        vz = h @ self.vz_weights.T
        power = (self.power_level_w + self.power_per_climb * np.maximum(vz, 0.0)
                 + self.power_per_sink * np.minimum(vz, 0.0))
        pitch = self.pitch_level + np.arctan2(vz, self.speed_m_s)  # plus the flight-path angle
        return {"u": u, "vz": vz, "pitch": pitch, "power_w": power}

    def samples_batch(self, mic_e: np.ndarray, mic_n: np.ndarray, altitudes: np.ndarray) -> dict[str, np.ndarray]:
        """Geometry and flight state of ``S`` designs at once, each row microphone-major over the samples.

        Parameters
        ----------
        mic_e, mic_n : ndarray, shape (S, m)
            Microphone positions, m.
        altitudes : ndarray, shape (S, k)
            Altitude of each repetition, m.

        Returns
        -------
        dict
            ``d`` (m), ``phi``, ``theta`` (rad), ``u`` (UAV height, m), ``vz`` (m/s),
            ``pitch`` (rad), ``power_w`` (W) and ``usable`` (distance within the
            signal-to-noise distance), shape (S, m n); ``mic`` (microphone index) and
            ``sample`` (index into the pattern's samples), shape (m n,).
        """
        plan = self.plan
        m, k = plan.n_mics, len(self.t)
        st = self.state(altitudes)
        n_s = st["u"].shape[0]
        de = np.asarray(mic_e, dtype=float)[:, :, None] - self.e[None, None, :]
        dn = np.asarray(mic_n, dtype=float)[:, :, None] - self.n[None, None, :]
        du = plan.mic_height_m[None, :, None] - st["u"][:, None, :]
        d, phi, theta = emission_angles(de, dn, du, self.yaw, st["pitch"][:, None, :], self.roll)
        d = d.reshape(n_s, m * k)

        def per_mic(a: np.ndarray) -> np.ndarray:
            return np.broadcast_to(a[:, None, :], (n_s, m, k)).reshape(n_s, m * k)

        return {"d": d, "phi": phi.reshape(n_s, m * k), "theta": theta.reshape(n_s, m * k),
                "u": per_mic(st["u"]), "vz": per_mic(st["vz"]), "pitch": per_mic(st["pitch"]),
                "power_w": per_mic(st["power_w"]), "usable": d <= plan.max_distance_m,
                "mic": np.repeat(np.arange(m), k), "sample": np.tile(np.arange(k), m)}

    def samples(self, design: Design) -> dict[str, np.ndarray]:
        """Per (microphone, sample) geometry of one design: :meth:`samples_batch` with ``S = 1``, squeezed."""
        b = self.samples_batch(design.mic_e[None, :], design.mic_n[None, :], design.altitudes[None, :])
        return {k: (v[0] if v.ndim == 2 else v) for k, v in b.items()}

    def model_inputs(self, s: Mapping[str, np.ndarray], *, design: Design | None = None) -> dict[str, Any]:
        """Ansatz inputs of the samples ``s`` (from :meth:`samples` or :meth:`samples_batch`), all rows.

        The names are those of :meth:`gisnoise.measure.samples.Samples.inputs`; vector inputs
        (``uav_enu``, ``mic_enu``, ``vel_enu``) need ``design`` and a single design's samples.
        """
        card = self.plan.card
        j = s["sample"]
        x: dict[str, Any] = {"d": s["d"], "phi": s["phi"], "theta": s["theta"],
                             "p_el": s["power_w"] / card.reference_power_w, "bank": self.roll[j],
                             "roll": np.degrees(self.roll[j]), "pitch": np.degrees(s["pitch"]),
                             "yaw": np.degrees(self.yaw[j]), "speed": np.hypot(self.speed_m_s[j], s["vz"]),
                             "t_e": self.t[j], "mic_agl": self.plan.mic_height_m[s["mic"]],
                             "meta": {"speed_of_sound_m_s": self.speed_of_sound_m_s,
                                      "weather": dict(self.plan.doc["weather"])}}
        if design is not None and s["d"].ndim == 1:
            mi = s["mic"]
            x["uav_enu"] = np.column_stack([self.e[j], self.n[j], s["u"]])
            x["mic_enu"] = np.column_stack([design.mic_e[mi], design.mic_n[mi], self.plan.mic_height_m[mi]])
            x["vel_enu"] = np.column_stack([self.vel_en[j], s["vz"]])
        return x
