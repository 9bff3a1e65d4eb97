"""campaign.json: reading the document and checking its fields (schema, origin, weather, vehicle,
microphones, flights, exclusions); each problem names the file and the field.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from gisnoise import acoustics
from gisnoise.errors import CampaignError, GisnoiseError
from gisnoise.flight import FLIGHT_SUFFIXES, as_unix_time
from gisnoise.geo import LocalFrame
from gisnoise.limits import check_range
from gisnoise.limits import current as current_limits
from gisnoise.measure.parts import Exclusion, Flight, Microphone, Problem

__all__ = ["SCHEMA"]

SCHEMA = "gisnoise/campaign/1"
SCHEMA_PREFIX = "gisnoise/campaign/"
SUPPORTED_VERSIONS = (1,)


class _Collector:
    """Raise at the first problem (strict) or collect them all."""

    def __init__(self, strict: bool) -> None:
        self.strict = strict
        self.problems: list[Problem] = []

    def add(self, file: str, field: str, message: str) -> None:
        if self.strict:
            raise CampaignError(message, field=field)
        self.problems.append(Problem(file, field, message))

    def error(self, file: str, exc: GisnoiseError) -> None:
        self.add(file, exc.field or "", str(exc))


def _read_document(cj: Path, col: _Collector) -> dict[str, Any] | None:
    """The JSON object of ``campaign.json``; None (after telling ``col``) when it is missing or not one."""
    cjs = str(cj)
    problem = None
    try:
        doc = json.loads(cj.read_text(encoding="utf-8-sig"))  # a byte-order mark is accepted, as in every JSON input
    except FileNotFoundError:
        problem = f"{cjs}: missing campaign file"
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        problem = f"{cjs}: not valid JSON ({exc})"
    else:
        if not isinstance(doc, dict):
            problem = f"{cjs}: expected a JSON object"
    if problem is not None:
        col.add(cjs, "campaign.json", problem)
        return None
    return doc


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _parse_header(cjs: str, doc: Mapping[str, Any], col: _Collector,
                  absorption: bool) -> tuple[LocalFrame, dict[str, Any], dict[str, Any], float] | None:
    schema = doc.get("schema")
    if not isinstance(schema, str) or not schema.startswith(SCHEMA_PREFIX):
        col.add(cjs, "schema", f"{cjs}: field 'schema' must be '{SCHEMA}', got {schema!r}")
        return None
    try:
        version = int(schema[len(SCHEMA_PREFIX):])
    except ValueError:
        version = -1
    if version not in SUPPORTED_VERSIONS:
        col.add(cjs, "schema", f"{cjs}: field 'schema': unknown version {schema!r}; this release reads {SCHEMA}")
        return None
    ok = True
    o = doc.get("origin")
    origin = None
    if not isinstance(o, dict) or not all(_is_number(o.get(k)) for k in ("lat", "lon", "h")):
        col.add(cjs, "origin", f"{cjs}: field 'origin' needs numbers lat, lon, h, got {o!r}")
        ok = False
    else:
        try:  # the microphones' rule: coordinates in range (never wrapped), the height plausible
            lim = current_limits()
            check_range("origin.h", o["h"], lim.min_height_m, lim.max_height_m, unit="m", source=cjs)
            origin = LocalFrame(float(o["lat"]), float(o["lon"]), float(o["h"]))
        except GisnoiseError as exc:
            if exc.field == "origin.h":
                col.add(cjs, "origin.h", str(exc))
            else:
                col.add(cjs, "origin", f"{cjs}: field 'origin': {exc}")
            ok = False
    w = doc.get("weather", {})
    weather: dict[str, Any] = {}
    if not isinstance(w, dict):
        col.add(cjs, "weather", f"{cjs}: field 'weather' must be an object")
        w = {}
    limits = {"temperature_c": (-60.0, 60.0), "humidity_pct": (0.0, 100.0), "pressure_kpa": (50.0, 110.0),
              "wind_speed_m_s": (0.0, 60.0), "wind_from_deg": (-360.0, 360.0)}
    for k, (lo, hi) in limits.items():
        v = w.get(k)
        if v is None:
            continue
        if not _is_number(v) or not lo <= v <= hi:
            col.add(cjs, f"weather.{k}", f"{cjs}: field 'weather.{k}' must be a number in [{lo:g}, {hi:g}], "
                    f"got {v!r}")
            ok = False
            continue
        weather[k] = float(v)
    weather.setdefault("pressure_kpa", 101.325)
    c = doc.get("speed_of_sound_m_s")
    if c is None:
        if "temperature_c" not in weather:
            col.add(cjs, "weather.temperature_c", f"{cjs}: field 'weather.temperature_c' is needed when "
                    "'speed_of_sound_m_s' is null")
            ok = False
            c = float("nan")
        else:
            c = float(acoustics.speed_of_sound(weather["temperature_c"]))
    elif not _is_number(c) or not 250.0 <= c <= 400.0:
        col.add(cjs, "speed_of_sound_m_s", f"{cjs}: field 'speed_of_sound_m_s' must be in [250, 400] m/s, "
                f"got {c!r}")
        ok = False
    if absorption:
        for k in ("temperature_c", "humidity_pct"):
            if k not in weather:
                col.add(cjs, f"weather.{k}", f"{cjs}: field 'weather.{k}' is needed for the absorption correction")
                ok = False
    v = doc.get("vehicle")
    vehicle: dict[str, Any] = {}
    if not isinstance(v, dict) or not _is_number(v.get("reference_power_w")) or v["reference_power_w"] <= 0:
        got = v.get("reference_power_w") if isinstance(v, dict) else v
        col.add(cjs, "vehicle.reference_power_w", f"{cjs}: field 'vehicle.reference_power_w' must be a positive "
                f"number (W), got {got!r}")
        ok = False
    else:
        vehicle = dict(v)
        vehicle["reference_power_w"] = float(v["reference_power_w"])
        vehicle.setdefault("name", "")
    if not ok or origin is None:
        return None
    return origin, weather, vehicle, float(c)


def _named_entries(cjs: str, doc: Mapping[str, Any], key: str, kind: str,
                   col: _Collector) -> Iterator[tuple[str, dict[str, Any], str]]:
    """``(where, entry, id)`` of each entry of the list ``doc[key]`` that is an object with a valid, unique id.

    The list being missing or empty, an entry not an object, a bad id and a duplicate ``kind`` id are
    reported to ``col`` (the entry is skipped)."""
    raw = doc.get(key)
    if not isinstance(raw, list) or not raw:
        col.add(cjs, key, f"{cjs}: field '{key}' must be a non-empty list")
        return
    seen = set()
    for i, m in enumerate(raw):
        where = f"{key}[{i}]"
        if not isinstance(m, dict):
            col.add(cjs, where, f"{cjs}: field '{where}' must be an object")
            continue
        mid = m.get("id")
        if not isinstance(mid, str) or not mid or "/" in mid or "\\" in mid:
            col.add(cjs, f"{where}.id", f"{cjs}: field '{where}.id' must be a non-empty name, got {mid!r}")
            continue
        if mid in seen:
            col.add(cjs, f"{where}.id", f"{cjs}: field '{where}.id': duplicate {kind} id {mid!r}")
            continue
        seen.add(mid)
        yield where, m, mid


FREE_TEXT_KEYS = ("name", "notes", "description")
"""Keys an entry of campaign.json may carry for people; gisnoise does not read them."""
MIC_KEYS = ("id", "lat", "lon", "h", "mount", "sensitivity_v_per_pa", "full_scale_v", "background_db", "height_agl_m")
FLIGHT_KEYS = ("id", "start_utc", "geoid_undulation_m", "power_w")


def _unknown_keys(cjs: str, where: str, entry: Mapping[str, Any], known: tuple[str, ...], col: _Collector) -> bool:
    """Report each key of ``entry`` gisnoise does not read (a misspelt one would be left out without a word),
    naming the nearest known key; True when there is none."""
    import difflib

    ok = True
    for k in entry:
        if k in known or k in FREE_TEXT_KEYS:
            continue
        near = difflib.get_close_matches(str(k), known, n=1, cutoff=0.6)
        col.add(cjs, f"{where}.{k}", f"{cjs}: field '{where}.{k}' is not one gisnoise reads"
                f"{f' (did you mean {near[0]!r}?)' if near else ''}; known: {', '.join(known)}, and free text in "
                f"{', '.join(FREE_TEXT_KEYS)}")
        ok = False
    return ok


def _parse_mics(cjs: str, doc: Mapping[str, Any], col: _Collector) -> list[Microphone]:
    out: list[Microphone] = []
    for where, m, mid in _named_entries(cjs, doc, "microphones", "microphone", col):
        good = _unknown_keys(cjs, where, m, MIC_KEYS, col)
        lim = current_limits()
        for k, (lo, hi) in (("lat", (-90.0, 90.0)), ("lon", (-180.0, 180.0)),
                            ("h", (lim.min_height_m, lim.max_height_m))):
            if k not in m:
                col.add(cjs, f"{where}.{k}", f"{cjs}: field '{where}.{k}' is missing (a number is needed)")
                good = False
                continue
            if not _is_number(m.get(k)):
                col.add(cjs, f"{where}.{k}", f"{cjs}: field '{where}.{k}' must be a number, got {m.get(k)!r}")
                good = False
                continue
            try:  # the shared rule set: coordinates in range (never wrapped), heights plausible
                check_range(f"{where}.{k}", m[k], lo, hi, source=cjs)
            except GisnoiseError as exc:
                col.add(cjs, f"{where}.{k}", str(exc))
                good = False
        mount = m.get("mount", "free_field")
        if not isinstance(mount, str) or mount not in acoustics.MOUNT_CORRECTIONS_DB:
            col.add(cjs, f"{where}.mount", f"{cjs}: field '{where}.mount': unknown mount {mount!r}; known: "
                    f"{', '.join(acoustics.MOUNT_CORRECTIONS_DB)}")
            good = False
        extra: dict[str, Any] = {}
        for k in ("sensitivity_v_per_pa", "full_scale_v", "background_db", "height_agl_m"):
            v = m.get(k)
            if v is None:
                continue
            if not _is_number(v) or (k == "height_agl_m" and v < 0) or (k not in ("background_db", "height_agl_m")
                                                                        and v <= 0):
                col.add(cjs, f"{where}.{k}", f"{cjs}: field '{where}.{k}' must be a positive number, got {v!r}")
                good = False
            else:
                extra[k] = float(v)
        if good:
            out.append(Microphone(id=mid, lat=float(m["lat"]), lon=float(m["lon"]), h=float(m["h"]),
                                  mount=str(mount), **extra))
    return out


def _parse_flights(cjs: str, root: Path, doc: Mapping[str, Any], col: _Collector) -> list[Flight]:
    out: list[Flight] = []
    for where, f, fid in _named_entries(cjs, doc, "flights", "flight", col):
        if not _unknown_keys(cjs, where, f, FLIGHT_KEYS, col):
            continue
        try:
            start = as_unix_time(f.get("start_utc"), field=f"{where}.start_utc")
        except GisnoiseError as exc:
            col.add(cjs, f"{where}.start_utc", f"{cjs}: field {exc}")
            continue
        und = f.get("geoid_undulation_m")
        if und is not None and not _is_number(und):
            col.add(cjs, f"{where}.geoid_undulation_m", f"{cjs}: field '{where}.geoid_undulation_m' must be a "
                    f"number, got {und!r}")
            continue
        pw = f.get("power_w")
        if pw is not None and not (_is_number(pw) and pw > 0):
            col.add(cjs, f"{where}.power_w", f"{cjs}: field '{where}.power_w' must be a positive number of watts, "
                    f"got {pw!r}")
            continue
        logs = [root / "flights" / f"{fid}{s}" for s in FLIGHT_SUFFIXES]
        fdir = root / "flights"
        found = sorted(p for p in fdir.iterdir() if p.stem == fid and p.suffix.lower() in FLIGHT_SUFFIXES
                       and p.is_file()) if fdir.is_dir() else []
        if not found:
            col.add(str(logs[0]), "flights", f"{logs[0]}: missing flight log for flight '{fid}' "
                    f"(.csv, .ulg or .bin)")
            log_path = ""
        elif len(found) > 1:
            col.add(str(found[0]), "flights", f"{found[0]}: flight '{fid}' has several logs "
                    f"({', '.join(p.name for p in found)}); keep one")
            log_path = ""
        else:
            log_path = str(found[0])
        out.append(Flight(id=fid, start_utc=start, log=log_path,
                          geoid_undulation_m=None if und is None else float(und),
                          power_w=None if pw is None else float(pw)))
    return out


def _parse_exclusions(src: str, raw: Any, col: _Collector, where: str) -> list[Exclusion]:
    if raw is None:
        return []
    if not isinstance(raw, list):
        col.add(src, where, f"{src}: field '{where}' must be a list")
        return []
    out = []
    for i, e in enumerate(raw):
        w = f"{where}[{i}]"
        if isinstance(e, Exclusion):
            out.append(e)
            continue
        if isinstance(e, (tuple, list)) and len(e) in (3, 4):
            e = dict(zip(("flight", "t0", "t1", "mic"), e, strict=False))
        if not isinstance(e, dict):
            col.add(src, w, f"{src}: field '{w}' must be an object with flight, t0, t1")
            continue
        if not isinstance(e.get("flight"), str) or not _is_number(e.get("t0")) or not _is_number(e.get("t1")) \
                or e["t1"] < e["t0"]:
            col.add(src, w, f"{src}: field '{w}' needs flight (name) and t0 <= t1 (s), got {e!r}")
            continue
        mic = e.get("mic")
        out.append(Exclusion(flight=e["flight"], t0=float(e["t0"]), t1=float(e["t1"]),
                             mic=None if mic is None else str(mic), reason=str(e.get("reason", ""))))
    return out
