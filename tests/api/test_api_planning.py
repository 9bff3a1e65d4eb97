"""Exposure layers stored by id (versioned) and ``POST /routes/compare`` against closed-form counts."""

from __future__ import annotations

import io
import math
import zipfile
from pathlib import Path

import geopandas as gpd
import numpy as np
import pytest
import rasterio
import shapely
from affine import Affine
from pyproj import CRS
from service_helpers import KEY, assert_names_field

from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)
G0, HEIGHT, HR = 70.0, 60.0, 1.5
OMNI = {"schema": "gisnoise/model-card/1", "id": "omni", "vehicle": "test", "phase": "horizontal",
        "ansatz": "paper-offset", "reference_power_w": 3000.0, "reference_distance_m": 40.0,
        "parameters": dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0)}


def route_csv(e: float) -> dict:
    t = np.arange(0.0, 1200.0 / 20.0 + 1e-9, 0.5)
    lat, lon, h = FRAME.to_wgs84(np.full_like(t, e), -600.0 + 20.0 * t, np.full_like(t, HEIGHT))
    tr = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t,
                    power_w=np.full_like(t, 3000.0), phase=np.full(t.size, "horizontal"))
    return {"format": "csv", "text": tr.to_csv()}


def population_tif(path: Path) -> bytes:
    """A 200 m x 200 m block of 1 person per 10 m x 10 m cell at the origin."""
    with rasterio.open(path, "w", driver="GTiff", width=20, height=20, count=1, dtype="float32",
                       crs=CRS.from_user_input(TMERC).to_wkt(), transform=Affine(10.0, 0, -100, 0, -10.0, 100)) as d:
        d.write(np.ones((20, 20), dtype=np.float32), 1)
    return path.read_bytes()


def upload(client, kind, lid, name, data, key=True):
    return client.post("/layers", data={"kind": kind, "id": lid}, files={"file": (name, data)},
                       headers={"X-API-Key": KEY} if key else {})


def test_layers_are_versioned_and_compare_ranks_by_closed_form_counts(make_client, tmp_path):
    client = make_client(api_keys=[KEY])
    data = population_tif(tmp_path / "pop.tif")
    assert upload(client, "population", "town", "pop.tif", data, key=False).status_code == 401
    r1 = upload(client, "population", "town", "pop.tif", data)
    assert r1.status_code == 201 and r1.json()["ref"] == "town@1" and r1.json()["total_people"] == 400.0
    r2 = upload(client, "population", "town", "pop.tif", data)
    assert r2.json()["ref"] == "town@2"
    assert [(x["id"], x["version"]) for x in client.get("/layers").json()] == [("town", 1), ("town", 2)]
    # buildings as a zipped Shapefile
    utm = CRS.from_epsg(32632)
    gdf = gpd.GeoDataFrame({"residents": [5]}, geometry=[shapely.box(0, 0, 10, 10)], crs=utm)
    gdf.to_file(tmp_path / "b.shp", engine="pyogrio")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for p in tmp_path.glob("b.*"):
            zf.write(p, p.name)
    rb = upload(client, "buildings", "houses", "b.zip", buf.getvalue())
    assert rb.status_code == 201 and rb.json()["buildings"] == 1

    body = {"routes": [route_csv(0.0), route_csv(400.0)], "names": ["over", "beside"], "cards": [OMNI],
            "population": "town@1", "ground_h_m": 0.0, "grid": {"resolution_m": 10.0, "margin_m": 150.0}}
    r = client.post("/routes/compare", json=body)
    assert r.status_code == 200, r.text
    doc = r.json()
    assert [x["route"] for x in doc["ranking"]] == ["beside", "over"]
    over = doc["ranking"][1]
    for level in (55.0, 65.0):
        rr = math.sqrt((40.0 * 10 ** ((G0 - level) / 20)) ** 2 - (HEIGHT - HR) ** 2)
        assert over["people_above"][f"{level:g}"] == pytest.approx(0.01 * 200 * 2 * min(rr, 100.0), rel=0.01)
    tif = client.post("/routes/compare", json={**body, "output": "difference"})
    assert tif.status_code == 200 and tif.headers["content-type"].startswith("image/tiff")


def test_compare_refusals_name_the_field(make_client, tmp_path):
    client = make_client()
    upload(client, "population", "town", "pop.tif", population_tif(tmp_path / "pop.tif"))
    base = {"routes": [route_csv(0.0), route_csv(400.0)], "cards": [OMNI], "population": "town",
            "ground_h_m": 0.0, "grid": {"resolution_m": 10.0, "margin_m": 150.0}}
    assert_names_field(client.post("/routes/compare", json={**base, "population": "nope"}), 404, "population")
    assert_names_field(client.post("/routes/compare", json={**base, "population": None}), 422, "population")
    assert_names_field(client.post("/routes/compare", json={**base, "buildings": "town"}), 422, "buildings")
    assert_names_field(client.post("/routes/compare", json={**base, "grid": {"resolution_m": 0.5}}), 413,
                       "grid.resolution_m")
    garbage = {"format": "log", "name": "x.ulg", "data_base64": "AAAAAAAA"}
    body = assert_names_field(client.post("/routes/compare", json={**base, "routes": [route_csv(0.0), garbage]}),
                              422, "routes[1].data_base64")
    assert "x.ulg" in body["detail"] and "trajectory" not in body["field"]
    body = assert_names_field(client.post("/routes/compare", json={**base, "levels": [-1000, 55]}), 422, "levels.0")
    assert "[-50, 200] dB(A)" in body["detail"]
    assert_names_field(upload(client, "population", "bad id", "pop.tif", b"x"), 422, "id")
    assert_names_field(upload(client, "population", "t2", "pop.tif", b"not a tiff"), 422, "file")
    assert client.get("/layers").json() == [{"id": "town", "version": 1, "kind": "population", "file": "pop.tif"}]


def test_rejected_layer_uploads_name_the_file_only_and_store_nothing(make_client, tmp_path):
    """A layer the core's readers refuse is 422 on ``file`` naming the uploaded file by its name, never by the
    server's temporary folder (it said 'cannot read layer-7d2kbgpp/f/garbage.tif'); a population raster with an
    infinite cell is refused (it was stored, the cell counted as 0 people)."""
    client = make_client()
    a = np.ones((20, 20), dtype=np.float32)
    a[2, 5] = np.inf
    with rasterio.open(tmp_path / "pop_inf.tif", "w", driver="GTiff", width=20, height=20, count=1, dtype="float32",
                       crs=CRS.from_user_input(TMERC).to_wkt(), transform=Affine(10.0, 0, -100, 0, -10.0, 100)) as d:
        d.write(a, 1)
    cases = [("population", "garbage.tif", b"not a tiff at all"),
             ("buildings", "garbage.geojson", b"not json at all"),
             ("population", "pop_inf.tif", (tmp_path / "pop_inf.tif").read_bytes())]
    for kind, name, data in cases:
        body = assert_names_field(upload(client, kind, "x", name, data), 422, "file")
        assert name in body["detail"], body
        assert "/" not in body["detail"], body  # no folder of the server, relative or absolute
        assert "layer-" not in body["detail"], body
    said = upload(client, "population", "x", "pop_inf.tif", cases[2][2]).json()["detail"]
    assert "first inf at row 2, column 5" in said
    assert client.get("/layers").json() == []


def town_tif(path: Path) -> bytes:
    """5 km x 4 km at 20 m: 0.2 people per cell, 8 in the 600 m block at the centre."""
    x = -2500.0 + 20.0 * (np.arange(250) + 0.5)
    y = 2000.0 - 20.0 * (np.arange(200) + 0.5)
    xx, yy = np.meshgrid(x, y)
    people = np.where((np.abs(xx) < 300) & (np.abs(yy) < 300), 8.0, 0.2).astype(np.float32)
    with rasterio.open(path, "w", driver="GTiff", width=250, height=200, count=1, dtype="float32",
                       crs=CRS.from_user_input(TMERC).to_wkt(), transform=Affine(20.0, 0, -2500, 0, -20.0, 2000)) as d:
        d.write(people, 1)
    return path.read_bytes()


def test_optimize_goes_around_the_block(make_client, tmp_path):
    client = make_client()
    assert upload(client, "population", "town", "pop.tif", town_tif(tmp_path / "t.tif")).status_code == 201
    card = {**OMNI, "phases": ["climb", "sink", "hover", "transition"],
            "parameters": {**OMNI["parameters"], "p1": 0.0}}
    lat_s, lon_s, _ = FRAME.to_wgs84(-1500.0, 0.0, 0.0)
    lat_g, lon_g, _ = FRAME.to_wgs84(1500.0, 0.0, 0.0)
    body = {"start": [float(lon_s), float(lat_s)], "goal": [float(lon_g), float(lat_g)], "cards": [card],
            "population": "town", "max_detour_pct": 25.0}
    r = client.post("/routes/optimize", json=body)
    assert r.status_code == 200, r.text
    doc = r.json()
    assert doc["summary"]["reduction_pct"] > 75.0
    assert doc["summary"]["optimized_length_m"] <= 1.25 * doc["summary"]["direct_length_m"] + 1e-6
    assert doc["route"]["features"][0]["properties"]["alt"] == 0.0
    assert_names_field(client.post("/routes/optimize", json={**body, "resolution_m": 5.0, "max_detour_pct": 300.0,
                                                              "goal": [11.5, 53.0]}), 413, "resolution_m")
    assert_names_field(client.post("/routes/optimize", json={**body, "avoid": {"type": "Point"}}), 422, "avoid")
    # pads closer than 4 turn radii: the request's fields start and goal, not the command line's --from/--to
    near = assert_names_field(client.post("/routes/optimize", json={**body, "goal": body["start"]}), 422, "goal")
    assert near["detail"].startswith("start and goal are 0 m apart;") and "--" not in near["detail"], near


def test_nodata_and_density_rasters_are_said_in_the_answers(make_client, tmp_path):
    """A population layer holding nodata east of x = 200 m (a raster ending at a border): a route 400 m east runs
    over no data, so its counts are lower bounds and the answer's warnings say so, as for a raster ending there.  A
    raster of 20 000 people in one 10 m cell (a density taken as people per cell) is refused on ``file``; one of 4 000
    (over a hectare: 400 000 per km^2) is stored with a warning in the upload's answer."""
    client = make_client()
    x = -1000.0 + 10.0 * (np.arange(200) + 0.5)
    strip = np.where(x[None, :] > 200.0, -99999.0, np.ones((200, 200)))

    def tif(name, values, nodata=-99999.0):
        with rasterio.open(tmp_path / name, "w", driver="GTiff", width=values.shape[1], height=values.shape[0],
                           count=1, dtype="float32", crs=CRS.from_user_input(TMERC).to_wkt(), nodata=nodata,
                           transform=Affine(10.0, 0, -1000, 0, -10.0, 1000)) as d:
            d.write(values.astype(np.float32), 1)
        return (tmp_path / name).read_bytes()

    assert upload(client, "population", "border", "strip.tif", tif("strip.tif", strip)).status_code == 201
    body = {"routes": [route_csv(0.0), route_csv(400.0)], "names": ["over", "beside"], "cards": [OMNI],
            "population": "border", "ground_h_m": 0.0, "grid": {"resolution_m": 10.0, "margin_m": 150.0}}
    r = client.post("/routes/compare", json=body)
    assert r.status_code == 200, r.text
    doc = r.json()
    beside = next(x for x in doc["ranking"] if x["route"] == "beside")
    assert beside["population_uncovered_share"] > 0.4 and beside["lower_bound"]["55"]  # the grid: 150 m about both
    assert any(w.startswith("beside: the population raster (strip.tif) does not cover") for w in doc["warnings"])
    dense = np.zeros((200, 200))
    dense[100, 100] = 20000.0
    said = assert_names_field(upload(client, "population", "d", "dense.tif", tif("dense.tif", dense)), 422, "file")
    assert "dense.tif" in said["detail"] and "looks like a density" in said["detail"]
    dense[100, 100] = 4000.0
    ok = upload(client, "population", "d", "thin.tif", tif("thin.tif", dense))
    assert ok.status_code == 201 and len(ok.json()["warnings"]) == 1 and "density" in ok.json()["warnings"][0]
