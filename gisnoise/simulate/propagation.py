"""The sound at the microphones: a truth card's level carried from the flying vehicle to each microphone.

For every microphone the reception time ``t_r`` is sampled at ``output.subsamples``
points per block; the emission time solves ``t_r = t_e + d(t_e) / c``.  The UAV level
at emission time comes from the truth card of the phase
(:meth:`gisnoise.model.ModelCard.level_uav`: the one model definition), spread over
one-third-octave bands with the vehicle's spectrum (normalized so its A-weighted sum
is exactly the card level), then the injected effects act
(:mod:`gisnoise.simulate.effects`).  Background (per band, A-weighted sum
``background.level_dba``) and transient events add energetically; energies are
averaged over each reception block -> clean band levels and LA per block.
Measurement noise (``noise_std_db`` per microphone, Gaussian, one draw per block, the
same in every band so LA and bands stay consistent) is added.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.acoustics import a_weighting, atmospheric_absorption, band_edges, band_name, third_octave_centres
from gisnoise.errors import ScenarioError
from gisnoise.geo import emission_angles
from gisnoise.simulate._random import ou_process, seeded_rng
from gisnoise.simulate.effects import bank_angle_db, doppler_db, ground_reflection_db, wind_db
from gisnoise.simulate.flying import _Flight, _interp_angle
from gisnoise.simulate.scenario import Scenario

__all__ = ["nominal_label", "source_spectrum", "background_spectrum"]


def nominal_label(f_exact: float) -> str:
    """Nominal one-third-octave label (``'160'``, ``'31.5'``) of an exact mid-band frequency, Hz."""
    return str(band_name(f_exact))[2:]


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


def _flight_events(sc: Scenario, fl: _Flight, index: int, t_end: float) -> list[dict[str, Any]]:
    """The transient background events of one flight (``background_event`` effect): given or placed at random."""
    ef = sc.doc["effects"].get("background_event")
    if ef is None:
        return []
    if ef["events"] is not None:
        return [dict(e) for e in ef["events"] if e["flight"] == fl.id]
    rng = seeded_rng(sc.seed, index, 4)
    dur = ef["duration_s"]
    out = []
    for _ in range(ef["count"]):
        t0 = float(rng.uniform(0.1 * t_end, max(0.1 * t_end, 0.9 * t_end - dur)))
        out.append({"flight": fl.id, "t_s": t0, "duration_s": dur, "peak_dba": ef["peak_dba"]})
    return out


@dataclass
class _Bands:
    """The one-third-octave bands of a scenario and the relative spectra in them."""

    f: np.ndarray  # exact mid-band, Hz
    labels: list[str]
    aw: np.ndarray  # A-weighting, dB
    src: np.ndarray  # UAV relative spectrum, dB (A-sum 0)
    bg: np.ndarray  # background relative spectrum, dB (A-sum 0)
    ev: np.ndarray  # event spectrum, dB (A-sum 0)
    alpha: np.ndarray  # absorption, dB/m


def _bands(sc: Scenario) -> _Bands:
    """The bands of the scenario's output, their A-weighting, spectra and absorption."""
    op = sc.doc["output"]
    f = np.asarray(third_octave_centres(op["band_min_hz"], op["band_max_hz"]), dtype=float)
    aw = np.asarray(a_weighting(f), dtype=float)
    w = sc.doc["weather"]
    alpha = np.asarray(atmospheric_absorption(f, w["temperature_c"], w["humidity_pct"], w["pressure_kpa"]),
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
    """What microphone ``mi`` hears of flight ``fi``: block levels with effects, background and noise."""
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
    bg_db = bgd["level_dba"] + ou_process(seeded_rng(sc.seed, fi, 10 + mi), tsub, bgd["fluctuation_db"],
                                          bgd["fluctuation_tau_s"])
    e_bg = 10.0 ** ((bg_db[:, None] + bands.bg[None, :]) / 10.0)
    for k, ev in enumerate(fl.events):
        u = (tsub - ev["t_s"]) / ev["duration_s"]
        env = np.where((u > 0) & (u < 1), np.sin(np.pi * np.clip(u, 0, 1)) ** 2, 0.0)
        off = seeded_rng(sc.seed, fi, 100 + k, mi).normal(0.0, eff["background_event"]["mic_spread_db"])
        e_bg = e_bg + env[:, None] * 10.0 ** ((ev["peak_dba"] + off + bands.ev[None, :]) / 10.0)
    e_tot = (e_uav + e_bg).reshape(nblk, ns, -1).mean(axis=1)
    e_u = e_uav.reshape(nblk, ns, -1).mean(axis=1)
    clean = 10.0 * np.log10(e_tot)
    w_a = 10.0 ** (bands.aw / 10.0)
    la_clean = 10.0 * np.log10(e_tot @ w_a)
    with np.errstate(divide="ignore"):
        la_uav = 10.0 * np.log10(e_u @ w_a)
    noise = seeded_rng(sc.seed, fi, 1000 + mi).normal(0.0, mic["noise_std_db"], nblk)
    tc = (np.arange(nblk) + 0.5) * blk
    return _MicFlight(t=tc, bands=clean + noise[:, None], la=la_clean + noise, la_clean=la_clean, la_uav=la_uav)

