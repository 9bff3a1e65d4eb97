"""GeoTIFF input and output: the levels raster and digital elevation models.

:func:`write_geotiff` writes a :class:`~gisnoise.maps.evaluate.MapResult` as one
float32 band per metric, band descriptions naming the metric (``LAmax``,
``LAeq``, ``SEL``, ...), nodata set, CRS and transform of the receiver grid, so
that the centre of every pixel is a receiver.  :func:`read_dem` reads an elevation
model for the receivers' ground heights.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from affine import Affine
from pyproj import CRS

from gisnoise.errors import CRSError, InputError

if TYPE_CHECKING:  # pragma: no cover
    from gisnoise.maps import MapResult

__all__ = ["Dem", "read_dem", "sample_dem", "write_geotiff", "NODATA"]

NODATA = -9999.0
"""Nodata value of the written bands (float32)."""


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

    from gisnoise.geo.grid import apply_affine

    lon, lat = np.broadcast_arrays(np.asarray(lon, dtype=float), np.asarray(lat, dtype=float))
    tr = Transformer.from_crs(CRS.from_epsg(4326), dem.crs, always_xy=True)
    x, y = tr.transform(lon.ravel(), lat.ravel())
    col, row = apply_affine(~dem.transform, x, y)
    # pixel centres sit at integer + 0.5 in (col, row)
    coords = np.vstack([np.asarray(row) - 0.5, np.asarray(col) - 0.5])
    out = map_coordinates(dem.heights, coords, order=1, mode="constant", cval=np.nan, prefilter=False)
    return out.reshape(lon.shape)


def write_geotiff(result: MapResult, path: str | os.PathLike[str], *, bands: Any = None) -> Path:
    """Write a map result as a GeoTIFF, one float32 band per metric.

    Parameters
    ----------
    result : MapResult
        Bands on a :class:`~gisnoise.geo.grid.GridSpec`.
    path : str or path-like
        Output file; written to a temporary name first and renamed.
    bands : sequence of str, optional
        Band names to write, default all in ``result.bands`` order.

    Notes
    -----
    Band ``i`` has description = metric name and the tags ``metric`` and ``unit``;
    the dataset tags hold the metadata as JSON (tag ``gisnoise``).  NaN is written
    as :data:`NODATA`.
    """
    import rasterio

    names = list(result.bands) if bands is None else list(bands)
    if not names:
        raise InputError("no bands to write", field="metrics")
    grid = result.grid
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    units = dict(result.metadata.get("units", {}))
    profile = {
        "driver": "GTiff", "width": grid.width, "height": grid.height, "count": len(names),
        "dtype": "float32", "crs": grid.crs.to_wkt(), "transform": grid.transform, "nodata": NODATA,
        "compress": "deflate", "predictor": 3,
    }
    if grid.width >= 256 and grid.height >= 256:
        profile.update(tiled=True, blockxsize=256, blockysize=256)
    with rasterio.open(tmp, "w", **profile) as dst:
        for i, name in enumerate(names, start=1):
            a = np.asarray(result.bands[name], dtype=np.float64)
            if a.shape != grid.shape:
                raise InputError(f"band {name!r} has shape {a.shape}, grid is {grid.shape}", field=name)
            out = np.where(np.isfinite(a), a, NODATA).astype(np.float32)
            dst.write(out, i)
            dst.set_band_description(i, name)
            dst.update_tags(i, metric=name, unit=str(units.get(name, "")))
        dst.update_tags(gisnoise=json.dumps(_jsonable(result.metadata), allow_nan=False), AREA_OR_POINT="Area")
    os.replace(tmp, p)
    return p


def _jsonable(v: Any) -> Any:
    if isinstance(v, Mapping):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())
    if isinstance(v, np.generic):
        return _jsonable(v.item())
    if isinstance(v, float) and not np.isfinite(v):
        return None
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v
    return str(v)
