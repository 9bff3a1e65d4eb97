"""The checks of a flight before it is mapped: one set for a map, a day of operations and route comparison.

:func:`flight_findings` runs them on one trajectory with the cards that serve it and returns the
warnings a user must see (in the order below) and the cards used outside their fitted power range;
the refusals among them raise :class:`~gisnoise.errors.InputError`:

* a flight log cut short or damaged inside, or positions mended (:func:`gisnoise.flight.track_warning`):
  mapped with what could be read;
* a track flying more than :data:`~gisnoise.limits.GROUND_TOLERANCE_M` below the ground taken from
  take-off or landing points (:func:`below_track_ground`);
* a flying track below the ground of a DEM (:func:`below_dem`, with a DEM only);
* airborne samples without electric power (:func:`airborne_without_power`; all of them: refused,
  field ``power_w``);
* samples lying upside down at rest after a crash (:func:`lying_upside_down`);
* the cards' stated power ranges (:func:`gisnoise.maps.powers.check_power_ranges`: a card valid only
  at the power it was fitted at, used at others, is refused, field ``power_w``);
* measured hemispheres flown away from the speed they were measured at
  (:func:`gisnoise.maps.conditions.check_hemisphere_speeds`).

:func:`crs_scale_warning` is the grid's own check (a CRS whose scale at the map is far from 1).
:func:`gisnoise.maps.make_map`, :func:`gisnoise.ops.evaluate_operations` and
:func:`gisnoise.planning.compare_routes` call these, so a flight is judged alike on every map of it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.flight import GROUND_HINT_CLI, Trajectory, track_warning
from gisnoise.geo import centre_lon, scale_factor
from gisnoise.limits import GROUND_TOLERANCE_M
from gisnoise.maps.cardset import CardSet, flying_cards
from gisnoise.maps.conditions import check_hemisphere_speeds
from gisnoise.maps.powers import check_power_ranges

__all__ = ["CRS_SCALE_TOLERANCE", "FlightFindings", "airborne_without_power", "below_dem", "below_track_ground",
           "crs_scale_warning", "flight_findings", "lying_upside_down"]


GROUND_FROM_OWN = "its take-off or landing point"
"""Where a map's ground came from when the track gave it (the words of :func:`below_track_ground`)."""



@dataclass(frozen=True)
class FlightFindings:
    """What :func:`flight_findings` found: ``warnings`` (one line each); per card used outside the powers
    it was fitted at, ``{"range_w": [lo, hi], "used_w": [min, max], "samples": n}``; per hemisphere card flown
    away from its stated speed, what :func:`~gisnoise.maps.conditions.check_hemisphere_speeds` gives."""

    warnings: list[str] = field(default_factory=list)
    power_outside: dict[str, Any] = field(default_factory=dict)
    speed_outside: dict[str, Any] = field(default_factory=dict)


def flight_findings(traj: Trajectory, cards: CardSet, *, ground_h: float | None = None,
                    ground_from: str = GROUND_FROM_OWN, ground_hint: str = GROUND_HINT_CLI,
                    dem: Any = None, dem_offset_m: float = 0.0) -> FlightFindings:
    """The checks of the module docstring on ``traj`` flown with ``cards``.

    ``ground_h``: the flat ground when it was taken from take-off or landing points (the track is then checked
    against it); None when the user gave the ground or a DEM.  ``ground_from``, ``ground_hint``: the warning's
    words for where that ground came from and how the user gives it on this face (default: the map's, the
    track's own take-off or landing point and the command line's options; :func:`below_track_ground`).
    ``dem``, ``dem_offset_m``: the map's DEM (:class:`~gisnoise.geo.Dem`) and its offset, when it has one.
    """
    below = below_track_ground(traj, ground_h, ground_from=ground_from, hint=ground_hint)
    if below is None and dem is not None:
        below = below_dem(traj, dem, dem_offset_m)
    unpowered = airborne_without_power(traj)
    lying = lying_upside_down(traj)
    served = flying_cards(traj, cards) if traj.flying.any() else None  # once for both checks
    power_warnings, outside = check_power_ranges(traj, cards, cards_flying=served)
    speed_warnings, speed_outside = check_hemisphere_speeds(traj, cards, cards_flying=served)
    warnings = [w for w in (track_warning(traj), below, unpowered, lying) if w is not None] + power_warnings
    return FlightFindings(warnings + speed_warnings, outside, speed_outside)


def airborne_without_power(traj: Trajectory) -> str | None:
    """The rule for airborne samples (not ``on_ground``) without electric power (see the module docstring).

    None when there are none; an error when no airborne sample has power (the log does not measure the current
    in flight: the way out is a constant power); else the warning that names them (they are silent).
    """
    if traj.on_ground is None:
        return None
    airborne = ~traj.on_ground
    silent = airborne & (traj.power_w <= 0)
    if not silent.any():
        return None
    i = int(np.flatnonzero(silent)[0])
    if silent.sum() == airborne.sum():
        raise InputError(f"{traj.source}: electric power is zero on all {int(silent.sum())} airborne samples (first "
                         f"at t = {traj.t[i]:.2f} s: the battery current is not measured in flight); give a "
                         f"constant power (--power-w W, field power_w)", field="power_w")
    return (f"{traj.source}: {int(silent.sum())} of {int(airborne.sum())} airborne samples draw no battery current "
            f"(first at t = {traj.t[i]:.2f} s; motors stopped while the land detector still says airborne, or a "
            f"current sensor dropout): silent on the map; --power-w W maps the whole flight at a constant power")


def lying_upside_down(traj: Trajectory) -> str | None:
    """The warning for samples that draw power and are not marked on the ground, yet lie upside down
    (:attr:`~gisnoise.flight.Trajectory.lying`): silent on the map; None when there are none."""
    lie = traj.lying & (traj.power_w > 0)
    if traj.on_ground is not None:
        lie &= ~traj.on_ground
    if not lie.any():
        return None
    i = np.flatnonzero(lie)
    return (f"{traj.source}: {i.size} samples from t = {traj.t[i[0]]:.1f} s to {traj.t[i[-1]]:.1f} s lie upside down "
            f"at rest (roll {traj.roll[i[0]]:.0f} deg, pitch {traj.pitch[i[0]]:.0f} deg; a vehicle cannot hover "
            f"inverted: a crash), drawing {float(np.mean(traj.power_w[i])):.0f} W with no landing logged: not flying, "
            f"silent on the map")


CRS_SCALE_TOLERANCE = 0.01
"""Largest departure of the grid CRS's scale factor from 1 at the map before the map says so (1 %)."""


def crs_scale_warning(grid: Any, lon: Any, lat: Any) -> str | None:
    """The warning for a grid CRS whose scale at the tracks (positions ``lon``, ``lat``, deg) is far from 1: its
    cells are not their size on the ground.  The scale is taken at the tracks' centre, its longitude on the circle
    (:func:`gisnoise.geo.centre_lon`: a track across the antimeridian is centred near 180 deg, not 0)."""
    k = scale_factor(grid.crs, centre_lon(lon), float(np.mean(lat)))
    if k is None or not np.isfinite(k) or abs(k - 1.0) <= CRS_SCALE_TOLERANCE:  # None: PROJ has no scale for it
        return None
    cell = abs(float(grid.transform.a))
    name = grid.crs.to_string()
    return (f"crs: {name} scales distances by {k:.3f} at the map: its {cell:g} m cells are {cell / k:.1f} m on "
            f"the ground and the margin shrinks alike (a local UTM zone, the default, keeps them true)")


def below_track_ground(traj: Trajectory, ground_h: float | None, *, ground_from: str = GROUND_FROM_OWN,
                       hint: str = GROUND_HINT_CLI) -> str | None:
    """The warning for a track that flies lower than the ground taken from a take-off or landing point.

    Logged heights drift (GPS heights of a hovering vehicle wander by metres); more than
    :data:`~gisnoise.limits.GROUND_TOLERANCE_M` below that ground the UAV is put under the receivers.
    ``ground_from``: where the ground came from, as the warning says it; ``hint``: how the user gives the ground
    instead (the face's option or field).
    """
    fly = traj.flying
    if ground_h is None or not fly.any():
        return None
    i = int(np.argmin(np.where(fly, traj.h, np.inf)))
    depth = ground_h - float(traj.h[i])
    if depth <= GROUND_TOLERANCE_M:
        return None
    return (f"{traj.source}: the track flies up to {depth:.1f} m below the ground taken from {ground_from} "
            f"({ground_h:.1f} m; at t = {traj.t[i]:.1f} s): its logged heights drift, and there the UAV is put "
            f"under the receivers; give the ground with {hint}")


def below_dem(traj: Trajectory, dem: Any, dem_offset_m: float = 0.0) -> str | None:
    """The warning for flying samples more than :data:`~gisnoise.limits.GROUND_TOLERANCE_M` below the ground of
    ``dem`` (a :class:`~gisnoise.geo.Dem`, plus ``dem_offset_m``) under them: there the UAV is put inside the
    terrain, beside receivers on the slope above it.  A route's altitudes above ground hold at its waypoints and
    its legs are straight between them (:mod:`gisnoise.flight.waypoints`), so a leg across a hill can pass
    through it.  Samples off the DEM are not judged; None when no sample lies below.
    """
    from gisnoise.geo import sample_dem

    fly = np.flatnonzero(traj.flying)
    if not fly.size:
        return None
    ground = sample_dem(dem, np.asarray(traj.lon)[fly], np.asarray(traj.lat)[fly]) + float(dem_offset_m)
    depth = np.where(np.isfinite(ground), ground - np.asarray(traj.h, dtype=float)[fly], -np.inf)
    deep = depth > GROUND_TOLERANCE_M
    if not deep.any():
        return None
    k = int(np.argmax(depth))
    i, first, last = fly[k], fly[np.flatnonzero(deep)[0]], fly[np.flatnonzero(deep)[-1]]
    return (f"{traj.source}: {int(deep.sum())} of {fly.size} flying samples lie below the DEM's ground, up to "
            f"{depth[k]:.1f} m (t = {traj.t[i]:.1f} s at {traj.lon[i]:.6f}, {traj.lat[i]:.6f}; between t = "
            f"{traj.t[first]:.1f} and {traj.t[last]:.1f} s): there the UAV is put inside the terrain. A route's "
            f"altitudes above ground hold at its waypoints, its legs straight between them: add waypoints over "
            f"the high ground or fly higher; for a log, check its heights' datum and the DEM's (the DEM's offset: --dem-offset, "
            f"field dem_offset_m)")
