"""Model cards: versioned JSON documents holding a fitted (or published) model.

A card names its ansatz, phase, parameters (in the ansatz's order), covariance,
reference power and distance, fit statistics, provenance and notes.  ``loads``
and ``dumps`` are symmetric; unknown schema versions are refused.

Examples
--------
>>> card = ModelCard(id="demo", vehicle="x", phase="horizontal", ansatz="paper",
...                  parameters={"p1": 13.4, "p2": 0.18, "p3": -0.28, "p4": -0.37,
...                              "p5": 1.05, "p6": 0.94, "p7": 40.4},
...                  reference_power_w=1500.0)
>>> loads(dumps(card)) == card
True
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise import jsonio
from gisnoise.data import bundled_card_ids, card_path
from gisnoise.errors import CardError, InputError, SchemaVersionError
from gisnoise.flight import PHASES
from gisnoise.jsonio import JsonObject, read_json_file
from gisnoise.model.ansatz import REFERENCE_DISTANCE_M, Ansatz
from gisnoise.model.effects import get_ansatz
from gisnoise.model.plausibility import check_card

__all__ = ["ModelCard", "SCHEMA", "PHASES", "load", "loads", "dump", "dumps", "save", "card_of_field", "from_dict",
           "with_parameters", "register_card_schema"]

SCHEMA = "gisnoise/model-card/1"
SCHEMA_PREFIX = "gisnoise/model-card/"
SUPPORTED_VERSIONS = (1,)

_CARD_KINDS: dict[str, Any] = {}
"""Further card kinds by their exact ``schema``: ``reader(doc, source=...) -> ModelCard`` (a subclass)."""


def register_card_schema(schema: str, reader: Any) -> None:
    """Let :func:`from_dict` (and so :func:`load`, :func:`loads`) read documents of ``schema`` with ``reader``."""
    _CARD_KINDS[schema] = reader


@dataclass(frozen=True)
class ModelCard:
    """A model card (see module docstring).  Frozen; use :func:`dataclasses.replace`."""

    id: str
    vehicle: str
    phase: str
    ansatz: str
    parameters: Mapping[str, float]
    reference_power_w: float
    reference_distance_m: float = REFERENCE_DISTANCE_M
    covariance: tuple[tuple[float, ...], ...] | None = None
    statistics: Mapping[str, Any] = field(default_factory=dict)
    provenance: Mapping[str, Any] = field(default_factory=dict)
    notes: str = ""
    phases: tuple[str, ...] = ()
    """Further phases this card serves besides ``phase`` (e.g. ``transition``)."""

    def __post_init__(self) -> None:
        _validate(self)

    # ------------------------------------------------------------------ model
    @property
    def model(self) -> Ansatz:
        """The card's ansatz from the registry."""
        return get_ansatz(self.ansatz)

    @property
    def p(self) -> np.ndarray:
        """Parameter vector in the ansatz's order."""
        return np.array([self.parameters[k] for k in self.model.params], dtype=float)

    @property
    def cov(self) -> np.ndarray | None:
        """Covariance matrix as an array, or None."""
        return None if self.covariance is None else np.array(self.covariance, dtype=float)

    @property
    def std(self) -> dict[str, float] | None:
        """Standard deviation of each parameter from the covariance, or None."""
        c = self.cov
        if c is None:
            return None
        return {k: float(math.sqrt(max(c[i, i], 0.0))) for i, k in enumerate(self.model.params)}

    @property
    def background_db(self) -> float | None:
        b = self.model.background
        return None if b is None else float(self.parameters[b])

    @property
    def served_phases(self) -> tuple[str, ...]:
        return (self.phase,) + tuple(p for p in self.phases if p != self.phase)

    def inputs(self, d: Any, phi: Any, theta: Any, power_w: Any, **extra: Any) -> dict[str, Any]:
        """Model inputs from distance (m), angles (rad) and electric power (W)."""
        x = {"d": d, "phi": phi, "theta": theta, "p_el": np.asarray(power_w, dtype=float) / self.reference_power_w}
        x.update(extra)
        return x

    def level_uav(self, x: Mapping[str, Any]) -> np.ndarray:
        """``L_UAV`` dB(A) for model inputs ``x`` (background excluded)."""
        return self.model.level_uav(self.p, x, d_ref=self.reference_distance_m)

    def level(self, x: Mapping[str, Any], *, background: bool = True) -> np.ndarray:
        """Level with the background term (Eq. 8) unless ``background=False``."""
        return self.model.level(self.p, x, background=background, d_ref=self.reference_distance_m)

    # ------------------------------------------------------------------ io
    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["parameters"] = {k: float(v) for k, v in self.parameters.items()}
        d["covariance"] = None if self.covariance is None else [list(r) for r in self.covariance]
        d["phases"] = list(self.phases)
        d["statistics"] = dict(self.statistics)
        d["provenance"] = dict(self.provenance)
        return {"schema": SCHEMA, **d}


def _fail(msg: str, fld: str) -> None:
    raise CardError(f"model card: {msg}", field=fld)


def _check_card_identity(card: Any, kind: str = "model card") -> None:
    """The fields every card kind shares: ``id``, ``vehicle``, ``phase`` (non-empty strings) and
    ``phase``/``phases`` among the flight phases; :class:`CardError` naming the field, the message
    starting with ``kind``."""
    for name in ("id", "vehicle", "phase"):
        v = getattr(card, name)
        if not isinstance(v, str) or not v:
            raise CardError(f"{kind}: field '{name}' must be a non-empty string, got {v!r}", field=name)
    if card.phase not in PHASES:
        raise CardError(f"{kind}: field 'phase' must be one of {', '.join(PHASES)}, got {card.phase!r}",
                        field="phase")
    for ph in card.phases:
        if ph not in PHASES:
            raise CardError(f"{kind}: field 'phases' has unknown phase {ph!r}", field="phases")


def _validate(card: ModelCard) -> None:
    _check_card_identity(card)
    if not isinstance(card.ansatz, str) or not card.ansatz:
        _fail(f"field 'ansatz' must be a non-empty string, got {card.ansatz!r}", "ansatz")
    try:
        model = get_ansatz(card.ansatz)
    except Exception as exc:  # noqa: BLE001 - re-raised with the field named
        raise CardError(f"model card: field 'ansatz': {exc}", field="ansatz") from None
    if not isinstance(card.parameters, Mapping):
        _fail("field 'parameters' must be an object of name -> number", "parameters")
    missing = [k for k in model.params if k not in card.parameters]
    extra = [k for k in card.parameters if k not in model.params]
    if missing:
        _fail(f"field 'parameters' lacks {', '.join(missing)} for ansatz {card.ansatz!r}", "parameters")
    if extra:
        _fail(f"field 'parameters' has {', '.join(extra)} unknown to ansatz {card.ansatz!r}", "parameters")
    for k, v in card.parameters.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            _fail(f"parameter '{k}' must be a finite number, got {v!r}", f"parameters.{k}")
    for name in ("reference_power_w", "reference_distance_m"):
        v = getattr(card, name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            _fail(f"field '{name}' must be a positive number, got {v!r}", name)
    if card.covariance is not None:
        n = model.n_params
        try:
            c = np.array(card.covariance, dtype=float)
        except (TypeError, ValueError):
            _fail("field 'covariance' must be a matrix of numbers or null", "covariance")
        if c.shape != (n, n):
            _fail(f"field 'covariance' must be {n}x{n} for ansatz {card.ansatz!r}, got shape {c.shape}", "covariance")
        if not np.all(np.isfinite(c)):
            _fail("field 'covariance' has non-finite entries", "covariance")
        if not np.allclose(c, c.T, rtol=1e-6, atol=1e-12):
            _fail("field 'covariance' is not symmetric", "covariance")
        if np.any(np.diag(c) < 0):
            _fail("field 'covariance' has a negative variance", "covariance")
    if not isinstance(card.notes, str):
        _fail("field 'notes' must be a string", "notes")


def from_dict(doc: Mapping[str, Any], *, source: str = "model card", force: bool = False) -> ModelCard:
    """Build a card from a parsed JSON object, checking the schema version and, unless ``force``
    (inspection only), its plausibility (:func:`gisnoise.model.plausibility.check_card`)."""
    if not isinstance(doc, Mapping):
        raise CardError(f"{source}: expected a JSON object", field="schema")
    schema = doc.get("schema")
    if isinstance(schema, str) and schema in _CARD_KINDS:  # another kind (a hemisphere card): the same guard
        other = _CARD_KINDS[schema](doc, source=source)
        if not force:
            check_card(other, source=source)
        return other
    if not isinstance(schema, str) or not schema.startswith(SCHEMA_PREFIX):
        raise SchemaVersionError(
            f"{source}: field 'schema' must be '{SCHEMA}', got {schema!r} (not a model card?)", field="schema"
        )
    try:
        version = int(schema[len(SCHEMA_PREFIX):])
    except ValueError:
        version = -1
    if version not in SUPPORTED_VERSIONS:
        raise SchemaVersionError(
            f"{source}: schema {schema!r} is not supported by this release (reads versions "
            f"{', '.join(map(str, SUPPORTED_VERSIONS))})",
            field="schema",
        )
    known = {f for f in ModelCard.__dataclass_fields__}
    required = ("id", "vehicle", "phase", "ansatz", "parameters", "reference_power_w")
    for k in required:
        if k not in doc:
            raise CardError(f"{source}: missing field '{k}'", field=k)
    kw = {k: v for k, v in doc.items() if k in known}
    if kw.get("covariance") is not None:
        try:
            kw["covariance"] = tuple(tuple(float(x) for x in row) for row in kw["covariance"])
        except (TypeError, ValueError):
            raise CardError(f"{source}: field 'covariance' must be a matrix of numbers or null",
                            field="covariance") from None
    if "phases" in kw:
        if not isinstance(kw["phases"], (list, tuple)):
            raise CardError(f"{source}: field 'phases' must be a list", field="phases")
        kw["phases"] = tuple(kw["phases"])
    for k in ("statistics", "provenance"):
        if k in kw and not isinstance(kw[k], Mapping):
            raise CardError(f"{source}: field '{k}' must be an object", field=k)
    try:
        card = ModelCard(**kw)
    except CardError as exc:
        raise CardError(str(exc).replace("model card", source, 1), field=exc.field) from None
    if not force:
        check_card(card, source=source)
    return card


def loads(text: str | bytes, *, source: str = "model card", force: bool = False) -> ModelCard:
    """Parse a card from JSON text (``force``: skip the plausibility guard, for inspection)."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CardError(f"{source}: malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}",
                        field="json") from None
    return from_dict(doc, source=source, force=force)


def dumps(card: ModelCard) -> str:
    """Serialize a card to JSON text (strict JSON, indent 2, :func:`gisnoise.jsonio.dumps`)."""
    return jsonio.dumps(card.to_dict(), indent=2)


def load(path: str | os.PathLike[str], *, force: bool = False) -> ModelCard:
    """Read a card file, or a bundled card by its id (``demo-horizontal``); errors name the file.

    An implausible card (:mod:`gisnoise.model.plausibility`) is refused unless ``force``
    (for inspection only; the evaluator refuses it anyway).

    A name that is no existing file, has no suffix and no folder is looked up among the
    bundled cards (:func:`gisnoise.data.bundled_card_ids`).

    Examples
    --------
    >>> load("demo-horizontal").phase
    'horizontal'
    """
    name = os.fspath(path)
    if not Path(name).exists() and not Path(name).suffix and "/" not in name and os.sep not in name:
        try:
            path = card_path(name)
        except KeyError:
            raise CardError(f"card: no file {name!r} and no bundled card of that id "
                            f"(bundled: {', '.join(bundled_card_ids())})", field="card") from None
    doc = read_json_file(path, what="card", error=CardError, field="card", json_field="json")
    return from_dict(doc, source=str(path), force=force)


def dump(card: ModelCard, fp: Any) -> None:
    """Write :func:`dumps` of ``card`` to the text file object ``fp``."""
    fp.write(dumps(card))


def save(card: ModelCard, path: str | os.PathLike[str], *, overwrite: bool = True) -> Path:
    """Write a card atomically (temp file + rename); with ``overwrite=False`` an existing file is refused."""
    p = Path(path)
    if p.exists() and not overwrite:
        raise CardError(f"{p}: exists; refusing to overwrite (--force overwrites it)", field="force")
    p.parent.mkdir(parents=True, exist_ok=True)
    return jsonio.write_json(card.to_dict(), p, indent=2)


def with_parameters(card: ModelCard, p: Any, **changes: Any) -> ModelCard:
    """A copy of ``card`` with the parameter vector ``p`` (ansatz order) and other changes."""
    params = {k: float(v) for k, v in zip(card.model.params, np.asarray(p, dtype=float), strict=True)}
    return replace(card, parameters=params, **changes)


def card_of_field(ref: Any, fld: str, base_dir: Path | None, reader: type[JsonObject]) -> ModelCard:
    """The model card a document's field ``fld`` names.

    ``ref`` is a card object (mapping), a card file (``.json`` or a path; relative to
    ``base_dir``) or the name of a bundled card (:func:`gisnoise.data.card_path`).  Errors are
    ``reader.error`` naming ``fld``, with messages starting ``reader.what``.
    """
    error, what = reader.error, reader.what
    try:
        if isinstance(ref, Mapping):
            return from_dict(ref, source=f"{what} field '{fld}'")
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
        return load(p)
    except error:
        raise
    except InputError as exc:
        raise error(f"{what}: field '{fld}': {exc}", field=fld) from None
