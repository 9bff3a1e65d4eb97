"""The ground rule of every map: where the receivers stand, and the checks of a given ground.

The command line, the service, the QGIS plugin and the in-memory calls
(:func:`gisnoise.maps.evaluate_grid`, :func:`gisnoise.maps.evaluate_flying`, :func:`gisnoise.maps.receivers_for`)
all take the flat ground under the receivers by :func:`checked_ground`:

1. the ground given (``ground_h``, the ellipsoidal height of flat ground, m), or a DEM (the DEM is the ground);
2. else the ground the source states (a waypoints route's ``ground_h_m``, kept in the trajectory's
   ``metadata["ground_h_m"]``);
3. else the track's own take-off or landing point (:func:`gisnoise.flight.ground_from_track`: the track starts
   or ends on the ground);
4. else the map is refused in one line naming ``ground_h`` (:class:`~gisnoise.errors.InputError`): a track in the
   air throughout says nothing about the ground, and the receivers would otherwise be put at flight altitude.

The receivers stand on or above the ground (``receiver_height`` within 0 to the limit of
:func:`gisnoise.limits.check_receiver_height`), and a given ground lies at or below the track's lowest flying point
(:func:`gisnoise.limits.check_receivers`).  A ground taken from the track's own take-off or landing point is not
checked against the track: the track lies within its height noise of it by construction, and a track flying lower
than it is said in a warning (:func:`gisnoise.maps.flightchecks.below_track_ground`).

A ground chosen once for a whole track (or a day of flights, or routes compared over one ground) is passed on as
a :class:`ChosenGround`: the evaluator takes it as it is, without applying the rule again to the part it is given
(a flying stretch of the track does not start on the ground).

Examples
--------
>>> import numpy as np
>>> from gisnoise.flight import Trajectory
>>> t = np.arange(5.0)
>>> z = np.zeros(5)
>>> cruise = Trajectory(t=t, lat=z + 50, lon=8 + 1e-4 * t, h=z + 160.0, roll=z, pitch=z, yaw=z, power_w=z + 900,
...                     phase=np.full(5, "horizontal"), source="cruise")
>>> checked_ground([cruise], 1.5, 100.0, None).source
'given'
>>> checked_ground([cruise], 1.5, None, None)
Traceback (most recent call last):
...
gisnoise.errors.InputError: cruise: ground unknown: the track neither starts nor ends on the ground (lowest point 160.0 m); give ground_h (ellipsoidal height of the ground, m) or dem
>>> up = cruise.with_(power_w=np.array([0, 900, 900, 900, 900.0]))   # motors off at the first sample
>>> g = checked_ground([up], 1.5, None, None)
>>> float(g), g.source
(160.0, 'take-off or landing point of the track')
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.flight import GROUND_HINT_CLI, Trajectory, ground_from_track
from gisnoise.limits import check_ground_below, check_receiver_height

__all__ = ["GROUND_FROM_TRACK", "GROUND_GIVEN", "GROUND_HINT_API", "GROUND_HINT_CLI", "GROUND_STATED",
           "ChosenGround", "checked_ground", "own_ground"]

GROUND_GIVEN = "given"
"""The map metadata's ``ground_h_source`` when the caller gave the ground height."""
GROUND_STATED = "stated by the route"
"""The map metadata's ``ground_h_source`` when the source states its ground (a waypoints route's ``ground_h_m``)."""
GROUND_FROM_TRACK = "take-off or landing point of the track"
"""The map metadata's ``ground_h_source`` when the ground is the track's own take-off or landing height."""
GROUND_HINT_API = "ground_h (ellipsoidal height of the ground, m) or dem"
"""How a Python caller gives the ground when the track does not (the command line names its options instead:
:data:`gisnoise.flight.GROUND_HINT_CLI`)."""


class ChosenGround(float):
    """A flat ground's ellipsoidal height, m, chosen by a ground rule, and where it came from (``source``, the
    map metadata's ``ground_h_source``).

    Passed as ``ground_h`` it is taken as it is: neither the rule nor the check against the track is applied to it
    again (the caller applied them to the whole track, day or set of routes).

    >>> g = ChosenGround(118.0, "take-off or landing point of the track")
    >>> g + 1.5, g.source
    (119.5, 'take-off or landing point of the track')
    """

    source: str

    def __new__(cls, value: float, source: str = GROUND_GIVEN) -> ChosenGround:
        obj = super().__new__(cls, value)
        obj.source = str(source)
        return obj

    def __reduce__(self) -> tuple[Any, ...]:
        return (ChosenGround, (float(self), self.source))


def own_ground(traj: Trajectory) -> ChosenGround | None:
    """The ground a track gives itself: the one its source states (``metadata["ground_h_m"]``), else its take-off
    or landing point (:func:`gisnoise.flight.ground_from_track`); None for a track in the air throughout."""
    stated = traj.metadata.get("ground_h_m")
    if stated is not None:
        return ChosenGround(float(stated), GROUND_STATED)
    g = ground_from_track(traj)
    return None if g is None else ChosenGround(g, GROUND_FROM_TRACK)


def checked_ground(trajectories: Iterable[Trajectory], receiver_height: Any, ground_h: Any, dem: Any, *,
                   stated_h: float | None = None, hint: str = GROUND_HINT_API) -> ChosenGround | None:
    """The flat ground of a map of ``trajectories`` by the rule of the module docstring, after the receiver checks.

    Parameters
    ----------
    trajectories : iterable of Trajectory
        The tracks mapped on one ground (usually one).  A given ground is checked against each; without one, the
        lowest of their own grounds (:func:`own_ground`) is taken.
    receiver_height : float or None
        Receiver height above the ground, m (None: checked by the caller).
    ground_h : float, ChosenGround or None
        The ground given, m.  A :class:`ChosenGround` is taken as it is.
    dem : optional
        A DEM (any form the evaluator takes); with one and without ``ground_h`` the DEM is the ground.
    stated_h : float, optional
        The ground the source states (a waypoints route read by the caller), m.
    hint : str
        How the caller's user gives the ground, for the refusal (:data:`GROUND_HINT_API`,
        :data:`gisnoise.flight.GROUND_HINT_CLI`).

    Returns
    -------
    ChosenGround or None
        None when the DEM is the ground.

    Raises
    ------
    InputError
        ``receiver_height`` below 0 or above its limit; a given ground above a track's lowest flying point
        (field ``ground_h``); no ground known (field ``ground_h``, naming ``hint``).
    """
    trajs = list(trajectories)
    if receiver_height is not None:
        check_receiver_height(receiver_height)
    if isinstance(ground_h, ChosenGround):
        return ground_h
    if ground_h is not None:
        for traj in trajs:
            check_ground_below(ground_h, traj.flying_heights())
        return ChosenGround(float(ground_h), GROUND_GIVEN)
    if dem is not None:
        return None
    if stated_h is not None:
        return ChosenGround(float(stated_h), GROUND_STATED)
    own = [g for g in (own_ground(tr) for tr in trajs) if g is not None]
    if own:
        return min(own)
    if not trajs:
        raise InputError(f"ground_h: ground unknown (no track); give {hint}", field="ground_h")
    lowest = min(trajs, key=lambda tr: float(np.min(tr.h)))
    lo = float(np.min(lowest.h))
    what = "the track neither starts nor ends" if len(trajs) == 1 else "no track starts or ends"
    raise InputError(f"{lowest.source}: ground unknown: {what} on the ground (lowest point {lo:.1f} m); give {hint}",
                     field="ground_h")

