"""The ansatz registry: the paper's directivity claims and analytic Jacobians."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gisnoise.errors import InputError
from gisnoise.model import ansatz_names, cards, get_ansatz, level_sum

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]
TABLE1_HORIZONTAL = [13.409, 0.176, -0.280, -0.365, 1.049, 0.939, 40.393]


def test_level_sum_of_equal_levels_is_plus_3db():
    assert level_sum(40.0, 40.0) == pytest.approx(40.0 + 10 * np.log10(2), abs=1e-12)
    assert level_sum(100.0, 0.0) == pytest.approx(100.0, abs=1e-9)


def test_published_horizontal_card_peaks_at_74_deg_azimuth():
    # SPEC 1 / paper Fig. 7: P_el = 1.1, 30 m; maximum at phi = p3 + pi/2 = 73.96 deg
    card = cards.load(ROOT / "gisnoise/data/cards/published_horizontal.json")
    phi = np.radians(np.arange(-180.0, 180.0, 0.01))
    for theta in (-1.2, -0.6, 0.0, 0.5):
        lvl = card.level_uav(card.inputs(30.0, phi, theta, 1.1 * card.reference_power_w))
        assert np.degrees(phi[np.argmax(lvl)]) == pytest.approx(74.0, abs=0.5)


def test_published_horizontal_card_falls_from_polar_0_to_minus_90():
    # paper section 4.2 and Fig. 7: at P_el = 1.1, the level decreases as the observer
    # moves from the horizon (theta = 0) to straight below (theta = -90 deg), at the
    # loud azimuths (ahead through starboard to aft); behind-port the p2 term reverses it
    card = cards.load(ROOT / "gisnoise/data/cards/published_horizontal.json")
    theta = np.radians(np.linspace(0.0, -90.0, 181))
    for phi_deg in (0.0, 40.0, 74.0, 110.0, 150.0):
        lvl = card.level_uav(card.inputs(30.0, np.radians(phi_deg), theta, 1.1 * card.reference_power_w))
        assert lvl[0] > lvl[-1]
        # (1 + p4 sin(theta - p5)) peaks at theta = p5 - pi/2 = -30 deg; below it the fall is monotone
        below = theta <= 1.049 - np.pi / 2
        assert np.all(np.diff(lvl[below]) < 0)


def test_spreading_is_p6_times_20log_distance():
    a = get_ansatz("paper")
    p = np.array(TABLE1_HORIZONTAL)
    x1 = {"d": 40.0, "phi": 0.3, "theta": -0.4, "p_el": 1.3}
    x2 = dict(x1, d=400.0)
    assert a.level_uav(p, x1) - a.level_uav(p, x2) == pytest.approx(0.939 * 20.0, rel=1e-12)


def test_offset_ansatz_with_zero_offset_equals_paper():
    p = np.array(TABLE1_HORIZONTAL)
    x = {"d": np.array([20.0, 90.0]), "phi": np.array([0.1, 2.0]), "theta": np.array([-1.0, 0.2]), "p_el": 1.4}
    np.testing.assert_allclose(get_ansatz("paper-offset").level(np.r_[0.0, p], x), get_ansatz("paper").level(p, x))


finite = dict(allow_nan=False, allow_infinity=False)


@pytest.mark.parametrize("name", ["paper", "paper-offset"])
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_jacobian_matches_central_differences(name, data):
    a = get_ansatz(name)
    n = 5
    x = {
        "d": np.array(data.draw(st.lists(st.floats(5.0, 800.0, **finite), min_size=n, max_size=n))),
        "phi": np.array(data.draw(st.lists(st.floats(-3.1, 3.1, **finite), min_size=n, max_size=n))),
        "theta": np.array(data.draw(st.lists(st.floats(-1.55, 1.55, **finite), min_size=n, max_size=n))),
        "p_el": np.array(data.draw(st.lists(st.floats(0.3, 8.0, **finite), min_size=n, max_size=n))),
    }
    base = np.array(([60.0] if name == "paper-offset" else []) + TABLE1_HORIZONTAL)
    p = base + np.array(data.draw(st.lists(st.floats(-0.3, 0.3, **finite), min_size=a.n_params,
                                           max_size=a.n_params)))
    for background in (True, False):
        _, jac = a.level_and_jacobian(p, x, background=background)
        for k in range(a.n_params):
            h = 1e-6 * max(1.0, abs(p[k]))
            pp, pm = p.copy(), p.copy()
            pp[k] += h
            pm[k] -= h
            fd = (a.level(pp, x, background=background) - a.level(pm, x, background=background)) / (2 * h)
            scale = np.maximum(np.abs(fd), 1e-3)
            assert np.all(np.abs(jac[:, k] - fd) <= 1e-6 * scale + 1e-7), (name, k, jac[:, k], fd)


def test_registry_lists_and_refuses_unknown():
    assert {"paper", "paper-offset"} <= set(ansatz_names())
    with pytest.raises(InputError, match="unknown ansatz 'nope'"):
        get_ansatz("nope")


def test_wrong_parameter_count_names_parameters():
    with pytest.raises(InputError, match="takes 7 parameters"):
        get_ansatz("paper").level([1.0, 2.0], {"d": 1, "phi": 0, "theta": 0, "p_el": 1})


def test_an_extension_chain_is_built_by_name_with_its_parameters_in_order():
    # "base+e1+e2": the base's parameters, then each effect's, in the order named
    from gisnoise.model import get_effect

    a = get_ansatz("paper-offset+bank_angle+doppler")
    base = get_ansatz("paper-offset")
    e1, e2 = get_effect("bank_angle"), get_effect("doppler")
    assert a.params == base.params + e1.params + e2.params
    with pytest.raises(InputError, match="unknown ansatz 'paper-offset\\+nope'.*unknown effect 'nope'"):
        get_ansatz("paper-offset+nope")
