"""The service's storage failing (a full disk, a job database that cannot be written), injected for a while:
the job worker lives on, the job running meanwhile fails naming the storage, later jobs run, /health tells, and
requests answer 507/503 naming the storage, leaving nothing behind."""

from __future__ import annotations

import errno
import pathlib
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from service_helpers import assert_names_field, wait_job

from gisnoise.service.jobs import JobStore, WorkerPool

FULL = "database or disk is full"


def _fail_database_while(store: JobStore, full: threading.Event, monkeypatch: pytest.MonkeyPatch,
                         said: str = FULL) -> None:
    """Every connection of ``store`` to its database raises SQLite's error ``said`` ('disk full') while ``full``
    is set."""
    real = store._connect

    @contextmanager
    def connect() -> Iterator[sqlite3.Connection]:
        if full.is_set():
            raise sqlite3.OperationalError(said)
        with real() as con:
            yield con

    monkeypatch.setattr(store, "_connect", connect)


def _slow_handler(started: threading.Event, release: threading.Event):
    """A job that reports progress until released (a long map), then writes its result; others finish at once."""

    def handler(ctx):
        if ctx.params.get("slow"):
            started.set()
            i = 0
            while not release.is_set():
                i += 1
                ctx.progress(min(i / 1000, 0.9), f"step {i}")
                ctx.check_cancel()
                time.sleep(0.01)
        (ctx.output_dir / "contours.geojson").write_text('{"type": "FeatureCollection", "features": []}')
        (ctx.output_dir / "levels.tif").write_bytes(b"II*\x00")
        return {"ok": True}

    return handler


def _until(pred, timeout: float = 10.0) -> None:
    end = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < end, "condition not reached"
        time.sleep(0.02)


@pytest.mark.parametrize(("said", "status", "reason"), [
    (FULL, 507, "storage: no space left on the device: cannot write the job database"),
    ("disk I/O error", 503, "storage: cannot read or write the job database (disk I/O error)")])
def test_a_failing_job_database_fails_the_running_job_and_the_worker_runs_the_next(tmp_path, monkeypatch, said,
                                                                                    status, reason):
    """SQLite's errors of a full disk and of a failing device, raised by every connection for a while (the
    finding: the progress write failed, then the write of the failure, and the worker thread died)."""
    s = JobStore(tmp_path / "jobs.sqlite3", tmp_path / "jobs")
    full, started, release = threading.Event(), threading.Event(), threading.Event()
    _fail_database_while(s, full, monkeypatch, said)
    pool = WorkerPool(s, {"contours": _slow_handler(started, release)}, 1, poll_s=0.02)
    pool.start()
    try:
        a = s.submit("contours", {"slow": True}).id
        assert started.wait(10)
        full.set()  # the next progress write fails, and so does writing the job's end
        _until(lambda: pool.unwritten == [a])
        time.sleep(0.3)  # the worker retries meanwhile
        assert pool.workers() == (1, 1)  # the worker lives
        assert s.write_failure is not None and s.write_failure.status == status
        full.clear()  # the storage is back: the job's end is written at the worker's next try
        _until(lambda: s.get(a).status == "failed")
        ja = s.get(a)
        assert (ja.error_field, ja.error_status, ja.message) == ("storage", status, "failed")
        assert ja.error.startswith(reason), ja.error
        assert not (s.job_dir(a) / "result.partial").exists()
        b = s.submit("contours", {}).id  # a job queued after the disk recovered runs and succeeds
        _until(lambda: s.get(b).status == "succeeded")
        assert s.get(b).files == ("contours.geojson", "levels.tif")
        assert pool.workers() == (1, 1) and pool.unwritten == [] and s.write_failure is None
    finally:
        release.set()
        pool.stop()


@pytest.mark.parametrize("raised", [OSError(errno.ENOSPC, "No space left on device"),
                                    OSError(errno.EDQUOT, "Disk quota exceeded")])
def test_a_result_the_disk_cannot_hold_fails_the_job_naming_the_space(tmp_path, raised):
    """The handler's result write fails (a core writer raised the system's error, or a core error raised from
    it): the job fails 507 on storage, not 500 'internal error'."""
    from gisnoise.errors import InputError

    s = JobStore(tmp_path / "jobs.sqlite3", tmp_path / "jobs")

    def handler(ctx):
        if ctx.params["wrapped"]:
            try:
                raise raised
            except OSError as exc:
                raise InputError("cannot write levels.tif", field="output") from exc
        raise raised

    pool = WorkerPool(s, {"contours": handler}, 1, poll_s=0.02)
    pool.start()
    try:
        ids = [s.submit("contours", {"wrapped": w}).id for w in (False, True)]
        _until(lambda: all(s.get(i).done for i in ids))
    finally:
        pool.stop()
    for i in ids:
        j = s.get(i)
        assert (j.status, j.error_field, j.error_status) == ("failed", "storage", 507), j
        assert j.error.startswith("storage: no space left on the device"), j.error


# ---------------------------------------------------------------- over HTTP
@pytest.fixture
def full_client(make_client, monkeypatch):
    """A client whose job store's database fails while ``c.full`` is set; its contour jobs run a fake handler
    (``slow`` ones until ``c.release``)."""
    c = make_client(start_workers=False)
    st = c.app.state.gisnoise
    c.full, c.started, c.release = threading.Event(), threading.Event(), threading.Event()
    _fail_database_while(st.jobs, c.full, monkeypatch)
    st.pool.handlers["contours"] = _slow_handler(c.started, c.release)
    st.pool.poll_s = 0.02
    st.pool.start()
    yield c
    c.release.set()


def test_health_jobs_and_the_worker_through_a_full_disk(full_client):
    """While the database is full: /health is 503 'failing' naming the storage (it was 200 ok, then 500),
    GET /jobs 507 naming it (was 500 'internal error (OperationalError)'; answered by the application, the
    test client would raise an escaped exception).  After: the running job has failed naming the storage, a new
    job runs, /health is ok with its worker alive."""
    c = full_client
    st = c.app.state.gisnoise
    h = c.get("/health")
    assert h.status_code == 200 and h.json()["status"] == "ok", h.json()
    assert h.json()["workers"] == {"started": 1, "alive": 1} and h.json()["problems"] == []
    a = st.jobs.submit("contours", {"slow": True}, {"request.json": b"{}"}).id
    assert c.started.wait(10)
    c.full.set()
    _until(lambda: st.pool.unwritten == [a])
    h = c.get("/health")
    assert h.status_code == 503, h.text
    body = h.json()
    assert body["status"] == "failing" and body["queued"] is None and body["workers"]["alive"] == 1, body
    assert any(p.startswith("storage: no space left on the device") for p in body["problems"]), body
    assert any("not written yet" in p for p in body["problems"]), body
    r = c.get("/jobs")
    assert_names_field(r, 507, "storage")
    assert "job database" in r.json()["detail"] and "internal error" not in r.json()["detail"]
    assert_names_field(c.post("/jobs/contours", json={}), 422)  # a bad request is still said as such
    c.full.clear()
    info = wait_job(c, a)
    assert info["status"] == "failed" and info["error"]["field"] == "storage", info
    assert info["error"]["status"] == 507 and "no space left on the device" in info["error"]["detail"], info
    b = st.jobs.submit("contours", {}, {"request.json": b"{}"}).id
    assert wait_job(c, b)["status"] == "succeeded"
    h = c.get("/health").json()
    assert h["status"] == "ok" and h["problems"] == [] and h["workers"] == {"started": 1, "alive": 1}, h
    assert (h["queued"], h["running"]) == (0, 0)


def test_health_says_failing_when_a_worker_is_dead(make_client, monkeypatch):
    c = make_client(start_workers=False)
    pool = c.app.state.gisnoise.pool
    monkeypatch.setattr(pool, "_loop", lambda: None)  # a worker that ends at once
    pool.start()
    _until(lambda: pool.workers()[1] == 0)
    r = c.get("/health")
    assert r.status_code == 503 and r.json()["status"] == "failing", r.text
    assert r.json()["workers"] == {"started": 1, "alive": 0}
    assert any(p.startswith("workers: 1 of 1 job worker(s) stopped") for p in r.json()["problems"]), r.json()


def _fail_writes_under(folder: pathlib.Path, monkeypatch, names: tuple[str, ...] = ()) -> None:
    """``Path.write_text`` and ``write_bytes`` raise ENOSPC for files under ``folder`` (those named ``names``
    only, when given), as on a full disk."""
    for method in ("write_text", "write_bytes"):
        real = getattr(pathlib.Path, method)

        def failing(self, *a, _real=real, **kw):
            if folder in self.parents and (not names or self.name in names):
                raise OSError(errno.ENOSPC, "No space left on device", str(self))
            return _real(self, *a, **kw)

        monkeypatch.setattr(pathlib.Path, method, failing)


def _card(card_id: str) -> dict:
    import json

    from service_helpers import CARDS

    doc = json.loads((CARDS / "demo_horizontal.json").read_text())
    doc["id"] = card_id
    return doc


@pytest.mark.parametrize("names", [(), (".highest_version.json.tmp",)], ids=["card file", "version record"])
def test_a_card_upload_on_a_full_disk_is_507_and_leaves_nothing(client, monkeypatch, names):
    cards = client.app.state.gisnoise.settings.cards_dir
    with monkeypatch.context() as m:
        _fail_writes_under(cards, m, names)
        r = client.post("/cards", json=_card("new-card"))
        body = assert_names_field(r, 507, "storage")
        assert "no space left on the device" in body["detail"] and "'new-card' was not stored" in body["detail"]
        assert not (cards / "new-card").exists()  # no folder, no temporary file
        # a new version of an existing card: its folder keeps what it held, no temporary file
        before = sorted(p.name for p in (cards / "demo-horizontal").iterdir())
        r = client.post("/cards", params={"new_version": "true"}, json={**_card("demo-horizontal"), "notes": "x"})
        assert_names_field(r, 507, "storage")
        assert sorted(p.name for p in (cards / "demo-horizontal").iterdir() if p.name.endswith(".tmp")) == []
        assert [n for n in sorted(p.name for p in (cards / "demo-horizontal").iterdir())
                if n.startswith("v")] == [n for n in before if n.startswith("v")]
    assert client.get("/cards/new-card").status_code == 404
    r = client.post("/cards", json=_card("new-card"))  # space again
    assert r.status_code == 201 and r.json()["version"] == 1, r.text


def test_a_job_submitted_on_a_full_disk_is_507_and_leaves_nothing(make_client, monkeypatch):
    c = make_client(start_workers=False)
    jobs_dir = c.app.state.gisnoise.settings.jobs_dir
    from test_api_contours import _request

    with monkeypatch.context() as m:
        _fail_writes_under(jobs_dir, m)
        r = c.post("/jobs/contours", json=_request())
        body = assert_names_field(r, 507, "storage")
        assert "no space left on the device" in body["detail"] and "not queued" in body["detail"], body
    assert list(jobs_dir.iterdir()) == [] and c.get("/jobs").json()["total"] == 0
    assert c.post("/jobs/contours", json=_request()).status_code == 202


# ---------------------------------------------------------------- gisnoise serve on a folder it cannot write
def test_serve_on_a_data_folder_it_cannot_create_says_so_in_one_line(tmp_path):
    from click.testing import CliRunner

    from gisnoise.cli.main import cli

    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    r = CliRunner().invoke(cli, ["serve", "--data-dir", str(blocker / "data"), "--port", "0"])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in r.output, r.output
    assert f"the data folder {blocker / 'data'} cannot be written" in lines[0], lines


def test_serve_on_a_read_only_data_folder_with_a_database_says_it_cannot_be_written(tmp_path, monkeypatch):
    """A data folder with its job database, on a file system that refuses writes (EROFS, injected: the tests
    may run as root, whom permissions do not stop): one line naming the folder, no traceback (was: sqlite3's
    'unable to open database file' as a traceback; an empty folder said 'cannot read the input')."""
    from click.testing import CliRunner

    from gisnoise.cli.main import cli

    data = tmp_path / "data"
    JobStore(data / "jobs.sqlite3", data / "jobs")
    real = pathlib.Path.write_bytes

    def read_only(self, *a, **kw):
        if data in self.parents:
            raise OSError(errno.EROFS, "Read-only file system", str(self))
        return real(self, *a, **kw)

    monkeypatch.setattr(pathlib.Path, "write_bytes", read_only)
    r = CliRunner().invoke(cli, ["serve", "--data-dir", str(data), "--port", "0"])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in r.output, r.output
    assert lines[0].startswith(f"Error: the data folder {data} cannot be written (Read-only file system)"), lines


def test_a_start_on_a_failing_database_serves_and_requeues_once_it_works(tmp_path, monkeypatch):
    """The last stop left a job running (a crash); the database refuses writes at the next start: the service
    starts anyway and says it is failing, and once the database works its worker re-queues the job before
    claiming any, then runs it (before, the start-up's re-queue raised and the service did not start)."""
    from fastapi.testclient import TestClient
    from service_helpers import CARDS

    from gisnoise.service import create_app
    from gisnoise.service.settings import Settings
    settings = Settings(data_dir=tmp_path / "data", seed_cards_dir=CARDS, tile_url="")  # as conftest's
    store = JobStore(settings.db_path, settings.jobs_dir)
    crashed = store.submit("contours", {}, {"request.json": b"{}"}).id
    store.claim_next()  # running when the process died
    app = create_app(settings)
    st = app.state.gisnoise
    full, started, release = threading.Event(), threading.Event(), threading.Event()
    st.pool.handlers["contours"] = _slow_handler(started, release)
    st.pool.poll_s = 0.02
    _fail_database_while(st.jobs, full, monkeypatch)
    full.set()
    with TestClient(app) as c:
        h = c.get("/health")
        assert h.status_code == 503 and h.json()["workers"] == {"started": 1, "alive": 1}, h.text
        full.clear()
        info = wait_job(c, crashed)
        assert info["status"] == "succeeded" and info["attempts"] == 2, info
        assert c.get("/health").json()["status"] == "ok"
