"""Campaign simulator: synthetic flight-noise campaigns with a known truth.

:func:`simulate` flies the flights of a *scenario* (a JSON document, schema
``gisnoise/scenario/1``), propagates the noise of a truth model card to every
microphone and writes a measurement campaign in the format of
:mod:`gisnoise.measure.campaign` (``campaign.json``, ``flights/<flight>.csv``,
``mics/<mic>/<flight>.csv`` or ``.wav``) with ``truth.json`` beside it.
:func:`simulate_samples` runs the same physics and returns the
:class:`~gisnoise.measure.samples.Samples` table that reading the campaign would give,
without files (the fast path for tests of fit and diagnosis).

Forward propagation
-------------------
1. The flight is flown at ``output.sim_rate_hz`` from its patterns
   (:mod:`gisnoise.flight.patterns`): vertical climb and sink, hover with slow yaw,
   transitions, racetrack loops and fly-bys joined by Dubins paths.  Turns are
   coordinated: bank ``atan(v^2 / (g R))`` with ground speed ``v`` and radius ``R``.
   Yaw follows the air-relative velocity (crab angle in wind), pitch is
   ``vehicle.pitch_deg`` plus the flight-path angle, electric power follows a
   parasitic + induced + climb power law with a slow random part, and propeller
   speed follows power (``rpm ~ P^(1/3)``) with a slow random part of its own.
2. For every microphone the reception time ``t_r`` is sampled at
   ``output.subsamples`` points per block; the emission time solves
   ``t_r = t_e + d(t_e) / c``.  The UAV level at emission time comes from the
   truth card of the phase (:meth:`gisnoise.model.cards.ModelCard.level_uav`: the one
   model definition), spread over one-third-octave bands with the vehicle's
   spectrum (normalized so its A-weighted sum is exactly the card level), then
   the injected effects act (below).
3. Background (per band, A-weighted sum ``background.level_dba``) and
   transient events add energetically; energies are averaged over each
   reception block -> clean band levels and LA per block.
4. Measurement noise (``noise_std_db`` per microphone, Gaussian, one draw per
   block, the same in every band so LA and bands stay consistent) is added.
   Level CSVs are free-field.  WAV files are synthesized block by block as
   random-phase multisines on the block's FFT grid, so every block holds exactly
   the target energy in every band; the microphone's mount correction
   (:func:`gisnoise.acoustics.physics.mount_correction`, ground plate: -6 dB) is undone
   in the pressure so that the reader's free-field correction recovers the level.
5. The flight log (``output.log_rate_hz``) is the true state sampled, with the
   log noise of ``vehicle.log_noise`` added.

Injected effects (``effects`` object; each key turns one on, ``{}`` takes defaults)
----------------------------------------------------------------------------------
``bank_angle``
    Interaction noise of the non-axial propeller inflow in turning flight:
    ``dL = db_at_30deg * (sin|bank| / sin 30deg)^2`` plus a random fluctuation
    (Ornstein-Uhlenbeck in time, ``fluctuation_tau_s``) whose standard deviation is
    ``fluctuation_db`` scaled by the same factor.  Defaults 3 dB, 1 dB, 0.3 s.
``atmospheric_absorption``
    ISO 9613-1 pure-tone absorption at each band's exact mid-band frequency over
    the whole path: ``dL_band = -scale * alpha(f, T, h_r, p) * d``.  Default scale 1.
    (The card is the absorption-free emission, which the reader's per-band
    correction recovers.)
``ground_reflection``
    Microphones above ground (``height_m > 0``, mount ``free_field``) receive an image
    source: band energy factor ``1 + (r1/r2)^2 q^2 + 2 (r1/r2) q gamma <cos k dr>``
    with the band average of ``cos(2 pi f dr / c)`` over the band edges, path
    difference ``dr = r2 - r1``, reflection coefficient ``q`` (real) and coherence
    ``gamma``.  Defaults q = 0.9, gamma = 0.9.
``doppler``
    Convective amplification of a moving source:
    ``dL = -10 n log10(1 - M cos(angle))``, ``M = |v_ground| / c``, angle between the
    velocity and the emission direction.  Default exponent n = 4.
``emission_time``
    A clock offset between log and audio: the flight log's time stamps are late by
    ``offset_s`` (log time = true time + offset).  Default 0.5 s.
``wind``
    Refraction by the wind's speed gradient: downwind propagation gains, upwind
    loses, growing with horizontal range:
    ``dL = db_per_100m * (w / 5 m/s) * cos(psi) * (r_h / 100 m)``, clipped to
    +-``max_db``; ``psi`` is the angle between the direction the wind blows to and
    the horizontal direction UAV -> microphone.  Defaults 1.5 dB, 6 dB.  Needs
    ``weather.wind_speed_m_s > 0``.
``rpm``
    Propeller speed changing the level beyond what power explains:
    ``dL = db_per_decade * log10(rpm / rpm_p)``, with ``rpm_p`` the propeller speed
    the power alone sets.  Default 40 dB per decade.  (The rpm column is written
    in every campaign and varies independently of power by ``vehicle.rpm.jitter_pct``
    whether this effect is on or not.)
``background_event``
    Transient background sound heard on all microphones at once (a jet take-off):
    energy envelope ``sin^2(pi (t - t0) / duration)`` over ``[t0, t0 + duration]``,
    peak ``peak_dba`` (A-weighted), a low-frequency broadband spectrum and a small
    random offset per microphone (``mic_spread_db``).  Either ``events``: a list of
    ``{"flight", "t_s" (start), "duration_s", "peak_dba"}`` or ``count`` events per
    flight placed at random.  Defaults 1 per flight, 40 s, 62 dB(A), 1 dB.

Each effect's form and parameters are written to ``truth.json``.

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

Examples
--------
>>> round(float(np.degrees(coordinated_bank(24.0, 80.0))), 2)
36.29
"""

from __future__ import annotations

import copy
import json
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise import __version__, acoustics
from gisnoise.errors import InputError, ScenarioError
from gisnoise.flight import G, PathBuilder, from_columns
from gisnoise.geo import LocalFrame, emission_angles, wrap_angle
from gisnoise.jsonio import JsonObject, read_json_file
from gisnoise.measure import Samples
from gisnoise.model import cards as _cards
from gisnoise.model import load_card

__all__ = [
    "SCHEMA",
    "TRUTH_SCHEMA",
    "EFFECTS",
    "simulate",
    "simulate_samples",
    "run",
    "load_scenario",
    "dumps_truth",
    "resolve_scenario",
    "coordinated_bank",
    "SimulationResult",
    "ScenarioError",
]

SCHEMA = "gisnoise/scenario/1"
TRUTH_SCHEMA = "gisnoise/simulation-truth/1"
EFFECTS = ("bank_angle", "atmospheric_absorption", "ground_reflection", "doppler", "emission_time", "wind",
           "rpm", "background_event")
MOUNTS = tuple(acoustics.MOUNT_CORRECTIONS_DB)


Progress = Callable[[float], None]


# =========================================================================== physics kernels


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


def nominal_label(f_exact: float) -> str:
    """Nominal one-third-octave label (``'160'``, ``'31.5'``) of an exact mid-band frequency, Hz."""
    return str(acoustics.band_name(f_exact))[2:]


def band_edges(f_mid: Any) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper edges of base-10 one-third-octave bands, Hz."""
    f = np.asarray(f_mid, dtype=float)
    r = 10.0 ** (1.0 / 20.0)
    return f / r, f * r


def _a_sum(levels_db: np.ndarray, aw: np.ndarray) -> np.ndarray:
    """A-weighted overall level of band levels (last axis = bands), dB."""
    return 10.0 * np.log10(np.sum(10.0 ** ((levels_db + aw) / 10.0), axis=-1))


def source_spectrum(f_mid: np.ndarray, aw: np.ndarray, spec: Mapping[str, Any]) -> np.ndarray:
    """Relative band levels of the UAV, dB, normalized so their A-weighted sum is 0 dB.

    Tones at ``bpf_hz`` and its harmonics (``harmonics_db`` relative levels) fall in
    the band that holds them; broadband noise peaks at ``broadband_peak_hz`` with
    ``broadband_db`` and falls ``slope_low_db_oct`` / ``slope_high_db_oct`` per octave.
    """
    lo, hi = band_edges(f_mid)
    e = np.zeros(len(f_mid))
    for k, rel in enumerate(spec["harmonics_db"], start=1):
        f = k * spec["bpf_hz"]
        inb = (lo <= f) & (f < hi)
        e[inb] += 10.0 ** (rel / 10.0)
    octs = np.log2(f_mid / spec["broadband_peak_hz"])
    bb = spec["broadband_db"] - np.where(octs < 0, -octs * spec["slope_low_db_oct"], octs * spec["slope_high_db_oct"])
    e += 10.0 ** (bb / 10.0)
    rel = 10.0 * np.log10(e)
    return rel - _a_sum(rel, aw)


def background_spectrum(f_mid: np.ndarray, aw: np.ndarray, spec: Any) -> np.ndarray:
    """Relative background band levels, dB, A-weighted sum 0 dB.

    ``"ambient"``: flat up to 100 Hz, then -3 dB per octave (distant traffic and
    wind in vegetation); ``"pink"``: equal energy per band; or an object of nominal
    band label -> relative dB (bands not named get -inf)."""
    if spec == "pink":
        rel = np.zeros(len(f_mid))
    elif spec == "ambient":
        rel = -3.0 * np.maximum(np.log2(f_mid / 100.0), 0.0)
    else:
        labels = [nominal_label(f) for f in f_mid]
        rel = np.array([float(spec.get(lb, -np.inf)) for lb in labels])
    return rel - _a_sum(rel, aw)


def _event_spectrum(f_mid: np.ndarray, aw: np.ndarray) -> np.ndarray:
    """Jet take-off heard from afar: broadband peaking near 250 Hz, A-sum 0 dB."""
    octs = np.log2(f_mid / 250.0)
    rel = np.where(octs < 0, 3.0 * octs, -6.0 * octs)
    return rel - _a_sum(rel, aw)


def bank_angle_db(bank_rad: Any, db_at_30deg: float) -> np.ndarray:
    """Turning-flight interaction noise, ``db_at_30deg (sin|bank| / sin 30deg)^2``, dB."""
    s = np.sin(np.abs(np.asarray(bank_rad, dtype=float))) / 0.5
    return db_at_30deg * s * s


def doppler_db(vel_enu: np.ndarray, r_enu: np.ndarray, c: float, exponent: float) -> np.ndarray:
    """Convective amplification ``-10 n log10(1 - M cos)``, dB.

    ``vel_enu`` (..., 3) m/s source velocity, ``r_enu`` (..., 3) source -> observer."""
    d = np.linalg.norm(r_enu, axis=-1)
    m_cos = np.sum(vel_enu * r_enu, axis=-1) / (c * np.where(d > 0, d, 1.0))
    return -10.0 * exponent * np.log10(1.0 - m_cos)


def wind_db(r_enu: np.ndarray, wind_speed: float, wind_from_deg: float, db_per_100m: float,
            max_db: float) -> np.ndarray:
    """Refraction gain of downwind / loss of upwind propagation, dB (see module docstring)."""
    to = math.radians(wind_from_deg) + math.pi
    w = np.array([math.sin(to), math.cos(to)])
    rh = np.hypot(r_enu[..., 0], r_enu[..., 1])
    cos_psi = (r_enu[..., 0] * w[0] + r_enu[..., 1] * w[1]) / np.where(rh > 0, rh, 1.0)
    return np.clip(db_per_100m * wind_speed / 5.0 * cos_psi * rh / 100.0, -max_db, max_db)


def ground_reflection_db(src_enu: np.ndarray, mic_enu: np.ndarray, mic_height: float, f_mid: np.ndarray, c: float,
                         q: float, coherence: float) -> np.ndarray:
    """Band level change by a ground image source, dB, shape (..., n_bands).

    The ground plane lies ``mic_height`` m below the microphone; ``src_enu`` (..., 3)."""
    ground = mic_enu[2] - mic_height
    r1 = np.linalg.norm(src_enu - mic_enu, axis=-1)
    img = src_enu.copy()
    img[..., 2] = 2.0 * ground - img[..., 2]
    r2 = np.linalg.norm(img - mic_enu, axis=-1)
    dr = (r2 - r1)[..., None]
    lo, hi = band_edges(f_mid)
    k_lo, k_hi = 2 * np.pi * lo / c, 2 * np.pi * hi / c
    with np.errstate(invalid="ignore", divide="ignore"):
        avg = (np.sin(k_hi * dr) - np.sin(k_lo * dr)) / ((k_hi - k_lo) * dr)
    avg = np.where(dr > 1e-9, avg, 1.0)
    a = (r1 / r2)[..., None] * q
    return 10.0 * np.log10(1.0 + a * a + 2.0 * a * coherence * avg)


def _ou(rng: np.random.Generator, t: np.ndarray, std: float, tau: float) -> np.ndarray:
    """Slow random process sampled at times ``t`` (s): a stationary Ornstein-Uhlenbeck
    process (standard deviation ``std``, correlation time ``tau`` s) drawn every ``tau / 10``
    and interpolated linearly, so it is smooth at the scale a 10 Hz log resolves."""
    if std == 0 or len(t) == 0:
        return np.zeros(len(t))
    step = tau / 10.0
    tk = np.arange(t[0], t[-1] + step, step)
    x = np.empty(len(tk))
    x[0] = rng.normal(0.0, std)
    a = math.exp(-step / tau)
    w = rng.normal(0.0, std * math.sqrt(1.0 - a * a), len(tk))
    for i in range(1, len(tk)):
        x[i] = a * x[i - 1] + w[i]
    return np.interp(t, tk, x)


def _interp_angle(t: np.ndarray, tp: np.ndarray, a_rad: np.ndarray) -> np.ndarray:
    return np.arctan2(np.interp(t, tp, np.sin(a_rad)), np.interp(t, tp, np.cos(a_rad)))


def _rng(seed: int, *keys: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, *keys]))


# =========================================================================== scenario


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
_EFFECT_KEYS = {
    "bank_angle": {"db_at_30deg": 3.0, "fluctuation_db": 1.0, "fluctuation_tau_s": 0.3},
    "atmospheric_absorption": {"scale": 1.0},
    "ground_reflection": {"reflection_coefficient": 0.9, "coherence": 0.9},
    "doppler": {"exponent": 4.0},
    "emission_time": {"offset_s": 0.5},
    "wind": {"db_per_100m": 1.5, "max_db": 6.0},
    "rpm": {"db_per_decade": 40.0},
    "background_event": {"count": 1, "duration_s": 40.0, "peak_dba": 62.0, "mic_spread_db": 1.0, "events": None},
}
_EFFECT_FORMS = {
    "bank_angle": "dL = db_at_30deg * (sin|bank| / sin 30deg)^2 + OU fluctuation (std fluctuation_db * same factor,"
                  " correlation time fluctuation_tau_s)",
    "atmospheric_absorption": "dL_band = -scale * alpha_ISO9613-1(f_mid, T, RH, p) * d",
    "ground_reflection": "band energy * (1 + a^2 + 2 a coherence <cos(2 pi f dr / c)>_band), a = q r1 / r2;"
                         " microphones above ground, not ground-plate",
    "doppler": "dL = -10 exponent log10(1 - M cos(angle(v, source->mic))), M = |v_ground| / c",
    "emission_time": "flight log time = true time + offset_s",
    "wind": "dL = clip(db_per_100m * (w / 5 m/s) * cos(psi) * r_h / 100 m, +-max_db), psi from downwind direction",
    "rpm": "dL = db_per_decade * log10(rpm / rpm_from_power)",
    "background_event": "event energy peak_dba * sin^2(pi (t - t0) / duration_s) on all microphones at once"
                        " (+ per-mic offset N(0, mic_spread_db)), jet-like spectrum",
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
    cards: dict[str, _cards.ModelCard]
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
    c = c_given if c_given is not None else float(acoustics.speed_of_sound(out["weather"]["temperature_c"]))

    # ---------------------------------------------------------------- vehicle and cards
    v = _Obj(top.get("vehicle", {}), "vehicle", ("name", "reference_power_w", "mass_kg", "cruise_speed_m_s",
                                                 "pitch_deg", "cards", "power", "rpm", "spectrum", "log_noise"))
    card_refs = dict(_DEFAULT_CARDS)
    given = v.get("cards", {})
    if not isinstance(given, Mapping):
        raise ScenarioError(f"scenario: field 'vehicle.cards' must be an object phase -> card, got {given!r}",
                            field="vehicle.cards")
    for ph in given:
        if ph not in _cards.PHASES:
            raise ScenarioError(f"scenario: field 'vehicle.cards.{ph}': unknown phase; known: "
                                f"{', '.join(_cards.PHASES)}", field=f"vehicle.cards.{ph}")
    card_refs.update(given)
    cards = {ph: load_card(ref, f"vehicle.cards.{ph}", bdir, _Obj) for ph, ref in card_refs.items()}
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
        mount = mo.str("mount", "ground_plate", MOUNTS)
        height = mo.num("height_m", 0.0 if mount == "ground_plate" else 1.2, lo=0.0, hi=100.0)
        if mount == "ground_plate" and height != 0.0:
            mo.fail("height_m", "0 for a ground_plate microphone", height)
        if "lat" in m or "lon" in m:
            lat, lon = mo.num("lat", lo=-90.0, hi=90.0), mo.num("lon", lo=-180.0, hi=180.0)
            e, n, _ = frame.to_enu(lat, lon, out["origin"]["h"])
            e, n = float(e), float(n)
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
        if outp["band_max_hz"] * 10 ** 0.05 >= outp["fs_hz"] / 2:
            op.fail("fs_hz", f"above twice the top band edge ({2 * outp['band_max_hz'] * 10 ** 0.05:.0f} Hz)",
                     outp["fs_hz"])
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


# =========================================================================== flying

_MAX_CLIMB_ANGLE = math.radians(6.0)


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
    rng = _rng(sc.seed, index, 1)
    power = power * np.exp(_ou(rng, t, pw["jitter_pct"] / 100.0, pw["jitter_tau_s"]))
    power = np.maximum(power, 0.05 * pw["cruise_w"])
    rp = veh["rpm"]
    rpm_p = np.where(wing, rp["cruise_rpm"] * (power / pw["cruise_w"]) ** (1 / 3),
                     rp["hover_rpm"] * (power / pw["hover_w"]) ** (1 / 3))
    rpm = rpm_p * np.exp(_ou(rng, t, rp["jitter_pct"] / 100.0, rp["jitter_tau_s"]))
    vel = np.stack([vg[:, 0], vg[:, 1], p["vz"]], axis=1)
    true = {"t": t, "e": p["e"], "n": p["n"], "u": p["u"], "yaw": wrap_angle(yaw), "pitch": pitch, "roll": bank,
            "power_w": power, "rpm": rpm, "rpm_p": rpm_p, "airspeed_m_s": airspeed, "phase": phase, "vel": vel,
            "turn": p["turn"]}
    if "bank_angle" in doc["effects"]:
        ef = doc["effects"]["bank_angle"]
        true["bank_fluct"] = _ou(_rng(sc.seed, index, 2), t, 1.0, ef["fluctuation_tau_s"])
    # ---- the flight log
    lr = doc["output"]["log_rate_hz"]
    tl = np.arange(0.0, t[-1], 1.0 / lr)
    if t[-1] - tl[-1] > 1e-9:
        tl = np.append(tl, t[-1])
    lrng = _rng(sc.seed, index, 3)
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


def _flight_events(sc: Scenario, fl: _Flight, index: int, t_end: float) -> list[dict[str, Any]]:
    ef = sc.doc["effects"].get("background_event")
    if ef is None:
        return []
    if ef["events"] is not None:
        return [dict(e) for e in ef["events"] if e["flight"] == fl.id]
    rng = _rng(sc.seed, index, 4)
    dur = ef["duration_s"]
    out = []
    for _ in range(ef["count"]):
        t0 = float(rng.uniform(0.1 * t_end, max(0.1 * t_end, 0.9 * t_end - dur)))
        out.append({"flight": fl.id, "t_s": t0, "duration_s": dur, "peak_dba": ef["peak_dba"]})
    return out


# =========================================================================== propagation


@dataclass
class _Bands:
    f: np.ndarray  # exact mid-band, Hz
    labels: list[str]
    aw: np.ndarray  # A-weighting, dB
    src: np.ndarray  # UAV relative spectrum, dB (A-sum 0)
    bg: np.ndarray  # background relative spectrum, dB (A-sum 0)
    ev: np.ndarray  # event spectrum, dB (A-sum 0)
    alpha: np.ndarray  # absorption, dB/m


def _bands(sc: Scenario) -> _Bands:
    ac = acoustics
    op = sc.doc["output"]
    f = np.asarray(ac.third_octave_centres(op["band_min_hz"], op["band_max_hz"]), dtype=float)
    aw = np.asarray(ac.a_weighting(f), dtype=float)
    w = sc.doc["weather"]
    alpha = np.asarray(ac.atmospheric_absorption(f, w["temperature_c"], w["humidity_pct"], w["pressure_kpa"]),
                       dtype=float)
    return _Bands(f=f, labels=[nominal_label(x) for x in f], aw=aw,
                  src=source_spectrum(f, aw, sc.doc["vehicle"]["spectrum"]),
                  bg=background_spectrum(f, aw, sc.doc["background"]["spectrum"]), ev=_event_spectrum(f, aw),
                  alpha=alpha)


@dataclass
class _MicFlight:
    """Block levels of one microphone during one flight."""

    t: np.ndarray  # block centres, reception time, s
    bands: np.ndarray  # (n, nb) measured (noisy) band levels, dB
    la: np.ndarray  # measured LA, dB
    la_clean: np.ndarray  # LA without measurement noise, dB
    la_uav: np.ndarray  # UAV-only LA (with effects), dB


def _mic_flight(sc: Scenario, bands: _Bands, fl: _Flight, fi: int, mi: int) -> _MicFlight:
    doc = sc.doc
    mic = doc["microphones"][mi]
    eff = doc["effects"]
    c = sc.c
    tr = fl.true
    t = tr["t"]
    mic_enu = np.array([mic["e"], mic["n"], mic["height_m"]])
    pos = np.stack([tr["e"], tr["n"], tr["u"]], axis=1)
    t_rx = t + np.linalg.norm(mic_enu - pos, axis=1) / c  # monotonic: |v| << c
    blk = doc["output"]["block_s"]
    ns = doc["output"]["subsamples"]
    nblk = int(math.floor((t_rx[-1] + 1.0) / blk))
    tsub = ((np.arange(nblk)[:, None] + (np.arange(ns)[None, :] + 0.5) / ns) * blk).ravel()
    on = (tsub >= t_rx[0]) & (tsub <= t_rx[-1])
    te = np.interp(tsub[on], t_rx, t)
    # state at emission time
    x = np.stack([np.interp(te, t, tr[k]) for k in ("e", "n", "u")], axis=1)
    yaw, pitch, roll = (_interp_angle(te, t, tr[k]) for k in ("yaw", "pitch", "roll"))
    power = np.interp(te, t, tr["power_w"])
    idx = np.clip(np.searchsorted(t, te, side="right") - 1, 0, len(t) - 1)
    phase = tr["phase"][idx]
    r = mic_enu - x
    d, phi, theta = emission_angles(r[:, 0], r[:, 1], r[:, 2], yaw, pitch, roll)
    if len(d) and d.min() < 1.0:
        raise ScenarioError(f"scenario: flight {fl.id!r} passes {d.min():.2f} m from microphone {mic['id']!r}; "
                            f"keep at least 1 m", field=f"microphones[{mi}]")
    l_uav = np.empty(len(te))
    for ph in np.unique(phase):
        m = phase == ph
        card = sc.cards[str(ph)]
        l_uav[m] = card.level_uav(card.inputs(d[m], phi[m], theta[m], power[m]))
    dl = np.zeros(len(te))
    if "bank_angle" in eff:
        ef = eff["bank_angle"]
        fac = bank_angle_db(roll, 1.0)
        dl += ef["db_at_30deg"] * fac + ef["fluctuation_db"] * fac * np.interp(te, t, tr["bank_fluct"])
    if "doppler" in eff:
        vel = np.stack([np.interp(te, t, tr["vel"][:, k]) for k in range(3)], axis=1)
        dl += doppler_db(vel, r, c, eff["doppler"]["exponent"])
    if "wind" in eff:
        w = doc["weather"]
        dl += wind_db(r, w["wind_speed_m_s"], w["wind_from_deg"], eff["wind"]["db_per_100m"], eff["wind"]["max_db"])
    if "rpm" in eff:
        dl += eff["rpm"]["db_per_decade"] * np.log10(np.interp(te, t, tr["rpm"]) / np.interp(te, t, tr["rpm_p"]))
    lb = (l_uav + dl)[:, None] + bands.src[None, :]
    if "atmospheric_absorption" in eff:
        lb = lb - eff["atmospheric_absorption"]["scale"] * bands.alpha[None, :] * d[:, None]
    if "ground_reflection" in eff and mic["mount"] != "ground_plate" and mic["height_m"] > 0:
        ef = eff["ground_reflection"]
        lb = lb + ground_reflection_db(x, mic_enu, mic["height_m"], bands.f, c, ef["reflection_coefficient"],
                                       ef["coherence"])
    e_uav = np.zeros((len(tsub), len(bands.f)))
    e_uav[on] = 10.0 ** (lb / 10.0)
    # background (+ slow fluctuation) and events, in reception time
    bgd = doc["background"]
    bg_db = bgd["level_dba"] + _ou(_rng(sc.seed, fi, 10 + mi), tsub, bgd["fluctuation_db"], bgd["fluctuation_tau_s"])
    e_bg = 10.0 ** ((bg_db[:, None] + bands.bg[None, :]) / 10.0)
    for k, ev in enumerate(fl.events):
        u = (tsub - ev["t_s"]) / ev["duration_s"]
        env = np.where((u > 0) & (u < 1), np.sin(np.pi * np.clip(u, 0, 1)) ** 2, 0.0)
        off = _rng(sc.seed, fi, 100 + k, mi).normal(0.0, eff["background_event"]["mic_spread_db"])
        e_bg = e_bg + env[:, None] * 10.0 ** ((ev["peak_dba"] + off + bands.ev[None, :]) / 10.0)
    e_tot = (e_uav + e_bg).reshape(nblk, ns, -1).mean(axis=1)
    e_u = e_uav.reshape(nblk, ns, -1).mean(axis=1)
    clean = 10.0 * np.log10(e_tot)
    w_a = 10.0 ** (bands.aw / 10.0)
    la_clean = 10.0 * np.log10(e_tot @ w_a)
    with np.errstate(divide="ignore"):
        la_uav = 10.0 * np.log10(e_u @ w_a)
    noise = _rng(sc.seed, fi, 1000 + mi).normal(0.0, mic["noise_std_db"], nblk)
    tc = (np.arange(nblk) + 0.5) * blk
    return _MicFlight(t=tc, bands=clean + noise[:, None], la=la_clean + noise, la_clean=la_clean, la_uav=la_uav)


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
                arrays[key] = json.dumps(v, separators=(",", ":"), allow_nan=False)
                blk[k] = key
    text = json.dumps(doc, indent=1, allow_nan=False)
    for key, v in arrays.items():
        text = text.replace(json.dumps(key), v)
    return text + "\n"


def _r(a: np.ndarray, nd: int) -> list[float | None]:
    return [None if not np.isfinite(v) else round(float(v), nd) for v in a]


def run(scenario: Mapping[str, Any] | Scenario, *, base_dir: str | os.PathLike[str] | None = None,
        progress: Progress | None = None) -> SimulationResult:
    """Run the simulation in memory (no files); see :func:`simulate`."""
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


# =========================================================================== outputs


def _campaign_doc(res: SimulationResult) -> dict[str, Any]:
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
    lg = fl.log
    lat, lon, h = res.scenario.frame.to_wgs84(lg["e"], lg["n"], lg["u"])
    cols = {"t": lg["t"], "lat": lat, "lon": lon, "h": h, "roll": np.degrees(lg["roll"]),
            "pitch": np.degrees(lg["pitch"]), "yaw": np.degrees(lg["yaw"]), "power_w": lg["power_w"],
            "rpm": lg["rpm"], "airspeed_m_s": lg["airspeed_m_s"], "phase": lg["phase"]}
    return from_columns(cols, source=f"flight {fl.id}")


def _write_levels_csv(path: Path, mf: _MicFlight, labels: list[str], with_bands: bool) -> None:
    cols = ["t", "LA"] + ([f"L_{lb}" for lb in labels] if with_bands else [])
    data = np.column_stack([mf.t, mf.la] + ([mf.bands] if with_bands else []))
    fmt = ["%.4f", "%.2f"] + ["%.1f"] * (data.shape[1] - 2)
    np.savetxt(path, data, fmt=fmt, delimiter=",", header=",".join(cols), comments="")


def synthesize_wav(bands_db: np.ndarray, f_mid: np.ndarray, block_s: float, fs_hz: int, rng: np.random.Generator,
                   *, fade_s: float = 0.002) -> np.ndarray:
    """Pressure signal (Pa) whose every block holds the given one-third-octave band levels.

    Each block is a random-phase multisine on the block's FFT grid (bins ``k / block_s``);
    the bins inside a band share its energy equally and have the same phase in every
    block, so the signal is continuous and block ``j`` holds exactly the energy of
    ``bands_db[j]`` (re 20 uPa) apart from a linear amplitude cross-fade of
    ``fade_s`` s at each block boundary.

    Parameters
    ----------
    bands_db : ndarray, shape (n_blocks, n_bands)
        Target band levels, dB re 20 uPa.
    f_mid : ndarray, shape (n_bands,)
        Exact mid-band frequencies, Hz (base-10 one-third octaves).
    block_s : float
        Block length, s; ``fs_hz * block_s`` must be whole.
    fs_hz : int
        Sample rate, Hz.
    rng : numpy.random.Generator
        Source of the bin phases.
    """
    nb, nbands = bands_db.shape
    n = int(round(fs_hz * block_s))
    fk = np.arange(n // 2 + 1) / block_s
    lo, hi = band_edges(f_mid)
    band_of = np.full(len(fk), -1)
    for b in range(nbands):
        band_of[(fk >= lo[b]) & (fk < hi[b]) & (fk > 0) & (fk < fs_hz / 2)] = b
    counts = np.bincount(band_of[band_of >= 0], minlength=nbands)
    if np.any(counts == 0):
        b = int(np.flatnonzero(counts == 0)[0])
        raise ScenarioError(f"output.block_s {block_s:g} s is too short to hold the {f_mid[b]:.1f} Hz band "
                            f"(FFT bins {1 / block_s:g} Hz apart)", field="output.block_s")
    phases = np.exp(1j * rng.uniform(0, 2 * np.pi, len(fk)))
    p2 = (20e-6) ** 2 * 10.0 ** (bands_db / 10.0)  # mean-square pressure per band, Pa^2
    sel = band_of >= 0
    out = np.empty(nb * n)
    r = max(1, int(round(fade_s * fs_hz)))
    w = (np.arange(2 * r) + 0.5) / (2 * r)
    prev = None
    chunk = max(1, int(2_000_000 // n))
    for j0 in range(0, nb, chunk):
        j1 = min(nb, j0 + chunk)
        amp = np.zeros((j1 - j0, len(fk)))
        amp[:, sel] = np.sqrt(2.0 * p2[j0:j1][:, band_of[sel]] / counts[band_of[sel]])
        spec = amp * phases * (n / 2.0)
        blocks = np.fft.irfft(spec, n=n, axis=1)
        if prev is not None:
            blocks = np.vstack([prev[None, :], blocks])
        else:
            blocks = np.vstack([blocks[:1], blocks])  # dummy previous block: no fade at the start
        cur = blocks[1:].copy()
        prv = blocks[:-1]
        # fade: tail of block j-1 and head of block j use both signals (all components are n-periodic)
        head = (1 - w[r:]) * prv[:, :r] + w[r:] * cur[:, :r]
        tail_prev = (1 - w[:r]) * prv[:, n - r:] + w[:r] * cur[:, n - r:]
        if j0 > 0:
            out[j0 * n - r:j0 * n] = tail_prev[0]
        cur[:, :r] = head
        if len(cur) > 1:
            # tail of each block but the last in this chunk
            cur[:-1, n - r:] = tail_prev[1:]
        out[j0 * n:j1 * n] = cur.ravel()
        prev = blocks[-1]
    return out


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
    (out / "campaign.json").write_text(json.dumps(_campaign_doc(res), indent=2) + "\n", encoding="utf-8")
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
                                _rng(sc.seed, fi, 5000 + list(mics).index(mid)))
            # undo the reader's mount correction (ground plate: pressure doubling) and calibrate to volts
            gain = 10.0 ** (-acoustics.mount_correction(m["mount"]) / 20.0)
            acoustics.write_wav(d / f"{fl.id}.wav", pr * gain, op["fs_hz"], m["sensitivity_v_per_pa"])
        else:
            _write_levels_csv(d / f"{fl.id}.csv", mf, res.band_labels, op["bands"])
        if progress:
            progress((0.5 if wav else 0.9) + (0.45 if wav else 0.05) * (k + 1) / len(items))
    (out / "truth.json").write_text(dumps_truth(res.truth()), encoding="utf-8")
    if progress:
        progress(1.0)
    return out


# =========================================================================== samples


def simulate_samples(scenario: Mapping[str, Any] | str | os.PathLike[str] | SimulationResult, *,
                     base_dir: str | os.PathLike[str] | None = None, snr_db: float = 3.0) -> Samples:
    """The :class:`~gisnoise.measure.samples.Samples` table of a simulated campaign, without files.

    Same physics and random draws as :func:`simulate`; the table is built the way
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
        Scenario document, its JSON file, or the result of :func:`run`.
    base_dir : path, optional
        Folder card paths are relative to.
    snr_db : float
        Margin of the ``low_snr`` mask above the background, dB.
    """
    if isinstance(scenario, (str, os.PathLike)):
        scenario = load_scenario(scenario)
    from gisnoise.measure import emission_time  # the reader's solver: one definition

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


def scenario_copy(scenario: Mapping[str, Any], **changes: Any) -> dict[str, Any]:
    """A deep copy of a scenario document with top-level fields replaced (for sweeps)."""
    out = copy.deepcopy(dict(scenario))
    out.update(copy.deepcopy(changes))
    return out
