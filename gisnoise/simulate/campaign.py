"""Writing a simulated measurement campaign folder: campaign.json, flight logs, microphone levels or audio, truth.

The folder has the format :func:`gisnoise.measure.read_campaign` reads (``campaign.json``,
``flights/<flight>.csv``, ``mics/<mic>/<flight>.csv`` or ``.wav``) with ``truth.json``
beside it.  Level CSVs are free-field.  In WAV files the microphone's mount correction
(:func:`gisnoise.acoustics.mount_correction`, ground plate: -6 dB) is undone in the
pressure so that the reader's free-field correction recovers the level.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise import __version__
from gisnoise.acoustics import mount_correction, write_wav
from gisnoise.errors import InputError
from gisnoise.flight import from_columns
from gisnoise.jsonio import write_json
from gisnoise.simulate._random import seeded_rng
from gisnoise.simulate.flying import _Flight
from gisnoise.simulate.propagation import _MicFlight
from gisnoise.simulate.result import Progress, SimulationResult, dumps_truth, run
from gisnoise.simulate.scenario import load_scenario, resolve_scenario
from gisnoise.simulate.wav import synthesize_wav

__all__ = ["simulate"]


def _campaign_doc(res: SimulationResult) -> dict[str, Any]:
    """The ``campaign.json`` document of a simulation run."""
    sc = res.scenario
    doc = sc.doc
    mics = []
    for m in doc["microphones"]:
        lat, lon, h = sc.frame.to_wgs84(m["e"], m["n"], m["height_m"])
        mics.append({"id": m["id"], "lat": round(float(lat), 9), "lon": round(float(lon), 9),
                     "h": round(float(h), 4), "height_agl_m": m["height_m"], "mount": m["mount"],
                     "sensitivity_v_per_pa": m["sensitivity_v_per_pa"]})
        if doc["output"]["background_in_campaign"]:
            # as measured before the flights; the reader then uses it in place of its own estimate
            mics[-1]["background_db"] = doc["background"]["level_dba"]
    return {"schema": "gisnoise/campaign/1", "name": doc["name"],
            "origin": dict(doc["origin"]), "speed_of_sound_m_s": doc["speed_of_sound_m_s"],
            "weather": dict(doc["weather"]),
            "vehicle": {"name": doc["vehicle"]["name"], "reference_power_w": doc["vehicle"]["reference_power_w"]},
            "microphones": mics,
            "flights": [{"id": f.id, "start_utc": f.start_utc} for f in res.flights],
            "notes": f"simulated by gisnoise {__version__} (scenario {doc['name']!r}); see truth.json"}


def _log_trajectory(res: SimulationResult, fl: _Flight) -> Any:
    """The flight log of one flight as a trajectory in WGS84, angles in degrees (the flight CSV)."""
    lg = fl.log
    lat, lon, h = res.scenario.frame.to_wgs84(lg["e"], lg["n"], lg["u"])
    cols = {"t": lg["t"], "lat": lat, "lon": lon, "h": h, "roll": np.degrees(lg["roll"]),
            "pitch": np.degrees(lg["pitch"]), "yaw": np.degrees(lg["yaw"]), "power_w": lg["power_w"],
            "rpm": lg["rpm"], "airspeed_m_s": lg["airspeed_m_s"], "phase": lg["phase"]}
    return from_columns(cols, source=f"flight {fl.id}")


def _write_levels_csv(path: Path, mf: _MicFlight, labels: list[str], with_bands: bool) -> None:
    """Write the block levels of one microphone and flight as a level CSV (``t``, ``LA``, ``L_<band>``)."""
    cols = ["t", "LA"] + ([f"L_{lb}" for lb in labels] if with_bands else [])
    data = np.column_stack([mf.t, mf.la] + ([mf.bands] if with_bands else []))
    fmt = ["%.4f", "%.2f"] + ["%.1f"] * (data.shape[1] - 2)
    np.savetxt(path, data, fmt=fmt, delimiter=",", header=",".join(cols), comments="")


def simulate(scenario: Mapping[str, Any] | str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
             progress: Progress | None = None, base_dir: str | os.PathLike[str] | None = None,
             overwrite: bool = False) -> Path:
    """Simulate a measurement campaign and write it to ``out_dir``.

    Parameters
    ----------
    scenario : dict or path
        Scenario document (schema ``gisnoise/scenario/1``) or the path of its JSON file.
    out_dir : path
        Campaign folder to create: ``campaign.json``, ``flights/<flight>.csv``,
        ``mics/<mic>/<flight>.csv`` (levels) or ``.wav`` (audio), ``truth.json``.
    progress : callable, optional
        Called with the fraction done (0-1).
    base_dir : path, optional
        Folder card paths are relative to (default: the scenario file's folder).
    overwrite : bool
        Allow writing into a non-empty folder.

    Returns
    -------
    pathlib.Path
        The campaign folder.
    """
    if isinstance(scenario, (str, os.PathLike)):
        scenario = load_scenario(scenario)
    out = Path(out_dir)
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise InputError(f"{out}: folder exists and is not empty; choose a new folder", field="out")
    sc = resolve_scenario(scenario, base_dir=base_dir)
    wav = sc.doc["output"]["format"] == "wav"

    def sub(a: float, b: float) -> Progress | None:
        return None if progress is None else (lambda f: progress(a + (b - a) * f))

    res = run(sc, progress=sub(0.0, 0.5 if wav else 0.9))
    (out / "flights").mkdir(parents=True, exist_ok=True)
    write_json(_campaign_doc(res), out / "campaign.json", indent=2)
    for fl in res.flights:
        _log_trajectory(res, fl).to_csv(out / "flights" / f"{fl.id}.csv")
    op = sc.doc["output"]
    mics = {m["id"]: m for m in sc.doc["microphones"]}
    items = [(fi, fl, mid) for fi, fl in enumerate(res.flights) for mid in mics]
    for k, (fi, fl, mid) in enumerate(items):
        d = out / "mics" / mid
        d.mkdir(parents=True, exist_ok=True)
        mf = res.levels[fl.id][mid]
        if wav:
            m = mics[mid]
            pr = synthesize_wav(mf.bands, res.band_f, op["block_s"], op["fs_hz"],
                                seeded_rng(sc.seed, fi, 5000 + list(mics).index(mid)))
            # undo the reader's mount correction (ground plate: pressure doubling) and calibrate to volts
            gain = 10.0 ** (-mount_correction(m["mount"]) / 20.0)
            write_wav(d / f"{fl.id}.wav", pr * gain, op["fs_hz"], m["sensitivity_v_per_pa"])
        else:
            _write_levels_csv(d / f"{fl.id}.csv", mf, res.band_labels, op["bands"])
        if progress:
            progress((0.5 if wav else 0.9) + (0.45 if wav else 0.05) * (k + 1) / len(items))
    (out / "truth.json").write_text(dumps_truth(res.truth()), encoding="utf-8")
    if progress:
        progress(1.0)
    return out

