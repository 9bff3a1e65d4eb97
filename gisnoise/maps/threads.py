"""Threads of the fast engine: a process-wide pool and the loop that feeds it, polling for cancel.

The kernel releases the GIL, so blocks of rows (one map) or tiles (a day of operations)
run in parallel on threads of one process.  :func:`default_threads` reads
``GISNOISE_THREADS`` (default: the CPUs this process may use).

Work started inside :func:`background` (the service's jobs) runs on pools of its own whose threads
have a lower scheduling priority (:data:`BACKGROUND_NICE`), so that a small map asked for meanwhile
(a route planner's request) neither queues behind a job's blocks nor shares the CPUs evenly with
them.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from contextlib import contextmanager
from typing import Any

from gisnoise.errors import InputError

__all__ = ["background", "BACKGROUND_NICE", "default_threads", "in_background", "lower_priority", "map_threads",
           "row_blocks", "thread_pool"]

log = logging.getLogger(__name__)

#: Nice value added to the threads of background work (Linux: per thread; CFS gives a thread of nice 0
#: about nine times the CPU of one at nice 10).
BACKGROUND_NICE = 10

_POOLS: dict[tuple[int, bool], ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()
_LOCAL = threading.local()


def lower_priority(nice: int = BACKGROUND_NICE) -> bool:
    """Give the calling thread the process's nice value plus ``nice`` (Linux; True when it holds after the call).

    The target is the process's (its main thread's) nice plus ``nice``, not the thread's own plus it: a thread
    started by a background thread inherits that thread's nice already, and is not lowered twice.  Where threads
    have no priority of their own (not Linux) or the system refuses, nothing changes and a debug line says so:
    the results are the same, only who gets the CPUs first differs.
    """
    if not hasattr(os, "setpriority") or not hasattr(threading, "get_native_id"):  # pragma: no cover
        log.debug("thread priorities are not available here; background work runs at normal priority")
        return False
    tid = threading.get_native_id()
    try:
        target = min(19, os.getpriority(os.PRIO_PROCESS, os.getpid()) + int(nice))
        if os.getpriority(os.PRIO_PROCESS, tid) < target:
            os.setpriority(os.PRIO_PROCESS, tid, target)
    except OSError as exc:  # pragma: no cover - a system that refuses even a lower priority
        log.debug("could not lower the priority of thread %s: %s", tid, exc)
        return False
    return True


@contextmanager
def background() -> Iterator[None]:
    """Within the block, maps started in the calling thread run their blocks on low-priority pools."""
    prev = in_background()
    _LOCAL.background = True
    try:
        yield
    finally:
        _LOCAL.background = prev


def in_background() -> bool:
    """Whether the calling thread is inside :func:`background`."""
    return bool(getattr(_LOCAL, "background", False))


def thread_pool(n: int, *, low_priority: bool | None = None) -> ThreadPoolExecutor:
    """A process-wide pool of ``n`` threads, kept for reuse (its threads keep their pyproj transformers).

    ``low_priority`` (default: :func:`in_background`): a pool of its own whose threads run at
    :data:`BACKGROUND_NICE`.
    """
    bg = in_background() if low_priority is None else bool(low_priority)
    with _POOLS_LOCK:
        pool = _POOLS.get((n, bg))
        if pool is None:
            pool = _POOLS[(n, bg)] = ThreadPoolExecutor(
                max_workers=n, thread_name_prefix=f"gisnoise-{'bg' if bg else 'fast'}{n}",
                initializer=lower_priority if bg else None)
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

