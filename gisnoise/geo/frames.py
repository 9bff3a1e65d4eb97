"""Frames and angles: WGS84 <-> local ENU, Z-Y-X Euler attitude, emission angles.

Conventions (fixed by the product specification):

* World frame: local ENU (east, north, up) in metres about an origin
  ``(lat0, lon0, h0)`` (WGS84, ellipsoidal height), through ECEF with pyproj's
  ``topocentric`` conversion.  NED = (north, east, -up).
* Attitude: aerospace Z-Y-X Euler angles yaw ``psi`` (heading from north,
  clockwise positive), pitch ``theta_b`` (nose up positive), roll ``phi_b``
  (right wing down positive).  Body axes: x forward, y right wing, z down.
* Emission angles of the vector from the UAV to the observer in body axes ``r_b``:
  azimuth ``phi = atan2(r_b.y, r_b.x)`` in (-pi, pi], 0 ahead, +pi/2 starboard;
  polar ``theta = atan2(-r_b.z, hypot(r_b.x, r_b.y))`` in [-pi/2, pi/2],
  -pi/2 straight below the UAV.

Examples
--------
>>> f = LocalFrame(52.0, 10.0, 80.0)
>>> e, n, u = f.to_enu(52.0, 10.0, 80.0)
>>> abs(float(e)) < 1e-6 and abs(float(n)) < 1e-6 and abs(float(u)) < 1e-6
True
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pyproj import Transformer

from gisnoise.errors import InputError

__all__ = ["LocalFrame", "dcm_ned_to_body", "body_vector", "emission_angles", "wrap_angle", "wrap_deg", "centre_lon"]


def wrap_angle(a: Any) -> np.ndarray:
    """Wrap radians into (-pi, pi].  Float or array_like."""
    a = np.asarray(a, dtype=float)
    w = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
    return np.where(w == -np.pi, np.pi, w)


def wrap_deg(a: Any) -> np.ndarray:
    """Wrap degrees into (-180, 180].  Float or array_like."""
    a = np.asarray(a, dtype=float)
    w = np.mod(a + 180.0, 360.0) - 180.0
    return np.where(w == -180.0, 180.0, w)


def centre_lon(lon: Any, how: str = "mean") -> float:
    """The centre longitude of points, deg in (-180, 180]: their mean (``how="mean"``) or median (``"median"``)
    on the circle.

    ``lon``: array_like of longitudes, deg.  Points that span at most 180 deg of longitude get the plain
    ``numpy.mean`` / ``numpy.median`` (the same numbers as ever); wider, they are taken on the circle:
    unwrapped about their circular mean (the direction of the mean of their unit vectors), averaged there and
    wrapped back.  A track across the antimeridian (lon 179.99 to -179.99) has its centre near 180, not near 0.

    >>> centre_lon([179.99, -179.99, -179.97])
    -179.99
    >>> centre_lon([10.0, 11.0, 15.0], "median")
    11.0
    """
    a = np.asarray(lon, dtype=float).ravel()
    f = np.median if how == "median" else np.mean
    if a.size == 0 or float(np.ptp(a)) <= 180.0:
        return float(f(a))
    r = np.radians(a)
    c = float(np.degrees(np.arctan2(np.mean(np.sin(r)), np.mean(np.cos(r)))))
    return round(float(wrap_deg(c + float(f(wrap_deg(a - c))))), 12)


@dataclass(frozen=True)
class LocalFrame:
    """A local ENU frame about a WGS84 origin.

    Parameters
    ----------
    lat0, lon0 : float
        Origin latitude and longitude, degrees.
    h0 : float
        Origin ellipsoidal height, m.
    """

    lat0: float
    lon0: float
    h0: float = 0.0
    _fwd: Transformer = field(init=False, repr=False, compare=False)
    _inv: Transformer = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("lat0", "lon0", "h0"):
            v = getattr(self, name)
            if not np.isfinite(v):
                raise InputError(f"origin {name} must be finite, got {v!r}", field=name)
        if not -90.0 <= self.lat0 <= 90.0:
            raise InputError(f"origin lat0 must be within [-90, 90] deg, got {self.lat0}", field="lat0")
        if not -180.0 <= self.lon0 <= 180.0:  # the shared rule: longitudes are never wrapped
            raise InputError(f"origin lon0 must be within [-180, 180] deg, got {self.lon0}", field="lon0")
        pipeline = (
            "+proj=pipeline +step +proj=axisswap +order=2,1 +step +proj=unitconvert +xy_in=deg +xy_out=rad "
            "+step +proj=cart +ellps=WGS84 "
            f"+step +proj=topocentric +ellps=WGS84 +lat_0={self.lat0!r} +lon_0={self.lon0!r} +h_0={self.h0!r}"
        )
        object.__setattr__(self, "_fwd", Transformer.from_pipeline(pipeline))
        object.__setattr__(self, "_inv", Transformer.from_pipeline(pipeline))

    def to_enu(self, lat: Any, lon: Any, h: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """WGS84 (deg, deg, m ellipsoidal) -> ENU metres.  Arrays broadcast."""
        lat, lon, h = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (lat, lon, h)))
        e, n, u = self._fwd.transform(lat, lon, h)
        return np.asarray(e), np.asarray(n), np.asarray(u)

    def to_wgs84(self, e: Any, n: Any, u: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """ENU metres -> WGS84 (lat deg, lon deg, h m ellipsoidal).  Arrays broadcast."""
        e, n, u = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (e, n, u)))
        lat, lon, h = self._inv.transform(e, n, u, direction="INVERSE")
        return np.asarray(lat), np.asarray(lon), np.asarray(h)


def dcm_ned_to_body(yaw: Any, pitch: Any, roll: Any) -> np.ndarray:
    """Direction cosine matrix NED -> body for Z-Y-X Euler angles (rad), shape (..., 3, 3)."""
    psi, th, ph = (np.asarray(v, dtype=float) for v in (yaw, pitch, roll))
    cps, sps = np.cos(psi), np.sin(psi)
    cth, sth = np.cos(th), np.sin(th)
    cph, sph = np.cos(ph), np.sin(ph)
    shape = np.broadcast(psi, th, ph).shape
    c = np.empty(shape + (3, 3))
    c[..., 0, 0] = cth * cps
    c[..., 0, 1] = cth * sps
    c[..., 0, 2] = -sth
    c[..., 1, 0] = sph * sth * cps - cph * sps
    c[..., 1, 1] = sph * sth * sps + cph * cps
    c[..., 1, 2] = sph * cth
    c[..., 2, 0] = cph * sth * cps + sph * sps
    c[..., 2, 1] = cph * sth * sps - sph * cps
    c[..., 2, 2] = cph * cth
    return c


def body_vector(de: Any, dn: Any, du: Any, yaw: Any, pitch: Any, roll: Any) -> tuple[np.ndarray, ...]:
    """Rotate the ENU vector UAV->observer ``(de, dn, du)`` m into body axes.

    Angles in radians; everything broadcasts.  Returns ``(x_b, y_b, z_b)``.
    """
    de, dn, du = (np.asarray(v, dtype=float) for v in (de, dn, du))
    psi, th, ph = (np.asarray(v, dtype=float) for v in (yaw, pitch, roll))
    # NED components
    rn, re, rd = dn, de, -du
    cps, sps = np.cos(psi), np.sin(psi)
    cth, sth = np.cos(th), np.sin(th)
    cph, sph = np.cos(ph), np.sin(ph)
    # yaw rotation, then pitch, then roll (C = Rx(ph) Ry(th) Rz(psi))
    x1 = cps * rn + sps * re
    y1 = -sps * rn + cps * re
    z1 = rd
    x2 = cth * x1 - sth * z1
    z2 = sth * x1 + cth * z1
    y3 = cph * y1 + sph * z2
    z3 = -sph * y1 + cph * z2
    return x2, y3, z3


def emission_angles(
    de: Any, dn: Any, du: Any, yaw: Any, pitch: Any, roll: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance (m), azimuth ``phi`` and polar ``theta`` (rad) of UAV->observer vectors.

    Parameters
    ----------
    de, dn, du : float or array_like
        ENU components of the vector from the UAV to the observer, m.
    yaw, pitch, roll : float or array_like
        Z-Y-X Euler angles of the UAV, rad.

    Examples
    --------
    >>> d, phi, theta = emission_angles(0.0, 0.0, -50.0, 0.0, 0.0, 0.0)
    >>> float(d), round(float(np.degrees(theta)), 6)
    (50.0, -90.0)
    >>> d, phi, theta = emission_angles(10.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # east of a north-heading UAV
    >>> round(float(np.degrees(phi)), 6)
    90.0
    """
    xb, yb, zb = body_vector(de, dn, du, yaw, pitch, roll)
    h = np.hypot(xb, yb)
    d = np.sqrt(h * h + zb * zb)
    phi = np.arctan2(yb, xb)
    phi = np.where(phi == -np.pi, np.pi, phi)
    theta = np.arctan2(-zb, h)
    return d, phi, theta
