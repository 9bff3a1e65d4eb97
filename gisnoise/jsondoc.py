"""Checked reading of JSON input documents (scenarios, design plans).

Kernel shared by :mod:`gisnoise.simulate.simulate` and :mod:`gisnoise.design.design`: a reader of one
JSON object that names every bad field with its dotted path, and the resolution of
a model-card reference (file, bundled card name or card object).  Each document
kind subclasses :class:`JsonObject` with its error class and the word its messages
start with (``"scenario: field 'x' ..."``, ``"plan: field 'x' ..."``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gisnoise.data import card_path
from gisnoise.errors import GisnoiseError, InputError
from gisnoise.model import cards as _cards

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
        if not isinstance(v, str) or not v or (choices is not None and v not in choices):
            self.fail(key, f"one of {', '.join(choices)}" if choices else "a non-empty string", v)
        return v

    def point(self, key: str, default: Any = REQUIRED) -> list[float]:
        """A point ``[east_m, north_m]`` of two finite numbers, m."""
        v = self.get(key, default)
        if (not isinstance(v, (list, tuple)) or len(v) != 2
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
            self.fail(key, "a point [east_m, north_m]", v)
        return [float(v[0]), float(v[1])]




def load_card(ref: Any, fld: str, base_dir: Path | None, reader: type[JsonObject]) -> _cards.ModelCard:
    """The model card a document's field ``fld`` names.

    ``ref`` is a card object (mapping), a card file (``.json`` or a path; relative to
    ``base_dir``) or the name of a bundled card (:func:`gisnoise.data.card_path`).  Errors are
    ``reader.error`` naming ``fld``, with messages starting ``reader.what``.
    """
    error, what = reader.error, reader.what
    try:
        if isinstance(ref, Mapping):
            return _cards.from_dict(ref, source=f"{what} field '{fld}'")
        if not isinstance(ref, str) or not ref:
            raise error(f"{what}: field '{fld}' must be a card file, a bundled card name or a card object, "
                        f"got {ref!r}", field=fld)
        if ref.endswith(".json") or "/" in ref or os.sep in ref:
            p = Path(ref)
            if not p.is_absolute() and base_dir is not None:
                p = base_dir / p
        else:
            try:
                p = card_path(ref)
            except KeyError:
                raise error(f"{what}: field '{fld}': no bundled card {ref!r}", field=fld) from None
        return _cards.load(p)
    except error:
        raise
    except InputError as exc:
        raise error(f"{what}: field '{fld}': {exc}", field=fld) from None
