"""What a level file computed from a WAV recording was computed with: its source record.

``gisnoise campaign levels`` turns ``mics/<mic>/<flight>.wav`` into ``<flight>.csv`` and writes beside
it ``<flight>.source.json``::

    {"schema": "gisnoise/level-source/1", "levels": "f1.csv",
     "wav": {"file": "f1.wav", "bytes": 960044, "mtime_ns": ..., "sha256": "..."},
     "microphone": {"id": "m1", "sensitivity_v_per_pa": 0.05, "full_scale_v": 1.0, "mount": "ground_plate"},
     "sample_rate_hz": 16000.0, "block_s": 0.125, "software": "gisnoise 0.1.0"}

The level CSV itself stays as the specification has it (``t``, ``LA``, ``L_<nominal Hz>``).  Where both
exist, the campaign reader takes the CSV; the record tells it when the CSV no longer follows the campaign:
the microphone's calibration in campaign.json (``sensitivity_v_per_pa``, ``full_scale_v``, ``mount``) or
the WAV file itself (its size, or its content when its modification time changed: a copied campaign keeps
its levels) differ from what the levels were computed with.  Such a CSV is refused, naming the file and
the field, with the one command that mends it: its levels are off by a known amount (60 dB for a
sensitivity typed in mV/Pa), and a warning would let a fit take them.  A level CSV without a record (levels
a user brings) is read as it is.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gisnoise import __version__, acoustics
from gisnoise.measure.parts import Microphone

__all__ = ["SOURCE_SCHEMA", "SOURCE_SUFFIX", "source_record_path", "write_source_record", "read_source_record",
           "stale_source"]

SOURCE_SCHEMA = "gisnoise/level-source/1"
SOURCE_SUFFIX = ".source.json"
CALIBRATION_FIELDS = ("sensitivity_v_per_pa", "full_scale_v", "mount")
"""The microphone's fields the levels of a WAV file depend on."""


def source_record_path(csv: str | os.PathLike[str]) -> Path:
    """The source record of a level CSV: ``<flight>.source.json`` beside ``<flight>.csv``.

    Examples
    --------
    >>> source_record_path("mics/m1/f1.csv").as_posix()
    'mics/m1/f1.source.json'
    """
    return Path(csv).with_suffix(SOURCE_SUFFIX)


def wav_digest(path: str | os.PathLike[str]) -> str:
    """SHA-256 of a file's bytes, hex."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 22), b""):
            h.update(block)
    return h.hexdigest()


def _calibration(mic: Microphone) -> dict[str, Any]:
    return {"sensitivity_v_per_pa": mic.sensitivity_v_per_pa, "full_scale_v": mic.full_scale_v,
            "mount": mic.mount}


def write_source_record(csv: str | os.PathLike[str], wav: str | os.PathLike[str], mic: Microphone, *,
                        sample_rate_hz: float, block_s: float) -> Path:
    """Write the source record of a level CSV computed from ``wav`` with ``mic``'s calibration.

    Parameters
    ----------
    csv, wav : path-like
        The level CSV written and the WAV recording it was computed from.
    mic : Microphone
        The microphone as campaign.json stated it (its calibration and mount).
    sample_rate_hz, block_s : float
        The recording's sample rate, Hz, and the averaging block, s.

    Returns
    -------
    Path
        The record written.
    """
    w = Path(wav)
    st = w.stat()
    doc = {"schema": SOURCE_SCHEMA, "levels": Path(csv).name,
           "wav": {"file": w.name, "bytes": st.st_size, "mtime_ns": st.st_mtime_ns, "sha256": wav_digest(w)},
           "microphone": {"id": mic.id, **_calibration(mic)},
           "sample_rate_hz": float(sample_rate_hz), "block_s": float(block_s),
           "software": f"gisnoise {__version__}"}
    out = source_record_path(csv)
    out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    return out


def read_source_record(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The source record's document; None when it cannot be read as one (a hand-edited or foreign file)."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8-sig"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("schema") != SOURCE_SCHEMA or not isinstance(doc.get("wav"), dict) \
            or not isinstance(doc.get("microphone"), dict):
        return None
    return doc


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(float(a), float(b), rel_tol=1e-9)
    return bool(a == b)


def _shift_db(key: str, old: Any, new: Any) -> float | None:
    """How much higher the levels read with the new value, dB (None when it cannot be said)."""
    try:
        if key == "sensitivity_v_per_pa":
            return 20.0 * math.log10(float(old) / float(new))
        if key == "full_scale_v":
            return 20.0 * math.log10(float(new) / float(old))
        return acoustics.mount_correction(new) - acoustics.mount_correction(old)
    except (TypeError, ValueError, ZeroDivisionError):
        return None


def _wav_changed(wav: Path, was: Mapping[str, Any]) -> str | None:
    """What changed in the WAV file since its record was written; None when nothing did."""
    st = wav.stat()
    if st.st_size != was.get("bytes"):
        return f"its size is {st.st_size} bytes, the levels were computed from {was.get('bytes')}"
    if st.st_mtime_ns != was.get("mtime_ns") and wav_digest(wav) != was.get("sha256"):
        return "its content differs from the one the levels were computed from (SHA-256)"
    return None


def stale_source(csv: str | os.PathLike[str], mic: Microphone, folder: str | os.PathLike[str]) -> \
        tuple[str, str] | None:
    """Whether a level CSV's source record says it no longer follows the campaign.

    Parameters
    ----------
    csv : path-like
        A level CSV (its record is :func:`source_record_path`).
    mic : Microphone
        The microphone as campaign.json now states it.
    folder : path-like
        The campaign folder, for the command the message gives.

    Returns
    -------
    (field, message) or None
        None without a record (levels a user brings) or when the record agrees; else the first changed
        field (``sensitivity_v_per_pa``, ``full_scale_v``, ``mount``, ``wav``, or ``source`` for a record that
        cannot be read) and one line naming the file, what changed and what to do.
    """
    c = Path(csv)
    rec_path = source_record_path(c)
    if not rec_path.is_file():
        return None
    wav = c.with_suffix(".wav")
    redo = f"recompute them with gisnoise campaign levels {folder} --force"
    if not wav.is_file():
        redo = f"its WAV {wav.name} is gone: restore it and {redo}, or delete {rec_path.name} to keep these levels"
    rec = read_source_record(rec_path)
    if rec is None:
        return "source", (f"{c}: its source record {rec_path.name} is not a {SOURCE_SCHEMA} document, so whether "
                          f"its levels follow campaign.json cannot be told; {redo}")
    was = rec["microphone"]
    now = _calibration(mic)
    changed = [k for k in CALIBRATION_FIELDS if not _same(was.get(k), now[k])]
    if changed:
        shifts = [_shift_db(k, was.get(k), now[k]) for k in changed]
        off = ("" if any(s is None for s in shifts) else
               f" (its levels read {abs(sum(s for s in shifts if s is not None)):.1f} dB too "
               f"{'low' if sum(s for s in shifts if s is not None) > 0 else 'high'})")
        old = " and ".join(f"{k} {was.get(k)!r}" for k in changed)
        new = " and ".join(repr(now[k]) for k in changed)
        return changed[0], (f"{c}: computed by gisnoise campaign levels with {old} for microphone '{mic.id}', "
                            f"campaign.json now states {new}{off}; {redo}")
    if wav.is_file():
        what = _wav_changed(wav, rec["wav"])
        if what is not None:
            return "wav", f"{c}: {wav.name} changed after its levels were computed ({what}); {redo}"
    return None
