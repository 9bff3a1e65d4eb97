"""JSON in and out: one reader of input files, one checked reader of a document's fields, one writer.

Reading a JSON document from a file with one-line errors that name the file.

One reader for every kind of JSON input file (model cards, scenarios, design plans,
operation schedules), so they all refuse a missing, unreadable or malformed file the
same way.  A byte-order mark at the start is accepted.
"""

from __future__ import annotations

import builtins
import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import GisnoiseError, InputError

__all__ = ["read_json_file", "to_jsonable", "dumps", "write_json", "JsonObject", "REQUIRED"]


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


def to_jsonable(value: Any) -> Any:
    """``value`` with numpy scalars and arrays, tuples, paths and mappings turned into plain JSON types.

    Non-finite floats become ``None`` (strict JSON has no NaN); keys become strings;
    anything else unknown becomes its ``str``.  The one converter of numpy values for
    every JSON file the package writes.

    Examples
    --------
    >>> to_jsonable({"a": np.float32(1.5), 2: np.array([1, 2]), "n": float("nan"), "p": Path("x")})
    {'a': 1.5, '2': [1, 2], 'n': None, 'p': 'x'}
    """
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return str(value)


def dumps(value: Any, *, indent: int | None = None) -> str:
    """Strict JSON text of ``value`` after :func:`to_jsonable`, with a final newline.

    Examples
    --------
    >>> dumps({"x": np.int64(3)})
    '{"x": 3}\\n'
    """
    return json.dumps(to_jsonable(value), indent=indent, allow_nan=False) + "\n"


def write_json(value: Any, path: str | os.PathLike[str], *, indent: int | None = None) -> Path:
    """Write :func:`dumps` of ``value`` to ``path`` (UTF-8) through a temporary file and an atomic replace."""
    p = Path(path)
    tmp = p.with_name(f".{p.name}.tmp")
    tmp.write_text(dumps(value, indent=indent), encoding="utf-8")
    os.replace(tmp, p)
    return p


REQUIRED = object()
"""Default meaning "the field must be given"."""


class JsonObject:
    """Reads one JSON object of a document, naming fields with their dotted path in errors.

    Subclasses set :attr:`error` (the exception raised) and :attr:`what` (the
    document's name at the start of every message).
    """

    error: type[GisnoiseError] = InputError
    what: str = "document"

    def __init__(self, doc: Any, path: str, known: tuple[str, ...]) -> None:
        if not isinstance(doc, Mapping):
            where = path or self.what
            raise self.error(f"{self.what}: field '{where}' must be an object, got {doc!r}", field=where)
        self.doc, self.path = doc, path
        unknown = [k for k in doc if k not in known]
        if unknown:
            name = self.name(unknown[0])
            raise self.error(f"{self.what}: unknown field '{name}' (known: {', '.join(known)})", field=name)

    def name(self, key: str) -> str:
        """Dotted path of ``key`` in the document."""
        return f"{self.path}.{key}" if self.path else key

    def fail(self, key: str, what: str, v: Any) -> None:
        """Raise the error for field ``key``: it must be ``what``, got ``v``."""
        raise self.error(f"{self.what}: field '{self.name(key)}' must be {what}, got {v!r}", field=self.name(key))

    def get(self, key: str, default: Any = REQUIRED) -> Any:
        if key not in self.doc:
            if default is REQUIRED:
                raise self.error(f"{self.what}: missing field '{self.name(key)}'", field=self.name(key))
            return default
        return self.doc[key]

    def num(self, key: str, default: Any = REQUIRED, lo: float = -math.inf, hi: float = math.inf, *,
            lo_open: bool = False, integer: bool = False, allow_none: bool = False) -> Any:
        """A finite number in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``), int with ``integer``."""
        v = self.get(key, default)
        if v is None and allow_none:
            return None
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        if ok and integer and float(v) != int(v):
            ok = False
        if ok and (v < lo or v > hi or (lo_open and v == lo)):
            ok = False
        if not ok:
            rng = f" in {'(' if lo_open else '['}{lo:g}, {hi:g}]" if (lo > -math.inf or hi < math.inf) else ""
            self.fail(key, f"{'an integer' if integer else 'a number'}{rng}", v)
        return int(v) if integer else float(v)

    def str(self, key: str, default: Any = REQUIRED, choices: tuple[str, ...] | None = None) -> Any:
        """A non-empty string, one of ``choices`` when given."""
        v = self.get(key, default)
        if not isinstance(v, builtins.str) or not v or (choices is not None and v not in choices):
            self.fail(key, f"one of {', '.join(choices)}" if choices else "a non-empty string", v)
        return v

    def point(self, key: builtins.str, default: Any = REQUIRED) -> list[float]:
        """A point ``[east_m, north_m]`` of two finite numbers, m."""
        v = self.get(key, default)
        if (not isinstance(v, (list, tuple)) or len(v) != 2
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
            self.fail(key, "a point [east_m, north_m]", v)
        return [float(v[0]), float(v[1])]
