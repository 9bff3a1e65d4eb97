"""Scenarios: reading and checking a simulation scenario (schema ``gisnoise/scenario/1``), every default filled in.

Scenario
--------
See ``sample_data/scenarios/`` for complete examples.  Top-level fields::

    schema        "gisnoise/scenario/1"
    name          free text
    seed          integer (all randomness derives from it)
    origin        {"lat", "lon", "h"}: WGS84, h = ellipsoidal height of the flat ground, m
    speed_of_sound_m_s   number or null (null: 331.3 sqrt(1 + T/273.15))
    weather       {"temperature_c", "humidity_pct", "pressure_kpa", "wind_speed_m_s", "wind_from_deg"}
    vehicle       {"name", "reference_power_w", "mass_kg", "cruise_speed_m_s", "pitch_deg",
                   "cards": {phase: card file, bundled card name or inline card},
                   "power": {...}, "rpm": {...}, "spectrum": {...}, "log_noise": {...}}
    microphones   [{"id", "e", "n" (m from origin) or "lat", "lon"; "height_m", "mount",
                    "noise_std_db", "sensitivity_v_per_pa"}]
    background    {"level_dba", "spectrum": "ambient" | "pink" | {"<nominal Hz>": dB},
                   "fluctuation_db", "fluctuation_tau_s"}
    output        {"format": "levels" | "wav", "block_s", "bands", "band_min_hz", "band_max_hz",
                   "sim_rate_hz", "log_rate_hz", "subsamples", "fs_hz", "background_in_campaign"}
                  (``background_in_campaign``, default true: write each microphone's
                  ``background_db`` into campaign.json, as a background measurement
                  before the flights would give it; false lets the reader estimate it)
    flights       [{"id", "start_utc", "start": {"e", "n", "height_m", "heading_deg"}, "patterns": [...]}]
                  (a flight starts at rest at ``start``; height 0: on the ground)
    effects       {name: {parameters}}

Patterns (heights in m above ground, speeds m/s, headings deg from north)::

    {"type": "climb" | "sink", "to_height_m", "rate_m_s", "yaw_rate_deg_s"}
    {"type": "hover", "duration_s", "yaw_rate_deg_s"}
    {"type": "transition", "duration_s", "to_speed_m_s"}
    {"type": "racetrack", "centre": [e, n], "heading_deg", "straight_m", "radius_m",
     "heights_m": [..], "laps", "turn": "right" | "left", "speed_m_s"}
    {"type": "flyby", "through": [e, n], "heading_deg", "length_m", "height_m", "speed_m_s", "radius_m"}
    {"type": "goto", "to": [e, n], "height_m", "speed_m_s", "radius_m", "heading_deg" (optional)}

The effects and their parameters: :mod:`gisnoise.simulate.effects`.

Examples
--------
>>> sc = resolve_scenario({"origin": {"lat": 52.0, "lon": 10.0}, "microphones": [{"id": "m1", "e": 0, "n": 0}],
...                        "flights": [{"id": "f1", "patterns": [{"type": "hover", "duration_s": 10}]}]})
>>> sc.doc["flights"][0]["patterns"][0]["yaw_rate_deg_s"], round(sc.c, 2)
(0.0, 340.28)
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

from gisnoise.acoustics import MOUNT_CORRECTIONS_DB, band_edges, speed_of_sound
from gisnoise.errors import ScenarioError
from gisnoise.flight import G
from gisnoise.geo import LocalFrame
from gisnoise.jsonio import JsonObject, read_json_file
from gisnoise.model import PHASES, ModelCard, card_of_field
from gisnoise.simulate.effects import _EFFECT_KEYS, EFFECTS

__all__ = ["SCHEMA", "Scenario", "load_scenario", "resolve_scenario", "scenario_copy"]

SCHEMA = "gisnoise/scenario/1"
_MOUNTS = tuple(MOUNT_CORRECTIONS_DB)


class _Obj(JsonObject):
    """Reads one JSON object of the scenario, naming fields with their dotted path in errors."""

    error = ScenarioError
    what = "scenario"


_DEFAULT_CARDS = {"horizontal": "demo_horizontal", "transition": "demo_horizontal", "climb": "demo_climb",
                  "sink": "demo_sink", "hover": "demo_climb"}
_PATTERN_KEYS = {
    "climb": ("type", "to_height_m", "rate_m_s", "yaw_rate_deg_s"),
    "sink": ("type", "to_height_m", "rate_m_s", "yaw_rate_deg_s"),
    "hover": ("type", "duration_s", "yaw_rate_deg_s"),
    "transition": ("type", "duration_s", "to_speed_m_s"),
    "racetrack": ("type", "centre", "heading_deg", "straight_m", "radius_m", "heights_m", "laps", "turn",
                  "speed_m_s"),
    "flyby": ("type", "through", "heading_deg", "length_m", "height_m", "speed_m_s", "radius_m"),
    "goto": ("type", "to", "heading_deg", "height_m", "speed_m_s", "radius_m"),
}


def load_scenario(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a scenario JSON file; card paths in it are relative to its folder."""
    p = Path(path)
    doc = read_json_file(p, what="scenario", error=ScenarioError, field="scenario")
    if isinstance(doc, dict):
        doc.setdefault("_base_dir", str(p.resolve().parent))
    return doc


@dataclass(frozen=True)
class Scenario:
    """A checked scenario: the normalized document (every default filled in) and its cards."""

    doc: dict[str, Any]
    cards: dict[str, ModelCard]
    frame: LocalFrame
    c: float

    @property
    def seed(self) -> int:
        return int(self.doc["seed"])


def resolve_scenario(scenario: Mapping[str, Any], *, base_dir: str | os.PathLike[str] | None = None) -> Scenario:
    """Check a scenario document and fill in every default.

    Errors are :class:`ScenarioError` naming the field (``vehicle.cards.climb``,
    ``flights[0].patterns[2].radius_m``, ...).
    """
    if not isinstance(scenario, Mapping):
        raise ScenarioError("scenario: expected a JSON object", field="scenario")
    doc = {k: v for k, v in scenario.items() if k != "_base_dir"}
    if base_dir is None and "_base_dir" in scenario:
        base_dir = scenario["_base_dir"]
    bdir = Path(base_dir) if base_dir is not None else None
    top = _Obj(doc, "", ("schema", "name", "description", "seed", "origin", "speed_of_sound_m_s", "weather",
                         "vehicle", "microphones", "background", "output", "flights", "effects"))
    schema = top.get("schema", SCHEMA)
    if schema != SCHEMA:
        raise ScenarioError(f"scenario: field 'schema' must be '{SCHEMA}', got {schema!r}", field="schema")
    out: dict[str, Any] = {"schema": SCHEMA, "name": top.str("name", "scenario"),
                           "description": top.get("description", ""), "seed": top.num("seed", 0, lo=0, integer=True)}
    o = _Obj(top.get("origin"), "origin", ("lat", "lon", "h"))
    out["origin"] = {"lat": o.num("lat", lo=-89.0, hi=89.0), "lon": o.num("lon", lo=-180.0, hi=180.0),
                     "h": o.num("h", 0.0, lo=-500.0, hi=9000.0)}
    w = _Obj(top.get("weather", {}), "weather",
             ("temperature_c", "humidity_pct", "pressure_kpa", "wind_speed_m_s", "wind_from_deg"))
    out["weather"] = {"temperature_c": w.num("temperature_c", 15.0, lo=-40.0, hi=50.0),
                      "humidity_pct": w.num("humidity_pct", 60.0, lo=1.0, hi=100.0),
                      "pressure_kpa": w.num("pressure_kpa", 101.325, lo=50.0, hi=110.0),
                      "wind_speed_m_s": w.num("wind_speed_m_s", 0.0, lo=0.0, hi=20.0),
                      "wind_from_deg": w.num("wind_from_deg", 270.0, lo=-360.0, hi=360.0)}
    c_given = top.num("speed_of_sound_m_s", None, lo=250.0, hi=400.0, allow_none=True)
    out["speed_of_sound_m_s"] = c_given
    c = c_given if c_given is not None else float(speed_of_sound(out["weather"]["temperature_c"]))

    # ---------------------------------------------------------------- vehicle and cards
    v = _Obj(top.get("vehicle", {}), "vehicle", ("name", "reference_power_w", "mass_kg", "cruise_speed_m_s",
                                                 "pitch_deg", "cards", "power", "rpm", "spectrum", "log_noise"))
    card_refs = dict(_DEFAULT_CARDS)
    given = v.get("cards", {})
    if not isinstance(given, Mapping):
        raise ScenarioError(f"scenario: field 'vehicle.cards' must be an object phase -> card, got {given!r}",
                            field="vehicle.cards")
    for ph in given:
        if ph not in PHASES:
            raise ScenarioError(f"scenario: field 'vehicle.cards.{ph}': unknown phase; known: "
                                f"{', '.join(PHASES)}", field=f"vehicle.cards.{ph}")
    card_refs.update(given)
    cards = {ph: card_of_field(ref, f"vehicle.cards.{ph}", bdir, _Obj) for ph, ref in card_refs.items()}
    ref_p = v.num("reference_power_w", cards["horizontal"].reference_power_w, lo=0.0, lo_open=True)
    for ph, cd in cards.items():
        if abs(cd.reference_power_w - ref_p) > 1e-9 * ref_p:
            raise ScenarioError(f"scenario: field 'vehicle.cards.{ph}': card reference power "
                                f"{cd.reference_power_w:g} W differs from vehicle.reference_power_w {ref_p:g} W",
                                field=f"vehicle.cards.{ph}")
    veh: dict[str, Any] = {
        "name": v.str("name", cards["horizontal"].vehicle), "reference_power_w": ref_p,
        "mass_kg": v.num("mass_kg", 35.0, lo=0.0, lo_open=True, hi=1e4),
        "cruise_speed_m_s": v.num("cruise_speed_m_s", 23.6, lo=1.0, hi=100.0),
        "pitch_deg": v.num("pitch_deg", 3.0, lo=-30.0, hi=30.0),
        "cards": {ph: (ref if isinstance(ref, str) else "inline") for ph, ref in card_refs.items()},
    }
    pw = _Obj(v.get("power", {}), "vehicle.power", ("cruise_w", "parasitic_fraction", "hover_w", "efficiency",
                                                    "jitter_pct", "jitter_tau_s"))
    veh["power"] = {"cruise_w": pw.num("cruise_w", ref_p, lo=0.0, lo_open=True),
                    "parasitic_fraction": pw.num("parasitic_fraction", 0.55, lo=0.0, hi=1.0),
                    "hover_w": pw.num("hover_w", 2.6 * ref_p, lo=0.0, lo_open=True),
                    "efficiency": pw.num("efficiency", 0.6, lo=0.05, hi=1.0),
                    "jitter_pct": pw.num("jitter_pct", 3.0, lo=0.0, hi=50.0),
                    "jitter_tau_s": pw.num("jitter_tau_s", 2.0, lo=0.01)}
    rp = _Obj(v.get("rpm", {}), "vehicle.rpm", ("cruise_rpm", "hover_rpm", "jitter_pct", "jitter_tau_s"))
    veh["rpm"] = {"cruise_rpm": rp.num("cruise_rpm", 4800.0, lo=1.0), "hover_rpm": rp.num("hover_rpm", 3600.0, lo=1.0),
                  "jitter_pct": rp.num("jitter_pct", 5.0, lo=0.0, hi=50.0),
                  "jitter_tau_s": rp.num("jitter_tau_s", 3.0, lo=0.01)}
    sp = _Obj(v.get("spectrum", {}), "vehicle.spectrum", ("bpf_hz", "harmonics_db", "broadband_db",
                                                          "broadband_peak_hz", "slope_low_db_oct",
                                                          "slope_high_db_oct"))
    harm = sp.get("harmonics_db", [0.0, -4.0, -8.0, -12.0, -16.0, -20.0])
    if (not isinstance(harm, list) or not harm
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in harm)):
        raise ScenarioError(f"scenario: field 'vehicle.spectrum.harmonics_db' must be a list of numbers, got {harm!r}",
                            field="vehicle.spectrum.harmonics_db")
    veh["spectrum"] = {"bpf_hz": sp.num("bpf_hz", 160.0, lo=20.0, hi=5000.0), "harmonics_db": [float(x) for x in harm],
                       "broadband_db": sp.num("broadband_db", -2.0, lo=-60.0, hi=60.0),
                       "broadband_peak_hz": sp.num("broadband_peak_hz", 1000.0, lo=25.0, hi=20000.0),
                       "slope_low_db_oct": sp.num("slope_low_db_oct", 3.0, lo=0.0, hi=40.0),
                       "slope_high_db_oct": sp.num("slope_high_db_oct", 5.0, lo=0.0, hi=40.0)}
    ln = _Obj(v.get("log_noise", {}), "vehicle.log_noise", ("position_m", "attitude_deg", "power_pct"))
    veh["log_noise"] = {"position_m": ln.num("position_m", 0.3, lo=0.0, hi=50.0),
                        "attitude_deg": ln.num("attitude_deg", 0.3, lo=0.0, hi=20.0),
                        "power_pct": ln.num("power_pct", 1.0, lo=0.0, hi=50.0)}
    out["vehicle"] = veh
    frame = LocalFrame(out["origin"]["lat"], out["origin"]["lon"], out["origin"]["h"])

    # ---------------------------------------------------------------- microphones
    mics = top.get("microphones")
    if not isinstance(mics, list) or not mics:
        raise ScenarioError("scenario: field 'microphones' must be a non-empty list", field="microphones")
    out["microphones"] = []
    seen: set[str] = set()
    for i, m in enumerate(mics):
        mo = _Obj(m, f"microphones[{i}]", ("id", "e", "n", "lat", "lon", "height_m", "mount", "noise_std_db",
                                            "sensitivity_v_per_pa"))
        mid = mo.str("id")
        if mid in seen or "/" in mid or mid in (".", ".."):
            mo.fail("id", "a unique name usable as a folder", mid)
        seen.add(mid)
        mount = mo.str("mount", "ground_plate", _MOUNTS)
        height = mo.num("height_m", 0.0 if mount == "ground_plate" else 1.2, lo=0.0, hi=100.0)
        if mount == "ground_plate" and height != 0.0:
            mo.fail("height_m", "0 for a ground_plate microphone", height)
        if "lat" in m or "lon" in m:
            lat, lon = mo.num("lat", lo=-90.0, hi=90.0), mo.num("lon", lo=-180.0, hi=180.0)
            e_enu, n_enu, _ = frame.to_enu(lat, lon, out["origin"]["h"])
            e, n = float(e_enu), float(n_enu)
        else:
            e, n = mo.num("e"), mo.num("n")
        out["microphones"].append({"id": mid, "e": e, "n": n, "height_m": height, "mount": mount,
                                   "noise_std_db": mo.num("noise_std_db", 0.5, lo=0.0, hi=20.0),
                                   "sensitivity_v_per_pa": mo.num("sensitivity_v_per_pa", 0.05, lo=0.0,
                                                                  lo_open=True)})

    # ---------------------------------------------------------------- background and output
    b = _Obj(top.get("background", {}), "background", ("level_dba", "spectrum", "fluctuation_db",
                                                       "fluctuation_tau_s"))
    bspec = b.get("spectrum", "ambient")
    if not (bspec in ("ambient", "pink") or isinstance(bspec, Mapping)):
        raise ScenarioError(f"scenario: field 'background.spectrum' must be 'ambient', 'pink' or an object "
                            f"band -> dB, got {bspec!r}", field="background.spectrum")
    out["background"] = {"level_dba": b.num("level_dba", 40.0, lo=-20.0, hi=120.0), "spectrum": bspec,
                         "fluctuation_db": b.num("fluctuation_db", 0.0, lo=0.0, hi=20.0),
                         "fluctuation_tau_s": b.num("fluctuation_tau_s", 10.0, lo=0.01)}
    op = _Obj(top.get("output", {}), "output", ("format", "block_s", "bands", "band_min_hz", "band_max_hz",
                                               "sim_rate_hz", "log_rate_hz", "subsamples", "fs_hz",
                                               "background_in_campaign"))
    outp = {"format": op.str("format", "levels", ("levels", "wav")),
            "block_s": op.num("block_s", 0.125, lo=0.01, hi=10.0),
            "bands": op.get("bands", True),
            "band_min_hz": op.num("band_min_hz", 25.0, lo=20.0, hi=20000.0),
            "band_max_hz": op.num("band_max_hz", 20000.0, lo=20.0, hi=20000.0),
            "sim_rate_hz": op.num("sim_rate_hz", 50.0, lo=5.0, hi=1000.0),
            "log_rate_hz": op.num("log_rate_hz", 10.0, lo=1.0, hi=1000.0),
            "subsamples": op.num("subsamples", 8, lo=1, hi=256, integer=True),
            "fs_hz": op.num("fs_hz", 48000, lo=8000, hi=192000, integer=True),
            "background_in_campaign": op.get("background_in_campaign", True)}
    for k in ("bands", "background_in_campaign"):
        if not isinstance(outp[k], bool):
            op.fail(k, "true or false", outp[k])
    if outp["band_max_hz"] < outp["band_min_hz"]:
        op.fail("band_max_hz", f"at least band_min_hz ({outp['band_min_hz']:g})", outp["band_max_hz"])
    if outp["format"] == "wav":
        n_blk = outp["fs_hz"] * outp["block_s"]
        if abs(n_blk - round(n_blk)) > 1e-6:
            op.fail("block_s", f"a whole number of samples at fs_hz {outp['fs_hz']}", outp["block_s"])
        top_edge = float(band_edges(outp["band_max_hz"])[1])
        if top_edge >= outp["fs_hz"] / 2:
            op.fail("fs_hz", f"above twice the top band edge ({2 * top_edge:.0f} Hz)", outp["fs_hz"])
    out["output"] = outp

    # ---------------------------------------------------------------- flights
    flights = top.get("flights")
    if not isinstance(flights, list) or not flights:
        raise ScenarioError("scenario: field 'flights' must be a non-empty list", field="flights")
    out["flights"] = []
    fseen: set[str] = set()
    t_base = datetime(2024, 5, 4, 10, 0, 0, tzinfo=timezone.utc)
    for i, f in enumerate(flights):
        fo = _Obj(f, f"flights[{i}]", ("id", "start_utc", "start", "patterns"))
        fid = fo.str("id")
        if fid in fseen or "/" in fid or fid in (".", ".."):
            fo.fail("id", "a unique name usable as a file name", fid)
        fseen.add(fid)
        start_utc = fo.str("start_utc", (t_base + timedelta(hours=i)).strftime("%Y-%m-%dT%H:%M:%SZ"))
        try:
            datetime.fromisoformat(start_utc.replace("Z", "+00:00"))
        except ValueError:
            fo.fail("start_utc", "an ISO 8601 time such as 2024-05-04T10:00:00Z", start_utc)
        so = _Obj(fo.get("start", {}), f"flights[{i}].start", ("e", "n", "height_m", "heading_deg"))
        start = {"e": so.num("e", 0.0), "n": so.num("n", 0.0), "height_m": so.num("height_m", 0.0, lo=0.0, hi=2000.0),
                 "heading_deg": so.num("heading_deg", 0.0)}
        pats = fo.get("patterns")
        if not isinstance(pats, list) or not pats:
            fo.fail("patterns", "a non-empty list", pats)
        plist = [_pattern(p, f"flights[{i}].patterns[{j}]", veh) for j, p in enumerate(pats)]
        out["flights"].append({"id": fid, "start_utc": start_utc, "start": start, "patterns": plist})

    # ---------------------------------------------------------------- effects
    eff = top.get("effects", {})
    if not isinstance(eff, Mapping):
        raise ScenarioError(f"scenario: field 'effects' must be an object name -> parameters, got {eff!r}",
                            field="effects")
    out["effects"] = {}
    for name, params in eff.items():
        if name not in _EFFECT_KEYS:
            raise ScenarioError(f"scenario: unknown effect 'effects.{name}'; known: {', '.join(EFFECTS)}",
                                field=f"effects.{name}")
        if params is False or params is None:
            continue
        if params is True:
            params = {}
        eo = _Obj(params, f"effects.{name}", tuple(_EFFECT_KEYS[name]))
        vals: dict[str, Any] = {}
        for k, d in _EFFECT_KEYS[name].items():
            if k == "events":
                vals[k] = _events(eo.get(k, None), f"effects.{name}.events", fseen)
            elif k == "count":
                vals[k] = eo.num(k, d, lo=0, hi=100, integer=True)
            elif k in ("offset_s", "db_at_30deg", "db_per_decade", "db_per_100m"):
                vals[k] = eo.num(k, d, lo=-100.0, hi=100.0)
            elif k in ("reflection_coefficient", "coherence"):
                vals[k] = eo.num(k, d, lo=0.0, hi=1.0)
            elif k in ("duration_s", "fluctuation_tau_s"):
                vals[k] = eo.num(k, d, lo=0.0, lo_open=True)
            else:
                vals[k] = eo.num(k, d, lo=0.0, hi=200.0)
        out["effects"][name] = vals
    if "wind" in out["effects"] and out["weather"]["wind_speed_m_s"] <= 0:
        raise ScenarioError("scenario: effect 'effects.wind' needs weather.wind_speed_m_s > 0",
                            field="weather.wind_speed_m_s")
    used = {ph for fl in out["flights"] for p in fl["patterns"] for ph in _pattern_phases(p)}
    for ph in used:
        if ph not in cards:
            raise ScenarioError(f"scenario: no truth card for phase '{ph}' in 'vehicle.cards'",
                                field=f"vehicle.cards.{ph}")
    return Scenario(doc=out, cards=cards, frame=frame, c=c)


def _pattern_phases(p: Mapping[str, Any]) -> tuple[str, ...]:
    t = p["type"]
    if t in ("climb", "sink", "hover", "transition"):
        return (t,)
    return ("horizontal",)


def _events(v: Any, fld: str, flights: set[str]) -> list[dict[str, Any]] | None:
    if v is None:
        return None
    if not isinstance(v, list):
        raise ScenarioError(f"scenario: field '{fld}' must be a list of events, got {v!r}", field=fld)
    out = []
    for i, e in enumerate(v):
        eo = _Obj(e, f"{fld}[{i}]", ("flight", "t_s", "duration_s", "peak_dba"))
        fl = eo.str("flight")
        if fl not in flights:
            eo.fail("flight", f"one of the flights ({', '.join(sorted(flights))})", fl)
        out.append({"flight": fl, "t_s": eo.num("t_s"), "duration_s": eo.num("duration_s", lo=0.0, lo_open=True),
                    "peak_dba": eo.num("peak_dba", lo=-20.0, hi=140.0)})
    return out


def _pattern(p: Any, fld: str, veh: Mapping[str, Any]) -> dict[str, Any]:
    if not isinstance(p, Mapping) or p.get("type") not in _PATTERN_KEYS:
        t = p.get("type") if isinstance(p, Mapping) else p
        raise ScenarioError(f"scenario: field '{fld}.type' must be one of {', '.join(_PATTERN_KEYS)}, got {t!r}",
                            field=f"{fld}.type")
    t = p["type"]
    o = _Obj(p, fld, _PATTERN_KEYS[t])
    vc = veh["cruise_speed_m_s"]
    if t in ("climb", "sink"):
        return {"type": t, "to_height_m": o.num("to_height_m", lo=0.0, hi=2000.0),
                "rate_m_s": o.num("rate_m_s", 2.0 if t == "climb" else 1.5, lo=0.0, lo_open=True, hi=20.0),
                "yaw_rate_deg_s": o.num("yaw_rate_deg_s", 0.0, lo=-90.0, hi=90.0)}
    if t == "hover":
        return {"type": t, "duration_s": o.num("duration_s", lo=0.0, lo_open=True, hi=7200.0),
                "yaw_rate_deg_s": o.num("yaw_rate_deg_s", 0.0, lo=-90.0, hi=90.0)}
    if t == "transition":
        return {"type": t, "duration_s": o.num("duration_s", 8.0, lo=0.0, lo_open=True, hi=600.0),
                "to_speed_m_s": o.num("to_speed_m_s", vc, lo=0.0, hi=100.0)}
    speed = o.num("speed_m_s", vc, lo=1.0, hi=100.0)
    # default radius: a 30 degree coordinated turn at the pattern's speed
    radius = o.num("radius_m", round(speed * speed / (G * math.tan(math.radians(30.0))), 1), lo=5.0, hi=5000.0)
    if t == "racetrack":
        hs = o.get("heights_m")
        if (not isinstance(hs, list) or not hs
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and 0 <= x <= 2000 for x in hs)):
            o.fail("heights_m", "a non-empty list of heights in [0, 2000] m", hs)
        return {"type": t, "centre": o.point("centre"), "heading_deg": o.num("heading_deg", 0.0),
                "straight_m": o.num("straight_m", 300.0, lo=0.0, hi=20000.0), "radius_m": radius,
                "heights_m": [float(x) for x in hs], "laps": o.num("laps", 1, lo=1, hi=100, integer=True),
                "turn": o.str("turn", "right", ("right", "left")), "speed_m_s": speed}
    if t == "flyby":
        return {"type": t, "through": o.point("through"), "heading_deg": o.num("heading_deg"),
                "length_m": o.num("length_m", 600.0, lo=1.0, hi=20000.0),
                "height_m": o.num("height_m", lo=0.0, hi=2000.0), "speed_m_s": speed, "radius_m": radius}
    return {"type": t, "to": o.point("to"), "heading_deg": o.num("heading_deg", None, allow_none=True),
            "height_m": o.num("height_m", lo=0.0, hi=2000.0), "speed_m_s": speed, "radius_m": radius}


def scenario_copy(scenario: Mapping[str, Any], **changes: Any) -> dict[str, Any]:
    """A deep copy of a scenario document with top-level fields replaced (for sweeps)."""
    out = copy.deepcopy(dict(scenario))
    out.update(copy.deepcopy(changes))
    return out
