"""The files of a day of operations: the bands as GeoTIFF, contours of Lden and Lnight, a JSON summary."""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.flight import Trajectory
from gisnoise.jsonio import to_jsonable
from gisnoise.maps import MapResult, plot_map, write_geojson, write_geotiff

__all__ = ["write_operations"]


def write_operations(result: MapResult, out_dir: str | os.PathLike[str], levels: Any = None,
                     contour_bands: Sequence[str] = ("Lden", "Lnight"), *, plot: bool = False,
                     tracks: Sequence[tuple[str, Trajectory]] = ()) -> dict[str, Path]:
    """Write ``DIR/operations.tif`` (every band), ``DIR/contours.geojson`` (of ``contour_bands``)
    and ``DIR/summary.json`` (metadata and per-band ranges); with ``plot`` also ``DIR/map.png``
    (Lden with its contours at the levels and the flights' ``tracks``, ``(id, trajectory)``)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: output exists and is not a folder", field="out")
    out.mkdir(parents=True, exist_ok=True)
    lv = result.metadata.get("levels_db") if levels is None else levels
    paths = {"levels": write_geotiff(result, out / "operations.tif")}
    if lv:
        paths["contours"] = write_geojson(result, out / "contours.geojson", lv, metrics=list(contour_bands))
    summary = {"metadata": result.metadata, "bands": {}}
    for k, a in result.bands.items():
        fin = a[np.isfinite(a)]
        summary["bands"][k] = {"unit": result.units.get(k, ""), "min": float(fin.min()) if fin.size else None,
                               "max": float(fin.max()) if fin.size else None}
    p = out / "summary.json"
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(json.dumps(to_jsonable(summary), indent=1, allow_nan=False), encoding="utf-8")
    os.replace(tmp, p)
    paths["summary"] = p
    if plot:
        if not lv:
            raise InputError("plot: give contour levels (--levels or the schedule's levels_db)", field="levels")
        paths["map"] = plot_map(result, out / "map.png", levels=list(lv), metric="Lden", tracks=tracks)
    return paths
