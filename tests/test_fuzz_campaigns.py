"""Property-based fuzzing of the campaign reader: campaign.json, the flight log and the microphone files.

Property, for every generated campaign folder (a valid flyover with some fields, cells, bytes or files
broken): :func:`gisnoise.measure.read_campaign` and :func:`gisnoise.measure.build_samples` either give
samples inside the rule set (finite levels of a microphone within -50..200 dB, distances positive and
finite, emission before reception, power within the limits, coordinates in range) or refuse with a
:class:`gisnoise.errors.GisnoiseError` naming a field in one line; nothing else (a traceback in the CLI, a
failed job in the service).  Default suite: a small budget; the slow study: 2,000 examples.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from _jsonedit import put
from hypothesis import given
from hypothesis import strategies as st
from test_campaign import MICS, make_campaign, straight_track
from test_fuzz_readers import _CELL, _VALUE, DEFAULT_BUDGET, STUDY_BUDGET, _budget, _refused_with_field, event

from gisnoise import limits
from gisnoise.measure import build_samples, read_campaign

LEVEL_RANGE_DB = (-50.0, 200.0)
"""Levels a microphone can record: below the self-noise of any measurement microphone, above a jet at 1 m."""

_TEMPLATE: dict[str, bytes] = {}


def _template() -> dict[str, bytes]:
    """The files of a valid two-microphone flyover (made once)."""
    if not _TEMPLATE:
        with tempfile.TemporaryDirectory() as d:
            track = straight_track()
            track["power_w"] = 3000.0 + 500.0 * np.sin(track["t"] / 5.0)  # varying power: every parameter fits
            root = make_campaign(Path(d) / "c", mics=MICS,
                                 t_r=np.arange(3.0, 58.0, 0.5), track=track)
            for p in sorted(root.rglob("*")):
                if p.is_file():
                    _TEMPLATE[p.relative_to(root).as_posix()] = p.read_bytes()
    return _TEMPLATE


_JSON_KEYS = ["schema", "origin.lat", "origin.lon", "origin.h", "speed_of_sound_m_s", "weather.temperature_c",
              "weather.humidity_pct", "weather.pressure_kpa", "vehicle.reference_power_w", "microphones.0.lat",
              "microphones.0.lon", "microphones.0.h", "microphones.0.mount", "microphones.0.id", "flights.0.id",
              "flights.0.start_utc", "microphones", "flights", "exclusions", "background_db"]


@st.composite
def campaign_files(draw) -> dict[str, bytes]:
    files = dict(_template())
    doc = json.loads(files["campaign.json"])
    for _ in range(draw(st.integers(0, 2))):
        put(doc, draw(st.sampled_from(_JSON_KEYS)).split("."), draw(_VALUE), draw(st.booleans()))
    text = json.dumps(doc, allow_nan=True)
    if draw(st.integers(0, 9)) == 0:  # broken JSON text
        k = draw(st.integers(0, len(text)))
        text = text[:k] + draw(st.text(max_size=3)) + text[k:]
    files["campaign.json"] = text.encode("utf-8", errors="surrogatepass")
    data_files = sorted(k for k in files if k != "campaign.json")
    for _ in range(draw(st.integers(0, 3))):
        name = draw(st.sampled_from(data_files))
        how = draw(st.sampled_from(["cell", "cell", "cell", "truncate", "bytes", "delete", "utf16"]))
        raw = files.get(name)
        if raw is None:
            continue
        if how == "delete":
            del files[name]
        elif how == "truncate":
            files[name] = raw[:draw(st.integers(0, len(raw)))]
        elif how == "bytes":
            k = draw(st.integers(0, len(raw)))
            files[name] = raw[:k] + draw(st.binary(min_size=1, max_size=8)) + raw[k:]
        elif how == "utf16":
            files[name] = raw.decode("utf-8", errors="replace").encode("utf-16")
        else:
            lines = raw.decode("utf-8", errors="replace").splitlines()
            if not lines:
                continue
            i = draw(st.integers(0, len(lines) - 1))
            cells = lines[i].split(",")
            cells[draw(st.integers(0, len(cells) - 1))] = draw(_CELL)
            lines[i] = ",".join(cells)
            files[name] = ("\n".join(lines) + "\n").encode()
    if draw(st.integers(0, 9)) == 0:  # a microphone file nobody declared, or a flight without a log
        files["mics/m9/f1.csv"] = files.get("mics/m1/f1.csv", b"t,LA\n")
    return files


def _check_samples(s) -> None:
    event("read")
    lim = limits.current()
    for name in ("level", "d", "t_e", "t_r", "power_w"):
        a = np.asarray(getattr(s, name), dtype=float)
        assert np.all(np.isfinite(a)), name
    assert np.all((s.level >= LEVEL_RANGE_DB[0]) & (s.level <= LEVEL_RANGE_DB[1])), (s.level.min(), s.level.max())
    assert np.all(s.d > 0)
    assert np.all(s.t_e <= s.t_r + 1e-9)  # sound is heard after it is made
    assert np.all((s.power_w >= 0) & (s.power_w <= lim.max_power_w))
    assert np.all(np.isfinite(s.uav_enu)) and np.all(np.isfinite(s.mic_enu))


def _campaign_property(files: dict[str, bytes]) -> None:
    d = Path(tempfile.mkdtemp(prefix="fuzz-campaign-"))
    try:
        for name, data in files.items():
            p = d / name
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_bytes(data)
        try:
            s = build_samples(read_campaign(d))
        except Exception as exc:  # noqa: BLE001 - the property: only refusals with a field
            _refused_with_field(exc)
            return
        _check_samples(s)
    finally:
        shutil.rmtree(d, ignore_errors=True)


def test_the_campaign_template_is_read():
    """The strategy starts from a campaign the reader takes: the fuzzer reaches both outcomes."""
    files = dict(_template())
    broken = dict(files, **{"mics/m1/f1.csv": b"t,LA\n0,1e300\n"})
    d = Path(tempfile.mkdtemp(prefix="fuzz-campaign-"))
    try:
        for name, data in files.items():
            (d / name).parent.mkdir(parents=True, exist_ok=True)
            (d / name).write_bytes(data)
        s = build_samples(read_campaign(d))
        assert len(s) == 3 * 110 and set(s.mic) == {"m1", "m2", "m3"}  # 110 blocks of 0.5 s per microphone
        _check_samples(s)
        (d / "mics/m1/f1.csv").write_bytes(broken["mics/m1/f1.csv"])
        with pytest.raises(Exception) as e:
            build_samples(read_campaign(d))
        _refused_with_field(e.value)
        assert e.value.field == "LA" and "1e+300" in str(e.value)  # a level no microphone records
    finally:
        shutil.rmtree(d, ignore_errors=True)


def test_campaign_reader_refuses_malformed_campaigns_with_a_field():
    _budget(DEFAULT_BUDGET // 2)(given(campaign_files())(_campaign_property))()


@pytest.mark.slow
def test_campaign_reader_fuzzed_at_the_study_budget():
    _budget(STUDY_BUDGET)(given(campaign_files())(_campaign_property))()
