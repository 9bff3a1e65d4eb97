"""Flight logs: the flight CSV, PX4 ULog and ArduPilot DataFlash as :class:`Trajectory`.

:func:`read_flight` dispatches on the file suffix:

``.csv``
    The flight CSV of the specification (:func:`gisnoise.flight.trajectory.read_flight_csv`);
    ``t`` is already seconds since the flight's start.
``.ulg``
    PX4 ULog through pyulog (:func:`gisnoise.flight.ulog.read_ulog`).  Position from
    ``vehicle_global_position`` when logged, else from ``vehicle_gps_position`` /
    ``sensor_gps`` (3D fixes only) with the estimator's height (see Heights); attitude from
    the ``vehicle_attitude`` quaternion;
    electric power as the sum over ``battery_status`` instances of voltage x current.
``.bin``
    ArduPilot DataFlash through pymavlink (:func:`gisnoise.flight.dataflash.read_dataflash`).
    Position from ``POS`` when logged, else ``GPS`` (3D fixes only); attitude from
    ``ATT``; power from ``BAT`` (one battery per ``Instance``) or ``CURR`` (+ ``CUR2``).

Time base
    The samples of the position source (or a uniform grid at ``rate_hz``), trimmed to
    the span where position, attitude and power are all logged; attitude and power are
    interpolated onto it (attitude on the circle).  With ``start_utc`` the times are
    seconds since that instant, mapped through the GPS clock in the log (PX4
    ``time_utc_usec``; ArduPilot GPS week and milliseconds minus the leap seconds);
    without it, seconds since the first kept sample.

Stretches left out at the start or end
    Where the log holds some but not all of position, attitude and power (an estimator
    that publishes attitude only once aligned, a GNSS receiver without a 3D fix yet, a
    battery monitor that starts late), nothing is filled in: attitude sets the direction
    of the sound and position its distance, and holding or guessing either would put
    invented levels on a map.  A stretch longer than 1 s and two position steps is
    recorded in the trajectory's metadata (``log_left_out``: its span on the log's clock
    and the trajectory's, the topics that start late or end early, the most battery power
    drawn in it, the seconds in the air by the log's landed flag or None without one) and,
    when the vehicle may have made noise in it (in the air, or no landed flag and power
    drawn), said in the one-line warning every face shows (:mod:`gisnoise.flight.logspan`).
    A stretch spent landed is silent on any map and stays in the metadata.

On the ground
    Samples while landed (PX4 ``vehicle_land_detected.landed``) are marked
    ``on_ground``; without a landed flag (ArduPilot), samples at rest (below 0.3 m/s,
    smoothed over 1 s) within 1 m of the track's lowest point are.  Samples with zero
    battery current are not flying either, nor are samples where the vehicle lies upside
    down: inverted (``cos(roll) cos(pitch) < 0``) and at rest for 1 s or longer, which no
    vehicle can be in the air (a crash the log does not mark, motors still drawing power; e.g. in
    ArduCopter's ACRO mode, which runs no crash check: :mod:`gisnoise.flight.rest`,
    :attr:`~gisnoise.flight.trajectory.Trajectory.flying`).  A log is never refused for its
    on-ground samples.

Heights
    Trajectories hold ellipsoidal heights.  PX4 logs give them (``alt_ellipsoid``);
    where only heights above mean sea level exist (ArduPilot, some PX4 topics), the
    geoid undulation N (ellipsoidal minus orthometric height, m) comes from
    ``geoid_undulation_m`` when given (the override), else from the GNSS receiver's own
    ellipsoidal and MSL heights (PX4), else from the EGM96 grid (:mod:`gisnoise.geo.geoid`,
    per sample).  Without a grid the error names ``--geoid-undulation``; N is never guessed.
    The trajectory's metadata states the datum (``height_datum``), the model
    (``geoid_model``) and the mean undulation used (``geoid_undulation_m``).

    A PX4 log without ``vehicle_global_position`` (the estimator's position) takes its
    height from the estimator's ``vehicle_local_position.z`` where that is valid over its span:
    ``-z`` (resets undone) plus its median offset to the GPS heights over the fixes inside that
    span (:func:`gisnoise.flight.ulog.estimator_height`); a GNSS receiver's height wanders by
    metres within seconds near the ground, the estimator's, which fuses the barometer, much less.
    The horizontal position stays the GPS fixes' (the estimator's ``x``, ``y`` lie about an origin
    that exists only with ``xy_valid``, and then they follow the GPS).  The metadata states the offset
    (``height_anchor_m``), how far the GPS heights wandered about it (``height_anchor_range_m``)
    and the resets undone (``height_resets``); where the GPS heights stay, ``height_note`` says why.

Phase (see :func:`~gisnoise.flight.phases.phase_by_speed`)
    A PX4 VTOL's state (``vtol_vehicle_status``, else ``vehicle_status``) gives
    ``horizontal`` in fixed-wing mode and ``transition`` while transitioning.  In
    multicopter mode, and for logs without a VTOL state (all ArduPilot logs), the
    phase follows the ground velocity smoothed over 1 s: ``climb`` / ``sink`` when the
    vertical speed exceeds 1 m/s and the horizontal speed, else ``hover`` below 3 m/s
    horizontal speed, else ``horizontal``.

Logs cut short
    A ``.ulg`` or ``.bin`` file that ends inside a message (the battery died, the SD card filled, a
    download stopped) is read up to its last whole message, as pyulog and pymavlink do without a word;
    the trajectory's metadata records the cut (``log_cut``) and maps and ``gisnoise campaign check``
    show one warning (:func:`gisnoise.flight.readnotes.track_warning`).  A file cut inside its
    definitions, before any logged data, is refused in one line naming it; any other error on a cut
    file names the cut (:mod:`gisnoise.flight.logcut`).

Logs damaged inside
    Bytes zeroed or garbled mid-file (a bad SD card sector, a broken copy) are found by walking the
    framing (:mod:`gisnoise.flight.logdamage`) and left out, from the message the damage begins in to
    where the framing holds again, before pyulog or pymavlink read the file: no zeroed or garbled value
    reaches the trajectory, and the samples on either side are read.  The trajectory's metadata records
    the stretches left out (``log_corrupt``) and the same one-line warning names the file, the bytes and
    the boot-clock times whose samples are missing.  What pyulog prints about corrupt data never reaches
    stdout.  Damage wholly inside one message's payload leaves the framing whole and cannot be told.

A log without battery voltage or current raises an error that names the way out:
a constant ``power_w``.  A missing topic or message raises :class:`~gisnoise.errors.MissingColumnError`
naming it and the file.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from gisnoise.errors import InputError
from gisnoise.flight.dataflash import read_dataflash
from gisnoise.flight.trajectory import Trajectory, read_flight_csv
from gisnoise.flight.ulog import read_ulog

__all__ = ["read_flight", "FLIGHT_SUFFIXES"]

FLIGHT_SUFFIXES = (".csv", ".ulg", ".bin")


def read_flight(path: str | os.PathLike[str], *, start_utc: Any = None,
                geoid_undulation_m: float | None = None, rate_hz: float | None = None,
                power_w: float | None = None) -> Trajectory:
    """Read a flight log (``.csv``, ``.ulg`` or ``.bin``) as a trajectory.

    Parameters
    ----------
    path : path-like
        The log file; the suffix selects the reader.
    start_utc : datetime, str (ISO 8601), float (unix s) or None
        For ``.ulg`` and ``.bin``: the instant that becomes ``t = 0`` (the flight's
        ``start_utc``).  Ignored for ``.csv``, whose ``t`` is already relative to it.
    geoid_undulation_m : float, optional
        Ellipsoidal minus orthometric height, m, for logs that only give heights
        above mean sea level (overrides the geoid model).
    rate_hz : float, optional
        Resample logs onto a uniform grid at this rate, Hz (default: the position
        samples).
    power_w : float, optional
        For ``.ulg`` and ``.bin``: a constant electric power, W, in place of the logged
        battery power (logs without current); a flight CSV carries its own ``power_w``.

    Returns
    -------
    Trajectory
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".csv":
        return read_flight_csv(p)
    if not p.is_file():
        raise InputError(f"{p}: no such flight log", field="path")
    if suffix == ".ulg":
        return read_ulog(p, start_utc=start_utc, geoid_undulation_m=geoid_undulation_m, rate_hz=rate_hz,
                         power_w=power_w)
    if suffix == ".bin":
        return read_dataflash(p, start_utc=start_utc, geoid_undulation_m=geoid_undulation_m, rate_hz=rate_hz,
                              power_w=power_w)
    raise InputError(f"{p}: unknown flight log type {p.suffix!r}; expected one of {', '.join(FLIGHT_SUFFIXES)}",
                     field="path")
