"""The Samples table of a campaign: every level block at its emission time, with the flight
state, the absorption correction and the masks.

One row per microphone and block:

1. emission time from ``t_r = t_e + |x_uav(t_e) - x_mic| / c``
   (:func:`~gisnoise.measure.emission.emission_time`, solved to 1e-9 s on the
   piecewise-linear ENU track);
2. the flight state at ``t_e`` (:meth:`~gisnoise.flight.Trajectory.interpolate`, angles on the circle),
   ground velocity from the differentiated positions, distance and emission angles
   (:func:`gisnoise.geo.frames.emission_angles`);
3. optionally (``absorption=True``) the ISO 9613-1 absorption over the path ``d`` added
   back to the bands that stand 10 dB or more above their background; the level becomes
   ``10 log10(10^(LA/10) + sum_b 10^(LA_b/10) (10^(alpha_b d / 10) - 1))`` with ``LA_b``
   the A-weighted band level.  ``bands`` stay as measured;
4. masks, one reason per row, in this priority: ``outside_flight`` (emission time
   outside the flight log), ``on_ground`` (within the log while the vehicle is not flying: on
   the ground, no current; :meth:`~gisnoise.flight.Trajectory.flying_at`), ``excluded`` (user
   intervals), ``event`` (see
   :func:`~gisnoise.measure.events.detect_events`), ``low_snr`` (level below
   background + ``snr_db``); background and events as :mod:`gisnoise.measure.events`
   finds them.

Band backgrounds for the absorption correction are the median band levels of the
blocks outside the flight log when there are 8 or more, else the 10th percentile of
each band over the farthest quarter of the distances (which overstates it while the
UAV is still audible there, so fewer bands are corrected: the correction errs towards
too little).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gisnoise import acoustics
from gisnoise.errors import CampaignError
from gisnoise.geo import emission_angles
from gisnoise.measure.emission import emission_time
from gisnoise.measure.events import _background_and_excess, detect_events
from gisnoise.measure.samples import Samples

if TYPE_CHECKING:  # pragma: no cover
    from gisnoise.measure.parts import Campaign

__all__ = ["build_samples", "SIGNAL_BAND_MARGIN_DB"]

log = logging.getLogger(__name__)

SIGNAL_BAND_MARGIN_DB = 10.0
"""A band is absorption-corrected only when this far above its background, dB."""
BACKGROUND_PERCENTILE = 10.0


def _band_key(f_hz: Any) -> np.ndarray:
    """Nominal frequency, Hz: the key that identifies a band across files."""
    return np.asarray(acoustics.nominal_frequency(f_hz), dtype=float)


def build_samples(camp: Campaign) -> Samples:
    """All microphones and flights of a read campaign stacked at emission time (see the module docstring)."""
    c = camp.speed_of_sound_m_s
    parts: list[dict[str, Any]] = []
    band_set = np.unique(np.concatenate([_band_key(lv.band_f) for lv in camp.levels if lv.band_f is not None]
                                        or [np.zeros(0)]))
    band_f = np.asarray(acoustics.exact_frequency(band_set), dtype=float) if band_set.size else None
    mic_pos = {m.id: camp.mic_enu(m.id) for m in camp.microphones}
    tracks = {}
    for fid, tr in camp.trajectories.items():
        enu = np.stack(tr.enu(camp.origin), axis=-1)
        vel = np.gradient(enu, tr.t, axis=0) if len(tr) > 1 else np.zeros_like(enu)
        tracks[fid] = (tr, enu, vel)
    for lv in camp.levels:
        tr, enu, vel = tracks[lv.flight]
        m = mic_pos[lv.mic]
        t_e = emission_time(lv.t, tr.t, enu, m, c)
        st = tr.interpolate(t_e)
        x = np.stack([np.interp(t_e, tr.t, enu[:, i]) for i in range(3)], axis=-1)
        v = np.stack([np.interp(t_e, tr.t, vel[:, i]) for i in range(3)], axis=-1)
        r = m - x
        d, phi, theta = emission_angles(r[:, 0], r[:, 1], r[:, 2], np.radians(st["yaw"]), np.radians(st["pitch"]),
                                        np.radians(st["roll"]))
        n = len(lv.t)
        bands = None
        if band_f is not None:
            bands = np.full((n, len(band_f)), np.nan)
            if lv.bands is not None:
                cols = np.searchsorted(band_set, _band_key(lv.band_f))
                bands[:, cols] = lv.bands
        parts.append({
            "mic": np.full(n, lv.mic, dtype=object), "flight": np.full(n, lv.flight, dtype=object),
            "t_r": lv.t, "t_e": t_e, "level": lv.la.copy(), "d": d, "phi": phi, "theta": theta,
            "power_w": st["power_w"], "phase": st["phase"], "roll": st["roll"], "pitch": st["pitch"],
            "yaw": st["yaw"], "uav_enu": x, "mic_enu": np.broadcast_to(m, (n, 3)).copy(), "vel_enu": v,
            "rpm": st.get("rpm", np.full(n, np.nan)), "airspeed_m_s": st.get("airspeed_m_s", np.full(n, np.nan)),
            "bands": bands,
            "outside": (t_e < tr.t[0]) | (t_e > tr.t[-1]) | ~tr.flying_at(t_e),  # on the ground: no UAV sound
            "on_ground": (t_e >= tr.t[0]) & (t_e <= tr.t[-1]) & ~tr.flying_at(t_e),
            "has_bands": lv.bands is not None,
        })
    if not parts:
        raise CampaignError(f"{camp.folder}: no microphone levels to read", field="mics")
    cat = {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k not in ("bands", "has_bands")}
    bands_all = np.concatenate([p["bands"] for p in parts]) if band_f is not None else None
    mic = cat["mic"].astype(str)
    flight = cat["flight"].astype(str)
    n = len(mic)
    level = cat["level"]
    outside = cat["outside"]

    # absorption (band-wise, bands clear of their background only), on the measured level
    meta_uncorrected = []
    if camp.absorption:
        level = level.copy()
        w = camp.weather
        start = 0
        for p in parts:
            k = len(p["t_r"])
            sl = slice(start, start + k)
            start += k
            if not p["has_bands"] or bands_all is None or band_f is None:
                meta_uncorrected.append((str(p["mic"][0]), str(p["flight"][0])))
                continue
            b = bands_all[sl]
            d = cat["d"][sl]
            quiet = outside[sl]
            if quiet.sum() >= 8:   # blocks before/after the flight: the background itself
                bg_b = np.array([np.median(col[np.isfinite(col)]) if np.isfinite(col).any() else np.nan
                                 for col in b[quiet].T])
            else:                  # the quiet end of the farthest quarter (high while the UAV is audible)
                far = ~quiet
                if far.any():
                    far &= d >= np.percentile(d[far], 75.0)
                bg_b = acoustics.background_levels(b[far], BACKGROUND_PERCENTILE) if far.any() else \
                    np.full(b.shape[1], np.inf)
            bg_b = np.where(np.isnan(bg_b), np.inf, bg_b)  # a band absent here is never corrected
            level[sl] = acoustics.absorption_corrected_level(
                level[sl], b, band_f, d, w["temperature_c"], w["humidity_pct"], w.get("pressure_kpa", 101.325),
                background_db=bg_b, min_snr_db=SIGNAL_BAND_MARGIN_DB)

    # masks
    reason = np.full(n, "", dtype=object)
    excluded = np.zeros(n, dtype=bool)
    for e in camp.exclusions:
        sel = (flight == e.flight) & (cat["t_r"] >= e.t0) & (cat["t_r"] <= e.t1)
        if e.mic is not None:
            sel &= mic == e.mic
        excluded |= sel
    given = {m.id: m.background_db for m in camp.microphones}
    background, excess, bg_how = _background_and_excess(given, mic, flight, cat, level, outside, excluded)
    with np.errstate(invalid="ignore"):
        low = level < background + camp.snr_db
    event = np.zeros(n, dtype=bool)
    for fid in np.unique(flight):
        rows = [np.flatnonzero((flight == fid) & (mic == mid)) for mid in np.unique(mic[flight == fid])]
        flags = detect_events([cat["t_r"][r] for r in rows], [excess[r] for r in rows], event_db=camp.event_db)
        for r, fl in zip(rows, flags, strict=True):
            event[r] = fl
    reason[low] = "low_snr"
    reason[event] = "event"
    reason[excluded] = "excluded"
    reason[outside] = "outside_flight"
    reason[cat["on_ground"]] = "on_ground"
    reason = reason.astype(str)

    rpm = cat["rpm"] if np.isfinite(cat["rpm"]).any() else None
    airspeed = cat["airspeed_m_s"] if np.isfinite(cat["airspeed_m_s"]).any() else None
    meta = {
        "folder": camp.folder.name,
        "origin": {"lat": camp.origin.lat0, "lon": camp.origin.lon0, "h": camp.origin.h0},
        "weather": dict(camp.weather),
        "vehicle": dict(camp.vehicle),
        "reference_power_w": camp.reference_power_w,
        "speed_of_sound_m_s": c,
        "absorption_corrected": bool(camp.absorption),
        "absorption_uncorrected_series": meta_uncorrected,
        "background": bg_how,
        "snr_db": camp.snr_db,
        "event_db": camp.event_db,
        "flights": {f.id: {"start_utc": f.start_utc, "log": Path(f.log).name} for f in camp.flights},
        "microphones": {m.id: {"lat": m.lat, "lon": m.lon, "h": m.h, "mount": m.mount,
                               **({} if m.height_agl_m is None else {"height_agl_m": m.height_agl_m})}
                        for m in camp.microphones},
    }
    if meta_uncorrected:
        log.info("absorption not corrected for %d series without band levels", len(meta_uncorrected))
    return Samples(mic=mic, flight=flight, t_r=cat["t_r"], t_e=cat["t_e"], level=level, d=cat["d"],
                   phi=cat["phi"], theta=cat["theta"], power_w=cat["power_w"], phase=cat["phase"].astype(str),
                   roll=cat["roll"], pitch=cat["pitch"], yaw=cat["yaw"], uav_enu=cat["uav_enu"],
                   mic_enu=cat["mic_enu"], vel_enu=cat["vel_enu"], valid=reason == "", mask_reason=reason,
                   rpm=rpm, airspeed_m_s=airspeed, band_f=band_f, bands=bands_all, background_db=background,
                   meta=meta)
