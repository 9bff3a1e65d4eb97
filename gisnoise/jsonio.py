"""Reading a JSON document from a file with one-line errors that name the file.

One reader for every kind of JSON input file (model cards, scenarios, design plans,
operation schedules), so they all refuse a missing, unreadable or malformed file the
same way.  A byte-order mark at the start is accepted.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from gisnoise.errors import GisnoiseError


def read_json_file(path: str | os.PathLike[str], *, what: str, error: type[GisnoiseError], field: str,
                   json_field: str | None = None) -> Any:
    """Parse the JSON file ``path``.

    Parameters
    ----------
    path : path
        The file.
    what : str
        The document's name in messages ("card", "scenario", ...).
    error : type
        The exception raised, with ``field=field``.
    field, json_field : str
        Field named by file errors and by malformed-JSON errors (default ``field``).

    Raises
    ------
    error
        ``"<path>: no such <what> file"``, ``"<path>: cannot read <what>: <reason>"`` or
        ``"<path>: malformed JSON at line L column C: <reason>"``.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise error(f"{p}: no such {what} file", field=field) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{p}: cannot read {what}: {exc}", field=field) from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{p}: malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}",
                    field=json_field or field) from None
