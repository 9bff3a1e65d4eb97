"""Audio to one-third-octave band levels: throughput as a multiple of real time.

48 kHz white noise through ``gisnoise.acoustics.band_levels`` (30 bands,
25 Hz - 20 kHz, 0.125 s blocks, multirate: low bands run decimated) against a
naive baseline measured in the same run: the same band-pass designs, every band
filtered at the full sample rate, then squared and summed per block.  Prints
seconds of audio per second of compute for both (wall clock, and CPU time of
this process: what one dedicated core takes when the machine is shared), their
ratio, and how far the two agree (mean band level over the steady blocks).  One
thread: numpy/scipy filtering here is single-threaded.

    python bench/bench_audio.py [seconds_of_audio]
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy import signal

from gisnoise import acoustics
from gisnoise.acoustics import _filterbank


def naive_band_levels(x: np.ndarray, fs: float, block_s: float, f_hz: np.ndarray) -> np.ndarray:
    """Every band filtered at full rate (no decimation), block mean square in dB."""
    block = int(round(block_s * fs))
    n_blocks = x.size // block
    starts = np.arange(n_blocks) * block
    out = np.empty((n_blocks, f_hz.size))
    for j, fm in enumerate(f_hz):
        lo, hi = acoustics.band_edges(fm)
        sos = signal.butter(_filterbank.ORDER, [float(lo), float(hi)], btype="bandpass", fs=fs, output="sos")
        y = signal.sosfilt(sos, x)
        np.square(y, out=y)
        out[:, j] = np.add.reduceat(y[: n_blocks * block], starts) / block
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(out / acoustics.P_REF**2)


def _best(fn, repeat: int):
    """Smallest wall and CPU time of ``repeat`` runs (the machine may be shared) and the result.

    CPU time (this process only) is what one dedicated core would take when
    other jobs share the machine.
    """
    wall, cpu, out = float("inf"), float("inf"), None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return (wall, cpu), out


def main(seconds: float = 60.0) -> None:
    fs, block_s = 48000.0, 0.125
    x = np.random.default_rng(0).standard_normal(int(seconds * fs)) * 0.1
    acoustics.band_levels(x[: int(fs)], fs, block_s)  # design once (cached), warm up
    t_fast, (t, f, L) = _best(lambda: acoustics.band_levels(x, fs, block_s), 3)
    t_naive, L_naive = _best(lambda: naive_band_levels(x, fs, block_s, f), 1)
    steady = slice(8, -8)
    dev = np.abs(10 * np.log10(np.mean(10 ** (L[steady] / 10), axis=0))
                 - 10 * np.log10(np.mean(10 ** (L_naive[steady] / 10), axis=0)))
    print(f"audio: {seconds:g} s at {fs:g} Hz, {f.size} bands {f[0]:.1f} Hz - {f[-1]:.0f} Hz, blocks {block_s} s")
    for name, (wall, cpu) in (("multirate band_levels", t_fast), ("naive full-rate bank ", t_naive)):
        print(f"{name} : wall {wall:7.3f} s = {seconds / wall:6.1f} x real time; "
              f"CPU {cpu:7.3f} s = {seconds / cpu:6.1f} x real time")
    print(f"speed-up (same run)   : wall {t_naive[0] / t_fast[0]:5.2f} x, CPU {t_naive[1] / t_fast[1]:5.2f} x")
    print(f"mean band level, multirate vs naive: max |diff| {dev.max():.3f} dB "
          f"(bands <= 10 kHz: {dev[f <= 10000].max():.3f} dB)")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 60.0)
