"""A small bounded cache of trajectories built from routes (route planners send the same route again).

Turning a waypoint route into a sampled trajectory is the largest part of a small
``POST /contours`` outside the evaluator.  Planners call the service in loops with
the same route and other levels, metrics or cell sizes, so the trajectory of a
route document is kept, keyed by its canonical JSON (sorted keys) and the sample
limit it was built under.  Only successful builds are kept; a hit returns a fresh
copy (its own arrays and metadata), so no request can change what another one gets.
"""

from __future__ import annotations

import copy
import json
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

from gisnoise.flight import Trajectory

__all__ = ["TrajectoryCache", "route_key"]


def route_key(data: Any, *options: Any) -> str:
    """The canonical JSON of a route document and the options it is built with."""
    return json.dumps([data, *options], sort_keys=True, separators=(",", ":"), allow_nan=True)


def _copy(traj: Trajectory) -> Trajectory:
    """A copy sharing the kept trajectory's arrays (a trajectory's arrays are read-only) with its own metadata.

    Not re-checked: the trajectory was checked when it was built and a kept one is never changed
    (``dataclasses.replace`` would run every check of the trajectory again on each hit).
    """
    out = copy.copy(traj)
    object.__setattr__(out, "metadata", copy.deepcopy(traj.metadata))
    return out


class TrajectoryCache:
    """Least-recently-used trajectories, at most ``size`` of them (0: no caching), safe across threads."""

    def __init__(self, size: int = 32) -> None:
        self.size = size
        self._items: OrderedDict[str, Trajectory] = OrderedDict()
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def __len__(self) -> int:
        return len(self._items)

    def clear(self) -> None:
        """Forget every kept trajectory."""
        with self._lock:
            self._items.clear()

    def get(self, key: str, build: Callable[[], Trajectory]) -> Trajectory:
        """The trajectory under ``key``, built with ``build()`` when absent (errors propagate, nothing is kept)."""
        with self._lock:
            hit = self._items.get(key)
            if hit is not None:
                self._items.move_to_end(key)
                self.hits += 1
        if hit is not None:
            return _copy(hit)
        traj = build()
        if self.size <= 0:
            return traj
        kept = _copy(traj)
        with self._lock:
            self.misses += 1
            self._items[key] = kept
            self._items.move_to_end(key)
            while len(self._items) > self.size:
                self._items.popitem(last=False)
        return traj
