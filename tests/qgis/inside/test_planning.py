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
    fitted powers), each warning once and as a warning, not an error."""
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
    assert warned and said.warnings == warned and said.errors == []
    summary = json.loads((tmp_path / "opt" / "optimize.json").read_text())
    assert res["REDUCTION_PCT"] == pytest.approx(summary["reduction_pct"])
    assert summary["reduction_pct"] > 50.0
    assert summary["optimized_length_m"] <= 1.25 * summary["direct_length_m"] + 1e-6
    assert not math.isnan(summary["turn_radius_m"])


def test_compare_takes_a_ground_height_for_routes_in_the_air(plugin, town, tmp_path):
    """Candidate flight CSVs in the air throughout need the ground (as on the command line, --ground-height): without
    it the algorithm stops naming GROUND_HEIGHT (not the command line's option or the core's field); with it, it
    ranks them."""
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
    with pytest.raises(QgsProcessingException, match="parameter GROUND_HEIGHT") as err:
        processing.run("gisnoise:compareroutes", params)
    assert "ground_h" not in str(err.value) and "--ground-height" not in str(err.value)
    res = processing.run("gisnoise:compareroutes", {**params, "GROUND_HEIGHT": 0.0})
    assert res["BEST"] == "around"


CARD_LIST = ",".join(str(CARDS / f"demo_{p}.json") for p in ("horizontal", "climb", "sink"))


@pytest.fixture(scope="module")
def candidates(tmp_path_factory):
    d = tmp_path_factory.mktemp("candidates")
    return [_route(d / "over.geojson", 0.0), _route(d / "around.geojson", 900.0)]


def _compare(town, routes, out, feedback=None, **params):
    import processing

    return processing.run("gisnoise:compareroutes", {
        "ROUTES": routes, "CARDS": CARD_LIST, "POPULATION": str(town / "pop.tif"), "RESOLUTION": 40.0,
        "OUTPUT_FOLDER": str(out), **params}, feedback=feedback)


def test_compare_defaults_are_the_command_lines(plugin, cli, town, candidates, tmp_path):
    """LEVELS and MARGIN left out: the same grid and counts as ``gisnoise compare`` with its defaults."""
    _compare(town, candidates, tmp_path / "qgis")
    cli("compare", *candidates, *sum((["--card", c] for c in CARD_LIST.split(",")), []), "--population",
        town / "pop.tif", "--resolution", "40", "--out", tmp_path / "cli",
        "--engine", "numpy")  # QGIS's Python has no numba: its "auto" is the NumPy engine (levels within 0.01 dB)
    a = json.loads((tmp_path / "qgis" / "comparison.json").read_text())
    b = json.loads((tmp_path / "cli" / "comparison.json").read_text())
    assert a["levels_db"] == b["levels_db"] == [45.0, 50.0, 55.0, 60.0, 65.0]
    assert a["grid"] == b["grid"]
    for ra, rb in zip(a["ranking"], b["ranking"], strict=True):
        assert ra["route"] == rb["route"]
        assert ra["people_above"] == pytest.approx(rb["people_above"], rel=1e-9)


def test_compare_margin_follows_its_own_advice(plugin, town, candidates, tmp_path):
    """On a 100 m margin the counts are cut by the grid's edge: the warning says so and names MARGIN; on a
    3 km margin the warning goes and no count is lower than its lower bound."""
    said = recording_feedback()
    _compare(town, candidates, tmp_path / "narrow", feedback=said, MARGIN=100.0)
    edge = [w for w in said.warnings if "grid's edge" in w]
    assert edge and all("a wider margin (parameter MARGIN)" in w for w in edge)
    wide = recording_feedback()
    _compare(town, candidates, tmp_path / "wide", feedback=wide, MARGIN=3000.0)
    assert not [w for w in wide.warnings if "grid's edge" in w]
    narrow = {r["route"]: r for r in json.loads((tmp_path / "narrow" / "comparison.json").read_text())["ranking"]}
    more = 0
    for r in json.loads((tmp_path / "wide" / "comparison.json").read_text())["ranking"]:
        for level, people in r["people_above"].items():
            assert people >= narrow[r["route"]]["people_above"][level] - 1e-9
            more += people > narrow[r["route"]]["people_above"][level] + 1.0
    assert more  # the narrow grid did cut people off


def test_compare_rank_level_must_be_one_of_the_levels(plugin, town, candidates, tmp_path):
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException) as err:
        _compare(town, candidates, tmp_path / "bad", RANK_LEVEL=57.0)
    msg = str(err.value)
    assert "RANK_LEVEL 57 dB(A) is not one of the levels (parameter LEVELS: 45, 50, 55, 60, 65)" in msg
    assert not (tmp_path / "bad" / "comparison.json").exists()
    res = _compare(town, candidates, tmp_path / "ok", RANK_LEVEL=57.0, LEVELS="45,50,57,60",
                   CRS="EPSG:25832")
    doc = json.loads((tmp_path / "ok" / "comparison.json").read_text())
    assert doc["levels_db"] == [45.0, 50.0, 57.0, 60.0] and doc["rank_level_db"] == 57.0
    assert "25832" in json.dumps(doc["grid"]) and res["BEST"] == "around"


def _cancel_at_first_progress():
    """A feedback that records what is said and cancels at the first progress the algorithm reports."""
    said = recording_feedback()
    said.progressChanged.connect(lambda _p: said.cancel())
    return said


@pytest.mark.parametrize("algorithm", ["compareroutes", "quieterroute"])
def test_planners_show_progress_and_stop_when_cancelled(plugin, town, candidates, tmp_path, algorithm):
    """Progress at each step the plugin drives and within the core's computation (rising, to 100 %); cancelled at
    the first, the algorithm stops before the core's computation, and cancelled within it, it stops there ("cancelled
    by the user"), writing no file either way."""
    import processing
    from qgis.core import QgsProcessingException

    s_lon, s_lat = _lonlat(-1500.0, 0.0)
    g_lon, g_lat = _lonlat(1500.0, 0.0)
    params = ({"ROUTES": candidates, "RESOLUTION": 40.0} if algorithm == "compareroutes" else
              {"START": f"{s_lon},{s_lat} [EPSG:4326]", "GOAL": f"{g_lon},{g_lat} [EPSG:4326]", "RESOLUTION": 50.0})
    params.update(CARDS=CARD_LIST, POPULATION=str(town / "pop.tif"))
    said = recording_feedback()
    processing.run(f"gisnoise:{algorithm}", {**params, "OUTPUT_FOLDER": str(tmp_path / "run")}, feedback=said)
    assert len(set(said.progress)) >= 4 and said.progress == sorted(said.progress)
    assert said.progress[-1] == pytest.approx(100.0)

    cancelled = _cancel_at_first_progress()
    with pytest.raises(QgsProcessingException, match="cancelled by the user"):
        processing.run(f"gisnoise:{algorithm}", {**params, "OUTPUT_FOLDER": str(tmp_path / "cancelled")},
                       feedback=cancelled)
    assert not [i for i in cancelled.infos if "comparing" in i or "searching" in i]  # the core's step never began
    left = tmp_path / "cancelled"
    assert not left.exists() or not any(left.iterdir())
    # within the core's computation (10-90 %) the bar moves, and a cancel there stops it too
    assert any(10.0 < p < 90.0 for p in said.progress)
    inside = recording_feedback()
    inside.progressChanged.connect(lambda p: inside.cancel() if 10.0 < p < 90.0 else None)
    with pytest.raises(QgsProcessingException, match="cancelled by the user"):
        processing.run(f"gisnoise:{algorithm}", {**params, "OUTPUT_FOLDER": str(tmp_path / "inside")},
                       feedback=inside)
    assert [i for i in inside.infos if "comparing" in i or "searching" in i]  # the core's step had begun
    assert max(inside.progress) < 90.0
    left = tmp_path / "inside"
    assert not left.exists() or not any(left.iterdir())


def test_compare_laeq_takes_one_period_named_period(plugin, town, candidates, tmp_path):
    """PERIOD, as --period: LAeq over one averaging period for every route; for LAmax, which has none, refused
    naming PERIOD (not the core's period_s)."""
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException) as err:
        _compare(town, candidates, tmp_path / "lamax", METRIC=0, PERIOD=600.0)
    assert "parameter PERIOD" in str(err.value) and "period_s" not in str(err.value)
    _compare(town, candidates, tmp_path / "laeq", METRIC=1, PERIOD=600.0)
    doc = json.loads((tmp_path / "laeq" / "comparison.json").read_text())
    assert doc["metric"] == "LAeq" and doc["period_s"] == 600.0
