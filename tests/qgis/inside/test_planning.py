"""Route planners through processing.run: candidate routes compared, a quieter route around a dense block."""

import json
import math

import numpy as np
import pytest
from conftest import CARDS, recording_feedback

pytestmark = pytest.mark.qgis

LAT0, LON0 = 52.27, 10.52
BLOCK = 300.0
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def _lonlat(e, n):
    from pyproj import Transformer

    tr = Transformer.from_crs(TMERC, "EPSG:4326", always_xy=True)
    return tr.transform(e, n)


@pytest.fixture(scope="module")
def town(tmp_path_factory):
    """A 5 km x 4 km population raster: 0.2 people per 20 m cell, 8 in the 600 m block at the centre."""
    import rasterio
    from affine import Affine

    d = tmp_path_factory.mktemp("town")
    x = -2500.0 + 20.0 * (np.arange(250) + 0.5)
    y = 2000.0 - 20.0 * (np.arange(200) + 0.5)
    xx, yy = np.meshgrid(x, y)
    people = np.where((np.abs(xx) < BLOCK) & (np.abs(yy) < BLOCK), 8.0, 0.2).astype(np.float32)
    with rasterio.open(d / "pop.tif", "w", driver="GTiff", width=250, height=200, count=1, dtype="float32",
                       crs=TMERC, transform=Affine(20.0, 0, -2500.0, 0, -20.0, 2000.0)) as dst:
        dst.write(people, 1)
    return d


def _route(path, e_mid):
    """Waypoints: take-off at e = -1500, cruise at 60 m through (e_mid, n), landing at e = 1500."""
    pts = [(-1500.0, 0.0, 0), (-1500.0, 0.0, 60), (0.0, e_mid, 60), (1500.0, 0.0, 60), (1500.0, 0.0, 0)]
    feats = []
    for e, n, alt in pts:
        lon, lat = _lonlat(e, n)
        feats.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat, alt]},
                      "properties": {"alt": alt}})
    path.write_text(json.dumps({"type": "FeatureCollection", "route": {"altitude_reference": "agl",
                                                                       "ground_h_m": 0.0},
                                "features": feats}))
    return str(path)


def test_compare_ranks_the_route_around_the_block_first(plugin, town, tmp_path):
    import processing

    over = _route(tmp_path / "over.geojson", 0.0)
    around = _route(tmp_path / "around.geojson", 900.0)
    cards = ",".join(str(CARDS / f"demo_{p}.json") for p in ("horizontal", "climb", "sink"))
    res = processing.run("gisnoise:compareroutes", {
        "ROUTES": [over, around], "CARDS": cards, "POPULATION": str(town / "pop.tif"), "METRIC": 0,
        "RANK_LEVEL": 55.0, "RESOLUTION": 40.0, "OUTPUT_FOLDER": str(tmp_path / "cmp")})
    assert res["BEST"] == "around"
    doc = json.loads((tmp_path / "cmp" / "comparison.json").read_text())
    rows = {r["route"]: r for r in doc["ranking"]}
    assert rows["over"]["people_above"]["55"] > 2 * rows["around"]["people_above"]["55"]
    assert (tmp_path / "cmp" / "difference.tif").is_file()


def test_quieter_route_goes_around_the_block(plugin, town, tmp_path):
    """... and says in the log what the comparison warns (here: the default vehicle flies outside the demo cards'
    fitted powers), each warning once."""
    import processing

    said = recording_feedback()
    s_lon, s_lat = _lonlat(-1500.0, 0.0)
    g_lon, g_lat = _lonlat(1500.0, 0.0)
    cards = ",".join(str(CARDS / f"demo_{p}.json") for p in ("horizontal", "climb", "sink"))
    res = processing.run("gisnoise:quieterroute", {
        "START": f"{s_lon},{s_lat} [EPSG:4326]", "GOAL": f"{g_lon},{g_lat} [EPSG:4326]", "CARDS": cards,
        "POPULATION": str(town / "pop.tif"), "ALTITUDE": 60.0, "MAX_DETOUR": 25.0, "RESOLUTION": 50.0,
        "OUTPUT_FOLDER": str(tmp_path / "opt")}, feedback=said)
    warned = json.loads((tmp_path / "opt" / "comparison.json").read_text())["warnings"]
    assert warned and said.errors == [f"warning: {w}" for w in warned]
    summary = json.loads((tmp_path / "opt" / "optimize.json").read_text())
    assert res["REDUCTION_PCT"] == pytest.approx(summary["reduction_pct"])
    assert summary["reduction_pct"] > 50.0
    assert summary["optimized_length_m"] <= 1.25 * summary["direct_length_m"] + 1e-6
    assert not math.isnan(summary["turn_radius_m"])


def test_compare_takes_a_ground_height_for_routes_in_the_air(plugin, town, tmp_path):
    """Candidate flight CSVs in the air throughout need the ground (as on the command line, --ground-height): without
    it the algorithm stops naming ground_h_m; with GROUND_HEIGHT it ranks them."""
    import processing
    from qgis.core import QgsProcessingException

    cards = ",".join(str(CARDS / f"demo_{p}.json") for p in ("horizontal", "climb", "sink"))
    paths = []
    for name, n in (("over", 0.0), ("around", 900.0)):
        lines = ["t,lat,lon,h,roll,pitch,yaw,power_w,phase"]
        for i in range(151):
            lon, lat = _lonlat(-1500.0 + 20.0 * i, n)
            lines.append(f"{i:.1f},{lat:.9f},{lon:.9f},60.0,0,0,90,3000,horizontal")
        p = tmp_path / f"{name}.csv"
        p.write_text("\n".join(lines) + "\n")
        paths.append(str(p))
    params = {"ROUTES": paths, "CARDS": cards, "POPULATION": str(town / "pop.tif"), "METRIC": 0, "RANK_LEVEL": 55.0,
              "RESOLUTION": 40.0, "OUTPUT_FOLDER": str(tmp_path / "cmp")}
    with pytest.raises(QgsProcessingException, match="ground_h_m"):
        processing.run("gisnoise:compareroutes", params)
    res = processing.run("gisnoise:compareroutes", {**params, "GROUND_HEIGHT": 0.0})
    assert res["BEST"] == "around"
