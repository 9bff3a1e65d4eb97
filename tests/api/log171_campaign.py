"""A campaign of one real flight for the service tests: the ArduCopter log171 (a DataFlash log, tests/data), whole
or cut short, with three microphones around its track whose levels come from a known card plus seeded noise, so
that a fit and a diagnosis run on it."""

from __future__ import annotations

import io
import json
import shutil
import zipfile
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from service_helpers import REPO

from gisnoise.flight import read_flight
from gisnoise.measure import read_campaign
from gisnoise.model import ModelCard

LOG = REPO / "tests" / "data" / "dronekit_la_testdata_log171_copter.bin"
N_SITE = 22.0   # geoid undulation at the log's site (Canberra), m: the log gives heights above mean sea level only
REF_W = 300.0
BACKGROUND_DB = 38.0
#: the card the levels come from (hover and horizontal: the phases log171 flies)
TRUTH = ModelCard(id="log171-truth", vehicle="log171 quad", phase="hover", ansatz="paper-offset",
                  parameters=dict(p0=62.0, p1=15.0, p2=0.05, p3=-0.2, p4=-0.1, p5=1.0, p6=1.0, p7=BACKGROUND_DB),
                  reference_power_w=REF_W, phases=("horizontal",))
MICS = {"m1": (30.0, 0.0), "m2": (-25.0, 20.0), "m3": (5.0, -35.0)}   # east, north of the track's median, m


def _write_levels(root: Path, t: np.ndarray, levels: dict[str, np.ndarray]) -> None:
    for mic, lv in levels.items():
        (root / "mics" / mic).mkdir(parents=True, exist_ok=True)
        (root / "mics" / mic / "f1.csv").write_text("t,LA\n" + "".join(f"{a:.3f},{b:.2f}\n" for a, b in zip(t, lv, strict=True)))


def campaign(root: Path, log: Path) -> Path:
    """The campaign folder of flight f1 = ``log`` (see the module's docstring)."""
    (root / "flights").mkdir(parents=True)
    shutil.copy(log, root / "flights" / "f1.bin")
    tr = read_flight(log, start_utc=0.0, geoid_undulation_m=N_SITE)   # t in unix seconds (the log's GPS clock)
    start = datetime.fromtimestamp(float(tr.t[0]) - 1.0, tz=timezone.utc).isoformat().replace("+00:00", "Z")
    lat, lon, h = float(np.median(tr.lat)), float(np.median(tr.lon)), float(tr.h.min())
    m_per_deg = 111_200.0
    doc = {"schema": "gisnoise/campaign/1", "origin": {"lat": lat, "lon": lon, "h": h},
           "speed_of_sound_m_s": 340.0, "weather": {"temperature_c": 10.0},
           "vehicle": {"name": "log171 quad", "reference_power_w": REF_W},
           "microphones": [{"id": m, "lat": lat + n / m_per_deg, "lon": lon + e / (m_per_deg * np.cos(np.radians(lat))),
                            "h": h + 1.2, "mount": "free_field", "background_db": BACKGROUND_DB}
                           for m, (e, n) in MICS.items()],
           "flights": [{"id": "f1", "start_utc": start, "geoid_undulation_m": N_SITE}]}
    (root / "campaign.json").write_text(json.dumps(doc))
    # reception blocks of 0.125 s: the background first, then the card's level at each block's emission + noise
    t_r = np.arange(0.0, tr.duration_s + 2.0, 0.125)
    rng = np.random.default_rng(171)
    _write_levels(root, t_r, {m: np.full(t_r.size, BACKGROUND_DB) for m in MICS})
    s = read_campaign(root).samples()
    model = TRUTH.level(s.inputs(REF_W))
    levels = {}
    for m in MICS:
        lv = BACKGROUND_DB + rng.normal(0.0, 0.8, t_r.size)
        rows = np.flatnonzero(s.mic == m)
        i = np.rint(s.t_r[rows] / 0.125).astype(int)
        assert np.allclose(t_r[i], s.t_r[rows])
        lv[i] = model[rows] + rng.normal(0.0, 0.8, rows.size)
        levels[m] = lv
    _write_levels(root, t_r, levels)
    return root


def cut_log(folder: Path, fraction: float = 0.9) -> tuple[Path, int]:
    """log171 cut after ``fraction`` of its bytes (inside a message) in ``folder``, and the bytes kept."""
    raw = LOG.read_bytes()
    k = int(fraction * len(raw))
    path = folder / "log171_cut.bin"
    path.write_bytes(raw[:k])
    return path, k


def zip_campaign(folder: Path) -> bytes:
    """The campaign folder zipped as a client uploads it (in a folder of its own)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                z.write(p, f"c171/{p.relative_to(folder)}")
    return buf.getvalue()
