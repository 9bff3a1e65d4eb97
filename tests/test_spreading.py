"""The spherical-spreading rule of ``campaign check`` (``gisnoise.measure.spreading``) on analytic tables."""

from __future__ import annotations

import numpy as np
import pytest

from gisnoise.errors import InputError
from gisnoise.measure import Samples, spreading_outliers

BLOCK_S = 0.125
T = np.arange(0.0, 120.0, BLOCK_S)      # reception time, s
D_TRUE = np.hypot(50.0, 25.0 * (T - 60.0))  # a fly-by at 25 m/s, 50 m from every microphone at t = 60 s
# spherical spreading from 70 dB(A) at 40 m, the drone's directivity turning by +-2 dB as it passes
LEVEL = 70.0 - 20.0 * np.log10(D_TRUE / 40.0) + 2.0 * np.cos(T / 3.0)


def event_db(t0: float, duration_s: float, peak_dba: float) -> np.ndarray:
    """A transient sound, ``peak_dba * sin^2(pi (t - t0) / duration_s)`` in energy, per block of T."""
    u = (T - t0) / duration_s
    return np.where((u > 0) & (u < 1), np.sin(np.pi * np.clip(u, 0, 1)) ** 2, 0.0) * 10.0 ** (peak_dba / 10.0)


def flyby_table(listed_factor: dict[str, float], extra_energy: dict[str, np.ndarray] | None = None) -> Samples:
    """Every microphone hears the same fly-by (LEVEL, plus ``extra_energy``); its listed distance is the true one
    times ``listed_factor[mic]``."""
    extra_energy = extra_energy or {}
    mics = list(listed_factor)
    n, k = T.size, len(mics)
    level = np.concatenate([10.0 * np.log10(10.0 ** (LEVEL / 10.0) + extra_energy.get(m, 0.0)) for m in mics])
    d = np.concatenate([D_TRUE * listed_factor[m] for m in mics])
    z = np.zeros(n * k)
    return Samples(mic=np.repeat(mics, n), flight=np.full(n * k, "f1"), t_r=np.tile(T, k), t_e=np.tile(T, k),
                   level=level, d=d, phi=z, theta=z, power_w=z + 3000.0, phase=np.full(n * k, "horizontal"),
                   roll=z, pitch=z, yaw=z, uav_enu=np.zeros((n * k, 3)), mic_enu=np.zeros((n * k, 3)),
                   vel_enu=np.zeros((n * k, 3)), valid=np.ones(n * k, bool), mask_reason=np.full(n * k, ""))


@pytest.mark.parametrize("factor", [12.0, 1.0 / 12.0])
def test_a_microphone_listed_twelve_times_too_far_or_near_is_named_by_its_factor(factor):
    """c's listed distance is 12 times (or a twelfth of) the true one at every sample: its source level from the
    listed position is 20 lg 12 = 21.6 dB off the others', exactly, though b hears an unmasked 85 dB(A) sound of 4 s
    while the drone is 1 km away (five microphones: b's and c's values are not the median)."""
    s = flyby_table({"a": 1.0, "b": 1.0, "c": factor, "d": 1.0, "e": 1.0}, {"b": event_db(18.0, 4.0, 85.0)})
    found = spreading_outliers(s)
    assert [(m, f) for m, f, *_ in found] == [("c", "f1")]
    mic, flight, level, dist, off = found[0]
    assert off == pytest.approx(20.0 * np.log10(factor), abs=1e-9)
    assert level + 20.0 * np.log10(dist) - off == pytest.approx(
        float(np.median(LEVEL + 20.0 * np.log10(D_TRUE))), abs=3.0)  # the drone's source level, within directivity


def test_eight_times_is_within_the_limit():
    """20 lg 8 = 18.1 dB: within OUTLIER_DB (20 dB, tenfold), the spread of a drone's directivity and the ground is
    not taken for a wrong position."""
    s = flyby_table({"a": 1.0, "b": 8.0, "c": 1.0})
    assert spreading_outliers(s) == []
    [(_, _, _, _, off)] = [x for x in spreading_outliers(s, limit_db=-np.inf) if x[0] == "b"]
    assert off == pytest.approx(20.0 * np.log10(8.0), abs=1e-9)


@pytest.mark.parametrize("extra", [
    event_db(18.0, 4.0, 85.0),                                   # an 85 dB(A) sound of 4 s, the drone 1 km off
    event_db(100.0, 8.0, 85.0),                                  # one of 8 s, the drone 1 km off on the other side
    np.where(np.arange(T.size) == 200, 10.0 ** 11.0, 0.0),       # one block at 110 dB(A)
])
def test_a_short_loud_sound_at_one_microphone_names_none(extra):
    """Three microphones hearing the same fly-by, one of them also a loud sound the reader did not mask.  Its
    loudest sample puts the source tens of dB off (the rule on one sample, window_s one block, names it); over the
    loudest WINDOW_S (20 s) the sound is a minority and the median is the drone's."""
    s = flyby_table({"a": 1.0, "b": 1.0, "c": 1.0}, {"b": extra})
    one_block = spreading_outliers(s, window_s=BLOCK_S)
    assert [m for m, *_ in one_block] == ["b"] and one_block[0][4] > 30.0
    assert spreading_outliers(s) == []
    [(_, _, _, _, off)] = [x for x in spreading_outliers(s, limit_db=-np.inf) if x[0] == "b"]
    assert 0.0 <= off < 4.0  # the sound displaces the window's quietest drone samples: b's median rises a little


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "20"])
def test_a_bad_window_is_refused(bad):
    with pytest.raises(InputError, match=r"^window_s must be a positive number of seconds, got "):
        spreading_outliers(flyby_table({"a": 1.0, "b": 1.0, "c": 1.0}), window_s=bad)
