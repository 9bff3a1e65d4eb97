"""Receiver grids: a raster (CRS, transform, shape) whose cell centres are the receivers.

A :class:`GridSpec` is a small frozen value object in the manner of rasterio's
``Window``: it knows its CRS, its affine transform (north-up, no rotation), its
width and height, and the coordinates of its cell centres.  The evaluator places
one receiver at the centre of every cell, at a height above the ground.

:func:`grid_for_points` chooses the grid around points (a flight's track, several
flights): their bounding box plus a margin, snapped to multiples of the resolution, in a
local UTM zone unless a CRS is given; grids round a pole, or beyond the UTM zones' latitudes in the default CRS,
are refused.  The number of cells is limited by the environment
variable ``GISNOISE_MAX_CELLS`` (default 25 000 000).

Examples
--------
>>> g = GridSpec.from_bounds("EPSG:32632", 600000.0, 5800000.0, 600100.0, 5800050.0, 10.0)
>>> g.width, g.height, g.n_cells
(10, 5, 50)
>>> x, y = g.centres()
>>> float(x[0, 0]), float(y[0, 0])  # the north-west cell's centre
(600005.0, 5800045.0)
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, Any, TypeVar, cast

import numpy as np
from affine import Affine
from pyproj import CRS, Transformer
from pyproj.exceptions import CRSError as _PyprojCRSError

from gisnoise.errors import CRSError, GridTooLargeError, InvalidGridError

if TYPE_CHECKING:  # pragma: no cover
    from gisnoise.geo.raster import Dem

__all__ = [
    "GridSpec",
    "DEFAULT_MAX_CELLS",
    "max_cells",
    "parse_crs",
    "utm_crs",
    "grid_for_points",
    "resample_dem",
    "transformer",
    "crs_label",
    "scale_factor",
    "apply_affine",
]

DEFAULT_MAX_CELLS = 25_000_000
WGS84 = CRS.from_epsg(4326)
_local = threading.local()
_T = TypeVar("_T")


class _IdentityCache:
    """Values keyed by the identity of the objects they are made of (hashing a CRS formats its WKT, which is slow).

    The objects are kept with their value, so their ids are not reused while cached; past
    ``size`` entries the cache starts afresh.
    """

    def __init__(self, size: int = 64) -> None:
        self._size = size
        self._items: dict[tuple[int, ...], tuple[tuple[object, ...], Any]] = {}

    def get(self, objs: tuple[object, ...], make: Callable[[], _T]) -> _T:
        """The value of ``objs``: cached, else ``make()`` (then cached)."""
        key = tuple(id(o) for o in objs)
        hit = self._items.get(key)
        if hit is not None and all(a is b for a, b in zip(hit[0], objs, strict=True)):
            value: _T = hit[1]
            return value
        if len(self._items) > self._size:
            self._items.clear()
        value = make()
        self._items[key] = (objs, value)
        return value


def transformer(src: CRS, dst: CRS) -> Transformer:
    """A cached ``always_xy`` transformer ``src -> dst`` (one cache per thread: transformers are not shared).

    Keyed by the identity of the CRS objects (:class:`_IdentityCache`).
    """
    cache = getattr(_local, "transformers", None)
    if cache is None:
        cache = _local.transformers = _IdentityCache()
    return cache.get((src, dst), lambda: Transformer.from_crs(src, dst, always_xy=True))


def apply_affine(t: Affine, x: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
    """Apply an affine transform to coordinate arrays (``t * (x, y)`` without the operator's deprecation)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    return t.a * x + t.b * y + t.c, t.d * x + t.e * y + t.f


def crs_label(crs: CRS) -> str:
    """``AUTH:CODE`` of a CRS when it has one, else its WKT.

    Cached by the identity of the CRS object, as :func:`transformer` (the look-up is slow, and so is
    hashing a CRS: it formats its WKT).
    """
    def label() -> str:
        auth = crs.to_authority()
        return ":".join(auth) if auth else crs.to_wkt()

    return _labels.get((crs,), label)


_labels = _IdentityCache()


def scale_factor(crs: CRS, lon: float, lat: float) -> float | None:
    """The point scale factor of a projected CRS at ``lon, lat`` (deg): the geometric mean of PROJ's meridional
    and parallel scale there; None when PROJ gives no factors for the CRS.

    Cached by the identity of the CRS object (as :func:`transformer`) and the point: making the
    ``pyproj.Proj`` of a CRS takes about 0.3 ms, and a service maps the same routes in the same CRS again.

    >>> round(scale_factor(utm_crs(9.0, 52.0), 9.0, 52.0), 6)  # on a UTM zone's central meridian: k0
    0.9996
    """
    key = (float(lon), float(lat))
    table: dict[tuple[float, float], float | None] = _scales.get((crs,), dict)
    hit = table.get(key, _MISSING)  # one look-up: another thread may clear the table meanwhile
    if hit is not _MISSING:
        return cast(float | None, hit)
    from pyproj import Proj
    from pyproj.exceptions import ProjError

    projs = getattr(_local, "projs", None)
    if projs is None:
        projs = _local.projs = _IdentityCache()  # one Proj per thread: pyproj objects are not shared
    k: float | None
    try:
        f = projs.get((crs,), lambda: Proj(crs)).get_factors(*key)
        k = float(np.sqrt(f.meridional_scale * f.parallel_scale))
    except (ProjError, TypeError, ValueError):
        k = None
    if len(table) > 256:
        table.clear()
    table[key] = k
    return k


_scales = _IdentityCache()
"""Per CRS object: scale factors by point (:func:`scale_factor`)."""
_MISSING = object()


def max_cells() -> int:
    """The cell limit: ``GISNOISE_MAX_CELLS`` from the environment, default 25 000 000."""
    raw = os.environ.get("GISNOISE_MAX_CELLS")
    if raw is None or raw.strip() == "":
        return DEFAULT_MAX_CELLS
    try:
        n = int(raw)
    except ValueError:
        raise InvalidGridError(f"GISNOISE_MAX_CELLS must be a positive integer, got {raw!r}",
                               field="GISNOISE_MAX_CELLS") from None
    if n <= 0:
        raise InvalidGridError(f"GISNOISE_MAX_CELLS must be a positive integer, got {raw!r}",
                               field="GISNOISE_MAX_CELLS")
    return n


def parse_crs(crs: Any, *, field: str = "crs") -> CRS:
    """A projected CRS in metres from anything pyproj understands (``"EPSG:25832"``, WKT, ...).

    Raises :class:`~gisnoise.errors.CRSError` naming ``field`` when the CRS is unknown,
    geographic or not in metres.
    """
    if isinstance(crs, CRS):
        out = crs
    else:
        try:
            out = CRS.from_user_input(crs)
        except (_PyprojCRSError, TypeError, ValueError):
            raise CRSError(f"{field}: unknown coordinate reference system {crs!r}", field=field) from None
    if not out.is_projected:
        raise CRSError(f"{field}: {crs!r} is not a projected CRS; the grid needs one in metres "
                       "(e.g. a UTM zone)", field=field)
    unit = out.axis_info[0].unit_name if out.axis_info else ""
    if unit not in ("metre", "meter"):
        raise CRSError(f"{field}: {crs!r} has axis unit {unit!r}; the grid needs metres", field=field)
    return out


def utm_crs(lon: float, lat: float) -> CRS:
    """The WGS84 UTM zone CRS (EPSG 326xx north, 327xx south) containing ``lon, lat`` (deg).

    >>> utm_crs(9.99, 53.55).to_epsg()  # Hamburg
    32632
    """
    if not (math.isfinite(lon) and math.isfinite(lat)) or abs(lat) > 90:
        raise CRSError(f"no UTM zone for lon={lon!r}, lat={lat!r}", field="crs")
    zone = int(math.floor((((lon + 180.0) % 360.0)) / 6.0)) + 1
    zone = min(max(zone, 1), 60)
    return _epsg_crs((32600 if lat >= 0 else 32700) + zone)


@lru_cache(maxsize=128)
def _epsg_crs(code: int) -> CRS:
    """One CRS object per EPSG code, so the per-thread transformer cache (keyed by identity) hits."""
    return CRS.from_epsg(code)


@dataclass(frozen=True)
class GridSpec:
    """A north-up raster of receivers.

    Parameters
    ----------
    crs : pyproj.CRS or str
        Projected CRS in metres (anything :func:`parse_crs` accepts).
    transform : affine.Affine
        Pixel-corner transform ``(col, row) -> (x, y)``; ``a > 0``, ``e < 0``, no rotation.
    width, height : int
        Number of columns and rows.

    Notes
    -----
    The receiver of cell ``(row, col)`` is the cell centre
    ``transform * (col + 0.5, row + 0.5)``; row 0 is the northern edge.
    """

    crs: Any
    transform: Affine
    width: int
    height: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "crs", parse_crs(self.crs))
        t = self.transform
        if not isinstance(t, Affine):
            try:
                t = Affine(*tuple(t)[:6])
            except TypeError:
                raise InvalidGridError(f"grid: transform must be an affine transform, got {t!r}",
                                       field="transform") from None
            object.__setattr__(self, "transform", t)
        if not all(math.isfinite(v) for v in tuple(t)[:6]):
            raise InvalidGridError(f"grid: transform has non-finite entries {tuple(t)[:6]}", field="transform")
        if t.b != 0 or t.d != 0:
            raise InvalidGridError("grid: rotated transforms are not supported", field="transform")
        if not (t.a > 0 and t.e < 0):
            raise InvalidGridError(f"grid: transform must be north-up with positive cell size, got a={t.a}, e={t.e}",
                                   field="transform")
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
                raise InvalidGridError(f"grid: {name} must be a positive integer, got {v!r}", field=name)
            object.__setattr__(self, name, int(v))

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_bounds(cls, crs: Any, left: float, bottom: float, right: float, top: float,
                    resolution: float) -> GridSpec:
        """The grid covering ``[left, right] x [bottom, top]`` (m) with square cells of ``resolution`` m.

        The upper-left corner is kept; width and height are rounded up.
        """
        _check_positive(resolution, "resolution_m")
        if not (right > left and top > bottom):
            raise InvalidGridError(f"grid: empty bounds ({left}, {bottom}, {right}, {top})", field="bounds")
        width = max(1, int(math.ceil((right - left) / resolution - 1e-9)))
        height = max(1, int(math.ceil((top - bottom) / resolution - 1e-9)))
        return cls(crs, Affine(resolution, 0.0, left, 0.0, -resolution, top), width, height)

    # ------------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``: the shape of the bands."""
        return (self.height, self.width)

    @property
    def n_cells(self) -> int:
        return self.width * self.height

    @property
    def resolution(self) -> tuple[float, float]:
        """Cell size ``(dx, dy)``, m."""
        return (self.transform.a, -self.transform.e)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(left, bottom, right, top)`` of the raster's outer edges, CRS units (m)."""
        t = self.transform
        return (t.c, t.f + t.e * self.height, t.c + t.a * self.width, t.f)

    @property
    def xs(self) -> np.ndarray:
        """Easting of the cell centres of each column, m, shape ``(width,)``."""
        t = self.transform
        return t.c + t.a * (np.arange(self.width) + 0.5)

    @property
    def ys(self) -> np.ndarray:
        """Northing of the cell centres of each row, m, shape ``(height,)`` (decreasing)."""
        t = self.transform
        return t.f + t.e * (np.arange(self.height) + 0.5)

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre coordinates ``(x, y)``, each of shape ``(height, width)``, m."""
        return np.meshgrid(self.xs, self.ys)

    def flat_centres(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """Cell centres ``(x, y)`` of flat (row-major) cell indices ``start <= k < stop``."""
        k = np.arange(start, stop)
        row, col = np.divmod(k, self.width)
        t = self.transform
        return t.c + t.a * (col + 0.5), t.f + t.e * (row + 0.5)

    def to_wgs84(self, x: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
        """Grid coordinates (m) -> ``(lon, lat)`` in degrees.  Arrays broadcast."""
        lon, lat = transformer(self.crs, WGS84).transform(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        return np.asarray(lon), np.asarray(lat)

    def from_wgs84(self, lon: Any, lat: Any) -> tuple[np.ndarray, np.ndarray]:
        """``(lon, lat)`` degrees -> grid coordinates (m).  Arrays broadcast."""
        x, y = transformer(WGS84, self.crs).transform(np.asarray(lon, dtype=float), np.asarray(lat, dtype=float))
        return np.asarray(x), np.asarray(y)

    def centre_wgs84(self) -> tuple[float, float]:
        """``(lon, lat)`` of the grid's centre, deg."""
        left, bottom, right, top = self.bounds
        lon, lat = self.to_wgs84(0.5 * (left + right), 0.5 * (bottom + top))
        return float(lon), float(lat)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able description (CRS as ``AUTH:CODE`` when it has one, else WKT)."""
        return {"crs": crs_label(self.crs), "transform": list(tuple(self.transform)[:6]),
                "width": self.width, "height": self.height}


def _check_positive(v: Any, name: str) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InvalidGridError(f"{name} must be a positive number of metres, got {v!r}", field=name) from None
    if not math.isfinite(f) or f <= 0:
        raise InvalidGridError(f"{name} must be a positive number of metres, got {v!r}", field=name)
    return f


def check_cell_limit(width: int, height: int, *, field: str = "resolution_m") -> None:
    """Raise :class:`~gisnoise.errors.GridTooLargeError` when ``width * height`` exceeds :func:`max_cells`."""
    limit = max_cells()
    n = width * height
    if n > limit:
        raise GridTooLargeError(
            f"{field}: a grid of {width} x {height} = {n:,} cells exceeds the limit of {limit:,} cells "
            "(GISNOISE_MAX_CELLS); use a coarser resolution or a smaller margin", field=field)


def grid_for_points(lon: Any, lat: Any, resolution_m: float = 10.0, margin_m: float = 500.0,
                    crs: Any = None) -> GridSpec:
    """The receiver grid around points.

    Parameters
    ----------
    lon, lat : array_like
        WGS84 longitude and latitude of the points, deg; their horizontal extent sets the grid.
    resolution_m : float
        Cell size, m (> 0).
    margin_m : float
        Distance added on every side of the points' bounding box, m (>= 0).
    crs : str or pyproj.CRS, optional
        Projected CRS in metres; default the WGS84 UTM zone of the points' centre.

    Returns
    -------
    GridSpec
        Edges snapped to multiples of ``resolution_m`` in the CRS.

    Raises
    ------
    CRSError
        ``crs`` is unknown, geographic or not in metres (field ``crs``); without ``crs``, the grid reaches beyond
        the latitudes of the UTM zones, 80 deg S to 84 deg N (field ``crs``; the message names the UPS CRS to give).
    InvalidGridError
        Resolution or margin out of range; the grid contains a pole (field ``margin_m``, or ``trajectory`` when the
        points' own extent holds it): contours in longitude and latitude cannot be drawn round it
        (:func:`_check_polar`).
    GridTooLargeError
        More cells than ``GISNOISE_MAX_CELLS`` (field ``resolution_m``).

    Examples
    --------
    >>> g = grid_for_points([9.99, 10.0], [53.55, 53.55], 10.0, 100.0)
    >>> g.crs.to_epsg(), g.resolution
    (32632, (10.0, 10.0))
    """
    res = _check_positive(resolution_m, "resolution_m")
    try:
        margin = float(margin_m)
    except (TypeError, ValueError):
        raise InvalidGridError(f"margin_m must be a number of metres >= 0, got {margin_m!r}", field="margin_m") from None
    if not math.isfinite(margin) or margin < 0:
        raise InvalidGridError(f"margin_m must be a number of metres >= 0, got {margin_m!r}", field="margin_m")
    lat = np.asarray(lat, dtype=float)
    out_crs, x_min, x_max, y_min, y_max = _projected_bounds(np.asarray(lon, dtype=float), lat, crs)
    left = math.floor((x_min - margin) / res) * res
    right = math.ceil((x_max + margin) / res) * res
    bottom = math.floor((y_min - margin) / res) * res
    top = math.ceil((y_max + margin) / res) * res
    if right <= left:
        right = left + res
    if top <= bottom:
        top = bottom + res
    width = int(round((right - left) / res))
    height = int(round((top - bottom) / res))
    check_cell_limit(width, height)
    # in a UTM zone (scale within 0.1 % of 1) the grid reaches less than this many degrees of latitude beyond the
    # points (a degree is over 110 km): ordinary maps are not transformed again for the polar checks
    reach = (margin + res + math.hypot(x_max - x_min, y_max - y_min)) / 100_000.0
    if crs is not None or float(lat.max()) + reach >= UTM_LATITUDES[1] or float(lat.min()) - reach <= UTM_LATITUDES[0]:
        _check_polar(out_crs, (left, bottom, right, top), (x_min, y_min, x_max, y_max), margin, res,
                     default_crs=crs is None)
    return GridSpec(out_crs, Affine(res, 0.0, left, 0.0, -res, top), width, height)


UTM_LATITUDES = (-80.0, 84.0)
"""Latitudes (deg) between which the UTM zones are defined; beyond, the polar stereographic (UPS) grids are."""


def _check_polar(crs: CRS, edges: tuple[float, float, float, float], track: tuple[float, float, float, float],
                 margin: float, res: float, *, default_crs: bool) -> None:
    """Refuse a grid that contains a pole, or, in the default CRS (a UTM zone), reaches beyond its latitudes.

    A map is contoured in longitude and latitude (RFC 7946): round a pole, every longitude meets, and a ring
    about the pole's neighbourhood drawn in longitude and latitude is not the area it encloses (a band round the
    pole would need the pole's latitude as an edge and all longitudes at once).  Such maps are refused, not drawn
    wrong: ``margin_m`` is named with the largest margin that keeps the pole out when the track's own extent
    stays off it (less one cell ``res``, m, for the edges' snapping), else ``trajectory``.  Beyond 84 deg N or 80 deg S the UTM zones are not defined; the default
    CRS is refused there, naming ``crs`` and the polar stereographic CRS to give (UPS North EPSG:32661, South
    EPSG:32761).  ``edges``: the grid's (left, bottom, right, top), ``track``: the points' bounding box
    (x_min, y_min, x_max, y_max), m in ``crs``.
    """
    left, bottom, right, top = edges
    x_min, y_min, x_max, y_max = track
    px, py = transformer(WGS84, crs).transform([0.0, 0.0], [90.0, -90.0])
    for name, x, y in zip(("North", "South"), px, py, strict=True):
        if not (math.isfinite(x) and math.isfinite(y) and left <= x <= right and bottom <= y <= top):
            continue
        off = max(x_min - x, x - x_max, y_min - y, y - y_max)  # how far the track's extent stays off the pole, m
        why = ("contours in longitude and latitude cannot be drawn round a pole, so gisnoise refuses such maps "
               "rather than draw them wrong")
        if off > 0:
            raise InvalidGridError(f"margin_m: the grid with a margin of {margin:g} m contains the {name} Pole: {why}; "
                                   f"a margin under {max(math.floor(off - res), 0):.0f} m keeps it out", field="margin_m")
        raise InvalidGridError(f"trajectory: the map's grid contains the {name} Pole, and so does the track's own extent: "
                               f"{why}", field="trajectory")
    if not default_crs:
        return
    xs = np.concatenate([np.linspace(left, right, 65), np.full(65, right), np.linspace(right, left, 65),
                         np.full(65, left)])
    ys = np.concatenate([np.full(65, top), np.linspace(top, bottom, 65), np.full(65, bottom),
                         np.linspace(bottom, top, 65)])
    lat = np.asarray(transformer(crs, WGS84).transform(xs, ys)[1], dtype=float)
    south, north = UTM_LATITUDES
    if float(np.nanmax(lat)) > north:
        raise CRSError(f"crs: the map reaches {float(np.nanmax(lat)):.2f} deg N, beyond {north:g} deg N where the UTM "
                       "zones (the default CRS) are defined; give the polar stereographic CRS UPS North: --crs "
                       "EPSG:32661", field="crs")
    if float(np.nanmin(lat)) < south:
        raise CRSError(f"crs: the map reaches {-float(np.nanmin(lat)):.2f} deg S, beyond {-south:g} deg S where the "
                       "UTM zones (the default CRS) are defined; give the polar stereographic CRS UPS South: --crs "
                       "EPSG:32761", field="crs")


BOUNDS_CACHE_POINTS = 20_000
"""Largest number of points whose projected bounding box :func:`grid_for_points` keeps (the key holds their bytes)."""


def _projected_bounds(lon: np.ndarray, lat: np.ndarray, crs: Any) -> tuple[CRS, float, float, float, float]:
    """The grid CRS of :func:`grid_for_points` and the points' bounding box in it: ``(crs, x_min, x_max, y_min,
    y_max)``, m.

    Kept by the points' bytes and the CRS as given when that is None or text (the same route mapped again at other
    cell sizes or margins is not projected again, and its CRS object is the same, so the transformer cache hits);
    errors are not kept.
    """
    key = None
    if (crs is None or isinstance(crs, str)) and lon.size <= BOUNDS_CACHE_POINTS:
        key = (lon.shape, lat.shape, lon.tobytes(), lat.tobytes(), crs)
        hit = _bounds.get(key)
        if hit is not None:
            return hit
    if crs is None:
        lon_c = float(np.degrees(np.arctan2(np.mean(np.sin(np.radians(lon))), np.mean(np.cos(np.radians(lon))))))
        out_crs = utm_crs(lon_c, float(np.mean(lat)))
    else:
        out_crs = parse_crs(crs)
    x, y = transformer(WGS84, out_crs).transform(lon, lat)
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise CRSError(f"crs: the trajectory lies outside the area of use of {out_crs.name!r}", field="crs")
    out = (out_crs, float(x.min()), float(x.max()), float(y.min()), float(y.max()))
    if key is not None:
        with _bounds_lock:
            if len(_bounds) >= 32:
                _bounds.clear()
            _bounds[key] = out
    return out


_bounds: dict[tuple[Any, ...], tuple[CRS, float, float, float, float]] = {}
_bounds_lock = threading.Lock()


def resample_dem(dem: Dem, grid: GridSpec) -> np.ndarray:
    """Ground heights at the grid's cell centres from a DEM, bilinear, m.

    Uses :func:`rasterio.warp.reproject` with bilinear resampling onto the grid;
    cells outside the DEM or on its nodata are NaN.

    Returns
    -------
    ndarray, shape ``grid.shape``
    """
    from rasterio.warp import Resampling, reproject

    out = np.full(grid.shape, np.nan, dtype=np.float64)
    src = np.asarray(dem.heights, dtype=np.float64)
    reproject(
        source=src, destination=out,
        src_transform=dem.transform, src_crs=dem.crs.to_wkt(), src_nodata=dem.nodata if dem.nodata is not None
        else np.nan,
        dst_transform=grid.transform, dst_crs=grid.crs.to_wkt(), dst_nodata=np.nan,
        resampling=Resampling.bilinear,
    )
    return out
