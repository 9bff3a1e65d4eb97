"""Request-size limit as pure ASGI middleware: 413 naming the body before it is read whole."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

from starlette.exceptions import HTTPException

__all__ = ["BodySizeLimit", "KeyBeforeBody"]

Scope = dict[str, Any]


class _TooLarge(HTTPException):
    """Raised inside the app while it reads the body, so the error handlers answer 413."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, f"body: request body exceeds the limit of {limit} bytes")


class KeyBeforeBody:
    """Refuse a write without a valid ``X-API-Key`` from its headers, before a byte of its body is read.

    ``refusal(method, path, query string, key)`` returns ``(status, message, extra headers)`` or None.
    """

    def __init__(self, app: Any,
                 refusal: Callable[[str, str, str, str | None], tuple[int, str, dict[str, str]] | None]) -> None:
        self.app = app
        self.refusal = refusal

    async def __call__(self, scope: Scope, receive: Any, send: Any) -> None:
        if scope["type"] == "http":
            key = next((v.decode("latin-1") for k, v in scope.get("headers", []) if k == b"x-api-key"), None)
            query = scope.get("query_string", b"").decode("latin-1")
            no = self.refusal(scope.get("method", ""), scope.get("path", ""), query, key)
            if no is not None:
                status, message, headers = no
                body = json.dumps({"detail": message, "field": "X-API-Key"}).encode()
                hdrs = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                        (b"connection", b"close")] + [(k.lower().encode(), v.encode()) for k, v in headers.items()]
                await send({"type": "http.response.start", "status": status, "headers": hdrs})
                await send({"type": "http.response.body", "body": body})
                return
        await self.app(scope, receive, send)


class BodySizeLimit:
    """Refuse request bodies above ``limit_for(path)`` bytes with 413.

    A declared ``Content-Length`` is checked before anything is read; a chunked
    body is counted as it arrives.
    """

    def __init__(self, app: Any, limit_for: Callable[[str], int]) -> None:
        self.app = app
        self.limit_for = limit_for

    async def __call__(self, scope: Scope, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = self.limit_for(scope.get("path", ""))
        for k, v in scope.get("headers", []):
            if k == b"content-length":
                try:
                    n = int(v)
                except ValueError:
                    await self._reject(send, "body: Content-Length is not a number", 400)
                    return
                if n > limit:
                    await self._reject(send, f"body: request body of {n} bytes exceeds the limit of {limit} bytes")
                    return
        seen = 0
        started = False

        async def limited_receive() -> Any:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > limit:
                    raise _TooLarge(limit)
            return msg

        async def tracking_send(msg: Any) -> None:
            nonlocal started
            if msg["type"] == "http.response.start":
                started = True
            await send(msg)

        try:
            await self.app(scope, limited_receive, tracking_send)
        except _TooLarge:
            if not started:
                await self._reject(send, f"body: request body exceeds the limit of {limit} bytes")

    @staticmethod
    async def _reject(send: Any, message: str, status: int = 413) -> None:
        body = json.dumps({"detail": message, "field": "body"}).encode()
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})
