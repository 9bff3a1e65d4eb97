"""One simulation run in memory: every flight flown and heard at every microphone, and its truth document."""

from __future__ import annotations

import copy
import json
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise import __version__
from gisnoise.jsonio import dumps, to_jsonable
from gisnoise.simulate.effects import _EFFECT_FORMS
from gisnoise.simulate.flying import _Flight, _state, coordinated_bank
from gisnoise.simulate.propagation import _bands, _flight_events, _mic_flight, _MicFlight
from gisnoise.simulate.scenario import Scenario, resolve_scenario

__all__ = ["TRUTH_SCHEMA", "Progress", "SimulationResult", "dumps_truth", "run"]

TRUTH_SCHEMA = "gisnoise/simulation-truth/1"

Progress = Callable[[float], None]
"""A progress callback, called with the fraction done (0-1)."""


@dataclass
class SimulationResult:
    """Everything one simulation run produced, in memory.

    Attributes
    ----------
    scenario : Scenario
        The checked scenario.
    flights : list
        Per flight: ``id``, ``start_utc``, true state (``true``, at the
        simulation rate, ENU m and rad), ``log`` (what the flight CSV holds, ENU m
        and rad), turn intervals and phases.
    levels : dict
        ``levels[flight][mic]`` with block centres ``t`` (s), measured ``bands`` and
        ``la``, and ``la_clean`` / ``la_uav`` (dB).
    band_f, band_labels : ndarray, list of str
        Exact mid-band frequencies (Hz) and nominal labels.
    """

    scenario: Scenario
    flights: list[_Flight]
    levels: dict[str, dict[str, _MicFlight]]
    band_f: np.ndarray
    band_labels: list[str]

    def truth(self) -> dict[str, Any]:
        """The ``truth.json`` document."""
        sc = self.scenario
        doc = sc.doc
        eff = [{"name": k, "form": _EFFECT_FORMS[k], "parameters": v} for k, v in doc["effects"].items()]
        flights = {}
        for fl in self.flights:
            flights[fl.id] = {
                "duration_s": float(fl.true["t"][-1]),
                "turns": [{"t0": a, "t1": b, "radius_m": r, "speed_m_s": v,
                           "bank_deg": float(np.degrees(coordinated_bank(v, r)))} for a, b, r, v in fl.turns],
                "phases": [{"t0": a, "t1": b, "phase": ph} for a, b, ph in fl.phases],
                "events": [{"t0": e["t_s"], "t1": e["t_s"] + e["duration_s"], "peak_dba": e["peak_dba"]}
                           for e in fl.events],
                "blocks": {mid: {"t": _r(mf.t, 4), "LA": _r(mf.la, 2), "LA_clean": _r(mf.la_clean, 3),
                                 "LA_uav": _r(mf.la_uav, 3)} for mid, mf in self.levels[fl.id].items()},
            }
        return {"schema": TRUTH_SCHEMA, "software": f"gisnoise {__version__}",
                "note": "times are true times since the flight's start_utc (the audio clock); block LA are "
                        "free-field reception-block levels: LA as written, LA_clean without measurement noise, "
                        "LA_uav the UAV alone",
                "speed_of_sound_m_s": sc.c, "scenario": doc,
                "cards": {ph: cd.to_dict() for ph, cd in sc.cards.items()},
                "microphones": {m["id"]: {"noise_std_db": m["noise_std_db"], "e": m["e"], "n": m["n"],
                                          "height_m": m["height_m"], "mount": m["mount"]}
                                for m in doc["microphones"]},
                "effects": eff, "flights": flights}


def dumps_truth(truth: Mapping[str, Any]) -> str:
    """``truth.json`` text: indented, with each block-level array on one line."""
    doc = copy.deepcopy(dict(truth))
    arrays: dict[str, str] = {}
    for fid, fl in doc.get("flights", {}).items():
        for mid, blk in fl.get("blocks", {}).items():
            for k, v in blk.items():
                key = f"@@{fid}/{mid}/{k}@@"
                arrays[key] = json.dumps(to_jsonable(v), separators=(",", ":"), allow_nan=False)
                blk[k] = key
    text = dumps(doc, indent=1)
    for key, v in arrays.items():
        text = text.replace(json.dumps(key), v)
    return text


def _r(a: np.ndarray, nd: int) -> list[float | None]:
    """Block levels rounded to ``nd`` decimals for ``truth.json``; non-finite values become ``None``."""
    return to_jsonable([round(float(v), nd) for v in a])


def run(scenario: Mapping[str, Any] | Scenario, *, base_dir: str | os.PathLike[str] | None = None,
        progress: Progress | None = None) -> SimulationResult:
    """Run the simulation in memory (no files); see :func:`gisnoise.simulate.simulate`."""
    sc = scenario if isinstance(scenario, Scenario) else resolve_scenario(scenario, base_dir=base_dir)
    bands = _bands(sc)
    doc = sc.doc
    nf, nm = len(doc["flights"]), len(doc["microphones"])
    total = nf * (nm + 1)
    done = 0
    flights: list[_Flight] = []
    levels: dict[str, dict[str, _MicFlight]] = {}
    for fi, fdoc in enumerate(doc["flights"]):
        fl = _state(sc, fdoc, fi)
        fl.events = _flight_events(sc, fl, fi, float(fl.true["t"][-1]))
        flights.append(fl)
        done += 1
        if progress:
            progress(done / total)
        levels[fl.id] = {}
        for mi, m in enumerate(doc["microphones"]):
            levels[fl.id][m["id"]] = _mic_flight(sc, bands, fl, fi, mi)
            done += 1
            if progress:
                progress(done / total)
    return SimulationResult(scenario=sc, flights=flights, levels=levels, band_f=bands.f, band_labels=bands.labels)

