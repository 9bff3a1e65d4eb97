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
"""

from __future__ import annotations

import math

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsCoordinateTransform,
    QgsFeatureRequest,
    QgsProcessingException,
    QgsWkbTypes,
)

WGS84 = "EPSG:4326"


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


def trajectory_columns(source, context, feedback, *, fields, layer_name="trajectory"):
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
    layer_name : str
        Name used in messages.

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
    idx = {}
    for col, what, param in (("t", "time", "TIME_FIELD"), ("h", "altitude", "ALTITUDE_FIELD"),
                             ("roll", "roll", "ROLL_FIELD"), ("pitch", "pitch", "PITCH_FIELD"),
                             ("yaw", "yaw", "YAW_FIELD"), ("power_w", "electric power", "POWER_FIELD"),
                             ("phase", "phase", "PHASE_FIELD")):
        name = (fields.get(col) or "").strip()
        if name:
            idx[col] = _field_index(layer_name, layer_fields, name, what, param)
    if "power_w" not in idx:
        raise QgsProcessingException(
            f"trajectory layer '{layer_name}': an electric power field is needed (parameter POWER_FIELD)")
    if is_line:
        if not QgsWkbTypes.hasM(source.wkbType()) and "t" not in idx:
            raise QgsProcessingException(
                f"trajectory layer '{layer_name}' has no time: its lines carry no M values (time, s) "
                "and no time field is given (parameter TIME_FIELD)")
        if "t" in idx:
            raise QgsProcessingException(
                f"trajectory layer '{layer_name}' is a line layer: the time of each vertex is its M value; "
                "leave the time field (parameter TIME_FIELD) empty")
        if not QgsWkbTypes.hasZ(source.wkbType()) and "h" not in idx:
            raise QgsProcessingException(
                f"trajectory layer '{layer_name}' has no altitude: its lines carry no Z values "
                "(parameter ALTITUDE_FIELD)")
    else:
        if "t" not in idx:
            raise QgsProcessingException(
                f"trajectory layer '{layer_name}' has no time field (parameter TIME_FIELD)")
        if "h" not in idx and not QgsWkbTypes.hasZ(source.wkbType()):
            raise QgsProcessingException(
                f"trajectory layer '{layer_name}' has no altitude field and its points have no Z "
                "(parameter ALTITUDE_FIELD)")
        if "yaw" not in idx:
            raise QgsProcessingException(
                f"trajectory layer '{layer_name}' has no yaw field (parameter YAW_FIELD)")

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
