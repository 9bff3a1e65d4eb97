"""Design plans: read and check a plan (schema ``gisnoise/design-plan/1``) and the designs it bounds.

A *plan* (JSON, see :func:`resolve_plan` and ``docs/design.md``) states the flight pattern
(racetrack loops of the simulator, repeated at one altitude per repetition), the current
microphone layout, how far each microphone may move (east and north, m), the altitude range
of each repetition, exclusion polygons where no microphone may stand, the signal-to-noise
margin and the model card.  :class:`Design` is one measurement design (microphone positions
and altitudes), :class:`Plan` the checked plan: its base design, the limits of the design
variables and the signal-to-noise distance.  The pattern and the fields passed on to the
simulator are checked by the simulator itself, on the scenario the plan flies
(:func:`_scenario_doc`, also used by the design model and the verification).
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.design.snr import snr_distance
from gisnoise.errors import DesignError, ScenarioError
from gisnoise.geo import LocalFrame
from gisnoise.jsonio import JsonObject, read_json_file
from gisnoise.model import PHASES, ModelCard, card_of_field

__all__ = ["SCHEMA", "OBJECTIVES", "Design", "Plan", "load_plan", "resolve_plan"]

SCHEMA = "gisnoise/design-plan/1"
OBJECTIVES = ("paper", "d-optimal")
"""The objectives a design can be optimized for (see :mod:`gisnoise.design.objectives`)."""

#: Callbacks of the long runs (optimizer, study, verification): ``progress(fraction done)``, and
#: ``cancel()`` polled on the way (True stops the run with :class:`~gisnoise.errors.Cancelled`).
Progress = Callable[[float], None]
CancelFn = Callable[[], bool]

#: Ansatz inputs the design model predicts (:meth:`gisnoise.design.designmodel.DesignModel.model_inputs`);
#: a card whose ansatz reads any other input is refused.
_SCALAR_INPUTS = ("d", "phi", "theta", "p_el", "bank", "roll", "pitch", "yaw", "speed", "t_e", "mic_agl", "meta")
_VECTOR_INPUTS = ("uav_enu", "mic_enu", "vel_enu")


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
    card: ModelCard
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

        Used by :func:`gisnoise.design.sweep.study` for the paper's Fig. 18; the result is checked like a plan.
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


def _load_card(ref: Any, base_dir: Path | None) -> ModelCard:
    if isinstance(ref, ModelCard):
        return ref
    return card_of_field(ref, "card", base_dir, _Doc)


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
    polys: list[Any] | None
    if t == "Polygon":
        polys = [coords]
    elif t == "MultiPolygon":
        polys = coords if isinstance(coords, list) else None
    else:
        raise DesignError(f"plan: field '{fld}.type' must be Polygon or MultiPolygon (lon/lat), got {t!r}",
                          field=f"{fld}.type")
    if polys is None:
        raise DesignError(f"plan: field '{fld}.coordinates' must be a list", field=f"{fld}.coordinates")
    out: list[list[list[list[float]]]] = []
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


def _scenario_doc(doc: Mapping[str, Any], card: ModelCard, design: Design, mics: Sequence[Mapping[str, Any]],
                  *, seed: int, start: Sequence[float] | np.ndarray | None, noise: bool = True) -> dict[str, Any]:
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
    vehicle["cards"] = {ph: card_doc for ph in PHASES}
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
                 card: ModelCard | None = None) -> Plan:
    """Check a plan document and fill in every default.

    Errors are :class:`~gisnoise.errors.DesignError` naming the field
    (``altitudes[1].min_m``, ``microphones[0].max_shift_m``, ``exclusions``, ...).
    An infeasible plan is refused: an altitude range with its minimum above its
    maximum, a negative displacement limit, exclusion polygons covering every
    position a microphone may take, or a displacement limit (also a study's) that lets a
    microphone leave the pattern's reach (farther than the signal-to-noise distance from
    every point of the pattern, :func:`_reach`).  A base altitude outside its own range is
    not refused: the base is the campaign as flown or planned, the range what the next one
    may use (:class:`~gisnoise.design.result.DesignResult` warns).

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
            e_enu, n_enu, _ = frame.to_enu(lat, lon, out["origin"]["h"])
            e, n = float(e_enu), float(n_enu)
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
            ex = json.loads(p.read_text(encoding="utf-8-sig"))
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
    _check_reach(out, base, shift, float(dmax))
    return dataclasses.replace(plan, max_distance_m=float(dmax))


def _reach(doc: Mapping[str, Any], e: float, n: float, dmax: float) -> float:
    """How far a microphone at (``e``, ``n``) m may usefully move, m: beyond, it cannot hear the pattern.

    Every point of the racetrack lies within ``straight_m / 2 + radius_m`` of its centre (horizontally);
    a microphone moved along one axis by more than its distance from the centre plus that plus the
    signal-to-noise distance ``dmax`` is farther than ``dmax`` from every point of the pattern, where the
    UAV's level has fallen below the background plus the margin: no sample it could record would count.
    """
    pat = doc["pattern"]
    ce, cn = (float(v) for v in pat["centre"])
    return float(math.hypot(e - ce, n - cn) + float(pat["straight_m"]) / 2.0 + float(pat["radius_m"]) + dmax)


def _check_reach(doc: Mapping[str, Any], base: Design, shift: np.ndarray, dmax: float) -> None:
    """Refuse a displacement limit (or a study's displacement) that lets a microphone leave the pattern's reach."""
    reach = [_reach(doc, float(base.mic_e[i]), float(base.mic_n[i]), dmax) for i in range(len(base.mic_e))]
    for i, m in enumerate(doc["microphones"]):
        if float(np.max(shift[i])) > reach[i]:
            raise DesignError(
                f"plan: field 'microphones[{i}].max_shift_m' ({float(np.max(shift[i])):g} m) lets microphone "
                f"{m['id']!r} move beyond {reach[i]:.0f} m, where it stands farther than the signal-to-noise distance "
                f"({dmax:.0f} m) from every point of the pattern: the UAV's level falls below the background plus the "
                f"margin there and no sample it records would count; give at most {reach[i]:.0f} m",
                field=f"microphones[{i}].max_shift_m")
    st = doc.get("study")
    if st and max(st["displacements_m"]) > min(reach):
        i = int(np.argmin(reach))
        raise DesignError(
            f"plan: field 'study.displacements_m' ({max(st['displacements_m']):g} m) lets microphone "
            f"{doc['microphones'][i]['id']!r} move beyond {reach[i]:.0f} m, where it stands farther than the "
            f"signal-to-noise distance ({dmax:.0f} m) from every point of the pattern; give at most {reach[i]:.0f} m",
            field="study.displacements_m")


def _enu_polygon(poly: list[list[list[float]]], frame: LocalFrame, h0: float) -> Any:
    from gisnoise.geo import shapes as shapely

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
    from gisnoise.geo import shapes as shapely

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
