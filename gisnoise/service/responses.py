"""JSON responses written as ASCII: any string a client sent (lone surrogates included) can be echoed."""

from __future__ import annotations

import json
from typing import Any

from fastapi.responses import JSONResponse

__all__ = ["AsciiJSONResponse"]


class AsciiJSONResponse(JSONResponse):
    """``application/json`` with non-ASCII escaped (``\\uXXXX``), so it always encodes."""

    def render(self, content: Any) -> bytes:
        return json.dumps(content, ensure_ascii=True, allow_nan=False, separators=(",", ":")).encode("ascii")
