"""Server-side jobs: the worker pool running the jobs of the job store (:mod:`gisnoise.service.jobstore`).

Workers claim queued jobs in submission order, run the handler of the job's kind and write the result into
``result.partial/``, which is renamed to ``result/`` only when the handler returns: a result folder is always
complete.  A job that was running when the process ended uncleanly (killed, crashed) is found ``running`` at the
next start-up and re-queued (:meth:`JobStore.requeue_interrupted`); a graceful stop re-queues it at once.

A worker thread never dies of a job: whatever a handler raises ends its job (failed, with the field and status
a synchronous request would answer), and when the job's end cannot be written (the disk is full, the job
database cannot be written) it is kept and written as soon as the storage takes it, the worker retrying
meanwhile.  A job whose progress or result cannot be stored fails with the storage's reason (field ``storage``,
507 or 503).

States: ``queued`` -> ``running`` -> ``succeeded`` | ``failed`` | ``cancelled``.
"""

from __future__ import annotations

import logging
import shutil
import threading
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gisnoise.errors import Cancelled, GisnoiseError
from gisnoise.service.errors import UNREADABLE, core_detail, scrub_paths, status_for
from gisnoise.service.jobstore import FINAL_STATES, STATES, Job, JobStore
from gisnoise.service.storage import STORAGE_FIELD

__all__ = ["Job", "JobContext", "JobStore", "WorkerPool", "STATES", "FINAL_STATES", "Handler"]

log = logging.getLogger(__name__)


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



class _Run:
    """What a running job's progress and cancel callbacks met: a storage failure the handler (or the core under
    it) may have turned into another error or a cancel."""

    def __init__(self) -> None:
        self.storage_exc: BaseException | None = None


class _Progress:
    """Adapter from the core's progress callbacks to the job row (throttled).

    Accepts ``progress(fraction)``, ``progress(done, total)`` or either followed
    by a message string.  A progress that cannot be written for lack of storage is raised (the job stops) and
    kept in ``run``.
    """

    def __init__(self, store: JobStore, job_id: str, run: _Run | None = None, interval_s: float = 0.25) -> None:
        self.store, self.job_id, self.interval_s = store, job_id, interval_s
        self.run = run or _Run()
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
        try:
            self.store.set_progress(self.job_id, f, texts[0] if texts else kwargs.get("message"))
        except Exception as exc:
            if self.store.failure(exc) is not None:
                self.run.storage_exc = exc
            raise


_INPUT_FAILURES: tuple[type[BaseException], ...] = (GisnoiseError, MemoryError, *UNREADABLE)
"""What a job's input can make a handler raise: the job fails with a 4xx status, not a crash."""

Outcome = tuple[str, dict[str, Any]]
"""A job's end: its state and the other arguments of :meth:`JobStore.finish`."""


def _failed(error: str, field: str, status: int, summary: Mapping[str, Any] | None = None) -> Outcome:
    return "failed", {"error": error, "error_field": field, "error_status": status, "message": "failed",
                      "summary": summary}


def _inside(path: object, folder: Path) -> bool:
    if not isinstance(path, (str, Path)):
        return False
    p = Path(path)
    return any(p == f or f in p.parents for f in (folder, folder.resolve()))


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
        self._pending: dict[str, Outcome] = {}
        self._pending_lock = threading.Lock()
        self._requeue = False
        self._requeue_lock = threading.Lock()

    def requeue_first(self) -> None:
        """Have the workers re-queue the jobs found running (:meth:`JobStore.requeue_interrupted`) before they
        claim any job: the start-up could not (the storage refused it)."""
        self._requeue = True

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
        if not self._flush():  # left for the restart rule: found running, re-queued
            log.error("the end of %d job(s) could not be written before the stop", len(self._pending))

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    def workers(self) -> tuple[int, int]:
        """Worker threads started and alive (a worker never ends before ``stop``: fewer alive is a fault)."""
        return len(self._threads), sum(t.is_alive() for t in self._threads)

    @property
    def unwritten(self) -> list[str]:
        """Ids of the jobs that ended but whose end is not written yet (the storage refused it)."""
        with self._pending_lock:
            return list(self._pending)

    def _loop(self) -> None:
        # jobs are background work: a small map asked for meanwhile runs first
        from gisnoise.maps.threads import background, lower_priority

        lower_priority()
        with background():
            failing = 0  # consecutive rounds the job database refused
            while not self._stop.is_set():
                try:
                    if self._requeue:
                        self._requeue_interrupted()
                    job = self.store.claim_next() if self._flush() else None
                    if job is None and self._pending:
                        raise RuntimeError("the end of a job is not written yet")
                except Exception as exc:  # noqa: BLE001 - the storage failing: wait, then retry
                    failing += 1
                    if failing == 1:
                        log.error("job worker: cannot use the job database (%s: %s); retrying",
                                  type(exc).__name__, exc)
                    self._stop.wait(min(max(self.poll_s, 0.01) * 2 ** min(failing, 10), 5.0))
                    continue
                if failing:
                    log.warning("job worker: the job database works again")
                    failing = 0
                if job is None:
                    self.store.wait_for_work(self.poll_s)
                    continue
                try:
                    self.run(job)
                except Exception:  # noqa: BLE001 - run() records every end; this keeps the worker whatever
                    log.error("job %s: the worker failed around it:\n%s", job.id, traceback.format_exc())

    def _requeue_interrupted(self) -> None:
        with self._requeue_lock:  # one worker re-queues; the others wait for it, then claim
            if self._requeue:
                n = self.store.requeue_interrupted()
                self._requeue = False
                if n:
                    log.warning("%d job(s) interrupted by the last stop were re-queued", n)

    def _cancel_fn(self, job_id: str, run: _Run) -> Callable[[], bool]:
        last = [0.0, False]

        def cancel() -> bool:
            if self._stop.is_set() or run.storage_exc is not None:
                return True
            now = time.monotonic()
            if now - last[0] > 0.2:
                last[0] = now
                try:
                    last[1] = self.store.cancel_requested(job_id)
                except Exception as exc:  # noqa: BLE001 - unreadable now: the last answer holds
                    log.warning("job %s: cannot read whether it was cancelled (%s)", job_id, exc)
            return bool(last[1])

        return cancel

    def _cancel_asked(self, job_id: str) -> bool:
        try:
            return self.store.cancel_requested(job_id)
        except Exception:  # noqa: BLE001 - unreadable: not asked (a stopped job is re-queued)
            return False

    def run(self, job: Job) -> None:
        """Run one claimed job to its end and record it (:meth:`_record`)."""
        partial = self.store.job_dir(job.id) / "result.partial"
        try:
            outcome = self._execute(job, partial)
        except Exception as exc:  # noqa: BLE001 - the work around the handler (folders, rename) failed
            shutil.rmtree(partial, ignore_errors=True)
            outcome = self._failure(job, exc, None, _Run())
        self._record(job.id, outcome)

    def _execute(self, job: Job, partial: Path) -> Outcome:
        store = self.store
        run = _Run()
        ctx = JobContext(job=job, input_dir=store.input_dir(job.id), output_dir=partial,
                         progress=_Progress(store, job.id, run), cancel=self._cancel_fn(job.id, run))
        if not ctx.input_dir.is_dir():
            return _failed(f"job: the stored input of job {job.id} is missing on the server (its folder was "
                           "removed after the submission); submit the job again", "job", 500)
        shutil.rmtree(partial, ignore_errors=True)
        shutil.rmtree(store.result_dir(job.id), ignore_errors=True)
        partial.mkdir(parents=True)
        handler = self.handlers.get(job.kind)
        try:
            if handler is None:
                raise GisnoiseError(f"no handler for job kind {job.kind!r}", field="kind")
            summary = handler(ctx)
        except Cancelled as exc:
            shutil.rmtree(partial, ignore_errors=True)
            if run.storage_exc is not None:
                return self._failure(job, exc, ctx, run)
            if self._stop.is_set() and not self._cancel_asked(job.id):
                log.info("job %s interrupted by shutdown; re-queued", job.id)
                return "queued", {"message": "server stopped; re-queued"}
            return "cancelled", {"message": "cancelled"}
        except Exception as exc:  # noqa: BLE001 - a job's failure, whatever it is, ends the job only
            shutil.rmtree(partial, ignore_errors=True)
            return self._failure(job, exc, ctx, run)
        partial.rename(store.result_dir(job.id))
        return "succeeded", {"summary": dict(summary or {}), "message": "done"}

    def _failure(self, job: Job, exc: BaseException, ctx: JobContext | None, run: _Run) -> Outcome:
        """The end of a job whose handler (or the work around it) raised ``exc``."""
        store = self.store
        summary = None if ctx is None or ctx.warnings is None else {"warnings": list(ctx.warnings)}
        failure = store.failure(exc) or store.failure(run.storage_exc)
        if failure is not None:
            log.error("job %s (%s) stopped: %s", job.id, job.kind, failure.reason)
            return _failed(f"{STORAGE_FIELD}: {failure.reason}; the job stopped (submit it again once the "
                           "storage takes it)", STORAGE_FIELD, failure.status, summary)
        if isinstance(exc, _INPUT_FAILURES):
            fld = getattr(exc, "field", None) or ("grid.resolution_m" if isinstance(exc, MemoryError) else
                                                  "campaign" if isinstance(exc, UNREADABLE) else "job")
            msg = str(exc) or type(exc).__name__
            if isinstance(exc, UNREADABLE):
                msg = f"{fld}: a file cannot be read ({type(exc).__name__}: {msg})"
            elif isinstance(exc, GisnoiseError):  # the detail a synchronous request would answer
                msg = core_detail(msg, fld)
            if ctx is not None:  # the server's folders mean nothing to the client
                for folder in (ctx.input_dir.resolve(), ctx.input_dir):
                    msg = msg.replace(str(folder), "upload")
            msg = scrub_paths(msg, [store.jobs_dir.resolve(), store.jobs_dir])
            return _failed(msg, fld, status_for(exc), summary)
        if ctx is not None and isinstance(exc, FileNotFoundError) and _inside(exc.filename, ctx.input_dir):
            name = Path(str(exc.filename)).name
            return _failed(f"job: the stored input of job {job.id} is missing on the server ({name!r} was removed "
                           "after the submission); submit the job again", "job", 500, summary)
        log.error("job %s (%s) crashed:\n%s", job.id, job.kind,
                  "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))
        return _failed(f"job: internal error ({type(exc).__name__})", "job", 500)

    def _record(self, job_id: str, outcome: Outcome) -> None:
        """Write a job's end; when the storage refuses it, keep it for the worker to write later.  An end that
        cannot be written for another reason (a summary that is not JSON, say) is recorded as an internal
        error instead."""
        status, kw = outcome
        try:
            self.store.finish(job_id, status, **kw)
            return
        except Exception as exc:  # noqa: BLE001 - whatever it is, the worker goes on
            if self.store.failure(exc) is None:
                log.error("job %s: its end (%s) cannot be written:\n%s", job_id, status, traceback.format_exc())
                outcome = _failed(f"job: internal error ({type(exc).__name__})", "job", 500)
            else:
                log.error("job %s: its end (%s) cannot be written now (%s); kept until it can", job_id, status,
                          exc)
        with self._pending_lock:
            self._pending[job_id] = outcome
        self._flush()

    def _flush(self) -> bool:
        """Write the kept ends of jobs; True when none is left."""
        if not self._pending:
            return True
        with self._pending_lock:
            items = list(self._pending.items())
        for job_id, (status, kw) in items:  # written without the lock: /health reads the list meanwhile
            try:
                self.store.finish(job_id, status, **kw)
            except Exception:  # noqa: BLE001 - still refused: kept
                return False
            with self._pending_lock:
                self._pending.pop(job_id, None)
            log.warning("job %s: its end (%s) is written now", job_id, status)
        return True
