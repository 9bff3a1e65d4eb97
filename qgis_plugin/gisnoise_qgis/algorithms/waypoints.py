"""A route plan (``gisnoise/waypoints/1``) from a QGIS layer of waypoints.

A point layer holds one waypoint per feature, in feature order (or ordered by a
sequence field); a line layer's vertices are the waypoints (its features in order).
The altitude comes from a field or the geometry's Z, the speed (m/s, optional) and
the phase and hold time (optional) from fields.  The document goes to the core's one
reader, ``gisnoise.flight.read_route``, which flies it with the vehicle model exactly
as a waypoints file (``gisnoise contour route.geojson``).
"""

from __future__ import annotations

import math

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsCoordinateTransform,
    QgsProcessingException,
    QgsWkbTypes,
)

from .layers import WGS84, _field_index, _number

#: Altitude references of the route plan (gisnoise.flight.waypoints).
ALT_REFERENCES = ("agl", "msl", "ellipsoid")


def is_waypoint_layer(source, time_field):
    """Whether a layer is a plan rather than a flown track: no time field (points) or no M and no time (lines)."""
    geom_type = QgsWkbTypes.geometryType(source.wkbType())
    has_time = bool(time_field) and source.fields().lookupField(time_field) >= 0
    if geom_type == QgsWkbTypes.LineGeometry:
        return not QgsWkbTypes.hasM(source.wkbType()) and not has_time
    return not has_time


def waypoints_document(source, context, feedback, *, fields, altitude_reference="agl", ground_h_m=None,
                       geoid_undulation_m=None, layer_name="waypoints"):
    """The waypoints document of a layer.

    Parameters
    ----------
    fields : dict
        ``alt``, ``speed``, ``phase``, ``hold_s``, ``seq`` -> layer field name; empty means "not in
        the layer" (the altitude then comes from the geometry's Z).
    altitude_reference : str
        ``agl`` (above the ground: the DEM or ``ground_h_m``), ``msl`` (needs ``geoid_undulation_m``)
        or ``ellipsoid``.
    """
    geom_type = QgsWkbTypes.geometryType(source.wkbType())
    if geom_type not in (QgsWkbTypes.PointGeometry, QgsWkbTypes.LineGeometry):
        raise QgsProcessingException(f"waypoint layer '{layer_name}' must hold points or lines, got "
                                     f"{QgsWkbTypes.displayString(source.wkbType())}")
    is_line = geom_type == QgsWkbTypes.LineGeometry
    layer_fields = source.fields()
    idx = {}
    for key, what, param in (("alt", "altitude", "WAYPOINT_ALT_FIELD"), ("speed", "speed", "WAYPOINT_SPEED_FIELD"),
                             ("phase", "phase", "PHASE_FIELD"), ("hold_s", "hold time", "WAYPOINT_HOLD_FIELD"),
                             ("seq", "order", "WAYPOINT_ORDER_FIELD")):
        name = (fields.get(key) or "").strip()
        if name:
            idx[key] = _field_index(layer_name, layer_fields, name, what, param)
    if "alt" not in idx and not QgsWkbTypes.hasZ(source.wkbType()):
        raise QgsProcessingException(f"waypoint layer '{layer_name}' has no altitude field and its geometries no Z "
                                     "(parameter WAYPOINT_ALT_FIELD)")
    xform = QgsCoordinateTransform(source.sourceCrs(), QgsCoordinateReferenceSystem(WGS84),
                                   context.transformContext())
    rows = []  # (order key, waypoint dict)
    for n, feat in enumerate(source.getFeatures()):
        if feedback.isCanceled():
            raise QgsProcessingException("cancelled by the user")
        fid = feat.id()
        geom = feat.geometry()
        if geom is None or geom.isNull():
            raise QgsProcessingException(f"waypoint layer '{layer_name}': feature {fid} has no geometry")
        attrs = feat.attributes()
        extra = {}
        for key in ("speed", "hold_s"):
            if key in idx and attrs[idx[key]] not in (None, "") and str(attrs[idx[key]]) != "NULL":
                extra[key] = _number(attrs[idx[key]], layer_name, layer_fields.at(idx[key]).name(), fid)
        if "phase" in idx and attrs[idx["phase"]] not in (None, "") and str(attrs[idx["phase"]]) != "NULL":
            extra["phase"] = str(attrs[idx["phase"]]).strip()
        order = _number(attrs[idx["seq"]], layer_name, layer_fields.at(idx["seq"]).name(), fid) if "seq" in idx else n
        if is_line:
            vertices = list(geom.constGet().vertices())
            if len(vertices) < 2:
                raise QgsProcessingException(f"waypoint layer '{layer_name}': line {fid} has fewer than 2 vertices")
        else:
            if geom.isMultipart():
                raise QgsProcessingException(
                    f"waypoint layer '{layer_name}': feature {fid} is a multipoint; one point per waypoint expected")
            vertices = [geom.constGet()]
        alt_attr = (_number(attrs[idx["alt"]], layer_name, layer_fields.at(idx["alt"]).name(), fid)
                    if "alt" in idx else None)
        for k, v in enumerate(vertices):
            p = xform.transform(v.x(), v.y())
            alt = alt_attr if alt_attr is not None else v.z()
            if not math.isfinite(alt):
                raise QgsProcessingException(f"waypoint layer '{layer_name}': feature {fid} has a vertex without "
                                             "altitude (Z value)")
            rows.append(((order, k), {"lon": p.x(), "lat": p.y(), "alt": alt, **extra}))
    if not rows:
        raise QgsProcessingException(f"waypoint layer '{layer_name}' has no features")
    rows.sort(key=lambda r: r[0])
    doc = {"schema": "gisnoise/waypoints/1", "altitude_reference": altitude_reference,
           "waypoints": [r[1] for r in rows]}
    if ground_h_m is not None:
        doc["ground_h_m"] = float(ground_h_m)
    if geoid_undulation_m is not None:
        doc["geoid_undulation_m"] = float(geoid_undulation_m)
    return doc
