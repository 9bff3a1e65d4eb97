"""A real uvicorn process on loopback: the CLI command, a kill during a running job, queued jobs kept."""

from __future__ import annotations

import sqlite3
import time

import httpx
import numpy as np
import pytest
from service_helpers import KEY, Server
from test_api_contours import _omni_card, _read_tif, flyover_csv

pytestmark = pytest.mark.server


def _wait(url: str, until: tuple[str, ...], timeout: float = 120.0, pred=None) -> dict:
    end = time.monotonic() + timeout
    while True:
        info = httpx.get(url, timeout=10).json()
        if info["status"] in until and (pred is None or pred(info)):
            return info
        assert time.monotonic() < end, info
        time.sleep(0.05)


def _heavy_request(resolution_m: float) -> dict:
    return {"trajectory": {"format": "csv", "text": flyover_csv()}, "cards": [_omni_card()],
            "grid": {"resolution_m": resolution_m, "margin_m": 300}, "levels": [50, 55, 60], "ground_h_m": 0}


def test_gisnoise_serve_answers_and_stops_cleanly(tmp_path):
    srv = Server(tmp_path / "data", cli=True, env={"GISNOISE_API_KEYS": KEY})
    try:
        h = httpx.get(srv.url + "/health").json()
        assert h["status"] == "ok" and h["queued"] == 0
        assert "swagger" in httpx.get(srv.url + "/docs").text.lower()
        paths = httpx.get(srv.url + "/openapi.json").json()["paths"]
        assert {"/cards", "/contours", "/jobs", "/jobs/fit", "/jobs/diagnose"} <= set(paths)
        page = httpx.get(srv.url + "/")
        assert page.status_code == 200 and "leaflet.js" in page.text
        assert httpx.get(srv.url + "/static/vendor/leaflet/leaflet.js").status_code == 200
        r = httpx.post(srv.url + "/cards", json=_omni_card("served"))
        assert r.status_code == 401 and r.json()["field"] == "X-API-Key"
        r = httpx.post(srv.url + "/cards", json=_omni_card("served"), headers={"X-API-Key": KEY})
        assert r.status_code == 201
    finally:
        srv.stop()
    # uvicorn shuts down, then re-raises the SIGTERM it caught: -15 is a clean exit here
    assert srv.proc.returncode in (0, -15)
    assert "Traceback" not in srv.log.read_text()


def test_kill_during_a_running_job_then_restart_gives_the_uninterrupted_result(tmp_path):
    data = tmp_path / "data"
    req = _heavy_request(5.0)  # a few seconds of work
    srv = Server(data)
    try:
        r = httpx.post(srv.url + "/jobs/contours", json=req, timeout=30)
        assert r.status_code == 202
        first = r.json()["id"]
        light = dict(req, grid={"resolution_m": 25, "margin_m": 100})
        second = httpx.post(srv.url + "/jobs/contours", json=light, timeout=30).json()["id"]
        _wait(f"{srv.url}/jobs/{first}", ("running",), pred=lambda i: i["progress"] > 0.05)
    finally:
        srv.kill()  # SIGKILL mid-job
    with sqlite3.connect(data / "jobs.sqlite3") as con:
        states = dict(con.execute("SELECT id, status FROM jobs").fetchall())
    assert states == {first: "running", second: "queued"}
    srv = Server(data)
    try:
        a = _wait(f"{srv.url}/jobs/{first}", ("succeeded", "failed", "cancelled"))
        b = _wait(f"{srv.url}/jobs/{second}", ("succeeded", "failed", "cancelled"))
        assert a["status"] == "succeeded" and a["attempts"] == 2, a
        assert b["status"] == "succeeded" and b["attempts"] == 1, b
        # the same request run once more, uninterrupted
        ref = httpx.post(srv.url + "/jobs/contours", json=req, timeout=30).json()["id"]
        c = _wait(f"{srv.url}/jobs/{ref}", ("succeeded", "failed", "cancelled"))
        assert c["status"] == "succeeded" and c["attempts"] == 1
        tif, ref_tif = (httpx.get(i["result_url"], params={"format": "geotiff"}).content for i in (a, c))
        geo, ref_geo = (httpx.get(i["result_url"]).json() for i in (a, c))
    finally:
        srv.stop()
    meta_a, bands_a = _read_tif(tif)
    meta_r, bands_r = _read_tif(ref_tif)
    assert meta_a == meta_r
    np.testing.assert_array_equal(bands_a, bands_r)
    assert geo == ref_geo
    assert not any((data / "jobs").glob("*/result.partial"))


def test_graceful_stop_requeues_the_running_job(tmp_path):
    data = tmp_path / "data"
    srv = Server(data)
    try:
        jid = httpx.post(srv.url + "/jobs/contours", json=_heavy_request(5.0), timeout=30).json()["id"]
        _wait(f"{srv.url}/jobs/{jid}", ("running",))
    finally:
        srv.stop()  # SIGTERM: the worker sees cancel(), the job goes back to the queue
    with sqlite3.connect(data / "jobs.sqlite3") as con:
        status, attempts = con.execute("SELECT status, attempts FROM jobs WHERE id = ?", (jid,)).fetchone()
    assert (status, attempts) == ("queued", 1)
    srv = Server(data)
    try:
        info = _wait(f"{srv.url}/jobs/{jid}", ("succeeded", "failed", "cancelled"))
    finally:
        srv.stop()
    assert info["status"] == "succeeded" and info["attempts"] == 2
