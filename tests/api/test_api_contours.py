"""POST /contours: GeoJSON and GeoTIFF equal to the CLI's, a physics check, large maps as jobs, errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from service_helpers import CARDS, KEY, REPO, assert_names_field, wait_job

rasterio = pytest.importorskip("rasterio")

P0 = 70.0  # omnidirectional card: L_UAV = P0 - 20 log10(d / 40 m) at P_el = 1


def _omni_card(card_id: str = "omni") -> dict:
    doc = json.loads((CARDS / "demo_horizontal.json").read_text())
    doc.update(id=card_id, phases=[], notes="omnidirectional test card", covariance=None, statistics={},
               provenance={})
    doc["parameters"] = {"p0": P0, "p1": 20.0, "p2": 0.0, "p3": 0.0, "p4": 0.0, "p5": 0.0, "p6": 1.0, "p7": 30.0}
    return doc


def flyover_csv(h: float = 100.0, speed: float = 20.0, dt: float = 0.1, length_m: float = 600.0,
                lat: float = 53.55, lon0: float = 9.99) -> str:
    """A level flight due east at ``h`` (ellipsoidal m), constant speed, reference power 3000 W."""
    n = int(length_m / speed / dt) + 1
    t = np.arange(n) * dt
    m_per_deg = 111_320.0 * math.cos(math.radians(lat))
    lon = lon0 + speed * t / m_per_deg
    rows = ["t,lat,lon,h,roll,pitch,yaw,power_w,phase"]
    rows += [f"{ti:.3f},{lat:.9f},{lo:.9f},{h:.3f},0,0,90,3000,horizontal" for ti, lo in zip(t, lon, strict=True)]
    return "\n".join(rows) + "\n"


def _read_tif(data: bytes) -> tuple[dict, np.ndarray]:
    from rasterio.io import MemoryFile

    with MemoryFile(data) as mf, mf.open() as ds:
        meta = {"crs": ds.crs.to_string(), "transform": tuple(ds.transform), "descriptions": ds.descriptions,
                "nodata": ds.nodata, "shape": (ds.count, ds.height, ds.width)}
        return meta, ds.read()


def _request(**kw) -> dict:
    req = {"trajectory": {"format": "csv", "text": flyover_csv()}, "cards": [_omni_card()],
           "grid": {"resolution_m": 10, "margin_m": 200}, "levels": [45, 50, 55, 60], "ground_h_m": 0.0}
    req.update(kw)
    return req


def test_lamax_below_a_level_flyover_is_spherical_spreading(client):
    r = client.post("/contours", json=_request(output="geotiff"))
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "image/tiff; application=geotiff"
    meta, bands = _read_tif(r.content)
    names = list(meta["descriptions"])
    assert {"LAmax", "LAeq", "SEL"} <= set(names)
    lamax = bands[names.index("LAmax")]
    # closest receiver: 98.5 m below the track (1.5 m receivers on flat ground at 0 m), at most
    # res/sqrt(2) = 7.1 m aside and 1 m along the track: within 0.03 dB of the level at 98.5 m
    expected = P0 - 20 * math.log10(98.5 / 40.0)
    assert np.nanmax(lamax) == pytest.approx(expected, abs=0.03)
    assert np.nanmax(lamax) <= expected + 1e-6


def test_geojson_contours_are_wgs84_isobands_and_isolines(client):
    r = client.post("/contours", json=_request(), headers={"accept": "application/geo+json"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/geo+json"
    fc = r.json()
    assert fc["type"] == "FeatureCollection" and fc["features"]
    kinds = {f["properties"]["kind"] for f in fc["features"]}
    assert kinds == {"isoband", "isoline"}
    assert {f["properties"]["metric"] for f in fc["features"]} == {"LAmax", "LAeq", "SEL"}
    lon = [c[0] for f in fc["features"] if f["geometry"]["type"] == "MultiPolygon"
           for poly in f["geometry"]["coordinates"] for ring in poly for c in ring]
    assert 9.98 < min(lon) and max(lon) < 10.01  # lon, lat order around the flight


def test_http_result_equals_the_cli(client, tmp_path):
    from click.testing import CliRunner

    from gisnoise.cli.main import cli

    csv = tmp_path / "route.csv"
    csv.write_text(flyover_csv(h=80.0))
    card = tmp_path / "omni.json"
    card.write_text(json.dumps(_omni_card()))
    out = tmp_path / "cli"
    res = CliRunner().invoke(cli, ["-q", "contour", str(csv), "--card", str(card), "--card",
                                   str(CARDS / "demo_climb.json"), "--out", str(out), "--resolution", "15",
                                   "--margin", "250", "--levels", "50,55,60", "--ground-height", "0"])
    assert res.exit_code == 0, res.output
    req = {"trajectory": {"format": "csv", "text": csv.read_text()}, "cards": ["demo-climb", _omni_card()],
           "grid": {"resolution_m": 15, "margin_m": 250}, "levels": [50, 55, 60], "ground_h_m": 0}
    tif = client.post("/contours", json=req, headers={"accept": "image/tiff; application=geotiff"})
    geo = client.post("/contours", json=req)
    assert tif.status_code == 200 and geo.status_code == 200
    meta_http, bands_http = _read_tif(tif.content)
    meta_cli, bands_cli = _read_tif((out / "levels.tif").read_bytes())
    assert meta_http == meta_cli
    np.testing.assert_array_equal(bands_http, bands_cli)
    assert geo.json() == json.loads((out / "contours.geojson").read_text())


def test_http_result_equals_the_cli_for_the_sample_route(client, tmp_path):
    from click.testing import CliRunner

    from gisnoise.cli.main import cli

    route = REPO / "gisnoise" / "data" / "routes" / "delivery_route.geojson"
    if not route.is_file():
        pytest.skip("no sample route in this checkout")
    out = tmp_path / "cli"
    args = ["-q", "contour", str(route), "--out", str(out), "--resolution", "40", "--margin", "200",
            "--levels", "45,55,65"]
    for name in ("demo_horizontal", "demo_climb", "demo_sink"):
        args += ["--card", str(CARDS / f"{name}.json")]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    req = {"trajectory": {"format": "waypoints", "data": json.loads(route.read_text())},
           "cards": ["demo-horizontal", "demo-climb", "demo-sink"], "grid": {"resolution_m": 40, "margin_m": 200},
           "levels": [45, 55, 65]}
    tif = client.post("/contours", json=dict(req, output="geotiff"))
    geo = client.post("/contours", json=req)
    assert tif.status_code == 200 and geo.status_code == 200, (tif.text, geo.text)
    meta_http, bands_http = _read_tif(tif.content)
    meta_cli, bands_cli = _read_tif((out / "levels.tif").read_bytes())
    assert meta_http == meta_cli
    np.testing.assert_array_equal(bands_http, bands_cli)
    doc_cli = json.loads((out / "contours.geojson").read_text())
    # the warnings that the demo cards are flown below the sample campaign's powers name the trajectory as each
    # face got it: the command line by its file, the service as "route"
    assert sum(w.startswith(f"{route}: card ") for w in doc_cli["gisnoise"]["warnings"]) == 1
    doc_cli["gisnoise"]["warnings"] = [w.replace(f"{route}: ", "route: ", 1) for w in doc_cli["gisnoise"]["warnings"]]
    assert geo.json() == doc_cli


def test_trajectory_formats_give_the_same_map(client):
    text = flyover_csv(length_m=300.0, dt=0.5)
    lines = [ln.split(",") for ln in text.strip().splitlines()]
    header, data = lines[0], lines[1:]
    cols = {h: [r[i] if h == "phase" else float(r[i]) for r in data] for i, h in enumerate(header)}
    rows = [{h: (r[i] if h == "phase" else float(r[i])) for i, h in enumerate(header)} for r in data]
    line = {"type": "Feature", "properties": {"times": cols["t"], "power_w": cols["power_w"], "yaw": cols["yaw"],
                                              "roll": cols["roll"], "pitch": cols["pitch"], "phase": cols["phase"]},
            "geometry": {"type": "LineString",
                         "coordinates": [[lo, la, h] for lo, la, h in zip(cols["lon"], cols["lat"], cols["h"],
                                                                          strict=True)]}}
    outs = []
    for traj in ({"format": "csv", "text": text}, {"format": "columns", "columns": cols},
                 {"format": "rows", "rows": rows}, {"format": "geojson", "data": line}):
        r = client.post("/contours", json=_request(trajectory=traj, output="geotiff"))
        assert r.status_code == 200, (traj["format"], r.text)
        outs.append(_read_tif(r.content)[1])
    for o in outs[1:]:
        np.testing.assert_allclose(o, outs[0], atol=1e-3)


def test_csv_text_with_a_byte_order_mark_or_crlf_gives_the_same_map(client):
    """A flight CSV's text as an editor saves it (UTF-8 byte-order mark, CRLF line ends) is the same flight: the
    command line reads such a file, and the service its text, to the same map."""
    text = flyover_csv(length_m=300.0, dt=0.5)
    outs = []
    for variant in (text, "\ufeff" + text, text.replace("\n", "\r\n"), "\ufeff" + text.replace("\n", "\r\n")):
        r = client.post("/contours", json=_request(trajectory={"format": "csv", "text": variant}, output="geotiff"))
        assert r.status_code == 200, r.text
        outs.append(_read_tif(r.content)[1])
    for o in outs[1:]:
        np.testing.assert_array_equal(o, outs[0])


def test_waypoints_route(client):
    wps = {"type": "FeatureCollection", "route": {"altitude_reference": "agl"}, "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": c}, "properties": {"alt": a, "speed": 20}}
        for c, a in [([9.99, 53.55], 0), ([9.99, 53.55], 60), ([10.0, 53.553], 60), ([10.0, 53.553], 0)]]}
    r = client.post("/contours", json={"trajectory": {"format": "waypoints", "data": wps},
                                       "cards": ["demo-horizontal", "demo-climb", "demo-sink"],
                                       "grid": {"resolution_m": 25, "margin_m": 200}})
    assert r.status_code == 200, r.text
    assert r.json()["features"]


def test_large_maps_become_jobs_with_the_same_result(make_client):
    c = make_client(sync_work_limit=1e5)
    req = _request(levels=[50, 55, 60])
    r = c.post("/contours", json=req)
    assert r.status_code == 202, r.text
    info = wait_job(c, r.json()["id"])
    assert info["status"] == "succeeded" and info["files"] == ["contours.geojson", "levels.tif"]
    job_tif = c.get(info["result_url"], params={"format": "geotiff"}).content
    job_geo = c.get(info["result_url"]).json()
    # the same request forced synchronous on a service with a high limit
    c2 = make_client(sync_work_limit=1e12, data_dir=c.app.state.gisnoise.settings.data_dir.parent / "other")
    np.testing.assert_array_equal(_read_tif(job_tif)[1],
                                  _read_tif(c2.post("/contours", json=dict(req, output="geotiff")).content)[1])
    assert job_geo == c2.post("/contours", json=req).json()


def test_job_keeps_the_cards_of_its_submission(make_client):
    c = make_client(start_workers=False)
    doc = _omni_card("mutable")
    assert c.post("/cards", json=doc).status_code == 201
    r = c.post("/jobs/contours", json=_request(cards=["mutable"]))
    assert r.status_code == 202
    c.delete("/cards/mutable")
    st = c.app.state.gisnoise
    stored = json.loads((st.jobs.input_dir(r.json()["id"]) / "request.json").read_text())
    assert stored["cards"][0]["parameters"]["p0"] == P0 and stored["cards"][0]["id"] == "mutable"
    st.pool.start()
    assert wait_job(c, r.json()["id"])["status"] == "succeeded"


def test_jobs_need_a_key_when_configured(make_client):
    c = make_client(api_keys=[KEY], sync_work_limit=1e5, start_workers=False)
    assert_names_field(c.post("/contours", json=_request()), 401, "X-API-Key")
    assert_names_field(c.post("/jobs/contours", json=_request()), 401, "X-API-Key")
    assert c.post("/contours", json=_request(), headers={"X-API-Key": KEY}).status_code == 202


def _csv_with(edit) -> str:
    lines = flyover_csv(length_m=100.0, dt=1.0).strip().splitlines()
    return "\n".join(edit(lines)) + "\n"


_ROW = {"t": 0, "lat": 53.5, "lon": 9.99, "h": 100, "roll": 0, "pitch": 0, "yaw": 90, "power_w": 3000}


@pytest.mark.parametrize("trajectory, status, field", [
    ({"format": "csv", "text": _csv_with(lambda ls: [ls[0].replace(",power_w", "")] +
                                         [ln.rsplit(",", 2)[0] + "," + ln.rsplit(",", 1)[1] for ln in ls[1:]])},
     422, "trajectory.power_w"),
    ({"format": "csv", "text": _csv_with(lambda ls: ls[:3] + [ls[3].replace(",80.000,", ",nan,")
                                                              .replace(",100.000,", ",nan,")] + ls[4:])},
     422, "trajectory.h"),
    ({"format": "csv", "text": _csv_with(lambda ls: [ls[0], ls[2], ls[1]] + ls[3:])}, 422, "trajectory.t"),
    ({"format": "csv", "text": _csv_with(lambda ls: ls[:1])}, 422, "trajectory.t"),
    ({"format": "csv", "text": _csv_with(lambda ls: [ls[0]] + [ln.replace("horizontal", "cruise") for ln in ls[1:]])},
     422, "trajectory.phase"),
    ({"format": "columns", "columns": {"t": [0, 1], "lat": [53.5]}}, 422, "trajectory.columns.lat"),
    ({"format": "rows", "rows": [dict(_ROW, phase="horizontal"), dict(_ROW, t=1)]}, 422, "trajectory.rows[1].phase"),
    ({"format": "rows", "rows": [{"t": 0}, dict(_ROW, t=1)]}, 422, "trajectory.rows.0.lat"),
    ({"format": "columns", "columns": {k: [v, v] for k, v in dict(_ROW, lon=500).items()}}, 422,
     "trajectory.columns.lon.0"),
    ({"format": "geojson", "data": {"type": "Point", "coordinates": [0, 0]}}, 422, None),
    ({"format": "gpx", "text": "x"}, 422, "trajectory"),
])
def test_bad_trajectories_name_the_field(client, trajectory, status, field):
    body = assert_names_field(client.post("/contours", json=_request(trajectory=trajectory)), status, field)
    assert body["field"].startswith("trajectory")


@pytest.mark.parametrize("change, status, field", [
    ({"grid": {"resolution_m": 0.1, "margin_m": 2000}}, 413, "grid.resolution_m"),
    ({"grid": {"resolution_m": 0.01}}, 422, "grid.resolution_m"),
    ({"grid": {"resolution_m": -1}}, 422, "grid.resolution_m"),
    ({"grid": {"crs": "EPSG:999999"}}, 422, "grid.crs"),
    ({"grid": {"crs": "EPSG:4326"}}, 422, "grid.crs"),
    ({"cards": []}, 422, "cards"),
    ({"cards": ["no-such-card"]}, 422, "cards[0]"),
    ({"cards": ["demo-climb"]}, 422, "cards"),
    ({"cards": [dict(_omni_card(), phase="cruise")]}, 422, "cards.0.phase"),
    ({"phase_cards": {"cruise": "demo-climb"}}, 422, "phase_cards.cruise"),
    ({"metrics": ["Lden"]}, 422, "metrics.0"),
    ({"levels": []}, 422, "levels"),
    ({"levels": ["loud"]}, 422, "levels.0"),
    ({"snapshot_t": 1e6}, 422, "snapshot_t"),
    ({"colour": "red"}, 422, "colour"),
    ({"uncertainty": True}, 422, None),
])
def test_bad_requests_name_the_field(client, change, status, field):
    body = assert_names_field(client.post("/contours", json=_request(**change)), status, field)
    assert body["detail"]


def test_levels_outside_the_range_a_microphone_records_are_refused_and_duplicates_drawn_once(client):
    """levels [60, 45, 45, -1000] is 422 on levels.3 stating the range [-50, 200] dB(A) and why (it was 200 with a band
    'LAmax -1000-45 dB(A)'); a time-above threshold likewise; [60, 45, 45] draws 45 and 60 once each, in order."""
    body = assert_names_field(client.post("/contours", json=_request(levels=[60, 45, 45, -1000])), 422, "levels.3")
    assert "[-50, 200] dB(A)" in body["detail"] and "microphone" in body["detail"] and "-1000" in body["detail"]
    assert_names_field(client.post("/contours", json=_request(levels=[45, 1e308])), 422, "levels.1")
    assert_names_field(client.post("/contours", json=_request(threshold_db=[-1000])), 422, "threshold_db.0")
    r = client.post("/contours", json=_request(levels=[60, 45, 45], metrics=["LAmax"]))
    assert r.status_code == 200, r.text
    fc = r.json()
    assert fc["gisnoise"]["levels"] == [45.0, 60.0]
    bands = [(f["properties"]["level"], f["properties"]["level_max"]) for f in fc["features"]
             if f["properties"]["kind"] == "isoband"]
    assert bands == [(45.0, 60.0), (60.0, None)]


def test_geojson_metrics_are_the_geotiff_bands_in_order_even_without_contours(client):
    """gisnoise.metrics lists the computed metrics in the order of the GeoTIFF's bands for the same request, also when
    no contour exists (199 dB(A)); it was sorted (['LAeq', 'LAmax']) and [] without a contour."""
    for levels in ([45, 50], [199]):
        req = _request(metrics=["SEL", "LAeq"], levels=levels)
        meta, _ = _read_tif(client.post("/contours", json=dict(req, output="geotiff")).content)
        fc = client.post("/contours", json=req).json()
        assert fc["gisnoise"]["metrics"] == list(meta["descriptions"]) == ["LAeq", "SEL"]
        assert (fc["features"] == []) == (levels == [199])


def test_phase_cards_bind_a_card_to_a_phase(client):
    # demo-climb states phases climb and hover; bound to horizontal it maps the level flight
    r = client.post("/contours", json=_request(cards=[], phase_cards={"horizontal": "demo-climb"},
                                               output="geotiff"))
    assert r.status_code == 200, r.text
    # an omnidirectional card stored for 'climb' serves no phase of the level flight on its own ...
    assert client.post("/cards", json=dict(_omni_card("omni-climb"), phase="climb")).status_code == 201
    assert_names_field(client.post("/contours", json=_request(cards=["omni-climb"])), 422, "cards")
    # ... bound to 'horizontal' it maps it: spherical spreading from 98.5 m below the track, as in
    # test_lamax_below_a_level_flyover_is_spherical_spreading
    r = client.post("/contours", json=_request(cards=[], phase_cards={"horizontal": "omni-climb"},
                                               output="geotiff"))
    assert r.status_code == 200, r.text
    meta, bands = _read_tif(r.content)
    lamax = bands[list(meta["descriptions"]).index("LAmax")]
    assert np.nanmax(lamax) == pytest.approx(P0 - 20 * math.log10(98.5 / 40.0), abs=0.03)


@pytest.mark.parametrize("path, text", [("grid.resolution_m", '"resolution_m": NaN'),
                                        ("grid.resolution_m", '"resolution_m": Infinity'),
                                        ("ground_h_m", '"ground_h_m": NaN'), ("levels.1", '"levels": [45, -Infinity]'),
                                        ("receiver_height_m", '"receiver_height_m": NaN')])
def test_non_finite_numbers_are_said_to_be_no_finite_number(client, path, text):
    """NaN and infinities (which Python's JSON reads) are refused as 'not a finite number' naming the field; NaN
    was reported as 'should be less than or equal to 100000, got nan'."""
    req = _request(grid={"resolution_m": 10, "margin_m": 200}, receiver_height_m=1.5)
    key = text.split(":")[0].strip('"')
    raw = json.dumps(req).replace(f'"{key}": ' + json.dumps(_path_value(req, key)), text, 1)
    assert text in raw
    r = client.post("/contours", content=raw, headers={"content-type": "application/json"})
    body = assert_names_field(r, 422, path)
    assert body["detail"].startswith(f"{path}: Input should be a finite number"), body


def _path_value(req: dict, key: str):
    return req["grid"][key] if key in req["grid"] else req[key]


@pytest.mark.parametrize("path", ["/contours", "/cards", "/routes/compare", "/routes/optimize"])
@pytest.mark.parametrize("content_type", ["text/plain", "application/x-www-form-urlencoded", None])
def test_a_json_body_sent_as_another_media_type_is_415_naming_application_json(client, path, content_type):
    """Valid JSON sent as text/plain (or form-encoded, or without Content-Type) is 415 naming the media type the
    operation reads; it was 422 'body: Input should be a valid dictionary'."""
    raw = json.dumps(_request()).encode()
    headers = {} if content_type is None else {"content-type": content_type}
    req = client.build_request("POST", path, content=raw, headers=headers)
    assert req.headers.get("content-type") == content_type
    r = client.send(req)
    body = assert_names_field(r, 415, "Content-Type")
    assert "application/json" in body["detail"] and (content_type or "none") in body["detail"]


def test_geo_json_media_type_is_read_as_json(client):
    r = client.post("/contours", content=json.dumps(_request(levels=[50])),
                    headers={"content-type": "application/geo+json; charset=utf-8"})
    assert r.status_code == 200, r.text


def test_malformed_json_is_422_naming_the_body(client):
    r = client.post("/contours", content=b'{"trajectory": ', headers={"content-type": "application/json"})
    assert_names_field(r, 422, "body")


def test_uncertainty_bands_from_a_card_with_covariance(client):
    card = json.loads((CARDS / "demo_horizontal.json").read_text())
    if card.get("covariance") is None:
        pytest.skip("the demo card has no covariance")
    r = client.post("/contours", json=_request(cards=["demo-horizontal"], uncertainty=True, output="geotiff",
                                               metrics=["LAmax", "LAeq"]))
    assert r.status_code == 200, r.text
    meta, bands = _read_tif(r.content)
    names = list(meta["descriptions"])
    assert {"LAmax_std", "LAeq_std", "LAmax_p95", "LAeq_p95"} <= set(names)
    std = bands[names.index("LAmax_std")]
    lamax, p95 = bands[names.index("LAmax")], bands[names.index("LAmax_p95")]
    ok = np.isfinite(std)
    assert np.all(std[ok] >= 0)
    np.testing.assert_allclose(p95[ok], lamax[ok] - 1.645 * std[ok], atol=1e-3)  # one-sided 95 % normal quantile


def test_uncertainty_of_an_omni_card_with_p0_variance_only(client):
    # covariance on p0 only (std 0.5 dB): dL_UAV/dp0 = 1 at every instant (p2 = p4 = 0, no background),
    # so LAmax_std = LAeq_std = 0.5 dB in every cell and the 95 % level is 1.6449 * 0.5 dB lower
    cov = np.zeros((8, 8))
    cov[0, 0] = 0.25
    card = dict(_omni_card("omni-cov"), covariance=cov.tolist())
    r = client.post("/contours", json=_request(cards=[card], uncertainty=True, output="geotiff",
                                               metrics=["LAmax", "LAeq"]))
    assert r.status_code == 200, r.text
    meta, bands = _read_tif(r.content)
    b = dict(zip(meta["descriptions"], bands, strict=True))
    np.testing.assert_allclose(b["LAmax_std"], 0.5, atol=1e-6)
    np.testing.assert_allclose(b["LAeq_std"], 0.5, atol=1e-6)
    np.testing.assert_allclose(b["LAmax_p95"], b["LAmax"] - 1.6448536 * 0.5, atol=1e-4)
    np.testing.assert_allclose(b["LAeq_p95"], b["LAeq"] - 1.6448536 * 0.5, atol=1e-4)
