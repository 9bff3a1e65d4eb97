"""The receiver grid of a map: around a trajectory's track, large enough for the contours.

:func:`grid_for_trajectory` covers the track's bounding box plus ``margin_m`` on every side,
snapped to multiples of the resolution, in the local UTM zone unless a CRS is given
(:func:`gisnoise.geo.grid_for_points`); its size is limited by ``GISNOISE_MAX_CELLS``.

:func:`audible_distance` bounds, from the cards, how far from the track the lowest
requested level can still be reached; :func:`grid_for_map` grows the margin to it, so
that the lowest contour of the maximum level closes inside the grid.  The bound is an
upper one: each card's own model (one definition, :meth:`gisnoise.model.ModelCard.level_uav`)
is evaluated over the whole emission sphere at the loudest electric power the track flies
with that card, at distances from 1 m to 100 km (a measured hemisphere's: its largest node level,
:meth:`gisnoise.model.HemisphereCard.loudest_level`, exact); spreading is the card's (``p6`` in the
paper's ansatz); atmospheric absorption, which only lowers levels, is left out, so the
bound holds with it too.  The time-averaged level ``LAeq`` never exceeds ``LAmax``, so the
same extent closes its lowest contour as well.  The sound exposure level ``SEL`` grows with
the event's duration; its contours lie :data:`gisnoise.maps.sel.SEL_OFFSET_DB` above the
map's levels and the extent grows until the lowest of them closes too, by the same bound
integrated over the event (:func:`gisnoise.maps.sel.sel_margin`).  Features cut by the
grid's edge (a fixed margin, or the cell limit) carry ``"clipped": true``
(:mod:`gisnoise.maps.contours`).

Examples
--------
>>> from gisnoise.model import HemisphereCard, ModelCard, get_ansatz
>>> p = {"p0": 60.0, "p1": 0.0, "p2": 0.0, "p3": 0.0, "p4": 0.0, "p5": 0.0, "p6": 1.0, "p7": 30.0}
>>> c = ModelCard(id="c", vehicle="v", phase="horizontal", ansatz="paper-offset", parameters=p,
...               reference_power_w=1000.0)
>>> d = audible_distance([c], [1000.0], 40.0)  # 60 dB at 40 m, 6 dB per doubling: 40 dB at 400 m
>>> 400.0 <= d <= 400.0 * 1.05  # an upper bound, at most one table step (4.9 %) beyond
True
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.flight import Trajectory
from gisnoise.geo import GridSpec, grid_for_points, max_cells
from gisnoise.maps.cardset import CardSet
from gisnoise.maps.effect_bounds import effect_bound_db
from gisnoise.maps.sel import SEL_OFFSET_DB, sel_margin
from gisnoise.model import HemisphereCard, ModelCard, get_ansatz

__all__ = ["grid_for_trajectory", "grid_for_map", "auto_margin", "audible_distance", "level_table", "MAX_DISTANCE_M",
           "SIZED_METRICS", "RESOLUTION_TOLERANCE_DB", "coarse_cell_loss_db", "finest_needed_resolution",
           "resolution_warning", "resolution_warning_of"]

MAX_DISTANCE_M = 100_000.0
"""Largest distance the bound looks at, m."""

SIZED_METRICS = ("LAmax", "LAeq")
"""Metrics whose lowest contour the default extent closes (``LAeq <= LAmax`` everywhere)."""

RESOLUTION_TOLERANCE_DB = 1.0
"""How far LAmax under the track may fall short for the cells' coarseness before a map warns, dB."""


def coarse_cell_loss_db(resolution_m: Any, height_m: Any) -> Any:
    """Most that LAmax under the track can fall short on a grid of cells ``resolution_m`` wide, dB.

    The receivers are the cell centres: the nearest one can lie ``resolution_m / sqrt(2)`` (half a cell's
    diagonal) beside the point under the UAV, ``height_m`` (m) below it, so by spherical spreading it hears
    ``10 lg(1 + (resolution_m / sqrt(2) / height_m)^2)`` dB less than a receiver right under the track.
    Float or array_like; broadcasts.

    >>> round(float(coarse_cell_loss_db(10.0, 100.0)), 4)  # 7.07 m beside, 100 m below
    0.0217
    >>> round(float(coarse_cell_loss_db(100.0 * math.sqrt(2.0), 100.0)), 4)  # as far beside as below: 3 dB
    3.0103
    """
    r = np.asarray(resolution_m, dtype=float) / math.sqrt(2.0)
    return 10.0 * np.log10(1.0 + (r / np.asarray(height_m, dtype=float)) ** 2)


def finest_needed_resolution(height_m: float, tolerance_db: float = RESOLUTION_TOLERANCE_DB) -> float:
    """The coarsest cells, m (rounded down to two significant digits), that keep :func:`coarse_cell_loss_db`
    within ``tolerance_db`` for a flight ``height_m`` (m) above the receivers.

    >>> finest_needed_resolution(50.0)  # sqrt(2) 50 sqrt(10^0.1 - 1) = 35.98 m
    35.0
    """
    exact = math.sqrt(2.0) * height_m * math.sqrt(10.0 ** (tolerance_db / 10.0) - 1.0)
    digits = 1 - math.floor(math.log10(exact))
    return float(f"{math.floor(exact * 10.0 ** digits) * 10.0 ** -digits:.10g}")


def resolution_warning(resolution_m: float, height_m: float | None,
                       tolerance_db: float = RESOLUTION_TOLERANCE_DB) -> str | None:
    """The warning of a grid whose cells are coarse for the flight's height above the receivers, or None.

    ``height_m``: the flight's median height above the receivers while flying, m (None or not positive: no
    warning).  Warns when :func:`coarse_cell_loss_db` exceeds ``tolerance_db``, naming the resolution and
    one that keeps the loss within it (:func:`finest_needed_resolution`).

    >>> resolution_warning(10.0, 100.0) is None
    True
    >>> print(resolution_warning(5000.0, 100.0))  # doctest: +NORMALIZE_WHITESPACE
    resolution: cells of 5000 m are coarse for a flight 100.0 m above the receivers (median while flying): the
    nearest cell centre can lie 3535.5 m (half a cell's diagonal) beside the track, so LAmax under it may be
    low by up to 31.0 dB (10 lg(1 + (resolution / sqrt(2) / height)^2)); cells of 71 m or finer keep that
    within 1 dB
    """
    if height_m is None or not math.isfinite(height_m) or height_m <= 0.0:
        return None
    loss = float(coarse_cell_loss_db(resolution_m, height_m))
    if loss <= tolerance_db:
        return None
    return (f"resolution: cells of {resolution_m:g} m are coarse for a flight {height_m:.1f} m above the receivers "
            f"(median while flying): the nearest cell centre can lie {resolution_m / math.sqrt(2.0):.1f} m (half a "
            f"cell's diagonal) beside the track, so LAmax under it may be low by up to {loss:.1f} dB "
            f"(10 lg(1 + (resolution / sqrt(2) / height)^2)); cells of "
            f"{finest_needed_resolution(height_m, tolerance_db):g} m or finer keep that within {tolerance_db:g} dB")


def resolution_warning_of(resolution_m: float, heights: Mapping[str, float | None], noun: str = "flight",
                          tolerance_db: float = RESOLUTION_TOLERANCE_DB) -> str | None:
    """:func:`resolution_warning` for several flights on one grid: one line naming every flight (by its key in
    ``heights``, its median height above the receivers) whose cells are coarse, judged at the lowest of them.

    >>> print(resolution_warning_of(200.0, {"a": 400.0, "b": 60.0, "c": 40.0}, "route"))  # doctest: +ELLIPSIS
    routes b, c: resolution: cells of 200 m are coarse for a flight 40.0 m above the receivers ...
    >>> resolution_warning_of(10.0, {"a": 150.0, "b": None}) is None
    True
    """
    coarse = {n: float(h) for n, h in heights.items()
              if h is not None and math.isfinite(h) and h > 0.0
              and float(coarse_cell_loss_db(resolution_m, h)) > tolerance_db}
    if not coarse:
        return None
    said = resolution_warning(resolution_m, min(coarse.values()), tolerance_db)
    return f"{noun}{'s' if len(coarse) > 1 else ''} {', '.join(coarse)}: {said}"


_DISTANCES = np.geomspace(1.0, MAX_DISTANCE_M, 241)
_PHI = np.radians(np.arange(0.0, 360.0, 5.0))
_THETA = np.radians(np.linspace(-90.0, 90.0, 37))


def grid_for_trajectory(traj: Trajectory, resolution_m: float = 10.0, margin_m: float = 500.0,
                        crs: Any = None) -> GridSpec:
    """The receiver grid around a trajectory's track: :func:`gisnoise.geo.grid_for_points` of its
    longitudes and latitudes, with the same parameters (the margin about the track's bounding box),
    result and errors.
    """
    return grid_for_points(traj.lon, traj.lat, resolution_m, margin_m, crs)


def audible_distance(cards: Sequence[ModelCard], powers_w: Sequence[float], level_db: float) -> float:
    """Upper bound of the slant distance (m) at which any of ``cards`` reaches ``level_db``.

    ``powers_w[i]`` is the loudest electric power card ``i`` flies with.  The level of each
    card (background excluded) is maximised over the emission sphere (5 deg steps) at 241
    distances from 1 m to :data:`MAX_DISTANCE_M`; the result is the first tabulated distance
    beyond the last one still at or above ``level_db`` (0 when none is).  Raises
    :class:`~gisnoise.errors.InputError` (field ``card``) for a card whose model needs inputs
    beyond distance, angles and power.
    """
    d, table = level_table(cards, powers_w)
    return _farthest_at(d, table, level_db)


def _farthest_at(distances: np.ndarray, table: np.ndarray, level_db: float) -> float:
    """The first tabulated distance beyond the last one at which any row of ``table`` reaches ``level_db`` (0: none)."""
    far = 0.0
    for loud in table:
        idx = np.flatnonzero(loud >= level_db)
        if idx.size:
            far = max(far, float(distances[min(int(idx[-1]) + 1, distances.size - 1)]))
    return far


def level_table(cards: Sequence[ModelCard], powers_w: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """The distances (m) of :func:`audible_distance` and, per card, its loudest level over the emission
    sphere at each of them at ``powers_w[i]`` (``-inf`` for a card without a positive power)."""
    phi, theta, d = np.meshgrid(_PHI, _THETA, _DISTANCES, indexing="ij")
    table = np.full((len(cards), _DISTANCES.size), -np.inf)
    done: dict[tuple[int, float | None], int] = {}  # a row already computed for the same card (and power)
    for i, (card, pw) in enumerate(zip(cards, powers_w, strict=True)):
        if not math.isfinite(float(pw)) or float(pw) <= 0:
            continue
        # a measured hemisphere's levels do not depend on the electric power: one row serves all its powers
        key = (id(card), None if isinstance(card, HemisphereCard) else float(pw))
        if key in done:
            table[i] = table[done[key]]
            continue
        done[key] = i
        if isinstance(card, HemisphereCard):  # its largest node level: exact, where the directions' grid samples
            table[i] = card.loudest_level(_DISTANCES)
            continue
        try:
            lv = card.level_uav(card.inputs(d, phi, theta, float(pw)))
        except InputError as exc:
            raise InputError(f"card {card.id!r}: its model cannot be bounded for the map's extent ({exc}); "
                             "give --margin", field="card") from None
        table[i] = np.nanmax(lv, axis=(0, 1))
    return _DISTANCES.copy(), table


def _base_card(card: ModelCard) -> ModelCard:
    """``card`` with its ansatz's effects left out (``paper-offset+bank_angle`` -> ``paper-offset``)."""
    if "+" not in card.ansatz:
        return card
    base = card.ansatz.split("+")[0]
    params = get_ansatz(base).params
    return dataclasses.replace(card, ansatz=base, parameters={k: card.parameters[k] for k in params},
                               covariance=None)


def _target_uav_level(level_db: float, cards: Sequence[ModelCard], background: bool) -> float | None:
    """The UAV level whose sum with the background equals ``level_db``; None if the background alone reaches it."""
    if not background:
        return level_db
    bgs = [b for b in (c.background_db for c in cards) if b is not None]
    if not bgs:
        return level_db
    bg = max(bgs)
    if bg >= level_db:
        return None
    return 10.0 * math.log10(10.0 ** (level_db / 10.0) - 10.0 ** (bg / 10.0))


def auto_margin(traj: Trajectory, cardset: CardSet, lowest_db: float, *, resolution_m: float = 10.0,
                crs: Any = None, background: bool = False, min_margin_m: float = 100.0,
                cell_limit: int | None = None, sel: bool = True) -> tuple[float, list[str]]:
    """The default margin (m) of a map's grid, and the warnings that go with it.

    The margin is :func:`audible_distance` of the cards at ``lowest_db`` (at least
    ``min_margin_m``, plus one cell), so no edge cell's maximum level reaches ``lowest_db``;
    with ``sel`` it grows further until no edge cell's ``SEL`` reaches the lowest SEL contour,
    ``lowest_db`` + :data:`gisnoise.maps.sel.SEL_OFFSET_DB` (:func:`gisnoise.maps.sel.sel_margin`).
    When that grid would exceed ``cell_limit`` (default ``GISNOISE_MAX_CELLS``) the margin is
    cut to the largest that fits, and a warning says so; when not even ``min_margin_m`` fits,
    that is returned and the grid's cell check refuses it.
    """
    idx = cardset.assign(traj.phase, traj.t)
    cards: list[ModelCard] = []
    powers: list[float] = []
    row = np.full(len(cardset.cards), -1)
    for i, card in enumerate(cardset.cards):
        m = idx == i
        if m.any():
            row[i] = len(cards)
            cards.append(card)
            powers.append(float(np.nanmax(np.asarray(traj.power_w, dtype=float)[m])))
    warnings: list[str] = []
    target = _target_uav_level(lowest_db, cards, background)
    if target is None:
        warnings.append(f"the cards' background level alone reaches {lowest_db:g} dB(A): no extent closes that "
                        "contour; the grid uses a 500 m margin")
        return 500.0, warnings
    res = float(resolution_m)
    ext_cards = cards
    added: np.ndarray | None = None  # the effect terms' bounds added to the base ansatzes' levels
    try:
        distances, table = level_table(cards, powers)
    except InputError:  # a model extension needs inputs of the flight: its base ansatz plus a bound of its terms
        ext_cards = [_base_card(c) for c in cards]
        distances, table = level_table(ext_cards, powers)
        added = np.zeros_like(table)
        unbounded = set()
        for i_all, k in enumerate(row):
            if k < 0:
                continue
            card = cards[k]
            bound = effect_bound_db(card, traj, idx == i_all, distances)
            if bound is None:
                unbounded.add(card.ansatz)
            else:
                added[k] = bound
        table = table + added
        if unbounded:
            warnings.append(f"the extent is bounded by the base ansatz of {', '.join(sorted(unbounded))}, without "
                            "its effects; check the contours' clipped flags")
    margin = max(_farthest_at(distances, table, target), float(min_margin_m)) + res
    base = grid_for_trajectory(traj, resolution_m, 0.0, crs)
    limit = max_cells() if cell_limit is None else int(cell_limit)
    w0, h0 = base.width * res, base.height * res
    # cells of a margin m: (w0 + 2m)(h0 + 2m) / res^2 <= limit
    disc = (w0 + h0) ** 2 - 4.0 * (w0 * h0 - limit * res * res)
    fit = (-(w0 + h0) + math.sqrt(max(disc, 0.0))) / 4.0 - 2.0 * res
    need = f"LAmax {lowest_db:g} dB(A)"
    if sel:
        sel_db = lowest_db + SEL_OFFSET_DB
        bgs = [c.background_db for c in cards if c.background_db is not None] if background else []
        rows, sel_table, sel_card = _power_rows(traj, idx, cardset.cards, row, cards, ext_cards)
        if added is not None and sel_card.size:
            sel_table = sel_table + added[sel_card]
        x0, y0, x1, y1 = base.bounds
        m_sel = sel_margin(traj, rows, distances, sel_table, sel_db, (x0, y0, x1, y1), base.crs,
                           start_m=margin, resolution_m=res, max_margin_m=max(fit, margin) + res,
                           background_db=max(bgs) if bgs else None) + 2.0 * res
        if m_sel > margin:
            margin, need = m_sel, f"SEL {sel_db:g} dB(A)"
    if margin > fit:
        cut = math.floor(fit / res) * res
        if cut < min_margin_m:  # not even the least margin fits: the grid's cell check refuses it
            return float(min_margin_m), warnings
        warnings.append(f"the {need} contour needs a margin above {margin:,.0f} m; the grid is cut to {cut:,.0f} m "
                        f"by the limit of {limit:,} cells; use a coarser resolution to see all of it")
        margin = cut
    return margin, warnings


#: Power steps of the SEL bound: each sample's power is rounded up to a multiple of 10^(1/40) (1/4 dB in 10 log P).
_POWER_STEP = 10.0 ** (1.0 / 40.0)


def _power_rows(traj: Trajectory, idx: np.ndarray, all_cards: Sequence[ModelCard], row: np.ndarray,
                cards: Sequence[ModelCard], bounded: Sequence[ModelCard]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each sample's row of a level table of (card, power), that table and each row's card (index into
    ``cards``); with more than 64 pairs the powers are rounded up to multiples of :data:`_POWER_STEP`.

    The SEL bound sums every sample's level: each at its own power (rounded up; levels grow with
    power as in :func:`audible_distance`), not the card's loudest.
    """
    power = np.asarray(traj.power_w, dtype=float)
    exact = len(set(zip(idx.tolist(), power.tolist(), strict=True))) <= 64  # few powers: each its own row
    with np.errstate(divide="ignore", invalid="ignore"):
        step = np.where(power > 0, np.ceil(np.log(np.where(power > 0, power, 1.0)) / np.log(_POWER_STEP)), -1e9)
    if exact:
        step = np.where(power > 0, power, -1e9)
    keys: dict[tuple[int, float], int] = {}
    rows = np.full(power.size, -1)
    tab_cards: list[ModelCard] = []
    tab_powers: list[float] = []
    for i in range(power.size):
        k = int(row[idx[i]])
        if k < 0 or step[i] < -1e8:
            continue
        key = (k, float(step[i]))
        if key not in keys:
            keys[key] = len(tab_cards)
            tab_cards.append(bounded[k])
            tab_powers.append(float(step[i]) if exact else float(_POWER_STEP ** step[i]))
        rows[i] = keys[key]
    if not tab_cards:
        return rows, np.full((0, 1), -np.inf), np.zeros(0, int)
    _d, table = level_table(tab_cards, tab_powers)
    return rows, table, np.array([k for k, _ in keys], dtype=int)


def grid_for_map(traj: Trajectory, cardset: CardSet, lowest_db: float, *, resolution_m: float = 10.0,
                 margin_m: float | None = None, crs: Any = None, background: bool = False,
                 cell_limit: int | None = None, sel: bool = True) -> tuple[GridSpec, list[str]]:
    """The receiver grid of a map and the warnings that go with it: :func:`grid_for_trajectory`
    with ``margin_m``, or with :func:`auto_margin` when it is None.
    """
    warnings: list[str] = []
    if margin_m is None:
        margin_m, warnings = auto_margin(traj, cardset, lowest_db, resolution_m=resolution_m, crs=crs,
                                         background=background, cell_limit=cell_limit, sel=sel)
    return grid_for_trajectory(traj, resolution_m, margin_m, crs), warnings
