"""Exposure statistics of a level raster: people by 5 dB class, area above each level.

How people meet levels
----------------------
Each population cell is split into sub-cells no larger than half a map cell; each
sub-cell carries its share of the cell's people and is moved into the map's CRS. Within
a sub-cell the level is taken linear: value and gradient at its centre come from a
second-order Taylor expansion about the nearest map cell centre (gradient and Hessian by
central differences), and the fraction of the sub-cell's people above a level is
the exact area fraction of a square on which the level is linear
(:func:`fraction_above`). Only the population cells that the map's extent may touch are expanded
(:func:`gisnoise.geo.raster_window`), and only their sub-cells on the map are kept: the people on the map.  Those
on cells where it has no value are counted as ``people_without_level``, never put in a class.  Where the population
raster does not reach (outside its extent) or holds no data (its nodata cells) the people are unknown, not none:
:func:`uncovered_shares` gives the share of the map's area above each level that it leaves uncovered, and the
exposure document marks the classes where that share exceeds :data:`UNCOVERED_SHARE` as lower bounds.

Area above a level uses the same rule on 2 x 2 sub-cells of the map's own cells, each weighing its cell's area
on the ground (:func:`gisnoise.geo.cell_areas`: the cell's area in the map's CRS over the CRS's areal scale there,
so a map in Web Mercator gives the same square metres as one in UTM).

Only where it can count
-----------------------
Most of a planner's map lies below the lowest level.  From a cell's value, gradient and
Hessian, :func:`_cell_upper` bounds the highest level any sub-cell square about a point of
that cell can reach (absolute values of every Taylor term at the cell's farthest offset);
points of cells whose bound lies below a level add exactly nothing above it and are never
expanded.  Of the rest, squares entirely above a level count whole; only squares that the
level cuts go through :func:`fraction_above`.  The sums are those of every point through
:func:`fraction_above` (the tests check this against the plain sum).

>>> float(fraction_above(60.0, 0.1, 0.0, 10.0, 60.0))  # the level runs through the middle
0.5
>>> float(fraction_above(60.0, 0.1, 0.0, 10.0, 60.25))  # a quarter of the square lies above 60.25 dB
0.25
>>> float(fraction_above(62.0, 0.0, 0.0, 1.0, 60.0))  # 2 dB above everywhere on a flat cell
1.0
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.exposure.layers import LevelsRaster, Population
from gisnoise.geo import GridSpec, apply_affine, cell_areas, raster_window, transformer

__all__ = ["CLASS_WIDTH_DB", "class_edges", "fraction_above", "level_field", "population_points",
           "population_exposure", "area_above", "person_db_above", "population_scores",
           "EVENT_EDGES", "cell_values", "events_area_above", "population_event_exposure", "UNCOVERED_SHARE",
           "population_coverage", "uncovered_shares", "covered_at", "ground_cell_areas"]

CLASS_WIDTH_DB = 5.0
"""Width of the exposure classes, dB."""
EVENT_EDGES = (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)
"""Lower edges of the classes of event counts (N-above bands), events."""


def class_edges(lo_db: float = 35.0, hi_db: float = 85.0, width_db: float = CLASS_WIDTH_DB) -> list[float]:
    """Lower edges of the classes ``[lo, lo + w), ...`` up to ``hi`` (the last class is open above)."""
    if not (math.isfinite(lo_db) and math.isfinite(hi_db) and hi_db > lo_db and width_db > 0):
        raise InputError(f"classes: need lo < hi and width > 0, got {lo_db}, {hi_db}, {width_db}", field="classes")
    n = int(math.floor((hi_db - lo_db) / width_db + 1e-9))
    return [lo_db + i * width_db for i in range(n + 1)]


def fraction_above(level: Any, gx: Any, gy: Any, side: Any, threshold: float) -> np.ndarray:
    """Area fraction of a square of side ``side`` (m) where a linear level exceeds ``threshold``.

    The level is ``level`` (dB) at the centre with gradient ``gx, gy`` (dB/m); the level over
    the square is the sum of two uniform variables of widths ``side |gx|`` and ``side |gy|``,
    whose distribution function is closed form (a trapezoid).  Array arguments broadcast.
    """
    a0 = np.abs(np.asarray(gx, dtype=float)) * side
    b0 = np.abs(np.asarray(gy, dtype=float)) * side
    level = np.asarray(level, dtype=float)
    tiny = 1e-9  # dB across the square: flat
    a = np.maximum(np.maximum(a0, b0), tiny)
    b = np.maximum(np.minimum(a0, b0), tiny)
    # z: how far the threshold lies above the square's lowest level
    z = threshold - (level - 0.5 * (a + b))
    trapezoid = np.where(z <= 0, 0.0, np.where(z <= b, z * z / (2 * a * b),
                         np.where(z <= a, (2 * z - b) / (2 * a),
                                  np.where(z < a + b, 1.0 - (a + b - z) ** 2 / (2 * a * b), 1.0))))
    uniform = np.clip((threshold - (level - 0.5 * a)) / a, 0.0, 1.0)
    step = np.where(level > threshold, 0.0, np.where(level < threshold, 1.0, 0.5))
    flat_a = np.maximum(a0, b0) <= tiny
    flat_b = np.minimum(a0, b0) <= tiny
    below = np.where(flat_a, step, np.where(flat_b, uniform, trapezoid))
    return np.clip(1.0 - below, 0.0, 1.0)


def _derivatives(band: np.ndarray, grid: GridSpec) -> tuple[np.ndarray, ...]:
    """Gradient (dB/m) and Hessian (dB/m^2) of a band by central differences, x east and y north.

    NaN next to cells without value; zero along an axis with a single cell.
    """
    rx, ry = grid.resolution

    def d_dx(a: np.ndarray) -> np.ndarray:
        return np.gradient(a, rx, axis=1) if a.shape[1] > 1 else np.zeros_like(a)

    def d_dy(a: np.ndarray) -> np.ndarray:
        return -np.gradient(a, ry, axis=0) if a.shape[0] > 1 else np.zeros_like(a)  # row 0 is north

    gx, gy = d_dx(band), d_dy(band)
    return gx, gy, d_dx(gx), d_dy(gy), d_dy(gx)


_TINY = 1e-9  # dB across a square below which fraction_above takes it flat
_SAFE_DB = 1e-6  # rounding allowance of the bounds, dB


def _cell_upper(band: np.ndarray, der: tuple[np.ndarray, ...], half_x: float, half_y: float,
                side: float) -> np.ndarray:
    """Per cell: an upper bound of ``L + (|gx| + |gy|) side / 2`` over points within ``half_x, half_y`` (m)
    of the cell centre, ``L, gx, gy`` from :func:`level_field` (NaN where the band or a derivative is)."""
    gx, gy, hxx, hyy, hxy = (np.abs(a) for a in der)
    top = (band + gx * half_x + gy * half_y
           + 0.5 * (hxx * half_x * half_x + 2 * hxy * half_x * half_y + hyy * half_y * half_y))
    slope = (gx + hxx * half_x + hxy * half_y) + (gy + hxy * half_x + hyy * half_y)
    return np.asarray(top + 0.5 * side * slope + _TINY + _SAFE_DB)


def _sum_above(weights: np.ndarray, L: np.ndarray, gx: np.ndarray, gy: np.ndarray, side: float,
               threshold: float) -> float:
    """``sum(weights * fraction_above(L, gx, gy, side, threshold))``: squares the level does not cut
    count 0 or 1 without the formula."""
    half = 0.5 * side * (np.abs(gx) + np.abs(gy)) + _TINY
    whole = L - half > threshold
    cut = ~whole & (L + half >= threshold)
    part = fraction_above(L[cut], gx[cut], gy[cut], side, threshold)
    return float(np.sum(weights[whole]) + np.sum(weights[cut] * part))


def level_field(band: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray,
                derivatives: tuple[np.ndarray, ...] | None = None) -> tuple[np.ndarray, ...]:
    """Level and gradient (dB, dB/m) of a band at points ``x, y`` of the grid's CRS.

    Second-order Taylor expansion about the centre of the cell holding the point (gradient
    and Hessian by central differences); NaN outside the grid.
    """
    gx, gy, hxx, hyy, hxy = _derivatives(band, grid) if derivatives is None else derivatives
    t = grid.transform
    col, row = apply_affine(~t, np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    c = np.floor(np.asarray(col)).astype(np.int64)
    r = np.floor(np.asarray(row)).astype(np.int64)
    h, w = band.shape
    inside = (c >= 0) & (c < w) & (r >= 0) & (r < h)
    out = [np.full(c.shape, np.nan) for _ in range(3)]
    ci, ri = c[inside], r[inside]
    dx = np.asarray(x, dtype=float)[inside] - (t.c + t.a * (ci + 0.5))
    dy = np.asarray(y, dtype=float)[inside] - (t.f + t.e * (ri + 0.5))
    a_xx, a_yy, a_xy = hxx[ri, ci], hyy[ri, ci], hxy[ri, ci]
    out[0][inside] = (band[ri, ci] + gx[ri, ci] * dx + gy[ri, ci] * dy
                      + 0.5 * (a_xx * dx * dx + 2 * a_xy * dx * dy + a_yy * dy * dy))
    out[1][inside] = gx[ri, ci] + a_xx * dx + a_xy * dy
    out[2][inside] = gy[ri, ci] + a_xy * dx + a_yy * dy
    return out[0], out[1], out[2]


def population_points(pop: Population, grid: GridSpec, *, max_points: int = 50_000_000
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Sub-cells of the populated cells on the map, in the map's CRS: ``x, y`` (m), people, side (m).

    Only the cells that the map's extent may touch are expanded (:func:`gisnoise.geo.raster_window`), and only
    their sub-cells whose centres lie on the map are kept.  Cells with no people are skipped.  Sub-cells are at
    most half a map cell wide.
    """
    r0, r1, c0, c1 = raster_window(pop.transform, pop.counts.shape, pop.crs, grid)
    rows, cols = np.nonzero(pop.counts[r0:r1, c0:c1] > 0)
    rows, cols = rows + r0, cols + c0
    if rows.size == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0), 0.0
    t = pop.transform
    tr = transformer(pop.crs, grid.crs)
    # the cell size in map metres, from the populated cells' middle cell
    i = rows.size // 2
    cx = np.array([cols[i], cols[i] + 1, cols[i]], dtype=float)
    cy = np.array([rows[i], rows[i], rows[i] + 1], dtype=float)
    px, py = apply_affine(t, cx, cy)
    mx, my = tr.transform(px, py)
    wx = math.hypot(mx[1] - mx[0], my[1] - my[0])
    wy = math.hypot(mx[2] - mx[0], my[2] - my[0])
    cell_m = math.sqrt(wx * wy)
    k = max(1, int(math.ceil(cell_m / (0.5 * min(grid.resolution)))))
    if rows.size * k * k > max_points:
        raise InputError(f"population: {rows.size} populated cells under the map x {k * k} sub-cells exceed "
                         f"{max_points} points; use a coarser map or a smaller one", field="population")
    off = (np.arange(k) + 0.5) / k - 0.5
    # each cell is mapped affinely about its centre (centre and the unit steps along a column and a row
    # transformed exactly; the cell is small against the curvature of any map projection)
    cc, rc = cols + 0.5, rows + 0.5
    x0, y0 = tr.transform(*apply_affine(t, cc, rc))
    x1, y1 = tr.transform(*apply_affine(t, cc + 1.0, rc))
    x2, y2 = tr.transform(*apply_affine(t, cc, rc + 1.0))
    x0, y0 = np.asarray(x0), np.asarray(y0)
    dcx, dcy = np.asarray(x1) - x0, np.asarray(y1) - y0  # one column to the right, map m
    drx, dry = np.asarray(x2) - x0, np.asarray(y2) - y0  # one row down, map m
    fc = np.tile(off, k)  # column offsets of the k x k sub-cells, cell units
    fr = np.repeat(off, k)  # row offsets
    x = (x0[:, None] + dcx[:, None] * fc[None, :] + drx[:, None] * fr[None, :]).ravel()
    y = (y0[:, None] + dcy[:, None] * fc[None, :] + dry[:, None] * fr[None, :]).ravel()
    people = np.repeat(pop.counts[rows, cols] / (k * k), k * k)
    gc, gr = apply_affine(~grid.transform, x, y)  # on the map: the cells level_field reads
    on = (gc >= 0) & (gc < grid.width) & (gr >= 0) & (gr < grid.height)
    return np.asarray(x[on]), np.asarray(y[on]), people[on], cell_m / k


UNCOVERED_SHARE = 0.01
"""Largest share of a band's area at or above a class's lower edge that the population raster may leave uncovered
before that class's people are a lower bound (and said so), 1 %.  A raster cut to the map in another CRS leaves
slivers along the map's edge, where the levels are the map's lowest; a real hole in the data (a raster ending inside
the map) leaves far more.  Below 1 % the people missed are within the accuracy of gridded population data."""


def covered_at(pop: Population, crs: Any, x: Any, y: Any) -> np.ndarray:
    """Whether the population raster holds data at points ``x, y`` of ``crs`` (bool, broadcast): within its extent
    and not on a nodata cell (:attr:`~gisnoise.exposure.Population.covered`).  Elsewhere the people are unknown,
    not zero."""
    px, py = transformer(crs, pop.crs).transform(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    c, r = apply_affine(~pop.transform, np.asarray(px, dtype=float), np.asarray(py, dtype=float))
    h, w = pop.counts.shape
    c, r = np.asarray(c), np.asarray(r)
    inside = (c >= 0) & (c < w) & (r >= 0) & (r < h)
    if pop.covered is None or not inside.any():
        return inside
    out = inside.copy()
    out[inside] = pop.covered[np.floor(r[inside]).astype(np.int64), np.floor(c[inside]).astype(np.int64)]
    return out


def population_coverage(pop: Population, grid: GridSpec, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Whether the population raster holds data at the centre of each map cell ``rows, cols`` (bool, one per cell).

    It holds data within its extent, on every cell but its nodata cells (:func:`covered_at`); elsewhere the people
    are unknown, not zero.
    """
    t = grid.transform
    x = t.c + t.a * (np.asarray(cols, dtype=float) + 0.5)
    y = t.f + t.e * (np.asarray(rows, dtype=float) + 0.5)
    return covered_at(pop, grid.crs, x, y)


def uncovered_shares(bands: dict[str, np.ndarray], grid: GridSpec, pop: Population,
                     edges: Mapping[str, Sequence[float]]) -> dict[str, list[float | None]]:
    """Per band and lower class edge, the share of the map's area at or above that edge whose cells the population
    raster does not cover (:func:`population_coverage`, cell centres); None where no cell reaches the edge.

    Cells are equal in area on the map's grid, so the share is a share of cells.
    """
    reached = [bands[n] >= min(edges[n]) for n in edges if edges[n]]  # NaN (no level) reaches nothing
    covered = np.ones(grid.shape, dtype=bool)
    if reached:
        rows, cols = np.nonzero(np.logical_or.reduce(reached))
        covered[rows, cols] = population_coverage(pop, grid, rows, cols)
    out: dict[str, list[float | None]] = {}
    for n, e_n in edges.items():
        shares: list[float | None] = []
        for e in e_n:
            above = bands[n] >= e
            total = int(above.sum())
            shares.append(float((above & ~covered).sum()) / total if total else None)
        out[n] = shares
    return out


def _points_that_count(band: np.ndarray, grid: GridSpec, der: tuple[np.ndarray, ...], x: np.ndarray,
                       y: np.ndarray, side: float, floor_db: float) -> np.ndarray:
    """Indices of the points whose level square may reach ``floor_db`` (or that have no level: outside the
    grid, or NaN bounds of cells next to no value)."""
    rx, ry = grid.resolution
    upper = _cell_upper(band, der, 0.5 * rx, 0.5 * ry, side)
    return np.flatnonzero(~(cell_values(upper, grid, x, y) < floor_db))


def population_scores(band: np.ndarray, grid: GridSpec, points: tuple[np.ndarray, np.ndarray, np.ndarray, float],
                      edges: Sequence[float], floor_db: float | None = None) -> dict[str, Any]:
    """People above each level of ``edges`` (``above``), people without a level and person-dB above
    ``floor_db`` (default the lowest edge) of one band, in one pass over the population's sub-cells
    (``points``: :func:`population_points`).  The levels are those of :func:`level_field` and the
    fractions those of :func:`fraction_above`; sub-cells that cannot reach the lowest level are skipped
    (module docstring)."""
    x, y, people, side = points
    if floor_db is None and not edges:
        raise InputError("population scores: give levels or a floor", field="levels")
    floor = min(edges) if floor_db is None else float(floor_db)
    der = _derivatives(band, grid)
    keep = _points_that_count(band, grid, der, x, y, side, min(floor, *edges) if edges else floor)
    L, gx, gy = level_field(band, grid, x[keep], y[keep], der)
    w = people[keep]
    ok = np.isfinite(L) & np.isfinite(gx) & np.isfinite(gy)
    L, gx, gy, wo = L[ok], gx[ok], gy[ok], w[ok]
    above = [_sum_above(wo, L, gx, gy, side, e) for e in edges]
    person_db = float(np.sum(wo * np.maximum(L - floor, 0.0)))
    return {"above": above, "people_without_level": float(w[~ok].sum()), "person_db": person_db}


def population_exposure(levels: LevelsRaster, pop: Population, *, metrics: Sequence[str] | None = None,
                        edges: Sequence[float] | None = None,
                        points: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None) -> dict[str, Any]:
    """People by class and above each level, per level band (see the module docstring).

    ``points``: the population's sub-cells on this grid (:func:`population_points`), when already computed.
    """
    names = list(metrics) if metrics is not None else levels.level_bands()
    edges = list(edges) if edges is not None else class_edges()
    x, y, people, side = points if points is not None else population_points(pop, levels.grid)
    out: dict[str, Any] = {}
    for name in names:
        if name not in levels.bands:
            raise InputError(f"no band {name!r}; bands: {', '.join(levels.bands)}", field="metric")
        sums = population_scores(levels.bands[name], levels.grid, (x, y, people, side), edges)
        above = sums["above"]
        classes = []
        for j, e in enumerate(edges):
            hi = edges[j + 1] if j + 1 < len(edges) else None
            n = above[j] - (above[j + 1] if hi is not None else 0.0)
            classes.append({"from_db": e, "to_db": hi, "people": n})
        out[name] = {"classes": classes,
                     "above": [{"level_db": e, "people": a} for e, a in zip(edges, above, strict=True)],
                     "people_without_level": sums["people_without_level"]}
    return {"total_people": float(people.sum()), "subcell_m": side, "metrics": out}


def area_above(band: np.ndarray, grid: GridSpec, edges: Sequence[float], *, chunk_cells: int = 1 << 20
               ) -> list[float]:
    """Area (m^2 on the ground) of the map where ``band`` exceeds each level.

    Each cell is split into 2 x 2 sub-cells whose levels follow the same rule as people's
    (:func:`level_field`), each linear within itself (:func:`fraction_above`) and weighing a quarter of
    its cell's ground area (:func:`ground_cell_areas`); cells whose bound lies below the lowest level are
    skipped (module docstring).
    """
    edges = list(edges)
    if not edges:
        return []
    der = _derivatives(band, grid)
    rx, ry = grid.resolution
    t = grid.transform
    side = 0.5 * math.sqrt(rx * ry)
    upper = _cell_upper(band, der, 0.25 * rx, 0.25 * ry, side)
    all_rows, all_cols = np.nonzero(~(upper < min(edges)))
    quarter = 0.25 * ground_cell_areas(grid, all_rows, all_cols)
    off = np.array([0.25, 0.75])
    total = np.zeros(len(edges))
    for s in range(0, all_rows.size, chunk_cells):
        rows, cols = all_rows[s:s + chunk_cells], all_cols[s:s + chunk_cells]
        cc = (cols[:, None, None] + off[None, :, None]).astype(float)
        rr = (rows[:, None, None] + off[None, None, :]).astype(float)
        xx = np.broadcast_to(t.c + t.a * cc, (rows.size, 2, 2)).ravel()
        yy = np.broadcast_to(t.f + t.e * rr, (rows.size, 2, 2)).ravel()
        L, gx, gy = level_field(band, grid, xx, yy, der)
        ok = np.isfinite(L) & np.isfinite(gx) & np.isfinite(gy)
        w = np.repeat(quarter[s:s + chunk_cells], 4)[ok]
        total += [_sum_above(w, L[ok], gx[ok], gy[ok], side, e) for e in edges]
    return [float(v) for v in total]


def ground_cell_areas(grid: GridSpec, rows: Any, cols: Any) -> np.ndarray:
    """Ground area (m^2) of the map cells ``rows, cols``: the cell's area in the map's CRS over the CRS's areal scale
    at the cell (:func:`gisnoise.geo.cell_areas`).  Refused (field ``crs``) where PROJ gives no areal scale."""
    a = cell_areas(grid.crs, grid.transform, rows, cols)
    if not np.isfinite(a).all():
        raise InputError("crs: PROJ gives no areal scale for some cells of the map in its CRS; map in a CRS that "
                         "holds them (a UTM zone)", field="crs")
    return a


def person_db_above(band: np.ndarray, grid: GridSpec, points: tuple[np.ndarray, np.ndarray, np.ndarray, float],
                    floor_db: float) -> float:
    """Total exposure in person-dB above ``floor_db``: the sum over people of ``max(L - floor, 0)``.

    ``points`` are :func:`population_points`; each sub-cell's level is taken at its centre.
    """
    return float(population_scores(band, grid, points, [], floor_db)["person_db"])


def cell_values(band: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The value of the map cell holding each point ``x, y`` (grid CRS); NaN outside the grid."""
    col, row = apply_affine(~grid.transform, np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    c = np.floor(np.asarray(col)).astype(np.int64)
    r = np.floor(np.asarray(row)).astype(np.int64)
    h, w = band.shape
    inside = (c >= 0) & (c < w) & (r >= 0) & (r < h)
    out = np.full(c.shape, np.nan)
    out[inside] = band[r[inside], c[inside]]
    return out


def events_area_above(band: np.ndarray, grid: GridSpec, edges: Sequence[float]) -> list[float]:
    """Area (m^2 on the ground) where a count band (N-above, events) reaches each edge: whole cells
    (:func:`ground_cell_areas`), as the band is constant over a cell (a count changes in whole events, so it is
    not interpolated)."""
    if not len(edges):
        return []
    with np.errstate(invalid="ignore"):
        rows, cols = np.nonzero(band >= min(edges))
    area = ground_cell_areas(grid, rows, cols)
    v = band[rows, cols]
    return [float(np.sum(area[v >= e])) for e in edges]


def population_event_exposure(band: np.ndarray, grid: GridSpec,
                              points: tuple[np.ndarray, np.ndarray, np.ndarray, float],
                              edges: Sequence[float]) -> dict[str, Any]:
    """People by class of a count band (N-above, events): each sub-cell takes the count of the map cell
    holding it; classes ``[edge_j, edge_j+1)``, the last open.  People on cells without value (or points given
    outside the map) are ``people_without_level``."""
    x, y, people, _ = points
    v = cell_values(band, grid, x, y)
    ok = np.isfinite(v)
    above = [float(np.sum(people[ok & (v >= e)])) for e in edges]
    classes = [{"from": e, "to": edges[j + 1] if j + 1 < len(edges) else None,
                "people": above[j] - (above[j + 1] if j + 1 < len(edges) else 0.0)} for j, e in enumerate(edges)]
    return {"classes": classes, "above": [{"level": e, "people": a} for e, a in zip(edges, above, strict=True)],
            "people_without_level": float(people[~ok].sum())}
