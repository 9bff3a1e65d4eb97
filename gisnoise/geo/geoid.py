"""Geoid undulation: heights above mean sea level -> WGS84 ellipsoidal heights.

Flight logs that give heights above mean sea level (ArduPilot ``GPS.Alt`` and ``POS.Alt``,
PX4 ``alt`` where no ``alt_ellipsoid`` is logged) become ellipsoidal heights ``h = H + N``
with the geoid undulation ``N`` of a geoid model.  The model is a published grid that PROJ
reads, evaluated through pyproj (``+proj=vgridshift``, bilinear interpolation between the
grid nodes, as PROJ does for every vertical grid):

``egm96_15.gtx``
    EGM96 on a 15' grid (Debian/Ubuntu package ``proj-data``; in PROJ's own data as
    ``us_nga_egm96_15.tif``);
``us_nga_egm96_15.tif``
    the same grid as PROJ distributes it now (``projsync --file us_nga_egm96_15.tif``);
``us_nga_egm08_25.tif``
    EGM2008 on a 2.5' grid.

The first grid found wins, searched in this order:

1. the file the environment variable ``GISNOISE_GEOID_GRID`` names (a missing file is an
   error, never a silent fallback);
2. the folders of ``PROJ_DATA`` and ``PROJ_LIB`` (path lists);
3. pyproj's data folder and its user data folder;
4. the system's PROJ data folders ``/usr/share/proj``, ``/usr/local/share/proj`` and
   ``<python prefix>/share/proj``.

Without a grid :func:`geoid_undulation` raises an error that names the way out: install
the grid (``apt-get install proj-data``, or ``projsync --file us_nga_egm96_15.tif``), point
``GISNOISE_GEOID_GRID`` at it, or give the undulation by hand (``--geoid-undulation``,
field ``geoid_undulation_m``).  An undulation is never guessed.

The interpolated 15' EGM96 grid agrees with NGA's spherical-harmonic EGM96 test values
within 0.06 m at NGA's six test points (``tests/test_geoid.py``), far below the metres of
a GNSS receiver's vertical error.
"""

from __future__ import annotations

import functools
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError

__all__ = ["GEOID_GRIDS", "GEOID_GRID_ENV", "GeoidGrid", "find_geoid_grid", "geoid_search_dirs",
           "geoid_undulation", "GEOID_WAY_OUT"]

GEOID_GRID_ENV = "GISNOISE_GEOID_GRID"
"""Environment variable naming a geoid grid file (searched first)."""

GEOID_GRIDS: tuple[tuple[str, str], ...] = (
    ("egm96_15.gtx", "EGM96"),
    ("us_nga_egm96_15.tif", "EGM96"),
    ("us_nga_egm08_25.tif", "EGM2008"),
)
"""Grid file names searched for, with the geoid model each holds."""

GEOID_WAY_OUT = (f"install the EGM96 grid (apt-get install proj-data, or projsync --file us_nga_egm96_15.tif), "
                 f"set {GEOID_GRID_ENV} to a geoid grid file, or give the undulation (--geoid-undulation N, "
                 f"field geoid_undulation_m)")


@dataclass(frozen=True)
class GeoidGrid:
    """A geoid grid file and the model it holds.

    Attributes
    ----------
    path : Path
        The grid file (GTX or GeoTIFF, as PROJ reads it).
    model : str
        ``EGM96`` or ``EGM2008`` (``other`` for a file ``GISNOISE_GEOID_GRID`` names that is
        none of :data:`GEOID_GRIDS`).
    """

    path: Path
    model: str

    def undulation(self, lat: Any, lon: Any) -> np.ndarray:
        """Geoid undulation N (ellipsoidal minus orthometric height, m) at WGS84 ``lat``, ``lon`` (deg).

        float or array_like, broadcast; longitudes in any range (wrapped).
        """
        lat_a, lon_a = np.broadcast_arrays(np.asarray(lat, dtype=float), np.asarray(lon, dtype=float))
        lon_w = (lon_a + 180.0) % 360.0 - 180.0
        if np.any(np.abs(lat_a) > 90.0) or not np.all(np.isfinite(lat_a) & np.isfinite(lon_a)):
            raise InputError("geoid undulation: latitude must be finite and within -90..90 deg", field="lat")
        tr = _vgridshift(str(self.path))
        _, _, n = tr.transform(lon_w.ravel(), lat_a.ravel(), np.zeros(lat_a.size))
        n = np.asarray(n, dtype=float).reshape(lat_a.shape)
        if not np.all(np.isfinite(n)):
            raise InputError(f"geoid grid {self.path.name} does not cover every position; {GEOID_WAY_OUT}",
                             field="geoid_undulation_m")
        return n

    def describe(self) -> str:
        """``'EGM96 (egm96_15.gtx)'``: the model and the grid's file name."""
        return f"{self.model} ({self.path.name})"


@functools.lru_cache(maxsize=4)
def _vgridshift(path: str) -> Any:
    """A transformer whose vertical output is the grid's value (``h = 0 + 1 * N``)."""
    import pyproj

    p = Path(path)
    grid = path
    if any(c.isspace() for c in path):   # a PROJ string cannot hold a blank: name the file in its folder
        pyproj.datadir.append_data_dir(str(p.parent))
        grid = p.name
    try:
        return pyproj.Transformer.from_pipeline(f"+proj=pipeline +step +proj=vgridshift +grids={grid} "
                                                "+multiplier=1")
    except pyproj.exceptions.ProjError as exc:
        raise InputError(f"geoid grid {p.name}: PROJ cannot read it ({exc}); {GEOID_WAY_OUT}",
                         field="geoid_undulation_m") from None


def geoid_search_dirs() -> list[Path]:
    """The folders searched for a geoid grid, in order (see the module docstring)."""
    dirs: list[str] = []
    for var in ("PROJ_DATA", "PROJ_LIB"):
        dirs += [d for d in os.environ.get(var, "").split(os.pathsep) if d]
    try:
        import pyproj.datadir

        dirs += [d for d in pyproj.datadir.get_data_dir().split(os.pathsep) if d]
        dirs.append(str(pyproj.datadir.get_user_data_dir()))
    except Exception:   # pragma: no cover - pyproj without a data folder: the system folders remain
        pass
    dirs += ["/usr/share/proj", "/usr/local/share/proj", str(Path(sys.prefix) / "share" / "proj")]
    return list(dict.fromkeys(Path(d) for d in dirs))


def find_geoid_grid() -> GeoidGrid | None:
    """The geoid grid to use, or None when there is none (see the module docstring for the search).

    Raises
    ------
    InputError
        ``GISNOISE_GEOID_GRID`` names a file that does not exist.
    """
    env = os.environ.get(GEOID_GRID_ENV, "").strip()
    if env:
        p = Path(env).expanduser()
        if not p.is_file():
            raise InputError(f"{GEOID_GRID_ENV}={env}: no such geoid grid file", field=GEOID_GRID_ENV)
        model = next((m for name, m in GEOID_GRIDS if name == p.name), "other")
        return GeoidGrid(p.resolve(), model)
    for d in geoid_search_dirs():
        for name, model in GEOID_GRIDS:
            p = d / name
            if p.is_file():
                return GeoidGrid(p.resolve(), model)
    return None


def geoid_undulation(lat: Any, lon: Any, *, what: str = "heights above mean sea level") -> tuple[np.ndarray, GeoidGrid]:
    """Geoid undulation N (m) at ``lat``, ``lon`` (deg, float or array_like) and the grid it came from.

    Parameters
    ----------
    lat, lon : float or array_like
        WGS84 latitude and longitude, deg.
    what : str
        What needs the undulation, for the error message.

    Raises
    ------
    InputError
        No geoid grid is found (field ``geoid_undulation_m``); the message names the way out.

    Examples
    --------
    >>> grid = find_geoid_grid()
    >>> if grid is not None:   # NGA's EGM96 test point: N = -31.628 m
    ...     n, _ = geoid_undulation(38.6281550, 269.7791550)
    ...     assert abs(float(n) + 31.628) < 0.1
    """
    grid = find_geoid_grid()
    if grid is None:
        raise InputError(f"{what}: no geoid grid found ({', '.join(n for n, _ in GEOID_GRIDS)}); {GEOID_WAY_OUT}",
                         field="geoid_undulation_m")
    return grid.undulation(lat, lon), grid
