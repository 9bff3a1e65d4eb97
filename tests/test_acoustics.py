"""Acoustic preprocessing against the standards: IEC 61672-1, IEC 61260-1, ISO 9613-1."""

from __future__ import annotations

import numpy as np
import pytest

from gisnoise import _filterbank, acoustics
from gisnoise.errors import InputError

# --------------------------------------------------------------------------- A-weighting

# IEC 61672-1:2013 Table 3, column "A": frequency weighting (dB) at the nominal
# one-third-octave frequencies 10 Hz - 20 kHz.  The standard computes the table
# from Annex E at the exact base-10 frequencies fm = 1000 * 10^(x/10) and rounds
# to 0.1 dB.
IEC61672_TABLE3_A = [
    (10, -70.4), (12.5, -63.4), (16, -56.7), (20, -50.5), (25, -44.7), (31.5, -39.4),
    (40, -34.6), (50, -30.2), (63, -26.2), (80, -22.5), (100, -19.1), (125, -16.1),
    (160, -13.4), (200, -10.9), (250, -8.6), (315, -6.6), (400, -4.8), (500, -3.2),
    (630, -1.9), (800, -0.8), (1000, 0.0), (1250, 0.6), (1600, 1.0), (2000, 1.2),
    (2500, 1.3), (3150, 1.2), (4000, 1.0), (5000, 0.5), (6300, -0.1), (8000, -1.1),
    (10000, -2.5), (12500, -4.3), (16000, -6.6), (20000, -9.3),
]


def test_a_weighting_equals_iec61672_table3():
    nominal = np.array([row[0] for row in IEC61672_TABLE3_A], dtype=float)
    table = np.array([row[1] for row in IEC61672_TABLE3_A])
    exact = acoustics.exact_frequency(nominal)
    got = acoustics.a_weighting(exact)
    assert np.max(np.abs(got - table)) <= 0.1
    # the table is the analytic weighting rounded to 0.1 dB: within half a step
    assert np.max(np.abs(got - table)) <= 0.05 + 1e-3


def test_a_weighting_normalised_at_1khz_and_broadcasts():
    assert float(acoustics.a_weighting(1000.0)) == pytest.approx(0.0, abs=1e-3)
    f = np.array([[100.0, 1000.0], [2000.0, 4000.0]])
    assert acoustics.a_weighting(f).shape == (2, 2)
    assert np.isneginf(acoustics.a_weighting(0.0))
    with pytest.raises(InputError) as err:
        acoustics.a_weighting(-5.0)
    assert err.value.field == "f_hz"


# ---------------------------------------------------------------------- band naming


def test_third_octave_centres_are_exact_base10_midbands():
    f = acoustics.third_octave_centres()
    assert f.size == 30
    np.testing.assert_allclose(f, 1000.0 * 10.0 ** (np.arange(-16, 14) / 10.0), rtol=1e-12)
    # IEC 61260-1: adjacent mid-band frequencies differ by G^(1/3), G = 10^(3/10)
    np.testing.assert_allclose(f[1:] / f[:-1], 10.0 ** 0.1, rtol=1e-12)
    assert acoustics.third_octave_centres(1000, 1000).tolist() == [1000.0]
    with pytest.raises(InputError) as err:
        acoustics.third_octave_centres(100, 50)
    assert err.value.field == "f_max"


def test_band_names_round_trip_nominal_and_exact():
    f = acoustics.third_octave_centres(10, 20000)
    names = acoustics.band_name(f)
    assert names[:4] == ["L_10", "L_12.5", "L_16", "L_20"]
    assert "L_160" in names and "L_1250" in names and "L_31.5" in names and names[-1] == "L_20000"
    back = np.array([acoustics.band_frequency(n) for n in names])
    np.testing.assert_allclose(back, f, rtol=1e-12)
    assert acoustics.band_name(158.489) == "L_160"
    assert acoustics.nominal_frequency(1258.925).tolist() == 1250.0
    for bad in ("L_150", "L160", "L_", "LA", "L_-160"):
        assert not acoustics.is_band_name(bad)
        with pytest.raises(InputError) as err:
            acoustics.band_frequency(bad)
        assert err.value.field == bad


# ------------------------------------------------------------------- mount, speed


def test_mount_correction():
    assert acoustics.mount_correction("ground_plate") == -6.0
    assert acoustics.mount_correction("free_field") == 0.0
    assert acoustics.mount_correction("pole") == 0.0
    with pytest.raises(InputError) as err:
        acoustics.mount_correction("tripod")
    assert err.value.field == "mount"
    assert "tripod" in str(err.value)


def test_speed_of_sound():
    # c = 331.3 sqrt(1 + T/273.15): 331.3 m/s at 0 C, 343.2 m/s at 20 C
    assert float(acoustics.speed_of_sound(0.0)) == pytest.approx(331.3, abs=1e-12)
    assert float(acoustics.speed_of_sound(20.0)) == pytest.approx(343.21, abs=0.01)
    with pytest.raises(InputError):
        acoustics.speed_of_sound(-300.0)


# --------------------------------------------------------------------- ISO 9613-1

# ISO 9613-1:1993 Table 1: pure-tone atmospheric-absorption attenuation coefficient,
# dB/km, at 101.325 kPa, printed to three significant figures and computed (Note 5)
# at the exact mid-band frequencies of the nominal frequencies listed.
# (temperature C, relative humidity %, nominal frequency Hz, alpha dB/km)
ISO9613_1_TABLE1 = [
    (-20, 10, 50, 0.589),
    (-20, 50, 1000, 9.14),
    (-20, 70, 8000, 27.8),
    (-20, 100, 10000, 47.0),
    (0, 10, 50, 0.302),
    (0, 50, 1000, 6.83),
    (0, 20, 2000, 34.6),
    (0, 100, 6300, 88.0),
    (5, 50, 1000, 5.08),
    (10, 70, 1000, 3.66),
    (10, 50, 4000, 46.7),
    (15, 50, 1000, 4.16),
    (15, 100, 10000, 105.0),
    (20, 50, 1000, 4.66),
    (20, 70, 1000, 4.98),
    (20, 50, 2000, 9.86),
    (25, 50, 1000, 5.68),
    (25, 100, 2000, 11.4),
    (30, 50, 1000, 7.03),
    (30, 50, 4000, 24.5),
    (35, 50, 1000, 8.43),
    (40, 50, 1000, 9.52),
    (45, 50, 800, 7.16),
    (50, 50, 2000, 24.8),
]


@pytest.mark.parametrize("temperature, humidity, nominal, table", ISO9613_1_TABLE1)
def test_absorption_reproduces_iso9613_1_table1(temperature, humidity, nominal, table):
    fm = float(acoustics.exact_frequency(nominal))
    got = float(acoustics.atmospheric_absorption(fm, temperature, humidity, 101.325)) * 1000.0
    half_digit = 0.5 * 10.0 ** (np.floor(np.log10(table)) - 2)  # rounding of 3 significant figures
    assert abs(got - table) <= half_digit + 1e-9


def test_absorption_pressure_and_broadcast():
    f = acoustics.third_octave_centres(50, 10000)
    a = acoustics.atmospheric_absorption(f[:, None], np.array([0.0, 20.0]), 50.0)
    assert a.shape == (f.size, 2)
    assert np.all(np.diff(a[:, 1]) > 0)  # grows with frequency
    # classical (translational) absorption dominates at very high frequency: ~ 1/p
    hi = 1e6
    ratio = acoustics.atmospheric_absorption(hi, 20.0, 50.0, 50.0) / acoustics.atmospheric_absorption(hi, 20.0, 50.0)
    assert float(ratio) == pytest.approx(101.325 / 50.0, rel=0.02)
    for kwargs, field in (({"humidity_pct": 120.0}, "humidity_pct"), ({"pressure_kpa": 0.0}, "pressure_kpa")):
        args = {"f_hz": 1000.0, "temperature_c": 20.0, "humidity_pct": 50.0, **kwargs}
        with pytest.raises(InputError) as err:
            acoustics.atmospheric_absorption(**args)
        assert err.value.field == field


def test_absorption_correction_only_where_band_clears_background():
    f = np.array([500.0, 1000.0, 4000.0])
    alpha = acoustics.atmospheric_absorption(f, 15.0, 60.0, 100.0)
    L = np.array([[70.0, 55.0, 49.9], [np.nan, 80.0, 80.0]])
    bg = np.array([40.0, 40.0, 40.0])
    d = np.array([100.0, 300.0])
    Lc, ok = acoustics.absorption_correction(L, f, d, 15.0, 60.0, 100.0, background_db=bg)
    assert ok.tolist() == [[True, True, False], [False, True, True]]
    np.testing.assert_allclose(Lc[0, :2], L[0, :2] + alpha[:2] * 100.0)
    assert Lc[0, 2] == 49.9 and np.isnan(Lc[1, 0])
    np.testing.assert_allclose(Lc[1, 1:], 80.0 + alpha[1:] * 300.0)

    # the overall level gains exactly the absorbed energy of the corrected bands
    la = acoustics.overall_a_level(np.nan_to_num(L, nan=-np.inf), f)
    lac = acoustics.absorption_corrected_level(la, np.nan_to_num(L, nan=-np.inf), f, d, 15.0, 60.0, 100.0,
                                               background_db=bg)
    expect = acoustics.overall_a_level(np.where(ok, Lc, np.nan_to_num(L, nan=-np.inf)), f)
    np.testing.assert_allclose(lac, expect, atol=1e-9)
    with pytest.raises(InputError) as err:
        acoustics.absorption_correction(L, f, d, 15.0, 60.0, background_db=[np.nan, 1.0, 1.0])
    assert err.value.field == "background_db"


def test_background_levels_is_low_percentile():
    rng = np.random.default_rng(3)
    L = np.column_stack([np.r_[np.full(90, 40.0), np.full(10, 80.0)], rng.uniform(0, 100, 100)])
    bg = acoustics.background_levels(L, 10.0)
    assert bg[0] == 40.0
    assert bg[1] == pytest.approx(np.percentile(L[:, 1], 10.0))


# --------------------------------------------------------------- overall A level


def test_overall_a_level_energy_sum_of_weighted_bands():
    f = acoustics.third_octave_centres(100, 4000)
    L = np.full(f.size, 60.0)
    expect = 10 * np.log10(np.sum(10 ** ((60.0 + acoustics.a_weighting(f)) / 10)))
    assert float(acoustics.overall_a_level(L, f)) == pytest.approx(expect, abs=1e-12)
    # a single 1 kHz band: unchanged; silence everywhere: -inf; a NaN band: NaN
    assert float(acoustics.overall_a_level([[70.0]], [1000.0])[0]) == pytest.approx(70.0, abs=1e-3)
    assert np.isneginf(acoustics.overall_a_level(np.full(3, -np.inf), f[:3]))
    assert np.isnan(acoustics.overall_a_level([60.0, np.nan], f[:2]))
    with pytest.raises(InputError):
        acoustics.overall_a_level(np.zeros((4, 3)), f[:2])
