"""Exposure layers: a population raster, buildings with residents, and a written levels raster.

* :func:`read_population`: a GeoTIFF (any CRS, any driver rasterio reads) whose band 1
  holds people per cell; nodata cells hold no data (people there are unknown, not none, as outside the raster),
  any other cell that is not a finite count >= 0 (negative, NaN, infinite) refuses the raster, and so does one
  denser than any city block has been (:data:`DENSEST_BLOCK_PER_KM2`: a density read as people per cell).
* :func:`read_buildings`: polygons (GeoPackage, GeoJSON, Shapefile, anything pyogrio reads), courtyards
  (holes) kept, with optional attributes for residents, dwellings, height and storeys.  A null (empty)
  residents or dwellings value is unknown for that building, not 0: its façade is classed, its residents
  are not counted and a warning says so (one missing value in a city's layer should not refuse the layer,
  nor count as nobody); any other value that is not a number >= 0 refuses the layer, naming the feature.
  A layer without a residents attribute (none of :data:`RESIDENT_FIELDS`, none named) is read with a
  warning naming the names looked for.  Heights are read in OpenStreetMap's forms (``"10"``, ``"10 m"``,
  ``"12 ft"``: :func:`gisnoise.exposure.storeys.parse_height`) and storeys from ``building:levels``
  (:data:`LEVEL_FIELDS`); a value that is neither is unknown for that building, never a reason to refuse
  the layer, and one warning per attribute says how many there are and shows the first.
* :func:`read_levels`: the ``levels.tif`` a map wrote, back as bands on its grid.
"""

from __future__ import annotations

import json
import os
from dataclasses import InitVar, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from affine import Affine
from pyproj import CRS

from gisnoise.errors import InputError
from gisnoise.exposure.storeys import is_blank, parse_height, parse_levels
from gisnoise.geo import GridSpec

__all__ = ["Population", "population_cells", "Buildings", "LevelsRaster", "read_population", "read_buildings", "read_levels",
           "RESIDENT_FIELDS", "DWELLING_FIELDS", "HEIGHT_FIELDS", "LEVEL_FIELDS", "DENSEST_BLOCK_PER_KM2",
           "DENSEST_DISTRICTS_PER_KM2", "BLOCK_M2"]

RESIDENT_FIELDS = ("residents", "population", "pop", "inhabitants", "persons", "people")
"""Attribute names tried, in order, for the residents of a building (case-insensitive)."""
DWELLING_FIELDS = ("dwellings", "households", "units", "flats")
"""Attribute names tried, in order, for the dwellings of a building (case-insensitive)."""
HEIGHT_FIELDS = ("height", "height_m", "building_height")
"""Attribute names tried, in order, for the height of a building, m (case-insensitive)."""
LEVEL_FIELDS = ("building:levels", "building_levels", "levels", "storeys", "floors")
"""Attribute names tried, in order, for the storeys above ground of a building (case-insensitive)."""


DENSEST_BLOCK_PER_KM2 = 1_500_000.0
"""People per km² of ground above which a population raster is refused: more than any city block has held.  The
densest on record, Kowloon Walled City (Hong Kong), held about 33 000 people on 2.6 ha in the late 1980s, about
1.3 million per km².  A density (people per km²) read as people per cell exceeds it wherever the density exceeds
15 000 per km² on cells of 1 ha or less (judged over :data:`BLOCK_M2`), more on larger cells (on 1 km cells a
density is a count)."""
DENSEST_DISTRICTS_PER_KM2 = 300_000.0
"""People per km² of ground above which a population raster is read with a warning: about what the densest
districts on record hold on average (Dharavi, Mumbai: some 300 000 per km²); a density read as people per cell
exceeds it wherever the density exceeds 3 000 per km² on cells of 1 ha or less."""
BLOCK_M2 = 10_000.0
"""A cell smaller than this (1 ha) is judged as if its people spread over 1 ha: one tower may fill a small cell."""


@dataclass(frozen=True, eq=False)
class Population:
    """People per cell of a north-up raster, checked as :func:`read_population` checks a file.

    Made from an array (``Population(counts, transform, crs)``) or by :func:`read_population`, the same rules hold
    (:func:`population_cells`): cells without data are those masked (a :class:`numpy.ma.MaskedArray`, as a
    raster's nodata value reads) or marked ``covered=False``; they count no people and are not covered (people
    there are unknown, not none).  Every other cell must be a finite count >= 0: a NaN, infinite or negative
    one is refused, not counted as 0 (mask NaN cells that hold no data: ``numpy.ma.masked_invalid(counts)``).
    A cell denser than any city block (:data:`DENSEST_BLOCK_PER_KM2`: a density, people per km² or per hectare,
    given as people per cell) is refused, one denser than the densest districts named in ``warnings``.  The
    raster is north-up without rotation, with a CRS.

    Attributes
    ----------
    counts : ndarray of float64, shape (height, width)
        People per cell (0 where the raster has nodata).
    transform : affine.Affine
        Pixel-corner transform in the raster's CRS.
    crs : pyproj.CRS
    source : str
        The file, or what the caller names the array (the refusals and warnings name its last path part).
    covered : ndarray of bool, shape (height, width), or None
        The cells that hold data; False where the raster has nodata: people there are unknown, not none, as
        outside the raster's extent.  None: every cell.
    warnings : list of str
        What the checks found that the counts depend on (cells denser than the densest districts on record).
    window : tuple of int
        Given when made: row and column of ``counts[0, 0]`` in the source raster (a window of it), so that the
        refusals name the cell as the file holds it.  Not kept.

    Raises
    ------
    InputError
        On field ``population``, in one line naming the source and the first bad cell.
    """

    counts: np.ndarray
    transform: Affine
    crs: Any
    source: str = "population"
    covered: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)
    window: InitVar[tuple[int, int]] = (0, 0)

    def __post_init__(self, window: tuple[int, int]) -> None:
        counts, covered, crs, said = population_cells(self.counts, self.transform, self.crs, self.source,
                                                      covered=self.covered, window=window)
        object.__setattr__(self, "counts", counts)
        object.__setattr__(self, "covered", covered)
        object.__setattr__(self, "crs", crs)
        warnings = list(self.warnings)
        if said is not None and said not in warnings:
            warnings.append(said)
        object.__setattr__(self, "warnings", warnings)

    @property
    def total(self) -> float:
        return float(self.counts.sum())


def population_cells(counts: Any, transform: Any, crs: Any, source: str, *, covered: Any = None,
                     window: tuple[int, int] = (0, 0)) -> tuple[np.ndarray, np.ndarray | None, CRS, str | None]:
    """The rules of a population raster (:class:`Population`): ``(counts, covered, crs, warning)`` checked.

    ``counts``: people per cell, an array or a masked array (masked: no data); ``covered``: optional, False where
    there is no data.  Returns the counts as float64 with 0 where there is no data, the covered cells (None when
    every cell is), the CRS as :class:`pyproj.CRS` and the warning of a raster denser than the densest districts
    (None when none is).  ``window``: row and column of ``counts[0, 0]`` in the source, for the messages.

    Raises :class:`~gisnoise.errors.InputError` (field ``population``) as the class documents.
    """
    name = Path(str(source)).name or str(source)
    if crs is None:
        raise InputError(f"population: {name} has no CRS", field="population")
    try:
        crs = CRS.from_user_input(crs)
    except Exception as exc:  # pyproj's CRSError and the TypeError of an unreadable object alike
        raise InputError(f"population: {name}: not a CRS: {crs!r} ({exc})", field="population") from None
    if not isinstance(transform, Affine):
        raise InputError(f"population: {name}: the transform must be an affine.Affine, got {type(transform).__name__}",
                         field="population")
    _north_up(transform, "population")
    try:
        data = np.asarray(np.ma.getdata(counts), dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"population: {name}: people per cell must be numbers", field="population") from None
    if data.ndim != 2:
        raise InputError(f"population: {name}: people per cell must be a 2-D array (rows, columns), got shape "
                         f"{data.shape}", field="population")
    nodata = np.ma.getmaskarray(counts) if np.ma.isMaskedArray(counts) else np.zeros(data.shape, dtype=bool)
    if covered is not None:
        cov = np.asarray(covered)
        if cov.shape != data.shape or cov.dtype != bool:
            raise InputError(f"population: {name}: covered must be a boolean array of the counts' shape {data.shape}",
                             field="population")
        nodata = nodata | ~cov
    with np.errstate(invalid="ignore"):
        bad = ~nodata & ~(np.isfinite(data) & (data >= 0))
    if bad.any():
        r, c = (int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"population: {name} has {int(bad.sum())} cell(s) that are not a number of people >= 0 "
                         f"(first {data[r, c]:g} at row {r + window[0]}, column {c + window[1]}); people per cell "
                         "must be finite and >= 0, cells without data must be marked as such (the raster's nodata "
                         "value; in an array, masked or covered=False)", field="population")
    out = np.where(nodata, 0.0, data)
    said = _density_said(out, transform, crs, name, window)
    return out, (~nodata if nodata.any() else None), crs, said


@dataclass(frozen=True, eq=False)
class Buildings:
    """Building footprints with residents, dwellings, heights and storeys.

    Attributes
    ----------
    polygons : list of shapely Polygon
        Footprints with their courtyards (holes) (multi-polygons split into parts, each part keeping
        its building's index in ``part_of``), in ``crs``.
    part_of : ndarray of int
        Building index of each polygon.
    residents, dwellings, height_m : ndarray of float, one per building, or None
        From the attributes; None when the layer has no such attribute.  A building whose residents or
        dwellings are null (empty) holds 0 there and is marked in ``unknown``; a height, m, that is null
        or not a height (:func:`~gisnoise.exposure.storeys.parse_height`) is NaN.
    crs : pyproj.CRS
    fields : dict
        Which attribute gave residents, dwellings and height (and ``levels``, when the layer has one).
    unknown : dict of str -> ndarray of bool
        Per attribute (``residents``, ``dwellings``) that has null values, the buildings without a value.
    warnings : list of str
        What the reader found that the counts depend on: null values, no residents attribute, heights or
        storeys that do not read.
    levels : ndarray of float or None
        Storeys above ground per building (``building:levels``), NaN where null or not a number of storeys
        (:func:`~gisnoise.exposure.storeys.parse_levels`); None when the layer has no such attribute.
    """

    polygons: list
    part_of: np.ndarray
    n: int
    residents: np.ndarray | None
    dwellings: np.ndarray | None
    height_m: np.ndarray | None
    crs: Any
    source: str = "buildings"
    fields: dict[str, str | None] = field(default_factory=dict)
    unknown: dict[str, np.ndarray] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    levels: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class LevelsRaster:
    """The bands of a written map (``levels.tif``) on its grid."""

    bands: dict[str, np.ndarray]
    grid: GridSpec
    units: dict[str, str]
    metadata: dict[str, Any]

    def level_bands(self) -> list[str]:
        """Bands holding levels in dB(A) (the ones exposure is classed by)."""
        return [b for b in self.bands if self.units.get(b) == "dB(A)"]


def _north_up(t: Affine, fld: str) -> None:
    if t.b != 0 or t.d != 0 or not (t.a > 0 and t.e < 0):
        raise InputError(f"{fld}: the raster must be north-up without rotation", field=fld)


def read_population(path: str | os.PathLike[str], *, band: int = 1, within: GridSpec | None = None) -> Population:
    """Read a population raster: people per cell of band ``band``.

    Cells holding the raster's nodata value hold no data: no people are counted there, and they are not covered
    (``Population.covered``), so the counts of a map reaching them are lower bounds, as where the raster ends (a
    national raster holds nodata beyond the border: the people there are unknown, not none).  Every other cell
    must be a finite count >= 0: a negative, NaN or infinite value is refused, not counted as 0 (an infinite
    count would otherwise vanish from every total, a NaN one hide a hole in the data).  A cell holding more
    people per km² of ground than :data:`DENSEST_BLOCK_PER_KM2` is refused (a density, people per km² or per
    hectare, read as people per cell); one above :data:`DENSEST_DISTRICTS_PER_KM2` is named in a warning
    (``Population.warnings``).  Cells smaller than :data:`BLOCK_M2` are judged over that area.  These are the
    rules of :class:`Population` itself (:func:`population_cells`): a population made from an array is checked
    alike, its masked cells read as the file's nodata.

    Parameters
    ----------
    within : GridSpec, optional
        Read only the window of the raster that the grid's extent may touch
        (:func:`gisnoise.geo.raster_window`); its checks then apply to that window.  Default the whole raster.

    Raises
    ------
    InputError
        No such file, no CRS, a rotated raster, a cell other than nodata that is not a finite count >= 0 (the
        first one named with its row, column and value), or a cell denser than any city block.
    """
    import rasterio
    from rasterio.errors import RasterioIOError
    from rasterio.windows import Window

    from gisnoise.geo import raster_window

    p = Path(path)
    r0 = c0 = 0
    try:
        with rasterio.open(p) as src:
            if src.crs is None:
                raise InputError(f"population: {p.name} has no CRS", field="population")
            if not 1 <= band <= src.count:
                raise InputError(f"population: band {band} not in 1..{src.count}", field="population")
            t, crs = src.transform, CRS.from_wkt(src.crs.to_wkt())
            _north_up(t, "population")
            win = None
            if within is not None:
                r0, r1, c0, c1 = raster_window(t, (src.height, src.width), crs, within)
                win = Window(c0, r0, c1 - c0, r1 - r0)
                t = Affine(t.a, 0.0, t.c + t.a * c0, 0.0, t.e, t.f + t.e * r0)  # north-up: the window's corner
            if win is not None and (win.width == 0 or win.height == 0):  # the grid lies beside the raster
                a = np.ma.masked_array(np.zeros((0, 0)), mask=np.zeros((0, 0), dtype=bool))
            else:
                a = src.read(band, masked=True, window=win).astype(np.float64)
    except RasterioIOError as exc:  # the file's name only: its folder may be a server's
        raise InputError(f"population: cannot read {p.name}: {str(exc).replace(str(p), p.name)}",
                         field="population") from None
    return Population(a, t, crs, source=str(p), window=(r0, c0))  # the class's checks (population_cells)


def _density_said(counts: np.ndarray, t: Affine, crs: Any, name: str, offset: tuple[int, int]) -> str | None:
    """Refuse a raster denser than :data:`DENSEST_BLOCK_PER_KM2` in some cell; the warning of one denser than
    :data:`DENSEST_DISTRICTS_PER_KM2` (None when no cell is).  Cells are judged over their ground area
    (:func:`gisnoise.geo.cell_areas`), at least :data:`BLOCK_M2`; ``offset`` (rows, columns) places a window's
    cells in the file, for the message."""
    from gisnoise.geo import cell_areas

    _refuse_dense_blocks(counts, t, crs, name, offset)
    rows, cols = np.nonzero(counts > DENSEST_DISTRICTS_PER_KM2 * BLOCK_M2 / 1e6)  # fewer cannot be denser
    if rows.size == 0:
        return None
    area = cell_areas(crs, t, rows, cols)
    with np.errstate(invalid="ignore"):
        per_km2 = counts[rows, cols] / np.maximum(area, BLOCK_M2) * 1e6  # NaN where PROJ gives no area
    if not np.isfinite(per_km2).any():
        return None
    k = int(np.nanargmax(per_km2))
    top, people, ha = float(per_km2[k]), float(counts[rows[k], cols[k]]), float(area[k]) / 1e4
    where = f"row {int(rows[k]) + offset[0]}, column {int(cols[k]) + offset[1]}"
    if top > DENSEST_BLOCK_PER_KM2:
        raise InputError(f"population: {name} holds {people:.0f} people in one cell ({where}, {ha:.2f} ha of ground): "
                         f"{top:.0f} per km², more than any city block has held ({DENSEST_BLOCK_PER_KM2:.0f} per "
                         "km²; Kowloon Walled City held about 1.3 million): it looks like a density (people per km² "
                         "or per hectare); give people per cell", field="population")
    if top <= DENSEST_DISTRICTS_PER_KM2:
        return None
    n = int(np.sum(per_km2 > DENSEST_DISTRICTS_PER_KM2))
    return (f"population: {name} holds up to {top:.0f} people per km² of ground ({people:.0f} people in one cell, "
            f"{where}; {n} cell(s) above {DENSEST_DISTRICTS_PER_KM2:.0f} per km², about the densest districts on "
            "record): if it holds a density (people per km² or per hectare) and not people per cell, every count "
            "is too large; give people per cell")


def _refuse_dense_blocks(counts: np.ndarray, t: Affine, crs: Any, name: str, offset: tuple[int, int]) -> None:
    """Refuse a raster of cells smaller than :data:`BLOCK_M2` whose densest block of about that area (k x k cells)
    holds more than :data:`DENSEST_BLOCK_PER_KM2`: each cell is judged over a hectare, so a density on small cells
    (3 000 per km² given as people per 10 m cell: 3 000 people in each) passes cell by cell but not as a block."""
    from gisnoise.geo import cell_areas

    if counts.ndim != 2 or min(counts.shape) < 2:
        return
    area = float(cell_areas(crs, t, counts.shape[0] // 2, counts.shape[1] // 2))
    if not np.isfinite(area) or area <= 0.0 or area >= 0.5 * BLOCK_M2:
        return
    k = min(int(round(np.sqrt(BLOCK_M2 / area))), *counts.shape)
    c = np.zeros((counts.shape[0] + 1, counts.shape[1] + 1))
    np.cumsum(np.cumsum(np.nan_to_num(counts, nan=0.0), axis=0), axis=1, out=c[1:, 1:])
    sums = c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]  # every k x k block
    r, q = np.unravel_index(int(np.argmax(sums)), sums.shape)
    top = float(sums[r, q]) / (k * k * area) * 1e6
    if top > DENSEST_BLOCK_PER_KM2:
        raise InputError(f"population: {name} holds {float(sums[r, q]):.0f} people in {k} x {k} cells from row "
                         f"{int(r) + offset[0]}, column {int(q) + offset[1]} ({k * k * area / 1e4:.2f} ha of ground): "
                         f"{top:.0f} per km², more than any city block has held ({DENSEST_BLOCK_PER_KM2:.0f} per "
                         "km²): it looks like a density (people per km² or per hectare); give people per cell",
                         field="population")


def _pick(columns: list[str], wanted: str | None, names: tuple[str, ...], what: str) -> str | None:
    lower = {c.lower(): c for c in columns}
    if wanted is not None:
        if wanted.lower() not in lower:
            raise InputError(f"buildings: no attribute {wanted!r} for {what}; attributes: {', '.join(columns)}",
                             field=what)
        return lower[wanted.lower()]
    for n in names:
        if n in lower:
            return lower[n]
    return None


def _plain(v: Any) -> str:
    """A value of an attribute as the layer holds it, without numpy's wrapping (``-5``, not ``np.int32(-5)``)."""
    v = v.item() if isinstance(v, np.generic) else v
    return repr(v) if isinstance(v, (str, bytes)) else f"{v:g}" if isinstance(v, float) else str(v)


def _numbers(df: Any, col: str | None, what: str) -> tuple[np.ndarray | None, np.ndarray]:
    """The numbers of attribute ``col`` and which features leave it null (empty); refuses any other value that is
    not a finite number >= 0, naming the feature and the value."""
    import pandas as pd

    if col is None:
        return None, np.zeros(len(df), dtype=bool)
    raw = df[col]
    null = np.asarray(raw.isna(), dtype=bool)
    kind = [isinstance(x, (bool, np.bool_)) for x in raw]  # true/false are no counts
    v = pd.to_numeric(raw.where(~np.asarray(kind, dtype=bool)), errors="coerce").to_numpy(dtype=float, copy=True)
    bad = ~null & (~np.isfinite(v) | (v < 0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"buildings: attribute {col!r} ({what}) of feature {i} is {_plain(raw.iloc[i])}, "
                         "not a number >= 0", field=what)
    return v, null


def _unknown_warning(name: str, col: str, what: str, null: np.ndarray) -> str:
    first = int(np.flatnonzero(null)[0])
    return (f"buildings: {name}: {int(null.sum())} of {null.size} buildings have no value of {col!r} ({what}; "
            f"first feature {first}): unknown, not 0; their façades are classed, their {what} are not counted, so "
            f"the {what} by class are lower bounds ({what}_unknown: the buildings without a value in each class)")


def _parsed(df: Any, col: str | None, name: str, what: str, parse: Any, reads: str,
            then: str) -> tuple[np.ndarray | None, str | None]:
    """The values of attribute ``col`` through ``parse`` (NaN: unknown), and the warning naming how many non-null
    values did not read and what follows (``then``); None when all did."""
    if col is None:
        return None, None
    raw = list(df[col])
    v = np.array([parse(x) for x in raw], dtype=float)
    bad = np.array([not is_blank(x) for x in raw], dtype=bool) & ~np.isfinite(v)
    if not bad.any():
        return v, None
    i = int(np.flatnonzero(bad)[0])
    return v, (f"buildings: {name}: {int(bad.sum())} of {len(raw)} buildings have a value of {col!r} ({what}) that "
               f"is not {reads} (first feature {i}: {_plain(raw[i])}): unknown, {then}")


def read_buildings(path: str | os.PathLike[str], *, layer: str | None = None, residents: str | None = None,
                   dwellings: str | None = None, height: str | None = None, levels: str | None = None) -> Buildings:
    """Read building footprints (polygons, courtyards kept) with residents, dwellings, height and storeys.

    Attribute names default to the first of :data:`RESIDENT_FIELDS`, :data:`DWELLING_FIELDS`,
    :data:`HEIGHT_FIELDS`, :data:`LEVEL_FIELDS` that the layer has.  Heights are read in m or ft
    (:func:`~gisnoise.exposure.storeys.parse_height`), storeys as numbers
    (:func:`~gisnoise.exposure.storeys.parse_levels`); values that do not read are unknown for their
    building, and a warning says how many (never a refusal of the layer).
    """
    import geopandas as gpd

    p = Path(path)
    if not p.exists():
        raise InputError(f"buildings: no such file {p}", field="buildings")
    try:
        df = gpd.read_file(p, layer=layer, engine="pyogrio")
    except Exception as exc:  # pyogrio's errors are many; the message names the file
        said = str(exc).splitlines()[0].replace(str(p), p.name)  # the file's name only: its folder may be a server's
        raise InputError(f"buildings: cannot read {p.name}: {said}", field="buildings") from None
    if df.crs is None:
        raise InputError(f"buildings: {p.name} has no CRS", field="buildings")
    if len(df) == 0:
        raise InputError(f"buildings: {p.name} has no features", field="buildings")
    cols = [c for c in df.columns if c != df.geometry.name]
    rc = _pick(cols, residents, RESIDENT_FIELDS, "residents")
    dc = _pick(cols, dwellings, DWELLING_FIELDS, "dwellings")
    hc = _pick(cols, height, HEIGHT_FIELDS, "height")
    lc = _pick(cols, levels, LEVEL_FIELDS, "levels")
    polys: list = []
    part_of: list[int] = []
    for i, g in enumerate(df.geometry):
        if g is None or g.is_empty:
            raise InputError(f"buildings: feature {i} has no geometry", field="buildings")
        if g.geom_type == "Polygon":
            parts = [g]
        elif g.geom_type == "MultiPolygon":
            parts = list(g.geoms)
        else:
            raise InputError(f"buildings: feature {i} is a {g.geom_type}, not a polygon", field="buildings")
        for part in parts:
            polys.append(part)  # with its courtyards: their walls are façades too
            part_of.append(i)
    values: dict[str, np.ndarray | None] = {}
    unknown: dict[str, np.ndarray] = {}
    warnings: list[str] = []
    if rc is None:
        warnings.append(f"buildings: {p.name} has no residents attribute (looked for {', '.join(RESIDENT_FIELDS)}; "
                        f"its attributes: {', '.join(map(str, cols)) or 'none'}): no residents are counted; name the "
                        "attribute with --residents-field")
    for what, col in (("residents", rc), ("dwellings", dc)):
        v, null = _numbers(df, col, what)
        if v is not None and null.any():
            v[null] = 0.0
            unknown[what] = null
            warnings.append(_unknown_warning(p.name, str(col), what, null))
        values[what] = v
    alone = "judged at the façade height alone (no storeys)"
    hv, note = _parsed(df, hc, p.name, "height", parse_height,
                       "a height in m or ft (a number > 0, at most 1000 m, with m, ft or no unit: '10', '10 m', "
                       "'12 ft')", f"so those buildings take their storeys from {lc!r} where it has a value, else are "
                       f"{alone}" if lc is not None else f"so those buildings are {alone}")
    warnings += [note] if note is not None else []
    lv, note = _parsed(df, lc, p.name, "storeys", parse_levels, "a number of storeys > 0",
                       f"so those buildings without a height are {alone}")
    warnings += [note] if note is not None else []
    fields: dict[str, str | None] = {"residents": rc, "dwellings": dc, "height": hc}
    if lc is not None:
        fields["levels"] = lc
    return Buildings(polys, np.asarray(part_of, dtype=int), len(df), values["residents"], values["dwellings"],
                     hv, CRS.from_wkt(df.crs.to_wkt()), source=str(p), fields=fields, unknown=unknown,
                     warnings=warnings, levels=lv)


def read_levels(path: str | os.PathLike[str]) -> LevelsRaster:
    """Read a map's ``levels.tif`` (:func:`gisnoise.maps.write_geotiff`): bands by description, units, metadata."""
    import rasterio
    from rasterio.errors import RasterioIOError

    p = Path(path)
    try:
        with rasterio.open(p) as src:
            names = [d or f"band{i + 1}" for i, d in enumerate(src.descriptions)]
            units = {n: src.tags(i + 1).get("unit", "") for i, n in enumerate(names)}
            bands = {n: np.asarray(src.read(i + 1, masked=True).astype(np.float64).filled(np.nan))
                     for i, n in enumerate(names)}
            meta = json.loads(src.tags().get("gisnoise", "{}"))
            if src.crs is None:
                raise InputError(f"map: {p.name} has no CRS", field="map")
            grid = GridSpec(src.crs.to_wkt(), src.transform, src.width, src.height)
    except RasterioIOError as exc:
        raise InputError(f"map: cannot read {p}: {exc}", field="map") from None
    return LevelsRaster(bands, grid, units, meta)
