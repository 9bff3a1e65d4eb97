"""Threads of the fast engine: a process-wide pool and the loop that feeds it, polling for cancel.

The kernel releases the GIL, so blocks of rows (one map) or tiles (a day of operations)
run in parallel on threads of one process.  :func:`default_threads` reads
``GISNOISE_THREADS`` (default: the CPUs this process may use).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from typing import Any

from gisnoise.errors import InputError

__all__ = ["default_threads", "map_threads", "row_blocks", "thread_pool"]


_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()


def thread_pool(n: int) -> ThreadPoolExecutor:
    """A process-wide pool of ``n`` threads, kept for reuse (its threads keep their pyproj transformers)."""
    with _POOLS_LOCK:
        pool = _POOLS.get(n)
        if pool is None:
            pool = _POOLS[n] = ThreadPoolExecutor(max_workers=n, thread_name_prefix=f"gisnoise-fast{n}")
        return pool


def row_blocks(height: int, width: int, chunk_cells: int, threads: int) -> list[tuple[int, int]]:
    """Blocks of whole rows ``(r0, r1)`` of a grid for ``threads`` threads: at most ``chunk_cells`` cells
    each (at least one row), and at least four blocks a thread when the grid has the rows."""
    rows = max(1, min(int(chunk_cells) // width, -(-height // (4 * threads))))
    return [(r, min(r + rows, height)) for r in range(0, height, rows)]


def default_threads() -> int:
    """Kernel threads: ``GISNOISE_THREADS`` if set, else the CPUs this process may use."""
    raw = os.environ.get("GISNOISE_THREADS", "").strip()
    if raw:
        try:
            n = int(raw)
        except ValueError:
            raise InputError(f"GISNOISE_THREADS must be a positive integer, got {raw!r}",
                             field="GISNOISE_THREADS") from None
        if n < 1:
            raise InputError(f"GISNOISE_THREADS must be a positive integer, got {raw!r}", field="GISNOISE_THREADS")
        return n
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def map_threads(fn: Callable[[Any], Any], items: Sequence[Any], put: Callable[[Any, Any], None], threads: int,
                 *, poll: Callable[[], None] | None = None) -> None:
    """``put(item, fn(item))`` for every item, ``put`` in the calling thread as results come.

    With ``threads > 1`` (and more than one item) ``fn`` runs on :func:`thread_pool`, at most
    ``2 threads`` items pending; ``poll`` (which may raise to stop) is called after every batch
    of finished items, and on the way out the pending items are cancelled or waited for.
    Otherwise the items run in order here, ``poll`` before each.
    """
    if threads == 1 or len(items) == 1:
        for x in items:
            if poll is not None:
                poll()
            put(x, fn(x))
        return
    pool = thread_pool(threads)
    pending: dict[Any, Any] = {}
    it = iter(items)
    try:
        for x in it:
            pending[pool.submit(fn, x)] = x
            if len(pending) >= 2 * threads:
                break
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for f in finished:
                put(pending.pop(f), f.result())
            if poll is not None:
                poll()
            for x in it:
                pending[pool.submit(fn, x)] = x
                if len(pending) >= 2 * threads:
                    break
    finally:
        for f in pending:
            f.cancel()
        wait(pending)

