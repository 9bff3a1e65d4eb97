"""Per-period accumulators of a grid (a tile, or façade points) over the flights, and the bands formed from them.

Per period ``p`` the exposure ``sum_f n_f,p E_f`` of the flights ``f`` with counts
``n_f,p`` (``E_f = integral 10^(L/10) dt``, s), the N-above and time-above sums per
threshold, and over the day the loudest flight's ``10^(LAmax/10)``.  The bands:
``Lday``, ``Levening``, ``Lnight`` = ``10 log10(sum_f n_f,p E_f / T_p)``, ``Lden``
(:func:`gisnoise.ops.periods.lden`), ``LAmax``, and per threshold ``L``:
``NA<L>_<period>``, ``NA<L>`` (flights whose LAmax exceeds ``L``), ``TA<L>_<period>``,
``TA<L>`` (time above ``L``, s).  One rule for the map (:func:`gisnoise.ops.evaluate_operations`)
and the façades (:func:`gisnoise.exposure.operations_facade_levels`): a period in which no
flight sounds (no count, or below the floor) has no level (NaN), and N-above compares the
float32 ``10^(LAmax/10)``.

With an audibility floor a flight skipped at a cell adds at most ``duration
10^(floor/10)`` there; that bound is accumulated too, and a level band is kept only
where the skipped flights could move it by at most :data:`UNCERTAIN_DB` (NaN elsewhere).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.ops.periods import PERIOD_HOURS, PERIODS, lden_energy

__all__ = ["UNCERTAIN_DB", "accumulate", "add_flight", "new_accumulators", "period_bands"]

UNCERTAIN_DB = 0.01
"""With a floor, level bands are NaN where the flights left out could move them by more than this, dB."""


def new_accumulators(shape: tuple[int, ...], n_thr: int, *, time_above: bool = True) -> dict[str, np.ndarray]:
    """Zeroed accumulators of a grid, a tile or a set of points of ``shape`` for ``n_thr`` thresholds.

    ``time_above=False``: without the time-above sums (receivers whose flights give no
    time series, such as façade points); :func:`period_bands` then forms no ``TA`` band.
    """
    acc = {f"E_{p}": np.zeros(shape) for p in PERIODS}
    acc.update({f"O_{p}": np.zeros(shape) for p in PERIODS})  # bound of the exposure left out below the floor
    acc["emax"] = np.zeros(shape, np.float32)
    acc["any"] = np.zeros(shape, bool)
    for k in range(n_thr):
        for p in PERIODS:
            acc[f"NA{k}_{p}"] = np.zeros(shape)
            if time_above:
                acc[f"TA{k}_{p}"] = np.zeros(shape)
    return acc


def accumulate(acc: dict[str, np.ndarray], res: Any, counts: Mapping[str, float],
                thresholds: Sequence[float], omitted_bound: float = 0.0) -> dict[str, np.ndarray]:
    """Add one flight's kernel result (``WindowResult``) with its counts per period, in place.

    ``omitted_bound`` (s): an upper bound of the flight's exposure where the kernel skipped it
    (``duration 10^(floor/10)``).
    """
    return add_flight(acc, res.energy, res.emax, counts, thresholds, ta=res.ta, computed=res.computed,
                      omitted_bound=omitted_bound)


def add_flight(acc: dict[str, np.ndarray], energy: Any, emax: Any, counts: Mapping[str, float],
               thresholds: Sequence[float], *, ta: Any = None, computed: Any = None,
               omitted_bound: float = 0.0) -> dict[str, np.ndarray]:
    """Add one flight with its counts per period to the accumulators, in place.

    Parameters
    ----------
    energy : array_like
        The flight's exposure ``E_f = integral 10^(L/10) dt`` at each receiver, s.
    emax : array_like
        Its largest ``10^(L/10)`` (``10^(LAmax/10)``), held in float32 as the kernel's.
    ta : array_like, optional
        Time above each threshold, s (one row per threshold); needed when ``acc`` has time-above sums.
    computed : array_like of bool, optional
        Where the flight was evaluated (default everywhere).
    omitted_bound : float
        Upper bound of the flight's exposure where it was not evaluated, s.
    """
    emax = np.asarray(emax, dtype=np.float32)
    np.maximum(acc["emax"], emax, out=acc["emax"])
    if computed is None:
        acc["any"][...] = True
        skipped = None
    else:
        acc["any"] |= computed
        skipped = None if omitted_bound == 0.0 else ~computed
    # LAmax > L  <=>  emax > 10^(L/10) (emax holds 10^(LAmax/10) in float32)
    above = [emax > np.float32(10.0 ** (thr / 10.0)) for thr in thresholds]
    for p in PERIODS:
        n = counts[p]
        if n == 0:
            continue
        acc[f"E_{p}"] += n * energy
        if skipped is not None:
            acc[f"O_{p}"] += (n * omitted_bound) * skipped
        for k in range(len(thresholds)):
            acc[f"NA{k}_{p}"] += n * above[k]
            if f"TA{k}_{p}" in acc:
                acc[f"TA{k}_{p}"] += n * ta[k]
    return acc


def period_bands(acc: dict[str, np.ndarray], thresholds: Sequence[float], floor_db: float | None = None
                 ) -> dict[str, np.ndarray]:
    """Bands from the accumulators (see the module docstring).

    A level band is NaN where no flight sounds in its period (no count there, or every
    flight below the floor): an empty period has no level, not ``-inf``.
    """
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
        for kind in ("NA", "TA") if f"TA{k}_{PERIODS[0]}" in acc else ("NA",):
            total = np.zeros(acc["emax"].shape)
            for p in PERIODS:
                bands[f"{kind}{thr:g}_{p}"] = acc[f"{kind}{k}_{p}"]
                total = total + acc[f"{kind}{k}_{p}"]
            bands[f"{kind}{thr:g}"] = total
    return bands
