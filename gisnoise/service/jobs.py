"""Persistent server-side jobs: an SQLite job table, job folders on disk and a worker pool.

A job is written to disk (its folder ``<jobs_dir>/<id>/input``) and to the
database *before* its submission is answered, so nothing submitted is lost.
Workers claim queued jobs in submission order, run the handler of the job's
kind and write the result into ``result.partial/``, which is renamed to
``result/`` only when the handler returns: a result folder is always complete.
A job that was running when the process stopped (killed, crashed, restarted)
is found ``running`` at the next start-up, re-queued and run again from its
inputs; after ``max_attempts`` interruptions it fails instead of looping.

States: ``queued`` -> ``running`` -> ``succeeded`` | ``failed`` | ``cancelled``.
"""

from __future__ import annotations

import json
import logging
import shutil
import sqlite3
import threading
import time
import traceback
import uuid
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gisnoise.errors import Cancelled, GisnoiseError
from gisnoise.service.errors import UNREADABLE, core_detail, scrub_paths, status_for

__all__ = ["Job", "JobContext", "JobStore", "WorkerPool", "STATES", "FINAL_STATES", "Handler"]

log = logging.getLogger(__name__)

STATES = ("queued", "running", "succeeded", "failed", "cancelled")
FINAL_STATES = ("succeeded", "failed", "cancelled")

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    seq INTEGER NOT NULL,
    kind TEXT NOT NULL,
    status TEXT NOT NULL,
    progress REAL NOT NULL DEFAULT 0,
    message TEXT NOT NULL DEFAULT '',
    params TEXT NOT NULL,
    created REAL NOT NULL,
    started REAL,
    finished REAL,
    attempts INTEGER NOT NULL DEFAULT 0,
    cancel_requested INTEGER NOT NULL DEFAULT 0,
    error TEXT,
    error_field TEXT,
    error_status INTEGER,
    summary TEXT
);
CREATE INDEX IF NOT EXISTS jobs_status_seq ON jobs (status, seq);
"""


@dataclass(frozen=True)
class Job:
    """One row of the job table."""

    id: str
    kind: str
    status: str
    progress: float
    message: str
    params: Mapping[str, Any]
    created: float
    started: float | None
    finished: float | None
    attempts: int
    cancel_requested: bool
    error: str | None
    error_field: str | None
    error_status: int | None
    summary: Mapping[str, Any] | None
    files: tuple[str, ...] = ()

    @property
    def done(self) -> bool:
        return self.status in FINAL_STATES


@dataclass
class JobContext:
    """What a handler gets: its folders, its parameters and the progress/cancel callbacks."""

    job: Job
    input_dir: Path
    output_dir: Path
    progress: Callable[..., None]
    cancel: Callable[[], bool]
    """Returns True when the job should stop; handlers pass it to the core as ``cancel=``."""
    warnings: list[str] | None = None
    """What the handler found to say about its input before the work (e.g. a campaign's cut logs), set once it
    has read that input (an empty list: nothing to say): kept as the summary of a job that then fails
    (``{"warnings": [...]}``, empty or not), where they may explain the failure; None until the input is read
    (a job failing before has no summary)."""

    @property
    def params(self) -> Mapping[str, Any]:
        return self.job.params

    def check_cancel(self) -> None:
        if self.cancel():
            raise Cancelled("job cancelled", field="job")


Handler = Callable[[JobContext], Mapping[str, Any] | None]


class JobStore:
    """The job table (SQLite) and the job folders.

    Parameters
    ----------
    db_path : path
        SQLite database file (created).
    jobs_dir : path
        Folder of the job folders (created).
    max_attempts : int
        Starts of a job (interrupted runs included) before it is failed.
    """

    def __init__(self, db_path: str | Path, jobs_dir: str | Path, *, max_attempts: int = 3) -> None:
        self.db_path = Path(db_path)
        self.jobs_dir = Path(jobs_dir)
        self.max_attempts = max_attempts
        self.db_path.parent.mkdir(parents=True, exist_ok=True)
        self.jobs_dir.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._wakeup = threading.Condition()
        with self._connect() as con:
            con.execute("PRAGMA journal_mode=WAL")
            con.executescript(_SCHEMA)

    # ------------------------------------------------------------ plumbing
    @contextmanager
    def _connect(self) -> Iterator[sqlite3.Connection]:
        con = sqlite3.connect(self.db_path, timeout=30.0, isolation_level=None)
        con.row_factory = sqlite3.Row
        try:
            con.execute("PRAGMA synchronous=FULL")
            yield con
        finally:
            con.close()

    def job_dir(self, job_id: str) -> Path:
        return self.jobs_dir / job_id

    def input_dir(self, job_id: str) -> Path:
        return self.job_dir(job_id) / "input"

    def result_dir(self, job_id: str) -> Path:
        return self.job_dir(job_id) / "result"

    def _row(self, r: sqlite3.Row) -> Job:
        rdir = self.result_dir(r["id"])
        files: tuple[str, ...] = ()
        if r["status"] == "succeeded" and rdir.is_dir():
            files = tuple(sorted(str(p.relative_to(rdir)) for p in rdir.rglob("*") if p.is_file()))
        return Job(
            id=r["id"], kind=r["kind"], status=r["status"], progress=float(r["progress"]), message=r["message"],
            params=json.loads(r["params"]), created=r["created"], started=r["started"], finished=r["finished"],
            attempts=int(r["attempts"]), cancel_requested=bool(r["cancel_requested"]), error=r["error"],
            error_field=r["error_field"], error_status=r["error_status"],
            summary=None if r["summary"] is None else json.loads(r["summary"]), files=files,
        )

    # ------------------------------------------------------------ public
    def submit(self, kind: str, params: Mapping[str, Any],
               inputs: Mapping[str, bytes | Path] | None = None) -> Job:
        """Store a job's inputs on disk, then its row; returns the queued job.

        ``inputs`` maps file names (relative, inside the job's input folder) to
        bytes or to a file or folder that is moved there.
        """
        job_id = uuid.uuid4().hex
        idir = self.input_dir(job_id)
        idir.mkdir(parents=True)
        for name, value in (inputs or {}).items():
            dest = idir / name
            dest.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(value, (bytes, bytearray)):
                dest.write_bytes(value)
            else:
                shutil.move(str(value), str(dest))
        with self._lock, self._connect() as con:
            seq = con.execute("SELECT COALESCE(MAX(seq), 0) + 1 FROM jobs").fetchone()[0]
            con.execute(
                "INSERT INTO jobs (id, seq, kind, status, params, created) VALUES (?, ?, ?, 'queued', ?, ?)",
                (job_id, seq, kind, json.dumps(dict(params)), time.time()),
            )
        with self._wakeup:
            self._wakeup.notify_all()
        job = self.get(job_id)
        assert job is not None
        return job

    def get(self, job_id: str) -> Job | None:
        with self._connect() as con:
            r = con.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return None if r is None else self._row(r)

    def list(self, *, status: str | None = None, kind: str | None = None, limit: int = 100,
             offset: int = 0) -> list[Job]:
        """Jobs, newest first."""
        q, args = "SELECT * FROM jobs", list[Any]()
        conds = []
        if status:
            conds.append("status = ?")
            args.append(status)
        if kind:
            conds.append("kind = ?")
            args.append(kind)
        if conds:
            q += " WHERE " + " AND ".join(conds)
        q += " ORDER BY seq DESC LIMIT ? OFFSET ?"
        args += [limit, offset]
        with self._connect() as con:
            rows = con.execute(q, args).fetchall()
        return [self._row(r) for r in rows]

    def count(self, *, status: str | None = None, kind: str | None = None) -> int:
        conds: list[str] = []
        args: list[Any] = []
        if status:
            conds.append("status = ?")
            args.append(status)
        if kind:
            conds.append("kind = ?")
            args.append(kind)
        q = "SELECT COUNT(*) FROM jobs" + (" WHERE " + " AND ".join(conds) if conds else "")
        with self._connect() as con:
            return int(con.execute(q, args).fetchone()[0])

    def requeue_interrupted(self) -> int:
        """Put jobs found ``running`` (the process stopped under them) back in the queue; returns how many."""
        with self._lock, self._connect() as con:
            con.execute("BEGIN IMMEDIATE")
            rows = con.execute("SELECT id, attempts, cancel_requested FROM jobs WHERE status = 'running'").fetchall()
            n = 0
            for r in rows:
                if r["cancel_requested"]:
                    con.execute("UPDATE jobs SET status = 'cancelled', finished = ?, message = 'cancelled' "
                                "WHERE id = ?", (time.time(), r["id"]))
                elif r["attempts"] >= self.max_attempts:
                    con.execute(  # the message says failed, as every failed job's (not its last progress)
                        "UPDATE jobs SET status = 'failed', finished = ?, error = ?, error_field = 'job', "
                        "error_status = 500, message = 'failed' WHERE id = ?",
                        (time.time(), f"job: interrupted {r['attempts']} times; not retried", r["id"]))
                else:
                    con.execute("UPDATE jobs SET status = 'queued', progress = 0, message = 'interrupted; re-queued' "
                                "WHERE id = ?", (r["id"],))
                    n += 1
            con.execute("COMMIT")
        for r in rows:
            shutil.rmtree(self.job_dir(r["id"]) / "result.partial", ignore_errors=True)
        return n

    def remove_orphans(self) -> int:
        """Delete folders of the jobs folder that belong to no job (a stop between writing inputs and the
        row, or an upload in flight); call at start-up only.  Returns how many."""
        with self._connect() as con:
            ids = {r[0] for r in con.execute("SELECT id FROM jobs").fetchall()}
        n = 0
        for p in self.jobs_dir.iterdir():
            if p.is_dir() and p.name not in ids:
                shutil.rmtree(p, ignore_errors=True)
                n += 1
        return n

    def claim_next(self) -> Job | None:
        """Mark the oldest queued job running and return it (None when the queue is empty)."""
        with self._lock, self._connect() as con:
            con.execute("BEGIN IMMEDIATE")
            r = con.execute("SELECT id FROM jobs WHERE status = 'queued' ORDER BY seq LIMIT 1").fetchone()
            if r is None:
                con.execute("COMMIT")
                return None
            con.execute("UPDATE jobs SET status = 'running', started = ?, attempts = attempts + 1, progress = 0, "
                        "message = 'running' WHERE id = ?", (time.time(), r["id"]))
            con.execute("COMMIT")
        return self.get(r["id"])

    def set_progress(self, job_id: str, fraction: float, message: str | None = None) -> None:
        f = min(max(float(fraction), 0.0), 1.0)
        with self._connect() as con:
            if message is None:
                con.execute("UPDATE jobs SET progress = ? WHERE id = ? AND status = 'running'", (f, job_id))
            else:
                con.execute("UPDATE jobs SET progress = ?, message = ? WHERE id = ? AND status = 'running'",
                            (f, message, job_id))

    def finish(self, job_id: str, status: str, *, error: str | None = None, error_field: str | None = None,
               error_status: int | None = None, summary: Mapping[str, Any] | None = None,
               message: str | None = None) -> None:
        if status not in FINAL_STATES and status != "queued":
            raise ValueError(f"status {status!r}")
        with self._lock, self._connect() as con:
            con.execute(
                "UPDATE jobs SET status = ?, finished = ?, error = ?, error_field = ?, error_status = ?, summary = ?, "
                "progress = CASE WHEN ? = 'succeeded' THEN 1.0 ELSE progress END, message = ? WHERE id = ?",
                (status, None if status == "queued" else time.time(), error, error_field, error_status,
                 None if summary is None else json.dumps(dict(summary)), status, message or status, job_id))

    def request_cancel(self, job_id: str) -> Job | None:
        """Ask a job to stop: a queued job is cancelled at once, a running one at its next cancel check."""
        with self._lock, self._connect() as con:
            con.execute("BEGIN IMMEDIATE")
            con.execute("UPDATE jobs SET cancel_requested = 1 WHERE id = ? AND status IN ('queued', 'running')",
                        (job_id,))
            con.execute("UPDATE jobs SET status = 'cancelled', finished = ?, message = 'cancelled' "
                        "WHERE id = ? AND status = 'queued'", (time.time(), job_id))
            con.execute("COMMIT")
        return self.get(job_id)

    def cancel_requested(self, job_id: str) -> bool:
        with self._connect() as con:
            r = con.execute("SELECT cancel_requested FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return r is None or bool(r[0])

    def delete(self, job_id: str) -> bool:
        """Remove a finished job's row and files; False when there is no such job."""
        with self._lock, self._connect() as con:
            n = con.execute("DELETE FROM jobs WHERE id = ?", (job_id,)).rowcount
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
        return n > 0

    def wait_for_work(self, timeout: float) -> None:
        with self._wakeup:
            self._wakeup.wait(timeout)

    def wake_all(self) -> None:
        with self._wakeup:
            self._wakeup.notify_all()


class _Progress:
    """Adapter from the core's progress callbacks to the job row (throttled).

    Accepts ``progress(fraction)``, ``progress(done, total)`` or either followed
    by a message string.
    """

    def __init__(self, store: JobStore, job_id: str, interval_s: float = 0.25) -> None:
        self.store, self.job_id, self.interval_s = store, job_id, interval_s
        self._last = 0.0
        self._last_f = -1.0

    def __call__(self, *args: Any, **kwargs: Any) -> None:
        nums = [a for a in args if isinstance(a, (int, float)) and not isinstance(a, bool)]
        texts = [a for a in args if isinstance(a, str)]
        if len(nums) >= 2 and nums[1]:
            f = float(nums[0]) / float(nums[1])
        elif nums:
            f = float(nums[0])
        else:
            f = max(self._last_f, 0.0)
        now = time.monotonic()
        if now - self._last < self.interval_s and f < 1.0 and abs(f - self._last_f) < 0.05:
            return
        self._last, self._last_f = now, f
        self.store.set_progress(self.job_id, f, texts[0] if texts else kwargs.get("message"))


_INPUT_FAILURES: tuple[type[BaseException], ...] = (GisnoiseError, MemoryError, *UNREADABLE)
"""What a job's input can make a handler raise: the job fails with a 4xx status, not a crash."""


class WorkerPool:
    """Worker threads running queued jobs with the handler registered for their kind.

    Stopping the pool (``stop``) makes running handlers see ``cancel() == True``;
    their jobs go back to the queue rather than being cancelled, so they run
    again at the next start.
    """

    def __init__(self, store: JobStore, handlers: Mapping[str, Handler], workers: int = 1,
                 poll_s: float = 1.0) -> None:
        self.store = store
        self.handlers = dict(handlers)
        self.n_workers = workers
        self.poll_s = poll_s
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._cancel_cache: dict[str, tuple[float, bool]] = {}

    def start(self) -> None:
        self._stop.clear()
        for i in range(self.n_workers):
            t = threading.Thread(target=self._loop, name=f"gisnoise-job-{i}", daemon=True)
            t.start()
            self._threads.append(t)

    def stop(self, timeout: float = 30.0) -> None:
        self._stop.set()
        self.store.wake_all()
        for t in self._threads:
            t.join(timeout)
        self._threads.clear()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    def _loop(self) -> None:
        # jobs are background work: a small map asked for meanwhile runs first
        from gisnoise.maps.threads import background, lower_priority

        lower_priority()
        with background():
            while not self._stop.is_set():
                job = self.store.claim_next()
                if job is None:
                    self.store.wait_for_work(self.poll_s)
                    continue
                self.run(job)

    def _cancel_fn(self, job_id: str) -> Callable[[], bool]:
        last = [0.0, False]

        def cancel() -> bool:
            if self._stop.is_set():
                return True
            now = time.monotonic()
            if now - last[0] > 0.2:
                last[0], last[1] = now, self.store.cancel_requested(job_id)
            return bool(last[1])

        return cancel

    def run(self, job: Job) -> None:
        """Run one claimed job to its final state."""
        store = self.store
        jdir = store.job_dir(job.id)
        partial = jdir / "result.partial"
        shutil.rmtree(partial, ignore_errors=True)
        shutil.rmtree(store.result_dir(job.id), ignore_errors=True)
        partial.mkdir(parents=True)
        handler = self.handlers.get(job.kind)
        ctx = JobContext(job=job, input_dir=store.input_dir(job.id), output_dir=partial,
                         progress=_Progress(store, job.id), cancel=self._cancel_fn(job.id))
        try:
            if handler is None:
                raise GisnoiseError(f"no handler for job kind {job.kind!r}", field="kind")
            summary = handler(ctx)
        except Cancelled:
            shutil.rmtree(partial, ignore_errors=True)
            if self._stop.is_set() and not store.cancel_requested(job.id):
                store.finish(job.id, "queued", message="server stopped; re-queued")
                log.info("job %s interrupted by shutdown; re-queued", job.id)
            else:
                store.finish(job.id, "cancelled", message="cancelled")
            return
        except _INPUT_FAILURES as exc:
            shutil.rmtree(partial, ignore_errors=True)
            fld = getattr(exc, "field", None) or ("grid.resolution_m" if isinstance(exc, MemoryError) else
                                                  "campaign" if isinstance(exc, UNREADABLE) else "job")
            msg = str(exc) or type(exc).__name__
            if isinstance(exc, UNREADABLE):
                msg = f"{fld}: a file cannot be read ({type(exc).__name__}: {msg})"
            elif isinstance(exc, GisnoiseError):  # the detail a synchronous request would answer
                msg = core_detail(msg, fld)
            # the server's folders mean nothing to the client
            for folder in (ctx.input_dir.resolve(), ctx.input_dir):
                msg = msg.replace(str(folder), "upload")
            msg = scrub_paths(msg, [store.jobs_dir.resolve(), store.jobs_dir])
            store.finish(job.id, "failed", error=msg, error_field=fld, error_status=status_for(exc), message="failed",
                         summary=None if ctx.warnings is None else {"warnings": list(ctx.warnings)})
            return
        except Exception as exc:  # noqa: BLE001 - a job's bug must not kill the worker
            shutil.rmtree(partial, ignore_errors=True)
            log.error("job %s (%s) crashed:\n%s", job.id, job.kind, traceback.format_exc())
            store.finish(job.id, "failed", error=f"job: internal error ({type(exc).__name__})", error_field="job",
                         error_status=500, message="failed")
            return
        partial.rename(store.result_dir(job.id))
        store.finish(job.id, "succeeded", summary=dict(summary or {}), message="done")
