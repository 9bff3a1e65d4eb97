"""Powers outside a card's stated power range on a map: a card without power term is refused there (CLI exit 2,
service 422, naming power_w); a card with a power term extrapolates, with a warning and metadata."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame
from gisnoise.model import ModelCard, holds_at_power_flown, power_range_findings, save

FRAME = LocalFrame(52.27, 10.52, 0.0)
PARAMS = dict(p0=64.0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0)


def _flyover(tmp_path, power_w, name="fly.csv"):
    """A level pass at 60 m above ground at 0 m, eastbound at 15 m/s."""
    t = np.arange(0.0, 40.0 + 1e-9, 0.5)
    lat, lon, h = FRAME.to_wgs84(15.0 * t - 300.0, 0 * t, 0 * t + 60.0)
    tr = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t + 90.0,
                    power_w=np.full(t.size, float(power_w)), phase=np.full(t.size, "horizontal"))
    tr.to_csv(tmp_path / name)
    return str(tmp_path / name)


def _steady_card(tmp_path):
    c = ModelCard(id="steady", vehicle="v", phase="horizontal", ansatz="paper-offset",
                  parameters=dict(PARAMS, p1=0.0), reference_power_w=3000.0,
                  statistics={"power_range_w": [2400.0, 2400.0]},
                  provenance={"held_parameters": {"p1": "steady power: held at 0"}})
    return c, str(save(c, tmp_path / "steady.json"))


def _fitted_card(tmp_path):
    c = ModelCard(id="fitted", vehicle="v", phase="horizontal", ansatz="paper-offset", parameters=PARAMS,
                  reference_power_w=3000.0, statistics={"power_range_w": [2000.0, 2600.0]})
    return c, str(save(c, tmp_path / "fitted.json"))


def run(*args):
    return CliRunner().invoke(cli, ["-q", *args], catch_exceptions=False)


def test_the_rule_on_its_own():
    steady = ModelCard(id="s", vehicle="v", phase="horizontal", ansatz="paper-offset", parameters=dict(PARAMS, p1=0.0),
                       reference_power_w=3000.0, statistics={"power_range_w": [2400.0, 2400.0]})
    assert holds_at_power_flown(steady)
    # within 0.02 dex (the fitter's steady-power threshold): 2400 W x 10^0.02 = 2513 W
    assert power_range_findings(steady, [2400.0, 2510.0]) == (None, None)
    refuse, _ = power_range_findings(steady, [2400.0, 2520.0])
    assert refuse is not None and "(2400-2400 W" in refuse and "at 2400-2520 W (1 flying sample(s)" in refuse
    fitted = ModelCard(id="f", vehicle="v", phase="horizontal", ansatz="paper-offset", parameters=PARAMS,
                       reference_power_w=3000.0, statistics={"power_range_w": [2000.0, 2600.0]})
    assert not holds_at_power_flown(fitted)
    refuse, warn = power_range_findings(fitted, [2500.0, 3000.0])
    assert refuse is None and "used at 2500-3000 W: 1 flying sample(s) outside the 2000-2600 W" in warn
    assert power_range_findings(ModelCard(id="n", vehicle="v", phase="horizontal", ansatz="paper-offset",
                                          parameters=PARAMS, reference_power_w=3000.0), [9e4]) == (None, None)


def test_card_without_power_term_maps_at_its_power_and_is_refused_at_another(tmp_path):
    _, card = _steady_card(tmp_path)
    ok = run("contour", _flyover(tmp_path, 2400.0), "--card", card, "--out", str(tmp_path / "ok"),
             "--ground-height", "0", "--resolution", "20", "--margin", "200")
    assert ok.exit_code == 0, ok.output
    # at its power the map is the card's level: straight below at 58.5 m, 64 - 20 log10(58.5/40) = 60.70 dB(A)
    with rasterio.open(tmp_path / "ok" / "levels.tif") as ds:
        lamax = ds.read(list(ds.descriptions).index("LAmax") + 1)
    assert float(np.nanmax(lamax)) == pytest.approx(64.0 - 20.0 * np.log10(58.5 / 40.0), abs=0.05)
    bad = run("contour", _flyover(tmp_path, 3000.0, "fast.csv"), "--card", card, "--out", str(tmp_path / "bad"),
              "--ground-height", "0", "--resolution", "20", "--margin", "200")
    assert bad.exit_code == 2
    assert "power_w" in bad.output and "2400-2400 W" in bad.output and len(bad.output.strip().splitlines()) == 1
    assert not (tmp_path / "bad").exists()


def test_card_with_power_term_outside_its_range_warns_and_states_it(tmp_path):
    _, card = _fitted_card(tmp_path)
    r = run("contour", _flyover(tmp_path, 3000.0), "--card", card, "--out", str(tmp_path / "m"),
            "--ground-height", "0", "--resolution", "20", "--margin", "200")
    assert r.exit_code == 0, r.output
    assert "card 'fitted' is used at 3000-3000 W: 81 flying sample(s) outside the 2000-2600 W" in r.stderr
    with rasterio.open(tmp_path / "m" / "levels.tif") as ds:
        meta = json.loads(ds.tags()["gisnoise"])
    assert meta["power_outside_card_range"] == {"fitted": {"range_w": [2000.0, 2600.0], "used_w": [3000.0, 3000.0],
                                                           "samples": 81}}


def test_a_track_partly_outside_the_range_counts_the_samples_outside():
    """40 samples at 2400 W (inside 2000-2600 W) and 41 at 3000 W: the warning and the metadata both count 41."""
    from gisnoise.maps import CardSet, check_power_ranges

    card = ModelCard(id="fitted", vehicle="v", phase="horizontal", ansatz="paper-offset", parameters=PARAMS,
                     reference_power_w=3000.0, statistics={"power_range_w": [2000.0, 2600.0]})
    t = np.arange(0.0, 40.0 + 1e-9, 0.5)
    lat, lon, h = FRAME.to_wgs84(15.0 * t - 300.0, 0 * t, 0 * t + 60.0)
    tr = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t + 90.0,
                    power_w=np.where(t < 20.0, 2400.0, 3000.0), phase=np.full(t.size, "horizontal"))
    warnings, meta = check_power_ranges(tr, CardSet([card]))
    assert len(warnings) == 1 and "used at 2400-3000 W: 41 flying sample(s) outside" in warnings[0]
    assert meta == {"fitted": {"range_w": [2000.0, 2600.0], "used_w": [2400.0, 3000.0], "samples": 41}}
