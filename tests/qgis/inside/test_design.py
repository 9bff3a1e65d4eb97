"""Optimize a measurement layout through processing.run on the sample plan (small optimizer settings)."""

import json

import pytest
from conftest import REPO

pytestmark = pytest.mark.qgis


@pytest.fixture(scope="module")
def small_plan(tmp_path_factory):
    """The paper's racetrack plan with a small optimizer and without study and verification."""
    doc = json.loads((REPO / "sample_data" / "plans" / "paper_racetrack.json").read_text(encoding="utf-8"))
    doc["optimizer"] = {**doc["optimizer"], "popsize": 6, "maxiter": 8}
    doc["objectives"] = ["paper"]
    doc.pop("study", None)
    doc["verify"] = {"seeds": 0}
    doc["card"] = str(REPO / "gisnoise" / "data" / "cards" / "demo_horizontal.json")
    path = tmp_path_factory.mktemp("plan") / "plan.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path, doc


def test_design_layout_moves_microphones_within_their_limits(plugin, small_plan, tmp_path):
    import processing
    from qgis.core import QgsVectorLayer

    path, doc = small_plan
    res = processing.run("gisnoise:designlayout", {
        "PLAN": str(path), "REPORT": False, "OUTPUT_FOLDER": str(tmp_path / "design"),
        "OUTPUT_MICS": str(tmp_path / "mics.gpkg"), "OUTPUT_TRACKS": str(tmp_path / "tracks.gpkg")})
    result = json.loads((tmp_path / "design" / "design.json").read_text(encoding="utf-8"))
    # the base design is in the initial population: the optimum is never worse
    assert 0.0 <= res["PAPER_OPTIMUM"] <= res["PAPER_BASE"] <= 1.0
    assert res["PAPER_OPTIMUM"] == pytest.approx(result["optima"]["paper"]["value"])
    mics = QgsVectorLayer(str(tmp_path / "mics.gpkg"), "m", "ogr")
    by_design = {}
    for f in mics.getFeatures():
        by_design.setdefault(f["design"], {})[f["id"]] = f
    assert set(by_design) == {"base", "paper"}
    plan_mics = {m["id"]: m for m in doc["microphones"]}
    assert set(by_design["base"]) == set(by_design["paper"]) == set(plan_mics)
    for mid, m in plan_mics.items():
        base, best = by_design["base"][mid], by_design["paper"][mid]
        assert (base["e_m"], base["n_m"]) == pytest.approx((m["e"], m["n"]))
        assert abs(best["de_m"]) <= m["max_shift_m"] + 1e-6 and abs(best["dn_m"]) <= m["max_shift_m"] + 1e-6
    tracks = QgsVectorLayer(str(tmp_path / "tracks.gpkg"), "t", "ogr")
    assert sorted(f["design"] for f in tracks.getFeatures()) == ["base", "paper"]
    for f in tracks.getFeatures():
        heights = [v.z() for v in f.geometry().vertices()]
        lo = min(a["min_m"] for a in doc["altitudes"]) + doc["origin"]["h"]
        hi = max(a["max_m"] for a in doc["altitudes"]) + doc["origin"]["h"]
        assert lo - 1.0 <= min(heights) and max(heights) <= hi + 1.0
