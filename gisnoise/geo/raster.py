"""Digital elevation models: reading a DEM GeoTIFF and sampling it at points.

:func:`read_dem` reads an elevation model (for the receivers' ground heights, or the
ground under waypoints); :func:`sample_dem` interpolates it at WGS84 points.
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
from gisnoise.geo.grid import apply_affine

__all__ = ["Dem", "read_dem", "sample_dem"]


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
