"""Background work (the service's jobs) runs at a lower priority than maps asked for meanwhile.

A small map asked while a large job ran waited behind the job's row blocks in one shared pool
(``bench/bench_api_load.py --during-job``: p95 19x its idle latency).  Work started inside
``threads.background()`` now runs on pools of its own whose threads are niced by
``BACKGROUND_NICE``; the results do not depend on it.
"""

from __future__ import annotations

import os
import sys
import threading

import numpy as np
import pytest

from gisnoise.maps import threads

linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread nice values are Linux's")


def _nice() -> int:
    return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())


def _nices_of_blocks() -> set[int]:
    seen: set[int] = set()
    barrier = threading.Barrier(2)

    def fn(_):
        barrier.wait(10)  # both threads of the pool take a block: every thread is seen
        return _nice()

    threads.map_threads(fn, range(2), lambda _i, v: seen.add(v), 2)
    return seen


@linux
def test_blocks_of_background_work_run_niced_and_others_do_not():
    base = os.getpriority(os.PRIO_PROCESS, 0)
    assert _nices_of_blocks() == {base}
    with threads.background():
        assert threads.in_background()
        assert _nices_of_blocks() == {min(19, base + threads.BACKGROUND_NICE)}
    assert not threads.in_background()
    assert _nices_of_blocks() == {base}  # the foreground pool was not niced by the background one


@linux
def test_a_pool_started_by_a_background_thread_is_niced_once():
    """Threads inherit their creator's nice: a background pool started from a job's (niced) thread gets the
    process's nice + BACKGROUND_NICE, not twice that (19, the floor, before)."""
    base = os.getpriority(os.PRIO_PROCESS, os.getpid())
    out = {}

    def job_thread():
        threads.lower_priority()
        with threads.background():
            out["blocks"] = _nices_of_blocks_in_a_new_pool()

    t = threading.Thread(target=job_thread)
    t.start()
    t.join()
    assert out["blocks"] == {min(19, base + threads.BACKGROUND_NICE)}


def _nices_of_blocks_in_a_new_pool() -> set[int]:
    from concurrent.futures import ThreadPoolExecutor

    barrier = threading.Barrier(2)

    def fn(_):
        barrier.wait(10)
        return _nice()

    with ThreadPoolExecutor(2, initializer=threads.lower_priority) as pool:  # as thread_pool makes a background pool
        return set(pool.map(fn, range(2)))


@linux
def test_lower_priority_changes_only_the_calling_thread():
    out = {}

    def worker():
        out["before"] = _nice()
        out["ok"] = threads.lower_priority()
        out["after"] = _nice()

    main_before = _nice()
    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert out["ok"] and out["after"] == min(19, out["before"] + threads.BACKGROUND_NICE)
    assert _nice() == main_before


def test_a_map_in_the_background_equals_the_same_map_in_the_foreground():
    pytest.importorskip("numba")
    from affine import Affine

    from gisnoise.flight import Trajectory
    from gisnoise.geo import GridSpec, LocalFrame
    from gisnoise.maps import evaluate_grid
    from gisnoise.model import ModelCard

    frame = LocalFrame(52.27, 10.52, 0.0)
    card = ModelCard(id="c", vehicle="test", phase="horizontal", ansatz="paper-offset", reference_power_w=3000.0,
                     parameters=dict(p0=66.0, p1=20.0, p2=0.15, p3=-0.28, p4=-0.3, p5=1.05, p6=1.0, p7=40.0))
    t = np.arange(60.0)
    lat, lon, h = frame.to_wgs84(15.0 * t - 450.0, np.zeros_like(t), np.full(t.size, 60.0))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.zeros_like(t), pitch=np.full(t.size, 4.0),
                      yaw=np.full(t.size, 90.0), power_w=np.full(t.size, 3000.0),
                      phase=np.full(t.size, "horizontal"))
    tmerc = "+proj=tmerc +lat_0=52.27 +lon_0=10.52 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
    grid = GridSpec(tmerc, Affine(20.0, 0.0, -600.0, 0.0, -20.0, 400.0), 60, 40)
    kw = dict(metrics=("LAmax", "LAeq", "SEL"), ground_h=0.0, engine="fast", threads=2, chunk_cells=120)
    fg = evaluate_grid(traj, [card], grid, **kw)
    with threads.background():
        bg = evaluate_grid(traj, [card], grid, **kw)
    for m in ("LAmax", "LAeq", "SEL"):
        assert np.isfinite(fg.bands[m]).all()
        np.testing.assert_array_equal(fg.bands[m], bg.bands[m])


@linux
def test_the_service_runs_its_jobs_as_background_work(tmp_path):
    from gisnoise.service.jobs import JobStore, WorkerPool

    store = JobStore(tmp_path / "jobs.sqlite3", tmp_path / "jobs")
    seen = {}

    def handler(ctx):
        seen["background"] = threads.in_background()
        seen["nice"] = _nice()
        return {}

    pool = WorkerPool(store, {"contours": handler}, 1, poll_s=0.05)
    base = _nice()
    pool.start()
    try:
        jid = store.submit("contours", {}).id
        for _ in range(400):
            if store.get(jid).status == "succeeded":
                break
            threading.Event().wait(0.025)
    finally:
        pool.stop()
    assert store.get(jid).status == "succeeded"
    assert seen == {"background": True, "nice": min(19, base + threads.BACKGROUND_NICE)}
    assert _nice() == base  # the serving threads keep their priority
