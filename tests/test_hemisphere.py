"""Measured hemispheres as sources: import of the real DJI Matrice 300 hemisphere, evaluation, maps."""

import csv
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from gisnoise.acoustics import a_weighting, atmospheric_absorption, exact_frequency, nominal_frequency
from gisnoise.errors import CardError
from gisnoise.model import (
    SALFORD_ATMOSPHERE,
    HemisphereCard,
    dumps,
    import_hemisphere,
    load,
    loads,
    save,
    table_angles,
)

openpyxl = pytest.importorskip("openpyxl")

M300 = Path(__file__).parent / "data" / "hemispheres" / "Hem_Ed_M3_10_F05_Y_W_dw_2.xlsx"
T, RH = 25.0, 70.0  # the file's back-propagation atmosphere


def read_sheets():
    """The workbook read here, independently of the importer: {band name: (phi, theta, table)}."""
    wb = openpyxl.load_workbook(M300, read_only=True, data_only=True)
    out = {}
    for name in wb.sheetnames:
        if not name.startswith("band_"):
            continue
        rows = list(wb[name].iter_rows(values_only=True))
        theta = [float(v) for v in rows[0][1:]]
        phi = [float(r[0]) for r in rows[1:]]
        out[name[5:]] = (phi, theta, np.array([[float(v) for v in r[1:]] for r in rows[1:]]))
    return out


@pytest.fixture(scope="module")
def sheets():
    return read_sheets()


@pytest.fixture(scope="module")
def card():
    return import_hemisphere(M300)


def bands_of(sheets):
    names = [k for k in sheets if k != "Overall"]
    return names, np.array([float(nominal_frequency(float(k))) for k in names])


def node_level(sheets, i, j, d, r0=1.0):
    """A-weighted level of node (row i, column j) at distance d: per band spreading and ISO 9613-1 absorption."""
    names, nominal = bands_of(sheets)
    f = exact_frequency(nominal)
    lb = np.array([sheets[k][2][i, j] for k in names])
    alpha = atmospheric_absorption(f, T, RH)
    return 10 * np.log10(np.sum(10 ** ((lb + a_weighting(f) - alpha * (d - r0)) / 10))) - 20 * np.log10(d / r0)


def product_angles(phi_t_deg, theta_t_deg):
    """Product azimuth and polar angle (rad) of the direction with table angles (deg) below the UAV."""
    xb = -math.tan(math.radians(phi_t_deg))
    yb = math.tan(math.radians(theta_t_deg))
    zb = 1.0
    return math.atan2(yb, xb), math.atan2(-zb, math.hypot(xb, yb))


def level(card, d, phi, theta):
    return float(card.level(card.inputs(np.asarray(d, float), phi, theta, 1.0)))


# --------------------------------------------------------------------------- import


def test_imported_table_equals_the_file_at_every_node(card, sheets):
    names, nominal = bands_of(sheets)
    assert card.bands_hz.size == len(names) == 31
    phi, theta, _ = sheets["1000"]
    np.testing.assert_array_equal(card.phi_deg, phi)
    np.testing.assert_array_equal(card.theta_deg, theta)
    for k, f in zip(names, nominal, strict=True):
        b = int(np.flatnonzero(card.bands_hz == f)[0])
        np.testing.assert_array_equal(card.levels_db[b], sheets[k][2])
    assert card.reference_distance_m == 1.0
    assert card.atmosphere == SALFORD_ATMOSPHERE
    assert card.condition == {"height_m": 10.0, "speed_m_s": 5.0}


def test_measured_cells_are_the_microphone_span_and_the_unrepeated_rows(card):
    # 9 microphones: |theta| <= 60; phi rows beyond +-49.4 repeat the +-49.4 row (constant fill)
    expect = (np.abs(card.phi_deg) <= 49.5)[:, None] & (np.abs(card.theta_deg) <= 60)[None, :]
    np.testing.assert_array_equal(card.measured, expect)


def test_card_round_trips_through_json_and_file(card, tmp_path):
    again = loads(dumps(card))
    assert isinstance(again, HemisphereCard) and again == card
    p = save(card, tmp_path / "m300.json")
    assert load(p) == card


def test_generic_csv_gives_the_same_card(card, sheets, tmp_path):
    p = tmp_path / "hemi.csv"
    names, _ = bands_of(sheets)
    with open(p, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["band", "phi_deg", "theta_deg", "level_db", "radius_m"])
        for k in names + ["Overall"]:
            phi, theta, tab = sheets[k]
            for i, a in enumerate(phi):
                for j, b in enumerate(theta):
                    w.writerow([k, a, b, tab[i, j], 1.0])
    c2 = import_hemisphere(p, atmosphere=dict(SALFORD_ATMOSPHERE), card_id=card.id, vehicle=card.vehicle)
    np.testing.assert_array_equal(c2.levels_db, card.levels_db)
    np.testing.assert_array_equal(c2.measured, card.measured)


def test_an_angle_beyond_the_horizon_is_refused_naming_its_line_and_column(tmp_path):
    """Table angles lie within -90..90 deg (0 straight below, +-90 at the horizon): a row at phi 95 is refused naming
    its line and column, not reported as some other node's missing level."""
    p = tmp_path / "h.csv"
    rows = [f"1000,{a},{b},60" for a in (-90, 0, 90) for b in (-90, 0, 90)]
    p.write_text("band,phi_deg,theta_deg,level_db\n" + "\n".join(rows) + "\n")
    assert import_hemisphere(p, atmosphere=dict(SALFORD_ATMOSPHERE)).levels_db.shape == (1, 3, 3)
    for col, k in (("phi_deg", 1), ("theta_deg", 2)):
        bad = [r.split(",") for r in rows]
        bad[4][k] = "95"
        p.write_text("band,phi_deg,theta_deg,level_db\n" + "\n".join(",".join(r) for r in bad) + "\n")
        with pytest.raises(CardError, match=f"line 6: {col} 95 .*-90..90") as e:
            import_hemisphere(p, atmosphere=dict(SALFORD_ATMOSPHERE))
        assert e.value.field == col


def test_bad_files_are_refused_naming_the_field(tmp_path):
    p = tmp_path / "h.csv"
    p.write_text("band,phi_deg,theta_deg,level_db\n1000,0,0,60\n1000,0,15,60\n1250,0,0,60\n")
    with pytest.raises(CardError, match="every band needs every node"):
        import_hemisphere(p, atmosphere=dict(SALFORD_ATMOSPHERE))
    p.write_text("band,phi_deg,theta_deg,level_db\n1000,0,0,60\n")
    with pytest.raises(CardError, match="atmosphere") as e:
        import_hemisphere(p)
    assert e.value.field == "atmosphere"
    p.write_text("band,phi_deg,theta_deg,level_db\n1100,0,0,60\n")
    with pytest.raises(CardError, match="one-third-octave"):
        import_hemisphere(p, atmosphere=dict(SALFORD_ATMOSPHERE))
    with pytest.raises(CardError, match="levels_db"):
        loads(dumps(import_hemisphere(M300)).replace('"levels_db": [', '"levels_db": [[[1.0]], ', 1))


# --------------------------------------------------------------------------- evaluation


def test_straight_below_at_10_m_is_the_band_sum_propagated(card, sheets):
    phi, theta, _ = sheets["1000"]
    i, j = phi.index(0.0), theta.index(0.0)
    expect = node_level(sheets, i, j, 10.0)
    # the same physics spelled out: A-weighted band sum at 1 m, 20 dB spreading, absorption over 9 m
    names, nominal = bands_of(sheets)
    f = exact_frequency(nominal)
    lb = np.array([sheets[k][2][i, j] for k in names]) + a_weighting(f)
    by_hand = 10 * np.log10(np.sum(10 ** ((lb - 9.0 * atmospheric_absorption(f, T, RH)) / 10))) - 20.0
    assert by_hand == pytest.approx(expect, abs=1e-9)
    got = level(card, 10.0, 0.0, -math.pi / 2)
    assert got == pytest.approx(expect, abs=0.05)
    assert abs(got - expect) < 1e-9


@pytest.mark.parametrize("a, b", [(-26.6, 30.0), (18.4, -45.0), (-45.0, 60.0), (0.0, -15.0)])
def test_node_direction_at_50_m(card, sheets, a, b):
    phi, theta, _ = sheets["1000"]
    ph, th = product_angles(a, b)
    assert level(card, 50.0, ph, th) == pytest.approx(node_level(sheets, phi.index(a), theta.index(b), 50.0),
                                                      abs=0.05)


def test_fore_is_negative_phi_and_starboard_positive_theta():
    # 60 deg below the horizon is 30 deg from straight below
    a, b, _ = table_angles(0.0, math.radians(-60.0))  # ahead
    assert float(a) == pytest.approx(-30.0) and float(b) == pytest.approx(0.0)
    a, b, _ = table_angles(math.pi, math.radians(-60.0))  # behind
    assert float(a) == pytest.approx(30.0)
    a, b, _ = table_angles(math.pi / 2, math.radians(-60.0))  # starboard
    assert float(a) == pytest.approx(0.0) and float(b) == pytest.approx(30.0)
    a, b, _ = table_angles(-math.pi / 2, math.radians(-60.0))  # port
    assert float(b) == pytest.approx(-30.0)


def test_the_logged_pitch_turns_the_table(card):
    """The table is read in the body frame: nose down by 10 deg, the receiver straight below lies 10 deg ahead of the
    body's vertical (phi_t = -10 deg), and the level is the table's there, not at (0, 0) (docs/hemispheres.md)."""
    from gisnoise.geo import emission_angles

    d, ph, th = emission_angles(0.0, 0.0, -10.0, 0.0, math.radians(-10.0), 0.0)
    a, b, _ = table_angles(ph, th)
    assert float(a) == pytest.approx(-10.0, abs=1e-9) and float(b) == pytest.approx(0.0, abs=1e-9)
    at = level(card, 10.0, *product_angles(-10.0, 0.0))
    assert level(card, float(d), float(ph), float(th)) == pytest.approx(at, abs=1e-9)
    assert (round(level(card, 10.0, 0.0, -math.pi / 2), 2), round(at, 2)) == (64.73, 64.58)


def test_between_nodes_the_level_lies_between_its_neighbours(card, sheets):
    phi, theta, _ = sheets["1000"]
    rng = np.random.default_rng(3)
    for _ in range(60):
        i = int(rng.integers(0, len(phi) - 1))
        j = int(rng.integers(0, len(theta) - 1))
        if max(abs(phi[i]), abs(phi[i + 1]), abs(theta[j]), abs(theta[j + 1])) >= 90:
            continue
        a = phi[i] + rng.uniform(0.05, 0.95) * (phi[i + 1] - phi[i])
        b = theta[j] + rng.uniform(0.05, 0.95) * (theta[j + 1] - theta[j])
        d = float(rng.uniform(2.0, 300.0))
        corners = [node_level(sheets, ii, jj, d) for ii in (i, i + 1) for jj in (j, j + 1)]
        got = level(card, d, *product_angles(a, b))
        assert min(corners) - 1e-9 <= got <= max(corners) + 1e-9


def test_loudest_level_is_the_largest_node_and_bounds_every_direction(card, sheets):
    # the map's default extent takes a hemisphere's loudest level over the sphere at each distance
    # from loudest_level: the largest node level (bilinear interpolation never exceeds its nodes)
    from gisnoise.maps import level_table

    phi, theta, _ = sheets["1000"]
    rng = np.random.default_rng(5)
    dist = np.array([1.0, 10.0, 120.0, 900.0])
    top = card.loudest_level(dist)
    for d, t in zip(dist, top, strict=True):
        want = max(node_level(sheets, i, j, d) for i in range(len(phi)) for j in range(len(theta)))
        assert t == pytest.approx(want, abs=1e-9)
        az, pol = rng.uniform(-np.pi, np.pi, 20000), rng.uniform(-np.pi / 2, np.pi / 2, 20000)
        swept = card.level(card.inputs(np.full(az.size, d), az, pol, 1.0))
        assert swept.max() <= t + 1e-9
        assert swept.max() >= t - 1.0  # and dense directions come close to it
    d_tab, table = level_table([card], [1.0])
    assert np.allclose(table[0], card.loudest_level(d_tab), rtol=0, atol=1e-12)


def test_interpolation_is_continuous_across_cells_and_the_horizon(card):
    # a fine sweep of directions: neighbouring directions give neighbouring levels
    az = np.radians(30.0)
    pol = np.radians(np.linspace(-89.9, 30.0, 4000))
    lv = card.level(card.inputs(np.full(pol.size, 20.0), np.full(pol.size, az), pol, 1.0))
    assert np.max(np.abs(np.diff(lv))) < 0.5


def test_summary_sound_power_and_the_file_s_own(card):
    # the file's SWL_Bands Overall, 91.0 dB, is the Salford tool's: the nodes' mean square pressure (no solid-angle
    # weights) times the lower hemisphere's area 2 pi r^2, rounded to 0.1 dB; the table gives it back
    assert card.statistics["file_sound_power_db"]["Overall"] == 91.0
    p2 = (10.0 ** (card.levels_db / 10.0)).sum(axis=0)
    assert 10 * np.log10(p2.mean() * 2 * np.pi * card.reference_distance_m ** 2) == pytest.approx(91.0, abs=0.05)
    # the card's own: the intensity integrated by solid angle over the lower half, the upper half mirrored;
    # a table of one level L at 1 m everywhere is L + 10 lg(4 pi) dB (more in test_hemisphere_power.py)
    flat = dataclasses.replace(card, levels_db=np.full_like(card.levels_db, 60.0))
    assert flat.sound_power_db()["overall_z"] == pytest.approx(60.0 + 10 * np.log10(card.levels_db.shape[0] * 4 * np.pi),
                                                               abs=1e-9)
    top = card.loudest_direction()
    assert top["level_db_a"] == pytest.approx(float(card.overall_a_db.max()))


# --------------------------------------------------------------------------- conversions


def test_fit_of_the_paper_ansatz_and_sampling_it_back(card):
    from gisnoise.model import fit_hemisphere, node_directions, sample_card

    fit = fit_hemisphere(card)
    st = fit.statistics
    assert fit.ansatz == "paper-offset" and st["n_nodes"] == int(card.measured.sum()) == 135
    # the stated residual is the RMS over the measured nodes of fitted minus table levels at 40 m
    phi, theta = node_directions(card.phi_deg, card.theta_deg)
    m = card.measured
    x = fit.inputs(np.full(m.sum(), 40.0), phi[m], theta[m], fit.reference_power_w)
    model = fit.level(x, background=False)
    table = card.node_levels(40.0)[m]
    assert st["residual_rms_db"] == pytest.approx(float(np.sqrt(np.mean((model - table) ** 2))), rel=1e-9)
    assert st["residual_rms_db"] < 2.0  # a smooth directivity: the ansatz holds it to about a dB
    assert abs(float(np.mean(model - table))) < 0.05  # least squares with a free level: unbiased
    # sampling the fitted card on the hemisphere's grid at 40 m gives the fitted values at the nodes
    back = sample_card(fit, phi_deg=card.phi_deg, theta_deg=card.theta_deg, radius_m=40.0)
    np.testing.assert_allclose(back.levels_db[0][m], model, atol=1e-9)
    np.testing.assert_allclose(back.node_levels(40.0)[m], model, atol=0.01)  # A(1 kHz) = 0, no absorption at r0
    a_phi, a_theta = np.radians(30.0), np.radians(-50.0)  # and between nodes it stays near the fitted card
    assert level(back, 40.0, a_phi, a_theta) == pytest.approx(
        float(fit.level(fit.inputs(40.0, a_phi, a_theta, fit.reference_power_w), background=False)), abs=0.3)


def test_map_atmosphere_changes_the_absorption(card, sheets):
    other = card.in_atmosphere(10.0, 30.0)
    assert loads(dumps(other)) == other and other.atmosphere == card.atmosphere
    phi, theta, _ = sheets["1000"]
    i, j = phi.index(0.0), theta.index(0.0)
    names, nominal = bands_of(sheets)
    f = exact_frequency(nominal)
    lb = np.array([sheets[k][2][i, j] for k in names]) + a_weighting(f)
    d = 200.0
    expect = 10 * np.log10(np.sum(10 ** ((lb - (d - 1.0) * atmospheric_absorption(f, 10.0, 30.0)) / 10))) \
        - 20 * np.log10(d)
    assert level(other, d, 0.0, -math.pi / 2) == pytest.approx(expect, abs=0.05)
    assert abs(level(card, d, 0.0, -math.pi / 2) - expect) > 0.5  # the atmospheres differ measurably at 200 m
    with pytest.raises(CardError, match="map_atmosphere.humidity_pct"):
        card.in_atmosphere(10.0, 130.0)
