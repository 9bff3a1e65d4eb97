"""Audio of band levels: a pressure signal whose every block holds given one-third-octave band levels.

WAV files are synthesized block by block as random-phase multisines on the block's
FFT grid, so every block holds exactly the target energy in every band.
"""

from __future__ import annotations

import numpy as np

from gisnoise.acoustics import band_edges
from gisnoise.errors import ScenarioError

__all__ = ["synthesize_wav"]


def synthesize_wav(bands_db: np.ndarray, f_mid: np.ndarray, block_s: float, fs_hz: int, rng: np.random.Generator,
                   *, fade_s: float = 0.002) -> np.ndarray:
    """Pressure signal (Pa) whose every block holds the given one-third-octave band levels.

    Each block is a random-phase multisine on the block's FFT grid (bins ``k / block_s``);
    the bins inside a band share its energy equally and have the same phase in every
    block, so the signal is continuous and block ``j`` holds exactly the energy of
    ``bands_db[j]`` (re 20 uPa) apart from a linear amplitude cross-fade of
    ``fade_s`` s at each block boundary.

    Parameters
    ----------
    bands_db : ndarray, shape (n_blocks, n_bands)
        Target band levels, dB re 20 uPa.
    f_mid : ndarray, shape (n_bands,)
        Exact mid-band frequencies, Hz (base-10 one-third octaves).
    block_s : float
        Block length, s; ``fs_hz * block_s`` must be whole.
    fs_hz : int
        Sample rate, Hz.
    rng : numpy.random.Generator
        Source of the bin phases.
    """
    nb, nbands = bands_db.shape
    n = int(round(fs_hz * block_s))
    fk = np.arange(n // 2 + 1) / block_s
    lo, hi = band_edges(f_mid)
    band_of = np.full(len(fk), -1)
    for b in range(nbands):
        band_of[(fk >= lo[b]) & (fk < hi[b]) & (fk > 0) & (fk < fs_hz / 2)] = b
    counts = np.bincount(band_of[band_of >= 0], minlength=nbands)
    if np.any(counts == 0):
        b = int(np.flatnonzero(counts == 0)[0])
        raise ScenarioError(f"output.block_s {block_s:g} s is too short to hold the {f_mid[b]:.1f} Hz band "
                            f"(FFT bins {1 / block_s:g} Hz apart)", field="output.block_s")
    phases = np.exp(1j * rng.uniform(0, 2 * np.pi, len(fk)))
    p2 = (20e-6) ** 2 * 10.0 ** (bands_db / 10.0)  # mean-square pressure per band, Pa^2
    sel = band_of >= 0
    out = np.empty(nb * n)
    r = max(1, int(round(fade_s * fs_hz)))
    w = (np.arange(2 * r) + 0.5) / (2 * r)
    prev = None
    chunk = max(1, int(2_000_000 // n))
    for j0 in range(0, nb, chunk):
        j1 = min(nb, j0 + chunk)
        amp = np.zeros((j1 - j0, len(fk)))
        amp[:, sel] = np.sqrt(2.0 * p2[j0:j1][:, band_of[sel]] / counts[band_of[sel]])
        spec = amp * phases * (n / 2.0)
        blocks = np.fft.irfft(spec, n=n, axis=1)
        if prev is not None:
            blocks = np.vstack([prev[None, :], blocks])
        else:
            blocks = np.vstack([blocks[:1], blocks])  # dummy previous block: no fade at the start
        cur = blocks[1:].copy()
        prv = blocks[:-1]
        # fade: tail of block j-1 and head of block j use both signals (all components are n-periodic)
        head = (1 - w[r:]) * prv[:, :r] + w[r:] * cur[:, :r]
        tail_prev = (1 - w[:r]) * prv[:, n - r:] + w[:r] * cur[:, n - r:]
        if j0 > 0:
            out[j0 * n - r:j0 * n] = tail_prev[0]
        cur[:, :r] = head
        if len(cur) > 1:
            # tail of each block but the last in this chunk
            cur[:-1, n - r:] = tail_prev[1:]
        out[j0 * n:j1 * n] = cur.ravel()
        prev = blocks[-1]
    return out

