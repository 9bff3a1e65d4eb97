"""The samples table of a simulated campaign, built in memory the way the campaign reader builds it from files."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from gisnoise.geo import emission_angles
from gisnoise.measure import Samples, emission_time  # the reader's solver: one definition
from gisnoise.simulate.campaign import _campaign_doc
from gisnoise.simulate.flying import _interp_angle
from gisnoise.simulate.result import SimulationResult, run
from gisnoise.simulate.scenario import load_scenario

__all__ = ["simulate_samples"]


def simulate_samples(scenario: Mapping[str, Any] | str | os.PathLike[str] | SimulationResult, *,
                     base_dir: str | os.PathLike[str] | None = None, snr_db: float = 3.0) -> Samples:
    """The :class:`~gisnoise.measure.samples.Samples` table of a simulated campaign, without files.

    Same physics and random draws as :func:`~gisnoise.simulate.simulate`; the table is built the way
    the campaign reader builds it from the written files: the emission time of each
    block centre is solved against the *logged* trajectory (so log noise and an
    injected clock offset act as they would), the logged state is interpolated at
    it (angles on the circle), distance and emission angles follow.  ``level`` is the
    measured (noisy) free-field LA, not absorption-corrected; ``bands`` the measured
    band levels; ``background_db`` the scenario's background level (known here, not
    estimated).  Masks as the reader sets them: ``outside_flight`` (emission time
    outside the log) and ``low_snr`` (level below background + ``snr_db``); transient
    events are *not* flagged (finding them is the reader's and the diagnosis' job).

    Parameters
    ----------
    scenario : dict, path or SimulationResult
        Scenario document, its JSON file, or the result of :func:`~gisnoise.simulate.run`.
    base_dir : path, optional
        Folder card paths are relative to.
    snr_db : float
        Margin of the ``low_snr`` mask above the background, dB.
    """
    if isinstance(scenario, (str, os.PathLike)):
        scenario = load_scenario(scenario)
    res = scenario if isinstance(scenario, SimulationResult) else run(scenario, base_dir=base_dir)
    sc = res.scenario
    doc = sc.doc
    rows: dict[str, list[np.ndarray]] = {}

    def put(**kw: Any) -> None:
        for k, v in kw.items():
            rows.setdefault(k, []).append(np.asarray(v))

    for fl in res.flights:
        lg = fl.log
        tl = lg["t"]
        pos = np.stack([lg["e"], lg["n"], lg["u"]], axis=1)
        vel = np.stack([np.gradient(pos[:, k], tl) for k in range(3)], axis=1)
        for m in doc["microphones"]:
            mf = res.levels[fl.id][m["id"]]
            mic = np.array([m["e"], m["n"], m["height_m"]])
            te = emission_time(mf.t, tl, pos, mic, sc.c)
            t_r = mf.t
            x = np.stack([np.interp(te, tl, pos[:, k]) for k in range(3)], axis=1)
            yaw, pitch, roll = (_interp_angle(te, tl, lg[k]) for k in ("yaw", "pitch", "roll"))
            r = mic - x
            d, phi, theta = emission_angles(r[:, 0], r[:, 1], r[:, 2], yaw, pitch, roll)
            idx = np.clip(np.searchsorted(tl, te, side="right") - 1, 0, len(tl) - 1)
            n = len(te)
            bg = doc["background"]["level_dba"]
            reason = np.where(mf.la < bg + snr_db, "low_snr", "")
            reason = np.where((te < tl[0]) | (te > tl[-1]), "outside_flight", reason)
            put(mic=np.full(n, m["id"], dtype=object), flight=np.full(n, fl.id, dtype=object), t_r=t_r, t_e=te,
                level=mf.la, d=d, phi=phi, theta=theta, power_w=np.interp(te, tl, lg["power_w"]),
                phase=lg["phase"][idx], roll=np.degrees(roll), pitch=np.degrees(pitch), yaw=np.degrees(yaw),
                uav_enu=x, mic_enu=np.broadcast_to(mic, (n, 3)),
                vel_enu=np.stack([np.interp(te, tl, vel[:, k]) for k in range(3)], axis=1),
                rpm=np.interp(te, tl, lg["rpm"]), airspeed_m_s=np.interp(te, tl, lg["airspeed_m_s"]),
                bands=mf.bands, background_db=np.full(n, bg), reason=reason)
    cat = {k: np.concatenate(v) for k, v in rows.items()}
    reason = cat["reason"].astype(str)
    cdoc = _campaign_doc(res)
    meta = {"source": "simulate", "scenario": doc["name"], "origin": dict(doc["origin"]),
            "weather": dict(doc["weather"]), "vehicle": dict(cdoc["vehicle"]),
            "reference_power_w": doc["vehicle"]["reference_power_w"], "speed_of_sound_m_s": sc.c,
            "absorption_corrected": False, "snr_db": snr_db, "block_s": doc["output"]["block_s"],
            "flights": {f["id"]: {"start_utc": f["start_utc"]} for f in cdoc["flights"]},
            "microphones": {m["id"]: {**{k: m[k] for k in ("lat", "lon", "h", "mount", "height_agl_m")},
                                      "enu": [s_["e"], s_["n"], s_["height_m"]]}
                            for m, s_ in zip(cdoc["microphones"], doc["microphones"], strict=True)},
            "noise_std_db": {m["id"]: m["noise_std_db"] for m in doc["microphones"]}}
    return Samples(mic=cat["mic"].astype(str), flight=cat["flight"].astype(str), t_r=cat["t_r"], t_e=cat["t_e"],
                   level=cat["level"], d=cat["d"], phi=cat["phi"], theta=cat["theta"], power_w=cat["power_w"],
                   phase=cat["phase"].astype(str), roll=cat["roll"], pitch=cat["pitch"], yaw=cat["yaw"],
                   uav_enu=cat["uav_enu"], mic_enu=np.array(cat["mic_enu"]), vel_enu=cat["vel_enu"],
                   valid=reason == "", mask_reason=reason, rpm=cat["rpm"], airspeed_m_s=cat["airspeed_m_s"],
                   band_f=res.band_f.copy(), bands=cat["bands"], background_db=cat["background_db"], meta=meta)

