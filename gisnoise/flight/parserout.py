"""What log parsers print, kept off the user's stdout without silencing other threads.

pyulog prints what it finds corrupt and pymavlink prints on bad data; neither belongs on the
user's stdout (a command's output, a service's log).  :func:`contextlib.redirect_stdout` would
keep them off, but it swaps ``sys.stdout`` for the whole process: in the service, where logs are
read in worker threads, another thread's output in that moment would be lost.
:func:`captured_stdout` captures only the calling thread's writes: while any thread captures,
``sys.stdout`` is a proxy that sends each write to the writing thread's capture, or, for a thread
that captures nothing, to the stream that was ``sys.stdout`` before.

>>> import threading
>>> with captured_stdout() as said:
...     print("pyulog: corrupt data")
...     t = threading.Thread(target=print, args=("another thread",))
...     t.start(); t.join()
another thread
>>> said.getvalue()
'pyulog: corrupt data\\n'
"""

from __future__ import annotations

import contextlib
import io
import sys
import threading
from collections.abc import Iterator
from typing import Any, TextIO

__all__ = ["captured_stdout"]

_lock = threading.Lock()
_local = threading.local()
_active = 0
_proxy: _ThreadStdout | None = None


class _ThreadStdout(io.TextIOBase):
    """``sys.stdout`` while a thread captures: each write goes to its thread's capture, else to ``base``."""

    def __init__(self, base: TextIO) -> None:
        self._base = base

    def _target(self) -> TextIO:
        buf = getattr(_local, "buf", None)
        return buf if buf is not None else self._base

    def write(self, s: str) -> int:
        return self._target().write(s)

    def flush(self) -> None:
        self._target().flush()

    def writable(self) -> bool:
        return True

    def __getattr__(self, name: str) -> Any:  # encoding, fileno, isatty, ... of the stream behind
        return getattr(self._base, name)


@contextlib.contextmanager
def captured_stdout() -> Iterator[io.StringIO]:
    """Capture what the calling thread writes to ``sys.stdout`` into the yielded buffer; other threads' writes
    go where they went before.  Nests; the proxy is removed when the last capture ends (unless something
    else replaced ``sys.stdout`` meanwhile, which is then left in place)."""
    global _active, _proxy
    buf = io.StringIO()
    outer = getattr(_local, "buf", None)
    with _lock:
        if _active == 0:
            _proxy = _ThreadStdout(sys.stdout)
            sys.stdout = _proxy
        _active += 1
    _local.buf = buf
    try:
        yield buf
    finally:
        _local.buf = outer
        with _lock:
            _active -= 1
            if _active == 0:
                if sys.stdout is _proxy and _proxy is not None:
                    sys.stdout = _proxy._base
                _proxy = None
