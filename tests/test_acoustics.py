"""Acoustic preprocessing against the standards: IEC 61672-1, IEC 61260-1, ISO 9613-1."""

from __future__ import annotations

import numpy as np
import pytest

from gisnoise import acoustics
from gisnoise.acoustics import _filterbank
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
    # each column at its own temperature: ISO 9613-1 Table 1, 1 kHz, 50 %: 6.83 dB/km at 0 C, 4.66 dB/km at 20 C
    j = int(np.argmin(np.abs(f - 1000.0)))
    np.testing.assert_allclose(a[j] * 1000.0, [6.83, 4.66], atol=0.005 + 1e-9)
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


@pytest.mark.parametrize("kwargs, field, said", [
    ({"temperature_c": 293.15}, "temperature_c", "293.15 K is 20 deg C"),          # kelvin
    ({"pressure_kpa": 101325.0}, "pressure_kpa", "101325 Pa is 101.325 kPa"),     # pascal
    ({"pressure_kpa": 1013.25}, "pressure_kpa", "1013.25 hPa is 101.325 kPa"),    # hectopascal
])
def test_absorption_refuses_air_in_other_units_naming_the_unit(kwargs, field, said):
    # the same air in other units gave 0.0031 dB/m (pascal read as kPa) for the 0.0050 of ISO 9613-1 at 1 kHz,
    # 20 C, 70 %: no air near the ground is 293 deg C or 101325 kPa
    args = {"f_hz": 1000.0, "temperature_c": 20.0, "humidity_pct": 70.0, **kwargs}
    with pytest.raises(InputError, match=said) as err:
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


# -------------------------------------------------------------------- filter bank

G = 10.0 ** 0.3  # IEC 61260-1 base-10 octave ratio

# IEC 61260-1:2014 Table 1, class 1 acceptance limits on relative attenuation (dB)
# at the octave-band normalized frequencies Omega = G^x (x >= 0; the low side
# mirrors at 1/Omega).  Pass band up to the edge: min -0.4, max as listed; just
# outside the edge and beyond: min as listed, no max.
IEC61260_CLASS1_PASS_MAX = [(0.0, 0.4), (1 / 8, 0.5), (1 / 4, 0.7), (3 / 8, 1.4), (1 / 2, 5.3)]
IEC61260_CLASS1_PASS_MIN = -0.4
IEC61260_CLASS1_STOP_MIN = [(1 / 2, 1.2), (1.0, 16.6), (2.0, 40.5), (3.0, 60.0), (4.0, 70.0)]


def _third_octave_omega(x: float) -> float:
    """IEC 61260-1:2014 Formula (9): octave breakpoint G^x -> one-third-octave breakpoint."""
    return 1.0 + (G ** (1 / 6) - 1.0) / (G ** 0.5 - 1.0) * (G**x - 1.0)


def _relative_attenuation(bank, f_probe, j):
    """Relative attenuation (dB) of band j, whole decimation chain, re its mid-band attenuation."""
    gain = _filterbank.chain_response(bank, f_probe, [j])[:, 0]
    ref = _filterbank.chain_response(bank, bank.f_hz[j], [j])[0, 0]
    with np.errstate(divide="ignore"):
        return -20.0 * np.log10(gain / ref)


@pytest.mark.parametrize("fs", [44100.0, 48000.0, 96000.0])
def test_every_band_within_iec61260_class1_limits(fs):
    f = acoustics.third_octave_centres()
    f = f[f <= _filterbank.max_centre(fs)]
    assert f.size >= 29  # 25 Hz - 16 kHz at 44.1 kHz, up to 20 kHz at 48 kHz and above
    bank = _filterbank.design(fs, f)
    eps = 1e-7
    for j, fm in enumerate(f):
        checks = []  # (Omega, min, max)
        for x, mx in IEC61260_CLASS1_PASS_MAX:
            om = _third_octave_omega(x) * (1 - eps if x == 0.5 else 1.0)
            checks += [(om, IEC61260_CLASS1_PASS_MIN, mx), (1 / om, IEC61260_CLASS1_PASS_MIN, mx)]
        for x, mn in IEC61260_CLASS1_STOP_MIN:
            om = _third_octave_omega(x) * (1 + eps if x == 0.5 else 1.0)
            checks += [(om, mn, np.inf), (1 / om, mn, np.inf)]
        om = np.array([c[0] for c in checks])
        inside = om * fm < fs / 2
        att = _relative_attenuation(bank, om[inside] * fm, j)
        lo = np.array([c[1] for c in checks])[inside]
        hi = np.array([c[2] for c in checks])[inside]
        assert np.all(att >= lo) and np.all(att <= hi), (fm, om[inside][(att < lo) | (att > hi)])
        # beyond G^4: at least 70 dB everywhere up to Nyquist, aliasing of the decimation chain included
        om4 = _third_octave_omega(4.0)
        k = int(bank.level[j])
        fs_k = fs / 2**k
        alias = np.concatenate([m * fs_k + np.array([-fm, fm]) for m in range(1, int(fs / fs_k) + 1)])
        grid = np.concatenate([np.geomspace(1.0, fs / 2, 20000), alias])
        grid = grid[(grid > 0) & (grid < fs / 2) & ((grid >= om4 * fm) | (grid <= fm / om4))]
        far = _relative_attenuation(bank, grid, j)
        assert far.min() >= 70.0, (fm, grid[np.argmin(far)], far.min())


def _sine(f, fs, seconds, rms=1.0):
    t = np.arange(int(round(seconds * fs))) / fs
    return rms * np.sqrt(2.0) * np.sin(2 * np.pi * f * t)


def test_1khz_sine_of_1pa_reads_94db():
    # 1 Pa RMS = 20 lg(1 / 20e-6) = 93.98 dB re 20 uPa
    fs = 48000.0
    t, f, L = acoustics.band_levels(_sine(1000.0, fs, 3.0), fs)
    j = acoustics.band_name(f).index("L_1000")
    assert t.size == 24 and t[0] == pytest.approx(0.0625) and np.allclose(np.diff(t), 0.125)
    assert np.all(np.abs(L[1:, j] - 94.0) <= 0.1)
    assert np.all(L[1:, j] - np.delete(L[1:], j, axis=1).max(axis=1) > 20.0)  # other bands far below
    la = acoustics.overall_a_level(L[1:], f)
    assert np.all(np.abs(la - 94.0) <= 0.1)  # A(1 kHz) = 0


@pytest.mark.parametrize("fs, nominal", [(48000.0, 25), (48000.0, 160), (48000.0, 20000),
                                         (44100.0, 100), (44100.0, 16000)])
def test_sine_at_midband_reads_its_level_with_any_block_length(fs, nominal):
    fm = float(acoustics.exact_frequency(nominal))
    t, f, L = acoustics.band_levels(_sine(fm, fs, 4.0, rms=0.1), fs)  # 74 dB; 44.1 kHz: 5512.5-sample blocks
    j = acoustics.band_name(f).index(f"L_{nominal}")
    steady = L[8:-1, j]  # the filters settle at both ends of the recording
    assert 10 * np.log10(np.mean(10 ** (steady / 10))) == pytest.approx(73.98, abs=0.05)
    # a block holds 2 f block_s half periods of sin^2: mean square ripples by up to 1 / (4 pi f block_s)
    ripple = 10 * np.log10(1 + 1 / (4 * np.pi * fm * 0.125))
    assert np.all(np.abs(steady - 73.98) <= ripple + 0.05)


def test_chain_response_is_what_band_levels_measures():
    # sines at in-band, skirt and alias frequencies: measured relative levels equal the analytic chain gain
    fs = 48000.0
    f = acoustics.third_octave_centres()
    bank = _filterbank.design(fs, f)
    j = acoustics.band_name(f).index("L_100")  # decimated 64 times
    fs_k = fs / 2 ** int(bank.level[j])
    probes = np.array([100.0, 89.0, 112.0, 80.0, 125.0, 2 * fs_k - 100.0, fs_k + 100.0, 3 * fs_k - 112.0])
    gain = _filterbank.chain_response(bank, probes)[:, j]
    for fp, g in zip(probes, gain, strict=True):
        t, _, L = acoustics.band_levels(_sine(fp, fs, 6.0), fs)
        measured = 10 * np.log10(np.mean(10 ** (L[16:-1, j] / 10)))
        assert measured == pytest.approx(93.98 + 20 * np.log10(g), abs=0.05), fp


def _multisine(fs, period_s, psd, seed):
    """Periodic random-phase noise with exact power spectral density psd(f) (Pa^2/Hz), three periods."""
    n = int(round(period_s * fs))
    k = np.arange(n // 2 + 1)
    fk = k * fs / n
    amp = np.zeros(fk.size)
    amp[1:-1] = np.sqrt(psd(fk[1:-1]) * fs / n)  # power per bin = psd * df, one-sided
    phase = np.random.default_rng(seed).uniform(0, 2 * np.pi, fk.size)
    x = np.fft.irfft(amp * np.exp(1j * phase) * n / np.sqrt(2.0), n)
    return np.tile(x, 3)


def _steady_band_levels(x, fs, period_s):
    t, f, L = acoustics.band_levels(x, fs)
    second = (t >= period_s) & (t < 2 * period_s)  # the second of three periods: filters settled
    return f, 10 * np.log10(np.mean(10 ** (L[second] / 10), axis=0))


def test_pink_noise_gives_flat_band_levels():
    fs, period = 48000.0, 8.0
    x = _multisine(fs, period, lambda f: 1e-3 / f, seed=7)
    f, L = _steady_band_levels(x, fs, period)
    assert f.size == 30
    assert L.max() - L.min() <= 0.3
    assert np.max(np.abs(L - np.median(L))) <= 0.15


def test_white_noise_band_levels_equal_butterworth_effective_bandwidth():
    # white noise of PSD S in a Butterworth band-pass of order 2N and bandwidth B carries
    # S * B * pi / (2N sin(pi / 2N)) (noise bandwidth of the N-th order prototype), N = 4: +0.112 dB
    fs, period, S = 48000.0, 4.0, 1e-6
    x = _multisine(fs, period, lambda f: np.full_like(f, S), seed=11)
    f, L = _steady_band_levels(x, fs, period)
    n = _filterbank.ORDER
    bw = f * (G ** (1 / 6) - G ** (-1 / 6))
    expect = 10 * np.log10(S * bw * np.pi / (2 * n * np.sin(np.pi / (2 * n))) / acoustics.P_REF**2)
    low = f <= 10000.0  # above, the bilinear transform reshapes the skirts near Nyquist
    assert np.max(np.abs(L[low] - expect[low])) <= 0.05
    assert np.max(np.abs(L - expect)) <= 0.3


def test_group_delay_compensation_centres_tone_bursts():
    # energy centroid of each band's block levels for a 1 s tone burst at its mid-band frequency
    # stays at the burst centre (1.5 s): the 25 Hz band alone delays by about 0.17 s uncompensated
    fs = 48000.0
    x = np.zeros(int(3.5 * fs))
    t, f, _ = acoustics.band_levels(x[: int(fs)], fs)
    for nominal in (25, 100, 1000, 10000):
        fm = float(acoustics.exact_frequency(nominal))
        x[:] = 0.0
        x[int(fs): int(2 * fs)] = _sine(fm, fs, 1.0)
        t, f, L = acoustics.band_levels(x, fs)
        j = acoustics.band_name(f).index(f"L_{nominal}")
        e = 10 ** (L[:, j] / 10)
        assert np.sum(e * t) / np.sum(e) == pytest.approx(1.5, abs=0.01), nominal
        if nominal >= 100:  # (a 1 s burst spreads over +-1 Hz: wider than the 25 Hz band's skirts allow)
            assert np.sum(e) * 0.125 == pytest.approx(1.0 / 4e-10, rel=0.02)  # energy of 1 Pa RMS for 1 s


def test_chunked_processing_equals_one_pass():
    fs = 48000.0
    x = np.random.default_rng(5).standard_normal(int(2.3 * fs))
    f = acoustics.third_octave_centres(25, 20000)
    bank = _filterbank.design(fs, f)
    a = _filterbank.run(bank, x, 0.1 * fs, 23, chunk=1 << 12)
    b = _filterbank.run(bank, x, 0.1 * fs, 23, chunk=1 << 22)
    np.testing.assert_allclose(a, b, rtol=1e-9)


def test_band_levels_inputs():
    fs = 48000.0
    x = np.zeros(4800)
    t, f, L = acoustics.band_levels(x, fs)  # shorter than one block
    assert t.size == 0 and L.shape == (0, 30)
    t, f, L = acoustics.band_levels(np.zeros(int(fs)), fs, f_min=100, f_max=1000)
    assert acoustics.band_name(f)[0] == "L_100" and acoustics.band_name(f)[-1] == "L_1000"
    assert np.all(np.isneginf(L))  # digital silence
    _, f441, _ = acoustics.band_levels(np.zeros(44100), 44100.0)
    assert acoustics.band_name(f441)[-1] == "L_16000"
    cases = [
        ((np.zeros((10, 2)), fs), {}, "pressure_pa"),
        ((np.r_[0.0, np.nan, 0.0], fs), {}, "pressure_pa"),
        ((x, -1.0), {}, "fs_hz"),
        ((x, fs), {"block_s": 0.0}, "block_s"),
        ((x, 44100.0), {"f_max": 20000}, "fs_hz"),
        ((x, 50.0), {}, "fs_hz"),
    ]
    for args, kwargs, field in cases:
        with pytest.raises(InputError) as err:
            acoustics.band_levels(*args, **kwargs)
        assert err.value.field == field, (args, kwargs)


# --------------------------------------------------------------------------- WAV


@pytest.mark.parametrize("dtype", ["float32", "int16", "int32"])
def test_wav_round_trip_and_calibration(tmp_path, dtype):
    fs, sens = 48000.0, 0.05
    p = _sine(1000.0, fs, 1.0, rms=2.0)  # 100 dB, 0.14 V peak
    path = tmp_path / "m1.wav"
    acoustics.write_wav(path, p, fs, sens, dtype=dtype)
    volts, rate = acoustics.read_wav(path)
    assert rate == fs
    np.testing.assert_allclose(volts, p * sens, atol=2.0 ** -15)
    pa, _ = acoustics.read_wav(path, sens)
    np.testing.assert_allclose(pa, acoustics.calibrate(volts, sens))
    t, f, L = acoustics.wav_band_levels(path, sens, expected_fs_hz=fs)
    t2, f2, L2 = acoustics.band_levels(pa, fs)
    np.testing.assert_allclose(L, L2, atol=1e-6)
    j = acoustics.band_name(f).index("L_1000")
    assert np.all(np.abs(L[1:, j] - 99.98) <= 0.1)


def test_wav_errors_name_file_and_field(tmp_path):
    from scipy.io import wavfile

    stereo = tmp_path / "stereo.wav"
    wavfile.write(stereo, 48000, np.zeros((100, 2), dtype=np.int16))
    mono = tmp_path / "mono.wav"
    wavfile.write(mono, 44100, np.zeros(100, dtype=np.float32))
    cases = [
        (lambda: acoustics.read_wav(stereo), "channels", "stereo.wav"),
        (lambda: acoustics.read_wav(mono, expected_fs_hz=48000), "sample_rate", "mono.wav"),
        (lambda: acoustics.wav_band_levels(mono, 0.05, expected_fs_hz=48000), "sample_rate", "mono.wav"),
        (lambda: acoustics.read_wav(tmp_path / "missing.wav"), "path", "missing.wav"),
        (lambda: acoustics.read_wav(mono, 0.0), "sensitivity_v_per_pa", ""),
        (lambda: acoustics.write_wav(tmp_path / "c.wav", np.full(10, 100.0), 48000, 0.05, dtype="int16"),
         "pressure_pa", ""),
    ]
    for call, field, name in cases:
        with pytest.raises(InputError) as err:
            call()
        assert err.value.field == field
        assert name in str(err.value) and "\n" not in str(err.value)


def test_progress_reports_fractions_and_can_cancel():
    from gisnoise.errors import Cancelled

    fs = 48000.0
    x = np.zeros(int(5 * fs))
    seen = []
    acoustics.band_levels(x, fs, progress=seen.append)
    assert len(seen) > 1 and np.all(np.diff(seen) > 0) and seen[-1] == pytest.approx(1.0)

    def stop(fraction):
        raise Cancelled("stopped", field="progress")

    with pytest.raises(Cancelled):
        acoustics.band_levels(x, fs, progress=stop)


@pytest.mark.parametrize("dtype", ["int16", "int32", "float32"])
def test_a_clipped_recording_is_refused_not_read_too_quiet(tmp_path, dtype):
    """A recorder driven past digital full scale flattens its peaks: the band levels of such a
    block are too low (a 1 kHz sine of peak 1.5 x full scale keeps a fundamental 20 log10(a1 / 1.5) =
    -2.2 dB below the true one, a1 its Fourier amplitude),
    so a clipped file must be refused naming the file, the field and the time, never read."""
    from scipy.io import wavfile

    fs = 48000
    t = np.arange(int(2.0 * fs)) / fs
    v = 0.05 * np.sin(2 * np.pi * 1000.0 * t)
    v[fs:fs + fs // 2] *= 30.0  # 1.5 x full scale for 0.5 s from t = 1 s
    v = np.clip(v, -1.0, 1.0)
    if dtype == "float32":
        data = v.astype(np.float32)
    else:
        full = 2 ** (8 * np.dtype(dtype).itemsize - 1)
        data = np.clip(np.round(v * full), -full, full - 1).astype(dtype)
    path = tmp_path / "clipped.wav"
    wavfile.write(path, fs, data)
    for call in (lambda: acoustics.read_wav(path, 0.05), lambda: acoustics.wav_band_levels(path, 0.05)):
        with pytest.raises(InputError) as err:
            call()
        msg = str(err.value)
        assert err.value.field == "samples"
        assert "clipped.wav" in msg and "full scale" in msg and "\n" not in msg
        assert "1.000 s" in msg  # the first clipped sample
    # the same signal below full scale reads
    wavfile.write(path, fs, (0.5 * v).astype(np.float32))
    acoustics.read_wav(path, 0.05)
    acoustics.wav_band_levels(path, 0.05)


# --------------------------------------------------------------------------- dropouts


def _dropout_wav(path, fs, seconds, gaps, dtype="float32", value=0.0):
    """A 1 kHz sine of 1 Pa rms (94.0 dB) at 0.05 V/Pa, its samples set to ``value`` over each ``(t0, t1)``."""
    from scipy.io import wavfile

    v = 0.05 * _sine(1000.0, fs, seconds)
    for a, b in gaps:
        v[int(round(a * fs)):int(round(b * fs))] = value
    data = v.astype(np.float32) if dtype == "float32" else np.round(v * 32768).astype(np.int16)
    wavfile.write(path, fs, data)


@pytest.mark.parametrize("dtype", ["float32", "int16"])
def test_a_dropout_is_refused_naming_the_file_and_its_times(tmp_path, dtype):
    """1 s of exact zeros (3-4 s) in a 94 dB 1 kHz recording at 16 kHz: no sound holds one value for 10 ms,
    so the blocks there would hold the filters' decay (70.5, 0.8, ... -47.6 dB(A) before), never a level.
    Refused, one line naming the file, 'dropout' and the stretch 3.000-4.000 s."""
    from gisnoise.errors import RecordingError

    path = tmp_path / "gap.wav"
    _dropout_wav(path, 16000, 10.0, [(3.0, 4.0)], dtype)
    for call in (lambda: acoustics.read_wav(path, 0.05), lambda: acoustics.wav_band_levels(path, 0.05)):
        with pytest.raises(RecordingError) as err:
            call()
        msg = str(err.value)
        assert err.value.field == "samples" and "\n" not in msg
        assert "gap.wav" in msg and "dropout" in msg and "3.000-4.000 s" in msg and "exactly 0" in msg
        # 3-4 s: 16000 samples (one more where the int16 sine's own zero at 4 s follows them)
        np.testing.assert_allclose(err.value.spans, [(3.0, 4.0)], atol=1.0 / 16000 + 1e-12)
    # a recorder holding its last value is a dropout too, named by that value (0.25 V)
    _dropout_wav(path, 16000, 10.0, [(3.0, 4.0)], "float32", value=0.25)
    with pytest.raises(RecordingError, match=r"one value \(0\.25 V\) from 3\.000 s"):
        acoustics.wav_band_levels(path, 0.05)


def test_a_recording_of_zeros_only_is_refused(tmp_path):
    """An all-zero WAV gave LA = -inf: it holds no sound, and there is no stretch to exclude (no spans)."""
    from scipy.io import wavfile

    from gisnoise.errors import RecordingError

    path = tmp_path / "zeros.wav"
    wavfile.write(path, 48000, np.zeros(96000, dtype=np.int16))
    for call in (lambda: acoustics.read_wav(path), lambda: acoustics.wav_band_levels(path, 0.05)):
        with pytest.raises(RecordingError, match=r"zeros\.wav: the recording holds no sound: all its 96000 samples "
                                                 r"\(2 s\) are exactly 0") as err:
            call()
        assert err.value.spans == ()


def test_the_dropout_length_rule(tmp_path):
    """Shorter than DROPOUT_S (10 ms) of zeros reads; 10 ms is refused.  A 1 kHz sine at 48 kHz repeats no value
    twice in a row (48 samples a period), so exactly the inserted zeros form the stretch."""
    fs = 48000
    assert acoustics.DROPOUT_S == 0.010
    path = tmp_path / "short.wav"
    _dropout_wav(path, fs, 1.0, [(0.5, 0.5 + 479 / fs)])  # samples 24000-24478: 9.98 ms
    acoustics.read_wav(path, 0.05)
    _dropout_wav(path, fs, 1.0, [(0.5, 0.5 + 481 / fs)])  # samples 24000-24480: 10.02 ms
    with pytest.raises(InputError, match="dropout"):
        acoustics.read_wav(path, 0.05)


def test_a_dropout_across_a_chunk_of_the_scan_is_one_stretch(tmp_path, monkeypatch):
    """Long files are screened chunk by chunk (here 1000 samples): a stretch crossing chunk boundaries is found
    whole.  At 16 kHz the 1 kHz sine is zero at every 8th sample only, so the zeros set are the stretch."""
    from gisnoise.acoustics import wav as wavmod
    from gisnoise.errors import RecordingError

    monkeypatch.setattr(wavmod, "_SCAN_CHUNK", 1000)
    fs = 16000
    path = tmp_path / "gap.wav"
    _dropout_wav(path, fs, 4.0, [(32010 / fs, 47990 / fs)])  # samples 32010-47989, over 17 chunks
    with pytest.raises(RecordingError, match=r"from 2\.001 s \(sample 32010\), over 2\.001-2\.999 s") as err:
        acoustics.read_wav(path, 0.05)
    assert err.value.spans == ((32010 / fs, 47990 / fs),)
    _dropout_wav(path, fs, 4.0, [(31950 / fs, 32110 / fs)])  # 160 samples (10 ms) across sample 32000
    with pytest.raises(RecordingError, match="dropout"):
        acoustics.read_wav(path, 0.05)
    _dropout_wav(path, fs, 4.0, [(31950 / fs, 32109 / fs)])  # 159 samples
    acoustics.read_wav(path, 0.05)


def test_an_excluded_dropout_leaves_its_blocks_out_and_the_rest_reads_94_db(tmp_path):
    """With the stretch in ``excluded_s``, the blocks whose levels depend on it (from the bands' largest group
    delay before it to the filters' 60 dB decay after it) are NaN, and every other block is sound: 1 Pa rms at
    1 kHz, 20 lg(1 / 20e-6) = 94.0 dB, in the 1 kHz band and A-weighted (A(1 kHz) = 0)."""
    fs = 16000
    path = tmp_path / "gap.wav"
    _dropout_wav(path, fs, 10.0, [(3.0, 4.0)])
    t, f, L = acoustics.wav_band_levels(path, 0.05, excluded_s=[(2.9, 4.1)])
    out = np.isnan(L).any(axis=1)
    assert np.all(np.isnan(L[out]))  # a block is left out whole
    gone = t[out]
    assert gone.min() < 3.0 and gone.max() > 4.0 + 1.0  # the decay of the 25 Hz band's filters: over 1 s
    assert np.all(np.diff(gone) == pytest.approx(0.125))  # one stretch of blocks
    la = np.asarray(acoustics.overall_a_level(L[~out], f))
    steady = t[~out] > 0.5  # the first blocks hold the filters' start from rest
    np.testing.assert_allclose(la[steady], 20 * np.log10(1 / 20e-6), atol=0.1)
    # an exclusion that does not hold the whole stretch still refuses it
    with pytest.raises(InputError, match="3.000-4.000 s"):
        acoustics.wav_band_levels(path, 0.05, excluded_s=[(3.2, 4.1)])


# --------------------------------------------------------------------------- sample rates below 44.1 kHz


def _pink_volts(fs, seconds, sens=0.05, seed=3):
    """Pink noise of 1 Pa rms over the bands 25 Hz-20 kHz (22.4 Hz-22.4 kHz; equal energy per one-third octave,
    power spectral density ~ 1/f) as a recorder at ``fs`` takes it: the same sinusoids (amplitude, phase) for
    every rate, up to its Nyquist frequency."""
    n48 = int(48000 * seconds)
    f48 = np.fft.rfftfreq(n48, 1 / 48000)
    phase = np.random.default_rng(seed).uniform(0, 2 * np.pi, f48.size)
    lo, hi = 1000 * 10 ** (-1.5 - 0.05), 1000 * 10 ** (1.3 + 0.05)
    a2 = np.where((f48 >= lo) & (f48 < hi), 1 / np.maximum(f48, 1.0), 0.0)
    a2 *= 2.0 / a2.sum()  # sum of a^2 / 2 = 1 Pa^2
    n = int(fs * seconds)
    x = np.fft.irfft(np.sqrt(a2[:n // 2 + 1]) * n / 2 * np.exp(1j * phase[:n // 2 + 1]), n)
    return x * sens


def _pink_table_loss(top_nominal):
    """A-weighted level a pink spectrum loses without the bands above ``top_nominal``, dB, from the A-weighting
    of IEC 61672-1 Table 3 at the 30 bands 25 Hz-20 kHz (equal energy in each)."""
    rows = [(f, a) for f, a in IEC61672_TABLE3_A if f >= 25]
    w = np.array([10 ** (a / 10) for _, a in rows])
    kept = np.array([f <= top_nominal for f, _ in rows])
    return 10 * np.log10(w.sum() / w[kept].sum())


def test_a_pink_recording_below_44k_loses_the_a_weighted_energy_of_its_missing_bands(tmp_path):
    """Pink noise recorded at 48, 16 and 8 kHz (the same sound below each Nyquist frequency): the bands stop at
    20 kHz, 6.3 kHz and 3.15 kHz, and the A-weighted level reads lower by the A-weighted energy of the missing
    bands, IEC 61672-1 Table 3: 0.61 dB at 16 kHz, 1.85 dB at 8 kHz (0.6 and 1.8 dB measured on synthesized pink noise);
    pink_band_loss_db states it."""
    from scipy.io import wavfile

    la = {}
    for fs, top in ((48000, "L_20000"), (16000, "L_6300"), (8000, "L_3150")):
        path = tmp_path / f"pink{fs}.wav"
        wavfile.write(path, fs, _pink_volts(fs, 10.0).astype(np.float32))
        t, f, L = acoustics.wav_band_levels(path, 0.05)
        assert acoustics.band_name(f[-1]) == top
        blocks = np.asarray(acoustics.overall_a_level(L, f))[t > 1.5]  # past the 25 Hz filters' start
        la[fs] = 10 * np.log10(np.mean(10 ** (blocks / 10)))
    for fs, top in ((16000, 6300), (8000, 3150)):
        expected = _pink_table_loss(top)
        assert la[48000] - la[fs] == pytest.approx(expected, abs=0.05)
        assert float(acoustics.pink_band_loss_db(top)) == pytest.approx(expected, abs=0.02)
    assert _pink_table_loss(6300) == pytest.approx(0.61, abs=0.01)
    assert _pink_table_loss(3150) == pytest.approx(1.85, abs=0.01)
    assert float(acoustics.pink_band_loss_db(20000)) == 0.0
