"""What the algorithms say: warnings as warnings, and the core's names of fields as the user's parameters."""

import pytest
from conftest import CARDS, REPO, recording_feedback, run_map

pytestmark = pytest.mark.qgis

ROUTE = REPO / "gisnoise" / "data" / "routes" / "delivery_route.geojson"
DEMO = [str(CARDS / f"demo_{p}.json") for p in ("horizontal", "climb", "sink")]


def cli_warnings(cli, *args):
    """The warnings the command line prints (stderr ``warning: ...``), in order."""
    r = cli(*args)
    return [line[len("warning: "):] for line in r.stderr.splitlines() if line.startswith("warning: ")]


def test_the_command_lines_warnings_are_warnings_not_errors(plugin, cli, tmp_path):
    """The delivery route on a 500 m margin: the power outside a card's range, LAmax and SEL contours clipped.
    Each is pushed as a warning (nothing reported as an error), naming MARGIN where it advises a wider margin."""
    expected = cli_warnings(cli, "contour", ROUTE, *sum((["--card", c] for c in DEMO), []),
                            "--resolution", "20", "--margin", "500", "--out", tmp_path / "cli")
    assert len(expected) == 3
    said = recording_feedback()
    import processing

    processing.run("gisnoise:noisemap", {
        "TRAJECTORY_FILE": str(ROUTE), "CARDS": DEMO, "RESOLUTION": 20.0, "MARGIN": 500.0,
        "OUTPUT_RASTER": str(tmp_path / "grid.tif"), "OUTPUT_BANDS": str(tmp_path / "bands.gpkg")}, feedback=said)
    assert said.errors == []
    assert [w.replace(" (parameter MARGIN)", "") for w in said.warnings] == expected
    assert all("(parameter MARGIN)" in w for w in said.warnings if "margin" in w)


def test_a_file_that_is_not_a_card_names_cards(plugin, flight_csv, tmp_path):
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException) as err:
        run_map(tmp_path, "map", TRAJECTORY_FILE=str(flight_csv), CARDS=[str(flight_csv)])
    msg = str(err.value)
    assert "malformed JSON" in msg and "(parameter CARDS: model cards are JSON files)" in msg
    assert "field 'json'" not in msg


def test_an_oversized_grid_names_resolution(plugin, flight_csv, tmp_path):
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException) as err:
        run_map(tmp_path, "map", TRAJECTORY_FILE=str(flight_csv), RESOLUTION=0.05, MARGIN=2000.0)
    msg = str(err.value)
    assert msg.startswith("parameter RESOLUTION: a grid of ") and "resolution_m" not in msg


def test_an_unknown_ground_names_the_parameters(plugin, flight_csv, tmp_path):
    """A flight in the air throughout without GROUND_HEIGHT: the core's advice (--ground-height M, --dem) in the
    algorithm's parameters."""
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException) as err:
        run_map(tmp_path, "map", TRAJECTORY_FILE=str(flight_csv), GROUND_HEIGHT=None)
    msg = str(err.value)
    assert "ground unknown" in msg and "parameter GROUND_HEIGHT" in msg and "parameter DEM" in msg
    assert "--" not in msg and "ground_h" not in msg
