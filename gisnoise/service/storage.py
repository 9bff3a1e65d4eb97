"""Failures of the service's own storage: the data folder's device and the job database.

A full disk, a device failing or a folder that became read-only is not a fault of the request: it is told in
one line naming the storage, 507 Insufficient Storage when the device has no space left, 503 when the storage
cannot be read or written for another reason (:func:`storage_failure`).  Every other exception is not a
storage failure (None).
"""

from __future__ import annotations

import errno
import logging
import os
import shutil
import sqlite3
import uuid
from dataclasses import dataclass
from pathlib import Path

from fastapi import FastAPI, Request, Response

from gisnoise.errors import InputError
from gisnoise.service.errors import ApiError, error_body
from gisnoise.service.responses import AsciiJSONResponse as JSONResponse

__all__ = ["StorageFailure", "storage_failure", "storage_error", "NO_SPACE", "check_data_dir", "DataDirError",
           "STORAGE_FIELD", "install_storage_handlers", "LOW_SPACE_BYTES", "free_bytes"]

log = logging.getLogger(__name__)

NO_SPACE = "no space left on the device"
"""The words every 'disk full' reason starts with."""

STORAGE_FIELD = "storage"
"""The ``field`` of a storage failure's error body: the server's storage, not a field of the request."""

_NO_SPACE_ERRNOS = {errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)}
_UNWRITABLE_ERRNOS = {errno.EROFS, errno.EACCES, errno.EPERM}


@dataclass(frozen=True)
class StorageFailure:
    """What went wrong with the storage: the HTTP status (507 or 503) and the one-line reason."""

    status: int
    reason: str

    @property
    def no_space(self) -> bool:
        return self.status == 507


def _one(exc: BaseException) -> StorageFailure | None:
    if isinstance(exc, sqlite3.OperationalError) or type(exc) is sqlite3.DatabaseError:
        said = str(exc) or type(exc).__name__
        low = said.lower()
        if "full" in low:  # SQLITE_FULL: 'database or disk is full'
            return StorageFailure(507, f"{NO_SPACE}: cannot write the job database ({said})")
        if "readonly" in low or "read-only" in low:
            return StorageFailure(503, f"cannot write the job database ({said})")
        return StorageFailure(503, f"cannot read or write the job database ({said})")
    if isinstance(exc, OSError) and exc.errno is not None:
        said = exc.strerror or os.strerror(exc.errno)
        if exc.errno in _NO_SPACE_ERRNOS:
            return StorageFailure(507, f"{NO_SPACE} holding the service's data ({said})")
        if exc.errno == errno.EIO:
            return StorageFailure(503, f"the device holding the service's data fails ({said})")
        if exc.errno in _UNWRITABLE_ERRNOS:
            return StorageFailure(503, f"the service's data folder cannot be written ({said})")
    return None


LOW_SPACE_BYTES = 1 << 20
"""Free space (1 MiB) below which the data folder's device counts as full."""


def free_bytes(folder: Path) -> int | None:
    """Space left on the device of ``folder`` for the service, bytes (None when it cannot be told)."""
    try:
        return shutil.disk_usage(folder).free
    except OSError:
        return None


def storage_failure(exc: BaseException | None, near: Path | None = None) -> StorageFailure | None:
    """The storage failure ``exc`` is, or one it was raised from (its cause or context, e.g. a core error
    raised while writing a result file on a full disk); None when it is none.

    ``near``: the folder of the storage.  SQLite says 'disk I/O error' when its journal cannot grow on a full
    disk: a failure found while that folder's device has less than :data:`LOW_SPACE_BYTES` free is said to be
    no space left (507).
    """
    seen: set[int] = set()
    found = None
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        found = _one(exc)
        if found is not None:
            break
        exc = exc.__cause__ or exc.__context__
    if found is not None and not found.no_space and near is not None:
        free = free_bytes(near)
        if free is not None and free < LOW_SPACE_BYTES:
            return StorageFailure(507, f"{NO_SPACE} ({free} bytes free): {found.reason}")
    return found


def storage_error(failure: StorageFailure, what: str = "") -> ApiError:
    """The error answered for a storage failure: ``storage: <reason>[; <what>]``, field ``storage``, 507 or 503
    (a 503 with ``Retry-After``)."""
    headers = None if failure.no_space else {"Retry-After": "30"}
    return ApiError(failure.status, f"{STORAGE_FIELD}: {failure.reason}{'; ' + what if what else ''}",
                    field=STORAGE_FIELD, headers=headers)


class DataDirError(InputError):
    """The data folder cannot be used (it cannot be created or written); ``gisnoise serve`` prints it in one
    line."""


def check_data_dir(data_dir: Path) -> None:
    """Create ``data_dir`` when missing and write (then remove) a file in it; the job database, when there is
    one, must be writable too.

    Raises
    ------
    DataDirError
        One line naming the folder (or the database) and that it cannot be written, with the system's reason.
    """
    try:
        data_dir.mkdir(parents=True, exist_ok=True)
        probe = data_dir / f".write-check-{uuid.uuid4().hex}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        said = exc.strerror or type(exc).__name__
        raise DataDirError(f"the data folder {data_dir} cannot be written ({said}); the service keeps its cards, "
                           "job database and job files there: give a writable folder (--data-dir, GISNOISE_DATA_DIR)",
                           field="GISNOISE_DATA_DIR") from None
    for name in ("jobs.sqlite3", "jobs.sqlite3-wal", "jobs.sqlite3-shm"):
        p = data_dir / name
        if p.exists() and not os.access(p, os.R_OK | os.W_OK):
            raise DataDirError(f"the job database {p} in the data folder {data_dir} cannot be written "
                               "(Permission denied): make it writable or give another folder",
                               field="GISNOISE_DATA_DIR")


def install_storage_handlers(app: FastAPI) -> None:
    """Answer a storage failure raised by any operation in one line naming the storage (507 or 503, field
    ``storage``) instead of a 500 "internal error"; other file system and database errors stay 500.

    Registered for ``OSError`` and ``sqlite3.Error`` themselves (not for ``Exception``), so they are answered
    in the application's exception layer and the connection is kept open.
    """

    async def _storage(request: Request, exc: Exception) -> Response:
        st = getattr(app.state, "gisnoise", None)
        failure = storage_failure(exc, near=None if st is None else st.settings.data_dir)
        if failure is None:
            log.error("%s %s crashed", request.method, request.url.path, exc_info=exc)
            fld = getattr(exc, "field", None) or "request"
            return JSONResponse(error_body(f"{fld}: internal error ({type(exc).__name__})", fld), status_code=500)
        log.error("%s %s: %s", request.method, request.url.path, failure.reason)
        err = storage_error(failure, "nothing was stored" if request.method not in ("GET", "HEAD") else "")
        return JSONResponse(error_body(str(err), err.field), status_code=err.status, headers=err.headers)

    app.add_exception_handler(OSError, _storage)
    app.add_exception_handler(sqlite3.Error, _storage)
