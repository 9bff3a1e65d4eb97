"""``gisnoise card import-hemisphere / show / plot / fit-hemisphere / sample-hemisphere`` and a contour map."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.model import HemisphereCard, cards, import_hemisphere

pytest.importorskip("openpyxl")

M300 = Path(__file__).parent / "data" / "hemispheres" / "Hem_Ed_M3_10_F05_Y_W_dw_2.xlsx"


def run(*args):
    return CliRunner().invoke(cli, ["-q", *args], catch_exceptions=False)


@pytest.fixture(scope="module")
def m300_json(tmp_path_factory):
    out = tmp_path_factory.mktemp("h") / "m300.json"
    r = run("card", "import-hemisphere", str(M300), "--out", str(out), "--id", "m300")
    assert r.exit_code == 0, r.output
    assert "135 nodes measured" in r.output
    return out


def test_import_writes_the_card_the_core_reads(m300_json):
    c = cards.load(m300_json)
    assert isinstance(c, HemisphereCard) and c.id == "m300"
    ref = import_hemisphere(M300, card_id="m300")
    np.testing.assert_array_equal(c.levels_db, ref.levels_db)


def test_show_summarises_power_and_loudest_direction(m300_json):
    r = run("card", "show", str(m300_json))
    assert r.exit_code == 0, r.output
    c = cards.load(m300_json)
    top = c.loudest_direction()
    assert f"max level {top['level_db_a']:.1f} dB(A)" in r.output
    assert f"phi {top['phi_t_deg']:g} deg (ahead)" in r.output  # -18.4 deg: ahead of the drone
    assert "135 of 273 nodes" in r.output
    assert f"sound power {c.sound_power_db()['overall_z']:.1f} dB" in r.output
    # the values an independent integration gives (tests/test_hemisphere_power.py); the file's 91.0 dB is the lower half
    assert "sound power 94.4 dB, 92.6 dB(A)" in r.output and "the lower half alone 91.4 dB" in r.output
    assert "the file states 91.0 dB for the lower half" in r.output and "coverage" not in r.output


def test_plot_draws_the_hemisphere(m300_json, tmp_path):
    pytest.importorskip("matplotlib")
    r = run("card", "plot", str(m300_json), "--distance", "10", "--out", str(tmp_path / "h.png"))
    assert r.exit_code == 0, r.output
    assert (tmp_path / "h.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_fit_and_sample_commands(m300_json, tmp_path):
    r = run("card", "fit-hemisphere", str(m300_json), "--out", str(tmp_path / "fit.json"))
    assert r.exit_code == 0, r.output
    fit = cards.load(tmp_path / "fit.json")
    assert f"residual RMS {fit.statistics['residual_rms_db']:.2f} dB" in r.output
    r = run("card", "sample-hemisphere", str(tmp_path / "fit.json"), "--out", str(tmp_path / "back.json"))
    assert r.exit_code == 0, r.output
    assert isinstance(cards.load(tmp_path / "back.json"), HemisphereCard)


def test_bad_input_exits_2_naming_the_field(tmp_path):
    bad = tmp_path / "h.csv"
    bad.write_text("band,phi_deg,theta_deg,level_db\n1000,0,0,60\n")
    r = CliRunner().invoke(cli, ["-q", "card", "import-hemisphere", str(bad), "--out", str(tmp_path / "x.json")])
    assert r.exit_code == 2
    assert "atmosphere" in r.output and not (tmp_path / "x.json").exists()
    doc = json.loads((Path(__file__).parents[1] / "gisnoise" / "data" / "cards" / "demo_horizontal.json").read_text())
    doc["schema"] = "gisnoise/hemisphere-card/1"
    (tmp_path / "h.json").write_text(json.dumps(doc))
    r = CliRunner().invoke(cli, ["-q", "card", "show", str(tmp_path / "h.json")])
    assert r.exit_code == 2 and "phi_deg" in r.output


def test_set_atmosphere_for_maps(m300_json, tmp_path):
    out = tmp_path / "cold.json"
    r = run("card", "set-atmosphere", str(m300_json), "--temperature", "5", "--humidity", "40", "--out", str(out))
    assert r.exit_code == 0, r.output
    c = cards.load(out)
    assert c.propagation_atmosphere["temperature_c"] == 5.0 and c.atmosphere["temperature_c"] == 25.0
    r = run("card", "show", str(out))
    assert "on maps   5 C, 40 % RH" in r.output


def _flyover_csv(path):
    from gisnoise.geo import LocalFrame

    t = np.arange(0.0, 40.1, 1.0)
    lat, lon, h = LocalFrame(52.0, 10.0, 0.0).to_wgs84(np.zeros(t.size), -100.0 + 5.0 * t, np.full(t.size, 10.0))
    rows = ["t,lat,lon,h,roll,pitch,yaw,power_w,phase"]
    rows += [f"{a},{b:.9f},{c:.9f},{d},0,0,0,1000,horizontal" for a, b, c, d in zip(t, lat, lon, h, strict=True)]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_contour_atmosphere_option(m300_json, tmp_path):
    """``contour --atmosphere``: the hemisphere card's absorption in that atmosphere; refused when it cannot apply."""
    rasterio = pytest.importorskip("rasterio")
    from gisnoise.maps import make_map

    traj = _flyover_csv(tmp_path / "fly.csv")
    common = ["--resolution", "20", "--margin", "300", "--ground-height", "0", "--metrics", "LAmax",
              "--engine", "numpy"]
    r = run("contour", str(traj), "--card", str(m300_json), "--out", str(tmp_path / "cold"), "--atmosphere", "0,10",
            *common)
    assert r.exit_code == 0, r.output
    card = cards.load(m300_json).in_atmosphere(0.0, 10.0)
    ref = make_map(str(traj), [card], tmp_path / "ref", resolution_m=20.0, margin_m=300.0, ground_h=0.0,
                   metrics=["LAmax"], engine="numpy")
    warm = make_map(str(traj), [str(m300_json)], tmp_path / "warm", resolution_m=20.0, margin_m=300.0, ground_h=0.0,
                    metrics=["LAmax"], engine="numpy")
    with rasterio.open(tmp_path / "cold" / "levels.tif") as a, rasterio.open(ref["levels"]) as b, \
            rasterio.open(warm["levels"]) as c:
        cold, same, default = a.read(1), b.read(1), c.read(1)
    np.testing.assert_allclose(cold, same, atol=1e-9)
    assert ref["result"].metadata["hemisphere_atmospheres"]["m300"] == {
        "temperature_c": 0.0, "humidity_pct": 10.0, "pressure_kpa": 101.325}
    # dry cold air (0 C, 10 % RH) absorbs the kHz bands more than the table's 25 C, 70 % (ISO 9613-1): quieter
    k = list(card.bands_hz).index(2000.0)
    assert card.absorption_db_m[k] > 1.5 * cards.load(m300_json).absorption_db_m[k]
    assert np.all(cold <= default + 1e-4) and np.nanmax(default - cold) > 0.5
    bad = run("contour", str(traj), "--card", str(m300_json), "--out", str(tmp_path / "x"), "--atmosphere", "20",
              *common)
    assert bad.exit_code == 2 and "atmosphere" in bad.output
    hot = run("contour", str(traj), "--card", str(m300_json), "--out", str(tmp_path / "y"), "--atmosphere",
              "90,50", *common)
    assert hot.exit_code == 2 and "map_atmosphere.temperature_c" in hot.output
    par = run("contour", str(traj), "--card", "demo-horizontal", "--out", str(tmp_path / "z"), "--atmosphere",
              "20,50", *common)
    assert par.exit_code == 2 and "atmosphere" in par.output


def test_an_existing_card_is_kept_and_the_refusal_names_force(m300_json, tmp_path):
    """Writing a card over an existing file is refused in one line that names --force; the file is unchanged."""
    out = tmp_path / "fit.json"
    out.write_text("{}")
    r = CliRunner().invoke(cli, ["-q", "card", "fit-hemisphere", str(m300_json), "--out", str(out)])
    assert r.exit_code == 2 and "--force" in r.output and len(r.output.strip().splitlines()) == 1
    assert out.read_text() == "{}"
    r = run("card", "fit-hemisphere", str(m300_json), "--out", str(out), "--force")
    assert r.exit_code == 0 and cards.load(out).ansatz == "paper-offset"


def test_diagnose_refuses_a_hemisphere_card_before_reading_the_campaign(m300_json, tmp_path):
    """``gisnoise diagnose --card HEMISPHERE`` is one usage error naming the card, before the campaign is read (the
    campaign folder here does not exist: the card is what is refused)."""
    r = CliRunner().invoke(cli, ["-q", "diagnose", str(tmp_path / "no-campaign"), "--card", str(m300_json),
                                 "--out", str(tmp_path / "out")])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "'m300' is a measured hemisphere" in lines[0], r.output
    assert not (tmp_path / "out").exists()

