"""City scale on Dask: flights x tiles of the grid spread over a ``dask.distributed`` cluster.

:func:`gisnoise.ops.operations.evaluate_operations` hands its work here when given a
scheduler address or a number of workers (or when ``GISNOISE_DASK_SCHEDULER`` names a
scheduler, the setting a service passes on).  The grid is cut into tiles whose column
edges fall on the fast kernel's segments (:func:`gisnoise.ops.tiles.tile_windows`).
Every (tile, flight) pair is one task: it runs the kernel for that flight on that tile and
adds the result, with the flight's counts per period, to the tile's accumulators, which
the tile's previous task produced.  So each tile is a chain over the flights in schedule
order, the chains of all tiles run in parallel, and the sums are formed in the same order
and with the same arithmetic as in one process: the bands are bitwise identical.

Memory per worker is bounded by the tile, not the grid: a task holds one tile's
accumulators and one flight's kernel output on it (about ``tile_cells x (40 + 24 n_thr)``
bytes), the flights' instants (small) and, with a DEM, the tile's heights only.  Finished
tiles are copied into the result on the client and released.

Without an address a local cluster of ``workers`` processes (one thread each, so the
kernel's threads do not compete) is started for the call and closed after it.

Examples
--------
>>> from gisnoise.ops.scale import chain_keys
>>> chain_keys(1, 2)
['gisnoise-tile1-flight0', 'gisnoise-tile1-flight1']
"""

from __future__ import annotations

import logging
import uuid
from collections.abc import Callable, Sequence
from typing import Any

from gisnoise.errors import Cancelled, InputError
from gisnoise.ops.tiles import Plan, _tile_step

__all__ = ["chain_keys", "local_cluster", "run_on_dask", "SCHEDULER_ENV"]

log = logging.getLogger(__name__)

SCHEDULER_ENV = "GISNOISE_DASK_SCHEDULER"
"""Environment variable naming a Dask scheduler address (the service's setting)."""


def _require_distributed() -> Any:
    try:
        import distributed
    except ImportError:  # pragma: no cover - dask is the optional extra "dask"
        raise InputError("Dask execution needs dask.distributed (pip install 'gisnoise[dask]')",
                         field="scheduler") from None
    return distributed


def chain_keys(tile: int, n_flights: int, run: str = "") -> list[str]:
    """Task keys of one tile's chain over the flights."""
    return [f"gisnoise-{run}tile{tile}-flight{k}" for k in range(n_flights)]


def local_cluster(workers: int, *, memory_limit: str | None = None) -> Any:
    """A local ``dask.distributed`` cluster of ``workers`` processes with one thread each.

    ``memory_limit`` per worker (Dask syntax, ``"2GiB"``); default Dask's (the machine's
    memory shared out).  On the loopback interface; the dashboard on a free port.
    """
    distributed = _require_distributed()
    if isinstance(workers, bool) or int(workers) < 1:
        raise InputError(f"workers must be a positive integer, got {workers!r}", field="workers")
    kw: dict[str, Any] = {}
    if memory_limit is not None:
        kw["memory_limit"] = memory_limit
    return distributed.LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                    host="127.0.0.1", dashboard_address=":0", **kw)


def run_on_dask(plan: Plan, windows: Sequence[tuple[int, ...]], put: Callable[[tuple[int, ...], dict], None], *,
                scheduler: str | None = None, workers: int | None = None, memory_limit: str | None = None,
                cancel: Callable[[], bool] | None = None) -> dict[str, Any]:
    """Run the (tile, flight) chains of an operations plan on a Dask cluster.

    Parameters
    ----------
    plan : Plan
        Receivers, flights' instants and counts, thresholds.
    windows : sequence of (r0, r1, c0, c1)
        Tiles, aligned to the kernel's segments.
    put : callable
        ``put(window, accumulators)`` receives every finished tile on the client.
    scheduler : str, optional
        Address of a running scheduler; else a local cluster of ``workers`` processes.
    workers : int, optional
        Size of the local cluster (default 2).
    memory_limit : str, optional
        Per worker of a local cluster.
    cancel : callable, optional
        Polled while tiles finish; true cancels the remaining tasks and raises
        :class:`~gisnoise.errors.Cancelled`.

    Returns
    -------
    dict
        How it ran: ``executor``, ``scheduler`` address, ``workers``, ``tasks``.
    """
    distributed = _require_distributed()
    cluster = None
    if scheduler is None:
        cluster = local_cluster(2 if workers is None else workers, memory_limit=memory_limit)
        address = cluster.scheduler_address
    else:
        address = scheduler
    try:
        try:
            client = distributed.Client(address, timeout="30s", set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise InputError(f"scheduler: cannot reach the Dask scheduler at {address!r}: {exc}",
                             field="scheduler") from None
        try:
            n_workers = len(client.scheduler_info().get("workers", {}))
            run = uuid.uuid4().hex[:8] + "-"
            flights = client.scatter(list(plan.flights), broadcast=True, hash=False)
            last: dict[Any, tuple[int, ...]] = {}
            for t, w in enumerate(windows):
                rc = client.scatter(plan.rc.for_window(*w), hash=False)
                fut = None
                for k, key in enumerate(chain_keys(t, len(flights), run)):
                    fut = client.submit(_tile_step, fut, flights[k], plan.counts[k], rc, w, plan.thresholds,
                                        copy=True, floor_db=plan.floor_db, key=key, pure=False, priority=-t)
                last[fut] = w
            tasks = len(windows) * len(flights)
            with client.as_current():
                for fut in distributed.as_completed(list(last)):
                    if cancel is not None and cancel():
                        client.cancel(list(last))
                        raise Cancelled("cancelled", field="cancel")
                    put(last.pop(fut), fut.result())
                    fut.release()
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()
    return {"executor": "dask", "scheduler": address if cluster is None else "local", "workers": n_workers,
            "tasks": tasks}
