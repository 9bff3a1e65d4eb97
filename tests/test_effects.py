"""The effect library: analytic Jacobians, physical limits of each extension term, testability."""

import numpy as np
import pytest
from scipy.integrate import quad

from gisnoise.errors import InputError
from gisnoise.model import bind, check_testable, effects, extend, get_ansatz, get_effect

BASE = np.array([62.0, 13.4, 0.18, -0.28, -0.37, 1.05, 0.94, 40.4])  # paper-offset
C = 331.3 * np.sqrt(1.0 + 11.0 / 273.15)


def circuit(n=240, seed=0, radius=150.0, speed=18.0, h=60.0):
    """Rows of two microphones watching a UAV on a circle (counter-clockwise, banked turn)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.125
    ang = speed / radius * t
    uav = np.column_stack([radius * np.cos(ang), radius * np.sin(ang), np.full(n, h)])
    vel = np.column_stack([-speed * np.sin(ang), speed * np.cos(ang), np.zeros(n)])
    rows = []
    for m_enu, mid in (((30.0, -20.0, 1.2), "m1"), ((-200.0, 40.0, 0.0), "m2")):
        mic = np.tile(m_enu, (n, 1))
        r = mic - uav
        d = np.linalg.norm(r, axis=1)
        rows.append(dict(d=d, uav=uav, mic=mic, vel=vel, t=t, id=np.full(n, mid)))
    cat = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}
    m = len(cat["d"])
    tt = cat["t"]
    f = np.array([100.0, 125.0, 160.0, 200.0, 250.0, 315.0, 400.0, 500.0, 630.0, 800.0, 1000.0, 1250.0, 1600.0,
                  2000.0, 2500.0, 3150.0, 4000.0])
    return {
        "d": cat["d"],
        "phi": np.sin(0.3 * tt) * 2.5 + rng.uniform(-0.2, 0.2),
        "theta": -0.6 + 0.5 * np.sin(0.2 * tt + 1.0),
        "p_el": 1.1 + 0.3 * np.cos(0.1 * tt),
        "bank": np.radians(rng.uniform(-35.0, 35.0, m)),
        "rpm": rng.uniform(2500.0, 4000.0, m),
        "band_f": f,
        "bands": 70.0 - 5.0 * np.log10(f / 100.0) + rng.normal(0.0, 1.0, (m, len(f))),
        "t_e": cat["t"],
        "uav_enu": cat["uav"],
        "mic_enu": cat["mic"],
        "vel_enu": cat["vel"],
        "mic": cat["id"],
        "flight": np.full(m, "f1"),
        "mic_agl": np.where(cat["id"] == "m1", 1.2, 0.0),
        "event_window": np.where((cat["t"] > 5.0) & (cat["t"] < 8.0), (cat["id"] == "m2").astype(int), -1),
        "meta": {"weather": {"temperature_c": 11.0, "humidity_pct": 45.0}},
    }


STARTS = {
    "bank_angle": [4.0],
    "atmospheric_absorption": [6.0],
    "ground_reflection": [0.7, 310.0],
    "doppler": [3.0],
    "emission_time": [0.4, 0.3],
    "wind": [1.5, -0.8],
    "rpm": [2.5, 3100.0],
    "background_event": [55.0, 47.0],
}


@pytest.mark.parametrize("name", list(effects.EFFECT_NAMES))
@pytest.mark.parametrize("background", [True, False])
def test_extended_jacobian_matches_central_differences(name, background):
    x = circuit()
    eff = bind(get_effect(name), x)
    a = extend("paper-offset", eff)
    p = np.r_[BASE, STARTS[name]]
    lvl, jac = a.level_and_jacobian(p, x, background=background)
    assert jac.shape == (len(x["d"]), a.n_params)
    for k in range(a.n_params):
        h = 1e-6 * max(1.0, abs(p[k]))
        pp, pm = p.copy(), p.copy()
        pp[k] += h
        pm[k] -= h
        fd = (a.level(pp, x, background=background) - a.level(pm, x, background=background)) / (2 * h)
        tol = 2e-5 * np.maximum(np.abs(fd), 1e-2) if name == "emission_time" else 1e-6 * np.maximum(np.abs(fd), 1e-3)
        assert np.all(np.abs(jac[:, k] - fd) <= tol + 1e-7), (name, a.params[k])


@pytest.mark.parametrize("name", [n for n in effects.EFFECT_NAMES if n != "background_event"])
def test_effect_vanishes_at_its_start_values(name):
    x = circuit()
    eff = get_effect(name)
    a = get_ansatz(f"paper-offset+{name}")
    p = np.r_[BASE, eff.start]
    if name == "rpm":
        p[-1] = 3000.0
    np.testing.assert_allclose(a.level(p, x), get_ansatz("paper-offset").level(BASE, x), atol=1e-12)


def delta(name, q, x):
    a = get_ansatz(f"paper-offset+{name}")
    return a.level_uav(np.r_[BASE, q], x) - get_ansatz("paper-offset").level_uav(BASE, x)


def row(**kw):
    x = {"bands": np.zeros((1, 1)), "band_f": np.array([2000.0]), "d": 100.0, "phi": 0.3, "theta": -0.5, "p_el": 1.2, "t_e": np.array([0.0]),
         "meta": {"speed_of_sound_m_s": 340.0}}
    x.update(kw)
    return x


def test_doppler_is_convective_amplification():
    # approaching at Mach 0.1: -q 10 log10(1 - 0.1); receding: -q 10 log10(1 + 0.1)
    uav, mic = np.array([[0.0, 0.0, 50.0]]), np.array([[100.0, 0.0, 50.0]])
    towards = row(uav_enu=uav, mic_enu=mic, vel_enu=np.array([[34.0, 0.0, 0.0]]))
    away = row(uav_enu=uav, mic_enu=mic, vel_enu=np.array([[-34.0, 0.0, 0.0]]))
    assert delta("doppler", [4.0], towards)[0] == pytest.approx(-40.0 * np.log10(0.9), rel=1e-12)
    assert delta("doppler", [4.0], away)[0] == pytest.approx(-40.0 * np.log10(1.1), rel=1e-12)
    # crossing at right angles: no amplification
    across = row(uav_enu=uav, mic_enu=mic, vel_enu=np.array([[0.0, 34.0, 0.0]]))
    assert delta("doppler", [4.0], across)[0] == pytest.approx(0.0, abs=1e-12)


def test_absorption_is_linear_in_path_beyond_reference_distance():
    x = row(d=np.array([40.0, 440.0, 1040.0]))
    np.testing.assert_allclose(delta("atmospheric_absorption", [5.0], x), [0.0, -2.0, -5.0], atol=1e-12)


def test_wind_raises_level_downwind_and_lowers_it_upwind():
    mic = np.array([[0.0, 0.0, 0.0]] * 3)
    uav = np.array([[-100.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]])  # west, east, north of the mic
    x = row(d=np.full(3, 100.0), uav_enu=uav, mic_enu=mic)
    # w_east = 1 dB/100 m: sound travelling east (from the west) gains 1 dB at 100 m
    np.testing.assert_allclose(delta("wind", [1.0, 0.0], x), [1.0, -1.0, 0.0], atol=1e-12)


def test_rpm_term_is_a_power_law_in_propeller_speed():
    x = row(rpm=np.array([3000.0, 6000.0]))
    np.testing.assert_allclose(delta("rpm", [3.0, 3000.0], x), [0.0, 60.0 * np.log10(2.0)], atol=1e-12)


def test_bank_term_follows_sine_of_bank():
    x = row(bank=np.radians([0.0, -30.0, 30.0, 90.0]))
    np.testing.assert_allclose(delta("bank_angle", [4.0], x), [0.0, 2.0, 2.0, 4.0], atol=1e-12)


def test_ground_reflection_limits():
    # in phase (tau = 0): pressure doubling 20 log10(1 + R); far apart in frequency: energies add 10 log10(1 + R^2)
    geo = {"uav_enu": np.zeros((1, 3)), "mic_enu": np.ones((1, 3))}
    x0 = row(tau_ground=np.array([0.0]), **geo)
    assert delta("ground_reflection", [1.0, 500.0], x0)[0] == pytest.approx(20 * np.log10(2.0), abs=1e-9)
    x1 = row(tau_ground=np.array([0.5]), **geo)  # 250 periods at 500 Hz, band average of the cosine ~ 0
    assert delta("ground_reflection", [0.5, 500.0], x1)[0] == pytest.approx(10 * np.log10(1.25), abs=0.05)


def test_band_averaged_cosine_equals_numerical_average():
    a1, a2 = effects.THIRD_OCTAVE
    for u in (1e-5, 0.3, 2.0, 7.5, 40.0):
        numeric = quad(np.cos, a1 * u, a2 * u)[0] / ((a2 - a1) * u)
        assert effects.band_cos(np.array(u), False)[0] == pytest.approx(numeric, abs=1e-8)


def test_reflection_delay_is_path_difference_over_c():
    # UAV 100 m above a 1.2 m microphone, straight overhead: delay 2 * 1.2 m / c
    x = row(uav_enu=np.array([[0.0, 0.0, 101.2]]), mic_enu=np.array([[0.0, 0.0, 1.2]]), mic_agl=np.array([1.2]))
    assert effects.reflection_delay(x)[0] == pytest.approx(2.4 / 340.0, rel=1e-12)


def test_emission_time_shift_equals_model_at_shifted_time():
    # inputs that change linearly in time: the extension at dt_clock = 0.5 s is the base model 0.5 s later
    t = np.arange(0.0, 20.0, 0.125)
    lin = {"d": 60.0 + 3.0 * t, "phi": -2.0 + 0.2 * t, "theta": -1.2 + 0.05 * t, "p_el": 1.0 + 0.01 * t}
    x = {**lin, "t_e": t, "mic_enu": np.zeros((len(t), 3)), "uav_enu": np.zeros((len(t), 3)),
         "meta": {"speed_of_sound_m_s": 340.0}}
    later = {k: np.interp(t + 0.5, t, v) for k, v in lin.items()}
    inner = slice(2, -6)  # np.gradient is exact inside a linear series
    got = get_ansatz("paper-offset+emission_time").level_uav(np.r_[BASE, 0.5, 0.0], x)
    np.testing.assert_allclose(got[inner], get_ansatz("paper-offset").level_uav(BASE, later)[inner], atol=1e-9)


def test_event_window_adds_energy():
    x = circuit()
    eff = bind(get_effect("background_event"), x)
    assert eff.params == ("ev1", "ev2")
    a = extend("paper-offset", eff)
    l0 = get_ansatz("paper-offset").level_uav(BASE, x)
    inside = x["event_window"] == 0
    q = np.array([0.0, 0.0])
    q[0] = 55.0
    got = a.level_uav(np.r_[BASE, q], x)
    np.testing.assert_allclose(got[inside], 10 * np.log10(10 ** (l0[inside] / 10) + 10 ** 5.5), rtol=1e-12)
    np.testing.assert_allclose(got[x["event_window"] < 0], l0[x["event_window"] < 0], rtol=1e-12)


def test_bound_effect_finds_its_rows_in_any_subset():
    x = circuit()
    eff = bind(get_effect("emission_time"), x)
    a = extend("paper-offset", eff)
    p = np.r_[BASE, 0.3, 0.1]
    full = a.level_uav(p, x)
    idx = np.random.default_rng(1).permutation(len(x["d"]))[:100]
    sub = {k: (v[idx] if isinstance(v, np.ndarray) and k != "band_f" else v) for k, v in x.items()}
    np.testing.assert_allclose(a.level_uav(p, sub), full[idx], rtol=1e-12)
    other = dict(sub, t_e=sub["t_e"] + 1000.0)
    with pytest.raises(InputError, match="not rows of the data set"):
        a.level_uav(p, other)


def test_missing_inputs_make_a_candidate_not_testable():
    x = circuit()
    no_rpm = {k: v for k, v in x.items() if k != "rpm"}
    assert check_testable(get_effect("rpm"), no_rpm) == (False, "no rpm column in the flight logs")
    no_bands = {k: v for k, v in x.items() if k not in ("bands", "band_f")}
    ok, why = check_testable(get_effect("atmospheric_absorption"), no_bands)
    assert not ok and "band levels" in why
    ground = dict(x, mic_agl=np.zeros(len(x["d"])))
    ok, why = check_testable(get_effect("ground_reflection"), ground)
    assert not ok and "on the ground" in why
    flat = dict(x, rpm=np.full(len(x["d"]), 3000.0))
    assert check_testable(get_effect("rpm"), flat) == (False, "the propeller speed does not vary")
    assert check_testable(get_effect("doppler"), dict(x, meta={})) == (
        False, "speed of sound unknown (campaign gives neither speed_of_sound_m_s nor temperature)")
    for name in ("bank_angle", "doppler", "emission_time", "wind", "rpm", "ground_reflection",
                 "atmospheric_absorption"):
        assert check_testable(get_effect(name), x) == (True, ""), name


def test_extended_model_refuses_missing_input_naming_it():
    with pytest.raises(InputError, match="needs input.*rpm"):
        get_ansatz("paper-offset+rpm").level(np.r_[BASE, 1.0, 3000.0], row())


def test_new_effect_registers_by_name():
    def term(q, x, d_ref, want_jac):
        s = np.asarray(x["d"], dtype=float) / 100.0
        return q[0] * s, (s[..., None] if want_jac else None)

    eff = effects.Effect(name="test_linear_d", params=("k_lin",), units=("dB",), start=(0.0,), reads=("d",),
                         bounds=((-5.0, 5.0),), needs=(("d", "no distance"),), apply=effects.additive(term))
    try:
        effects.register_effect(eff)
        a = get_ansatz("paper-offset+test_linear_d")
        assert a.params[-1] == "k_lin"
        assert delta("test_linear_d", [2.0], row(d=np.array([50.0])))[0] == pytest.approx(1.0)
    finally:
        effects._EFFECTS.pop("test_linear_d", None)
        from gisnoise.model import ansatz as model
        model._REGISTRY.pop("paper-offset+test_linear_d", None)
        model._REGISTRY.pop("paper+test_linear_d", None)
