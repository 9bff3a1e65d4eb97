"""The map's extent: the default grid closes the lowest level; a fixed margin flags what it cuts (issue 17)."""

import json
import math

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.data import card_path
from gisnoise.data import sample_route_path as sample_route
from gisnoise.flight import read_route
from gisnoise.maps import (
    SEL_OFFSET_DB,
    CardSet,
    audible_distance,
    auto_margin,
    level_table,
    make_map,
    sel_edge_bound,
    sel_margin,
)
from gisnoise.model import ModelCard

DEMO = ["demo-horizontal", "demo-climb", "demo-sink"]
DEMO_LEVELS = "45,50,55,60,65"


def omni(p6=1.0, g0=70.0):
    return ModelCard(id="omni", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=g0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=p6, p7=30.0),
                     reference_power_w=3000.0)


@pytest.mark.parametrize("p6", [1.0, 0.5, 1.3])
def test_audible_distance_is_the_spherical_spreading_distance(p6):
    # omnidirectional source at the reference power: L(d) = 70 - 20 p6 log10(d / 40 m)
    for level in (45.0, 55.0, 65.0):
        truth = 40.0 * 10.0 ** ((70.0 - level) / (20.0 * p6))
        d = audible_distance([omni(p6)], [3000.0], level)
        assert truth <= d <= truth * 1.05  # an upper bound, one table step (4.9 %) at most above


def test_audible_distance_grows_with_power_by_the_cards_power_law():
    # p1 = 20: doubling the power adds 20 log10(2) = 6.02 dB, i.e. doubles the distance (p6 = 1)
    d1 = audible_distance([omni()], [3000.0], 50.0)
    d2 = audible_distance([omni()], [6000.0], 50.0)
    assert d2 / d1 == pytest.approx(2.0, rel=0.06)
    assert audible_distance([omni()], [3000.0], 200.0) == 0.0


def levels_edges(path):
    with rasterio.open(path) as ds:
        out = {}
        for i, name in enumerate(ds.descriptions, start=1):
            a = ds.read(i)
            out[name] = np.concatenate([a[0], a[-1], a[:, 0], a[:, -1]])
        return out


def doc_power_warnings(warnings):
    """How many of a demo map's warnings say a demo card is flown outside the powers it was fitted at."""
    return sum("flying sample(s) outside the" in w for w in warnings)


def test_demo_default_extent_closes_the_lowest_level(tmp_path):
    """The demo (scripts/demo) without --margin: no edge cell at or above the lowest level of its metric:
    LAmax and LAeq below 45 dB(A), SEL below its lowest contour, 45 + 10 = 55 dB(A); nothing clipped, no extent
    warning."""
    pytest.importorskip("numba")
    r = CliRunner().invoke(cli, ["-q", "contour", str(sample_route()), *sum((["--card", c] for c in DEMO), []),
                                 "--out", str(tmp_path), "--resolution", "10", "--levels", DEMO_LEVELS,
                                 "--engine", "fast"],  # the reference engine's equal within 0.01 dB, faster
                           catch_exceptions=False)
    assert r.exit_code == 0, r.output
    edges = levels_edges(tmp_path / "levels.tif")
    assert edges["LAmax"].max() < 45.0
    assert edges["LAeq"].max() < 45.0
    assert edges["SEL"].max() < 45.0 + SEL_OFFSET_DB
    doc = json.loads((tmp_path / "contours.geojson").read_text())
    sel_levels = sorted({f["properties"]["level"] for f in doc["features"] if f["properties"]["metric"] == "SEL"})
    assert sel_levels == [55.0, 60.0, 65.0, 70.0, 75.0]
    for f in doc["features"]:
        assert f["properties"]["clipped"] is False
    # no warning but the one that says the route flies demo-horizontal below the sample campaign's powers while
    # it slows down
    # (README, "Powers a card was fitted at"; tests/test_cards_demo_power_range.py)
    warn = [line.removeprefix("warning: ") for line in r.output.splitlines() if line.startswith("warning:")]
    assert doc["gisnoise"]["warnings"] == warn and len(warn) == 1
    assert all("flying sample(s) outside the" in w for w in warn)


def test_a_forced_small_margin_flags_the_cut_contours_and_warns(tmp_path):
    r = CliRunner().invoke(cli, ["-q", "contour", str(sample_route()), *sum((["--card", c] for c in DEMO), []),
                                 "--out", str(tmp_path), "--resolution", "20", "--margin", "100", "--metrics", "LAmax",
                                 "--levels", "45,50,55,60,65,85"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    top = levels_edges(tmp_path / "levels.tif")["LAmax"].max()
    assert 65.0 <= top < 85.0
    warn = [line for line in r.output.splitlines() if line.startswith("warning:")]
    assert doc_power_warnings(warn) == 1     # the demo card's powers (test_demo_default_extent_...)
    warn_extent = [w for w in warn if "flying sample(s) outside the" not in w]
    assert len(warn_extent) == 1
    assert warn_extent[0].startswith("warning: LAmax 45, 50, 55, 60, 65 dB(A) contours are clipped")
    doc = json.loads((tmp_path / "contours.geojson").read_text())
    flags = {(f["properties"]["kind"], f["properties"]["level"]): f["properties"]["clipped"] for f in doc["features"]}
    assert flags[("isoline", 45.0)] and flags[("isoband", 65.0)]
    assert flags[("isoline", 85.0)] is False  # the loudest contour closes around the track
    assert doc["gisnoise"]["warnings"] == [w.removeprefix("warning: ") for w in warn]


def test_the_cell_limit_cuts_the_default_extent_with_a_warning(tmp_path, monkeypatch):
    route = read_route(sample_route())
    cards = CardSet([card_path(c) for c in DEMO])
    full, w = auto_margin(route.trajectory, cards, 45.0, resolution_m=20.0)
    assert w == []
    monkeypatch.setenv("GISNOISE_MAX_CELLS", "40000")
    cut, w = auto_margin(route.trajectory, cards, 45.0, resolution_m=20.0, sel=False)  # the map below: LAmax only
    assert cut < full and len(w) == 1 and "40,000 cells" in w[0] and "LAmax 45 dB(A) contour" in w[0]
    _cut, w_sel = auto_margin(route.trajectory, cards, 45.0, resolution_m=20.0)
    assert "the SEL 55 dB(A) contour needs a margin above" in w_sel[0]
    paths = make_map(route.trajectory, cards, tmp_path, resolution_m=20.0, levels=[45.0], metrics=["LAmax"])
    assert paths["result"].grid.n_cells <= 40000
    extent = [x for x in paths["warnings"] if "flying sample(s) outside the" not in x]
    assert doc_power_warnings(paths["warnings"]) == 1
    assert extent[0] == w[0]
    assert extent[1].startswith("LAmax 45 dB(A) contours are clipped")


def test_the_margin_bound_holds_over_the_demo_cards_sphere():
    """The bound is an upper one: at the bound's distance no direction of any demo card reaches the level."""
    cards = [CardSet([card_path(c) for c in DEMO]).cards[i] for i in range(3)]
    for card in cards:
        d = audible_distance([card], [card.reference_power_w * 1.5], 50.0)
        phi, theta = np.meshgrid(np.radians(np.arange(0, 360, 1.0)), np.radians(np.arange(-90, 90.5, 1.0)))
        lv = card.level_uav(card.inputs(np.full(phi.shape, d), phi, theta, card.reference_power_w * 1.5))
        assert np.nanmax(lv) < 50.0 + 0.05
        lv_in = card.level_uav(card.inputs(np.full(phi.shape, d / 1.1), phi, theta, card.reference_power_w * 1.5))
        assert np.nanmax(lv_in) >= 50.0


def extended(base, ext, **params):
    import dataclasses

    from gisnoise.model import get_ansatz

    p = dict(base.parameters)
    for k in get_ansatz(ext).params:
        p.setdefault(k, 0.0)
    p.update(params)
    return dataclasses.replace(base, ansatz=ext, parameters=p)


def test_a_card_with_effect_extensions_is_bounded_by_its_base_plus_the_terms_bounds():
    """Effects bounded over every direction and instant: a switched-off bank term adds nothing; a ground
    reflection with R = 1 adds at most 20 lg 2 = 6.02 dB (the comb's peaks), the same extent as the base card
    made 6.02 dB louder; no warning."""
    route = read_route(sample_route())
    traj = route.trajectory.with_(phase=np.full(len(route.trajectory), "horizontal"))
    m_base, w0 = auto_margin(traj, CardSet([omni()]), 45.0, resolution_m=20.0)
    m_bank, w = auto_margin(traj, CardSet([extended(omni(), "paper-offset+bank_angle")]), 45.0, resolution_m=20.0)
    assert m_bank == m_base and w0 == w == []
    refl = extended(omni(), "paper-offset+bank_angle+ground_reflection", r_ground=1.0, f_ground=300.0)
    m_refl, w = auto_margin(traj, CardSet([refl]), 45.0, resolution_m=20.0)
    m_loud, _ = auto_margin(traj, CardSet([omni(g0=70.0 + 20.0 * np.log10(2.0))]), 45.0, resolution_m=20.0)
    assert w == [] and m_refl > m_base
    assert m_refl == pytest.approx(m_loud, rel=0.05)  # one table step (4.9 %) at most apart


def test_effect_bounds_are_the_terms_closed_forms():
    """Per distance d: absorption -a (d - d_ref)/1000 exactly, wind |w| d/100, Doppler -q 10 lg(1 - v/c) at the
    fastest speed and the slowest sound (-40 degC), ground reflection 20 lg(1 + R); a per-instant bank term its
    largest value over the card's instants (k sin(roll): k sin 30 deg for a 30 deg bank)."""
    from gisnoise.acoustics import speed_of_sound
    from gisnoise.flight import Trajectory
    from gisnoise.geo import LocalFrame
    from gisnoise.maps.effect_bounds import COLDEST_C, effect_bound_db

    f = LocalFrame(48.137, 11.575, 500.0)
    n = 41
    t = np.arange(n) * 0.5
    lat, lon, h = f.to_wgs84(12.0 * t, np.zeros(n), np.full(n, 40.0))  # 12 m/s east
    roll = np.where(t < 10.0, 30.0, 10.0)
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=roll, pitch=np.zeros(n), yaw=np.full(n, 90.0),
                      power_w=np.full(n, 3000.0), phase=np.full(n, "horizontal"))
    d = np.array([5.0, 40.0, 300.0, 2000.0])
    serves = np.ones(n, bool)
    card = extended(omni(), "paper-offset+bank_angle+atmospheric_absorption+wind+doppler+ground_reflection",
                    k_bank=3.0, a_abs=8.0, w_east=1.5, w_north=-2.0, q_doppler=2.0, r_ground=0.5, f_ground=300.0)
    mach = 12.0 / float(speed_of_sound(COLDEST_C))
    truth = (3.0 * np.sin(np.radians(30.0)) - 8.0 * (d - 40.0) / 1000.0 + 2.5 * d / 100.0
             - 20.0 * np.log10(1.0 - mach) + 20.0 * np.log10(1.5))
    np.testing.assert_allclose(effect_bound_db(card, traj, serves, d), truth, atol=1e-3)
    assert np.all(effect_bound_db(omni(), traj, serves, d) == 0.0)
    # an effect without a bound here (tied to a campaign's data): None, the extent says so
    event = extended(omni(), "paper-offset+emission_time")
    assert effect_bound_db(event, traj, serves, d) is None


def hover(seconds=30.0):
    from gisnoise.flight import Trajectory
    from gisnoise.geo import LocalFrame

    f = LocalFrame(48.137, 11.575, 500.0)
    lat, lon, h = f.to_wgs84(np.zeros(2), np.zeros(2), np.full(2, 40.0))
    return Trajectory(t=np.array([0.0, seconds]), lat=lat, lon=lon, h=h, roll=np.zeros(2), pitch=np.zeros(2),
                      yaw=np.zeros(2), power_w=np.full(2, 3000.0), phase=np.full(2, "horizontal"))


def test_the_sel_bound_of_a_hover_is_its_level_plus_ten_log_duration():
    """An omnidirectional hover of T = 30 s: SEL(r) = L(r) + 10 log10(T / 1 s), L(r) = 70 - 20 log10(r / 40 m)."""
    from gisnoise.geo import transformer, utm_crs

    traj = hover()
    crs = utm_crs(11.575, 48.137)
    x0, y0 = transformer("EPSG:4326", crs).transform(11.575, 48.137)
    d, table = level_table([omni()], [3000.0])
    for r in (200.0, 800.0, 3000.0):
        # a square of half-side r about the hover: its nearest edge points lie at r
        b = sel_edge_bound(traj, np.zeros(2, dtype=int), d, table, (x0 - r, y0 - r, x0 + r, y0 + r), crs,
                           spacing_m=10.0)
        truth = 70.0 - 20.0 * np.log10(r / 40.0) + 10.0 * np.log10(30.0)
        # an upper bound, within one table step (20 log10 1.049 = 0.42 dB) and the shortened distances
        assert truth <= b <= truth + 0.45 + 20.0 * np.log10(r / (0.998 * r - 5.0))


def test_the_default_extent_closes_sel_of_a_long_hover():
    """SEL of a hover grows with its duration: 300 s need a wider margin than LAmax alone, by the analytic distance."""
    traj = hover(300.0)
    cards = CardSet([omni()])
    m_max, _ = auto_margin(traj, cards, 45.0, resolution_m=20.0, sel=False)
    m_sel, w = auto_margin(traj, cards, 45.0, resolution_m=20.0)
    r_max = 40.0 * 10.0 ** ((70.0 - 45.0) / 20.0)  # 711 m
    r_sel = 40.0 * 10.0 ** ((70.0 + 10.0 * np.log10(300.0) - 55.0) / 20.0)  # SEL 55 at 3.9 km
    assert r_max <= m_max <= r_max * 1.05 + 40.0
    # within one table step (4.9 %), the bisection's cell and two cells of safety
    assert w == [] and r_sel <= m_sel <= r_sel * 1.05 + 80.0


def test_sel_margin_steps_are_the_edge_bound_of_their_rectangle_with_the_track_prepared_once(monkeypatch):
    """sel_margin prepares the track (CRS transform, weights) once; each bisection step's bound equals
    sel_edge_bound of that step's rectangle and spacing computed afresh."""
    from gisnoise.geo import transformer, utm_crs
    from gisnoise.maps import sel as sel_module

    traj = hover(300.0)
    crs = utm_crs(11.575, 48.137)
    x0, y0 = transformer("EPSG:4326", crs).transform(11.575, 48.137)
    d, table = level_table([omni()], [3000.0])
    ci = np.zeros(2, dtype=int)
    steps, made = [], []
    edge_bound, make = sel_module._edge_bound, sel_module.transformer

    def recording(src, rect, spacing, background_db):
        steps.append((rect, spacing, background_db, edge_bound(src, rect, spacing, background_db)))
        return steps[-1][-1]

    def counting(*a, **kw):
        made.append(a)
        return make(*a, **kw)

    monkeypatch.setattr(sel_module, "_edge_bound", recording)
    monkeypatch.setattr(sel_module, "transformer", counting)
    m = sel_margin(traj, ci, d, table, 55.0, (x0 - 10.0, y0 - 10.0, x0 + 10.0, y0 + 10.0), crs, start_m=100.0,
                   resolution_m=20.0, max_margin_m=20000.0, background_db=30.0)
    assert len(made) == 1 and len(steps) >= 5  # doubling, then bisection: one transformer for all steps
    monkeypatch.undo()
    for rect, spacing, bg, got in steps:
        assert got == sel_edge_bound(traj, ci, d, table, rect, crs, spacing_m=spacing, background_db=bg)
    at_m = [b for r, _, _, b in steps if math.isclose(r[2] - r[0], 20.0 + 2.0 * m)]
    assert at_m and at_m[-1] < 55.0 <= max(b for *_, b in steps)  # the margin returned closes SEL 55, a smaller one not
