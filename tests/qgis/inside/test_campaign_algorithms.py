"""Fit and diagnose through processing.run on simulated campaigns with a known truth."""

import json

import pytest
from conftest import REPO, recording_feedback

pytestmark = pytest.mark.qgis

SCENARIOS = REPO / "sample_data" / "scenarios"
SAMPLE_CAMPAIGN = REPO / "sample_data" / "campaign"


def truth_card(campaign, tmp_path):
    """The horizontal card the campaign was simulated with (from its truth.json), as a file."""
    from gisnoise.model import cards

    doc = json.loads((campaign / "truth.json").read_text(encoding="utf-8"))["cards"]["horizontal"]
    return cards.save(cards.from_dict(doc), tmp_path / "truth_horizontal.json")


@pytest.fixture(scope="module")
def control_campaign(cli, tmp_path_factory):
    """Two short flights, no unmodelled effect injected: the truth is the demo card."""
    out = tmp_path_factory.mktemp("control") / "campaign"
    cli("simulate", SCENARIOS / "diagnosis_base.json", "--out", out)
    return out


@pytest.fixture(scope="module")
def control_fit(plugin, control_campaign, tmp_path_factory):
    import processing

    card = tmp_path_factory.mktemp("fit") / "card.json"
    res = processing.run("gisnoise:fitcard", {"CAMPAIGN": str(control_campaign), "PHASE": 0,
                                              "ANSATZ": "paper-offset", "OUTPUT_CARD": str(card),
                                              "OUTPUT_REPORT": str(card.parent / "report")})
    return res, card


def test_fit_recovers_the_simulated_truth(control_fit, control_campaign, tmp_path):
    from gisnoise.model import cards

    res, path = control_fit
    card, truth = cards.load(path), cards.load(truth_card(control_campaign, tmp_path))
    assert card.phase == "horizontal" and card.ansatz == truth.ansatz
    for name, value in truth.parameters.items():
        assert abs(card.parameters[name] - value) < 4.0 * card.std[name], name
    assert res["N_SAMPLES"] == card.statistics["n_samples"] > 1000
    assert res["RMS_DB"] == pytest.approx(card.statistics["rms_db"])
    # the simulated microphones' noise is 0.8-1.2 dB, so the residual cannot be much smaller or larger
    assert 0.6 < res["RMS_DB"] < 2.0
    assert res["CARD_ID"] == card.id
    assert (path.parent / "report" / "report.html").is_file()


def test_fit_and_diagnose_say_what_the_command_line_says_about_the_flights(plugin, control_campaign, tmp_path):
    """One sample of a flight CSV moved 1.1 km north (a position glitch, mended on reading): both algorithms
    report the line campaign check prints, once and as a warning, before they fit or diagnose."""
    import shutil

    import processing

    from gisnoise.measure import campaign_log_warnings, read_campaign

    camp = tmp_path / "campaign"
    shutil.copytree(control_campaign, camp)
    flight = sorted((camp / "flights").glob("*.csv"))[0]
    lines = flight.read_text().splitlines()
    col = lines[0].split(",").index("lat")
    row = lines[len(lines) // 2].split(",")
    row[col] = repr(float(row[col]) + 0.01)
    lines[len(lines) // 2] = ",".join(row)
    flight.write_text("\n".join(lines) + "\n")
    expected = campaign_log_warnings(read_campaign(camp))
    assert len(expected) == 1 and str(flight) in expected[0] and "position glitch" in expected[0]
    said = recording_feedback()
    processing.run("gisnoise:fitcard", {"CAMPAIGN": str(camp), "PHASE": 0, "ANSATZ": "paper-offset",
                                        "OUTPUT_CARD": str(tmp_path / "card.json")}, feedback=said)
    assert said.warnings == expected and said.errors == []  # a warning, not an error
    said = recording_feedback()
    processing.run("gisnoise:diagnose", {"CAMPAIGN": str(camp), "CARD": str(truth_card(control_campaign, tmp_path)),
                                         "OUTPUT_JSON": str(tmp_path / "diagnosis.json")}, feedback=said)
    assert said.warnings == expected and said.errors == []  # a warning, not an error


def test_fit_of_a_folder_that_is_no_campaign_names_the_file(plugin, tmp_path):
    import processing
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException) as err:
        processing.run("gisnoise:fitcard", {"CAMPAIGN": str(tmp_path), "PHASE": 0,
                                            "OUTPUT_CARD": str(tmp_path / "card.json")})
    assert "campaign.json" in str(err.value)


def test_diagnose_names_bank_angle_and_maps_the_flagged_segments(plugin, tmp_path):
    """The sample campaign has turning-flight noise (3 dB at 30 deg bank) injected in the turns."""
    import processing
    from qgis.core import QgsVectorLayer

    from gisnoise.measure import read_campaign

    res = processing.run("gisnoise:diagnose", {
        "CAMPAIGN": str(SAMPLE_CAMPAIGN), "CARD": str(truth_card(SAMPLE_CAMPAIGN, tmp_path)), "OUTPUT_JSON": str(tmp_path / "diagnosis.json"),
        "OUTPUT_SEGMENTS": str(tmp_path / "segments.gpkg"), "OUTPUT_MICS": str(tmp_path / "mics.geojson"),
        "OUTPUT_REPORT": str(tmp_path / "report")})
    assert (tmp_path / "report" / "report.html").is_file()
    doc = json.loads((tmp_path / "diagnosis.json").read_text(encoding="utf-8"))
    assert res["VERDICT"] == doc["verdict"]["effect"] == "bank_angle"
    assert res["BASELINE_RMS_DB"] == pytest.approx(doc["baseline"]["rms_db"])
    segments = QgsVectorLayer(str(tmp_path / "segments.gpkg"), "s", "ogr")
    assert segments.featureCount() == len(doc["segments"]) > 0
    campaign = read_campaign(SAMPLE_CAMPAIGN)
    by_key = {(g["flight"], g["mic"], g["t0"]): g for g in doc["segments"]}
    for f in segments.getFeatures():
        seg = by_key[(f["flight"], f["mic"], f["t0"])]
        assert f["t1"] == seg["t1"] and f["rms_db"] == pytest.approx(seg["rms_db"])
        # the line runs along the flight track from t0 to t1
        line = f.geometry().constGet()
        state = campaign.trajectories[f["flight"]].interpolate([seg["t0"], seg["t1"]])
        for vertex, i in ((line.startPoint(), 0), (line.endPoint(), 1)):
            assert (vertex.x(), vertex.y(), vertex.z()) == pytest.approx(
                (state["lon"][i], state["lat"][i], state["h"][i]), abs=1e-7)
    mics = QgsVectorLayer(str(tmp_path / "mics.geojson"), "m", "ogr")
    assert sorted(f["id"] for f in mics.getFeatures()) == ["m1", "m2", "m3"]
