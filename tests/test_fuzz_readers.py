"""Property-based fuzzing of the readers: malformed input is refused with a field, never crashes.

Property, for every generated input: the reader either returns data inside the rule set of
:mod:`gisnoise.limits` (finite, in range) or raises a :class:`gisnoise.errors.GisnoiseError`
naming a field; any other exception (a traceback in the CLI, a 500 in the service) fails.
The default suite draws a small budget per reader; the slow study draws 2,000.
"""

from __future__ import annotations

import io
import json
import math
import struct
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import event as _hyp_event
from hypothesis import strategies as st

from gisnoise import limits
from gisnoise.errors import GisnoiseError
from gisnoise.flight import read_flight_csv, read_trajectory
from gisnoise.model import cards as gcards

REPO = Path(__file__).resolve().parents[1]
CARD = json.loads((REPO / "gisnoise" / "data" / "cards" / "demo_horizontal.json").read_text())
DEFAULT_BUDGET = 60
STUDY_BUDGET = 2000


def event(what: str) -> None:
    """Count an outcome in hypothesis's statistics (inside a fuzz run only)."""
    from hypothesis.control import _current_build_context

    if _current_build_context.value is not None:
        _hyp_event(what)


def _budget(n: int):
    return settings(max_examples=n, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                           HealthCheck.data_too_large])


def _refused_with_field(exc: BaseException) -> None:
    assert isinstance(exc, GisnoiseError), f"{type(exc).__name__}: {exc}"
    event(f"refused: {exc.field}")
    assert exc.field, f"no field: {exc}"
    assert "\n" not in str(exc).strip(), f"more than one line: {exc!r}"


# ------------------------------------------------------------------ strategies
_NUM = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**12, 10**12),
                 st.sampled_from([0.0, -0.0, 1e300, -1e300, 180.0000001, 90.5, -500.1, 1e9]))
_CELL = st.one_of(_NUM.map(repr), st.text(max_size=6), st.sampled_from(["", "nan", "inf", "1e999", "0x10", " "]))
_VALUE = st.one_of(_NUM, st.text(max_size=6), st.none(), st.booleans(), st.lists(_NUM, max_size=3),
                   st.dictionaries(st.text(max_size=3), _NUM, max_size=2))
"""A JSON value put in place of a document's field by the fuzzers' mutations (:mod:`_jsonedit`)."""
_COLS = ["t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w", "phase", "rpm"]


@st.composite
def flight_csv(draw) -> bytes:
    """A flight CSV near the valid one: plausible rows with some cells, columns or bytes broken."""
    n = draw(st.integers(0, 8))
    cols = draw(st.lists(st.sampled_from(_COLS), min_size=0, max_size=10, unique=True)) if draw(
        st.booleans()) else _COLS[:8]
    base = {"t": lambda i: float(i), "lat": lambda i: 52.2 + 1e-4 * i, "lon": lambda i: 10.5 + 1e-4 * i,
            "h": lambda i: 150.0, "roll": lambda i: 0.0, "pitch": lambda i: 0.0, "yaw": lambda i: 90.0,
            "power_w": lambda i: 3000.0, "phase": lambda i: "horizontal", "rpm": lambda i: 4000.0}
    rows = []
    for i in range(n):
        row = [str(base[c](i)) for c in cols]
        if row and draw(st.booleans()):
            j = draw(st.integers(0, len(row) - 1))
            row[j] = draw(_CELL)
        rows.append(",".join(row))
    text = "\n".join([",".join(cols), *rows]) + "\n"
    enc = draw(st.sampled_from(["utf-8", "utf-16", "latin-1"]))
    data = text.encode(enc, errors="replace")
    if draw(st.booleans()):  # a few bytes of garbage somewhere
        k = draw(st.integers(0, len(data)))
        data = data[:k] + draw(st.binary(max_size=8)) + data[k:]
    return data


@st.composite
def card_doc(draw) -> bytes:
    doc = json.loads(json.dumps(CARD))
    for _ in range(draw(st.integers(0, 3))):
        key = draw(st.sampled_from(list(doc) + ["parameters.p0", "parameters.p7", "covariance", "extra"]))
        val = draw(st.one_of(_NUM, st.text(max_size=5), st.none(), st.lists(_NUM, max_size=3),
                             st.dictionaries(st.text(max_size=3), _NUM, max_size=2)))
        if key.startswith("parameters."):
            if isinstance(doc.get("parameters"), dict):
                doc["parameters"][key.split(".")[1]] = val
        elif draw(st.booleans()):
            doc[key] = val
        else:
            doc.pop(key, None)
    text = json.dumps(doc, allow_nan=True)
    if draw(st.booleans()):
        k = draw(st.integers(0, len(text)))
        text = text[:k] + draw(st.text(max_size=4)) + text[k:]
    return text.encode("utf-8", errors="surrogatepass")


@st.composite
def wav_bytes(draw) -> bytes:
    channels = draw(st.sampled_from([1, 1, 1, 2, 0]))
    rate = draw(st.sampled_from([48000, 8000, 1, 0, 2**31]))
    bits = draw(st.sampled_from([16, 16, 32, 8, 24, 0]))
    n = draw(st.integers(0, 400))
    data = draw(st.binary(min_size=0, max_size=2 * n)) if draw(st.booleans()) else np.zeros(n, "<i2").tobytes()
    declared = draw(st.one_of(st.just(len(data)), st.integers(0, 2**32 - 1)))
    fmt_tag = draw(st.sampled_from([1, 1, 3, 0xFFFE, 7]))
    fmt = struct.pack("<HHIIHH", fmt_tag, channels, rate, rate * max(channels, 1) * max(bits // 8, 1) % 2**32,
                      max(channels, 1) * max(bits // 8, 1), bits)
    raw = (b"RIFF" + struct.pack("<I", (36 + declared) % 2**32) + b"WAVE" + b"fmt " + struct.pack("<I", 16) + fmt
           + b"data" + struct.pack("<I", declared) + data)
    cut = draw(st.one_of(st.just(len(raw)), st.integers(0, len(raw))))
    return raw[:cut]


@st.composite
def route_doc(draw) -> dict:
    wps = []
    for _ in range(draw(st.integers(0, 5))):
        wp = {"lon": draw(st.one_of(st.floats(-200, 200), _NUM)), "lat": draw(st.one_of(st.floats(-95, 95), _NUM)),
              "alt": draw(st.one_of(st.floats(-100, 500), _NUM))}
        if draw(st.booleans()):
            wp["speed"] = draw(st.one_of(st.floats(1e-6, 100), _NUM))
        if draw(st.booleans()):
            wp["hold_s"] = draw(st.one_of(st.floats(0, 100), _NUM))
        wps.append(wp)
    return {"schema": "gisnoise/waypoints/1", "altitude_reference": "agl",
            "sample_dt_s": draw(st.one_of(st.just(0.5), st.floats(1e-7, 10))), "waypoints": wps}


# ------------------------------------------------------------------ properties
def _check_trajectory(tr) -> None:
    event("read")
    lim = limits.current()
    for name in ("t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w"):
        a = np.asarray(getattr(tr, name), dtype=float)
        assert np.all(np.isfinite(a)), name
    assert np.all(np.abs(tr.lon) <= 180) and np.all(np.abs(tr.lat) <= 90)
    assert np.all((tr.power_w >= 0) & (tr.power_w <= lim.max_power_w))  # 0 W: a sample on the ground
    assert np.all((tr.h >= lim.min_height_m) & (tr.h <= lim.max_height_m))
    if len(tr) > 1:
        assert np.diff(tr.t).max() <= lim.max_gap_s


def _flight_property(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "f.csv"
        p.write_bytes(data)
        try:
            tr = read_flight_csv(p)
        except Exception as exc:  # noqa: BLE001 - the property: only refusals with a field
            _refused_with_field(exc)
            return
    _check_trajectory(tr)


def _card_property(data: bytes) -> None:
    try:
        card = gcards.loads(data.decode("utf-8", errors="replace"), source="card")
    except Exception as exc:  # noqa: BLE001
        _refused_with_field(exc)
        return
    event("read")
    assert all(math.isfinite(v) for v in card.parameters.values())
    assert card.reference_power_w > 0 and math.isfinite(card.reference_power_w)


def _wav_property(data: bytes) -> None:
    from gisnoise.acoustics import read_wav

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "a.wav"
        p.write_bytes(data)
        try:
            v, fs = read_wav(p)
        except Exception as exc:  # noqa: BLE001
            _refused_with_field(exc)
            return
    event("read")
    assert v.ndim == 1 and v.size >= 1 and fs > 0 and np.all(np.isfinite(v))


def _route_property(doc: dict) -> None:
    with limits.override(max_samples=20_000):
        try:
            tr = read_trajectory(doc)
        except Exception as exc:  # noqa: BLE001
            _refused_with_field(exc)
            return
    assert len(tr) <= 20_000
    _check_trajectory(tr)


_PROPS = {"flight_csv": (flight_csv(), _flight_property), "card": (card_doc(), _card_property),
          "wav": (wav_bytes(), _wav_property), "route": (route_doc(), _route_property)}


def _fuzz(name: str, budget: int) -> None:
    strategy, prop = _PROPS[name]
    _budget(budget)(given(strategy)(prop))()


@pytest.mark.parametrize("reader", sorted(_PROPS))
def test_readers_refuse_malformed_input_with_a_field(reader):
    _fuzz(reader, DEFAULT_BUDGET)


@pytest.mark.slow
@pytest.mark.parametrize("reader", sorted(_PROPS))
def test_readers_fuzzed_at_the_study_budget(reader):
    _fuzz(reader, STUDY_BUDGET)


def test_the_fuzzers_reach_both_outcomes():
    """The strategies are not degenerate: the valid seed inputs are read, broken ones are refused."""
    good = "t,lat,lon,h,roll,pitch,yaw,power_w\n0,52.2,10.5,150,0,0,90,3000\n1,52.2001,10.5001,150,0,0,90,3000\n"
    _flight_property(good.encode())
    assert len(read_flight_csv(io.StringIO(good))) == 2
    with pytest.raises(GisnoiseError):
        read_flight_csv(io.StringIO(good.replace("3000\n1", "1e300\n1")))
    assert gcards.loads(json.dumps(CARD)).id == CARD["id"]
