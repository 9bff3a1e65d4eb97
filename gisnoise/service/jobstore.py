"""The job table (SQLite) and the job folders on disk.

A job is written to disk (its folder ``<jobs_dir>/<id>/input``) and to the database *before* its submission is
answered, so nothing submitted is lost; a submission the storage cannot hold (a full disk) leaves nothing
behind.  A job found ``running`` at start-up ended uncleanly (the process was killed or crashed): it is
re-queued and run again from its inputs, and after ``max_attempts`` unclean ends it fails instead of looping.
A graceful stop re-queues its running job itself (:class:`gisnoise.service.jobs.WorkerPool`); that end is clean
and does not count.

The store remembers whether its last write failed for lack of storage (:attr:`JobStore.write_failure`), which
``/health`` reports until a write succeeds again.

States: ``queued`` -> ``running`` -> ``succeeded`` | ``failed`` | ``cancelled``.
"""

from __future__ import annotations

import json
import shutil
import sqlite3
import threading
import time
import uuid
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gisnoise.service.storage import StorageFailure, storage_error, storage_failure

__all__ = ["Job", "JobStore", "STATES", "FINAL_STATES"]

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
    summary TEXT,
    crashes INTEGER NOT NULL DEFAULT 0
);
CREATE INDEX IF NOT EXISTS jobs_status_seq ON jobs (status, seq);
CREATE TABLE IF NOT EXISTS write_check (id INTEGER PRIMARY KEY CHECK (id = 1), t REAL NOT NULL);
"""
# crashes: the unclean ends of the job (found running at start-up); attempts: its starts


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
    result_missing: bool = False
    """A succeeded job whose result folder is no longer on the server (removed after the job ended)."""

    @property
    def done(self) -> bool:
        return self.status in FINAL_STATES


class JobStore:
    """The job table (SQLite) and the job folders.

    Parameters
    ----------
    db_path : path
        SQLite database file (created).
    jobs_dir : path
        Folder of the job folders (created).
    max_attempts : int
        Unclean ends of a job (found running at start-up) before it is failed; a graceful stop's re-queue does
        not count.
    """

    def __init__(self, db_path: str | Path, jobs_dir: str | Path, *, max_attempts: int = 3) -> None:
        self.db_path = Path(db_path)
        self.jobs_dir = Path(jobs_dir)
        self.max_attempts = max_attempts
        self.db_path.parent.mkdir(parents=True, exist_ok=True)
        self.jobs_dir.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._wakeup = threading.Condition()
        self.write_failure: StorageFailure | None = None
        """The storage failure of the last write, None once a write succeeded (or before any failed)."""
        with self._connect() as con:
            con.execute("PRAGMA journal_mode=WAL")
            con.executescript(_SCHEMA)
            cols = {r["name"] for r in con.execute("PRAGMA table_info(jobs)").fetchall()}
            if "crashes" not in cols:  # a database of an older release
                con.execute("ALTER TABLE jobs ADD COLUMN crashes INTEGER NOT NULL DEFAULT 0")

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

    @contextmanager
    def _write(self) -> Iterator[sqlite3.Connection]:
        """A connection for a write: a storage failure is remembered (:attr:`write_failure`), a success clears
        it."""
        try:
            with self._connect() as con:
                yield con
        except Exception as exc:
            failure = self.failure(exc)
            if failure is not None:
                self.write_failure = failure
            raise
        self.write_failure = None

    def failure(self, exc: BaseException | None) -> StorageFailure | None:
        """The storage failure ``exc`` is (:func:`storage_failure`, judged by the device of the store)."""
        return storage_failure(exc, near=self.db_path.parent)

    def job_dir(self, job_id: str) -> Path:
        return self.jobs_dir / job_id

    def input_dir(self, job_id: str) -> Path:
        return self.job_dir(job_id) / "input"

    def result_dir(self, job_id: str) -> Path:
        return self.job_dir(job_id) / "result"

    def _row(self, r: sqlite3.Row) -> Job:
        rdir = self.result_dir(r["id"])
        files: tuple[str, ...] = ()
        missing = False
        if r["status"] == "succeeded":
            if rdir.is_dir():
                files = tuple(sorted(str(p.relative_to(rdir)) for p in rdir.rglob("*") if p.is_file()))
            else:
                missing = True
        return Job(
            id=r["id"], kind=r["kind"], status=r["status"], progress=float(r["progress"]), message=r["message"],
            params=json.loads(r["params"]), created=r["created"], started=r["started"], finished=r["finished"],
            attempts=int(r["attempts"]), cancel_requested=bool(r["cancel_requested"]), error=r["error"],
            error_field=r["error_field"], error_status=r["error_status"],
            summary=None if r["summary"] is None else json.loads(r["summary"]), files=files, result_missing=missing,
        )

    # ------------------------------------------------------------ public
    def submit(self, kind: str, params: Mapping[str, Any],
               inputs: Mapping[str, bytes | Path] | None = None) -> Job:
        """Store a job's inputs on disk, then its row; returns the queued job.

        ``inputs`` maps file names (relative, inside the job's input folder) to bytes or to a file or folder
        that is moved there.  When the storage cannot hold them (no space left, the database cannot be written),
        the job's folder is removed and the error raised names the storage (507 or 503): nothing is queued.
        """
        job_id = uuid.uuid4().hex
        idir = self.input_dir(job_id)
        try:
            idir.mkdir(parents=True)
            for name, value in (inputs or {}).items():
                dest = idir / name
                dest.parent.mkdir(parents=True, exist_ok=True)
                if isinstance(value, (bytes, bytearray)):
                    dest.write_bytes(value)
                else:
                    shutil.move(str(value), str(dest))
            with self._lock, self._write() as con:
                seq = con.execute("SELECT COALESCE(MAX(seq), 0) + 1 FROM jobs").fetchone()[0]
                con.execute(
                    "INSERT INTO jobs (id, seq, kind, status, params, created) VALUES (?, ?, ?, 'queued', ?, ?)",
                    (job_id, seq, kind, json.dumps(dict(params)), time.time()),
                )
        except Exception as exc:
            shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
            failure = self.failure(exc)
            if failure is not None:
                raise storage_error(failure, "the job was not queued") from None
            raise
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
        where, args = _where(status, kind)
        q = "SELECT * FROM jobs" + where + " ORDER BY seq DESC LIMIT ? OFFSET ?"
        args += [limit, offset]
        with self._connect() as con:
            rows = con.execute(q, args).fetchall()
        return [self._row(r) for r in rows]

    def count(self, *, status: str | None = None, kind: str | None = None) -> int:
        where, args = _where(status, kind)
        q = "SELECT COUNT(*) FROM jobs" + where
        with self._connect() as con:
            return int(con.execute(q, args).fetchone()[0])

    def counts(self) -> dict[str, int]:
        """Jobs per state (every state, 0 when none), in one read."""
        out = dict.fromkeys(STATES, 0)
        with self._connect() as con:
            for r in con.execute("SELECT status, COUNT(*) FROM jobs GROUP BY status").fetchall():
                out[r[0]] = int(r[1])
        return out

    def check_writable(self) -> StorageFailure | None:
        """After a failed write (:attr:`write_failure`), try a small write: None when it succeeds (the failure is
        cleared), else the failure.  Without a failed write nothing is written (None)."""
        if self.write_failure is None:
            return None
        try:
            with self._write() as con:
                con.execute("INSERT OR REPLACE INTO write_check (id, t) VALUES (1, ?)", (time.time(),))
        except Exception as exc:  # noqa: BLE001 - reported, whatever it is
            return self.failure(exc) or self.write_failure
        return None

    def requeue_interrupted(self) -> int:
        """Put jobs found ``running`` (the process ended under them: killed, crashed) back in the queue, their
        progress and start time reset; a job found so for the ``max_attempts``-th time fails instead.  Returns
        how many were re-queued."""
        with self._lock, self._write() as con:
            con.execute("BEGIN IMMEDIATE")
            rows = con.execute("SELECT id, crashes, cancel_requested FROM jobs WHERE status = 'running'").fetchall()
            n = 0
            for r in rows:
                crashes = int(r["crashes"]) + 1
                if r["cancel_requested"]:
                    con.execute("UPDATE jobs SET status = 'cancelled', finished = ?, message = 'cancelled', "
                                "crashes = ? WHERE id = ?", (time.time(), crashes, r["id"]))
                elif crashes >= self.max_attempts:
                    con.execute(  # the message says failed, as every failed job's (not its last progress)
                        "UPDATE jobs SET status = 'failed', finished = ?, error = ?, error_field = 'job', "
                        "error_status = 500, message = 'failed', crashes = ? WHERE id = ?",
                        (time.time(), f"job: interrupted {crashes} times; not retried", crashes, r["id"]))
                else:
                    con.execute("UPDATE jobs SET status = 'queued', progress = 0, started = NULL, "
                                "message = 'interrupted; re-queued', crashes = ? WHERE id = ?", (crashes, r["id"]))
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
        """Mark the oldest queued job running and return it (None when the queue is empty).

        The row returned is read in the claiming transaction: a job is never left running unseen by its worker.
        """
        with self._lock, self._write() as con:
            con.execute("BEGIN IMMEDIATE")
            r = con.execute("SELECT id FROM jobs WHERE status = 'queued' ORDER BY seq LIMIT 1").fetchone()
            if r is None:
                con.execute("COMMIT")
                return None
            con.execute("UPDATE jobs SET status = 'running', started = ?, attempts = attempts + 1, progress = 0, "
                        "message = 'running' WHERE id = ?", (time.time(), r["id"]))
            row = con.execute("SELECT * FROM jobs WHERE id = ?", (r["id"],)).fetchone()
            con.execute("COMMIT")
        return self._row(row)

    def set_progress(self, job_id: str, fraction: float, message: str | None = None) -> None:
        f = min(max(float(fraction), 0.0), 1.0)
        with self._write() as con:
            if message is None:
                con.execute("UPDATE jobs SET progress = ? WHERE id = ? AND status = 'running'", (f, job_id))
            else:
                con.execute("UPDATE jobs SET progress = ?, message = ? WHERE id = ? AND status = 'running'",
                            (f, message, job_id))

    def finish(self, job_id: str, status: str, *, error: str | None = None, error_field: str | None = None,
               error_status: int | None = None, summary: Mapping[str, Any] | None = None,
               message: str | None = None) -> None:
        """Write a job's end: a final state, or ``queued`` again (a graceful stop), which resets its progress and
        start time as a job that never ran."""
        if status not in FINAL_STATES and status != "queued":
            raise ValueError(f"status {status!r}")
        with self._lock, self._write() as con:
            if status == "queued":
                con.execute("UPDATE jobs SET status = 'queued', started = NULL, finished = NULL, progress = 0, "
                            "error = NULL, error_field = NULL, error_status = NULL, summary = NULL, message = ? "
                            "WHERE id = ?", (message or status, job_id))
                return
            con.execute(
                "UPDATE jobs SET status = ?, finished = ?, error = ?, error_field = ?, error_status = ?, summary = ?, "
                "progress = CASE WHEN ? = 'succeeded' THEN 1.0 ELSE progress END, message = ? WHERE id = ?",
                (status, time.time(), error, error_field, error_status,
                 None if summary is None else json.dumps(dict(summary)), status, message or status, job_id))

    def request_cancel(self, job_id: str) -> Job | None:
        """Ask a job to stop: a queued job is cancelled at once, a running one at its next cancel check."""
        with self._lock, self._write() as con:
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
        with self._lock, self._write() as con:
            n = con.execute("DELETE FROM jobs WHERE id = ?", (job_id,)).rowcount
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
        return n > 0

    def wait_for_work(self, timeout: float) -> None:
        with self._wakeup:
            self._wakeup.wait(timeout)

    def wake_all(self) -> None:
        with self._wakeup:
            self._wakeup.notify_all()


def _where(status: str | None, kind: str | None) -> tuple[str, list[Any]]:
    """The ``WHERE`` clause (with its leading blank; empty without a condition) and arguments of a jobs query."""
    conds = [c for c, v in (("status = ?", status), ("kind = ?", kind)) if v]
    return (" WHERE " + " AND ".join(conds) if conds else ""), [v for v in (status, kind) if v]
