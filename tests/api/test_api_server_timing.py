"""``Server-Timing: total`` (the app's own time) on every answer, and the HTTP stack ``gisnoise serve`` runs."""

from __future__ import annotations

import asyncio
import json
import os
import time

import httpx
import pytest
from service_helpers import Server

from gisnoise.cli.serve import http_stack
from gisnoise.service.timing import ServerTiming

ROUTE = {"type": "FeatureCollection", "route": {"altitude_reference": "agl"}, "features": [
    {"type": "Feature", "geometry": {"type": "Point", "coordinates": c}, "properties": {"alt": a, "speed": 22}}
    for c, a in [([10.5200, 52.2600], 0), ([10.5200, 52.2600], 80), ([10.5350, 52.2660], 80), ([10.5350, 52.2660], 0)]]}


def _timing(resp) -> dict[str, float]:
    header = resp.headers.get_list("server-timing")
    assert len(header) == 1, header  # one header: the app's entries and total together
    return {k.strip(): float(v) for k, v in (p.split(";dur=") for p in header[0].split(","))}


def _run(app, method: str = "GET", body: bytes = b"") -> tuple[list[dict], float]:
    """Call an ASGI app once; its messages and the wall time of the call (ms)."""
    sent: list[dict] = []
    msgs = [{"type": "http.request", "body": body, "more_body": False}]

    async def receive():
        return msgs.pop() if msgs else {"type": "http.disconnect"}

    async def send(m):
        sent.append(m)

    scope = {"type": "http", "method": method, "path": "/", "headers": []}
    t0 = time.perf_counter()
    asyncio.run(app(scope, receive, send))
    return sent, 1000 * (time.perf_counter() - t0)


def _slow_app(delay_s: float, headers: list[tuple[bytes, bytes]]):
    async def app(scope, receive, send):
        await receive()
        await asyncio.sleep(delay_s)
        await send({"type": "http.response.start", "status": 200, "headers": headers})
        await send({"type": "http.response.body", "body": b"ok"})
    return app


def test_total_spans_the_apps_work_and_lies_within_the_callers_time():
    sent, wall = _run(ServerTiming(_slow_app(0.05, [(b"content-type", b"text/plain")])))
    head = dict(sent[0]["headers"])
    total = float(head[b"server-timing"].decode().split("total;dur=")[1])
    assert 50.0 <= total <= wall + 0.05  # the app slept 50 ms before its head; the caller waited for all of it
    assert sent[1] == {"type": "http.response.body", "body": b"ok"}  # the body untouched


def test_total_is_appended_to_the_apps_own_server_timing():
    app = ServerTiming(_slow_app(0.0, [(b"Server-Timing", b"evaluate;dur=1.0, map;dur=2.0")]))
    sent, _ = _run(app)
    values = [v for k, v in sent[0]["headers"] if k.lower() == b"server-timing"]
    assert len(values) == 1 and values[0].startswith(b"evaluate;dur=1.0, map;dur=2.0, total;dur=")


def test_contours_evaluate_within_map_within_total_within_the_clients_latency(client):
    req = {"trajectory": {"format": "waypoints", "data": ROUTE}, "cards": ["demo-horizontal", "demo-climb", "demo-sink"],
           "grid": {"resolution_m": 40, "margin_m": 200}, "levels": [45, 55, 65]}
    t0 = time.perf_counter()
    r = client.post("/contours", json=req)
    latency = 1000 * (time.perf_counter() - t0)
    assert r.status_code == 200, r.text
    t = _timing(r)
    # nested intervals, each written to 0.1 ms
    assert 0 < t["evaluate"] <= t["map"] + 0.1 and t["map"] <= t["total"] + 0.1 and t["total"] <= latency + 0.1
    assert json.loads(r.content)["type"] == "FeatureCollection"


def test_every_answer_carries_total_errors_too(client):
    ok = client.get("/cards")
    bad = client.post("/contours", content=b"{", headers={"content-type": "application/json"})
    assert ok.status_code == 200 and bad.status_code == 422
    for r in (ok, bad):
        assert set(_timing(r)) == {"total"} and _timing(r)["total"] >= 0


def test_http_stack_is_the_fast_one_when_installed_else_the_plain_one(monkeypatch):
    pytest.importorskip("uvloop")
    pytest.importorskip("httptools")
    assert http_stack() == ("uvloop", "httptools")
    monkeypatch.setitem(__import__("sys").modules, "uvloop", None)  # import raises ImportError
    monkeypatch.setitem(__import__("sys").modules, "httptools", None)
    assert http_stack() == ("asyncio", "h11")


@pytest.mark.server
def test_gisnoise_serve_starts_and_maps_without_uvloop_and_httptools(tmp_path):
    blocked = tmp_path / "blocked"
    blocked.mkdir()
    for name in ("uvloop", "httptools"):  # as on an install without them
        (blocked / f"{name}.py").write_text(f"raise ImportError('{name} is not installed')\n")
    path = os.pathsep.join(p for p in (str(blocked), os.environ.get("PYTHONPATH", "")) if p)
    srv = Server(tmp_path / "data", cli=True, env={"PYTHONPATH": path})
    try:
        req = {"trajectory": {"format": "waypoints", "data": ROUTE}, "cards": ["demo-horizontal", "demo-climb", "demo-sink"],
               "grid": {"resolution_m": 40, "margin_m": 200}, "levels": [45, 55]}
        r = httpx.post(srv.url + "/contours", json=req, timeout=60)
        assert r.status_code == 200 and {"evaluate", "map", "total"} <= set(_timing(r))
    finally:
        srv.stop()
    assert "event loop asyncio, HTTP parser h11" in srv.log.read_text()
