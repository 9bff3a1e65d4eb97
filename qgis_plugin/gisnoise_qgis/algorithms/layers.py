"""Trajectory columns from a QGIS vector layer (points, or lines with Z and M).

The result is the flight-CSV column dictionary that
``gisnoise.flight.trajectory.from_columns`` takes; positions are transformed to WGS84
longitude and latitude through QGIS's own transform of the layer's CRS.

Point layers have one feature per log sample: time, attitude, power and phase
come from attribute fields, the height from a field or from the point's Z.
Line layers have one sample per vertex: time is the vertex's M value, height
its Z value; attitude, power and phase come from the feature's fields (the same
for all its vertices), and the heading (yaw) is the direction of travel along
the line unless a yaw field is given.

Field parameters left at their default name that the layer lacks mean "not in the
layer" when the column has a fallback (height: the geometry's Z; roll, pitch: 0 deg;
for lines time: the M values, yaw: along the line; phase: horizontal), said in the log,
unless a field of the layer looks like that column (``altitude`` for the height): then
which one is meant is asked, not guessed.  Every field parameter that does not fit the
layer is named in one message.
"""

from __future__ import annotations

import math
import re

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsCoordinateTransform,
    QgsFeatureRequest,
    QgsProcessingException,
    QgsWkbTypes,
)

WGS84 = "EPSG:4326"

#: Column of a flown track -> (what it is, the parameter naming its field, names a layer's field for it often has,
#: lower case).  Such names are only suggested in messages, never read without being named in the parameter: a
#: field called ``time`` may hold milliseconds or clock times, one called ``altitude`` heights above the ground.
TRACK_COLUMNS = {
    "t": ("time", "TIME_FIELD", ("t", "time", "times", "timestamp", "time_s", "t_s", "t_sec", "time_sec", "seconds",
                                 "secs", "elapsed", "elapsed_s", "datetime", "date_time", "gps_time", "time_utc",
                                 "utc", "time_ms", "time_us", "timeus", "time_boot_ms", "flight_time")),
    "h": ("height", "ALTITUDE_FIELD", ("h", "h_m", "height", "height_m", "alt", "alt_m", "altitude", "altitude_m",
                                       "hae", "height_ellipsoid", "ellipsoidal_height", "elevation", "z")),
    "roll": ("roll", "ROLL_FIELD", ("roll", "roll_deg", "phi")),
    "pitch": ("pitch", "PITCH_FIELD", ("pitch", "pitch_deg", "theta")),
    "yaw": ("yaw", "YAW_FIELD", ("yaw", "yaw_deg", "heading", "heading_deg", "hdg", "psi")),
    "power_w": ("electric power", "POWER_FIELD", ("power_w", "power", "power_watts", "watts", "electric_power",
                                                  "electric_power_w", "p_el", "p_el_w")),
    "phase": ("phase", "PHASE_FIELD", ("phase", "flight_phase")),
}


def _like(col, layer_fields, exclude=()):
    """The layer's fields whose names look like the column ``col`` (:data:`TRACK_COLUMNS`)."""
    alike = TRACK_COLUMNS[col][2]
    return [n for n in layer_fields.names() if n.lower() in alike and n not in exclude]


def track_evidence(layer_fields):
    """The fields that make a layer look like a flown track rather than a waypoint plan: a time, roll, pitch or
    electric power field (by the names of :data:`TRACK_COLUMNS`; yaw and height are in plans too)."""
    return [n for n in layer_fields.names()
            if any(n.lower() in TRACK_COLUMNS[c][2] for c in ("t", "roll", "pitch", "power_w"))]


def _quoted(names):
    return ", ".join(f"'{n}'" for n in names)


def track_fields(source, fields, defaults=None):
    """Which layer field gives each column of a flown track, and what is taken instead of a missing one.

    Parameters
    ----------
    source : QgsFeatureSource
        Points or lines.
    fields : dict
        Column -> the name in its field parameter (empty: not in the layer).
    defaults : dict, optional
        Column -> the parameter's default name: a default name the layer lacks means "not in the layer"
        where the column has a fallback and no field of the layer looks like it.

    Returns
    -------
    names : dict
        Column -> the layer's field name, or ``""`` (from the geometry or the fallback).
    notes : list of str
        What was taken for a default name the layer lacks, one line each (for the log).
    problems : list of str
        One clause per field parameter that does not fit the layer, naming it and the fields that look
        like the column; empty when the layer can be read.
    """
    defaults = defaults or {}
    wkb = source.wkbType()
    is_line = QgsWkbTypes.geometryType(wkb) == QgsWkbTypes.LineGeometry
    has_z, has_m = QgsWkbTypes.hasZ(wkb), QgsWkbTypes.hasM(wkb)
    layer_fields = source.fields()
    fallbacks = {"h": ("the vertices' Z" if is_line else "the points' Z") if has_z else None,
                 "roll": "0 deg", "pitch": "0 deg", "yaw": "the direction along the line" if is_line else None,
                 "phase": "horizontal", "t": None, "power_w": None}
    given = {col: (fields.get(col) or "").strip() for col in TRACK_COLUMNS}
    named = {layer_fields.at(layer_fields.lookupField(n)).name() for n in given.values()
             if n and layer_fields.lookupField(n) >= 0}
    names, notes, problems = {}, [], []
    for col, (what, param, _) in TRACK_COLUMNS.items():
        name = given[col]
        default = defaults.get(col)
        idx = layer_fields.lookupField(name) if name else -1
        if col == "t" and is_line:  # a line's times are its vertices' M values
            names[col] = ""
            if not has_m:
                problems.append(f"its lines carry no M values (time, s), and a line's time cannot come from a field "
                                f"(parameter {param})")
            elif name and name != default:
                problems.append(f"the time of each vertex is its M value: leave {param} empty, not '{name}'")
            elif name and idx >= 0:
                notes.append(f"time from the lines' M values (field '{name}' of {param} not read)")
            continue
        if idx >= 0:
            names[col] = layer_fields.at(idx).name()
            continue
        fallback = fallbacks[col]
        like = _like(col, layer_fields, exclude=named)
        hint = f"; the layer has {_quoted(like)}: set {param} to it" if like else ""
        if name and name != default:  # a name the user gave must be in the layer
            problems.append(f"no {what} field '{name}' (parameter {param}{hint})")
        elif fallback and (not name or not like):  # empty, or a default name the layer lacks
            names[col] = ""
            if name:
                notes.append(f"no {what} field '{name}' (parameter {param}): {what} {fallback}")
        elif fallback:  # the default name is missing but a field looks like the column: which one is meant?
            problems.append(f"no {what} field '{name}' (parameter {param}{hint}, or empty {param} to take "
                            f"{fallback})")
        else:
            quoted = f" '{name}'" if name else ""
            problems.append(f"no {what} field{quoted} (parameter {param}{hint})")
    return names, notes, problems


def _field_index(layer_name, fields, name, what, parameter):
    idx = fields.lookupField(name)
    if idx < 0:
        raise QgsProcessingException(
            f"trajectory layer '{layer_name}' has no {what} field '{name}' (parameter {parameter}); "
            f"its fields are: {', '.join(fields.names()) or 'none'}"
        )
    return idx


def _number(value, layer_name, field_name, fid):
    try:
        out = float(value)
    except (TypeError, ValueError):
        out = math.nan
    if value is None or not math.isfinite(out):
        raise QgsProcessingException(
            f"trajectory layer '{layer_name}': field '{field_name}' of feature {fid} is not a number: {value!r}"
        )
    return out


def trajectory_columns(source, context, feedback, *, fields, defaults=None, layer_name="trajectory",
                       feature_ids=None):
    """Flight-CSV columns from a feature source.

    Parameters
    ----------
    source : QgsProcessingFeatureSource
        Points (one sample per feature) or lines (one sample per vertex).
    context : QgsProcessingContext
        Gives the transform context for the transformation to WGS84.
    feedback : QgsProcessingFeedback
        Progress and cancel.
    fields : dict
        Column name -> layer field name, for ``t``, ``h``, ``roll``, ``pitch``,
        ``yaw``, ``power_w`` and ``phase``; an empty or missing entry means
        "not in the layer" (time and height then come from the geometry's M and Z,
        roll and pitch are 0 deg, the phase is ``horizontal``).
    defaults : dict, optional
        Column -> its parameter's default name (see :func:`track_fields`).
    layer_name : str
        Name used in messages.
    feature_ids : list, optional
        Filled with the feature id of each sample, in the order of the columns.

    Returns
    -------
    dict of str -> list
        Columns ``t`` (s), ``lat``, ``lon`` (deg), ``h`` (m), ``roll``,
        ``pitch``, ``yaw`` (deg), ``power_w`` (W), ``phase``, sorted by time.
    """
    geom_type = QgsWkbTypes.geometryType(source.wkbType())
    if geom_type not in (QgsWkbTypes.PointGeometry, QgsWkbTypes.LineGeometry):
        raise QgsProcessingException(
            f"trajectory layer '{layer_name}' must hold points or lines, got {QgsWkbTypes.displayString(source.wkbType())}"
        )
    is_line = geom_type == QgsWkbTypes.LineGeometry
    layer_fields = source.fields()
    names, notes, problems = track_fields(source, fields, defaults)
    if problems:
        raise QgsProcessingException(f"trajectory layer '{layer_name}' as a flown track: {'; '.join(problems)}; "
                                     f"its fields are: {', '.join(layer_fields.names()) or 'none'}")
    for note in notes:
        feedback.pushInfo(f"trajectory layer '{layer_name}': {note}")
    idx = {col: layer_fields.lookupField(name) for col, name in names.items() if name}

    xform = QgsCoordinateTransform(source.sourceCrs(), QgsCoordinateReferenceSystem(WGS84),
                                   context.transformContext())
    rows = []  # (t, lat, lon, h, roll, pitch, yaw or None, power, phase, feature id)
    total = max(source.featureCount(), 1)
    request = QgsFeatureRequest()
    for i, feat in enumerate(source.getFeatures(request)):
        if feedback.isCanceled():
            break
        fid = feat.id()
        geom = feat.geometry()
        if geom is None or geom.isNull():
            raise QgsProcessingException(f"trajectory layer '{layer_name}': feature {fid} has no geometry")
        attrs = feat.attributes()

        def attr(col, default=None, _attrs=attrs, _fid=fid):
            if col not in idx:
                return default
            return _number(_attrs[idx[col]], layer_name, layer_fields.at(idx[col]).name(), _fid)

        phase = "horizontal"
        if "phase" in idx:
            value = attrs[idx["phase"]]
            if value is None or str(value).strip() in ("", "NULL"):
                raise QgsProcessingException(
                    f"trajectory layer '{layer_name}': field '{layer_fields.at(idx['phase']).name()}' "
                    f"of feature {fid} is empty")
            phase = str(value).strip()
        roll, pitch, power = attr("roll", 0.0), attr("pitch", 0.0), attr("power_w")
        yaw = attr("yaw")
        if is_line:
            vertices = list(geom.constGet().vertices())
            if len(vertices) < 2:
                raise QgsProcessingException(f"trajectory layer '{layer_name}': line {fid} has fewer than 2 vertices")
            for v in vertices:
                p = xform.transform(v.x(), v.y())
                h = attr("h") if "h" in idx else v.z()
                rows.append((v.m(), p.y(), p.x(), h, roll, pitch, yaw, power, phase, fid))
        else:
            if geom.isMultipart():
                raise QgsProcessingException(
                    f"trajectory layer '{layer_name}': feature {fid} is a multipoint; one point per sample expected")
            v = geom.constGet()
            p = xform.transform(v.x(), v.y())
            h = attr("h") if "h" in idx else v.z()
            rows.append((attr("t"), p.y(), p.x(), h, roll, pitch, yaw, power, phase, fid))
        feedback.setProgress(10.0 * (i + 1) / total)
    if feedback.isCanceled():
        raise QgsProcessingException("cancelled by the user")
    if not rows:
        raise QgsProcessingException(f"trajectory layer '{layer_name}' has no features")
    for r in rows:
        if not math.isfinite(r[0]):
            raise QgsProcessingException(
                f"trajectory layer '{layer_name}': feature {r[9]} has a vertex without time (M value)")
        if not math.isfinite(r[3]):
            raise QgsProcessingException(
                f"trajectory layer '{layer_name}': feature {r[9]} has a vertex without altitude (Z value)")
    rows.sort(key=lambda r: r[0])
    if feature_ids is not None:
        feature_ids[:] = [r[9] for r in rows]
    cols = {
        "t": [r[0] for r in rows], "lat": [r[1] for r in rows], "lon": [r[2] for r in rows],
        "h": [r[3] for r in rows], "roll": [r[4] for r in rows], "pitch": [r[5] for r in rows],
        "power_w": [r[7] for r in rows], "phase": [r[8] for r in rows],
    }
    if "yaw" in idx:
        cols["yaw"] = [r[6] for r in rows]
    else:
        cols["yaw"] = track_heading_deg(cols["lat"], cols["lon"])
    return cols


def layer_route(source, context, feedback, *, fields, defaults=None, layer_name="trajectory"):
    """The route (``gisnoise.flight.Route``) of a flown-track layer, read by the core's one reader.

    The core checks the columns (times strictly increasing, heights, powers and attitudes within
    their limits); its messages name the columns by the flight-CSV names (``t``, ``h``, ...) and
    the samples by their place in time: here they name the layer's field and its parameter, or the
    geometry's M and Z, and the feature of the sample.
    """
    from gisnoise.errors import GisnoiseError
    from gisnoise.flight import read_route
    from gisnoise.flight import trajectory as gtraj

    from .base import translate

    fids = []
    cols = trajectory_columns(source, context, feedback, fields=fields, defaults=defaults, layer_name=layer_name,
                              feature_ids=fids)
    names, _, _ = track_fields(source, fields, defaults)
    is_line = QgsWkbTypes.geometryType(source.wkbType()) == QgsWkbTypes.LineGeometry
    phrases = {col: f"field '{name}' (parameter {TRACK_COLUMNS[col][1]})" for col, name in names.items() if name}
    if not names.get("t"):
        phrases["t"] = "the M values (time)"
    if not names.get("h"):
        phrases["h"] = "the Z values (height)" if is_line else "the points' Z (height)"
    try:
        return read_route(gtraj.from_columns(cols, source=f"trajectory layer '{layer_name}'"))
    except GisnoiseError as exc:
        msg = translate(str(exc), phrases)

        def feature(m):
            i = int(m.group(1))
            return f"{m.group(0)} (feature {fids[i]})" if 0 <= i < len(fids) else m.group(0)

        raise QgsProcessingException(re.sub(r"\bsample (\d+)\b", feature, msg)) from None


def track_heading_deg(lat, lon):
    """Heading along a track, deg clockwise from north (forward azimuth to the next point).

    The last point keeps the heading of the segment before it; repeated points
    keep the previous heading (the first segment's when they lead).
    """
    from pyproj import Geod

    n = len(lat)
    if n < 2:
        raise QgsProcessingException("a line trajectory needs at least two vertices to give a heading")
    geod = Geod(ellps="WGS84")
    az, _, dist = geod.inv(lon[:-1], lat[:-1], lon[1:], lat[1:])
    az = [float(a) for a in az]
    moving = [float(d) > 1e-6 for d in dist]
    if not any(moving):
        raise QgsProcessingException("a line trajectory without a yaw field must move to give a heading")
    first = next(a for a, m in zip(az, moving, strict=True) if m)
    out, last = [], first
    for a, m in zip(az, moving, strict=True):
        if m:
            last = a
        out.append(last)
    out.append(last)
    return out
