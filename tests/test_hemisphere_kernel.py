"""The fast engine's hemisphere kernel against the card's definition: distance table, levels, filled weights."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_hemisphere import M300, node_level

from gisnoise.model import import_hemisphere

openpyxl = pytest.importorskip("openpyxl")
numba = pytest.importorskip("numba")

from gisnoise.maps.hemisource import DIST_STEP, distance_table, hemisphere_level_points  # noqa: E402


@pytest.fixture(scope="module")
def m300():
    return import_hemisphere(M300)


@pytest.fixture(scope="module")
def sheets():
    from test_hemisphere import read_sheets
    return read_sheets()


def test_distance_table_holds_the_per_band_sum_within_a_thousandth_of_a_db(m300, sheets):
    """Linear in log d between table points: within 0.0011 dB of the exact per-band sum from 1 m to 200 km."""
    tab, s0, hs = distance_table(m300, 0.999, 200_000.0)
    assert hs == pytest.approx(2 * DIST_STEP / math.log(2))
    d = np.exp(np.linspace(0.0, math.log(200_000.0), 401) + 0.37 * math.log(200_000.0) / 400)[:-1]
    x = (2 * np.log2(d) - s0) / hs
    k = np.clip(x.astype(int), 0, tab.shape[0] - 2)
    f = x - k
    nt = m300.theta_deg.size
    worst = 0.0
    for i, j in ((10, 6), (3, 2), (17, 9), (0, 0), (20, 12)):  # below, measured corners, filled edges
        node = i * nt + j
        approx = tab[k, node] * (1 - f) + tab[k + 1, node] * f - 20 * np.log10(d)
        exact = np.array([node_level(sheets, i, j, dk) for dk in d])
        worst = max(worst, float(np.max(np.abs(approx - exact))))
    assert worst < 0.0011


def body(d, a_deg, b_deg, below=True):
    """Body vector of distance d (m) in the direction of table angles a (along), b (across), below or above."""
    v = np.array([-math.tan(math.radians(a_deg)), math.tan(math.radians(b_deg)), 1.0 if below else -1.0])
    return v * d / np.linalg.norm(v)


def product_angles(v):
    x, y, z = v
    return math.atan2(y, x), math.atan2(-z, math.hypot(x, y))


@settings(max_examples=60, deadline=None)
@given(d=st.floats(1.0, 5000.0), a=st.floats(-89.9, 89.9), b=st.floats(-89.9, 89.9), below=st.booleans())
def test_kernel_equals_the_cards_definition_within_a_hundredth_of_a_db(m300, d, a, b, below):
    """Float32, polynomial angles, the distance table: within 0.01 dB of ``level_direction`` (NumPy engine)."""
    v = body(d, a, b, below)
    lev, fw = hemisphere_level_points(m300, v[0:1], v[1:2], v[2:3])
    phi, theta = product_angles(v)
    ref = float(m300.level_direction(d, phi, theta))
    assert float(lev[0]) == pytest.approx(ref, abs=0.01)
    _, fw_ref, _ = m300.interpolation(phi, theta)
    assert float(fw[0]) == pytest.approx(float(fw_ref), abs=1e-3)


def test_kernel_at_nodes_and_below(m300, sheets):
    """Straight below at 10 m and a node direction at 50 m: the table's per-band sum, within 0.01 dB."""
    i0, j0 = list(m300.phi_deg).index(0.0), list(m300.theta_deg).index(0.0)
    lev, fw = hemisphere_level_points(m300, [0.0], [0.0], [10.0])
    assert float(lev[0]) == pytest.approx(node_level(sheets, i0, j0, 10.0), abs=0.01)
    assert float(fw[0]) == 0.0  # measured
    i, j = list(m300.phi_deg).index(-33.7), list(m300.theta_deg).index(45.0)
    v = body(50.0, -33.7, 45.0)
    lev, fw = hemisphere_level_points(m300, v[0:1], v[1:2], v[2:3])
    assert float(lev[0]) == pytest.approx(node_level(sheets, i, j, 50.0), abs=0.01)
    v = body(50.0, 76.5, 75.0)  # a filled node
    _, fw = hemisphere_level_points(m300, v[0:1], v[1:2], v[2:3])
    assert float(fw[0]) == pytest.approx(1.0, abs=1e-4)


def test_table_codes_hold_the_levels_within_one_step_and_the_filled_flags(m300):
    """Four 16-bit codes per entry: both theta nodes at both distances, within one code step, flag in the lowest bit."""
    from gisnoise.maps._hemikernel import Q_MAX
    from gisnoise.maps.hemisource import _quads

    tab, _, _ = distance_table(m300, 0.999, 5000.0)
    filled = ~m300.measured.ravel()
    nt = m300.theta_deg.size
    q, base, step = _quads(tab, filled, nt)
    assert step == pytest.approx((tab.max() - tab.min()) / Q_MAX)
    assert step < 0.003  # the table spans less than 200 dB
    nd, nn = tab.shape
    codes = q.view(np.uint64).reshape(nn, nd - 1)
    fields = [(codes >> np.uint64(16 * b)) & np.uint64(0xFFFF) for b in range(4)]
    right = np.array([n if n % nt == nt - 1 else n + 1 for n in range(nn)])  # the last theta node pairs with itself
    want = [tab[:-1].T, tab[1:].T, tab[:-1, right].T, tab[1:, right].T]
    flags = [filled, filled, filled[right], filled[right]]
    for f, w, fl in zip(fields, want, flags, strict=True):
        assert np.max(np.abs(base + step * f.astype(float) - w)) <= step * (1 + 1e-9)
        np.testing.assert_array_equal(f & np.uint64(1), np.broadcast_to(fl[:, None], f.shape).astype(np.uint64))


@pytest.mark.parametrize("phi, theta", [
    ([-80.0, -61.0, -30.5, -12.0, 0.0, 7.5, 21.0, 40.0, 55.5, 80.0], [-70.0, -20.0, 0.0, 33.0, 70.0]),
    ([-75.0, -40.0, -5.0, 30.0, 65.0], [-60.0, -52.0, -31.0, -10.0, -2.0, 4.0, 18.0, 35.0, 47.0, 60.0]),
    ([-45.0, 0.0, 10.0, 45.0], [0.0]),
])
def test_kernel_on_uneven_axes_equals_the_cards_definition(phi, theta):
    """Uneven axes of several lengths (the kernel sums their intervals eight, then four at a time, padded).

    At every node direction and at random directions between them, the kernel's level is the
    card's ``level_direction`` (the NumPy engine's definition; at a node the node's per-band
    sum) within 0.01 dB, and its filled weight the card's bilinear weight on filled nodes
    (off the table's edges).
    """
    from gisnoise.model import HemisphereCard

    rng = np.random.default_rng(7)
    bands = np.array([100.0, 250.0, 630.0, 1600.0, 4000.0, 10000.0])
    ni, nj = len(phi), len(theta)
    levels = 50.0 + 20.0 * rng.random((bands.size, ni, nj))
    card = HemisphereCard(id="uneven", vehicle="test", phase="horizontal", ansatz="hemisphere", parameters={},
                          reference_power_w=1.0, reference_distance_m=1.0, phi_deg=phi, theta_deg=theta,
                          bands_hz=bands, levels_db=levels, measured=rng.random((ni, nj)) < 0.6)
    a, b = np.meshgrid(phi, theta, indexing="ij")
    a = np.concatenate([a.ravel(), rng.uniform(phi[0], phi[-1], 200)])
    b = np.concatenate([b.ravel(), rng.uniform(theta[0], theta[-1], 200)])
    d = np.where(np.arange(a.size) % 2 == 0, 30.0, 700.0)
    v = np.array([body(dk, ak, bk) for dk, ak, bk in zip(d, a, b, strict=True)])
    lev, fw = hemisphere_level_points(card, v[:, 0], v[:, 1], v[:, 2])
    phis, thetas = zip(*(product_angles(x) for x in v), strict=True)
    ref = card.level_direction(d, np.array(phis), np.array(thetas))
    np.testing.assert_allclose(lev, ref, atol=0.01)
    _, fw_ref, _ = card.interpolation(np.array(phis), np.array(thetas))
    # on the table's edge a direction is inside or outside (filled weight 1) by rounding: compare inside it
    inside = (a > phi[0] + 1e-6) & (a < phi[-1] - 1e-6) & (b > theta[0] + 1e-6) & (b < theta[-1] - 1e-6)
    np.testing.assert_allclose(fw[inside], fw_ref[inside], atol=1e-3)
