"""Per-period accumulators of a grid (or a tile) over the flights, and the bands formed from them.

Per period ``p`` the exposure ``sum_f n_f,p E_f`` of the flights ``f`` with counts
``n_f,p`` (``E_f = integral 10^(L/10) dt``, s), the N-above and time-above sums per
threshold, and over the day the loudest flight's ``10^(LAmax/10)``.  The bands:
``Lday``, ``Levening``, ``Lnight`` = ``10 log10(sum_f n_f,p E_f / T_p)``, ``Lden``
(:func:`gisnoise.ops.periods.lden`), ``LAmax``, and per threshold ``L``:
``NA<L>_<period>``, ``NA<L>`` (flights whose LAmax exceeds ``L``), ``TA<L>_<period>``,
``TA<L>`` (time above ``L``, s).

With an audibility floor a flight skipped at a cell adds at most ``duration
10^(floor/10)`` there; that bound is accumulated too, and a level band is kept only
where the skipped flights could move it by at most :data:`UNCERTAIN_DB` (NaN elsewhere).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.ops.periods import PERIOD_HOURS, PERIODS, lden_energy

__all__ = ["UNCERTAIN_DB", "accumulate", "bands_of", "new_accumulators"]

UNCERTAIN_DB = 0.01
"""With a floor, level bands are NaN where the flights left out could move them by more than this, dB."""


def new_accumulators(shape: tuple[int, int], n_thr: int) -> dict[str, np.ndarray]:
    """Zeroed accumulators of a grid or tile of ``shape`` for ``n_thr`` thresholds."""
    acc = {f"E_{p}": np.zeros(shape) for p in PERIODS}
    acc.update({f"O_{p}": np.zeros(shape) for p in PERIODS})  # bound of the exposure left out below the floor
    acc["emax"] = np.zeros(shape, np.float32)
    acc["any"] = np.zeros(shape, bool)
    for k in range(n_thr):
        for p in PERIODS:
            acc[f"NA{k}_{p}"] = np.zeros(shape)
            acc[f"TA{k}_{p}"] = np.zeros(shape)
    return acc


def accumulate(acc: dict[str, np.ndarray], res: Any, counts: Mapping[str, float],
                thresholds: Sequence[float], omitted_bound: float = 0.0) -> dict[str, np.ndarray]:
    """Add one flight's kernel result (``WindowResult``) with its counts per period, in place.

    ``omitted_bound`` (s): an upper bound of the flight's exposure where the kernel skipped it
    (``duration 10^(floor/10)``).
    """
    np.maximum(acc["emax"], res.emax, out=acc["emax"])
    acc["any"] |= res.computed
    skipped = None if omitted_bound == 0.0 else ~res.computed
    # LAmax > L  <=>  emax > 10^(L/10) (emax holds 10^(LAmax/10) in float32)
    above = [res.emax > np.float32(10.0 ** (thr / 10.0)) for thr in thresholds]
    for p in PERIODS:
        n = counts[p]
        if n == 0:
            continue
        acc[f"E_{p}"] += n * res.energy
        if skipped is not None:
            acc[f"O_{p}"] += (n * omitted_bound) * skipped
        for k in range(len(thresholds)):
            acc[f"NA{k}_{p}"] += n * above[k]
            acc[f"TA{k}_{p}"] += n * res.ta[k]
    return acc


def bands_of(acc: dict[str, np.ndarray], thresholds: Sequence[float], floor_db: float | None = None
            ) -> dict[str, np.ndarray]:
    """Bands from the accumulators."""
    with np.errstate(divide="ignore"):
        e = {p: acc[f"E_{p}"] / (PERIOD_HOURS[p] * 3600.0) for p in PERIODS}
        o = {p: acc[f"O_{p}"] / (PERIOD_HOURS[p] * 3600.0) for p in PERIODS}
        e_den = lden_energy(e["day"], e["evening"], e["night"])
        bands = {"Lden": 10.0 * np.log10(e_den),
                 "Lday": 10.0 * np.log10(e["day"]), "Levening": 10.0 * np.log10(e["evening"]),
                 "Lnight": 10.0 * np.log10(e["night"]), "LAmax": 10.0 * np.log10(acc["emax"].astype(np.float64))}
    for a in bands.values():
        a[~np.isfinite(a)] = np.nan  # no sound (above the floor) in that period: nodata
    if floor_db is not None:
        # what the skipped flights may add: at most o; the level is kept where that is < 0.01 dB
        rel = 10.0 ** (UNCERTAIN_DB / 10.0) - 1.0
        for p, name in (("day", "Lday"), ("evening", "Levening"), ("night", "Lnight")):
            bands[name][o[p] > rel * e[p]] = np.nan
        bands["Lden"][lden_energy(o["day"], o["evening"], o["night"]) > rel * e_den] = np.nan
        skipped = (acc["O_day"] + acc["O_evening"] + acc["O_night"]) > 0
        bands["LAmax"][skipped & ~(bands["LAmax"] >= floor_db)] = np.nan
    for k, thr in enumerate(thresholds):
        for kind in ("NA", "TA"):
            total = np.zeros(acc["emax"].shape)
            for p in PERIODS:
                bands[f"{kind}{thr:g}_{p}"] = acc[f"{kind}{k}_{p}"]
                total = total + acc[f"{kind}{k}_{p}"]
            bands[f"{kind}{thr:g}"] = total
    return bands
