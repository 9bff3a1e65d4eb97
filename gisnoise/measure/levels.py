"""Levels of the microphones: level CSV files, levels of WAV recordings, and a campaign's WAV files
turned into level CSVs.

A level CSV has the columns ``t`` (reception time at the block centre, s since the
flight's start), ``LA`` (A-weighted level, free field, dB(A)) and optionally one
``L_<nominal Hz>`` column per one-third-octave band (unweighted, free field, dB).
One computed from a WAV file has a source record beside it (:mod:`gisnoise.measure.provenance`).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import struct
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise import acoustics, limits
from gisnoise.errors import CampaignError, RecordingError
from gisnoise.measure.document import _Collector, _is_number, _parse_exclusions, _parse_mics, _read_document
from gisnoise.measure.parts import Exclusion, LevelSeries, Microphone, ProgressFn
from gisnoise.measure.provenance import write_source_record

__all__ = ["read_level_csv", "write_level_csv", "wav_levels", "write_levels", "band_column", "band_limit_warnings",
           "DEFAULT_BLOCK_S", "CLASS1_TOP_HZ"]

DEFAULT_BLOCK_S = 0.125

CLASS1_TOP_HZ = 16000.0
"""Highest one-third-octave band (nominal, Hz) an A-weighted level needs: IEC 61672-1 class 1 allows a sound
level meter +3.5/-17 dB at 16 kHz and +4/-inf dB at 20 kHz, so a meter may miss the 20 kHz band, not the
16 kHz one.  A recording whose sample rate cannot carry it (below 44.1 kHz: the bands stop at 12.5 kHz at
32 kHz, 6.3 kHz at 16 kHz) is named by :func:`band_limit_warnings`."""
_BAND_RE = re.compile(r"^L_")


def band_column(f_hz: float) -> str:
    """Column name ``L_<nominal Hz>`` of the one-third-octave band at ``f_hz`` (:func:`gisnoise.acoustics.band_name`).

    Examples
    --------
    >>> band_column(158.489), band_column(1258.9), band_column(31.62)
    ('L_160', 'L_1250', 'L_31.5')
    """
    return str(acoustics.band_name(float(f_hz)))


def read_level_csv(path: str | os.PathLike[str], *, mic: str = "", flight: str = "") -> LevelSeries:
    """Read a level CSV (``t``, ``LA``, optional ``L_<nominal Hz>``); errors name file and field."""
    src = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise CampaignError(f"{src}: missing microphone file", field="path") from None
    except UnicodeDecodeError as exc:
        raise CampaignError(f"{src}: not a UTF-8 text CSV (byte {exc.start}: {exc.reason})", field="path") from None
    rows = [r for r in csv.reader(io.StringIO(text)) if r and any(x.strip() for x in r)]
    if not rows:
        raise CampaignError(f"{src}: the file is empty", field="t")
    header = [h.strip() for h in rows[0]]
    for sep, name in ((";", "';'"), ("\t", "tab")):
        if len(header) == 1 and sep in header[0]:  # a spreadsheet's export in a decimal-comma locale
            raise CampaignError(f"{src}: fields are separated by {name}; a level CSV separates them by a comma and "
                                "writes numbers with a decimal point", field="csv")
    for need in ("t", "LA"):
        if need not in header:
            raise CampaignError(f"{src}: missing column '{need}'", field=need)
    band_cols = []
    for j, h in enumerate(header):
        if _BAND_RE.match(h):
            if not acoustics.is_band_name(h) or not 10.0 <= float(h[2:]) <= 20000.0:
                raise CampaignError(f"{src}: column '{h}' is not a one-third-octave band of 10 Hz-20 kHz", field=h)
            band_cols.append((j, h, float(acoustics.band_frequency(h))))
    data = np.full((len(rows) - 1, len(header)), np.nan)
    used = [header.index("t"), header.index("LA")] + [j for j, _, _ in band_cols]
    for i, r in enumerate(rows[1:], start=2):
        if len(r) != len(header):
            raise CampaignError(f"{src}: line {i} has {len(r)} fields, header has {len(header)}", field="csv")
        for j in used:
            try:
                data[i - 2, j] = float(r[j])
            except ValueError:
                raise CampaignError(f"{src}: column '{header[j]}' line {i}: not a number: {r[j]!r}",
                                    field=header[j]) from None
    for k, j in enumerate(used):
        col = data[:, j]
        # a band may be -inf (digital silence); t, LA and everything else must be finite
        bad = ~np.isfinite(col) if k < 2 else (np.isnan(col) | (col == np.inf))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise CampaignError(f"{src}: column '{header[j]}' line {i + 2}: NaN or infinite value", field=header[j])
    limits.check_levels(data[:, header.index("LA")], field="LA", source=src, error=CampaignError)
    for j, h, _ in band_cols:
        limits.check_levels(data[:, j], field=h, source=src, error=CampaignError, silence=True)
    t = data[:, header.index("t")]
    if len(t) == 0:
        raise CampaignError(f"{src}: no rows", field="t")
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.flatnonzero(dt <= 0)[0]) + 1
        raise CampaignError(f"{src}: column 't' is not strictly increasing at line {i + 2} "
                            f"({t[i]:g} s after {t[i - 1]:g} s)", field="t")
    band_f = bands = None
    if band_cols:
        band_cols.sort(key=lambda b: b[2])
        band_f = np.array([b[2] for b in band_cols])
        bands = data[:, [b[0] for b in band_cols]]
    return LevelSeries(mic=mic, flight=flight, source=src, t=t, la=data[:, header.index("LA")],
                       band_f=band_f, bands=bands)


def write_level_csv(path: str | os.PathLike[str] | None, t: Any, la: Any, band_f: Any = None,
                    bands: Any = None) -> str:
    """Write a level CSV: ``t`` (s), ``LA`` (dB(A)) and one ``L_<nominal>`` column per band (dB).

    Returns the text; writes it to ``path`` when given.
    """
    t = np.asarray(t, dtype=float)
    la = np.asarray(la, dtype=float)
    cols = ["t", "LA"]
    mat = [t, la]
    if band_f is not None and bands is not None:
        bands = np.asarray(bands, dtype=float).reshape(len(t), -1)
        for j, f in enumerate(np.asarray(band_f, dtype=float)):
            cols.append(band_column(f))
            mat.append(bands[:, j])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    arr = np.column_stack(mat)
    for row in arr:
        w.writerow([f"{row[0]:.6f}"] + [f"{v:.3f}" for v in row[1:]])
    text = buf.getvalue()
    if path is not None:
        Path(path).write_text(text, encoding="utf-8")
    return text


def _wav_rate(path: Path) -> int:
    """Sample rate of a WAV file from its ``fmt`` chunk (the data is not read)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(12)
            if len(head) < 12 or head[:4] not in (b"RIFF", b"RF64") or head[8:12] != b"WAVE":
                raise CampaignError(f"{path}: not a WAV file (no RIFF/WAVE header)", field="path")
            while True:
                ch = fh.read(8)
                if len(ch) < 8:
                    raise CampaignError(f"{path}: WAV file without a 'fmt ' chunk", field="path")
                cid, size = ch[:4], struct.unpack("<I", ch[4:])[0]
                if cid == b"fmt ":
                    body = fh.read(min(size, 16))
                    if len(body) < 8:
                        raise CampaignError(f"{path}: truncated WAV 'fmt ' chunk", field="path")
                    return int(struct.unpack("<I", body[4:8])[0])
                fh.seek(size + (size & 1), 1)
    except FileNotFoundError:
        raise CampaignError(f"{path}: missing microphone file", field="path") from None
    except OSError as exc:
        raise CampaignError(f"{path}: cannot read WAV file ({exc})", field="path") from None


def _most_common_rate(rates: Iterable[int]) -> int:
    """The sample rate most WAV files share (ties: the higher rate)."""
    vals = list(rates)
    return max(set(vals), key=lambda r: (vals.count(r), r))


def wav_levels(path: str | os.PathLike[str], mic: Microphone, *, block_s: float = DEFAULT_BLOCK_S,
               flight: str = "", sample_rate_hz: float | None = None,
               exclusions: Iterable[Exclusion] = ()) -> LevelSeries:
    """Levels of a WAV recording: bands, A-weighted level per block, mount correction.

    Sample values (float, or integer PCM with full scale 1) times ``mic.full_scale_v``
    are volts; divided by ``mic.sensitivity_v_per_pa`` they are pascals
    (:func:`gisnoise.acoustics.wav_band_levels`).  The mount correction of ``mic.mount``
    is added to the bands, and the overall level is their A-weighted sum, so the result
    is free field.  A clipped or dropped-out stretch of the recording (digital zeros, say) is
    refused, naming the file and its times and giving the exclusion that would leave it out;
    inside an exclusion of this flight and microphone it is accepted, and the blocks whose
    levels depend on it are left out of the result.

    Parameters
    ----------
    path : path-like
        Mono WAV file, first sample at the flight's ``start_utc``.
    mic : Microphone
        Its calibration and mount.
    block_s : float
        Averaging block, s.
    flight : str
        Flight id recorded in the result.
    sample_rate_hz : float, optional
        Required sample rate, Hz.
    exclusions : iterable of Exclusion
        The campaign's excluded intervals (reception time, s since the flight's start); those of ``flight``
        and of ``mic`` (or of every microphone) are where clipped or dropped-out stretches are accepted.
    """
    p = Path(path)
    rate = _wav_rate(p)
    if sample_rate_hz is not None and rate != sample_rate_hz:
        raise CampaignError(f"{p}: sample_rate_hz is {rate} Hz, the campaign states {sample_rate_hz:g} Hz",
                            field="sample_rate_hz")
    if mic.sensitivity_v_per_pa is None:
        raise CampaignError(f"microphone '{mic.id}': field 'sensitivity_v_per_pa' is needed for WAV input ({p})",
                            field="sensitivity_v_per_pa")
    excluded = [(e.t0, e.t1) for e in exclusions if e.flight == flight and e.mic in (None, mic.id)]
    try:
        t, f, lev = acoustics.wav_band_levels(p, mic.sensitivity_v_per_pa / mic.full_scale_v, block_s,
                                              excluded_s=excluded or None)
    except RecordingError as exc:
        raise CampaignError(f"{exc}{_exclusion_hint(exc.spans, flight, mic.id)}", field=exc.field) from None
    bands = np.asarray(lev, dtype=float) + acoustics.mount_correction(mic.mount)
    keep = ~np.isnan(bands).any(axis=1)  # blocks of an excluded clipped or dropped-out stretch
    if not keep.any():
        raise CampaignError(f"{p}: no block of levels is left outside its excluded clipped or dropped-out "
                            "stretches", field="exclusions")
    bands = bands[keep]
    la = acoustics.overall_a_level(bands, f)
    return LevelSeries(mic=mic.id, flight=flight, source=str(p), t=np.asarray(t, dtype=float)[keep],
                       la=np.asarray(la, dtype=float), band_f=np.asarray(f, dtype=float), bands=bands,
                       sample_rate_hz=float(rate))


def _exclusion_hint(spans: tuple[tuple[float, float], ...], flight: str, mic: str) -> str:
    """The exclusions of campaign.json that would leave the stretches out (whole milliseconds, outwards)."""
    if not spans:
        return ""
    if len(spans) > 3:
        return (f": campaign.json \"exclusions\" with flight '{flight}', mic '{mic}', t0 and t1 (s) for each of "
                f"its {len(spans)} stretches")
    ex = [{"flight": flight, "mic": mic, "t0": math.floor(a * 1000.0 + 1e-6) / 1000.0,
           "t1": math.ceil(b * 1000.0 - 1e-6) / 1000.0} for a, b in spans]
    return f": campaign.json \"exclusions\": {json.dumps(ex)}"


def band_limit_warnings(series: Iterable[LevelSeries]) -> list[str]:
    """One line per sample rate of the WAV recordings whose bands stop below :data:`CLASS1_TOP_HZ`.

    Names the files (the first three, and how many more), the rate, the highest band the rate carries
    and what the A-weighted level of a broadband source with a pink spectrum (equal energy per
    one-third octave) loses without the bands above it, up to 20 kHz
    (:func:`gisnoise.acoustics.pink_band_loss_db`, IEC 61672-1 A-weighting): 0.6 dB at 16 kHz, 1.8 dB at
    8 kHz.  A source whose energy falls off faster above loses less.  Levels a user brings (no sample
    rate known) are not judged.
    """
    groups: dict[tuple[float, float], list[str]] = {}
    for lv in series:
        if lv.sample_rate_hz is None or lv.band_f is None or not lv.band_f.size:
            continue
        top = float(acoustics.nominal_frequency(float(np.max(lv.band_f))))
        if top < CLASS1_TOP_HZ:
            groups.setdefault((lv.sample_rate_hz, top), []).append(lv.source)
    out = []
    for (fs, top), files in sorted(groups.items()):
        loss = float(acoustics.pink_band_loss_db(top))
        names = ", ".join(files[:3]) + (f" and {len(files) - 3} more" if len(files) > 3 else "")
        out.append(f"{names}: recorded at {fs:g} Hz, which carries the one-third-octave bands up to "
                   f"{top / 1000.0:g} kHz, not 20 kHz: its A-weighted levels leave out the bands above, and a "
                   f"broadband source with a pink spectrum (equal energy per band) would read {loss:.1f} dB(A) low "
                   "(less if its energy falls off faster above); record at 44.1 kHz or more")
    return out


def write_levels(folder: str | os.PathLike[str], *, block_s: float | None = None, force: bool = False,
                 progress: ProgressFn | None = None, warn: Callable[[str], None] | None = None) -> list[Path]:
    """Turn every WAV of a campaign into a level CSV beside it (``mics/<mic>/<flight>.csv``).

    The CSV holds ``t`` (block centre, s), ``LA`` (free field, dB(A)) and the free-field
    band levels ``L_<nominal>`` (dB); its source record ``<flight>.source.json`` beside it
    keeps the calibration and the WAV it was computed from
    (:mod:`gisnoise.measure.provenance`).  Existing CSVs are refused unless ``force``.
    A recording with a clipped or dropped-out stretch is refused (nothing is written)
    unless campaign.json's ``exclusions`` hold that stretch; its blocks are then left out.

    Parameters
    ----------
    folder : path-like
        Campaign folder.
    block_s : float, optional
        Averaging block, s (default: campaign.json ``block_s`` or 0.125).
    force : bool
        Overwrite existing level CSVs.
    progress : callable, optional
        ``progress(done_s, total_s)`` in seconds of audio.
    warn : callable, optional
        Called with each one-line warning about the levels written (:func:`band_limit_warnings`:
        a sample rate that cannot carry the bands up to 16 kHz).

    Returns
    -------
    list of Path
        The level files written.
    """
    col = _Collector(strict=True)
    root = Path(folder)
    cj = root / "campaign.json"
    doc = _read_document(cj, col)
    assert doc is not None  # a strict collector raises
    mics = _parse_mics(str(cj), doc, col)
    exclusions = _parse_exclusions(str(cj), doc.get("exclusions"), col, "exclusions")
    flights = [f.get("id") for f in doc.get("flights", []) if isinstance(f, dict)]
    if block_s is None:
        block_s = doc.get("block_s", DEFAULT_BLOCK_S)
    if not (_is_number(block_s) and block_s > 0):
        raise CampaignError(f"block_s must be a positive number, got {block_s!r}", field="block_s")
    rate: Any = doc.get("sample_rate_hz")
    jobs = []
    for m in mics:
        for fid in flights:
            wav = root / "mics" / m.id / f"{fid}.wav"
            if wav.is_file():
                jobs.append((m, str(fid), wav))
    missing = [root / "mics" / m.id / f"{fid}.wav" for m in mics for fid in flights
               if not (root / "mics" / m.id / f"{fid}.wav").is_file()
               and not (root / "mics" / m.id / f"{fid}.csv").is_file()]
    if jobs and missing:  # named, never skipped
        raise CampaignError(f"{missing[0]}: missing microphone file (neither WAV nor level CSV; "
                            f"{len(missing)} missing in all)", field="path")
    if not jobs:
        raise CampaignError(f"{root / 'mics'}: no WAV file of a known microphone and flight", field="mics")
    info = {wav: _wav_rate(wav) for _, _, wav in jobs}
    common = float(rate) if _is_number(rate) else float(_most_common_rate(info.values()))
    for wav, fs in info.items():
        if fs != common:
            which = "campaign.json states" if _is_number(rate) else "the campaign's other WAV files have"
            raise CampaignError(f"{wav}: sample_rate_hz is {fs} Hz, {which} {common:g} Hz", field="sample_rate_hz")
        target = wav.with_suffix(".csv")
        if target.exists() and not force:
            raise CampaignError(f"{target}: exists; use --force to overwrite", field="force")
    durations = {wav: max(wav.stat().st_size, 1) / fs for wav, fs in info.items()}  # proportional to seconds
    total = float(sum(durations.values()))
    done = 0.0
    series = []  # every recording is read before any file is written: a refused one leaves the campaign as it was
    for m, fid, wav in jobs:
        series.append((m, wav, wav_levels(wav, m, block_s=float(block_s), flight=fid, sample_rate_hz=common,
                                          exclusions=exclusions)))
        done += durations[wav]
        if progress is not None:
            progress(done, total)
    written = []
    for m, wav, lv in series:
        target = wav.with_suffix(".csv")
        write_level_csv(target, lv.t, lv.la, lv.band_f, lv.bands)
        write_source_record(target, wav, m, sample_rate_hz=common, block_s=float(block_s))
        written.append(target)
    if warn is not None:
        for w in band_limit_warnings(lv for _, _, lv in series):
            warn(w)
    return written
