"""The job store and worker pool: persistence, order, progress, cancel, failures, re-queue after a stop."""

from __future__ import annotations

import threading
import time

import pytest
from service_helpers import KEY, assert_names_field, wait_job

from gisnoise.errors import Cancelled, CardError, GridTooLargeError
from gisnoise.service.jobs import JobStore, WorkerPool


def _store(tmp_path, **kw):
    return JobStore(tmp_path / "jobs.sqlite3", tmp_path / "jobs", **kw)


def test_submit_is_durable_before_it_returns(tmp_path):
    s = _store(tmp_path)
    job = s.submit("contours", {"a": 1}, {"request.json": b"{}", "sub/x.bin": b"\x00\x01"})
    assert job.status == "queued" and job.params == {"a": 1}
    # a second store on the same files (a new process) sees the job and its inputs
    s2 = _store(tmp_path)
    again = s2.get(job.id)
    assert again is not None and again.status == "queued"
    assert (s2.input_dir(job.id) / "sub" / "x.bin").read_bytes() == b"\x00\x01"


def test_folders_without_a_job_are_removed_at_start_up(tmp_path):
    s = _store(tmp_path)
    keep = s.submit("contours", {}, {"request.json": b"{}"}).id
    (s.jobs_dir / "upload-abc" / "campaign").mkdir(parents=True)  # an upload cut off by a stop
    (s.jobs_dir / "deadbeef" / "input").mkdir(parents=True)  # inputs written, row never inserted
    assert _store(tmp_path).remove_orphans() == 2
    assert [p.name for p in s.jobs_dir.iterdir()] == [keep]


def test_jobs_are_claimed_in_submission_order(tmp_path):
    s = _store(tmp_path)
    ids = [s.submit("contours", {"i": i}).id for i in range(5)]
    claimed = [s.claim_next().id for _ in range(5)]
    assert claimed == ids
    assert s.claim_next() is None
    assert all(s.get(i).status == "running" and s.get(i).attempts == 1 for i in ids)


def test_interrupted_jobs_are_requeued_then_failed_after_max_attempts(tmp_path):
    s = _store(tmp_path, max_attempts=2)
    jid = s.submit("contours", {}).id
    s.claim_next()
    (s.job_dir(jid) / "result.partial").mkdir()
    # the process dies; the next start-up finds the job running
    s = _store(tmp_path, max_attempts=2)
    assert s.requeue_interrupted() == 1
    j = s.get(jid)
    assert j.status == "queued" and j.attempts == 1 and "re-queued" in j.message
    assert not (s.job_dir(jid) / "result.partial").exists()
    s.claim_next()
    s.set_progress(jid, 0.4, "evaluating the grid")
    assert s.requeue_interrupted() == 0
    j = s.get(jid)
    assert j.status == "failed" and j.error_field == "job" and "2 times" in j.error
    assert j.message == "failed"  # not the last progress message ('evaluating the grid'), as it was


def test_cancel_of_a_queued_job_is_immediate(tmp_path):
    s = _store(tmp_path)
    jid = s.submit("contours", {}).id
    j = s.request_cancel(jid)
    assert j.status == "cancelled" and j.cancel_requested
    assert s.claim_next() is None


def _pool(store, handler, workers=1):
    pool = WorkerPool(store, {"contours": handler}, workers, poll_s=0.05)
    pool.start()
    return pool


def _wait(store, jid, states=("succeeded", "failed", "cancelled"), timeout=10.0):
    t_end = time.monotonic() + timeout
    while (j := store.get(jid)).status not in states:
        assert time.monotonic() < t_end, j
        time.sleep(0.01)
    return j


def test_worker_writes_result_atomically_and_reports_progress(tmp_path):
    s = _store(tmp_path)
    seen = []

    def handler(ctx):
        ctx.progress(1, 4)
        seen.append(s.get(ctx.job.id).progress)
        assert ctx.output_dir.name == "result.partial"
        (ctx.output_dir / "out.txt").write_text(ctx.params["text"])
        return {"n": 1}

    pool = _pool(s, handler)
    try:
        jid = s.submit("contours", {"text": "hello"}).id
        j = _wait(s, jid)
    finally:
        pool.stop()
    assert seen == [0.25]
    assert j.status == "succeeded" and j.progress == 1.0 and j.summary == {"n": 1} and j.files == ("out.txt",)
    assert (s.result_dir(jid) / "out.txt").read_text() == "hello"
    assert not (s.job_dir(jid) / "result.partial").exists()


def test_failures_keep_the_field_and_status_and_do_not_kill_the_worker(tmp_path):
    s = _store(tmp_path)

    def handler(ctx):
        kind = ctx.params["raise"]
        if kind == "card":
            raise CardError("card: field 'phase' must be ...", field="phase")
        if kind == "grid":
            raise GridTooLargeError("grid too large", field="grid.resolution_m")
        if kind == "bug":
            raise ZeroDivisionError("oops")
        return {}

    pool = _pool(s, handler)
    try:
        a = s.submit("contours", {"raise": "card"}).id
        b = s.submit("contours", {"raise": "grid"}).id
        c = s.submit("contours", {"raise": "bug"}).id
        d = s.submit("contours", {"raise": "none"}).id
        ja, jb, jc, jd = (_wait(s, i) for i in (a, b, c, d))
    finally:
        pool.stop()
    assert (ja.status, ja.error_field, ja.error_status) == ("failed", "phase", 422)
    assert (jb.status, jb.error_field, jb.error_status) == ("failed", "grid.resolution_m", 413)
    assert (jc.status, jc.error_field, jc.error_status) == ("failed", "job", 500)
    assert "ZeroDivisionError" in jc.error
    assert jd.status == "succeeded"
    assert not (s.job_dir(a) / "result").exists()


def test_cancel_of_a_running_job_reaches_the_core_callback(tmp_path):
    s = _store(tmp_path)
    started = threading.Event()

    def handler(ctx):
        started.set()
        for _ in range(1000):
            if ctx.cancel():
                raise Cancelled("cancelled", field="job")
            time.sleep(0.01)
        return {}

    pool = _pool(s, handler)
    try:
        jid = s.submit("contours", {}).id
        assert started.wait(5)
        s.request_cancel(jid)
        j = _wait(s, jid)
    finally:
        pool.stop()
    assert j.status == "cancelled"
    assert not (s.job_dir(jid) / "result").exists()


def test_stopping_the_pool_requeues_the_running_job(tmp_path):
    s = _store(tmp_path)
    started = threading.Event()

    def handler(ctx):
        started.set()
        while not ctx.cancel():
            time.sleep(0.01)
        raise Cancelled("stop", field="job")

    pool = _pool(s, handler)
    jid = s.submit("contours", {}).id
    assert started.wait(5)
    pool.stop()
    j = s.get(jid)
    assert j.status == "queued" and "re-queued" in j.message


# ---------------------------------------------------------------- over HTTP
@pytest.fixture
def fake_client(make_client):
    """A client whose contour jobs run a fake handler controlled by the test."""
    c = make_client(start_workers=False)
    st = c.app.state.gisnoise
    gate = threading.Event()

    def handler(ctx):
        ctx.progress(0.5, "half way")
        while not gate.wait(0.01):
            ctx.check_cancel()
        (ctx.output_dir / "contours.geojson").write_text('{"type": "FeatureCollection", "features": []}')
        (ctx.output_dir / "levels.tif").write_bytes(b"II*\x00")
        return {"ok": True}

    st.pool.handlers["contours"] = handler
    st.pool.poll_s = 0.02
    st.pool.start()
    c.gate = gate
    return c


def _submit(c):
    return c.app.state.gisnoise.jobs.submit("contours", {}, {"request.json": b"{}"}).id


def test_job_endpoints(fake_client):
    c = fake_client
    jid = _submit(c)
    wait_job(c, jid, until=("running",))
    assert_names_field(c.get(f"/jobs/{jid}/result"), 409, "job_id")
    t_end = time.monotonic() + 5
    while c.get(f"/jobs/{jid}").json()["progress"] != 0.5:
        assert time.monotonic() < t_end
        time.sleep(0.01)
    info = c.get(f"/jobs/{jid}").json()
    assert info["message"] == "half way" and info["result_url"] is None
    assert_names_field(c.delete(f"/jobs/{jid}"), 409, "job_id")
    c.gate.set()
    info = wait_job(c, jid)
    assert info["status"] == "succeeded" and info["summary"] == {"ok": True}
    assert info["files"] == ["contours.geojson", "levels.tif"]
    r = c.get(info["result_url"])
    assert r.status_code == 200 and r.headers["content-type"] == "application/geo+json"
    assert r.json() == {"type": "FeatureCollection", "features": []}
    r = c.get(f"/jobs/{jid}/result", params={"format": "geotiff"})
    assert r.headers["content-type"] == "image/tiff; application=geotiff" and r.content == b"II*\x00"
    r = c.get(f"/jobs/{jid}/result", headers={"accept": "image/tiff; application=geotiff"})
    assert r.content == b"II*\x00"
    assert c.get(f"/jobs/{jid}/files/levels.tif").content == b"II*\x00"
    assert_names_field(c.get(f"/jobs/{jid}/files/nope.txt"), 404, "name")
    assert_names_field(c.get(f"/jobs/{jid}/files/../../jobs.sqlite3"), 404)
    assert_names_field(c.post(f"/jobs/{jid}/cancel"), 409, "job_id")
    listed = c.get("/jobs").json()
    assert listed["total"] == 1 and listed["jobs"][0]["id"] == jid
    assert c.get("/jobs", params={"status": "queued"}).json()["jobs"] == []
    assert_names_field(c.get("/jobs", params={"status": "sleeping"}), 422, "status")
    assert c.delete(f"/jobs/{jid}").status_code == 204
    assert_names_field(c.get(f"/jobs/{jid}"), 404, "job_id")
    assert_names_field(c.get("/jobs/not-a-job"), 404, "job_id")


def test_cancel_over_http(fake_client):
    c = fake_client
    running = _submit(c)
    queued = _submit(c)
    wait_job(c, running, until=("running",))
    r = c.post(f"/jobs/{queued}/cancel")
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    r = c.post(f"/jobs/{running}/cancel")
    assert r.status_code == 200 and r.json()["cancel_requested"]
    assert wait_job(c, running)["status"] == "cancelled"
    for jid in (running, queued):  # a cancelled job never has a result: said so, not 'no result yet'
        body = assert_names_field(c.get(f"/jobs/{jid}/result"), 409, "job_id")
        assert body["detail"] == f"job_id: job {jid} was cancelled; it has no result", body
        body = assert_names_field(c.get(f"/jobs/{jid}/files/levels.tif"), 409, "job_id")
        assert "was cancelled" in body["detail"], body
    assert c.get("/health").json()["running"] == 0


def test_job_writes_need_a_key(make_client):
    c = make_client(api_keys=[KEY], start_workers=False)
    jid = _submit(c)
    assert_names_field(c.post(f"/jobs/{jid}/cancel"), 401, "X-API-Key")
    assert_names_field(c.delete(f"/jobs/{jid}", headers={"X-API-Key": "bad"}), 403, "X-API-Key")
    assert c.post(f"/jobs/{jid}/cancel", headers={"X-API-Key": KEY}).status_code == 200
    assert c.get(f"/jobs/{jid}").status_code == 200


# ---------------------------------------------------------------- restarts
def test_a_graceful_stop_requeues_as_never_run_and_does_not_count_toward_the_limit(tmp_path):
    """Three graceful stops of a job limited to 2 unclean ends: each re-queues it with progress 0 and no start
    time (it kept 0.5 and its start), none counts; then 2 unclean ends (found running at start-up) fail it."""
    s = _store(tmp_path, max_attempts=2)
    jid = s.submit("contours", {}).id
    for n in range(1, 4):
        started = threading.Event()

        def handler(ctx, started=started):
            ctx.progress(0.5, "half way")
            started.set()
            while not ctx.cancel():
                time.sleep(0.01)
            raise Cancelled("stop", field="job")

        pool = _pool(s, handler)
        assert started.wait(5)
        pool.stop()
        j = s.get(jid)
        assert (j.status, j.progress, j.started, j.attempts) == ("queued", 0.0, None, n), j
        assert j.message == "server stopped; re-queued"
        assert s.requeue_interrupted() == 0 and s.get(jid).status == "queued"
    s.claim_next()
    s.set_progress(jid, 0.7)
    assert _store(tmp_path, max_attempts=2).requeue_interrupted() == 1  # the first unclean end
    j = s.get(jid)
    assert (j.status, j.progress, j.started) == ("queued", 0.0, None), j
    s.claim_next()
    assert _store(tmp_path, max_attempts=2).requeue_interrupted() == 0  # the second: not retried
    j = s.get(jid)
    assert j.status == "failed" and j.error == "job: interrupted 2 times; not retried" and j.attempts == 5, j


# ---------------------------------------------------------------- inputs and results removed from the server
def test_a_job_whose_stored_input_was_removed_fails_saying_so(tmp_path):
    s = _store(tmp_path)
    gone = s.submit("contours", {}, {"request.json": b"{}"}).id
    import shutil

    shutil.rmtree(s.input_dir(gone))  # the whole input folder
    part = s.submit("contours", {}, {"request.json": b"{}"}).id
    (s.input_dir(part) / "request.json").unlink()  # one input file

    def handler(ctx):
        return {"text": (ctx.input_dir / "request.json").read_text()}

    pool = _pool(s, handler)
    try:
        jg, jp = _wait(s, gone), _wait(s, part)
    finally:
        pool.stop()
    for j in (jg, jp):
        assert (j.status, j.error_field) == ("failed", "job"), j
        assert f"the stored input of job {j.id} is missing on the server" in j.error, j.error
        assert "internal error" not in j.error and "FileNotFoundError" not in j.error
    assert "'request.json' was removed" in jp.error and str(tmp_path) not in jp.error


def test_a_result_removed_from_the_server_is_named_missing(fake_client):
    import shutil

    c = fake_client
    jid = _submit(c)
    c.gate.set()
    assert wait_job(c, jid)["status"] == "succeeded"
    rdir = c.app.state.gisnoise.jobs.result_dir(jid)
    (rdir / "contours.geojson").unlink()  # the main result file alone
    body = assert_names_field(c.get(f"/jobs/{jid}/result"), 410, "job_id")
    assert "'contours.geojson'" in body["detail"] and "missing on the server" in body["detail"], body
    assert c.get(f"/jobs/{jid}/result", params={"format": "geotiff"}).content == b"II*\x00"
    shutil.rmtree(rdir)  # the whole result folder
    info = c.get(f"/jobs/{jid}").json()
    assert info["status"] == "succeeded" and info["files"] == [] and info["result_url"] is None, info
    assert "result is missing on the server" in info["message"], info
    for url in (f"/jobs/{jid}/result", f"/jobs/{jid}/files/levels.tif"):  # was 404 on 'name' for /result
        body = assert_names_field(c.get(url), 410, "job_id")
        assert body["detail"].startswith(f"job_id: the result of job {jid} is missing on the server"), body
