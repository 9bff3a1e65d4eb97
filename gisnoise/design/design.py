"""Measurement design: microphone positions and flight altitudes for an identifiable next campaign.

The paper's section 6: when distance, polar emission angle, bank angle and power
move together in the data, the maximum-likelihood estimate cannot tell their
effects apart and loses accuracy.  A *plan* (JSON, schema ``gisnoise/design-plan/1``,
see :func:`resolve_plan` and ``docs/design.md``) states the flight pattern (racetrack
loops of :mod:`gisnoise.simulate.simulate`, repeated at one altitude per repetition), the
current microphone layout, how far each microphone may move (east and north, m),
the altitude range of each repetition, exclusion polygons where no microphone may
stand, the signal-to-noise margin and the model card.  :func:`optimize` moves the
microphones and altitudes to minimize one of two objectives:

``paper``
    The largest absolute correlation coefficient (Eq. 12-14) among electric power,
    polar emission angle, distance and bank angle over the samples within the
    signal-to-noise distance (the paper's target function), over the pairs the
    design can change: power and bank angle are coupled by the turns themselves
    (:data:`PATTERN_PAIRS`), so their correlation is reported, not minimized.
``d-optimal``
    Minus the log-determinant of the fit's Fisher information ``J^T R^-1 J`` for the
    card's ansatz at the card's parameters (Jacobian from
    :meth:`gisnoise.model.ansatz.Ansatz.level_and_jacobian`, the one model definition;
    ``R`` diagonal with each microphone's noise variance), so the Cramer-Rao bounds
    of the next fit shrink.

Design model
------------
The pattern is flown by the simulator (:func:`gisnoise.simulate.simulate.run`, seeded by the
plan) with every repetition at the first base altitude; this gives the horizontal
track, heading, coordinated-turn bank, ground speed, level-flight pitch and electric
power at the simulator's rate.  Heights follow the pattern's own climb rule: the
racetrack climbs linearly along the first straight and turn of each later repetition,
so the height and vertical speed of every sample are linear in the altitudes,
``u = W h``, ``vz = W' h``; ``W`` and ``W'`` come from flying the pattern
(:class:`gisnoise.flight.patterns.PathBuilder`) with unit altitudes.  A design's pitch adds
the flight-path angle ``atan2(vz, v)`` to the level pitch, and its power adds the
power per m/s of climb or sink times the vertical speed; these slopes are measured on
two more simulator flights climbing and sinking between repetitions, so climbs cost
power exactly as in the simulator (the same random draws for the same seed).  Samples
are taken every ``1 / evaluation.rate_hz`` s per microphone at emission time; a sample
counts when the source-microphone distance is at most the signal-to-noise distance
(:func:`snr_distance`).  The Fisher information is scaled to the campaign's averaging
blocks (``evaluation.block_s``) so the expected standard deviations are those of a fit
of the whole pattern with white noise.

Optimizer
---------
:func:`scipy.optimize.differential_evolution` (seeded, ``workers=1``, reproducible).
Displacement limits and altitude ranges are the variables' bounds (the evolution
never leaves them); exclusion polygons are nonlinear *constraints*, the signed
distance of each microphone to the union of the polygons (positive outside), which
scipy handles with Lampinen's feasibility rules (a feasible design always beats an
infeasible one; infeasible ones compare by violation).  No penalty is added to the
objective.  The base design is put into the initial population, so the optimum is
never worse than the base.

Examples
--------
>>> x = {"a": np.array([1.0, 2.0, 3.0, 4.0]), "b": np.array([2.0, 4.0, 6.0, 8.0]),
...      "c": np.array([1.0, -1.0, 1.0, -1.0])}
>>> round(max_abs_correlation(x), 3), round(max_abs_correlation(x, skip=[("a", "b")]), 3)
(1.0, 0.447)
"""

from __future__ import annotations

import copy
import dataclasses
import inspect
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise import __version__
from gisnoise.errors import Cancelled, DesignError, FitError, InputError, ScenarioError
from gisnoise.flight import PathBuilder, fwd, right
from gisnoise.geo import LocalFrame, emission_angles
from gisnoise.jsonio import JsonObject, read_json_file
from gisnoise.model import cards as _cards
from gisnoise.model import load_card

__all__ = [
    "SCHEMA",
    "RESULT_SCHEMA",
    "OBJECTIVES",
    "CORRELATION_VARIABLES",
    "PATTERN_PAIRS",
    "Plan",
    "Design",
    "DesignModel",
    "Evaluation",
    "Optimum",
    "StudyPoint",
    "VerifyResult",
    "DesignResult",
    "load_plan",
    "resolve_plan",
    "snr_distance",
    "max_abs_correlation",
    "correlation_matrix",
    "fisher_information",
    "evaluate",
    "optimize",
    "study",
    "verify",
    "run_design",
    "write_outputs",
    "DesignError",
]

SCHEMA = "gisnoise/design-plan/1"
RESULT_SCHEMA = "gisnoise/design-result/1"
OBJECTIVES = ("paper", "d-optimal")
CORRELATION_VARIABLES = ("power", "polar", "distance", "bank")
"""Quantities whose largest mutual correlation the paper minimizes (section 6), in this order."""

PATTERN_PAIRS = (("power", "bank"),)
"""Pairs of flight-state quantities whose correlation the flight pattern alone sets.

Electric power follows the load factor of the coordinated turns, so power and bank
angle move together whatever the microphones and altitudes are; no design variable
changes their correlation.  Kept in the maximum, the pair would put a floor under the
paper's objective (0.91 for the sample plan's 30 degree turns) that hides every
improvement of the pairs the design does change.  The ``paper`` objective therefore
takes the maximum over the other pairs and reports this one beside it."""

_UNITS = {"power": "W", "polar": "deg", "distance": "m", "bank": "deg"}
_TRANSITION_S = 8.0  # the simulator accelerates for 8 s before a horizontal pattern flown from rest
Progress = Callable[[float], None]
CancelFn = Callable[[], bool]


# =========================================================================== plan


class _Doc(JsonObject):
    """Reads one JSON object of a plan, naming fields with their dotted path in errors."""

    error = DesignError
    what = "plan"


def _num_list(v: Any) -> bool:
    return (isinstance(v, (list, tuple)) and len(v) > 0
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v))


@dataclass(frozen=True)
class Design:
    """One measurement design: microphone positions and the altitude of each repetition.

    Attributes
    ----------
    mic_e, mic_n : ndarray, shape (m,)
        Microphone positions east and north of the plan's origin, m.
    altitudes : ndarray, shape (k,)
        Height above ground of each repetition of the pattern, m.
    """

    mic_e: np.ndarray
    mic_n: np.ndarray
    altitudes: np.ndarray

    def vector(self, base: Design) -> np.ndarray:
        """Design variables ``[de_1, dn_1, ..., de_m, dn_m, h_1, ..., h_k]`` (m) relative to ``base``."""
        shift = np.column_stack([self.mic_e - base.mic_e, self.mic_n - base.mic_n]).ravel()
        return np.concatenate([shift, self.altitudes])

    @staticmethod
    def from_vector(v: np.ndarray, base: Design) -> Design:
        m = len(base.mic_e)
        s = np.asarray(v[:2 * m], dtype=float).reshape(m, 2)
        return Design(mic_e=base.mic_e + s[:, 0], mic_n=base.mic_n + s[:, 1],
                      altitudes=np.array(v[2 * m:], dtype=float))


@dataclass(frozen=True, eq=False)
class Plan:
    """A checked design plan (see :func:`resolve_plan`); frozen, change with :meth:`with_limits`.

    Attributes
    ----------
    doc : dict
        The normalized plan document (every default filled in).
    card : ModelCard
        The model whose parameters the next campaign shall identify.
    frame : LocalFrame
        Local ENU frame of the plan's origin.
    mic_ids : tuple of str
    base : Design
        The current layout and altitudes.
    max_shift : ndarray, shape (m, 2)
        Allowed displacement of each microphone east and north, +- m.
    altitude_range : ndarray, shape (k, 2)
        Allowed altitude range of each repetition, m.
    noise_std_db : ndarray, shape (m,)
        Measurement noise of each microphone, dB.
    mic_height_m : ndarray, shape (m,)
        Microphone heights above ground, m.
    exclusions : list of shapely Polygon
        Exclusion polygons in the local ENU frame, m.
    background_db, margin_db : float
        Background level (dB(A)) and signal-to-noise margin (dB) of the SNR distance.
    max_distance_m : float
        Largest source-microphone distance of a usable sample, m (given or :func:`snr_distance`).
    """

    doc: dict[str, Any]
    card: _cards.ModelCard
    frame: LocalFrame
    mic_ids: tuple[str, ...]
    base: Design
    max_shift: np.ndarray
    altitude_range: np.ndarray
    noise_std_db: np.ndarray
    mic_height_m: np.ndarray
    exclusions: tuple[Any, ...]
    background_db: float
    margin_db: float
    max_distance_m: float = math.nan

    @property
    def n_mics(self) -> int:
        return len(self.mic_ids)

    @property
    def n_reps(self) -> int:
        return len(self.base.altitudes)

    @property
    def seed(self) -> int:
        return int(self.doc["seed"])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of the full design vector (see :meth:`Design.vector`)."""
        s = self.max_shift.ravel()
        lo = np.concatenate([-s, self.altitude_range[:, 0]])
        hi = np.concatenate([s, self.altitude_range[:, 1]])
        return lo, hi

    def variable_names(self) -> list[str]:
        names = [f"{m}.{ax}" for m in self.mic_ids for ax in ("de_m", "dn_m")]
        return names + [f"altitude[{k}]_m" for k in range(self.n_reps)]

    def with_limits(self, *, max_shift_m: float | Sequence[float] | None = None,
                    altitude_range_m: Sequence[float] | None = None) -> Plan:
        """A copy with every microphone's displacement limit and/or every repetition's altitude range replaced.

        Used by :func:`study` for the paper's Fig. 18; the result is checked like a plan.
        """
        doc = copy.deepcopy(self.doc)
        if max_shift_m is not None:
            for m in doc["microphones"]:
                m["max_shift_m"] = list(np.broadcast_to(np.asarray(max_shift_m, dtype=float), (2,)))
        if altitude_range_m is not None:
            lo, hi = (float(v) for v in altitude_range_m)
            for a in doc["altitudes"]:
                a["min_m"], a["max_m"] = lo, hi
        return resolve_plan(doc, card=self.card)


_PLAN_KEYS = ("schema", "name", "description", "seed", "origin", "card", "pattern", "altitudes", "microphones",
              "exclusions", "snr", "objectives", "evaluation", "optimizer", "study", "verify", "weather", "vehicle")


def load_plan(path: str | os.PathLike[str]) -> Plan:
    """Read and check a plan file; card and exclusion paths in it are relative to its folder."""
    p = Path(path)
    doc = read_json_file(p, what="plan", error=DesignError, field="plan")
    return resolve_plan(doc, base_dir=p.resolve().parent)


def _load_card(ref: Any, base_dir: Path | None) -> _cards.ModelCard:
    if isinstance(ref, _cards.ModelCard):
        return ref
    return load_card(ref, "card", base_dir, _Doc)


def _polygons(obj: Any, fld: str) -> list[list[list[list[float]]]]:
    """Polygon rings (lon, lat) of a GeoJSON object: FeatureCollection, Feature, Polygon or MultiPolygon."""
    if not isinstance(obj, Mapping) or "type" not in obj:
        raise DesignError(f"plan: field '{fld}' must be a GeoJSON object (FeatureCollection, Feature, Polygon or "
                          f"MultiPolygon), got {obj!r}"[:300], field=fld)
    t = obj["type"]
    if t == "FeatureCollection":
        feats = obj.get("features")
        if not isinstance(feats, list):
            raise DesignError(f"plan: field '{fld}.features' must be a list", field=f"{fld}.features")
        return [poly for i, f in enumerate(feats) for poly in _polygons(f, f"{fld}.features[{i}]")]
    if t == "Feature":
        return _polygons(obj.get("geometry"), f"{fld}.geometry")
    coords = obj.get("coordinates")
    if t == "Polygon":
        polys = [coords]
    elif t == "MultiPolygon":
        polys = coords if isinstance(coords, list) else None
    else:
        raise DesignError(f"plan: field '{fld}.type' must be Polygon or MultiPolygon (lon/lat), got {t!r}",
                          field=f"{fld}.type")
    if polys is None:
        raise DesignError(f"plan: field '{fld}.coordinates' must be a list", field=f"{fld}.coordinates")
    out = []
    for poly in polys:
        ok = isinstance(poly, list) and len(poly) > 0 and all(
            isinstance(ring, list) and len(ring) >= 4 and all(_num_list(pt) and len(pt) in (2, 3) for pt in ring)
            for ring in poly)
        if not ok:
            raise DesignError(f"plan: field '{fld}.coordinates' must hold polygons of closed rings of at least 4 "
                              f"[lon, lat] points", field=f"{fld}.coordinates")
        for ring in poly:
            for lon, lat, *_ in ring:
                if not (-180.0 <= lon <= 180.0 and -90.0 <= lat <= 90.0):
                    raise DesignError(f"plan: field '{fld}.coordinates' holds [{lon}, {lat}], not a [lon, lat] "
                                      f"point", field=f"{fld}.coordinates")
        out.append(poly)
    return out


def _scenario_doc(doc: Mapping[str, Any], card: _cards.ModelCard, design: Design, mics: Sequence[Mapping[str, Any]],
                  *, seed: int, start: Sequence[float] | None, noise: bool = True) -> dict[str, Any]:
    """A simulator scenario flying the plan's pattern at ``design``'s altitudes over ``design``'s microphones."""
    pat = dict(doc["pattern"])
    pat["heights_m"] = [float(h) for h in design.altitudes]
    card_doc = card.to_dict()
    h0 = float(design.altitudes[0])
    flight: dict[str, Any] = {"id": "f1", "patterns": [pat]}
    if start is not None:
        flight["start"] = {"e": float(start[0]), "n": float(start[1]), "height_m": h0,
                           "heading_deg": float(pat.get("heading_deg", 0.0))}
    vehicle = dict(doc.get("vehicle") or {})
    vehicle["cards"] = {ph: card_doc for ph in _cards.PHASES}
    mic_docs = []
    for i, m in enumerate(mics):
        md = {"id": m["id"], "e": float(design.mic_e[i]), "n": float(design.mic_n[i]),
              "height_m": m["height_m"], "mount": m["mount"],
              "noise_std_db": m["noise_std_db"] if noise else 0.0}
        mic_docs.append(md)
    return {"schema": "gisnoise/scenario/1", "name": f"design {doc['name']}", "seed": int(seed),
            "origin": dict(doc["origin"]), "weather": dict(doc.get("weather") or {}), "vehicle": vehicle,
            "microphones": mic_docs,
            "background": {"level_dba": float(doc["snr"]["background_db"]), "spectrum": "ambient"},
            "output": {"format": "levels", "bands": False, "band_min_hz": 50.0, "band_max_hz": 10000.0,
                       "block_s": doc["evaluation"]["block_s"]},
            "flights": [flight], "effects": {}}


def _renamed(exc: ScenarioError) -> DesignError:
    """A scenario error in plan terms (``flights[0].patterns[0].x`` -> ``pattern.x``)."""
    msg = str(exc).replace("scenario: ", "plan: ", 1)
    fld = exc.field or "plan"
    for a, b in (("flights[0].patterns[0]", "pattern"), ("flights[0].start", "pattern"),
                 ("vehicle.cards.horizontal", "card")):
        msg, fld = msg.replace(a, b), fld.replace(a, b)
    return DesignError(msg, field=fld)


def resolve_plan(doc: Mapping[str, Any], *, base_dir: str | os.PathLike[str] | None = None,
                 card: _cards.ModelCard | None = None) -> Plan:
    """Check a plan document and fill in every default.

    Errors are :class:`~gisnoise.errors.DesignError` naming the field
    (``altitudes[1].min_m``, ``microphones[0].max_shift_m``, ``exclusions``, ...).
    An infeasible plan is refused: an altitude range with its minimum above its
    maximum, a negative displacement limit, or exclusion polygons covering every
    position a microphone may take.

    Parameters
    ----------
    doc : mapping
        The plan (schema ``gisnoise/design-plan/1``); see ``docs/design.md``.
    base_dir : path, optional
        Folder card and exclusion paths are relative to.
    card : ModelCard, optional
        Use this card in place of the plan's ``card`` field.
    """
    from gisnoise.simulate import resolve_scenario

    bdir = Path(base_dir) if base_dir is not None else None
    top = _Doc(doc, "", _PLAN_KEYS)
    schema = top.get("schema", SCHEMA)
    if schema != SCHEMA:
        raise DesignError(f"plan: field 'schema' must be '{SCHEMA}', got {schema!r}", field="schema")
    out: dict[str, Any] = {"schema": SCHEMA}
    name = top.get("name", "design")
    if not isinstance(name, str) or not name:
        top.fail("name", "a non-empty string", name)
    out["name"] = name
    out["description"] = top.get("description", "")
    out["seed"] = top.num("seed", 0, lo=0, integer=True)
    o = _Doc(top.get("origin"), "origin", ("lat", "lon", "h"))
    out["origin"] = {"lat": o.num("lat", lo=-89.0, hi=89.0), "lon": o.num("lon", lo=-180.0, hi=180.0),
                     "h": o.num("h", 0.0, lo=-500.0, hi=9000.0)}
    frame = LocalFrame(out["origin"]["lat"], out["origin"]["lon"], out["origin"]["h"])
    if card is None:
        card = _load_card(top.get("card", "demo_horizontal"), bdir)
    out["card"] = card.id
    model = card.model
    if "horizontal" not in card.served_phases:
        raise DesignError(f"plan: field 'card': card {card.id!r} serves {', '.join(card.served_phases)}, not the "
                          f"horizontal flight the pattern is", field="card")
    if model.background is None:
        raise DesignError(f"plan: field 'card': ansatz {model.name!r} has no background parameter",
                          field="card")
    missing = [k for k in model.inputs if k not in _SCALAR_INPUTS + _VECTOR_INPUTS]
    if missing:
        raise DesignError(f"plan: field 'card': ansatz {model.name!r} reads {', '.join(missing)}, which a design "
                          f"cannot predict (it knows {', '.join(_SCALAR_INPUTS + _VECTOR_INPUTS)})", field="card")

    # ---------------------------------------------------------------- pattern
    pat = top.get("pattern")
    if not isinstance(pat, Mapping) or pat.get("type", "racetrack") != "racetrack":
        t = pat.get("type") if isinstance(pat, Mapping) else pat
        raise DesignError(f"plan: field 'pattern.type' must be 'racetrack' (loops with coordinated turns), "
                          f"got {t!r}", field="pattern.type")
    if "heights_m" in pat:
        raise DesignError("plan: field 'pattern.heights_m': the altitudes of the repetitions are given in "
                          "'altitudes'", field="pattern.heights_m")
    pat = {"type": "racetrack", **{k: v for k, v in pat.items() if k != "type"}}

    # ---------------------------------------------------------------- altitudes
    alts = top.get("altitudes")
    if not isinstance(alts, list) or not alts:
        raise DesignError("plan: field 'altitudes' must be a non-empty list of {base_m, min_m, max_m}, one per "
                          "repetition of the pattern", field="altitudes")
    out["altitudes"] = []
    for i, a in enumerate(alts):
        ao = _Doc(a, f"altitudes[{i}]", ("base_m", "min_m", "max_m"))
        base_h = ao.num("base_m", lo=1.0, hi=2000.0)
        lo_h = ao.num("min_m", base_h, lo=1.0, hi=2000.0)
        hi_h = ao.num("max_m", base_h, lo=1.0, hi=2000.0)
        if lo_h > hi_h:
            raise DesignError(f"plan: field 'altitudes[{i}].min_m' ({lo_h:g} m) is above 'altitudes[{i}].max_m' "
                              f"({hi_h:g} m): the range is empty", field=f"altitudes[{i}].min_m")
        out["altitudes"].append({"base_m": base_h, "min_m": lo_h, "max_m": hi_h})

    # ---------------------------------------------------------------- microphones
    mics = top.get("microphones")
    if not isinstance(mics, list) or not mics:
        raise DesignError("plan: field 'microphones' must be a non-empty list", field="microphones")
    out["microphones"] = []
    seen: set[str] = set()
    for i, m in enumerate(mics):
        mo = _Doc(m, f"microphones[{i}]", ("id", "e", "n", "lat", "lon", "max_shift_m", "noise_std_db", "height_m",
                                            "mount"))
        mid = mo.get("id")
        if not isinstance(mid, str) or not mid or mid in seen or "/" in mid:
            mo.fail("id", "a unique non-empty name", mid)
        seen.add(mid)
        if "lat" in m or "lon" in m:
            lat, lon = mo.num("lat", lo=-90.0, hi=90.0), mo.num("lon", lo=-180.0, hi=180.0)
            e, n, _ = frame.to_enu(lat, lon, out["origin"]["h"])
            e, n = float(e), float(n)
        else:
            e, n = mo.num("e", lo=-1e5, hi=1e5), mo.num("n", lo=-1e5, hi=1e5)
        shift = mo.get("max_shift_m", 0.0)
        if isinstance(shift, (int, float)) and not isinstance(shift, bool):
            shift = [shift, shift]
        if not (_num_list(shift) and len(shift) == 2):
            mo.fail("max_shift_m", "a displacement limit in m, or [east, north] limits", shift)
        if min(shift) < 0:
            mo.fail("max_shift_m", "non-negative (the microphone may move +- this far)", m.get("max_shift_m"))
        mount = mo.get("mount", "ground_plate")
        out["microphones"].append({"id": mid, "e": e, "n": n, "max_shift_m": [float(shift[0]), float(shift[1])],
                                   "noise_std_db": mo.num("noise_std_db", 1.0, lo=0.0, lo_open=True, hi=20.0),
                                   "height_m": mo.num("height_m", 0.0, lo=0.0, hi=100.0), "mount": mount})

    # ---------------------------------------------------------------- snr
    so = _Doc(top.get("snr", {}), "snr", ("background_db", "margin_db", "max_distance_m"))
    bg = so.num("background_db", None, lo=-20.0, hi=120.0, allow_none=True)
    out["snr"] = {"background_db": card.background_db if bg is None else bg,
                  "margin_db": so.num("margin_db", 3.0, lo=0.0, hi=60.0),
                  "max_distance_m": so.num("max_distance_m", None, lo=1.0, lo_open=True, hi=1e5, allow_none=True)}

    # ---------------------------------------------------------------- objectives, evaluation, optimizer
    objs = top.get("objectives", list(OBJECTIVES))
    if isinstance(objs, str):
        objs = [objs]
    if not isinstance(objs, list) or not objs or any(o_ not in OBJECTIVES for o_ in objs) or len(set(objs)) != len(objs):
        top.fail("objectives", f"a list of distinct names from {', '.join(OBJECTIVES)}", objs)
    out["objectives"] = list(objs)
    ev = _Doc(top.get("evaluation", {}), "evaluation", ("rate_hz", "block_s"))
    out["evaluation"] = {"rate_hz": ev.num("rate_hz", 2.0, lo=0.05, hi=50.0),
                         "block_s": ev.num("block_s", 0.125, lo=0.01, hi=10.0)}
    op = _Doc(top.get("optimizer", {}), "optimizer", ("popsize", "maxiter", "tol", "seed", "polish"))
    out["optimizer"] = {"popsize": op.num("popsize", 15, lo=2, hi=200, integer=True),
                        "maxiter": op.num("maxiter", 150, lo=1, hi=100000, integer=True),
                        "tol": op.num("tol", 1e-4, lo=0.0, hi=1e3),
                        "seed": op.num("seed", out["seed"], lo=0, integer=True),
                        "polish": op.get("polish", False)}
    if not isinstance(out["optimizer"]["polish"], bool):
        op.fail("polish", "true or false", out["optimizer"]["polish"])
    st = top.get("study", {})
    if st is None:
        out["study"] = None
    else:
        sto = _Doc(st, "study", ("displacements_m", "altitude_ranges_m", "objectives", "maxiter", "popsize"))
        disp = sto.get("displacements_m", [0.0, 25.0, 50.0, 100.0, 150.0, 200.0])
        if not _num_list(disp) or min(disp) < 0:
            sto.fail("displacements_m", "a non-empty list of displacement limits >= 0 m", disp)
        rngs = sto.get("altitude_ranges_m", [[60.0, 60.0], [50.0, 150.0], [35.0, 200.0]])
        if not isinstance(rngs, list) or not rngs:
            sto.fail("altitude_ranges_m", "a non-empty list of [min, max] altitude ranges, m", rngs)
        for j, r in enumerate(rngs):
            if not (_num_list(r) and len(r) == 2 and r[0] >= 1.0):
                sto.fail("altitude_ranges_m", "a list of [min, max] altitude ranges with min >= 1 m", rngs)
            if r[0] > r[1]:
                raise DesignError(f"plan: field 'study.altitude_ranges_m[{j}]': minimum {r[0]:g} m is above maximum "
                                  f"{r[1]:g} m", field=f"study.altitude_ranges_m[{j}]")
        sobj = sto.get("objectives", ["paper"])
        if isinstance(sobj, str):
            sobj = [sobj]
        if not isinstance(sobj, list) or not sobj or any(o_ not in OBJECTIVES for o_ in sobj):
            sto.fail("objectives", f"a list of names from {', '.join(OBJECTIVES)}", sobj)
        out["study"] = {"displacements_m": sorted(float(x) for x in disp),
                        "altitude_ranges_m": [[float(a), float(b)] for a, b in rngs],
                        "objectives": list(dict.fromkeys(sobj)),
                        "maxiter": sto.num("maxiter", 60, lo=1, hi=100000, integer=True),
                        "popsize": sto.num("popsize", out["optimizer"]["popsize"], lo=2, hi=200, integer=True)}
    vo = _Doc(top.get("verify", {}), "verify", ("seeds", "first_seed"))
    out["verify"] = {"seeds": vo.num("seeds", 0, lo=0, hi=10000, integer=True),
                     "first_seed": vo.num("first_seed", 1000, lo=0, integer=True)}
    for k in ("weather", "vehicle"):
        v = top.get(k, {})
        if not isinstance(v, Mapping):
            top.fail(k, "an object (as in a simulator scenario)", v)
        if k == "vehicle" and "cards" in v:
            raise DesignError("plan: field 'vehicle.cards': the plan's 'card' is the model", field="vehicle.cards")
        out[k] = copy.deepcopy(dict(v))

    # ---------------------------------------------------------------- pattern and passthrough checked by the simulator
    base = Design(mic_e=np.array([m["e"] for m in out["microphones"]]),
                  mic_n=np.array([m["n"] for m in out["microphones"]]),
                  altitudes=np.array([a["base_m"] for a in out["altitudes"]]))
    out["pattern"] = pat
    try:
        sc = resolve_scenario(_scenario_doc(out, card, base, out["microphones"], seed=out["seed"], start=None))
    except ScenarioError as exc:
        raise _renamed(exc) from None
    rp = dict(sc.doc["flights"][0]["patterns"][0])
    rp.pop("heights_m")
    out["pattern"] = rp
    out["weather"] = dict(sc.doc["weather"])
    out["vehicle"] = {k: v for k, v in sc.doc["vehicle"].items() if k != "cards"}
    for i, m in enumerate(sc.doc["microphones"]):
        out["microphones"][i]["mount"] = m["mount"]

    # ---------------------------------------------------------------- exclusions
    ex = top.get("exclusions", None)
    if isinstance(ex, str):
        p = Path(ex)
        if not p.is_absolute() and bdir is not None:
            p = bdir / p
        try:
            ex = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise DesignError(f"plan: field 'exclusions': cannot read GeoJSON {p}: {exc}", field="exclusions") from None
    rings = [] if ex is None else _polygons(ex, "exclusions")
    out["exclusions"] = ex
    polys = tuple(_enu_polygon(poly, frame, out["origin"]["h"]) for poly in rings)

    mic_ids = tuple(m["id"] for m in out["microphones"])
    shift = np.array([m["max_shift_m"] for m in out["microphones"]], dtype=float)
    _check_feasible(mic_ids, base, shift, polys)
    plan = Plan(doc=out, card=card, frame=frame, mic_ids=mic_ids, base=base, max_shift=shift,
                altitude_range=np.array([[a["min_m"], a["max_m"]] for a in out["altitudes"]], dtype=float),
                noise_std_db=np.array([m["noise_std_db"] for m in out["microphones"]], dtype=float),
                mic_height_m=np.array([m["height_m"] for m in out["microphones"]], dtype=float),
                exclusions=polys, background_db=float(out["snr"]["background_db"]),
                margin_db=float(out["snr"]["margin_db"]))
    dmax = out["snr"]["max_distance_m"]
    if dmax is None:
        dmax = snr_distance(card, plan.background_db + plan.margin_db,
                            power_w=float(out["vehicle"]["power"]["cruise_w"]))
    return dataclasses.replace(plan, max_distance_m=float(dmax))


def _enu_polygon(poly: list[list[list[float]]], frame: LocalFrame, h0: float) -> Any:
    import shapely

    rings = []
    for ring in poly:
        arr = np.asarray([pt[:2] for pt in ring], dtype=float)
        e, n, _ = frame.to_enu(arr[:, 1], arr[:, 0], np.full(len(arr), h0))
        rings.append(np.column_stack([e, n]))
    g = shapely.Polygon(rings[0], rings[1:])
    if not g.is_valid:
        g = shapely.make_valid(g)
    return g


def _check_feasible(mic_ids: Sequence[str], base: Design, shift: np.ndarray, polys: Sequence[Any]) -> None:
    """Refuse a plan whose exclusions cover every allowed position of some microphone."""
    if not polys:
        return
    import shapely

    union = shapely.union_all(list(polys))
    for i, mid in enumerate(mic_ids):
        e, n = base.mic_e[i], base.mic_n[i]
        se, sn = shift[i]
        if se > 0 and sn > 0:
            allowed = shapely.box(e - se, n - sn, e + se, n + sn)
        elif se > 0 or sn > 0:
            allowed = shapely.LineString([(e - se, n - sn), (e + se, n + sn)])
        else:
            allowed = shapely.Point(e, n)
        free = allowed.difference(union)
        if free.is_empty or (allowed.area > 0 and free.area <= 1e-9 * allowed.area):
            raise DesignError(f"plan: field 'exclusions' covers every allowed position of microphone {mid!r} "
                              f"(within +-{se:g} m east, +-{sn:g} m north of ({e:.1f}, {n:.1f}) m); move it or "
                              f"allow a larger displacement", field="exclusions")


# =========================================================================== signal to noise


def snr_distance(card: _cards.ModelCard, level_db: float, *, power_w: float | None = None,
                 n_dir: int = 24) -> float:
    """Distance (m) at which the card's ``L_UAV`` falls to ``level_db``.

    ``L_UAV`` is averaged energetically over the directions of the lower hemisphere
    (uniform in solid angle: azimuth -180..180 deg, polar angle -90..0 deg) at the
    electric power ``power_w`` (default the card's reference power), and the distance
    is solved with the card's model (the one model definition), not from a formula
    of its own.  For an extended ansatz (``base+effect``) the base model is used: the
    level of steady, straight, level flight.

    Parameters
    ----------
    card : ModelCard
    level_db : float
        Level to fall to, dB(A): background plus the signal-to-noise margin.
    power_w : float, optional
        Electric power, W.
    n_dir : int
        Grid points per angle of the direction average.

    Examples
    --------
    >>> from gisnoise.data import card_path
    >>> from gisnoise.model.cards import load
    >>> card = load(card_path("demo-horizontal"))
    >>> d = snr_distance(card, 43.0, power_w=3000.0)
    >>> 200 < d < 800
    True
    """
    from scipy.optimize import brentq

    pw = card.reference_power_w if power_w is None else float(power_w)
    if "+" in card.ansatz:  # an extension (bank angle, Doppler, ...): the base model in steady level flight
        from gisnoise.model import get_ansatz

        base_model = get_ansatz(card.ansatz.split("+", 1)[0])
        card = dataclasses.replace(card, ansatz=base_model.name, covariance=None,
                                   parameters={k: card.parameters[k] for k in base_model.params})
    # midpoint grid: azimuth uniform, sin(polar) uniform in [-1, 0] (equal solid angle per cell)
    phi = (np.arange(n_dir) + 0.5) / n_dir * 2.0 * np.pi - np.pi
    theta = np.arcsin(-(np.arange(n_dir) + 0.5) / n_dir)
    ph, th = np.meshgrid(phi, theta)

    def excess(log_d: float) -> float:
        x = card.inputs(np.full(ph.shape, math.exp(log_d)), ph, th, np.full(ph.shape, pw))
        lv = np.asarray(card.level_uav(x), dtype=float)
        return float(10.0 * np.log10(np.mean(10.0 ** (lv / 10.0)))) - level_db

    lo, hi = math.log(0.1), math.log(1e6)
    f_lo, f_hi = excess(lo), excess(hi)
    if not (f_lo > 0 > f_hi):
        raise DesignError(f"plan: field 'snr': the card's level never falls to {level_db:.1f} dB(A) between 0.1 m "
                          f"and 1000 km (at 0.1 m {f_lo + level_db:.1f}, at 1000 km {f_hi + level_db:.1f} dB(A)); "
                          f"give snr.max_distance_m", field="snr")
    return float(math.exp(brentq(excess, lo, hi, xtol=1e-6)))


# =========================================================================== objectives


def correlation_matrix(columns: Mapping[str, np.ndarray]) -> np.ndarray:
    """Correlation matrix (paper Eq. 12-14, 1/N moments) of equally long columns.

    A column that does not vary has no defined correlation; its entries are set to
    1 (it cannot be told apart from a constant level offset), its diagonal to 1.
    """
    x = np.vstack([np.asarray(v, dtype=float) for v in columns.values()])
    n = x.shape[1]
    if n < 2:
        return np.ones((len(x), len(x)))
    xc = x - x.mean(axis=1, keepdims=True)
    cov = xc @ xc.T / n
    sd = np.sqrt(np.diag(cov))
    const = sd <= 1e-12 * np.maximum(1.0, np.abs(x).max(axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    corr[const, :] = 1.0
    corr[:, const] = 1.0
    np.fill_diagonal(corr, 1.0)
    return np.clip(corr, -1.0, 1.0)


def max_abs_correlation(columns: Mapping[str, np.ndarray], *,
                        skip: Sequence[tuple[str, str]] = ()) -> float:
    """The paper's target function: the largest absolute off-diagonal correlation of the columns.

    Parameters
    ----------
    columns : mapping name -> array_like
        Equally long columns (Eq. 12-14).
    skip : sequence of (name, name)
        Pairs left out of the maximum (see :data:`PATTERN_PAIRS`).
    """
    c = correlation_matrix(columns)
    names = list(columns)
    k = len(c)
    use = ~np.eye(k, dtype=bool)
    for a, b in skip:
        if a in names and b in names:
            i, j = names.index(a), names.index(b)
            use[i, j] = use[j, i] = False
    if not use.any():
        return 0.0
    return float(np.max(np.abs(c[use])))


def fisher_information(card: _cards.ModelCard, x: Mapping[str, Any], noise_std_db: Any) -> np.ndarray:
    """Fisher information ``J^T R^-1 J`` of the card's parameters for samples ``x``.

    ``J`` is the Jacobian of the level with the background term (Eq. 8) at the card's
    parameters, from :meth:`gisnoise.model.ansatz.Ansatz.level_and_jacobian`; ``R`` is diagonal
    with ``noise_std_db**2`` per sample (scalar or one value per sample).
    """
    _, jac = card.model.level_and_jacobian(card.p, x, d_ref=card.reference_distance_m)
    jac = np.asarray(jac, dtype=float).reshape(-1, card.model.n_params)
    w = 1.0 / np.broadcast_to(np.asarray(noise_std_db, dtype=float), (len(jac),)) ** 2
    return jac.T @ (jac * w[:, None])


def _logdet(m: np.ndarray) -> float:
    # scale to unit diagonal first so the determinant of badly scaled matrices is accurate
    d = np.sqrt(np.clip(np.diag(m), 1e-300, None))
    sign, ld = np.linalg.slogdet(m / np.outer(d, d))
    if sign <= 0 or not np.isfinite(ld):
        return -math.inf
    return float(ld + 2.0 * np.sum(np.log(d)))


# =========================================================================== the design model


@dataclass(frozen=True, eq=False)
class DesignModel:
    """The pattern flown by the simulator, ready to give the samples of any design (see the module docstring).

    Attributes
    ----------
    plan : Plan
    t : ndarray, shape (n,)
        Sample times since the start of the pattern, s (emission time).
    e, n : ndarray, shape (n,)
        Horizontal UAV position, m.
    weights : ndarray, shape (n, k)
        Height of each sample is ``weights @ altitudes`` (m).
    vz_weights : ndarray, shape (n, k)
        Vertical speed of each sample is ``vz_weights @ altitudes`` (m/s).
    yaw, roll : ndarray, shape (n,)
        Heading and bank, rad (the same at every altitude).
    pitch_level : ndarray, shape (n,)
        Pitch in level flight, rad; a design adds its flight-path angle ``atan2(vz, v)``.
    power_level_w : ndarray, shape (n,)
        Electric power in level flight, W.
    power_per_climb, power_per_sink : ndarray, shape (n,)
        Change of electric power per m/s of climb and of sink, W s/m, measured on the
        simulator by flying the pattern climbing and sinking between repetitions.
    speed_m_s : ndarray, shape (n,)
        Horizontal ground speed, m/s.
    vel_en : ndarray, shape (n, 2)
        Horizontal ground velocity (east, north), m/s.
    repetition : ndarray of int, shape (n,)
        Repetition of the pattern each sample belongs to.
    track : dict of ndarray
        ``t``, ``e``, ``n``, ``weights`` at the simulator's rate, for drawing the track.
    start_en : ndarray, shape (2,)
        Where the simulated flight starts (it accelerates for 8 s into the pattern's entry), m.
    duration_s : float
        Duration of the pattern (all repetitions), s.
    speed_of_sound_m_s : float
        Of the plan's weather (as the simulator takes it), m/s; for ansatz extensions that need it.
    """

    plan: Plan
    t: np.ndarray
    e: np.ndarray
    n: np.ndarray
    weights: np.ndarray
    vz_weights: np.ndarray
    yaw: np.ndarray
    roll: np.ndarray
    pitch_level: np.ndarray
    power_level_w: np.ndarray
    power_per_climb: np.ndarray
    power_per_sink: np.ndarray
    speed_m_s: np.ndarray
    vel_en: np.ndarray
    repetition: np.ndarray
    track: dict[str, np.ndarray] = field(repr=False)
    start_en: np.ndarray = field(repr=False)
    duration_s: float = 0.0
    speed_of_sound_m_s: float = 340.0

    @classmethod
    def build(cls, plan: Plan, *, calibration_step_m: float = 50.0) -> DesignModel:
        """Fly the plan's pattern with the simulator and derive the height weights.

        Three flights of the simulator: every repetition at the first base altitude
        (level flight), and climbing and sinking by ``calibration_step_m`` between
        repetitions; the power change over the vertical speed gives the power per m/s
        of climb and of sink at every sample (the simulator's power law and its slow
        random part, the same draws for the same seed), so a design's power follows
        its climbs without a second statement of the power law.
        """
        from gisnoise.simulate import run

        pat = plan.doc["pattern"]
        heading = math.radians(pat["heading_deg"])
        turn = 1 if pat["turn"] == "right" else -1
        v, radius, straight = pat["speed_m_s"], pat["radius_m"], pat["straight_m"]
        centre = np.array(pat["centre"], dtype=float)
        entry = centre - 0.5 * straight * fwd(heading) - turn * radius * right(heading)
        # the simulator accelerates from rest for 8 s along the heading before a horizontal pattern:
        # start that far before the entry so the pattern is flown from its entry, without a joining path
        start = entry - 0.5 * v * _TRANSITION_S * fwd(heading)
        k_reps = plan.n_reps
        h0 = float(plan.base.altitudes[0])
        mics = plan.doc["microphones"]

        def fly(heights: np.ndarray) -> dict[str, np.ndarray]:
            d = Design(plan.base.mic_e, plan.base.mic_n, heights)
            try:
                res = run(_scenario_doc(plan.doc, plan.card, d, mics, seed=plan.seed, start=start, noise=False))
            except ScenarioError as exc:
                raise _renamed(exc) from None
            tr = res.flights[0].true
            i0 = int(np.argmax(tr["phase"] == "horizontal"))
            out = {k: np.asarray(tr[k])[i0:] for k in ("t", "e", "n", "u", "yaw", "pitch", "roll", "power_w")}
            out["vel"] = np.asarray(tr["vel"][i0:], dtype=float)
            out["t"] = out["t"] - out["t"][0]
            out["dt"] = np.array(1.0 / float(res.scenario.doc["output"]["sim_rate_hz"]))
            out["c"] = np.array(res.scenario.c)
            return out

        sim = fly(np.full(k_reps, h0))
        dt = float(sim["dt"])
        cols, vcols = [], []
        for k in range(k_reps):
            unit = [1.0 if j == k else 0.0 for j in range(k_reps)]
            b = PathBuilder(e=float(entry[0]), n=float(entry[1]), u=unit[0], heading=heading, dt=dt, speed=v)
            b.racetrack(centre, heading, straight, radius, unit, pat["laps"], v, turn, math.radians(6.0))
            p = b.finish()
            cols.append(p["u"])
            vcols.append(p["vz"])
        w, wv = np.column_stack(cols), np.column_stack(vcols)
        if (len(w) != len(sim["t"]) or np.max(np.abs(p["e"] - sim["e"])) > 1e-6
                or np.max(np.abs(p["n"] - sim["n"])) > 1e-6 or np.max(np.abs(w.sum(axis=1) - 1.0)) > 1e-9):
            raise RuntimeError("design model: the pattern flown by the simulator and by the path builder differ")
        per_climb = np.zeros(len(w))
        per_sink = np.zeros(len(w))
        if k_reps > 1:
            step = calibration_step_m * np.arange(k_reps)
            for heights, out in ((h0 + step, per_climb), (h0 + step[::-1], per_sink)):
                f = fly(heights)
                vz = wv @ heights
                moving = np.abs(vz) > 1e-6
                out[moving] = (f["power_w"][moving] - sim["power_w"][moving]) / vz[moving]
        rep_s = pat["laps"] * (2.0 * straight + 2.0 * math.pi * radius) / v
        step_i = max(1, int(round(1.0 / (plan.doc["evaluation"]["rate_hz"] * dt))))
        idx = np.arange(0, len(sim["t"]), step_i)
        t = sim["t"][idx]
        rep = np.minimum((t / rep_s).astype(int), k_reps - 1)
        vel = sim["vel"][idx]
        return cls(plan=plan, t=t, e=sim["e"][idx], n=sim["n"][idx], weights=w[idx], vz_weights=wv[idx],
                   yaw=sim["yaw"][idx], roll=sim["roll"][idx], pitch_level=sim["pitch"][idx],
                   power_level_w=sim["power_w"][idx], power_per_climb=per_climb[idx], power_per_sink=per_sink[idx],
                   speed_m_s=np.hypot(vel[:, 0], vel[:, 1]), vel_en=vel[:, :2], repetition=rep,
                   track={"t": sim["t"], "e": sim["e"], "n": sim["n"], "weights": w}, start_en=start,
                   duration_s=float(sim["t"][-1]), speed_of_sound_m_s=float(sim["c"]))

    @property
    def rate_hz(self) -> float:
        return float(self.plan.doc["evaluation"]["rate_hz"])

    def state(self, altitudes: np.ndarray) -> dict[str, np.ndarray]:
        """Height ``u`` (m), vertical speed ``vz`` (m/s), ``pitch`` (rad) and ``power_w`` (W) of the
        pattern flown at ``altitudes`` (shape (S, k)), each of shape (S, n)."""
        h = np.asarray(altitudes, dtype=float)
        u = h @ self.weights.T
        vz = h @ self.vz_weights.T
        power = (self.power_level_w + self.power_per_climb * np.maximum(vz, 0.0)
                 + self.power_per_sink * np.minimum(vz, 0.0))
        pitch = self.pitch_level + np.arctan2(vz, self.speed_m_s)  # plus the flight-path angle
        return {"u": u, "vz": vz, "pitch": pitch, "power_w": power}

    def samples_batch(self, mic_e: np.ndarray, mic_n: np.ndarray, altitudes: np.ndarray) -> dict[str, np.ndarray]:
        """Geometry and flight state of ``S`` designs at once, each row microphone-major over the samples.

        Parameters
        ----------
        mic_e, mic_n : ndarray, shape (S, m)
            Microphone positions, m.
        altitudes : ndarray, shape (S, k)
            Altitude of each repetition, m.

        Returns
        -------
        dict
            ``d`` (m), ``phi``, ``theta`` (rad), ``u`` (UAV height, m), ``vz`` (m/s),
            ``pitch`` (rad), ``power_w`` (W) and ``usable`` (distance within the
            signal-to-noise distance), shape (S, m n); ``mic`` (microphone index) and
            ``sample`` (index into the pattern's samples), shape (m n,).
        """
        plan = self.plan
        m, k = plan.n_mics, len(self.t)
        st = self.state(altitudes)
        n_s = st["u"].shape[0]
        de = np.asarray(mic_e, dtype=float)[:, :, None] - self.e[None, None, :]
        dn = np.asarray(mic_n, dtype=float)[:, :, None] - self.n[None, None, :]
        du = plan.mic_height_m[None, :, None] - st["u"][:, None, :]
        d, phi, theta = emission_angles(de, dn, du, self.yaw, st["pitch"][:, None, :], self.roll)
        d = d.reshape(n_s, m * k)

        def per_mic(a: np.ndarray) -> np.ndarray:
            return np.broadcast_to(a[:, None, :], (n_s, m, k)).reshape(n_s, m * k)

        return {"d": d, "phi": phi.reshape(n_s, m * k), "theta": theta.reshape(n_s, m * k),
                "u": per_mic(st["u"]), "vz": per_mic(st["vz"]), "pitch": per_mic(st["pitch"]),
                "power_w": per_mic(st["power_w"]), "usable": d <= plan.max_distance_m,
                "mic": np.repeat(np.arange(m), k), "sample": np.tile(np.arange(k), m)}

    def samples(self, design: Design) -> dict[str, np.ndarray]:
        """Per (microphone, sample) geometry of one design: :meth:`samples_batch` with ``S = 1``, squeezed."""
        b = self.samples_batch(design.mic_e[None, :], design.mic_n[None, :], design.altitudes[None, :])
        return {k: (v[0] if v.ndim == 2 else v) for k, v in b.items()}

    def model_inputs(self, s: Mapping[str, np.ndarray], *, design: Design | None = None) -> dict[str, Any]:
        """Ansatz inputs of the samples ``s`` (from :meth:`samples` or :meth:`samples_batch`), all rows.

        The names are those of :meth:`gisnoise.measure.samples.Samples.inputs`; vector inputs
        (``uav_enu``, ``mic_enu``, ``vel_enu``) need ``design`` and a single design's samples.
        """
        card = self.plan.card
        j = s["sample"]
        x: dict[str, Any] = {"d": s["d"], "phi": s["phi"], "theta": s["theta"],
                             "p_el": s["power_w"] / card.reference_power_w, "bank": self.roll[j],
                             "roll": np.degrees(self.roll[j]), "pitch": np.degrees(s["pitch"]),
                             "yaw": np.degrees(self.yaw[j]), "speed": np.hypot(self.speed_m_s[j], s["vz"]),
                             "t_e": self.t[j], "mic_agl": self.plan.mic_height_m[s["mic"]],
                             "meta": {"speed_of_sound_m_s": self.speed_of_sound_m_s,
                                      "weather": dict(self.plan.doc["weather"])}}
        if design is not None and s["d"].ndim == 1:
            mi = s["mic"]
            x["uav_enu"] = np.column_stack([self.e[j], self.n[j], s["u"]])
            x["mic_enu"] = np.column_stack([design.mic_e[mi], design.mic_n[mi], self.plan.mic_height_m[mi]])
            x["vel_enu"] = np.column_stack([self.vel_en[j], s["vz"]])
        return x


_SCALAR_INPUTS = ("d", "phi", "theta", "p_el", "bank", "roll", "pitch", "yaw", "speed", "t_e", "mic_agl", "meta")
_VECTOR_INPUTS = ("uav_enu", "mic_enu", "vel_enu")


# =========================================================================== evaluation


@dataclass(frozen=True, eq=False)
class Evaluation:
    """Both objectives and what they are made of, for one design.

    Attributes
    ----------
    design : Design
    max_abs_corr : float
        The paper's objective: the largest absolute correlation over the pairs of
        :data:`CORRELATION_VARIABLES` but :data:`PATTERN_PAIRS`, or 1 when fewer than 3
        samples are usable.
    max_abs_corr_all : float
        The same over all pairs.
    log_det_fisher : float
        Log-determinant of the Fisher information at the campaign's block rate (``-inf`` if singular).
    correlation : ndarray, shape (4, 4)
        Correlation matrix of :data:`CORRELATION_VARIABLES` over the usable samples.
    expected_std : dict
        Cramer-Rao standard deviation of each parameter expected for a fit of the campaign.
    n_usable : int
        Usable samples at the evaluation rate (all microphones).
    n_usable_per_mic : dict
    feasible : bool
        No microphone inside an exclusion polygon and every variable within its bounds.
    """

    design: Design
    max_abs_corr: float
    max_abs_corr_all: float
    log_det_fisher: float
    correlation: np.ndarray
    expected_std: dict[str, float]
    n_usable: int
    n_usable_per_mic: dict[str, int]
    feasible: bool

    def objective(self, name: str) -> float:
        """The value the optimizer minimizes for objective ``name``."""
        return self.max_abs_corr if name == "paper" else -self.log_det_fisher

    def to_dict(self, plan: Plan) -> dict[str, Any]:
        d = self.design
        lat, lon, h = plan.frame.to_wgs84(d.mic_e, d.mic_n, plan.mic_height_m)
        return {
            "microphones": [{"id": mid, "e_m": round(float(d.mic_e[i]), 3), "n_m": round(float(d.mic_n[i]), 3),
                             "de_m": round(float(d.mic_e[i] - plan.base.mic_e[i]), 3),
                             "dn_m": round(float(d.mic_n[i] - plan.base.mic_n[i]), 3),
                             "lat": round(float(lat[i]), 9), "lon": round(float(lon[i]), 9),
                             "n_usable": self.n_usable_per_mic[mid]} for i, mid in enumerate(plan.mic_ids)],
            "altitudes_m": [round(float(a), 3) for a in d.altitudes],
            "variables": [round(float(x), 4) for x in d.vector(plan.base)],
            "objectives": {"paper": self.max_abs_corr, "d-optimal": self.log_det_fisher},
            "max_abs_corr_all_pairs": self.max_abs_corr_all,
            "correlation": {"variables": list(CORRELATION_VARIABLES), "matrix": self.correlation.tolist()},
            "expected_std": dict(self.expected_std),
            "n_usable": self.n_usable, "feasible": self.feasible,
        }


def _in_exclusion(plan: Plan, design: Design) -> np.ndarray:
    if not plan.exclusions:
        return np.zeros(plan.n_mics, dtype=bool)
    import shapely

    union = shapely.union_all(list(plan.exclusions))
    return np.asarray(shapely.contains_xy(union, design.mic_e, design.mic_n), dtype=bool)


def evaluate(model: DesignModel, design: Design | None = None) -> Evaluation:
    """Both objectives, the input correlation matrix and the expected standard deviations of a design.

    Parameters
    ----------
    model : DesignModel
    design : Design, optional
        Default: the plan's base design.
    """
    plan = model.plan
    design = plan.base if design is None else design
    s = model.samples(design)
    sel = s["usable"]
    corr = _corr_batch(model, {k: v[None] if v.ndim == 1 and k not in ("mic", "sample") else v
                               for k, v in s.items()})[0]
    mac = _max_abs(corr, _pair_mask(PATTERN_PAIRS)) if sel.sum() >= 3 else 1.0
    mac_all = _max_abs(corr, _pair_mask(())) if sel.sum() >= 3 else 1.0
    m = _fisher(model, s, design)
    ld = _logdet(m)
    names = plan.card.model.params
    try:
        cov = np.linalg.inv(m) if np.isfinite(ld) else None
    except np.linalg.LinAlgError:
        cov = None
    std = {k: (float(math.sqrt(cov[i, i])) if cov is not None and cov[i, i] > 0 else math.inf)
           for i, k in enumerate(names)}
    lo, hi = plan.bounds()
    v = design.vector(plan.base)
    feasible = bool(np.all(v >= lo - 1e-9) and np.all(v <= hi + 1e-9) and not _in_exclusion(plan, design).any())
    per_mic = {mid: int(np.sum(sel & (s["mic"] == i))) for i, mid in enumerate(plan.mic_ids)}
    return Evaluation(design=design, max_abs_corr=float(mac), max_abs_corr_all=float(mac_all), log_det_fisher=ld,
                      correlation=corr, expected_std=std, n_usable=int(sel.sum()), n_usable_per_mic=per_mic,
                      feasible=feasible)


def _pair_mask(skip: Sequence[tuple[str, str]]) -> np.ndarray:
    names = list(CORRELATION_VARIABLES)
    use = ~np.eye(len(names), dtype=bool)
    for a, b in skip:
        i, j = names.index(a), names.index(b)
        use[i, j] = use[j, i] = False
    return use


def _max_abs(corr: np.ndarray, use: np.ndarray) -> float:
    return float(np.max(np.abs(corr[use])))


def _corr_batch(model: DesignModel, s: Mapping[str, np.ndarray]) -> np.ndarray:
    """Correlation matrices (S, 4, 4) of :data:`CORRELATION_VARIABLES` over each design's usable samples.

    The same numbers as :func:`correlation_matrix` of the usable rows (Eq. 12-14, 1/N moments;
    a column that does not vary correlates 1 with everything); fewer than 3 usable rows give ones.
    """
    j = s["sample"]
    w = s["usable"].astype(float)  # (S, N)
    n_s = w.shape[0]
    x = np.stack([s["power_w"], np.degrees(s["theta"]), s["d"],
                  np.broadcast_to(np.degrees(model.roll[j]), w.shape)], axis=1)  # (S, 4, N)
    nw = w.sum(axis=1)
    safe = np.maximum(nw, 1.0)
    mean = np.einsum("san,sn->sa", x, w) / safe[:, None]
    xc = (x - mean[:, :, None]) * w[:, None, :]
    cov = np.matmul(xc, xc.transpose(0, 2, 1)) / safe[:, None, None]
    sd = np.sqrt(np.maximum(np.einsum("saa->sa", cov), 0.0))
    scale = np.maximum(1.0, np.max(np.abs(x * w[:, None, :]), axis=2))
    const = sd <= 1e-12 * scale
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / (sd[:, :, None] * sd[:, None, :])
    corr = np.where(const[:, :, None] | const[:, None, :], 1.0, corr)
    idx = np.arange(4)
    corr[:, idx, idx] = 1.0
    corr = np.clip(corr, -1.0, 1.0)
    corr[nw < 3] = 1.0
    return corr if n_s else np.ones((0, 4, 4))


def _fisher(model: DesignModel, s: Mapping[str, np.ndarray], design: Design) -> np.ndarray:
    """Fisher information of a fit of the whole campaign (block rate) for one design's samples."""
    plan = model.plan
    k = plan.card.model.n_params
    sel = s["usable"]
    if not sel.any():
        return np.zeros((k, k))
    x = model.model_inputs(s, design=design)
    x = {key: (v[sel] if isinstance(v, np.ndarray) and len(v) == len(sel) else v) for key, v in x.items()}
    m = fisher_information(plan.card, x, plan.noise_std_db[s["mic"][sel]])
    return m * _blocks_per_sample(model)


def _blocks_per_sample(model: DesignModel) -> float:
    return 1.0 / (model.rate_hz * model.plan.doc["evaluation"]["block_s"])


def _logdet_batch(m: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.clip(np.einsum("spp->sp", m), 1e-300, None))
    sign, ld = np.linalg.slogdet(m / (d[:, :, None] * d[:, None, :]))
    out = ld + 2.0 * np.sum(np.log(d), axis=1)
    return np.where((sign > 0) & np.isfinite(out), out, -np.inf)


def _fisher_logdet_batch(model: DesignModel, s: Mapping[str, np.ndarray], designs: Sequence[Design]) -> np.ndarray:
    """``log det`` of the Fisher information of ``S`` designs (one row of ``s`` each)."""
    plan = model.plan
    card = plan.card
    if any(k in _VECTOR_INPUTS for k in card.model.inputs):  # kernels of vector inputs take one design at a time
        out = []
        for i, d in enumerate(designs):
            one = {k: (v[i] if v.ndim == 2 else v) for k, v in s.items()}
            out.append(_logdet(_fisher(model, one, d)))
        return np.array(out)
    x = model.model_inputs(s)
    _, jac = card.model.level_and_jacobian(card.p, x, d_ref=card.reference_distance_m)
    jac = np.broadcast_to(jac, s["d"].shape + (card.model.n_params,))
    w = s["usable"] / plan.noise_std_db[s["mic"]][None, :] ** 2
    m = np.matmul(jac.transpose(0, 2, 1) * w[:, None, :], jac) * _blocks_per_sample(model)
    return _logdet_batch(m)


def _objective_batch(model: DesignModel, name: str) -> Callable[[Sequence[Design]], np.ndarray]:
    """The minimized value for many designs at once: ``max |corr|`` (paper) or ``-log det`` (d-optimal)."""
    if name not in OBJECTIVES:
        raise InputError(f"objective must be one of {', '.join(OBJECTIVES)}, got {name!r}", field="objective")
    use = _pair_mask(PATTERN_PAIRS)

    def f(designs: Sequence[Design]) -> np.ndarray:
        s = model.samples_batch(np.array([d.mic_e for d in designs]), np.array([d.mic_n for d in designs]),
                                np.array([d.altitudes for d in designs]))
        if name == "paper":
            corr = _corr_batch(model, s)
            return np.max(np.abs(corr[:, use]), axis=1)
        ld = _fisher_logdet_batch(model, s, designs)
        # a singular design is worse than every regular one; a large finite value keeps the
        # population statistics of the evolution finite
        return np.where(np.isfinite(ld), -ld, 1e6)

    return f


# =========================================================================== optimizer


@dataclass(frozen=True, eq=False)
class Optimum:
    """Result of :func:`optimize`.

    Attributes
    ----------
    objective : str
    design : Design
    evaluation, base : Evaluation
        The optimum and the base design, each with both objectives.
    value, base_value : float
        The minimized value at the optimum and at the base (``max |corr|`` or ``-log det``).
    at_shift_limit : dict
        Microphone id -> True when it ended within 1 % of a displacement limit.
    at_altitude_bound : list of str
        Per repetition ``"min"``, ``"max"`` or ``""`` (within 1 % of the range from a bound).
    nit, nfev : int
        Generations and objective evaluations.
    success : bool
    message : str
    settings : dict
        Optimizer settings used (seed, popsize, maxiter, tol, constraint handling).
    """

    objective: str
    design: Design
    evaluation: Evaluation
    base: Evaluation
    value: float
    base_value: float
    at_shift_limit: dict[str, bool]
    at_altitude_bound: list[str]
    nit: int
    nfev: int
    success: bool
    message: str
    settings: dict[str, Any]

    def to_dict(self, plan: Plan) -> dict[str, Any]:
        return {"objective": self.objective, "value": self.value, "base_value": self.base_value,
                "design": self.evaluation.to_dict(plan), "at_shift_limit": dict(self.at_shift_limit),
                "at_altitude_bound": list(self.at_altitude_bound), "nit": self.nit, "nfev": self.nfev,
                "success": self.success, "message": self.message, "settings": dict(self.settings)}


def _limits(plan: Plan, design: Design, tol: float = 0.01) -> tuple[dict[str, bool], list[str]]:
    sh = np.column_stack([design.mic_e - plan.base.mic_e, design.mic_n - plan.base.mic_n])
    at_shift = {mid: bool(np.any((plan.max_shift[i] > 0) & (np.abs(sh[i]) >= (1 - tol) * plan.max_shift[i])))
                for i, mid in enumerate(plan.mic_ids)}
    at_alt = []
    for k, h in enumerate(design.altitudes):
        lo, hi = plan.altitude_range[k]
        span = hi - lo
        if span <= 0:
            at_alt.append("fixed")
        elif h <= lo + tol * span:
            at_alt.append("min")
        elif h >= hi - tol * span:
            at_alt.append("max")
        else:
            at_alt.append("")
    return at_shift, at_alt


def optimize(model: DesignModel, objective: str = "paper", *, x0: Design | None = None,
             maxiter: int | None = None, popsize: int | None = None, seed: int | None = None,
             tol: float | None = None, progress: Progress | None = None, cancel: CancelFn | None = None) -> Optimum:
    """Optimize the microphone positions and altitudes of ``model.plan`` for one objective.

    Parameters
    ----------
    model : DesignModel
        The plan's pattern flown once (:meth:`DesignModel.build`).
    objective : {"paper", "d-optimal"}
    x0 : Design, optional
        A design put into the initial population (default the plan's base design,
        clipped into the bounds); the optimum is never worse than it if it is feasible.
    maxiter, popsize, seed, tol : optional
        Override the plan's ``optimizer`` settings; the evolution stops when the
        objective values of its population spread (standard deviation) less than ``tol``
        (absolute: correlation units or log det units) or after ``maxiter`` generations.
    progress : callable, optional
        Called with the fraction of ``maxiter`` generations done.
    cancel : callable, optional
        Polled every generation; returning True raises :class:`~gisnoise.errors.Cancelled`.

    Returns
    -------
    Optimum
    """
    from scipy.optimize import NonlinearConstraint, differential_evolution

    plan = model.plan
    f_batch = _objective_batch(model, objective)
    opt = plan.doc["optimizer"]
    maxiter = int(opt["maxiter"] if maxiter is None else maxiter)
    popsize = int(opt["popsize"] if popsize is None else popsize)
    seed = int(opt["seed"] if seed is None else seed)
    tol = float(opt["tol"] if tol is None else tol)
    lo, hi = plan.bounds()
    free = hi > lo
    start = (plan.base if x0 is None else x0).vector(plan.base)
    start = np.clip(start, lo, hi)
    fixed_v = start.copy()

    def design_of(x: np.ndarray) -> Design:
        v = fixed_v.copy()
        v[free] = x
        return Design.from_vector(v, plan.base)

    def designs_of(xs: np.ndarray) -> list[Design]:
        xs = np.asarray(xs, dtype=float)
        return [design_of(xs)] if xs.ndim == 1 else [design_of(xs[:, i]) for i in range(xs.shape[1])]

    n_eval = [0]

    def energy(xs: np.ndarray) -> Any:
        # vectorized: xs has shape (n_free, S); the polish step sends one vector (n_free,)
        ds = designs_of(xs)
        n_eval[0] += len(ds)
        v = f_batch(ds)
        return float(v[0]) if np.ndim(xs) == 1 else v

    base_eval = evaluate(model)
    base_value = base_eval.objective(objective)
    settings = {"method": "scipy.optimize.differential_evolution", "strategy": "best1bin", "seed": seed,
                "popsize": popsize, "maxiter": maxiter, "tol": tol, "polish": bool(opt["polish"]), "workers": 1,
                "limits": "bounds of the variables (displacement box, altitude range)",
                "exclusions": ("nonlinear constraints: signed distance of each microphone to the exclusion polygons "
                               ">= 0 (Lampinen's feasibility rules, no penalty)") if plan.exclusions else "none",
                "free_variables": [n for n, f in zip(plan.variable_names(), free, strict=True) if f]}
    if not free.any():
        ev = evaluate(model, design_of(np.zeros(0)))
        at_shift, at_alt = _limits(plan, ev.design)
        return Optimum(objective=objective, design=ev.design, evaluation=ev, base=base_eval,
                       value=ev.objective(objective), base_value=base_value, at_shift_limit=at_shift,
                       at_altitude_bound=at_alt, nit=0, nfev=1, success=True,
                       message="no free variable: every displacement limit is 0 and every altitude range a point",
                       settings=settings)

    constraints: Any = ()
    if plan.exclusions:
        import shapely

        union = shapely.union_all(list(plan.exclusions))
        shapely.prepare(union)
        boundary = union.boundary
        shapely.prepare(boundary)
        # only microphones whose box reaches an exclusion constrain anything
        near = []
        for i in range(plan.n_mics):
            box = shapely.box(plan.base.mic_e[i] - plan.max_shift[i, 0], plan.base.mic_n[i] - plan.max_shift[i, 1],
                              plan.base.mic_e[i] + plan.max_shift[i, 0], plan.base.mic_n[i] + plan.max_shift[i, 1])
            if box.intersects(union):
                near.append(i)
        if near:
            near_a = np.array(near)

            def signed_distance(x: np.ndarray) -> np.ndarray:
                ds = designs_of(x)
                e = np.array([d.mic_e[near_a] for d in ds]).T  # (n_near, S)
                n = np.array([d.mic_n[near_a] for d in ds]).T
                dist = shapely.distance(boundary, shapely.points(e, n))
                val = np.where(shapely.contains_xy(union, e, n), -dist, dist)
                return val[:, 0] if np.ndim(x) == 1 else val

            constraints = NonlinearConstraint(signed_distance, 0.0, np.inf)

    gen = [0]

    def callback(xk: np.ndarray, convergence: float = 0.0) -> bool:
        gen[0] += 1
        if progress is not None:
            progress(min(1.0, gen[0] / maxiter))
        if cancel is not None and cancel():
            raise Cancelled("design optimization cancelled", field="cancel")
        return False

    kw: dict[str, Any] = {}
    if "rng" in inspect.signature(differential_evolution).parameters:
        kw["rng"] = seed
    else:  # scipy < 1.15
        kw["seed"] = seed
    with np.errstate(all="ignore"):
        res = differential_evolution(energy, list(zip(lo[free], hi[free], strict=True)),
                                     maxiter=maxiter, popsize=popsize, tol=0.0, atol=tol, polish=bool(opt["polish"]),
                                     callback=callback, x0=start[free], constraints=constraints, workers=1,
                                     updating="deferred", vectorized=True, init="latinhypercube", **kw)
    if progress is not None:
        progress(1.0)
    design = design_of(np.asarray(res.x, dtype=float))
    ev = evaluate(model, design)
    at_shift, at_alt = _limits(plan, design)
    return Optimum(objective=objective, design=design, evaluation=ev, base=base_eval, value=ev.objective(objective),
                   base_value=base_value, at_shift_limit=at_shift, at_altitude_bound=at_alt, nit=int(res.nit),
                   nfev=int(n_eval[0]), success=bool(res.success), message=str(res.message), settings=settings)


# =========================================================================== study (paper Fig. 18)


@dataclass(frozen=True)
class StudyPoint:
    """One optimization of the study: objective value for a displacement limit and an altitude range."""

    objective: str
    max_shift_m: float
    altitude_range_m: tuple[float, float]
    value: float
    max_abs_corr: float
    log_det_fisher: float
    altitudes_m: tuple[float, ...]
    shifts_m: tuple[tuple[float, float], ...]
    correlation: tuple[tuple[float, ...], ...]
    at_shift_limit: bool
    altitudes_at_bounds: bool

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["altitude_range_m"] = list(self.altitude_range_m)
        d["altitudes_m"] = list(self.altitudes_m)
        d["shifts_m"] = [list(s) for s in self.shifts_m]
        d["correlation"] = [list(r) for r in self.correlation]
        return d


def study(plan: Plan, *, objectives: Sequence[str] | None = None, displacements_m: Sequence[float] | None = None,
          altitude_ranges_m: Sequence[Sequence[float]] | None = None, maxiter: int | None = None,
          popsize: int | None = None, progress: Progress | None = None, cancel: CancelFn | None = None,
          model: DesignModel | None = None) -> list[StudyPoint]:
    """Optimum objective against the allowed displacement for several altitude ranges (paper Fig. 18).

    Every microphone gets the same displacement limit in both directions and every
    repetition the same altitude range.  Each run starts from the best design found
    for a range inside its own (a smaller displacement or a narrower altitude range),
    so the curves cannot rise where the feasible sets are nested.

    Defaults come from the plan's ``study`` section.
    """
    st = plan.doc["study"] or {}
    objectives = list(objectives if objectives is not None else st.get("objectives", ["paper"]))
    disps = sorted(float(x) for x in (displacements_m if displacements_m is not None
                                      else st.get("displacements_m", [0.0, 50.0, 200.0])))
    ranges = [tuple(float(v) for v in r) for r in (altitude_ranges_m if altitude_ranges_m is not None
                                                   else st.get("altitude_ranges_m", [[60.0, 60.0]]))]
    maxiter = int(maxiter if maxiter is not None else st.get("maxiter", 60))
    popsize = int(popsize if popsize is not None else st.get("popsize", plan.doc["optimizer"]["popsize"]))
    if model is None:
        model = DesignModel.build(plan)
    runs = [(o, r, s) for o in objectives for r in ranges for s in disps]
    out: list[StudyPoint] = []
    done: list[tuple[str, float, tuple[float, float], Design, float]] = []
    for i, (obj, rng, shift) in enumerate(runs):
        sub_plan = plan.with_limits(max_shift_m=shift, altitude_range_m=rng)
        sub = dataclasses.replace(model, plan=sub_plan)
        # warm start: the best earlier design whose limits lie inside these
        inner = [(val, d) for o, s, r, d, val in done
                 if o == obj and s <= shift and r[0] >= rng[0] and r[1] <= rng[1]]
        x0 = min(inner, key=lambda t: t[0])[1] if inner else None

        def sub_progress(f: float, i: int = i) -> None:
            if progress is not None:
                progress((i + f) / len(runs))

        res = optimize(sub, obj, x0=x0, maxiter=maxiter, popsize=popsize, progress=sub_progress, cancel=cancel)
        done.append((obj, shift, rng, res.design, res.value))
        ev = res.evaluation
        sh = tuple((float(ev.design.mic_e[j] - plan.base.mic_e[j]), float(ev.design.mic_n[j] - plan.base.mic_n[j]))
                   for j in range(plan.n_mics))
        out.append(StudyPoint(objective=obj, max_shift_m=shift, altitude_range_m=(rng[0], rng[1]), value=res.value,
                              max_abs_corr=ev.max_abs_corr, log_det_fisher=ev.log_det_fisher,
                              altitudes_m=tuple(float(a) for a in ev.design.altitudes), shifts_m=sh,
                              correlation=tuple(tuple(float(c) for c in row) for row in ev.correlation),
                              at_shift_limit=any(res.at_shift_limit.values()),
                              altitudes_at_bounds=all(a in ("min", "max", "fixed") for a in res.at_altitude_bound)))
    return out


# =========================================================================== closing the loop


@dataclass(frozen=True, eq=False)
class VerifyResult:
    """Closing the loop: campaigns simulated with each design and refitted (see :func:`verify`).

    Attributes
    ----------
    param_names : tuple of str
    truth : ndarray
        The card's parameters (the simulation's truth).
    estimates : dict
        Design name -> array (n_ok, n_params) of fitted parameters.
    empirical_std : dict
        Design name -> standard deviation of the estimates over the seeds.
    rms_error : dict
        Design name -> root mean square of ``estimate - truth`` over the seeds.
    expected_std : dict
        Design name -> Cramer-Rao standard deviation expected by the design model.
    mean_cr_std : dict
        Design name -> mean Cramer-Rao standard deviation reported by the fits.
    n_samples : dict
        Design name -> mean number of fitted samples.
    failures : dict
        Design name -> list of ``"seed: reason"`` of fits that failed.
    seeds : list of int
    duration_s : dict
        Design name -> flight time of the simulated campaign, s.
    background : str or None
        Name of the background parameter (its estimate is far from Gaussian where the UAV
        is loud everywhere; summaries are also given without it).
    """

    param_names: tuple[str, ...]
    truth: np.ndarray
    estimates: dict[str, np.ndarray]
    empirical_std: dict[str, np.ndarray]
    rms_error: dict[str, np.ndarray]
    expected_std: dict[str, np.ndarray]
    mean_cr_std: dict[str, np.ndarray]
    n_samples: dict[str, float]
    failures: dict[str, list[str]]
    seeds: list[int]
    duration_s: dict[str, float]
    background: str | None = None

    def ratio(self, design: str, reference: str = "base", *, what: str = "empirical_std") -> np.ndarray:
        """Per-parameter ratio of ``what`` (``empirical_std``, ``rms_error``, ``expected_std``) design / reference."""
        a = getattr(self, what)
        return np.asarray(a[design]) / np.asarray(a[reference])

    def geometric_mean_ratio(self, design: str, reference: str = "base", *, what: str = "empirical_std",
                             exclude: Sequence[str] = ()) -> float:
        """Geometric mean over the parameters (but ``exclude``) of :meth:`ratio`: the factor by which a
        typical deviation shrinks."""
        keep = np.array([k not in exclude for k in self.param_names])
        return float(np.exp(np.mean(np.log(self.ratio(design, reference, what=what)[keep]))))

    def to_dict(self) -> dict[str, Any]:
        designs = list(self.estimates)
        out: dict[str, Any] = {"param_names": list(self.param_names), "truth": self.truth.tolist(),
                               "seeds": list(self.seeds), "designs": {}}
        for d in designs:
            out["designs"][d] = {
                "n_fits": int(len(self.estimates[d])), "failures": list(self.failures[d]),
                "empirical_std": self.empirical_std[d].tolist(), "rms_error": self.rms_error[d].tolist(),
                "expected_std": self.expected_std[d].tolist(), "mean_cr_std": self.mean_cr_std[d].tolist(),
                "n_samples": self.n_samples[d], "duration_s": self.duration_s[d]}
            if d != "base" and "base" in self.estimates:
                out["designs"][d]["empirical_std_ratio_to_base"] = self.ratio(d).tolist()
                out["designs"][d]["geometric_mean_empirical_std_ratio"] = self.geometric_mean_ratio(d)
                out["designs"][d]["geometric_mean_rms_error_ratio"] = self.geometric_mean_ratio(d, what="rms_error")
                out["designs"][d]["geometric_mean_expected_std_ratio"] = self.geometric_mean_ratio(
                    d, what="expected_std")
                if self.background is not None:
                    out["designs"][d]["geometric_mean_empirical_std_ratio_without_background"] = (
                        self.geometric_mean_ratio(d, exclude=(self.background,)))
        return out


def campaign_scenario(model: DesignModel, design: Design, seed: int) -> dict[str, Any]:
    """Simulator scenario of a campaign flown with ``design`` (the plan's noise and background, no effects)."""
    plan = model.plan
    return _scenario_doc(plan.doc, plan.card, design, plan.doc["microphones"], seed=seed, start=model.start_en)


def verify(model: DesignModel, designs: Mapping[str, Design], seeds: Sequence[int], *,
           progress: Progress | None = None, cancel: CancelFn | None = None) -> VerifyResult:
    """Simulate a campaign with each design and seed, refit it, and compare the scatter of the estimates.

    Every campaign flies the same pattern (the same flight time; the climbs between
    repetitions happen inside the laps) with the same microphone noise and background
    (:func:`gisnoise.simulate.simulate.simulate_samples`, the card as truth, no injected effects).
    The horizontal samples within the signal-to-noise distance (selected by the logged
    geometry, not by the measured level, so the selection does not bias the fit) are
    fitted with :func:`gisnoise.identify.fit.fit` (the card's ansatz, one noise variance per
    microphone).  Seeds whose fit fails are listed, not hidden.
    """
    from gisnoise.identify.fit import fit, usable_rows
    from gisnoise.simulate import run, simulate_samples

    plan = model.plan
    card = plan.card
    names = card.model.params
    truth = card.p
    est: dict[str, list[np.ndarray]] = {k: [] for k in designs}
    crs: dict[str, list[np.ndarray]] = {k: [] for k in designs}
    nsamp: dict[str, list[int]] = {k: [] for k in designs}
    fails: dict[str, list[str]] = {k: [] for k in designs}
    dur: dict[str, float] = {}
    total = len(designs) * len(seeds)
    done = 0
    for name, design in designs.items():
        for seed in seeds:
            if cancel is not None and cancel():
                raise Cancelled("design verification cancelled", field="cancel")
            sim = run(campaign_scenario(model, design, int(seed)))
            dur[name] = float(sim.flights[0].true["t"][-1])
            s = simulate_samples(sim)
            rows = usable_rows(s, "horizontal")
            rows = rows.select(rows.d <= plan.max_distance_m)
            try:
                res = fit(rows, card.ansatz, reference_power_w=card.reference_power_w, p0=card)
            except (FitError, InputError) as exc:
                fails[name].append(f"{seed}: {exc}")
            else:
                est[name].append(res.p)
                crs[name].append(res.std_array)
                nsamp[name].append(len(rows))
            done += 1
            if progress is not None:
                progress(done / total)
    expected = {k: np.array([evaluate(model, d).expected_std[p] for p in names]) for k, d in designs.items()}
    e_arr = {k: np.array(v).reshape(-1, len(names)) for k, v in est.items()}
    emp = {k: (a.std(axis=0, ddof=1) if len(a) > 1 else np.full(len(names), np.nan)) for k, a in e_arr.items()}
    rms = {k: (np.sqrt(np.mean((a - truth) ** 2, axis=0)) if len(a) else np.full(len(names), np.nan))
           for k, a in e_arr.items()}
    mcr = {k: (np.mean(np.array(v), axis=0) if v else np.full(len(names), np.nan)) for k, v in crs.items()}
    return VerifyResult(param_names=tuple(names), truth=truth, estimates=e_arr, empirical_std=emp, rms_error=rms,
                        expected_std=expected, mean_cr_std=mcr,
                        n_samples={k: float(np.mean(v)) if v else 0.0 for k, v in nsamp.items()}, failures=fails,
                        seeds=[int(s) for s in seeds], duration_s=dur, background=card.model.background)


# =========================================================================== everything


@dataclass(frozen=True, eq=False)
class DesignResult:
    """Outcome of :func:`run_design`: base evaluation, optima, study and verification."""

    plan: Plan
    model: DesignModel
    base: Evaluation
    optima: dict[str, Optimum]
    study: list[StudyPoint]
    verify: VerifyResult | None

    def to_dict(self) -> dict[str, Any]:
        plan = self.plan
        return {
            "schema": RESULT_SCHEMA, "software": f"gisnoise {__version__}", "plan": plan.doc["name"],
            "card": {"id": plan.card.id, "ansatz": plan.card.ansatz, "parameters": dict(plan.card.parameters),
                     "reference_power_w": plan.card.reference_power_w},
            "origin": dict(plan.doc["origin"]),
            "snr": {"background_db": plan.background_db, "margin_db": plan.margin_db,
                    "max_distance_m": plan.max_distance_m},
            "pattern": dict(plan.doc["pattern"]), "duration_s": self.model.duration_s,
            "evaluation": dict(plan.doc["evaluation"]),
            "variables": {"names": plan.variable_names(), "lower": plan.bounds()[0].tolist(),
                          "upper": plan.bounds()[1].tolist()},
            "base": self.base.to_dict(plan),
            "optima": {k: o.to_dict(plan) for k, o in self.optima.items()},
            "study": [p.to_dict() for p in self.study],
            "verify": None if self.verify is None else self.verify.to_dict(),
        }


def run_design(plan: Plan, *, objectives: Sequence[str] | None = None, with_study: bool = True,
               verify_seeds: int | None = None, progress: Progress | None = None,
               cancel: CancelFn | None = None) -> DesignResult:
    """Evaluate the base design, optimize it for each objective, run the study and the verification.

    Parameters
    ----------
    plan : Plan
    objectives : sequence of str, optional
        Default the plan's ``objectives``.
    with_study : bool
        Run the plan's ``study`` (Fig. 18) when it has one.
    verify_seeds : int, optional
        Seeds of the closing-the-loop verification (default the plan's ``verify.seeds``;
        0 skips it).  Needs the ``d-optimal`` optimum.
    progress : callable, optional
        Called with the fraction done.
    """
    objectives = list(objectives if objectives is not None else plan.doc["objectives"])
    for o in objectives:
        if o not in OBJECTIVES:
            raise InputError(f"objective must be one of {', '.join(OBJECTIVES)}, got {o!r}", field="objective")
    n_verify = int(plan.doc["verify"]["seeds"] if verify_seeds is None else verify_seeds)
    st = plan.doc["study"] if with_study else None
    # work units: generations of each optimization, one per verification campaign
    w_opt = [float(plan.doc["optimizer"]["maxiter"])] * len(objectives)
    n_study = (len(st["objectives"]) * len(st["displacements_m"]) * len(st["altitude_ranges_m"])) if st else 0
    w_study = float(n_study * st["maxiter"]) if st else 0.0
    w_verify = (1.0 + len(objectives)) * n_verify * 10.0
    total = sum(w_opt) + w_study + w_verify
    done = [0.0]

    def stage(weight: float) -> Progress | None:
        if progress is None:
            return None
        start = done[0]
        done[0] += weight
        return lambda f: progress(min(1.0, (start + weight * f) / total))

    model = DesignModel.build(plan)
    base = evaluate(model)
    if base.n_usable < plan.card.model.n_params:
        raise DesignError(f"plan: field 'snr': the base design has {base.n_usable} samples within the "
                          f"signal-to-noise distance {plan.max_distance_m:.0f} m; the pattern does not come close "
                          f"enough to the microphones", field="snr")
    optima = {}
    for o, w in zip(objectives, w_opt, strict=True):
        optima[o] = optimize(model, o, progress=stage(w), cancel=cancel)
    pts = study(plan, model=model, progress=stage(w_study), cancel=cancel) if st else []
    ver = None
    if n_verify > 0:
        if "d-optimal" not in optima:
            raise InputError("verification compares the d-optimal design with the base: add 'd-optimal' to the "
                             "objectives", field="verify")
        first = int(plan.doc["verify"]["first_seed"])
        designs = {"base": plan.base, **{k: o.design for k, o in optima.items()}}
        ver = verify(model, designs, list(range(first, first + n_verify)), progress=stage(w_verify), cancel=cancel)
    if progress is not None:
        progress(1.0)
    return DesignResult(plan=plan, model=model, base=base, optima=optima, study=pts, verify=ver)


def layout_geojson(result: DesignResult) -> dict[str, Any]:
    """RFC 7946 FeatureCollection: microphones and track (lon, lat, ellipsoidal height) of the base and each optimum."""
    plan, model = result.plan, result.model
    feats: list[dict[str, Any]] = []
    designs = {"base": result.base, **{k: o.evaluation for k, o in result.optima.items()}}
    tr = model.track
    step = max(1, len(tr["t"]) // 2000)
    for name, ev in designs.items():
        d = ev.design
        lat, lon, h = plan.frame.to_wgs84(d.mic_e, d.mic_n, plan.mic_height_m)
        for i, mid in enumerate(plan.mic_ids):
            feats.append({"type": "Feature",
                          "geometry": {"type": "Point", "coordinates": [round(float(lon[i]), 9),
                                                                        round(float(lat[i]), 9),
                                                                        round(float(h[i]), 3)]},
                          "properties": {"kind": "microphone", "design": name, "id": mid,
                                         "e_m": round(float(d.mic_e[i]), 3), "n_m": round(float(d.mic_n[i]), 3),
                                         "de_m": round(float(d.mic_e[i] - plan.base.mic_e[i]), 3),
                                         "dn_m": round(float(d.mic_n[i] - plan.base.mic_n[i]), 3),
                                         "max_shift_m": [float(s) for s in plan.max_shift[i]],
                                         "n_usable": ev.n_usable_per_mic[mid]}})
        u = tr["weights"] @ d.altitudes
        idx = np.unique(np.append(np.arange(0, len(u), step), len(u) - 1))
        tlat, tlon, th = plan.frame.to_wgs84(tr["e"][idx], tr["n"][idx], u[idx])
        coords = [[round(float(a), 8), round(float(b), 8), round(float(c), 2)] for a, b, c in zip(tlon, tlat, th,
                                                                                                  strict=True)]
        feats.append({"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords},
                      "properties": {"kind": "track", "design": name,
                                     "altitudes_m": [round(float(a), 3) for a in d.altitudes],
                                     "duration_s": round(model.duration_s, 2)}})
    return {"type": "FeatureCollection", "features": feats}


def write_outputs(result: DesignResult, out_dir: str | os.PathLike[str], *, report: bool = True) -> dict[str, Path]:
    """Write ``design.json`` (variables, objectives, correlations, expected standard deviations,
    study and verification), ``layout.geojson`` (microphones and tracks) and, with ``report``,
    the report (:func:`gisnoise.design.report.write_report`).  Returns name -> path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {}
    doc = _finite(result.to_dict())
    p = out / "design.json"
    p.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    files["design.json"] = p
    p = out / "layout.geojson"
    p.write_text(json.dumps(layout_geojson(result), allow_nan=False) + "\n", encoding="utf-8")
    files["layout.geojson"] = p
    if report:
        from gisnoise.design.report import write_report

        files.update(write_report(result, out))
    return files


def _finite(obj: Any) -> Any:
    """JSON-safe copy: non-finite floats become None, numpy scalars plain numbers."""
    if isinstance(obj, Mapping):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _finite(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj
