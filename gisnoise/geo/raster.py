"""Digital elevation models: reading a DEM GeoTIFF and sampling it at points; the part of a raster under a grid.

:func:`read_dem` reads an elevation model (for the receivers' ground heights, or the
ground under waypoints); :func:`sample_dem` interpolates it at WGS84 points.
:func:`raster_window` gives the rows and columns of a raster (in any CRS) that a grid's
extent may touch, so that only they are read or expanded.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from affine import Affine
from pyproj import CRS

from gisnoise.errors import CRSError, InputError
from gisnoise.geo.grid import GridSpec, apply_affine, transformer

__all__ = ["Dem", "read_dem", "sample_dem", "raster_window"]


@dataclass(frozen=True, eq=False)
class Dem:
    """A digital elevation model.

    Attributes
    ----------
    heights : ndarray, shape (rows, cols)
        Ground heights, m, NaN where the file has nodata.
    transform : affine.Affine
        Pixel-corner transform.
    crs : pyproj.CRS
        Horizontal CRS of the raster.
    nodata : float or None
        Always NaN after reading (nodata values are replaced by NaN).
    source : str
        File name, for messages.
    """

    heights: np.ndarray
    transform: Affine
    crs: CRS
    nodata: float | None = float("nan")
    source: str = "DEM"


def read_dem(path: str | os.PathLike[str]) -> Dem:
    """Read band 1 of a DEM GeoTIFF (heights in metres).

    Raises
    ------
    InputError
        The file is missing, unreadable or has no CRS (field ``dem``).
    """
    import rasterio
    from rasterio.errors import RasterioIOError

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such DEM file", field="dem")
    try:
        with rasterio.open(p) as src:
            if src.crs is None:
                raise CRSError(f"{p}: the DEM has no coordinate reference system", field="dem")
            heights = src.read(1, masked=True).astype(np.float64).filled(np.nan)
            transform = src.transform
            crs = CRS.from_wkt(src.crs.to_wkt())
    except RasterioIOError as exc:
        raise InputError(f"{p}: cannot read DEM: {exc}", field="dem") from None
    return Dem(heights=heights, transform=transform, crs=crs, nodata=float("nan"), source=str(p))


def sample_dem(dem: Dem, lon: Any, lat: Any) -> np.ndarray:
    """Ground height (m) of ``dem`` at WGS84 points ``lon, lat`` (deg), bilinear between pixel centres.

    NaN outside the DEM or next to nodata.  Arrays broadcast.
    """
    from pyproj import Transformer
    from scipy.ndimage import map_coordinates

    lon, lat = np.broadcast_arrays(np.asarray(lon, dtype=float), np.asarray(lat, dtype=float))
    tr = Transformer.from_crs(CRS.from_epsg(4326), dem.crs, always_xy=True)
    x, y = tr.transform(lon.ravel(), lat.ravel())
    col, row = apply_affine(~dem.transform, x, y)
    # pixel centres sit at integer + 0.5 in (col, row)
    coords = np.vstack([np.asarray(row) - 0.5, np.asarray(col) - 0.5])
    out = map_coordinates(dem.heights, coords, order=1, mode="constant", cval=np.nan, prefilter=False)
    return out.reshape(lon.shape)


def raster_window(transform: Affine, shape: tuple[int, int], crs: CRS, grid: GridSpec, *, pad: int = 2
                  ) -> tuple[int, int, int, int]:
    """The rows ``r0:r1`` and columns ``c0:c1`` of a north-up raster (``transform``, ``shape``, ``crs``) that the
    extent of ``grid`` may touch: the grid's outline, 64 points a side, in the raster's pixels, its bounding box
    grown by ``pad`` cells and clipped to the raster.  Empty (``r0 == r1`` or ``c0 == c1``) when the grid lies
    beside the raster; the whole raster when part of the outline has no place in its CRS.  The outline bounds
    the image of the extent (a projection maps the boundary of a region to the boundary of its image), and
    ``pad`` takes the curvature between its points.

    Examples
    --------
    >>> g = GridSpec.from_bounds("EPSG:32632", 600000.0, 5800000.0, 600100.0, 5800050.0, 10.0)
    >>> raster_window(Affine(10.0, 0, 599000.0, 0, -10.0, 5801000.0), (300, 300), CRS.from_epsg(32632), g)
    (93, 102, 98, 112)
    """
    h, w = shape
    left, bottom, right, top = grid.bounds
    s = np.linspace(0.0, 1.0, 65)
    x = np.concatenate([left + (right - left) * s, np.full(s.size, right), right - (right - left) * s,
                        np.full(s.size, left)])
    y = np.concatenate([np.full(s.size, top), top - (top - bottom) * s, np.full(s.size, bottom),
                        bottom + (top - bottom) * s])
    px, py = transformer(grid.crs, crs).transform(x, y)
    col, row = apply_affine(~transform, np.asarray(px, dtype=float), np.asarray(py, dtype=float))
    if not (np.isfinite(col).all() and np.isfinite(row).all()):  # part of the outline beyond the raster's CRS
        return 0, h, 0, w
    c0 = int(np.clip(np.floor(col.min()) - pad, 0, w))
    c1 = int(np.clip(np.ceil(col.max()) + pad, 0, w))
    r0 = int(np.clip(np.floor(row.min()) - pad, 0, h))
    r1 = int(np.clip(np.ceil(row.max()) + pad, 0, h))
    return r0, max(r0, r1), c0, max(c0, c1)
