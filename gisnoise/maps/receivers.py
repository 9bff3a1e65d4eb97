"""The receivers of a grid as the fast kernel reads them: a lattice of exact positions per row segment.

Receivers of a grid row are taken in segments of at most :data:`SEGMENT_M` metres
(:func:`segment_cells` cells); their local-ENU positions are exact (pyproj) at each
segment's ends and middle (:meth:`Receivers.lattice`) and the kernel interpolates them
quadratically in between.  :func:`receivers_for` applies the ground rule of every map
(:func:`gisnoise.maps.ground.checked_ground`, then :func:`~gisnoise.maps.prepare.ground_on_grid`): a DEM
gives each receiver its height above the lattice's reference height.

>>> segment_cells(10.0), segment_cells(0.25)
(102, 2048)
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.flight import Trajectory
from gisnoise.geo import WGS84, GridSpec, LocalFrame, transformer
from gisnoise.maps._checks import as_float
from gisnoise.maps.ground import checked_ground
from gisnoise.maps.prepare import ground_on_grid, local_frame

__all__ = ["SEGMENT_M", "Receivers", "receivers_for", "segment_cells"]

SEGMENT_M = 1024.0
"""Longest run of receivers (m) along a grid row between exact positions (ends and middle)."""


@dataclass(frozen=True, eq=False)
class Receivers:
    """The receivers of a grid in a local frame, as the kernel reads them.

    Attributes
    ----------
    grid : GridSpec
    origin : tuple of float
        ``(lat0, lon0, h0)`` of the local ENU frame (deg, deg, m ellipsoidal).
    h_ref : float
        Ellipsoidal height of the lattice positions, m (flat ground: the receivers' height).
    dh : ndarray of float32, shape ``grid.shape``, or None
        Receiver height above ``h_ref`` from a DEM, m (0 where the DEM has no value).
    valid : ndarray of bool, shape ``grid.shape``, or None
        Receivers on the DEM (the others get NaN).
    seg : int
        Cells per segment (exact positions every ``seg`` columns).
    ground : dict
        How the ground was chosen (for the result's metadata).
    dh_origin : tuple of int
        Grid row and column of ``dh[0, 0]`` and ``valid[0, 0]`` (a window's copy, see
        :meth:`for_window`).
    receiver_height_m : float or None
        Receiver height above the ground, m (None: ``h_ref`` minus the origin's height).
    """

    grid: GridSpec
    origin: tuple[float, float, float]
    h_ref: float
    dh: np.ndarray | None = None
    valid: np.ndarray | None = None
    seg: int = 1
    ground: dict | None = None
    dh_origin: tuple[int, int] = (0, 0)
    receiver_height_m: float | None = None

    @property
    def height_agl(self) -> float:
        """Receiver height above the ground, m."""
        return float(self.h_ref - self.origin[2]) if self.receiver_height_m is None else self.receiver_height_m

    def for_window(self, r0: int, r1: int, c0: int, c1: int) -> Receivers:
        """The same receivers holding only the DEM heights of rows ``r0:r1``, columns ``c0:c1``
        (what a worker needs for one tile)."""
        if self.dh is None:
            return self
        o_r, o_c = self.dh_origin
        sl = (slice(r0 - o_r, r1 - o_r), slice(c0 - o_c, c1 - o_c))
        return replace(self, dh=np.ascontiguousarray(self.dh[sl]),
                       valid=None if self.valid is None else np.ascontiguousarray(self.valid[sl]),
                       dh_origin=(r0, c0))

    def window_heights(self, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        """The window's DEM heights above the reference as a kernel reads them (``(1, 1)`` zeros without a DEM),
        after checking that rows ``r0:r1`` and columns ``c0:c1`` lie in the grid and in the held heights."""
        if not (0 <= r0 < r1 <= self.grid.height and 0 <= c0 < c1 <= self.grid.width):
            raise InputError(f"window rows {r0}:{r1}, columns {c0}:{c1} outside the grid {self.grid.shape}",
                             field="window")
        if self.dh is None:
            return np.zeros((1, 1), np.float32)
        o_r, o_c = self.dh_origin
        if r0 < o_r or c0 < o_c or r1 - o_r > self.dh.shape[0] or c1 - o_c > self.dh.shape[1]:
            raise InputError(f"window rows {r0}:{r1}, columns {c0}:{c1} outside the receivers' DEM heights",
                             field="window")
        return np.ascontiguousarray(self.dh[r0 - o_r:r1 - o_r, c0 - o_c:c1 - o_c])

    @property
    def frame(self) -> LocalFrame:
        """The local frame (a per-thread instance: pyproj transformers are not shared)."""
        return local_frame(*self.origin)

    @property
    def n_segments(self) -> int:
        return -(-self.grid.width // self.seg)

    def lattice(self, r0: int, r1: int, m0: int, m1: int) -> tuple[np.ndarray, np.ndarray]:
        """Exact ENU positions ``P`` (and unit normals ``U``) of rows ``r0:r1`` at the ends and middles of segments ``m0:m1``.

        Shape ``(r1 - r0, 2 (m1 - m0) + 1, 3)``, m; column ``c`` (fractional in the middles)
        has its centre at ``x = transform.c + transform.a (c + 0.5)``.
        """
        t = self.grid.transform
        cols = np.arange(2 * m0, 2 * m1 + 1) * (0.5 * self.seg)  # segment ends and middles
        rows = np.arange(r0, r1)
        x = np.broadcast_to(t.c + t.a * (cols + 0.5), (rows.size, cols.size))
        y = np.broadcast_to((t.f + t.e * (rows + 0.5))[:, None], (rows.size, cols.size))
        lon, lat = transformer(self.grid.crs, WGS84).transform(np.ascontiguousarray(x), np.ascontiguousarray(y))
        fr = self.frame
        P = np.stack(fr.to_enu(lat, lon, np.full(lat.shape, self.h_ref)), axis=-1)
        if self.dh is None:
            return np.ascontiguousarray(P), np.zeros((1, 1, 3))
        up = np.stack(fr.to_enu(lat, lon, np.full(lat.shape, self.h_ref + 1.0)), axis=-1)
        return np.ascontiguousarray(P), np.ascontiguousarray(up - P)


def segment_cells(resolution_m: float) -> int:
    """Cells per segment for a cell size (m): the longest run within :data:`SEGMENT_M`, 1 to 2048."""
    return int(min(2048, max(1, math.floor(SEGMENT_M / float(resolution_m)))))


def receivers_for(grid: GridSpec, trajectories: Iterable[Trajectory] = (), *, receiver_height: float = 1.5,
                  dem: Any = None, ground_h: float | None = None, dem_offset_m: float = 0.0) -> Receivers:
    """Receivers of ``grid``, ``receiver_height`` (m) above the ground of the map's ground rule.

    With a DEM the ground comes from it (frame height: the mean ground); else flat at ``ground_h`` (m, checked at
    or below every trajectory's lowest flying point), by default the ground the trajectories give themselves (a
    route's stated ground, else a take-off or landing point; the lowest of them); trajectories all in the air
    throughout are refused (:func:`gisnoise.maps.ground.checked_ground`).
    """
    chosen = checked_ground(trajectories, receiver_height, ground_h, dem)
    hr = as_float(receiver_height, "receiver_height")
    lon_c, lat_c = grid.centre_wgs84()
    seg = segment_cells(min(grid.resolution))
    ground = ground_on_grid(grid, dem=dem, ground_h=chosen, dem_offset_m=dem_offset_m)
    h0 = ground.h0
    if ground.heights is not None:
        valid = np.isfinite(ground.heights)
        dh = np.where(valid, ground.heights - h0, 0.0).astype(np.float32)
        return Receivers(grid, (lat_c, lon_c, h0), h0 + hr, dh, valid, seg, ground.description, receiver_height_m=hr)
    return Receivers(grid, (lat_c, lon_c, h0), h0 + hr, None, None, seg, ground.description, receiver_height_m=hr)
