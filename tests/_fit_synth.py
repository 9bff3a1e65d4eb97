"""Synthetic flight campaigns with a known truth for the fit tests.

Racetrack loops with coordinated turns at several altitudes and speeds over
three ground microphones; levels from the ansatz itself (one model definition)
plus seeded Gaussian noise per microphone, optionally AR(1)-coloured.
"""

from __future__ import annotations

import numpy as np

from gisnoise.geo import emission_angles
from gisnoise.measure import Samples
from gisnoise.model import get_ansatz

TRUTH = {"p0": 64.0, "p1": 20.0, "p2": 0.08, "p3": -0.28, "p4": -0.2, "p5": 1.05, "p6": 1.0, "p7": 40.0}
NOISE = {"m1": 0.8, "m2": 1.2, "m3": 1.6}
MICS = {"m1": (0.0, -60.0, 1.2), "m2": (250.0, 120.0, 1.2), "m3": (-320.0, 30.0, 1.2)}
REF_W = 3000.0
G = 9.80665


def racetrack(altitudes=(40.0, 90.0, 150.0), speeds=(22.0, 26.0, 30.0), leg_m=700.0, radius_m=160.0,
              dt=0.125, seed=0):
    """UAV states along racetrack loops: t, ENU position, velocity, yaw/pitch/roll (rad), P_el."""
    rng = np.random.default_rng(seed)
    out = {k: [] for k in ("t", "e", "n", "u", "ve", "vn", "yaw", "pitch", "roll", "p_el")}
    t0 = 0.0
    loop_len = 2 * leg_m + 2 * np.pi * radius_m
    for j, h in enumerate(altitudes):
        for v in speeds:
            n_s = int(loop_len / v / dt)
            s = np.arange(n_s) * v * dt
            e = np.empty(n_s)
            nn = np.empty(n_s)
            head = np.empty(n_s)  # heading from north, clockwise
            bank = np.zeros(n_s)
            phi_b = np.arctan(v * v / (G * radius_m))
            a = s < leg_m  # eastbound leg along n = -R
            e[a], nn[a], head[a] = -leg_m / 2 + s[a], -radius_m, np.pi / 2
            b = (s >= leg_m) & (s < leg_m + np.pi * radius_m)  # turn left around (leg/2, 0)
            ang = (s[b] - leg_m) / radius_m
            e[b], nn[b] = leg_m / 2 + radius_m * np.sin(ang), -radius_m * np.cos(ang)
            head[b], bank[b] = np.pi / 2 - ang, -phi_b
            c = (s >= leg_m + np.pi * radius_m) & (s < 2 * leg_m + np.pi * radius_m)
            sc = s[c] - leg_m - np.pi * radius_m
            e[c], nn[c], head[c] = leg_m / 2 - sc, radius_m, -np.pi / 2
            d_ = s >= 2 * leg_m + np.pi * radius_m
            ang = (s[d_] - 2 * leg_m - np.pi * radius_m) / radius_m
            e[d_], nn[d_] = -leg_m / 2 - radius_m * np.sin(ang), radius_m * np.cos(ang)
            head[d_], bank[d_] = -np.pi / 2 - ang, -phi_b
            # rotate the pattern per altitude so geometry decorrelates
            rot = np.radians(35.0 * j)
            er = e * np.cos(rot) - nn * np.sin(rot)
            nr = e * np.sin(rot) + nn * np.cos(rot)
            head = head - rot
            ve, vn = v * np.sin(head), v * np.cos(head)
            p_el = 0.85 + 0.5 * (v - 22.0) / 8.0 + 0.15 * (1 / np.cos(bank) - 1) + rng.normal(0, 0.03, n_s)
            out["t"].append(t0 + np.arange(n_s) * dt)
            out["e"].append(er)
            out["n"].append(nr)
            out["u"].append(np.full(n_s, h))
            out["ve"].append(ve)
            out["vn"].append(vn)
            out["yaw"].append(head)
            out["pitch"].append(np.full(n_s, np.radians(2.0 + 4.0 * (26.0 - v) / 8.0)))
            out["roll"].append(bank)
            out["p_el"].append(p_el)
            t0 += n_s * dt + 5.0
    return {k: np.concatenate(v) for k, v in out.items()}


def synthetic_samples(seed=0, truth=None, noise=None, ansatz="paper-offset", ar=0.0, mics=None,
                      altitudes=(40.0, 90.0, 150.0), speeds=(22.0, 26.0, 30.0), flights=1, ref_w=REF_W,
                      p_el_scale=1.0, **kw):
    """Samples of ``flights`` identical racetrack flights with levels from ``truth`` + noise.

    ``p_el_scale`` multiplies the nondimensional power (with ``ref_w`` the reference
    power, W).  ``ar`` is the AR(1) coefficient of the noise of each microphone (0: white);
    the marginal standard deviation equals ``noise[mic]``.
    """
    truth = dict(TRUTH if truth is None else truth)
    noise = dict(NOISE if noise is None else noise)
    mics = dict(MICS if mics is None else mics)
    model = get_ansatz(ansatz)
    p = np.array([truth[k] for k in model.params])
    seq_traj, seq_noise = np.random.SeedSequence(seed).spawn(2)
    rng = np.random.default_rng(seq_noise)
    traj = racetrack(altitudes=altitudes, speeds=speeds, seed=seq_traj, **kw)
    traj["p_el"] = traj["p_el"] * p_el_scale
    cols = {k: [] for k in ("mic", "flight", "t", "level", "d", "phi", "theta", "p_el", "roll", "pitch", "yaw",
                            "uav", "mic_enu", "vel", "clean")}
    nt = len(traj["t"])
    for f in range(flights):
        for m, (me, mn, mu) in mics.items():
            d, phi, theta = emission_angles(me - traj["e"], mn - traj["n"], mu - traj["u"], traj["yaw"],
                                            traj["pitch"], traj["roll"])
            x = {"d": d, "phi": phi, "theta": theta, "p_el": traj["p_el"]}
            clean = model.level(p, x)
            sd = noise[m]
            z = rng.normal(0.0, sd, nt)
            if ar:
                e = np.empty(nt)
                e[0] = z[0]
                scale = np.sqrt(1 - ar * ar)
                for i in range(1, nt):
                    e[i] = ar * e[i - 1] + scale * z[i]
                z = e
            cols["mic"].append(np.full(nt, m))
            cols["flight"].append(np.full(nt, f"f{f + 1}"))
            cols["t"].append(traj["t"])
            cols["level"].append(clean + z)
            cols["clean"].append(clean)
            for k, v in (("d", d), ("phi", phi), ("theta", theta), ("p_el", traj["p_el"]),
                         ("roll", traj["roll"]), ("pitch", traj["pitch"]), ("yaw", traj["yaw"])):
                cols[k].append(v)
            cols["uav"].append(np.column_stack([traj["e"], traj["n"], traj["u"]]))
            cols["mic_enu"].append(np.tile([me, mn, mu], (nt, 1)))
            cols["vel"].append(np.column_stack([traj["ve"], traj["vn"], np.zeros(nt)]))
    c = {k: np.concatenate(v) for k, v in cols.items()}
    n = len(c["level"])
    samples = Samples(
        mic=c["mic"], flight=c["flight"], t_r=c["t"] + c["d"] / 340.0, t_e=c["t"], level=c["level"], d=c["d"],
        phi=c["phi"], theta=c["theta"], power_w=c["p_el"] * ref_w, phase=np.full(n, "horizontal"),
        roll=np.degrees(c["roll"]), pitch=np.degrees(c["pitch"]), yaw=np.degrees(c["yaw"]), uav_enu=c["uav"],
        mic_enu=c["mic_enu"], vel_enu=c["vel"], valid=np.ones(n, dtype=bool), mask_reason=np.full(n, ""),
        meta={"reference_power_w": ref_w},
    )
    return samples, c["clean"]
