"""Pydantic request and response models of the service, and its media types."""

from __future__ import annotations

import re
from enum import Enum
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, WithJsonSchema

from gisnoise import limits as _limits
from gisnoise.errors import GisnoiseError
from gisnoise.flight import OPTIONAL_COLUMNS, REQUIRED_COLUMNS
from gisnoise.limits import CARD_REF_PATTERN, SAFE_ID_PATTERN
from gisnoise.model import EFFECT_NAMES, PHASES, ansatz_names, get_ansatz
from gisnoise.model.plausibility import REFERENCE_DISTANCE_RANGE_M

__all__ = [
    "MediaType", "ErrorBody", "FieldError", "CardDocument", "CardInfo", "CardList", "CardVersions",
    "JobInfo", "JobList", "JobError", "GridRequest", "ContourRequest", "Health", "PhaseName",
    "TrajectoryInput", "LogTrajectory", "Metric", "MapLevel", "OutputFormat", "SafeId", "CardRef", "FileName", "AnsatzName", "CARD_SCHEMAS",
    "TRAJECTORY_COLUMNS",
]


def _matching(pattern: str, what: str) -> Any:
    rx = re.compile(pattern)

    def check(value: str) -> str:
        if rx.fullmatch(value) is None:
            raise ValueError(f"{value!r} is not a valid {what}: letters, digits, '-', '_', '.', no leading dot, "
                             "no reserved device name (con, nul, com1 ...), at most 128 characters")
        return value

    return AfterValidator(check)


SafeId = Annotated[str, _matching(SAFE_ID_PATTERN, "identifier"),
                   WithJsonSchema({"type": "string", "pattern": SAFE_ID_PATTERN, "minLength": 1, "maxLength": 128})]
"""An identifier of a card, job or layer: one safe pattern, stated in the OpenAPI schema."""

FileName = Annotated[str, Field(min_length=1, max_length=255, pattern=r"^[A-Za-z0-9._/-]+$")]
"""A result file name of a job (looked up in the job's listing, never joined to a path)."""



class MediaType(str, Enum):
    """Every media type the service reads or writes."""

    json = "application/json"
    geojson = "application/geo+json"
    geotiff = "image/tiff; application=geotiff"
    zip = "application/zip"
    csv = "text/csv"
    html = "text/html"
    png = "image/png"
    octet = "application/octet-stream"


class OutputFormat(str, Enum):
    geojson = "geojson"
    geotiff = "geotiff"


PhaseName = Literal["horizontal", "climb", "sink", "hover", "transition"]
assert set(PhaseName.__args__) == set(PHASES)  # type: ignore[attr-defined]

Metric = Literal["LAmax", "LAeq", "SEL"]

CARD_SCHEMAS = ("gisnoise/model-card/1", "gisnoise/hemisphere-card/1")
"""The card documents the store takes (an ansatz card, a measured hemisphere card)."""

_BASES = tuple(n for n in ansatz_names() if "+" not in n)
_ANSATZ_PATTERN = (rf"^(hemisphere|({'|'.join(re.escape(b) for b in _BASES)})"
                   rf"(\+({'|'.join(re.escape(e) for e in EFFECT_NAMES)}))*)$")
"""An ansatz name: ``hemisphere``, or a base of the registry with effects of the library joined by ``+``."""


def _known_ansatz(value: str) -> str:
    """``value`` when it names the hemisphere or an ansatz the registry has or builds (a chain ``base+e1+e2``)."""
    if value != "hemisphere" and re.fullmatch(_ANSATZ_PATTERN, value) is None:
        raise ValueError(f"{value!r} is not a known ansatz: 'hemisphere', or one of {', '.join(_BASES)} with effects "
                         f"of {', '.join(EFFECT_NAMES)} joined by '+' (e.g. 'paper-offset+bank_angle+rpm')")
    if value != "hemisphere":
        try:
            get_ansatz(value)
        except GisnoiseError as exc:
            raise ValueError(str(exc)) from None
    return value


def _one_of(values: tuple[str, ...], what: str) -> Any:
    def check(value: str) -> str:
        if value not in values:
            raise ValueError(f"{value!r} is not a known {what}; known: {', '.join(values)}")
        return value

    return AfterValidator(check)


def _length(lo: int, hi: int) -> Any:
    """A string of ``lo``..``hi`` characters, checked after parsing (lone surrogates stay data, as JSON allows)."""

    def check(value: str) -> str:
        if not lo <= len(value) <= hi:
            raise ValueError(f"must have {lo} to {hi} characters, has {len(value)}")
        return value

    return AfterValidator(check)


def _map_level(value: float) -> float:
    """A level asked of a map within :data:`gisnoise.limits.MEASURED_LEVEL_RANGE_DB` (the core's
    :func:`~gisnoise.limits.check_map_level`, said with its reason)."""
    lo, hi = _limits.MEASURED_LEVEL_RANGE_DB
    if not lo <= value <= hi:
        raise ValueError(f"a level must lie within [{lo:g}, {hi:g}] dB(A) ({_limits.MAP_LEVEL_WHY})")
    return value


MapLevel = Annotated[float, AfterValidator(_map_level),
                     WithJsonSchema({"type": "number", "minimum": _limits.MEASURED_LEVEL_RANGE_DB[0],
                                     "maximum": _limits.MEASURED_LEVEL_RANGE_DB[1], "description": "dB(A)"})]
"""An A-weighted level asked of a map (contour level, time-above threshold), dB(A), within [-50, 200]."""


_Vehicle = Annotated[str, _length(1, 200), WithJsonSchema({"type": "string", "minLength": 1, "maxLength": 200})]
_Notes = Annotated[str, _length(0, 100_000), WithJsonSchema({"type": "string", "maxLength": 100_000})]


AnsatzName = Annotated[str, AfterValidator(_known_ansatz), WithJsonSchema({"type": "string", "maxLength": 200,
                                                                          "pattern": _ANSATZ_PATTERN})]
"""An ansatz of the registry (``paper``, ``paper-offset``, ``<base>+<effect>``) or ``hemisphere``."""


# ---------------------------------------------------------------- errors
class FieldError(BaseModel):
    field: str = Field(description="Dotted path of the invalid field, e.g. 'grid.resolution_m'.")
    message: str
    type: str = ""


class ErrorBody(BaseModel):
    """Body of every 4xx/5xx response."""

    detail: str = Field(description="One line naming the field and the bad value.")
    field: str | None = Field(description="The field the error is about (dotted path), or null.")
    errors: list[FieldError] | None = Field(default=None, description="Every invalid field of a rejected body.")


# ---------------------------------------------------------------- cards
class CardDocument(BaseModel):
    """A model card (``gisnoise/model-card/1``, SPEC section 4); validated by the core on upload."""

    model_config = ConfigDict(extra="allow", populate_by_name=True, strict=True, json_schema_extra={"example": {
        "schema": "gisnoise/model-card/1", "id": "my-horizontal", "vehicle": "demo 35 kg cargo eVTOL",
        "phase": "horizontal", "ansatz": "paper-offset",
        "parameters": {"p0": 64.0, "p1": 20.0, "p2": 0.03, "p3": -0.28, "p4": -0.05, "p5": 1.05, "p6": 1.0,
                       "p7": 40.0},
        "reference_power_w": 3000.0, "reference_distance_m": 40.0, "covariance": None, "notes": "",
        "phases": ["transition"]}})

    schema_: Literal["gisnoise/model-card/1", "gisnoise/hemisphere-card/1"] = Field(
        alias="schema", description="'gisnoise/model-card/1' (an ansatz card) or 'gisnoise/hemisphere-card/1'")
    id: SafeId
    vehicle: _Vehicle
    phase: PhaseName
    ansatz: AnsatzName
    parameters: dict[Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]{0,31}$")], float] = Field(
        max_length=64, description="Parameter name -> value; exactly the parameters of the ansatz.")
    reference_power_w: float = Field(gt=0, le=1e9, description="Reference electric power, W.")
    reference_distance_m: float = Field(
        default=40.0, gt=0, le=1e6, json_schema_extra={"minimum": REFERENCE_DISTANCE_RANGE_M[0],
                                                       "maximum": REFERENCE_DISTANCE_RANGE_M[1]},
        description="Reference distance, m: 1 m to 1 km; the card's plausibility check refuses a card stated "
                    "outside it (422 naming reference_distance_m).")
    covariance: list[Annotated[list[float], Field(max_length=64)]] | None = Field(
        default=None, max_length=64, description="Covariance of the parameters (their order), or null.")
    statistics: dict[str, Any] = Field(default_factory=dict)
    provenance: dict[str, Any] = Field(default_factory=dict)
    notes: _Notes = ""
    phases: list[PhaseName] = Field(default_factory=list, max_length=len(PHASES),
                                    description="Further phases the card serves.")


class CardInfo(BaseModel):
    id: str
    version: int = Field(description="Latest version (1, 2, ...).")
    versions: list[int]
    vehicle: str
    phase: str
    phases: list[str] = Field(description="Every phase the card serves (its phase first).")
    ansatz: str
    reference_power_w: float
    has_covariance: bool
    notes: str
    url: str


class CardList(BaseModel):
    cards: list[CardInfo]


class CardVersions(BaseModel):
    id: str
    versions: list[int]


# ---------------------------------------------------------------- jobs
class JobError(BaseModel):
    detail: str
    field: str | None
    status: int | None = Field(description="HTTP status the same error has in a synchronous request.")


class JobInfo(BaseModel):
    id: str
    kind: Literal["contours", "fit", "diagnose"]
    status: Literal["queued", "running", "succeeded", "failed", "cancelled"]
    progress: float = Field(ge=0, le=1, description="Fraction done, 0..1.")
    message: str = Field(description="The last progress while the job runs, then done, failed or cancelled; a "
                                     "succeeded job whose result was removed from the server says so.")
    created: float = Field(description="Unix time, s.")
    started: float | None = Field(description="Unix time of the current start, s; null while queued (a re-queued "
                                              "job too).")
    finished: float | None
    attempts: int = Field(description="Starts of the job; more than 1 after a restart re-ran it.")
    cancel_requested: bool
    error: JobError | None = Field(description="Why the job failed: the detail, field and status a synchronous "
                                               "request would answer; field storage (status 507 or 503) when the "
                                               "service's storage failed under it.")
    summary: dict[str, Any] | None = Field(
        description="The result of a succeeded job: the numbers its kind reports.  Fit and diagnose jobs carry "
                    "`warnings` (list of str, empty when none): what the command line says about the campaign's "
                    "flight logs (a log cut short, say), one line each.  A fit or diagnose job that fails after "
                    "reading the campaign has the summary {\"warnings\": [...]} (empty or not); null otherwise.")
    files: list[str] = Field(description="Result files, downloadable at /jobs/{id}/files/{name}.")
    url: str
    result_url: str | None = Field(description="The main result of a succeeded job; null otherwise, and when its "
                                               "result was removed from the server.")


class JobList(BaseModel):
    jobs: list[JobInfo]
    total: int


class WorkerHealth(BaseModel):
    started: int = Field(description="Job worker threads started.")
    alive: int = Field(description="Of them, alive (fewer than started: jobs are not run; restart the service).")


class Health(BaseModel):
    status: Literal["ok", "failing"] = Field(
        description="ok, or failing (answered with 503) when a job worker died or the job database cannot be read "
                    "or written; `problems` says which.")
    version: str
    queued: int | None = Field(description="Queued jobs (null when the job database cannot be read).")
    running: int | None = Field(description="Running jobs (null when the job database cannot be read).")
    workers: WorkerHealth
    free_bytes: int | None = Field(None, description="Space left on the device of the data folder, bytes.")
    problems: list[str] = Field(default_factory=list, description="One line per problem, naming what fails.")


# ---------------------------------------------------------------- contours
class CsvTrajectory(BaseModel):
    """A flight CSV (SPEC section 3 columns) as text."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    format: Literal["csv"]
    text: str = Field(min_length=1, max_length=100_000_000,
                      description="Flight CSV text: t, lat, lon, h, roll, pitch, yaw, power_w[, phase]")


_LIM = _limits.current()  # the rule set's limits when the service starts (GISNOISE_MAX_POWER_W, ...)
_N = Field(min_length=_limits.MIN_SAMPLES, max_length=_LIM.max_samples)


_T = Annotated[float, Field(description="s")]
_LAT = Annotated[float, Field(ge=-90, le=90, description="deg")]
_LON = Annotated[float, Field(ge=-180, le=180, description="deg (never wrapped)")]
_H = Annotated[float, Field(ge=_LIM.min_height_m, le=_LIM.max_height_m, description="ellipsoidal height, m")]
_ANGLE = Annotated[float, Field(ge=-180, le=180, description="deg")]
_YAW = Annotated[float, Field(ge=-360, le=360, description="deg (wrapped)")]
_POWER = Annotated[float, Field(ge=0, le=_LIM.max_power_w, description="electric power, W")]

TRAJECTORY_COLUMNS = (*REQUIRED_COLUMNS, *OPTIONAL_COLUMNS)
"""The columns of a flight (SPEC section 3, :mod:`gisnoise.flight`), each with the range of :mod:`gisnoise.limits`."""


class FlightColumns(BaseModel):
    """Flight-CSV columns as arrays of equal length (at least two samples, times strictly increasing)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    t: list[_T] = _N
    lat: list[_LAT] = _N
    lon: list[_LON] = _N
    h: list[_H] = _N
    roll: list[_ANGLE] = _N
    pitch: list[_ANGLE] = _N
    yaw: list[_YAW] = _N
    power_w: list[_POWER] = _N
    phase: list[PhaseName] | None = Field(default=None, min_length=_limits.MIN_SAMPLES, max_length=_LIM.max_samples)
    rpm: list[float] | None = Field(default=None, min_length=_limits.MIN_SAMPLES, max_length=_LIM.max_samples)
    airspeed_m_s: list[float] | None = Field(default=None, min_length=_limits.MIN_SAMPLES,
                                             max_length=_LIM.max_samples)
    on_ground: list[Literal[0, 1]] | None = Field(default=None, min_length=_limits.MIN_SAMPLES,
                                                  max_length=_LIM.max_samples)


class FlightRow(BaseModel):
    """One log sample (the flight-CSV columns of one row)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    t: _T
    lat: _LAT
    lon: _LON
    h: _H
    roll: _ANGLE
    pitch: _ANGLE
    yaw: _YAW
    power_w: _POWER
    phase: PhaseName | None = None
    rpm: float | None = None
    airspeed_m_s: float | None = None
    on_ground: Literal[0, 1] | None = None


assert set(FlightColumns.model_fields) == set(TRAJECTORY_COLUMNS) == set(FlightRow.model_fields)


class ColumnsTrajectory(BaseModel):
    """Flight-CSV columns as arrays."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    format: Literal["columns"]
    columns: FlightColumns = Field(description="Column name -> values (" + ", ".join(TRAJECTORY_COLUMNS) + ")")


class RowsTrajectory(BaseModel):
    """Flight-CSV rows as objects."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    format: Literal["rows"]
    rows: list[FlightRow] = Field(min_length=_limits.MIN_SAMPLES, max_length=_LIM.max_samples,
                                  description="One object per log sample (the same fields in each).")


_NUMBER = {"type": "number"}
_WAYPOINT = {
    "type": "object", "required": ["lon", "lat", "alt"],
    "properties": {
        "lon": {"type": "number", "minimum": -180, "maximum": 180, "description": "deg (never wrapped)"},
        "lat": {"type": "number", "minimum": -90, "maximum": 90, "description": "deg"},
        "alt": {"type": "number", "description": "m above the altitude_reference"},
        "speed": {"type": ["number", "null"], "exclusiveMinimum": 0, "description": "m/s"},
        "hold_s": {"type": "number", "minimum": 0, "maximum": _LIM.max_duration_s, "description": "s"},
        "phase": {"enum": [*PHASES, None]},
        "heading_deg": {"type": ["number", "null"], "description": "deg"}}}
_ROUTE_SETTINGS = {
    "altitude_reference": {"enum": ["agl", "msl", "ellipsoid"]},
    "ground_h_m": _NUMBER, "geoid_undulation_m": _NUMBER,
    "sample_dt_s": {"type": "number", "exclusiveMinimum": 0, "maximum": 10, "description": "s"}}
_ROUTE_DATA_SCHEMA: dict[str, Any] = {"anyOf": [
    {"title": "Waypoints document", "type": "object", "required": ["schema", "waypoints"],
     "properties": {"schema": {"const": "gisnoise/waypoints/1"},
                    "waypoints": {"type": "array", "minItems": 2, "items": _WAYPOINT}, **_ROUTE_SETTINGS}},
    {"title": "GeoJSON", "type": "object", "required": ["type"],
     "description": "A FeatureCollection of Point waypoints (properties as a waypoint's; route settings in a "
                    "'route' member) or of one LineString, a Feature or a bare LineString with Z (and times in "
                    "properties.times, or as a fourth coordinate)",
     "properties": {"type": {"enum": ["FeatureCollection", "Feature", "LineString"]}}}]}


class GeoJSONTrajectory(BaseModel):
    """A GeoJSON LineString with Z and times, or waypoints (SPEC section 7) as GeoJSON or JSON."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    format: Literal["geojson", "waypoints"]
    data: Annotated[dict[str, Any], WithJsonSchema(_ROUTE_DATA_SCHEMA)] = Field(
        description="GeoJSON object (Feature, FeatureCollection, LineString) or waypoint document, as read by "
                    "gisnoise.flight.routes.read_trajectory")


class LogTrajectory(BaseModel):
    """A flight log file, base64-encoded: PX4 ULog (``.ulg``) or ArduPilot DataFlash (``.bin``), any letter case.

    Read by the same reader as the command line (``gisnoise.flight.read_route``): on-ground samples are
    silent, heights above mean sea level get the EGM96 geoid undulation unless ``geoid_undulation_m`` is given,
    a log without battery current needs ``power_w``.
    """

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    format: Literal["log"]
    name: str = Field(pattern=r"^[A-Za-z0-9_][A-Za-z0-9._-]{0,99}\.([uU][lL][gG]|[bB][iI][nN])$",
                      description="File name; its suffix (.ulg or .bin, any case) selects the reader.")
    data_base64: str = Field(min_length=4, description="The log file's bytes, base64 (RFC 4648).")
    geoid_undulation_m: float | None = Field(
        default=None, ge=-150, le=150, description="Geoid undulation, m, for heights above mean sea level "
                                                   "(default: the EGM96 grid at each sample).")
    power_w: float | None = Field(default=None, gt=0, le=1e7,
                                  description="Constant electric power, W, for a log without battery current.")


TrajectoryInput = Annotated[CsvTrajectory | ColumnsTrajectory | RowsTrajectory | GeoJSONTrajectory | LogTrajectory,
                            Field(discriminator="format")]


class GridRequest(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    resolution_m: float = Field(default=10.0, ge=0.1, le=100_000, description="Cell size, m (0.1 m or more).")
    margin_m: float | None = Field(
        default=None, ge=0, le=1_000_000,
        description="Margin around the track, m; default from the cards, so the lowest level's LAmax and LAeq "
                    "contours close.  Contours cut by the grid's edge carry \"clipped\": true.")
    crs: str | None = Field(default=None, description="Grid CRS (e.g. 'EPSG:25832'); default a local UTM zone.")


CardRef = Annotated[str, _matching(CARD_REF_PATTERN, "card reference"),
                    WithJsonSchema({"type": "string", "pattern": CARD_REF_PATTERN, "minLength": 1, "maxLength": 138,
                                    "description": "Card id in the store, or 'id@version'."})]


_ROUTE_EXAMPLE: dict[str, Any] = {"type": "FeatureCollection", "route": {"altitude_reference": "agl"}, "features": [
    {"type": "Feature", "geometry": {"type": "Point", "coordinates": c}, "properties": p}
    for c, p in [([10.540, 52.243], {"alt": 0}), ([10.540, 52.243], {"alt": 60}),
                 ([10.550, 52.250], {"alt": 60, "speed": 22}), ([10.550, 52.250], {"alt": 0})]]}


class ContourRequest(BaseModel):
    """A noise map of one trajectory."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, json_schema_extra={"example": {
        "trajectory": {"format": "waypoints", "data": _ROUTE_EXAMPLE},
        "cards": ["demo-horizontal", "demo-climb", "demo-sink"], "grid": {"resolution_m": 20, "margin_m": 400},
        "metrics": ["LAmax", "LAeq"], "levels": [45, 50, 55, 60]}})
    trajectory: TrajectoryInput
    cards: list[CardRef | CardDocument] = Field(
        default_factory=list, max_length=32,
        description="Cards by id ('demo-horizontal', 'demo-horizontal@2') or inline documents; each serves "
                    "its phase and phases.")
    phase_cards: dict[PhaseName, CardRef] = Field(
        default_factory=dict, description="Phase -> card id: the card serves exactly that phase "
                                          "(overrides the phases the card states).")
    grid: GridRequest = Field(default_factory=GridRequest)
    metrics: list[Metric] = Field(default=["LAmax", "LAeq", "SEL"], max_length=3,
                                  description="Bands LAmax, LAeq, SEL (dB(A)); time above and snapshot are asked "
                                              "for with threshold_db and snapshot_t.")
    levels: list[MapLevel] = Field(default=[45.0, 50.0, 55.0, 60.0], min_length=1, max_length=40,
                                   description="Contour levels, dB(A), each within [-50, 200] (the A-weighted "
                                               "levels a microphone records); drawn in ascending order, a level "
                                               "given twice is drawn once (gisnoise.levels of the GeoJSON lists "
                                               "the levels drawn).")
    receiver_height_m: float = Field(default=1.5, ge=0, le=1000, description="Receiver height above ground, m.")
    ground_h_m: float | None = Field(default=None, ge=-1000, le=9000,
                                     description="Flat ground's ellipsoidal height, m; default the trajectory's "
                                                 "lowest point.")
    background: bool = Field(default=False, description="Add the card's background level (Eq. 8).")
    period_s: float | None = Field(default=None, gt=0, le=1e7, description="LAeq period, s (default duration).")
    threshold_db: list[MapLevel] | None = Field(
        default=None, max_length=10, description="Levels of time-above bands TA<level> (s), dB(A).")
    snapshot_t: float | None = Field(default=None, ge=-1e7, le=1e7,
                                     description="Instant of a snapshot band LA@<t>s, s (within the trajectory).")
    substeps: int = Field(default=1, ge=1, le=50, description="Time steps per trajectory sample interval.")
    uncertainty: bool = Field(default=False, description="Add LAmax/LAeq standard-deviation bands "
                                                         "(cards need a covariance).")
    output: Literal["geojson", "geotiff"] | None = Field(default=None, description="Response format; default from the Accept "
                                                                  "header, else GeoJSON.")
