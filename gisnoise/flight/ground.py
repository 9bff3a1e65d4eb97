"""Where the ground is, from a track alone, and which stretches of a track fly.

The ground rule of the map faces (command line, service, QGIS): without a DEM or a
stated ground height, the ground is taken from the track only when the track starts
or ends on the ground, a take-off or a landing:

* its first or last sample is not flying (:attr:`~gisnoise.flight.trajectory.Trajectory.flying`:
  marked ``on_ground``, or zero electric power), or
* its first or last sample lies within :data:`GROUND_TOLERANCE_M` of the track's lowest
  point and either moves slower than :data:`REST_SPEED_M_S` there or is in a vertical
  multicopter phase (``climb`` at the start, ``sink`` at the end, ``hover`` at either).

Then the ground is the height of that end sample.  A track that starts and ends in
the air (a flyover segment) says nothing about the ground: :func:`ground_from_track`
returns None and the faces refuse with a message naming ``--ground-height`` and ``--dem``.
"""

from __future__ import annotations

import numpy as np

from gisnoise.errors import TrajectoryError
from gisnoise.flight.rest import REST_SPEED_M_S
from gisnoise.flight.trajectory import Trajectory
from gisnoise.limits import GROUND_TOLERANCE_M

__all__ = ["ground_from_track", "flying_parts", "flying_segments", "GROUND_TOLERANCE_M", "REST_SPEED_M_S", "GROUND_RULE",
           "GROUND_HINT_CLI"]

GROUND_RULE = ("without --dem or --ground-height, the ground is taken from the track only when it starts or "
               "ends on the ground (take-off or landing)")

GROUND_HINT_CLI = "--ground-height M (field ground_h_m) or --dem DEM.tif"
"""How a map's user gives the ground when the track does not (the command line's options and the request's
field); the service names its own field instead (:data:`gisnoise.service.errors.CLI_WORDS`)."""


def ground_from_track(traj: Trajectory) -> float | None:
    """Ellipsoidal ground height (m) of a track that starts or ends on the ground, else None.

    An end is on the ground when it does not fly (:attr:`~gisnoise.flight.Trajectory.flying`: on the ground or
    without power); a track with a land detector (``on_ground``) is taken at its word, and one without is also on
    the ground at an end lying at its lowest point (within :data:`~gisnoise.limits.GROUND_TOLERANCE_M`) at rest or
    in a vertical phase (a route's pad, a log without a land detector).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(5.0)
    >>> z = np.zeros(5)
    >>> fly = Trajectory(t=t, lat=z + 50, lon=8 + 1e-4 * t, h=z + 160.0, roll=z, pitch=z, yaw=z, power_w=z + 900,
    ...                  phase=np.full(5, "horizontal"))
    >>> ground_from_track(fly) is None
    True
    >>> up = fly.with_(h=np.array([100.0, 100.0, 102.0, 105.0, 110.0]), power_w=np.array([0, 900, 900, 900, 900.0]))
    >>> ground_from_track(up)
    100.0
    """
    n = len(traj)
    fly = traj.flying
    h_min = float(np.min(traj.h))
    if n >= 2:
        enu = np.stack(traj.enu(traj.origin()), axis=-1)
        speed = np.linalg.norm(np.gradient(enu, traj.t, axis=0), axis=1)
    else:
        speed = np.zeros(n)
    for i, vertical in ((0, ("climb", "hover")), (n - 1, ("sink", "hover"))):
        if not fly[i]:
            return float(traj.h[i])
        if traj.on_ground is not None:  # the log's land detector says airborne: a low end is no take-off or landing
            continue                    # (a stretch cut from a log that ends in a low hover)
        low = traj.h[i] - h_min <= GROUND_TOLERANCE_M
        if low and (speed[i] < REST_SPEED_M_S or str(traj.phase[i]) in vertical):
            return float(traj.h[i])
    return None


def flying_segments(traj: Trajectory) -> list[tuple[int, int]]:
    """Index ranges ``(i0, i1)`` (``i1`` exclusive) of consecutive flying samples, at least two each.

    A stretch between two flying samples counts as flying; one that touches a
    not-flying sample does not, so a vehicle standing on the ground adds no sound.
    """
    fly = traj.flying
    out: list[tuple[int, int]] = []
    i, n = 0, len(fly)
    while i < n:
        if not fly[i]:
            i += 1
            continue
        j = i
        while j < n and fly[j]:
            j += 1
        if j - i >= 2:
            out.append((i, j))
        i = j
    return out


def flying_parts(traj: Trajectory) -> list[Trajectory]:
    """The parts of ``traj`` that make noise: itself when it flies throughout, else its flying stretches
    (:func:`flying_segments`), each its own trajectory.  What a map and a day of operations evaluate.

    Raises :class:`~gisnoise.errors.TrajectoryError` (field ``power_w``) when no two consecutive samples fly.
    """
    if bool(np.all(traj.flying)):
        return [traj]
    segs = flying_segments(traj)
    if not segs:
        raise TrajectoryError(f"{traj.source}: no two consecutive flying samples (all on the ground or without "
                              "power): nothing makes noise", field="power_w")
    return [traj.select(np.arange(i0, i1)) for i0, i1 in segs]
