"""``Server-Timing: total;dur=...`` on every HTTP answer, as pure ASGI middleware.

``total`` is the time (ms) from when the application receives the request (this
middleware is the outermost one the application adds) to when its answer's head is
sent: for an answer made whole in memory (the map's GeoJSON or GeoTIFF, JSON bodies)
that is when its body is ready; for a streamed answer (static files) it is the time to
its head.  An answer that carries ``Server-Timing`` already (``POST /contours``:
``evaluate``, ``map``) gets ``total`` appended to it, so a client reads all of them
from one header.  What the client sees on top (its HTTP stack, the server's HTTP
parser, the connection) is its own latency minus ``total``.
"""

from __future__ import annotations

import time
from typing import Any

__all__ = ["ServerTiming"]

_HEADER = b"server-timing"


class ServerTiming:
    """Add ``total;dur=<ms>`` to the ``Server-Timing`` header of every HTTP answer."""

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t0 = time.perf_counter()

        async def timed_send(msg: Any) -> None:
            if msg["type"] == "http.response.start":
                entry = f"total;dur={1000 * (time.perf_counter() - t0):.1f}".encode("latin-1")
                headers = list(msg.get("headers", ()))
                for i, (k, v) in enumerate(headers):
                    if k.lower() == _HEADER:
                        headers[i] = (k, v + b", " + entry)
                        break
                else:
                    headers.append((_HEADER, entry))
                msg = {**msg, "headers": headers}
            await send(msg)

        await self.app(scope, receive, timed_send)
