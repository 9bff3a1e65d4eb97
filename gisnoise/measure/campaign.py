"""The measurement campaign: folder -> levels at emission time (:class:`~gisnoise.measure.samples.Samples`).

A campaign folder (see the specification, section 3)::

    campaign.json
    flights/<flight>.csv | .ulg | .bin
    mics/<mic>/<flight>.csv     # levels: t, LA, optional L_<nominal Hz>
    mics/<mic>/<flight>.wav     # or raw audio (mono, first sample at start_utc)

:func:`read_campaign` reads and checks everything and raises
:class:`~gisnoise.errors.CampaignError` (naming the file and field) at the first
problem; :func:`check_campaign` collects every problem instead.  What is read but
should be said (a flight log cut short) is not a problem: :func:`campaign_log_warnings`
gives it, one line per log, for every face to show.  Where both a level
CSV and a WAV exist for a microphone and flight, the CSV is read (``gisnoise
campaign levels`` writes it from the WAV), unless its source record says it was computed
with another calibration of the microphone or from another WAV: then it is refused
(:func:`gisnoise.measure.provenance.stale_source`).

Optional keys of ``campaign.json`` beyond the specification: ``sample_rate_hz`` (all
WAV files must have it; otherwise they must share one rate), ``block_s`` (averaging
block of WAV input, default 0.125 s), per microphone ``full_scale_v`` (voltage of
digital full scale of integer or float WAV samples, default 1 V) and
``background_db`` (the A-weighted background level, dB, replacing the estimate),
per flight ``geoid_undulation_m`` (for logs that give heights above mean sea level
only; default the EGM96 grid, :mod:`gisnoise.geo.geoid`) and ``power_w`` (a constant electric power, W, for logs without battery current), and ``exclusions``: ``[{"flight": .., "t0": .., "t1": .., "mic": ..}]``
(reception times, s since the flight's start; ``mic`` optional).  An exclusion also lets the
levels of a WAV file leave out a clipped or dropped-out stretch it holds (otherwise refused).

:meth:`Campaign.samples <gisnoise.measure.parts.Campaign.samples>` turns the levels into one
row per microphone and block at emission time (:mod:`gisnoise.measure.table`), with
the background and the masks of :mod:`gisnoise.measure.events`.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import CampaignError, GisnoiseError
from gisnoise.flight import Trajectory, flying_segments, ground_from_track, read_flight, track_warning
from gisnoise.limits import GROUND_TOLERANCE_M
from gisnoise.measure.document import (
    _Collector,
    _is_number,
    _parse_exclusions,
    _parse_flights,
    _parse_header,
    _parse_mics,
    _read_document,
)
from gisnoise.measure.events import DEFAULT_EVENT_DB, DEFAULT_SNR_DB
from gisnoise.measure.levels import (
    DEFAULT_BLOCK_S,
    _most_common_rate,
    _wav_rate,
    band_limit_warnings,
    read_level_csv,
    wav_levels,
)
from gisnoise.measure.parts import Campaign, Flight, LevelSeries, Microphone, Problem, ProgressFn
from gisnoise.measure.provenance import read_source_record, source_record_path, stale_source
from gisnoise.measure.spreading import spreading_notes

__all__ = ["read_campaign", "check_campaign", "inspect_campaign", "campaign_log_warnings", "FAR_TRACK_M",
           "QUIET_PERCENTILE", "BACKGROUND_MARGIN_DB", "UNSTATED_MIC_HEIGHT_M"]

FAR_TRACK_M = 10_000.0
"""A flight track whose nearest point lies farther than this from every microphone (m) cannot have been heard:
spherical spreading alone takes 80 dB off the level at 1 m over 10 km (air absorption more), far below any
outdoor background.  A flight with no block within its log names that distance instead of its clock."""

UNSTATED_MIC_HEIGHT_M = 10.0
"""How high above its ground a microphone without ``height_agl_m`` (and not on a ground plate) may stand, m, for
the heights check of the flight logs: tripods stand 1.2-4 m high, masts up to 10 m."""

QUIET_PERCENTILE = 2.0
"""The quiet end of a microphone's levels that :func:`campaign_log_warnings` compares with its stated
background, percent of its blocks."""

BACKGROUND_MARGIN_DB = 3.0
"""How far below its stated background a microphone's quiet end (:data:`QUIET_PERCENTILE`) may lie, dB: a
measured level is the energetic sum of the UAV and the background, so only the background's own fluctuation
takes a block below it; 2 % of the blocks lie 3 dB or more below only for a background fluctuating by more than
1.5 dB (std of its block levels), the rule by which the level-trend fit refuses a background estimate
(:func:`gisnoise.measure.events.fit_level_trend`)."""


def read_campaign(folder: str | os.PathLike[str], *, exclusions: Iterable[Any] | None = None,
                  absorption: bool = False, snr_db: float = DEFAULT_SNR_DB, event_db: float = DEFAULT_EVENT_DB,
                  block_s: float | None = None, progress: ProgressFn | None = None) -> Campaign:
    """Read and check a campaign folder.

    Parameters
    ----------
    folder : path-like
        The campaign folder (``campaign.json``, ``flights/``, ``mics/``).
    exclusions : iterable, optional
        Extra excluded intervals: :class:`~gisnoise.measure.parts.Exclusion`, mappings with ``flight``, ``t0``,
        ``t1`` (reception time, s) and optional ``mic``, or tuples
        ``(flight, t0, t1[, mic])``.  Added to those of campaign.json.
    absorption : bool
        Correct levels for atmospheric absorption (rows with band levels only).
    snr_db : float
        Margin above the background below which rows are masked ``low_snr``, dB.
    event_db : float
        Joint rise flagging an ``event``, dB.
    block_s : float, optional
        Averaging block for WAV input, s (default: campaign.json ``block_s`` or 0.125).
    progress : callable, optional
        ``progress(done, total)`` after each microphone file; may raise
        :class:`~gisnoise.errors.Cancelled`.

    Raises
    ------
    CampaignError
        At the first problem, naming the file and the field; among them a flight log whose
        heights put the vehicle below the microphones' ground (field ``h``) and a level file
        none of whose blocks falls within its flight's log (field ``t``; the samples are
        computed to find it).
    """
    camp, col = _load(folder, strict=True, exclusions=exclusions, absorption=absorption, snr_db=snr_db,
                      event_db=event_db, block_s=block_s, progress=progress)
    assert camp is not None
    if camp.levels:   # a series none of whose blocks falls within its flight log is refused as check reports it
        _outside_problems(camp, camp.samples(), col)
    return camp


def inspect_campaign(folder: str | os.PathLike[str], **kwargs: Any) -> tuple[Campaign | None, list[Problem]]:
    """Read what can be read and collect every problem (the keywords of :func:`read_campaign`).

    Returns the campaign built from the readable parts (None when campaign.json
    itself is unusable) and the problems.  Samples are computed to find problems of
    the geometry (levels outside the flight log, say).
    """
    camp, collector = _load(folder, strict=False, **kwargs)
    if camp is not None and camp.levels:
        try:
            s = camp.samples()
        except GisnoiseError as exc:
            collector.error(str(Path(folder) / "campaign.json"), exc)
        else:
            _outside_problems(camp, s, collector)
            cjs = str(Path(folder) / "campaign.json")
            for note in spreading_notes(s):
                collector.add(cjs, "microphones", f"{cjs}: {note}")
    return camp, collector.problems


def campaign_log_warnings(camp: Campaign) -> list[str]:
    """The one-line warnings about a campaign: its flight logs, in the order of its flights, then its microphones.

    What :func:`gisnoise.flight.track_warning` says about each flight's log, naming
    the file: a log cut short (a dead battery, a full SD card, a broken download) is
    read up to its cut and fitted or diagnosed as far as it goes, not a problem of the
    campaign, but said.  Then each microphone whose quiet levels lie below the
    background campaign.json states for it: the quiet end of its levels (their
    :data:`QUIET_PERCENTILE` percentile over its files, user exclusions left out, 50
    blocks or more) more than :data:`BACKGROUND_MARGIN_DB` below its ``background_db``.
    A measured level holds the background, so this says the levels are too low (a
    calibration or sensitivity error) or the stated background too high.  Then each
    microphone and flight whose airborne blocks are :data:`MOSTLY_MASKED` or more masked
    (``low_snr``, ``event``): they are lost to fit and diagnosis.  Then the levels of WAV
    recordings whose sample rate cannot carry the one-third-octave bands up to 16 kHz
    (below 44.1 kHz; :func:`gisnoise.measure.levels.band_limit_warnings`: the files, their
    rate, their highest band and what a pink source's A-weighted level loses without the
    bands above).  The one list
    every face shows: the command line prints each line on stderr as
    ``warning: <line>``; the service's fit and diagnose jobs carry them in their
    result's ``warnings``.

    Parameters
    ----------
    camp : Campaign
        A campaign of :func:`read_campaign` (or :func:`inspect_campaign`).

    Returns
    -------
    list of str
        One line per flight whose log needs one, per microphone below its background, per microphone
        and flight mostly masked, per sample rate below 44.1 kHz; empty when none does.
    """
    out = []
    for f in camp.flights:
        traj = camp.trajectories.get(f.id)
        w = track_warning(traj) if traj is not None else None
        if w is not None:
            out.append(w)
    return out + _background_warnings(camp) + _masked_warnings(camp) + band_limit_warnings(camp.levels)


MOSTLY_MASKED = 0.9
"""Share of a microphone's airborne blocks masked (``low_snr``, ``event``) that :func:`campaign_log_warnings` names."""


def _masked_warnings(camp: Campaign) -> list[str]:
    """One line per microphone and flight whose airborne blocks (not excluded by the user) are mostly masked.

    Their levels are then lost to fit and diagnosis: a background stated or estimated too high, a calibration
    error or events everywhere; the line names the masks and the background with where it came from.
    """
    if not camp.levels:
        return []
    try:
        s = camp.samples()
    except GisnoiseError:  # a campaign whose samples cannot be built has its problems said elsewhere
        return []
    how = {(b["mic"], b["flight"]): b for b in s.meta.get("background", [])}
    out = []
    for (mic, flight), b in how.items():
        rows = (s.mic == mic) & (s.flight == flight) & ~np.isin(s.mask_reason, ("outside_flight", "on_ground",
                                                                                 "excluded"))
        n = int(rows.sum())
        masked = rows & ~s.valid
        if n < 8 or masked.sum() < MOSTLY_MASKED * n:
            continue
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(zip(*np.unique(s.mask_reason[masked], return_counts=True),
                                                                strict=True)))
        bg = b.get("background_db")
        bg_text = (f"the background {bg:.1f} dB(A) ({b['source']})" if bg is not None and np.isfinite(bg)
                   else "no background")
        out.append(f"microphone '{mic}', flight '{flight}': {int(masked.sum())} of its {n} airborne blocks are masked "
                   f"({reasons}; {bg_text}, levels {float(np.nanmin(s.level[rows])):.1f}-"
                   f"{float(np.nanmax(s.level[rows])):.1f} dB(A)) and are lost to fit and diagnose: check the stated "
                   "background_db, the calibration or the exclusions")
    return out


def _background_warnings(camp: Campaign) -> list[str]:
    """One line per microphone whose quiet levels lie below its stated background (see :func:`campaign_log_warnings`)."""
    out = []
    for m in camp.microphones:
        if m.background_db is None:
            continue
        la = [lv.la[_kept(camp, lv)] for lv in camp.levels if lv.mic == m.id]
        levels = np.concatenate(la) if la else np.zeros(0)
        if levels.size < 100.0 / QUIET_PERCENTILE:
            continue
        quiet = float(np.percentile(levels, QUIET_PERCENTILE))
        if quiet < m.background_db - BACKGROUND_MARGIN_DB:
            out.append(f"microphone '{m.id}': the quietest {QUIET_PERCENTILE:g} % of its {levels.size} levels lie "
                       f"below {quiet:.1f} dB(A), {m.background_db - quiet:.1f} dB under the background_db "
                       f"{m.background_db:g} dB(A) campaign.json states for it; a level holds the background and "
                       f"lies below it only by the background's fluctuation (allowed {BACKGROUND_MARGIN_DB:g} dB): "
                       "check its calibration (sensitivity_v_per_pa, full_scale_v, the level files) or its "
                       "background_db")
    return out


def _kept(camp: Campaign, lv: LevelSeries) -> np.ndarray:
    """Finite levels of a series outside the user's exclusions."""
    keep = np.isfinite(lv.la)
    for e in camp.exclusions:
        if e.flight == lv.flight and (e.mic is None or e.mic == lv.mic):
            keep &= ~((lv.t >= e.t0) & (lv.t <= e.t1))
    return keep


def _outside_problems(camp: Campaign, s: Any, col: _Collector) -> None:
    """A level file none of whose blocks falls within its flight's log: its clock (start_utc), or a track far
    from the microphones (farther than :data:`FAR_TRACK_M`: another place's log)."""
    for lv in camp.levels:
        m = (s.mic == lv.mic) & (s.flight == lv.flight)
        if not m.any() or not np.all(np.isin(s.mask_reason[m], ("outside_flight", "on_ground"))):
            continue
        traj = camp.trajectories[lv.flight]
        grounded = s.mask_reason[m] == "on_ground"
        if grounded.any():  # the clock can be right: the recording misses only the airborne part
            te = s.t_e[m][grounded]
            col.add(lv.source, "t", f"{lv.source}: no block falls while flight '{lv.flight}' is airborne: its "
                    f"{int(grounded.sum())} block(s) emitted within the log ({te.min():.1f}-{te.max():.1f} s) find "
                    f"the vehicle on the ground, and it flies at {_airborne_text(traj)} s of the log; the recording "
                    "misses the flight, or check start_utc")
            continue
        far = _track_distance_m(traj, camp.microphones)
        hint = (f"the flight track is {far / 1000.0:,.0f} km from the microphones; check that the log is this "
                "campaign's" if far > FAR_TRACK_M else "check start_utc")
        col.add(lv.source, "t", f"{lv.source}: no block falls within the flight log of '{lv.flight}' ({hint})")


def _airborne_text(traj: Trajectory) -> str:
    """The log's airborne stretches (:func:`gisnoise.flight.flying_segments`, the stretches a map evaluates),
    ``a-b, c-d`` (s of the log), or ``no time`` when it never flies."""
    t = np.asarray(traj.t, float)
    segs = flying_segments(traj)
    return ", ".join(f"{t[a]:.1f}-{t[b - 1]:.1f}" for a, b in segs) if segs else "no time"


def _track_distance_m(traj: Trajectory, mics: tuple[Microphone, ...]) -> float:
    """Great-circle distance from the track's nearest point to the nearest microphone, m (haversine, mean radius)."""
    if not mics:
        return 0.0
    lat = np.radians(np.asarray(traj.lat, float))[:, None]
    lon = np.radians(np.asarray(traj.lon, float))[:, None]
    mlat = np.radians([m.lat for m in mics])[None, :]
    mlon = np.radians([m.lon for m in mics])[None, :]
    a = np.sin((lat - mlat) / 2) ** 2 + np.cos(lat) * np.cos(mlat) * np.sin((lon - mlon) / 2) ** 2
    return float(2.0 * 6_371_008.8 * np.arcsin(np.sqrt(np.clip(np.min(a), 0.0, 1.0))))


def _mic_ground(m: Microphone) -> float:
    """The lowest a microphone's ground can lie, m ellipsoidal: its ``h`` less ``height_agl_m``; a ground plate
    lies on it; another mount of unstated height stands at most :data:`UNSTATED_MIC_HEIGHT_M` above it."""
    if m.height_agl_m is not None:
        return m.h - m.height_agl_m
    return m.h if m.mount == "ground_plate" else m.h - UNSTATED_MIC_HEIGHT_M


def _below_ground(f: Flight, traj: Trajectory, mics: list[Microphone]) -> str | None:
    """The flight's heights in the wrong datum: more than half its airborne samples more than
    GROUND_TOLERANCE_M below the lowest microphone's ground (:func:`_mic_ground`)."""
    if not mics or len(traj) == 0:
        return None
    ground = min(_mic_ground(m) for m in mics)
    fly = np.asarray(traj.flying, bool)
    h = np.asarray(traj.h, float)[fly] if fly.any() else np.asarray(traj.h, float)
    below = h < ground - GROUND_TOLERANCE_M
    if below.mean() <= 0.5:
        return None
    g = ground_from_track(traj)
    by = (f"its take-off or landing at {g:.1f} m lies {ground - g:.1f} m below that ground" if g is not None
          else f"its median airborne height {float(np.median(h)):.1f} m lies {ground - float(np.median(h)):.1f} m "
               "below that ground")
    return (f"{f.log}: field 'h' of flight '{f.id}' puts the vehicle below the microphones' ground ({ground:.1f} m, "
            f"ellipsoidal) for {100.0 * below.mean():.0f} % of its airborne time: {by}; heights must be ellipsoidal "
            "(a log above mean sea level needs the flight's geoid_undulation_m, one above take-off the take-off's "
            "ellipsoidal height added)")


def check_campaign(folder: str | os.PathLike[str], **kwargs: Any) -> list[Problem]:
    """Every problem of a campaign folder (empty when it reads cleanly)."""
    return inspect_campaign(folder, **kwargs)[1]


def _load(folder: str | os.PathLike[str], *, strict: bool, exclusions: Iterable[Any] | None = None,
          absorption: bool = False, snr_db: float = DEFAULT_SNR_DB, event_db: float = DEFAULT_EVENT_DB,
          block_s: float | None = None, progress: ProgressFn | None = None) -> tuple[Campaign | None, _Collector]:
    col = _Collector(strict)
    root = Path(folder)
    cj = root / "campaign.json"
    cjs = str(cj)
    for name, v in (("snr_db", snr_db), ("event_db", event_db)):
        if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
            raise CampaignError(f"{name} must be a non-negative number, got {v!r}", field=name)
    if not root.is_dir():
        col.add(str(root), "folder", f"{root}: no such campaign folder")
        return None, col
    doc = _read_document(cj, col)
    if doc is None:
        return None, col
    header = _parse_header(cjs, doc, col, absorption)
    if header is None:
        return None, col
    origin, weather, vehicle, c = header
    mics = _parse_mics(cjs, doc, col)
    flights = _parse_flights(cjs, root, doc, col)
    excl = _parse_exclusions(cjs, doc.get("exclusions"), col, "exclusions")
    excl += _parse_exclusions("exclusions", list(exclusions) if exclusions is not None else None, col,
                              "exclusions")
    fids, mids = {f.id for f in flights}, {m.id for m in mics}
    raw_mids = {m.get("id") for m in doc.get("microphones", []) if isinstance(m, dict)} \
        if isinstance(doc.get("microphones"), list) else set()
    for i, e in enumerate(excl):
        if e.flight not in fids:
            col.add(cjs, "exclusions", f"{cjs}: exclusion {i} names unknown flight {e.flight!r}")
        elif e.mic is not None and e.mic not in mids and e.mic not in raw_mids:
            col.add(cjs, "exclusions", f"{cjs}: exclusion {i} names unknown microphone {e.mic!r}")
    rate = doc.get("sample_rate_hz")
    if rate is not None and not (_is_number(rate) and rate > 0):
        col.add(cjs, "sample_rate_hz", f"{cjs}: field 'sample_rate_hz' must be a positive number, got {rate!r}")
        rate = None
    if block_s is None:
        block_s = doc.get("block_s", DEFAULT_BLOCK_S)
    if not (_is_number(block_s) and block_s > 0):
        col.add(cjs, "block_s", f"{cjs}: field 'block_s' must be a positive number, got {block_s!r}")
        block_s = DEFAULT_BLOCK_S
    # flights
    trajectories: dict[str, Trajectory] = {}
    for f in flights:
        if not f.log:
            continue
        try:
            trajectories[f.id] = read_flight(f.log, start_utc=f.start_utc, geoid_undulation_m=f.geoid_undulation_m,
                                             power_w=f.power_w)
        except GisnoiseError as exc:
            col.error(f.log, exc)
            continue
        wrong_datum = _below_ground(f, trajectories[f.id], mics)
        if wrong_datum is not None:
            col.add(f.log, "h", wrong_datum)
    # microphone files
    pairs = []
    for m in mics:
        for f in flights:
            base = root / "mics" / m.id / f.id
            csv_p, wav_p = base.with_suffix(".csv"), base.with_suffix(".wav")
            if csv_p.is_file():
                pairs.append((m, f, csv_p))
            elif wav_p.is_file():
                pairs.append((m, f, wav_p))
            else:
                col.add(str(wav_p), "mics", f"{wav_p}: missing microphone file (no {f.id}.wav or {f.id}.csv "
                        f"for microphone '{m.id}', flight '{f.id}')")
    wavs = [p for _, _, p in pairs if p.suffix == ".wav"]
    bad_rate: set[Path] = set()
    if wavs:
        rates = {}
        for p in wavs:
            try:
                rates[p] = _wav_rate(p)
            except GisnoiseError as exc:
                col.error(str(p), exc)
                bad_rate.add(p)
        if rate is None and rates:
            common = _common_rate(root, {f.id for f in flights}, rates)
            for p, r in rates.items():
                if r != common:
                    col.add(str(p), "sample_rate_hz", f"{p}: sample_rate_hz is {r} Hz, the campaign's other WAV "
                            f"files have {common} Hz")
                    bad_rate.add(p)
        elif rate is not None:
            for p, r in rates.items():
                if r != rate:
                    col.add(str(p), "sample_rate_hz", f"{p}: sample_rate_hz is {r} Hz, campaign.json states "
                            f"{rate:g} Hz")
                    bad_rate.add(p)
    levels = []
    total = float(len(pairs))
    for k, (m, f, p) in enumerate(pairs):
        if p in bad_rate:
            continue
        stale = stale_source(p, m, root) if p.suffix == ".csv" else None
        try:
            if stale is not None:  # computed from its WAV with another calibration, or from another WAV
                raise CampaignError(stale[1], field=stale[0])
            if p.suffix == ".csv":
                levels.append(_recorded_rate(read_level_csv(p, mic=m.id, flight=f.id)))
            else:
                levels.append(wav_levels(p, m, block_s=float(block_s), flight=f.id, exclusions=excl))
        except GisnoiseError as exc:
            col.error(str(p), exc)
        else:
            if absorption and (levels[-1].bands is None or levels[-1].band_f is None or not levels[-1].band_f.size):
                # the correction is per band: without bands this file would stay uncorrected beside corrected ones
                col.add(str(p), "bands", f"{p}: the absorption correction needs one-third-octave band levels "
                        "(columns L_<nominal Hz>); this file has none")
        if progress is not None:
            progress(k + 1.0, total)
    camp = Campaign(folder=root, origin=origin, weather=weather, vehicle=vehicle, speed_of_sound_m_s=c,
                    microphones=tuple(mics), flights=tuple(f for f in flights if f.id in trajectories),
                    trajectories=trajectories,
                    levels=tuple(lv for lv in levels if lv.flight in trajectories),
                    exclusions=tuple(excl), absorption=bool(absorption), snr_db=float(snr_db),
                    event_db=float(event_db))
    return camp, col


def _recorded_rate(lv: LevelSeries) -> LevelSeries:
    """A level CSV's series with the sample rate of the WAV file its source record names (if it has one)."""
    rec = read_source_record(source_record_path(lv.source))
    fs: Any = rec.get("sample_rate_hz") if rec is not None else None
    return replace(lv, sample_rate_hz=float(fs)) if _is_number(fs) and fs > 0 else lv


def _common_rate(root: Path, flight_ids: set[str], rates: Mapping[Path, int]) -> int:
    """The sample rate most WAV files of the campaign share (ties: the higher rate)."""
    every = dict(rates)
    for p in sorted(root.glob("mics/*/*.wav")):
        if p.stem in flight_ids and p not in every:
            try:
                every[p] = _wav_rate(p)
            except GisnoiseError:
                continue
    return _most_common_rate(every.values())
