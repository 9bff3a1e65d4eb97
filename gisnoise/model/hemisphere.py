"""Measured hemispheres as sources: the hemisphere card (``gisnoise/hemisphere-card/1``).

A hemisphere card holds one-third-octave band levels (dB re 20 uPa, unweighted) at a
reference radius ``radius_m`` on a rectilinear grid of two table angles, for one flight
condition of one vehicle, with the atmosphere the table was back-propagated with and which
cells were measured (the others are filled by the importer or the source of the table).

**Table angles** (the Salford / NORAH hemisphere convention, fixed here).  With the body axes
of the product (x forward, y starboard, z down) and the unit vector ``(x_b, y_b, z_b)`` from
the UAV to the observer below it (``z_b > 0``):

* ``phi_t = atan2(-x_b, z_b)``: the angle in the vertical plane along the track, 0 straight
  below, negative ahead (fore), positive behind (aft), +-90 deg at the horizon;
* ``theta_t = atan2(y_b, z_b)``: the angle in the vertical plane across the track, 0 straight
  below, positive to starboard, +-90 deg at the horizon.

The sign of ``phi_t`` follows the measurement: the table's rows before the overhead time
(drone approaching the microphone line, the microphone ahead of it) carry negative angles.
In the product's azimuth ``phi`` and polar angle ``theta`` (SPEC section 1):
``x_b = cos(theta) cos(phi)``, ``y_b = cos(theta) sin(phi)``, ``z_b = -sin(theta)``.  Above the
horizon (``z_b < 0``) nothing was measured: the table is mirrored in the horizontal plane
(``|z_b|`` in place of ``z_b``), which is continuous at the horizon; those directions count as
filled.

**Interpolation** (stated scheme): bilinear in ``(phi_t, theta_t)`` of the A-weighted overall
level *at the receiver's distance* of the four surrounding nodes,

    L_node(d) = 10 lg sum_b 10^((L_b,node + A(f_b) - alpha_b (d - r0)) / 10) - 20 lg(d / r0)

with ``A`` the A-weighting (IEC 61672-1) and ``alpha_b`` the ISO 9613-1 absorption (dB/m) at
the band's exact mid-band frequency in the map's atmosphere (``map_atmosphere``, by default the
card's ``atmosphere``, the one the table was back-propagated with).  It is exact at the nodes,
continuous, and between nodes lies between the values of the neighbouring nodes.  Outside the
table's angle range the edge values hold (counted as filled).  The level does not depend on
the electric power: the table stands for its stated flight condition.

**Checks of a table that enters the product** (:func:`table_problems`; every card document read,
:func:`hemisphere_from_dict`, so card files, ``--card``, the service's upload and the QGIS plugin,
and every import, :func:`gisnoise.model.import_hemisphere`): the slips a table typed or edited by
hand carries, which a card's structure does not show and the map would turn into wrong levels:

* angles in degrees: an axis of more than one angle, all within +-:data:`RADIAN_LIMIT_DEG`
  (1.571, pi/2 rounded up), is refused as given in radians (radians fill that range; in degrees
  such an axis would span at most 3.1 deg about straight below, 0.55 m across at 10 m, where a
  measured hemisphere spans tens of degrees: the Salford line of microphones +-60), naming
  ``phi_deg`` or ``theta_deg``;
* bands: nominal one-third-octave mid-band frequencies in Hz, none below :data:`LOWEST_BAND_HZ`
  (10 Hz, the lowest frequency IEC 61672-1 states the A-weighting for: a table in kHz gives
  0.02-20 "Hz"), every band between the lowest and the highest (a band missing from the table
  would drop its energy from every level), naming ``bands_hz``.

A card built in Python from arrays is checked for its structure only (shapes, order, ranges).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gisnoise.acoustics import a_weighting, atmospheric_absorption, exact_frequency, nominal_frequency
from gisnoise.errors import CardError
from gisnoise.model.ansatz import Ansatz
from gisnoise.model.cards import ModelCard, _check_card_identity, register_card_schema

__all__ = ["HEMISPHERE_ANSATZ", "HEMISPHERE_SCHEMA", "LOWEST_BAND_HZ", "RADIAN_LIMIT_DEG", "HemisphereCard",
           "band_problem", "hemisphere_from_dict", "hemisphere_quadrature", "table_angles", "table_problems"]

HEMISPHERE_SCHEMA = "gisnoise/hemisphere-card/1"
HEMISPHERE_ANSATZ = "hemisphere"
DEFAULT_ATMOSPHERE = {"temperature_c": 20.0, "humidity_pct": 70.0, "pressure_kpa": 101.325}
LOWEST_BAND_HZ = 10.0
"""Lowest one-third-octave band taken, Hz: the lowest frequency of the A-weighting in IEC 61672-1 (a band below
it is no audio band; a table in kHz gives 0.02-20)."""
RADIAN_LIMIT_DEG = 1.571
"""An axis whose angles all lie within +-this many "degrees" is taken to be in radians: pi/2 rounded up to three
decimals, so that radians written rounded (1.5708) count (module docstring)."""


_LN10_10 = math.log(10.0) / 10.0
"""``10^(x/10) = exp(x _LN10_10)``."""


def table_angles(phi: Any, theta: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Table angles ``(phi_t, theta_t)`` in degrees of product angles ``phi``, ``theta`` (rad).

    Also returns ``above``: True where the direction lies above the horizon (mirrored).

    Examples
    --------
    >>> a, b, up = table_angles(0.0, -np.pi / 2)          # straight below
    >>> abs(round(float(a), 6)), round(float(b), 6), bool(up)
    (0.0, 0.0, False)
    >>> a, b, _ = table_angles(0.0, -np.pi / 4)           # 45 deg ahead and down
    >>> round(float(a), 6), round(float(b), 6)
    (-45.0, 0.0)
    >>> a, b, _ = table_angles(np.pi / 2, -np.pi / 4)     # 45 deg to starboard and down
    >>> round(float(a), 6) + 0.0, round(float(b), 6) + 0.0   # + 0.0: no negative zero
    (0.0, 45.0)
    """
    phi = np.asarray(phi, dtype=float)
    theta = np.asarray(theta, dtype=float)
    ct = np.cos(theta)
    xb = ct * np.cos(phi)
    yb = ct * np.sin(phi)
    zb = -np.sin(theta)
    zc = np.abs(zb)
    return np.degrees(np.arctan2(-xb, zc)), np.degrees(np.arctan2(yb, zc)), zb < 0


def _axis_weights(grid: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lower node index, weight of the upper node, and whether ``a`` lay outside the grid."""
    n = grid.size
    outside = (a < grid[0]) | (a > grid[-1])
    ac = np.clip(a, grid[0], grid[-1])
    if n == 1:
        return np.zeros(a.shape, dtype=np.intp), np.zeros(a.shape), outside
    i = np.clip(np.searchsorted(grid, ac, side="right") - 1, 0, n - 2)
    w = (ac - grid[i]) / (grid[i + 1] - grid[i])
    return i, w, outside


def _bilinear(grid_a: np.ndarray, grid_b: np.ndarray, a: np.ndarray, b: np.ndarray
              ) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """Bilinear stencil at table angles ``a``, ``b`` (deg): ``[(flat node index, weight)] x 4`` and outside."""
    i, wi, out_i = _axis_weights(grid_a, a)
    j, wj, out_j = _axis_weights(grid_b, b)
    nt = grid_b.size
    i1 = np.minimum(i + 1, grid_a.size - 1)
    j1 = np.minimum(j + 1, nt - 1)
    return [(i * nt + j, (1 - wi) * (1 - wj)), (i * nt + j1, (1 - wi) * wj),
            (i1 * nt + j, wi * (1 - wj)), (i1 * nt + j1, wi * wj)], out_i | out_j


def hemisphere_quadrature(phi_deg: Any, theta_deg: Any, n: int = 16) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points ``(phi_t, theta_t)`` (deg) and solid-angle weights (sr) integrating over the lower hemisphere.

    ``phi_t = atan2(-x_b, z_b)`` is the longitude of a direction about the body y axis, and
    ``lambda = asin(y_b)`` its latitude: the direction is ``(-cos lambda sin phi_t, sin lambda,
    cos lambda cos phi_t)``, the solid angle element ``cos lambda dlambda dphi_t`` and
    ``theta_t = atan2(sin lambda, cos lambda cos phi_t)`` (so the table's column ``theta_t = b`` is
    ``lambda = atan(tan b cos phi_t)``).  Gauss-Legendre rules of ``n`` points run over each
    interval between the rows ``phi_deg`` (and the horizon, -90 and 90 deg) in ``phi_t`` and, at
    each of their points, over each interval between the columns ``theta_deg`` in ``lambda``: the
    bilinear interpolation is smooth inside every piece (only at the horizon, ``phi_t = +-90 deg``,
    where the columns meet, is the integral over ``lambda`` not smooth in ``phi_t``).  With 16
    points a level linear in ``theta_t`` on the M300 grid is integrated within 3e-6 dB of its
    closed form, the M300 table within 2e-6 dB of 32 points.  The weights sum to ``2 pi``.

    Examples
    --------
    >>> a, b, w = hemisphere_quadrature([-90.0, 0.0, 90.0], [-90.0, 0.0, 90.0])
    >>> round(float(w.sum() / np.pi), 12)       # the lower hemisphere: 2 pi sr
    2.0
    >>> round(float(np.sum(w * (a < 0)) / np.pi), 12)   # phi_t is uniform in solid angle: half ahead
    1.0
    """
    x, wx = np.polynomial.legendre.leggauss(int(n))
    ends = np.radians(np.unique(np.clip(np.concatenate([[-90.0], np.ravel(phi_deg), [90.0]]), -90.0, 90.0)))
    lo, span = ends[:-1], np.diff(ends)
    a = (lo[:, None] + span[:, None] * (x + 1.0) / 2.0).ravel()
    wa = (span[:, None] * wx / 2.0).ravel()
    cols = np.radians(np.unique(np.clip(np.concatenate([[-90.0], np.ravel(theta_deg), [90.0]]), -90.0, 90.0)))
    lam = np.arctan(np.tan(cols[None, 1:-1]) * np.cos(a)[:, None])
    lam = np.concatenate([np.full((a.size, 1), -np.pi / 2), lam, np.full((a.size, 1), np.pi / 2)], axis=1)
    l0, dl = lam[:, :-1, None], np.diff(lam, axis=1)[:, :, None]
    lp = l0 + dl * (x + 1.0) / 2.0                       # (phi points, column intervals, n)
    w = wa[:, None, None] * dl * wx / 2.0 * np.cos(lp)
    b = np.arctan2(np.sin(lp), np.cos(lp) * np.cos(a)[:, None, None])
    aa = np.broadcast_to(a[:, None, None], lp.shape)
    return np.degrees(aa).ravel(), np.degrees(b).ravel(), w.ravel()


def band_problem(f_hz: float) -> str | None:
    """What makes ``f_hz`` no band of a hemisphere table, completing ``"band <value> ..."``; None for a band.

    A band is a nominal one-third-octave mid-band frequency in Hz (within 0.02 decades) from
    :data:`LOWEST_BAND_HZ` on.

    Examples
    --------
    >>> band_problem(1000.0) is None, band_problem(0.02)[:32]
    (True, 'Hz lies below 10 Hz, the lowest ')
    """
    f = float(f_hz)
    if not math.isfinite(f) or f <= 0:
        return "is not a positive frequency"
    if f < LOWEST_BAND_HZ * 10 ** -0.05:  # below the 10 Hz band's lower edge
        return (f"Hz lies below {LOWEST_BAND_HZ:g} Hz, the lowest band of the A-weighting (IEC 61672-1): bands are "
                "nominal frequencies in Hz (kHz given?)")
    if abs(math.log10(float(nominal_frequency(f)) / f)) > 0.02:
        return "Hz is no one-third-octave mid-band frequency"
    return None


def table_problems(phi_deg: Any, theta_deg: Any, bands_hz: Any) -> list[tuple[str, str]]:
    """``(field, reason)`` of every slip of units or bands in a table's axes (module docstring); empty when none.

    ``field`` is ``phi_deg``, ``theta_deg`` or ``bands_hz``; ``reason`` reads after the field's name.
    The axes are 1-D, finite and ascending (as a card holds them).

    Examples
    --------
    >>> table_problems([-90.0, 0.0, 90.0], [0.0], [800.0, 1000.0, 1250.0])
    []
    >>> [f for f, _ in table_problems([-1.5708, 0.0, 1.5708], [0.0], [0.8, 1.0, 1.25])]
    ['phi_deg', 'bands_hz']
    """
    out: list[tuple[str, str]] = []
    for name, axis in (("phi_deg", phi_deg), ("theta_deg", theta_deg)):
        a = np.asarray(axis, dtype=float).reshape(-1)
        if a.size > 1 and np.abs(a).max() <= RADIAN_LIMIT_DEG:
            out.append((name, f"all {a.size} angles lie within +-{RADIAN_LIMIT_DEG:g} ({a[0]:g}..{a[-1]:g}), the "
                              "range of radians; table angles are degrees (-90..90, 0 straight below)"))
    bands = np.asarray(bands_hz, dtype=float).reshape(-1)
    bad = [(f, why) for f in bands.tolist() if (why := band_problem(f)) is not None]
    if bad:
        out.append(("bands_hz", f"band {bad[0][0]:g} {bad[0][1]}"))
    elif bands.size:
        idx = np.rint(10.0 * np.log10(exact_frequency(bands) / 1000.0)).astype(int)
        missing = sorted(set(range(int(idx.min()), int(idx.max()) + 1)) - set(idx.tolist()))
        if missing:
            names = ", ".join(f"{float(nominal_frequency(1000.0 * 10.0 ** (k / 10.0))):g}" for k in missing)
            out.append(("bands_hz", f"the bands {bands[0]:g}-{bands[-1]:g} Hz lack {names} Hz: a one-third-octave "
                                    "table needs every band between its lowest and highest (a missing band drops "
                                    "its energy from every level)"))
    return out


def _fail(msg: str, fld: str) -> None:
    raise CardError(f"hemisphere card: {msg}", field=fld)


@dataclass(frozen=True, eq=False)
class HemisphereCard(ModelCard):
    """A measured hemisphere as a source (see module docstring).

    Besides the fields of a model card (``ansatz`` is ``"hemisphere"``, ``parameters`` empty,
    ``reference_distance_m`` the table's radius): ``phi_deg`` (rows, ascending), ``theta_deg``
    (columns, ascending), ``bands_hz`` (nominal one-third-octave mid-band frequencies),
    ``levels_db`` (array ``(bands, rows, columns)``, unweighted band levels at the radius),
    ``measured`` (bool ``(rows, columns)``), ``atmosphere`` (``temperature_c``,
    ``humidity_pct``, ``pressure_kpa`` of the back-propagation) and ``condition`` (the flight
    condition: e.g. ``speed_m_s``, ``height_m``, ``power_w``).
    """

    phi_deg: Any = field(default_factory=lambda: np.zeros(0))
    theta_deg: Any = field(default_factory=lambda: np.zeros(0))
    bands_hz: Any = field(default_factory=lambda: np.zeros(0))
    levels_db: Any = field(default_factory=lambda: np.zeros((0, 0, 0)))
    measured: Any = field(default_factory=lambda: np.zeros((0, 0), bool))
    atmosphere: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_ATMOSPHERE))
    condition: Mapping[str, Any] = field(default_factory=dict)
    map_atmosphere: Mapping[str, float] | None = None
    """Atmosphere of the propagation on the map (ISO 9613-1 absorption); None: the card's ``atmosphere``."""

    def __post_init__(self) -> None:
        s = object.__setattr__
        for name in ("phi_deg", "theta_deg", "bands_hz", "levels_db"):
            try:
                a = np.array(getattr(self, name), dtype=float)
            except (TypeError, ValueError):
                _fail(f"field '{name}' must be numbers", name)
            a.setflags(write=False)
            s(self, name, a)
        try:
            m = np.array(self.measured, dtype=bool)
        except (TypeError, ValueError):
            _fail("field 'measured' must be a matrix of booleans", "measured")
        m.setflags(write=False)
        s(self, "measured", m)
        s(self, "atmosphere", dict(self.atmosphere))
        s(self, "condition", dict(self.condition))
        if self.map_atmosphere is not None:
            if not isinstance(self.map_atmosphere, Mapping):
                _fail("field 'map_atmosphere' must be an object or null", "map_atmosphere")
            s(self, "map_atmosphere", {**DEFAULT_ATMOSPHERE, **self.map_atmosphere})
        self._validate()
        s(self, "_weighted", self._a_weighted())
        s(self, "_ansatz", Ansatz(name=HEMISPHERE_ANSATZ, params=(), inputs=("d", "phi", "theta"),
                                  kernel=self._kernel, background=None,
                                  description=f"measured hemisphere {self.id}"))

    # ------------------------------------------------------------------ checks
    def _validate(self) -> None:
        _check_card_identity(self, "hemisphere card")
        if self.ansatz != HEMISPHERE_ANSATZ:
            _fail(f"field 'ansatz' must be {HEMISPHERE_ANSATZ!r}, got {self.ansatz!r}", "ansatz")
        if dict(self.parameters):
            _fail("field 'parameters' must be empty (the table is the model)", "parameters")
        for name in ("reference_power_w", "reference_distance_m"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                _fail(f"field '{name}' must be a positive number, got {v!r}", name)
        for name in ("phi_deg", "theta_deg"):
            a = getattr(self, name)
            if a.ndim != 1 or a.size < 1 or not np.all(np.isfinite(a)):
                _fail(f"field '{name}' must be a non-empty list of finite angles", name)
            if np.any(np.abs(a) > 90.0):
                _fail(f"field '{name}' angles must lie in -90..90 deg", name)
            if np.any(np.diff(a) <= 0):
                _fail(f"field '{name}' must be strictly ascending", name)
        b = self.bands_hz
        if b.ndim != 1 or b.size < 1 or np.any(~np.isfinite(b)) or np.any(b <= 0):
            _fail("field 'bands_hz' must be a non-empty list of positive frequencies", "bands_hz")
        if np.any(np.diff(b) <= 0):
            _fail("field 'bands_hz' must be strictly ascending", "bands_hz")
        shape = (b.size, self.phi_deg.size, self.theta_deg.size)
        if self.levels_db.shape != shape:
            _fail(f"field 'levels_db' must have shape (bands, phi, theta) = {shape}, got {self.levels_db.shape}",
                  "levels_db")
        if not np.all(np.isfinite(self.levels_db)):
            _fail("field 'levels_db' has non-finite levels", "levels_db")
        if self.measured.shape != shape[1:]:
            _fail(f"field 'measured' must have shape (phi, theta) = {shape[1:]}, got {self.measured.shape}",
                  "measured")
        for name in ("atmosphere", "map_atmosphere"):
            atm = getattr(self, name)
            if atm is None:
                continue
            for k, lo, hi in (("temperature_c", -60.0, 60.0), ("humidity_pct", 0.0, 100.0),
                              ("pressure_kpa", 50.0, 120.0)):
                v = atm.get(k)
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= float(v) <= hi:
                    _fail(f"field '{name}.{k}' must be a number in {lo:g}..{hi:g}, got {v!r}", f"{name}.{k}")

    # ------------------------------------------------------------------ physics
    def _a_weighted(self) -> tuple[np.ndarray, np.ndarray]:
        f = exact_frequency(self.bands_hz)
        la = self.levels_db + a_weighting(f)[:, None, None]
        atm = self.propagation_atmosphere
        alpha = atmospheric_absorption(f, atm["temperature_c"], atm["humidity_pct"], atm["pressure_kpa"])
        return la, np.asarray(alpha, dtype=float)

    @property
    def propagation_atmosphere(self) -> dict[str, float]:
        """The atmosphere of the absorption on the map: ``map_atmosphere``, else the card's ``atmosphere``."""
        return dict(self.map_atmosphere if self.map_atmosphere is not None else self.atmosphere)

    def in_atmosphere(self, temperature_c: float, humidity_pct: float, pressure_kpa: float = 101.325
                      ) -> HemisphereCard:
        """A copy propagating through another atmosphere on the map (the table stays as back-propagated)."""
        return replace(self, map_atmosphere={"temperature_c": float(temperature_c),
                                             "humidity_pct": float(humidity_pct), "pressure_kpa": float(pressure_kpa)})

    @property
    def band_frequencies_hz(self) -> np.ndarray:
        """Exact mid-band frequencies of ``bands_hz``, Hz."""
        return np.asarray(exact_frequency(self.bands_hz), dtype=float)

    @property
    def absorption_db_m(self) -> np.ndarray:
        """ISO 9613-1 absorption of each band in the card's atmosphere, dB/m."""
        return self._weighted[1]  # type: ignore[attr-defined]

    @property
    def a_weighted_db(self) -> np.ndarray:
        """A-weighted band levels at the radius, ``(bands, phi, theta)``."""
        return self._weighted[0]  # type: ignore[attr-defined]

    @property
    def overall_a_db(self) -> np.ndarray:
        """A-weighted overall level at the radius, ``(phi, theta)``."""
        return np.asarray(10.0 * np.log10(np.sum(10.0 ** (self.a_weighted_db / 10.0), axis=0)))

    def node_levels(self, d: Any) -> np.ndarray:
        """A-weighted level of every node at distance ``d`` (m): ``(…d, phi, theta)``."""
        d = np.asarray(d, dtype=float)
        flat = d.reshape(-1)
        g, c, e = self._band_terms(flat)
        # einsum, not BLAS: BLAS threads keep spinning after a call, taking CPU from the map's threads
        s = np.maximum(np.einsum("kb,bn->kn", g, e), 1e-300)
        lv = 10.0 * np.log10(s) + c[:, None] - 20.0 * np.log10(flat / float(self.reference_distance_m))[:, None]
        return lv.reshape(d.shape + self.a_weighted_db.shape[1:])

    def loudest_level(self, d: Any) -> np.ndarray:
        """The loudest level over all directions at distance ``d`` (m), dB(A): the largest node level.

        Exact: bilinear interpolation never exceeds its nodes, and every node is a direction
        (those at +-90 deg the horizon's limit).
        """
        d = np.asarray(d, dtype=float)
        return np.asarray(self.node_levels(d).reshape(d.shape + (-1,)).max(axis=-1))

    def _band_terms(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(G, c, E)`` with ``sum_b 10^((la_b,n - alpha_b (x - r0)) / 10) = 10^(c/10) sum_b G[x, b] E[b, n]``.

        ``x`` (m) flat; ``E = 10^((la - top_b) / 10)`` per band and node, ``G = 10^((top_b -
        alpha_b (x - r0) - c) / 10)`` and ``c`` the largest exponent at ``x``: nothing
        overflows, and the loudest band at each distance never underflows.
        """
        la, alpha = self._weighted  # type: ignore[attr-defined]
        la2 = la.reshape(la.shape[0], -1)
        top = la2.max(axis=1)
        ex = top[None, :] - alpha[None, :] * (x[:, None] - float(self.reference_distance_m))
        c = ex.max(axis=1)
        return np.exp((ex - c[:, None]) * _LN10_10), c, np.exp((la2 - top[:, None]) * _LN10_10)

    def interpolation(self, phi: Any, theta: Any) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray,
                                                           np.ndarray]:
        """Bilinear stencil of directions: ``[(flat node index, weight)] x 4``, ``filled_weight``, ``above``.

        ``filled_weight`` is the summed weight on filled nodes (1 outside the table or above
        the horizon).
        """
        a, b, above = table_angles(phi, theta)
        st, outside = _bilinear(self.phi_deg, self.theta_deg, a, b)
        filled = (~self.measured).ravel().astype(float)
        fw = sum(w * filled[k] for k, w in st)
        fw = np.where(outside | above, 1.0, fw)
        return st, np.asarray(fw), above

    def level_direction(self, d: Any, phi: Any, theta: Any) -> np.ndarray:
        """A-weighted level (dB(A)) at distance ``d`` (m) in direction ``phi``, ``theta`` (rad); broadcasts."""
        d, phi, theta = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (d, phi, theta)))
        st, _, _ = self.interpolation(phi, theta)
        flat = d.reshape(-1)
        nodes = [np.asarray(k).reshape(-1) for k, _ in st]  # flat node index per point
        weights = [np.broadcast_to(w, d.shape).reshape(-1) for _, w in st]
        out = np.empty(flat.shape)
        step = 1 << 14  # points per pass: the (points, bands) terms stay a few MB
        for a in range(0, flat.size, step):
            x = flat[a:a + step]
            g, c, e = self._band_terms(x)
            et = np.ascontiguousarray(e.T)  # (nodes, bands)
            lv = np.zeros(x.shape)
            for k, w in zip(nodes, weights, strict=True):
                s = np.maximum(np.einsum("kb,kb->k", g, et[k[a:a + step]]), 1e-300)
                lv += w[a:a + step] * (10.0 * np.log10(s) + c)
            out[a:a + step] = lv - 20.0 * np.log10(x / float(self.reference_distance_m))
        return out.reshape(d.shape)

    def _kernel(self, p: np.ndarray, x: Mapping[str, Any], d_ref: float, want_jac: bool
                ) -> tuple[np.ndarray, np.ndarray | None]:
        lv = self.level_direction(x["d"], x["phi"], x["theta"])
        return lv, (np.zeros(lv.shape + (0,)) if want_jac else None)

    @property
    def model(self) -> Ansatz:
        """The card's table as an ansatz without parameters (not in the registry)."""
        return self._ansatz  # type: ignore[attr-defined]

    # ------------------------------------------------------------------ summary
    def sound_power_db(self) -> dict[str, float]:
        """Sound power level (dB re 1 pW) of the table: the whole sphere, its upper half mirrored.

        The intensity ``p^2 / (rho c)`` (``rho c = 400`` rayl, so that ``Lw = Lp + 10 lg(area)``)
        integrated by solid angle over the lower hemisphere at the radius ``r0`` and doubled (the
        upper half is the lower half's mirror image, as on the map); ``p^2`` follows the card's
        interpolation, bilinear in the table angles of the nodes' overall levels (edge values
        outside the table), integrated by :func:`hemisphere_quadrature`.  A table of one level
        ``L`` gives ``L + 10 lg(4 pi r0^2)``.

        Returns
        -------
        dict
            ``overall_z`` (unweighted) and ``overall_a`` (A-weighted), dB; ``lower_half_z`` and
            ``lower_half_a``: the lower hemisphere alone (``2 pi r0^2``; 3.01 dB less), the
            half a Salford file's ``SWL_Bands`` states.
        """
        a, b, w = hemisphere_quadrature(self.phi_deg, self.theta_deg)
        st, _ = _bilinear(self.phi_deg, self.theta_deg, a, b)
        r2 = float(self.reference_distance_m) ** 2
        out: dict[str, float] = {}
        z = 10.0 * np.log10(np.sum(10.0 ** (self.levels_db / 10.0), axis=0))
        for key, nodes in (("z", z), ("a", self.overall_a_db)):
            flat = np.asarray(nodes, dtype=float).ravel()
            lv = sum(wk * flat[k] for k, wk in st)
            lower = 10.0 * math.log10(float(np.sum(w * 10.0 ** (lv / 10.0))) * r2)
            out[f"overall_{key}"] = lower + 10.0 * math.log10(2.0)
            out[f"lower_half_{key}"] = lower
        return out

    def uncovered(self) -> dict[str, Any]:
        """Directions of the lower hemisphere outside the table's angles (they take its edge values).

        Returns ``{"share": s, "ranges": [...]}``: ``s`` the share of the lower hemisphere's solid
        angle outside ``phi_deg[0]..phi_deg[-1]`` x ``theta_deg[0]..theta_deg[-1]`` (exact:
        the solid angle of a table-angle rectangle ``[a0, a1] x [b0, b1]`` is
        ``F(a1, b1) - F(a0, b1) - F(a1, b0) + F(a0, b0)``, ``F(a, b) = asin(sin a sin b)``), and
        the uncovered table-angle ranges in words (empty when the table reaches the horizon
        on all four sides).
        """
        a0, a1 = np.radians([self.phi_deg[0], self.phi_deg[-1]])
        b0, b1 = np.radians([self.theta_deg[0], self.theta_deg[-1]])

        def f(a: float, b: float) -> float:
            return math.asin(max(-1.0, min(1.0, math.sin(a) * math.sin(b))))

        inside = f(a1, b1) - f(a0, b1) - f(a1, b0) + f(a0, b0)
        ranges = []
        for name, g, lo_word, hi_word in (("phi", self.phi_deg, "ahead", "behind"),
                                          ("theta", self.theta_deg, "port", "starboard")):
            if g[0] > -90.0:
                ranges.append(f"{name} -90..{g[0]:g} deg ({lo_word})")
            if g[-1] < 90.0:
                ranges.append(f"{name} {g[-1]:g}..90 deg ({hi_word})")
        return {"share": max(0.0, 1.0 - inside / (2.0 * math.pi)), "ranges": ranges}

    def loudest_direction(self) -> dict[str, float]:
        """Node of the largest A-weighted overall level: table angles (deg) and level at the radius."""
        la = self.overall_a_db
        i, j = np.unravel_index(int(np.argmax(la)), la.shape)
        return {"phi_t_deg": float(self.phi_deg[i]), "theta_t_deg": float(self.theta_deg[j]),
                "level_db_a": float(la[i, j]), "measured": bool(self.measured[i, j])}

    # ------------------------------------------------------------------ io
    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": HEMISPHERE_SCHEMA, "id": self.id, "vehicle": self.vehicle, "phase": self.phase,
            "phases": list(self.phases), "ansatz": HEMISPHERE_ANSATZ, "parameters": {},
            "reference_power_w": float(self.reference_power_w),
            "reference_distance_m": float(self.reference_distance_m),
            "angle_convention": "phi_t = atan2(-x_b, z_b) along the track (negative ahead), "
                                "theta_t = atan2(y_b, z_b) across it (positive starboard); body axes x forward, "
                                "y starboard, z down",
            "phi_deg": self.phi_deg.tolist(), "theta_deg": self.theta_deg.tolist(),
            "bands_hz": self.bands_hz.tolist(), "levels_db": self.levels_db.tolist(),
            "measured": self.measured.tolist(), "atmosphere": dict(self.atmosphere),
            "condition": dict(self.condition),
            "map_atmosphere": None if self.map_atmosphere is None else dict(self.map_atmosphere),
            "statistics": dict(self.statistics),
            "provenance": dict(self.provenance), "notes": self.notes,
        }

    def __eq__(self, other: object) -> bool:
        return isinstance(other, HemisphereCard) and self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]


def hemisphere_from_dict(doc: Mapping[str, Any], *, source: str = "hemisphere card") -> HemisphereCard:
    """Build a hemisphere card from a parsed JSON object (schema ``gisnoise/hemisphere-card/1``).

    Besides the card's structure, the table's units and bands are checked (:func:`table_problems`): a
    :class:`~gisnoise.errors.CardError` naming ``phi_deg``, ``theta_deg`` or ``bands_hz``.
    """
    if doc.get("schema") != HEMISPHERE_SCHEMA:
        raise CardError(f"{source}: field 'schema' must be '{HEMISPHERE_SCHEMA}', got {doc.get('schema')!r}",
                        field="schema")
    required = ("id", "vehicle", "phase", "phi_deg", "theta_deg", "bands_hz", "levels_db", "measured")
    for k in required:
        if k not in doc:
            raise CardError(f"{source}: missing field '{k}'", field=k)
    known = set(HemisphereCard.__dataclass_fields__)
    kw = {k: v for k, v in doc.items() if k in known}
    kw.setdefault("ansatz", HEMISPHERE_ANSATZ)
    kw.setdefault("parameters", {})
    kw.setdefault("reference_power_w", 1.0)
    kw.setdefault("reference_distance_m", 1.0)
    for k in ("statistics", "provenance", "atmosphere", "condition"):
        if k in kw and not isinstance(kw[k], Mapping):
            raise CardError(f"{source}: field '{k}' must be an object", field=k)
    if "phases" in kw:
        if not isinstance(kw["phases"], (list, tuple)):
            raise CardError(f"{source}: field 'phases' must be a list", field="phases")
        kw["phases"] = tuple(kw["phases"])
    if "atmosphere" in kw:
        kw["atmosphere"] = {**DEFAULT_ATMOSPHERE, **kw["atmosphere"]}
    try:
        card = HemisphereCard(**kw)
    except CardError as exc:
        raise CardError(str(exc).replace("hemisphere card", source, 1), field=exc.field) from None
    except ValueError as exc:  # ragged nested lists
        raise CardError(f"{source}: table fields must be rectangular ({exc})", field="levels_db") from None
    problems = table_problems(card.phi_deg, card.theta_deg, card.bands_hz)
    if problems:
        fld, reason = problems[0]
        raise CardError(f"{source}: field '{fld}': {reason}", field=fld)
    return card


register_card_schema(HEMISPHERE_SCHEMA, hemisphere_from_dict)
