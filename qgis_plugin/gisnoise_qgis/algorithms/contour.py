"""Noise grid and contours of a trajectory: ``gisnoise.maps.pipeline.make_map`` in QGIS."""

from __future__ import annotations

import importlib.util
import os
import shutil
import tempfile

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsCoordinateTransform,
    QgsFeature,
    QgsFeatureSink,
    QgsField,
    QgsFields,
    QgsGeometry,
    QgsLineString,
    QgsPoint,
    QgsProcessing,
    QgsProcessingException,
    QgsProcessingParameterBoolean,
    QgsProcessingParameterCrs,
    QgsProcessingParameterDefinition,
    QgsProcessingParameterEnum,
    QgsProcessingParameterFeatureSink,
    QgsProcessingParameterFeatureSource,
    QgsProcessingParameterField,
    QgsProcessingParameterFile,
    QgsProcessingParameterMultipleLayers,
    QgsProcessingParameterNumber,
    QgsProcessingParameterRasterDestination,
    QgsProcessingParameterRasterLayer,
    QgsProcessingParameterString,
    QgsProcessingUtils,
    QgsRasterLayer,
    QgsVectorLayer,
    QgsWkbTypes,
)
from qgis.PyQt.QtCore import QVariant

from .._core import pip_hint
from . import styles
from .base import FeedbackProgress, GisnoiseAlgorithm, warn
from .layers import layer_route, track_evidence, track_fields
from .waypoints import ALT_REFERENCES, is_waypoint_layer, waypoints_document

METRICS = ("LAmax", "LAeq", "SEL")
#: What a trajectory layer holds: a flown track (times per sample) or waypoints (flown by the vehicle model).
TRAJECTORY_KINDS = ("auto (waypoints when the layer has no time)", "flown track (time, attitude, power per sample)",
                    "waypoints")
ALT_REFERENCE_LABELS = ("the ground (AGL: the DEM or the flat ground height)", "mean sea level (needs the geoid "
                        "undulation)", "the WGS84 ellipsoid")


class NoiseMapAlgorithm(GisnoiseAlgorithm):
    """Noise grid (GeoTIFF, one band per metric) and contours (isobands, isolines)."""

    TRAJECTORY = "TRAJECTORY"
    TRAJECTORY_FILE = "TRAJECTORY_FILE"
    TIME_FIELD = "TIME_FIELD"
    ALTITUDE_FIELD = "ALTITUDE_FIELD"
    ROLL_FIELD = "ROLL_FIELD"
    PITCH_FIELD = "PITCH_FIELD"
    YAW_FIELD = "YAW_FIELD"
    POWER_FIELD = "POWER_FIELD"
    PHASE_FIELD = "PHASE_FIELD"
    TRAJECTORY_KIND = "TRAJECTORY_KIND"
    WAYPOINT_ALT_FIELD = "WAYPOINT_ALT_FIELD"
    WAYPOINT_SPEED_FIELD = "WAYPOINT_SPEED_FIELD"
    WAYPOINT_HOLD_FIELD = "WAYPOINT_HOLD_FIELD"
    WAYPOINT_ORDER_FIELD = "WAYPOINT_ORDER_FIELD"
    ALTITUDE_REFERENCE = "ALTITUDE_REFERENCE"
    POWER_W = "POWER_W"
    GEOID_UNDULATION = "GEOID_UNDULATION"
    CARDS = "CARDS"
    RESOLUTION = "RESOLUTION"
    MARGIN = "MARGIN"
    LEVELS = "LEVELS"
    METRICS = "METRICS"
    CONTOUR_METRICS = "CONTOUR_METRICS"
    RECEIVER_HEIGHT = "RECEIVER_HEIGHT"
    DEM = "DEM"
    CRS = "CRS"
    BACKGROUND = "BACKGROUND"
    GROUND_HEIGHT = "GROUND_HEIGHT"
    DEM_OFFSET = "DEM_OFFSET"
    SUBSTEPS = "SUBSTEPS"
    UNCERTAINTY = "UNCERTAINTY"
    PERIOD = "PERIOD"
    THRESHOLD = "THRESHOLD"
    SNAPSHOT_T = "SNAPSHOT_T"
    OUTPUT_RASTER = "OUTPUT_RASTER"
    OUTPUT_BANDS = "OUTPUT_BANDS"
    OUTPUT_LINES = "OUTPUT_LINES"
    OUTPUT_TRACK = "OUTPUT_TRACK"

    #: Column of a flown track, its field parameter and the parameter's default (the flight CSV's name).
    TRACK_FIELDS = (("t", TIME_FIELD, "t"), ("h", ALTITUDE_FIELD, "h"), ("roll", ROLL_FIELD, "roll"),
                    ("pitch", PITCH_FIELD, "pitch"), ("yaw", YAW_FIELD, "yaw"), ("power_w", POWER_FIELD, "power_w"),
                    ("phase", PHASE_FIELD, "phase"))
    CORE_FIELDS = {"resolution_m": RESOLUTION, "grid.resolution_m": RESOLUTION, "margin_m": MARGIN,
                   "levels": LEVELS, "metrics": METRICS, "crs": CRS, "dem": DEM, "receiver_height": RECEIVER_HEIGHT,
                   "dem_offset_m": DEM_OFFSET, "substeps": SUBSTEPS, "ground_h": GROUND_HEIGHT,
                   "ground_h_m": GROUND_HEIGHT, "period_s": PERIOD, "threshold_db": THRESHOLD,
                   "snapshot_t": SNAPSHOT_T, "uncertainty": UNCERTAINTY, "geoid_undulation_m": GEOID_UNDULATION,
                   "cards": CARDS}
    CLI_OPTIONS = {"--resolution": RESOLUTION, "--margin": MARGIN, "--levels": LEVELS, "--dem-offset": DEM_OFFSET,
                   "--dem": DEM, "--receiver-height": RECEIVER_HEIGHT, "--ground-height": GROUND_HEIGHT,
                   "--power-w": POWER_W, "--geoid-undulation": GEOID_UNDULATION, "--crs": CRS, "--metrics": METRICS,
                   "--period": PERIOD, "--threshold": THRESHOLD, "--snapshot": SNAPSHOT_T, "--substeps": SUBSTEPS,
                   "--background": BACKGROUND, "--uncertainty": UNCERTAINTY, "--card": CARDS}
    PHRASES = {"a wider margin": "a wider margin (parameter MARGIN)"}

    GROUP = "Noise maps"
    GROUP_ID = "maps"

    def name(self):
        return "noisemap"

    def displayName(self):  # noqa: N802 - QGIS API
        return "Noise grid and contours of a trajectory"

    def shortHelpString(self):  # noqa: N802 - QGIS API
        return (
            "A-weighted levels of a drone flying a trajectory, from model cards (one per flight phase), "
            "on a grid of receivers around it.\n\n"
            "Trajectory: a point layer (one feature per log sample with time in s, height in m (WGS84 "
            "ellipsoidal; a field or the points' Z), roll, pitch, yaw in deg, electric power in W, phase), "
            "a line layer (one sample per vertex: Z = height, M = time; attitude, power and phase from the "
            "feature's fields; yaw along the line unless a yaw field is given), a layer of waypoints (points "
            "in order or a line's vertices; fields alt, speed, hold_s, seq, phase; read as waypoints when the "
            "layer has no time field and no M, or by 'The layer holds'; a point layer with fields of a flown track "
            "(time, timestamp, roll, pitch, power, ...) but not the time field is refused, naming what to set), "
            "flown by the vehicle model as a waypoints file, or a "
            "file as the gisnoise command line reads it: flight CSV, GeoJSON, waypoints, PX4 .ulg, ArduPilot "
            ".bin (constant power for a log without battery current, geoid undulation for ArduPilot).\n\n"
            "Outputs: a GeoTIFF with one band per metric (LAmax, LAeq over the flight, SEL), "
            "isobands and isolines of the chosen levels (properties metric, level and clipped: true where the "
            "grid's edge, or the end of the DEM, cuts the contour; the default margin closes the lowest level of LAmax and LAeq, and "
            "of SEL, which is contoured 10 dB above the levels), "
            "styled with graduated colours by level."
        )

    def initAlgorithm(self, config=None):  # noqa: N802 - QGIS API
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.TRAJECTORY, "Trajectory layer (points or lines)",
            [QgsProcessing.TypeVectorPoint, QgsProcessing.TypeVectorLine], optional=True))
        self.addParameter(QgsProcessingParameterFile(
            self.TRAJECTORY_FILE, "or a trajectory file (flight CSV, GeoJSON, PX4 .ulg, ArduPilot .bin)",
            behavior=QgsProcessingParameterFile.File, optional=True,
            fileFilter="Trajectories (*.csv *.geojson *.json *.ulg *.ULG *.bin *.BIN);;All files (*)"))
        for key, label, ftype in (
            (self.TIME_FIELD, "Time field (s; lines: their M values)", QgsProcessingParameterField.Numeric),
            (self.ALTITUDE_FIELD, "Height field (m, ellipsoidal; empty: geometry Z)",
             QgsProcessingParameterField.Numeric),
            (self.ROLL_FIELD, "Roll field (deg; empty: 0)", QgsProcessingParameterField.Numeric),
            (self.PITCH_FIELD, "Pitch field (deg; empty: 0)", QgsProcessingParameterField.Numeric),
            (self.YAW_FIELD, "Yaw field (deg from north; empty for lines: along the line)",
             QgsProcessingParameterField.Numeric),
            (self.POWER_FIELD, "Electric power field (W)", QgsProcessingParameterField.Numeric),
            (self.PHASE_FIELD, "Flight phase field (empty: horizontal)", QgsProcessingParameterField.Any),
        ):
            default = next(d for _, k, d in self.TRACK_FIELDS if k == key)
            self.addParameter(QgsProcessingParameterField(
                key, label, defaultValue=default, parentLayerParameterName=self.TRAJECTORY, type=ftype,
                optional=True))
        self.addParameter(QgsProcessingParameterEnum(
            self.TRAJECTORY_KIND, "The layer holds", options=list(TRAJECTORY_KINDS), defaultValue=0))
        for key, label, default in (
            (self.WAYPOINT_ALT_FIELD, "Waypoint altitude field (m, see altitude reference; empty: geometry Z)", "alt"),
            (self.WAYPOINT_SPEED_FIELD, "Waypoint speed field (m/s; empty: the vehicle's cruise speed)", "speed"),
            (self.WAYPOINT_HOLD_FIELD, "Waypoint hold time field (s; empty: no hold)", "hold_s"),
            (self.WAYPOINT_ORDER_FIELD, "Waypoint order field (empty: feature order)", "seq"),
        ):
            self.addParameter(QgsProcessingParameterField(
                key, label, defaultValue=default, parentLayerParameterName=self.TRAJECTORY,
                type=QgsProcessingParameterField.Any, optional=True))
        self.addParameter(QgsProcessingParameterEnum(
            self.ALTITUDE_REFERENCE, "Waypoint altitudes are above", options=list(ALT_REFERENCE_LABELS),
            defaultValue=0))
        for key, label in ((self.POWER_W, "Constant electric power (W; for a flight log without battery current)"),
                           (self.GEOID_UNDULATION, "Geoid undulation (m; ArduPilot logs and waypoints above mean sea "
                                                   "level)")):
            self.addParameter(QgsProcessingParameterNumber(key, label, QgsProcessingParameterNumber.Double,
                                                           optional=True))
        self.addParameter(QgsProcessingParameterMultipleLayers(
            self.CARDS, "Model cards (JSON, one per phase)", layerType=QgsProcessing.TypeFile))
        self.addParameter(QgsProcessingParameterNumber(
            self.RESOLUTION, "Cell size (m)", QgsProcessingParameterNumber.Double, 10.0, minValue=0.01))
        self.addParameter(QgsProcessingParameterNumber(
            self.MARGIN, "Margin around the trajectory (m; empty: from the cards, so the lowest level closes)",
            QgsProcessingParameterNumber.Double, None, optional=True, minValue=0.0))
        self.addParameter(QgsProcessingParameterString(
            self.LEVELS, "Contour levels (dB(A), comma separated, each within -50..200)", "45,50,55,60,65"))
        self.addParameter(QgsProcessingParameterEnum(
            self.METRICS, "Metrics (raster bands)", options=list(METRICS), allowMultiple=True,
            defaultValue=[0, 1, 2]))
        self.addParameter(QgsProcessingParameterEnum(
            self.CONTOUR_METRICS, "Metrics to contour (the layers hold one set of bands per metric)",
            options=list(METRICS), allowMultiple=True, defaultValue=[0]))
        self.addParameter(QgsProcessingParameterNumber(
            self.RECEIVER_HEIGHT, "Receiver height above ground (m)", QgsProcessingParameterNumber.Double, 1.5,
            minValue=0.0))
        self.addParameter(QgsProcessingParameterRasterLayer(
            self.DEM, "Ground elevation (DEM; empty: the flat ground height, or the take-off/landing point)", optional=True))
        self.addParameter(QgsProcessingParameterCrs(
            self.CRS, "Grid CRS (projected, metres; empty: local UTM zone)", optional=True))
        self.addParameter(QgsProcessingParameterBoolean(
            self.BACKGROUND, "Add the cards' background level", False))
        self.addParameter(QgsProcessingParameterBoolean(
            self.UNCERTAINTY, "Add standard deviation and 95 % bands (cards need a covariance)", False))
        advanced = [QgsProcessingParameterNumber(
            self.DEM_OFFSET, "Added to DEM heights to reach the trajectory's ellipsoidal heights (m)",
            QgsProcessingParameterNumber.Double, 0.0), QgsProcessingParameterNumber(
            self.SUBSTEPS, "Time substeps between trajectory samples", QgsProcessingParameterNumber.Integer, 1,
            minValue=1, maxValue=1000)]
        for param in advanced:
            param.setFlags(param.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
            self.addParameter(param)
        for key, label in ((self.GROUND_HEIGHT, "Flat ground height without a DEM (m, ellipsoidal; empty: the "
                                                "take-off or landing point; a track in the air needs it)"),
                           (self.PERIOD, "LAeq period (s; empty: the trajectory's duration)"),
                           (self.THRESHOLD, "Time above this level (dB(A); empty: none)"),
                           (self.SNAPSHOT_T, "Snapshot at this time (s; empty: none)")):
            param = QgsProcessingParameterNumber(key, label, QgsProcessingParameterNumber.Double, optional=True)
            param.setFlags(param.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
            self.addParameter(param)
        self.addParameter(QgsProcessingParameterRasterDestination(
            self.OUTPUT_RASTER, "Noise grid"))
        self.addParameter(QgsProcessingParameterFeatureSink(
            self.OUTPUT_BANDS, "Noise contours (isobands)", QgsProcessing.TypeVectorPolygon))
        self.addParameter(QgsProcessingParameterFeatureSink(
            self.OUTPUT_LINES, "Noise contours (isolines)", QgsProcessing.TypeVectorLine, optional=True,
            createByDefault=True))
        self.addParameter(QgsProcessingParameterFeatureSink(
            self.OUTPUT_TRACK, "Flight track (by phase)", QgsProcessing.TypeVectorLine, optional=True,
            createByDefault=True))

    # ------------------------------------------------------------------ inputs
    def _optional(self, parameters, key, context):
        return None if parameters.get(key) in (None, "") else self.parameterAsDouble(parameters, key, context)

    def _trajectory(self, parameters, context, feedback):
        """The route (``gisnoise.flight.Route``) of the layer or file, read by the core's one reader."""
        from gisnoise.flight import read_route

        source = self.parameterAsSource(parameters, self.TRAJECTORY, context)
        path = self.parameterAsFile(parameters, self.TRAJECTORY_FILE, context)
        if source is not None and path:
            raise QgsProcessingException("give either a trajectory layer (TRAJECTORY) or a trajectory file "
                                         "(TRAJECTORY_FILE), not both")
        if source is None and not path:
            raise QgsProcessingException("no trajectory: give a trajectory layer (TRAJECTORY) or a trajectory "
                                         "file (TRAJECTORY_FILE)")
        dem_layer = self.parameterAsRasterLayer(parameters, self.DEM, context)
        dem = dem_layer.source() if dem_layer is not None else None
        dem_offset = self.parameterAsDouble(parameters, self.DEM_OFFSET, context)
        geoid = self._optional(parameters, self.GEOID_UNDULATION, context)
        if path and path.lower().endswith(".bin") and importlib.util.find_spec("pymavlink") is None:
            raise QgsProcessingException(
                "reading an ArduPilot .bin log needs pymavlink in QGIS's Python (compiled, so the plugin does not "
                f"bundle it; Debian and Ubuntu do not package it): {pip_hint(['pymavlink'])} "
                "(parameter TRAJECTORY_FILE)")
        if path:  # flight CSV, GeoJSON, waypoints, PX4 .ulg, ArduPilot .bin
            return read_route(path, dem=dem, dem_offset_m=dem_offset, geoid_undulation_m=geoid,
                              power_w=self._optional(parameters, self.POWER_W, context))
        layer = self.parameterAsVectorLayer(parameters, self.TRAJECTORY, context)
        name = layer.name() if layer is not None else "trajectory"
        kind = TRAJECTORY_KINDS[self.parameterAsEnum(parameters, self.TRAJECTORY_KIND, context)]
        fields = {col: self.parameterAsString(parameters, key, context) for col, key, _ in self.TRACK_FIELDS}
        defaults = {col: default for col, _, default in self.TRACK_FIELDS}
        if kind.startswith("auto") and is_waypoint_layer(source, fields["t"]):
            # a point layer without the time field: a plan, unless its fields say it is a flown track
            evidence = (track_evidence(source.fields())
                        if QgsWkbTypes.geometryType(source.wkbType()) == QgsWkbTypes.PointGeometry else [])
            if evidence:
                _, _, problems = track_fields(source, fields, defaults)
                raise QgsProcessingException(
                    f"trajectory layer '{name}' has fields of a flown track ({', '.join(evidence)}), so it is not "
                    f"flown as waypoints (parameter TRAJECTORY_KIND: auto), but they do not fit: "
                    f"{'; '.join(problems)}; or set TRAJECTORY_KIND to waypoints to fly its points as a plan")
        if kind == "waypoints" or (kind.startswith("auto") and is_waypoint_layer(source, fields["t"])):
            names = {}
            for col, key, default in (("alt", self.WAYPOINT_ALT_FIELD, "alt"), ("speed", self.WAYPOINT_SPEED_FIELD,
                                                                               "speed"),
                                      ("hold_s", self.WAYPOINT_HOLD_FIELD, "hold_s"),
                                      ("seq", self.WAYPOINT_ORDER_FIELD, "seq"), ("phase", self.PHASE_FIELD, "phase")):
                field = self.parameterAsString(parameters, key, context).strip()
                # a default name the layer does not have means "not in the layer"; a name the user gave must exist
                names[col] = "" if field == default and source.fields().lookupField(field) < 0 else field
            ref = ALT_REFERENCES[self.parameterAsEnum(parameters, self.ALTITUDE_REFERENCE, context)]
            doc = waypoints_document(source, context, feedback, fields=names, altitude_reference=ref,
                                     ground_h_m=self._optional(parameters, self.GROUND_HEIGHT, context),
                                     geoid_undulation_m=geoid, layer_name=name)
            feedback.pushInfo(f"waypoint layer '{name}': {len(doc['waypoints'])} waypoints, altitudes {ref}")
            return read_route(doc, dem=dem, dem_offset_m=dem_offset)
        return layer_route(source, context, feedback, fields=fields, defaults=defaults, layer_name=name)

    def _cards(self, parameters, context):
        from gisnoise.errors import GisnoiseError
        from gisnoise.model import cards as gcards

        paths = self.parameterAsFileList(parameters, self.CARDS, context)
        if not paths:
            raise QgsProcessingException("no model card given (parameter CARDS)")
        out = []
        for p in paths:
            try:
                out.append(gcards.load(p))
            except GisnoiseError as exc:  # its field is the card's ('p2', 'schema') or the file's ('json')
                what = "model cards are JSON files" if exc.field in ("json", "card") else "a model card"
                raise QgsProcessingException(f"{exc} (parameter CARDS: {what})") from None
        return out

    # ------------------------------------------------------------------ run
    def compute(self, parameters, context, feedback):
        from gisnoise.maps import make_map, parse_levels

        levels = parse_levels(self.parameterAsString(parameters, self.LEVELS, context), field="LEVELS")
        route = self._trajectory(parameters, context, feedback)
        traj = route.trajectory
        cards = self._cards(parameters, context)
        metric_idx = self.parameterAsEnums(parameters, self.METRICS, context)
        metrics = tuple(METRICS[i] for i in sorted(metric_idx)) or METRICS
        contoured = {METRICS[i] for i in self.parameterAsEnums(parameters, self.CONTOUR_METRICS, context)}
        contoured = contoured or {METRICS[0]}
        missing = contoured - set(metrics)
        if missing:
            raise QgsProcessingException(f"metrics to contour (parameter CONTOUR_METRICS) {', '.join(sorted(missing))} "
                                         f"are not computed (parameter METRICS: {', '.join(metrics)})")
        crs = self.parameterAsCrs(parameters, self.CRS, context)
        crs_text = None
        if crs.isValid():
            if crs.isGeographic():
                raise QgsProcessingException(f"grid CRS (parameter CRS) must be projected in metres, "
                                             f"got {crs.authid() or crs.description()}")
            crs_text = crs.authid() or crs.toWkt(QgsCoordinateReferenceSystem.WKT_PREFERRED)
        dem_layer = self.parameterAsRasterLayer(parameters, self.DEM, context)
        dem = dem_layer.source() if dem_layer is not None else None
        feedback.pushInfo(f"trajectory: {len(traj)} samples over {traj.duration_s:.1f} s; "
                          f"cards: {', '.join(c.id for c in cards)}")

        steps = FeedbackProgress(feedback, 10.0, 90.0)
        work = tempfile.mkdtemp(prefix="gisnoise_", dir=QgsProcessingUtils.tempFolder())
        kw = {"background": self.parameterAsBoolean(parameters, self.BACKGROUND, context),
              "dem_offset_m": self.parameterAsDouble(parameters, self.DEM_OFFSET, context),
              "substeps": self.parameterAsInt(parameters, self.SUBSTEPS, context)}
        for key, name in ((self.GROUND_HEIGHT, "ground_h"), (self.PERIOD, "period_s"),
                          (self.THRESHOLD, "threshold_db"), (self.SNAPSHOT_T, "snapshot_t")):
            if parameters.get(key) not in (None, ""):
                kw[name] = self.parameterAsDouble(parameters, key, context)
        paths = make_map(
            route, cards, work,
            resolution_m=self.parameterAsDouble(parameters, self.RESOLUTION, context),
            margin_m=(None if parameters.get(self.MARGIN) in (None, "")
                      else self.parameterAsDouble(parameters, self.MARGIN, context)),
            levels=levels, metrics=metrics, crs=crs_text, dem=dem,
            receiver_height=self.parameterAsDouble(parameters, self.RECEIVER_HEIGHT, context),
            uncertainty=self.parameterAsBoolean(parameters, self.UNCERTAINTY, context), plot=False,
            progress=steps.progress, cancel=steps.cancel, **kw)
        tif, geojson = os.fspath(paths["levels"]), os.fspath(paths["contours"])
        for warning in paths.get("warnings", []):
            self.warn(feedback, warning)

        raster_out = self.parameterAsOutputLayer(parameters, self.OUTPUT_RASTER, context)
        _write_raster(tif, raster_out)
        feedback.setProgress(92.0)
        results = {self.OUTPUT_RASTER: raster_out}
        grid_crs = QgsRasterLayer(tif, "grid", "gdal").crs()
        bands, lines = _contour_layers(geojson)
        for key, layer in ((self.OUTPUT_BANDS, bands), (self.OUTPUT_LINES, lines)):
            dest = self._copy_to_sink(parameters, key, layer, context, feedback, contoured, grid_crs)
            if dest:
                results[key] = dest
        track = self._track_to_sink(parameters, traj, grid_crs, context)
        if track:
            results[self.OUTPUT_TRACK] = track
        feedback.setProgress(98.0)
        shown = next(m for m in metrics if m in contoured)
        from gisnoise.maps import metric_levels

        shown_levels = metric_levels(shown, levels)  # SEL's contours lie higher than the map's levels
        self._style_outputs(results, context, shown_levels, shown, metrics.index(shown) + 1)
        self._save_styles(results, shown_levels, shown, metrics.index(shown) + 1, feedback)
        feedback.setProgress(100.0)
        return results

    def _copy_to_sink(self, parameters, key, layer, context, feedback, contoured, crs):
        """Copy the contours (WGS84) into the sink, in the grid's CRS ``crs``."""
        sink, dest = self.parameterAsSink(parameters, key, context, layer.fields(),
                                          QgsWkbTypes.multiType(layer.wkbType()), crs)
        xform = QgsCoordinateTransform(layer.crs(), crs, context.transformContext())
        if sink is None and key == self.OUTPUT_LINES and not dest:
            return None  # optional output not wanted
        if sink is None:
            raise QgsProcessingException(self.invalidSinkError(parameters, key))
        for feat in layer.getFeatures():
            if feedback.isCanceled():
                raise QgsProcessingException("cancelled by the user")
            if feat["metric"] not in contoured:
                continue
            out = QgsFeature(feat)
            geom = out.geometry()
            geom.transform(xform)
            out.setGeometry(geom)
            if not sink.addFeature(out, QgsFeatureSink.FastInsert):
                raise QgsProcessingException(f"cannot write a contour feature to {dest}: {sink.lastError()}")
        return dest

    def _track_to_sink(self, parameters, traj, crs, context):
        """The flight track as one line per run of equal phase (fields phase, t_start_s, t_end_s)."""
        fields = QgsFields()
        fields.append(QgsField("phase", QVariant.String))
        fields.append(QgsField("t_start_s", QVariant.Double))
        fields.append(QgsField("t_end_s", QVariant.Double))
        sink, dest = self.parameterAsSink(parameters, self.OUTPUT_TRACK, context, fields,
                                          QgsWkbTypes.LineStringZ, crs)
        if sink is None:
            return None
        xform = QgsCoordinateTransform(QgsCoordinateReferenceSystem("EPSG:4326"), crs, context.transformContext())
        phase = [str(p) for p in traj.phase]
        start = 0
        for i in range(1, len(phase) + 1):
            if i < len(phase) and phase[i] == phase[start]:
                continue
            stop = min(i + 1, len(phase))  # runs share their boundary sample: the track has no gaps
            pts = [QgsPoint(float(traj.lon[k]), float(traj.lat[k]), float(traj.h[k])) for k in range(start, stop)]
            if len(pts) >= 2:
                geom = QgsGeometry(QgsLineString(pts))
                geom.transform(xform)
                feat = QgsFeature(fields)
                feat.setGeometry(geom)
                feat.setAttributes([phase[start], float(traj.t[start]), float(traj.t[stop - 1])])
                if not sink.addFeature(feat, QgsFeatureSink.FastInsert):
                    raise QgsProcessingException(f"cannot write the track to {dest}: {sink.lastError()}")
            start = i
        return dest

    def _save_styles(self, results, levels, metric, band, feedback):
        """A style beside each file output, so it opens styled from qgis_process, models and scripts."""
        for key in (self.OUTPUT_RASTER, self.OUTPUT_BANDS, self.OUTPUT_LINES, self.OUTPUT_TRACK):
            dest = results.get(key)
            if not dest or not os.path.isfile(str(dest)):
                continue
            if key == self.OUTPUT_RASTER:
                layer = QgsRasterLayer(dest, "noise grid", "gdal")
                styles.style_raster(layer, levels, metric, band)
            else:
                layer = QgsVectorLayer(dest, os.path.splitext(os.path.basename(dest))[0], "ogr")
                if key == self.OUTPUT_TRACK:
                    styles.style_track(layer)
                else:
                    styles.style_contours(layer, levels, polygons=key == self.OUTPUT_BANDS, metric=metric)
            if not layer.isValid():
                warn(feedback, f"cannot open {dest} to save its style")
                continue
            styles.save_style(layer, dest)

    def _style_outputs(self, results, context, levels, metric, band):
        for key, post in ((self.OUTPUT_RASTER, styles.RasterStyle(levels, metric, band)),
                          (self.OUTPUT_BANDS, styles.ContourStyle(levels, polygons=True, metric=metric)),
                          (self.OUTPUT_LINES, styles.ContourStyle(levels, polygons=False, metric=metric)),
                          (self.OUTPUT_TRACK, styles.TrackStyle())):
            dest = results.get(key)
            if dest and context.willLoadLayerOnCompletion(dest):
                details = context.layerToLoadOnCompletionDetails(dest)
                details.setPostProcessor(styles.keep(post))


#: Files GDAL and QGIS keep beside a raster: cached statistics and histograms (PAM), overviews, masks.  They
#: describe the file they were made for; left beside a new grid they show the old grid's min/max.
RASTER_SIDECARS = (".aux.xml", ".ovr", ".msk")


def _write_raster(tif, dest):
    """Copy the core's GeoTIFF to ``dest``; other formats through GDAL.

    The sidecars of an earlier file at ``dest`` (:data:`RASTER_SIDECARS`) are removed first.
    """
    folder = os.path.dirname(dest)
    if folder:
        os.makedirs(folder, exist_ok=True)
    for ext in RASTER_SIDECARS:
        try:
            os.remove(dest + ext)
        except FileNotFoundError:
            pass
        except OSError as exc:
            raise QgsProcessingException(f"cannot remove {dest + ext}, left by an earlier grid at the output "
                                         f"(parameter OUTPUT_RASTER): {exc}") from None
    if dest.lower().endswith((".tif", ".tiff")):
        shutil.copyfile(tif, dest)
        return
    from osgeo import gdal
    from qgis.core import QgsRasterFileWriter

    driver = QgsRasterFileWriter.driverForExtension(os.path.splitext(dest)[1])
    if not driver:
        raise QgsProcessingException(f"no raster format for the output {dest!r} (parameter OUTPUT_RASTER)")
    gdal.PushErrorHandler("CPLQuietErrorHandler")
    try:
        gdal.ErrorReset()
        try:
            out = gdal.Translate(dest, tif, format=driver)
            reason = gdal.GetLastErrorMsg().strip()
        except RuntimeError as exc:  # when something in this QGIS turned GDAL's exceptions on
            out, reason = None, str(exc).strip()
    finally:
        gdal.PopErrorHandler()
    if out is None:
        src = gdal.Open(tif)
        names = [src.GetRasterBand(i + 1).GetDescription() for i in range(src.RasterCount)]
        src = None
        reason = " ".join(reason.replace(f"{dest}: ", "").split()).rstrip(".")
        why = f": {reason}" if reason else ""
        if len(names) > 1:
            why += (f"; the noise grid has {len(names)} bands ({', '.join(names)}): write a GeoTIFF (.tif), or choose "
                    "one metric (parameter METRICS) without uncertainty bands for a one-band format")
        raise QgsProcessingException(f"GDAL could not write {dest!r} as {driver} (parameter OUTPUT_RASTER){why}")
    out = None


def _contour_layers(geojson):
    """The core's contours as two memory-free OGR layers: isobands (polygons) and isolines (lines)."""
    layers = []
    for geometry in ("Polygon", "LineString"):
        layer = QgsVectorLayer(f"{geojson}|geometrytype={geometry}", f"contours {geometry}", "ogr")
        if not layer.isValid():
            raise QgsProcessingException(f"cannot read the contours the core wrote ({geojson})")
        layers.append(layer)
    bands, lines = layers
    if QgsWkbTypes.geometryType(bands.wkbType()) != QgsWkbTypes.PolygonGeometry:
        raise QgsProcessingException("the core's contours hold no isobands")
    return bands, lines


__all__ = ["NoiseMapAlgorithm"]
