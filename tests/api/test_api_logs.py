"""POST /contours with a flight log upload (PX4 .ulg, ArduPilot .bin, any letter case): the same reader
and the same map as the command line; bad uploads are 422 naming the field, never a server path."""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import pytest
from service_helpers import assert_names_field

rasterio = pytest.importorskip("rasterio")
pytest.importorskip("pyulog")
pytest.importorskip("pymavlink")

DATA = Path(__file__).parent.parent / "data"
VTOL = DATA / "pyulog_sample_log_small_vtol.ulg"
COPTER = DATA / "dronekit_la_testdata_log171_copter.bin"
CARD = {"schema": "gisnoise/model-card/1", "id": "omni", "vehicle": "test", "phase": "hover",
        "phases": ["horizontal", "climb", "sink", "transition"], "ansatz": "paper-offset",
        "parameters": {"p0": 65.0, "p1": 10.0, "p2": 0.0, "p3": 0.0, "p4": 0.0, "p5": 0.0, "p6": 1.0, "p7": 40.0},
        "covariance": None, "reference_power_w": 300.0, "reference_distance_m": 40.0}


def _log(path: Path, name: str, **kw) -> dict:
    return {"format": "log", "name": name, "data_base64": base64.b64encode(path.read_bytes()).decode(), **kw}


def _read_tif(data: bytes) -> np.ndarray:
    from rasterio.io import MemoryFile

    with MemoryFile(data) as mf, mf.open() as ds:
        return ds.read()


@pytest.mark.parametrize("path, name, opts", [
    (VTOL, "hop.ULG", []),
    (COPTER, "f1.BIN", ["--geoid-undulation", "19.5"]),
])
def test_log_upload_makes_the_map_the_cli_makes(client, tmp_path, path, name, opts):
    from click.testing import CliRunner

    from gisnoise.cli.main import cli

    log = tmp_path / name
    log.write_bytes(path.read_bytes())
    card = tmp_path / "omni.json"
    card.write_text(json.dumps(CARD))
    out = tmp_path / "cli"
    res = CliRunner().invoke(cli, ["-q", "contour", str(log), "--card", str(card), "--out", str(out),
                                   "--resolution", "20", "--margin", "100", "--levels", "45,50", *opts],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.output
    extra = {"geoid_undulation_m": float(opts[1])} if opts else {}
    req = {"trajectory": _log(path, name, **extra), "cards": [CARD], "grid": {"resolution_m": 20, "margin_m": 100},
           "levels": [45, 50], "output": "geotiff"}
    r = client.post("/contours", json=req)
    assert r.status_code == 200, r.text
    np.testing.assert_array_equal(_read_tif(r.content), _read_tif((out / "levels.tif").read_bytes()))


def test_corrupt_log_is_422_naming_the_upload_not_a_server_path(client):
    req = {"trajectory": {"format": "log", "name": "broken.bin",
                          "data_base64": base64.b64encode(b"\x00not a dataflash log" * 50).decode()},
           "cards": [CARD], "grid": {"resolution_m": 20, "margin_m": 100}}
    body = assert_names_field(client.post("/contours", json=req), 422, None)
    assert body["field"].startswith("trajectory")
    assert "broken.bin" in body["detail"] and "gisnoise-log-" not in body["detail"] and "/tmp" not in body["detail"]


@pytest.mark.parametrize("trajectory, field", [
    ({"format": "log", "name": "f1.bin", "data_base64": "@@@@not base64"}, "trajectory.data_base64"),
    ({"format": "log", "name": "f1.csv", "data_base64": "AAAA"}, "trajectory.name"),
    ({"format": "log", "name": "../f1.bin", "data_base64": "AAAA"}, "trajectory.name"),
    # bytes no reader makes sense of: the fault of data_base64 (it said trajectory.path and trajectory.GPS, names of
    # the reader's argument and of a log message, no fields of the request)
    ({"format": "log", "name": "x.ulg", "data_base64": "AAAAAAAA"}, "trajectory.data_base64"),
    ({"format": "log", "name": "x.BIN", "data_base64": "AAAAAAAA"}, "trajectory.data_base64"),
])
def test_bad_log_uploads_name_the_field(client, trajectory, field):
    """Every refusal of a log upload names a field of the request's log trajectory (format, name, data_base64,
    geoid_undulation_m, power_w), at the head of its one-line detail."""
    req = {"trajectory": trajectory, "cards": [CARD], "grid": {"resolution_m": 20, "margin_m": 100}}
    body = assert_names_field(client.post("/contours", json=req), 422, field)
    assert body["detail"].startswith(field + ": ") and "\n" not in body["detail"], body


def test_cut_log_upload_is_mapped_with_a_warning_naming_the_upload(client):
    """A log cut mid-message (a dead battery, a stopped download) is mapped up to the cut, and the GeoJSON's
    warnings say so, naming the upload and never the server's temporary folder."""
    raw = VTOL.read_bytes()
    k = int(0.9 * len(raw))
    req = {"trajectory": {"format": "log", "name": "hop_cut.ulg", "data_base64": base64.b64encode(raw[:k]).decode()},
           "cards": [CARD], "grid": {"resolution_m": 20, "margin_m": 100}, "levels": [45, 50]}
    r = client.post("/contours", json=req)
    assert r.status_code == 200, r.text
    named = [w for w in r.json()["gisnoise"]["warnings"] if "the file was cut" in w]
    assert len(named) == 1 and named[0].startswith(f"hop_cut.ulg: the log ends mid-message at byte {k} of ")
    whole = client.post("/contours", json={**req, "trajectory": _log(VTOL, "hop.ulg")})
    assert not any("the file was cut" in w for w in whole.json()["gisnoise"]["warnings"])
