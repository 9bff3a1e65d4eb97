"""The adversarial probe's service findings (issue 19): bounded memory, refusals before work, no 500.

Each test reproduces one finding: the request that exhausted the server, crashed it (500),
stored a bad identifier or answered a wrong ``Allow``; now a 4xx naming the field.
"""

from __future__ import annotations

import io
import json
import socket
import zipfile
from pathlib import Path

import httpx
import pytest
from service_helpers import KEY, REPO, Server, assert_names_field, wait_job

from gisnoise.limits import SAFE_ID_PATTERN

CAMPAIGN = REPO / "sample_data" / "campaign"
GB = 1 << 30

_ROUTE = {"type": "FeatureCollection", "route": {"altitude_reference": "agl"}, "features": [
    {"type": "Feature", "geometry": {"type": "Point", "coordinates": c}, "properties": p}
    for c, p in [([10.540, 52.243], {"alt": 0}), ([10.540, 52.243], {"alt": 60}),
                 ([10.550, 52.250], {"alt": 60, "speed": 22}), ([10.550, 52.250], {"alt": 0})]]}


def _route(**settings) -> dict:
    doc = json.loads(json.dumps(_ROUTE))
    doc["route"].update(settings)
    return doc


def _peak_rss_bytes(pid: int) -> int:
    """The process's peak resident memory (VmHWM), bytes."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmHWM")


@pytest.fixture()
def server(tmp_path):
    if not Path("/proc/self/status").is_file():
        pytest.skip("needs /proc to read the server's memory")
    srv = Server(tmp_path / "data", env={"GISNOISE_API_KEYS": KEY})
    yield srv
    srv.stop()


def test_tiny_sample_step_is_refused_before_the_route_is_sampled(server):
    """1e-5 s and 1e-6 s steps grew the server to 6.8 and 21.5 GB; now 413 and memory stays bounded."""
    for dt in (1e-5, 1e-6):
        body = {"trajectory": {"format": "waypoints", "data": _route(sample_dt_s=dt)}, "cards": ["demo-horizontal"]}
        r = httpx.post(server.url + "/contours", json=body, timeout=60)
        b = assert_names_field(r, 413, "trajectory.data.sample_dt_s")
        assert "200000" in b["detail"]
    for props, field in (({"hold_s": 1e12}, "hold_s"), ({"speed": 1e-9}, "sample_dt_s")):
        doc = _route()
        doc["features"][2]["properties"].update(props)
        r = httpx.post(server.url + "/contours", json={"trajectory": {"format": "waypoints", "data": doc},
                                                       "cards": ["demo-horizontal"]}, timeout=60)
        assert r.status_code in (413, 422) and r.json()["field"] == f"trajectory.data.{field}", r.text
    assert httpx.get(server.url + "/health", timeout=5).status_code == 200
    assert _peak_rss_bytes(server.proc.pid) < GB


def test_unauthenticated_upload_is_refused_from_its_headers(server):
    """A 200 MB upload without a key was read in full before the 401; now refused before the body."""
    with socket.create_connection(("127.0.0.1", server.port), timeout=30) as s:
        s.sendall(b"POST /jobs/fit HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; boundary=b\r\n"
                  b"Content-Length: 200000000\r\n\r\n" + b"\0" * 65536)
        # the answer comes although 199.9 MB of the declared body were never sent
        raw = b""
        while chunk := s.recv(65536):  # the server closes the connection after its answer
            raw += chunk
        answer = raw.decode("latin-1")
    assert answer.startswith("HTTP/1.1 401"), answer[:200]
    assert '"field": "X-API-Key"' in answer or '"field":"X-API-Key"' in answer
    with socket.create_connection(("127.0.0.1", server.port), timeout=30) as s:
        s.sendall(b"POST /jobs/diagnose HTTP/1.1\r\nHost: x\r\nX-API-Key: wrong\r\nContent-Length: 200000000\r\n\r\n")
        assert s.recv(65536).decode("latin-1").startswith("HTTP/1.1 403")
    assert _peak_rss_bytes(server.proc.pid) < GB


def _asgi(app, method: str, path: str, query: bytes = b"", headers: tuple = (), body: bytes = b"{}",
          content_type: bytes = b"application/json"):
    """Call ``app`` once over ASGI; returns (status, body, whether the app asked for the request's body)."""
    import asyncio

    asked = []
    sent: list[dict] = []

    async def receive():
        asked.append(True)
        return {"type": "http.request", "body": body, "more_body": False}

    async def send(msg):
        sent.append(msg)

    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": method, "scheme": "http",
             "path": path, "raw_path": path.encode(), "query_string": query, "root_path": "",
             "headers": [(b"host", b"x"), (b"content-type", content_type),
                         (b"content-length", str(len(body)).encode()), *headers],
             "client": ("127.0.0.1", 1), "server": ("x", 80)}
    asyncio.run(app(scope, receive, send))
    status = next(m["status"] for m in sent if m["type"] == "http.response.start")
    return status, b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body"), bool(asked)


@pytest.mark.parametrize("path, query", [("/layers", b""), ("/contours", b"job=true"), ("/contours", b"job=1"),
                                         ("/jobs/contours", b"")])
def test_writes_without_a_key_are_refused_before_their_body_is_read(make_client, path, query):
    """POST /layers (uploads up to 500 MB) and POST /contours?job=true without a key are 401 from the headers: not a
    byte of the body is read (POST /layers read the whole upload, /contours?job=true prepared the map first)."""
    c = make_client(api_keys=[KEY], start_workers=False)
    kw = {}
    if path == "/layers":  # an upload: a multipart form, which FastAPI reads before any dependency
        kw = {"content_type": b"multipart/form-data; boundary=b",
              "body": b'--b\r\nContent-Disposition: form-data; name="kind"\r\n\r\npopulation\r\n--b--\r\n'}
    status, body, asked = _asgi(c.app, "POST", path, query, **kw)
    assert status == 401 and not asked, (status, body, asked)
    assert json.loads(body)["field"] == "X-API-Key"
    status, body, asked = _asgi(c.app, "POST", path, query, headers=((b"x-api-key", b"wrong"),), **kw)
    assert status == 403 and not asked, (status, body)


def test_a_map_that_stays_synchronous_needs_no_key(make_client):
    """Reads need no key: POST /contours without job (a small map) or with job=false is answered without one."""
    from test_api_contours import _request

    c = make_client(api_keys=[KEY], start_workers=False)
    for params in ({}, {"job": "false"}):
        r = c.post("/contours", json=_request(levels=[50]), params=params)
        assert r.status_code == 200, r.text


# ------------------------------------------------------------------ the six 500s
def _zip(files: dict[str, bytes | str]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return buf.getvalue()


def _sample_campaign_zip(replace: dict[str, bytes] | None = None) -> bytes:
    files: dict[str, bytes | str] = {}
    doc = json.loads((CAMPAIGN / "campaign.json").read_text())
    doc["flights"] = [f for f in doc["flights"] if f["id"] == "f1"]
    files["c/campaign.json"] = json.dumps(doc)
    for p in sorted(CAMPAIGN.rglob("f1.csv")):
        files[f"c/{p.relative_to(CAMPAIGN)}"] = p.read_bytes()
    for k, v in (replace or {}).items():
        files[k] = v
    return _zip(files)


def test_corrupt_deflate_data_is_422(client):
    good = _zip({"campaign.json": "{}", "flights/f1.csv": "t,lat\n" * 2000})
    raw = bytearray(good)
    start = raw.index(b"flights/f1.csv") + len("flights/f1.csv")  # the member's compressed data
    for i in range(start + 2, start + 40):
        raw[i] ^= 0x5A
    r = client.post("/jobs/fit", files={"campaign": ("c.zip", bytes(raw), "application/zip")},
                    data={"phase": "horizontal"})
    body = assert_names_field(r, 422, "campaign")
    assert "unzip" in body["detail"]


def test_binary_card_file_in_diagnose_is_422(client):
    r = client.post("/jobs/diagnose", files={"campaign": ("c.zip", _zip({"campaign.json": "{}"}), "application/zip"),
                                             "card": ("card.json", bytes(range(256)), "application/json")})
    assert_names_field(r, 422, "card")


@pytest.mark.skipif(not (CAMPAIGN / "campaign.json").is_file(), reason="no sample campaign")
def test_fit_on_a_binary_microphone_csv_fails_with_422_naming_the_file(client):
    z = _sample_campaign_zip({"c/mics/m1/f1.csv": b"\xff\xfe\x00\x81" * 200})
    r = client.post("/jobs/fit", files={"campaign": ("c.zip", z, "application/zip")}, data={"phase": "horizontal"})
    assert r.status_code == 202, r.text
    info = wait_job(client, r.json()["id"], timeout=120)
    assert info["status"] == "failed"
    assert info["error"]["status"] == 422, info["error"]
    assert "f1.csv" in info["error"]["detail"] and "UTF-8" in info["error"]["detail"]


@pytest.mark.skipif(not (CAMPAIGN / "campaign.json").is_file(), reason="no sample campaign")
def test_campaign_errors_show_no_server_path(client):
    z = _sample_campaign_zip({"c/campaign.json": b'{"schema": "gisnoise/campaign/1", "microphones": 3}'})
    r = client.post("/jobs/fit", files={"campaign": ("c.zip", z, "application/zip")}, data={"phase": "horizontal"})
    info = wait_job(client, r.json()["id"], timeout=120)
    assert info["status"] == "failed" and 400 <= info["error"]["status"] < 500, info
    detail = info["error"]["detail"]
    data_dir = client.app.state.gisnoise.settings.data_dir
    assert "campaign.json" in detail
    assert str(data_dir) not in detail and str(data_dir.resolve()) not in detail and "/jobs/" not in detail, detail


def test_nul_byte_and_unlisted_file_names_are_404_never_joined_to_a_path(client):
    c = client
    body = {"trajectory": {"format": "waypoints", "data": _route()}, "cards": ["demo-horizontal", "demo-climb", "demo-sink"],
            "grid": {"resolution_m": 100, "margin_m": 100}, "metrics": ["LAmax"]}
    r = c.post("/jobs/contours", json=body)
    assert r.status_code == 202, r.text
    job = wait_job(c, r.json()["id"], timeout=120)
    assert job["status"] == "succeeded" and "levels.tif" in job["files"], job["error"]
    assert c.get(f"/jobs/{job['id']}/files/levels.tif").status_code == 200
    for name in ("levels.tif%00.json", "levels.tif%00", "..%2Fjobs.sqlite3", "..%2F..%2Fjobs.sqlite3", "%2Fetc%2Fpasswd",
                 "nope.tif"):
        r = c.get(f"/jobs/{job['id']}/files/{name}")
        assert r.status_code in (404, 422), (name, r.status_code, r.text)
        assert r.json()["field"] == "name", r.json()


# ------------------------------------------------------------------ identifiers and headers
def _card(card_id: str) -> dict:
    doc = json.loads((REPO / "gisnoise" / "data" / "cards" / "demo_horizontal.json").read_text())
    doc["id"] = card_id
    return doc


@pytest.mark.parametrize("card_id", ["x\n", "con", "CON.json", "nul", "com1", ".hidden", "a b", "a\x00b", "a" * 129])
def test_unsafe_card_ids_are_refused_on_upload(client, card_id):
    assert_names_field(client.post("/cards", json=_card(card_id)), 422, "id")
    assert client.get("/cards").status_code == 200


def test_ids_in_urls_follow_the_one_pattern_and_headers_stay_valid(client):
    assert_names_field(client.get("/cards/x%0A"), 422, "card_id")
    assert_names_field(client.get("/cards/con"), 422, "card_id")
    assert_names_field(client.get("/jobs/x%0A"), 422, "job_id")
    r = client.post("/cards", json=_card("ok.card-1_a"))
    assert r.status_code == 201
    r = client.get("/cards/ok.card-1_a")
    assert r.status_code == 200 and r.headers["etag"] == '"ok.card-1_a@1"'
    spec = client.get("/openapi.json").json()
    params = {p["name"]: p["schema"] for p in spec["paths"]["/cards/{card_id}"]["get"]["parameters"]}
    assert params["card_id"]["pattern"] == SAFE_ID_PATTERN
    params = {p["name"]: p["schema"] for p in spec["paths"]["/jobs/{job_id}"]["get"]["parameters"]}
    assert params["job_id"]["pattern"] == SAFE_ID_PATTERN
    card_schema = spec["components"]["schemas"]["CardDocument"]["properties"]["id"]
    assert card_schema["pattern"] == SAFE_ID_PATTERN


# ------------------------------------------------------------------ values that passed for data
def test_longitude_500_and_ground_above_the_track_are_422(client):
    n = 5
    cols = {"t": [0.0, 1, 2, 3, 4], "lat": [52.2] * n, "lon": [500.0] * n, "h": [150.0] * n, "roll": [0.0] * n,
            "pitch": [0.0] * n, "yaw": [0.0] * n, "power_w": [3000.0] * n}
    body = {"trajectory": {"format": "columns", "columns": cols}, "cards": ["demo-horizontal"]}
    b = assert_names_field(client.post("/contours", json=body), 422, "trajectory.columns.lon.0")
    assert "500" in b["detail"]
    cols["lon"] = [10.5] * n
    body["ground_h_m"] = 9000.0
    b = assert_names_field(client.post("/contours", json=body), 422)
    assert b["field"] == "ground_h_m" and "9000" in b["detail"] and "above the track" in b["detail"]


# ------------------------------------------------------------------ methods and query strings
@pytest.mark.parametrize("method,path,allow", [
    ("PUT", "/cards", "GET, HEAD, POST"),
    ("PATCH", "/cards/demo-horizontal", "DELETE, GET, HEAD"),
    ("POST", "/cards/demo-horizontal", "DELETE, GET, HEAD"),
    ("PUT", "/jobs/abc", "DELETE, GET, HEAD"),
    ("GET", "/contours", "POST"),
])
def test_405_carries_the_methods_the_path_has(client, method, path, allow):
    r = client.request(method, path)
    assert_names_field(r, 405, "method")
    assert r.headers["allow"] == allow


def test_a_repeated_query_parameter_is_refused(client):
    assert_names_field(client.get("/jobs?offset=1&offset=2"), 422, "offset")
    assert client.get("/jobs?offset=1&limit=2").status_code == 200
