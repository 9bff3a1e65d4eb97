"""Route planners in QGIS: candidate routes compared by exposure, and a quieter route between two pads.

The core's ``compare_routes`` and ``optimize_route`` take no progress or cancel callbacks: the
progress bar moves between the steps the plugin drives (reading the layers, the core's
computation, writing the files), and a cancel stops at the next of them, before any file is written.
"""

from __future__ import annotations

import json
import os

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsCoordinateTransform,
    QgsProcessing,
    QgsProcessingException,
    QgsProcessingOutputNumber,
    QgsProcessingOutputString,
    QgsProcessingParameterCrs,
    QgsProcessingParameterEnum,
    QgsProcessingParameterFile,
    QgsProcessingParameterFolderDestination,
    QgsProcessingParameterMultipleLayers,
    QgsProcessingParameterNumber,
    QgsProcessingParameterPoint,
    QgsProcessingParameterRasterLayer,
    QgsProcessingParameterString,
    QgsProcessingParameterVectorLayer,
    QgsProject,
)

from .._core import ensure_core
from .base import GisnoiseAlgorithm

METRICS = ("LAmax", "LAeq", "SEL")


def _cards(alg, parameters, context):
    text = alg.parameterAsString(parameters, alg.CARDS, context)
    refs = [c.strip() for c in text.replace(";", ",").split(",") if c.strip()]
    if not refs:
        raise QgsProcessingException("no model card given (parameter CARDS)")
    return refs


def _population(alg, parameters, context):
    from gisnoise.exposure import read_population

    layer = alg.parameterAsRasterLayer(parameters, alg.POPULATION, context)
    return None if layer is None else read_population(layer.source())


def _buildings(alg, parameters, context):
    path = alg.parameterAsFile(parameters, alg.BUILDINGS, context)
    if not path:
        return None
    from gisnoise.exposure import read_buildings

    return read_buildings(path)


def step(feedback, percent):
    """A step the plugin drives is done: stop here when the user cancelled, else move the bar to ``percent``."""
    if feedback.isCanceled():
        raise QgsProcessingException("cancelled by the user")
    feedback.setProgress(percent)


class _PlanningBase(GisnoiseAlgorithm):
    CARDS = "CARDS"
    POPULATION = "POPULATION"
    BUILDINGS = "BUILDINGS"
    OUTPUT_FOLDER = "OUTPUT_FOLDER"
    GROUP = "Route planning"
    GROUP_ID = "planning"

    def _exposure(self, parameters, context, feedback, start, end):
        """The population raster and the buildings, read with a step each from ``start`` to ``end`` percent."""
        step(feedback, start)
        population = _population(self, parameters, context)
        step(feedback, (start + end) / 2)
        buildings = _buildings(self, parameters, context)
        step(feedback, end)
        return population, buildings

    def _layers(self):
        self.addParameter(QgsProcessingParameterString(
            self.CARDS, "Model cards (files or bundled ids, comma-separated)",
            defaultValue="demo-horizontal,demo-climb,demo-sink"))
        self.addParameter(QgsProcessingParameterRasterLayer(
            self.POPULATION, "Population raster (people per cell)", optional=True))
        self.addParameter(QgsProcessingParameterFile(
            self.BUILDINGS, "Buildings with residents/dwellings (GeoPackage, GeoJSON, Shapefile)", optional=True,
            fileFilter="Vector files (*.gpkg *.geojson *.json *.shp)"))


class CompareRoutesAlgorithm(_PlanningBase):
    """``gisnoise compare``: candidate routes on one grid, ranked by the people they expose."""

    ROUTES = "ROUTES"
    METRIC = "METRIC"
    LEVELS = "LEVELS"
    RESOLUTION = "RESOLUTION"
    MARGIN = "MARGIN"
    CRS = "CRS"
    RANK_LEVEL = "RANK_LEVEL"
    GROUND_HEIGHT = "GROUND_HEIGHT"
    PERIOD = "PERIOD"
    BEST = "BEST"

    CORE_FIELDS = {"routes": ROUTES, "metric": METRIC, "levels": LEVELS, "rank_level": RANK_LEVEL,
                   "resolution_m": RESOLUTION, "grid.resolution_m": RESOLUTION, "margin_m": MARGIN, "crs": CRS,
                   "ground_h": GROUND_HEIGHT, "ground_h_m": GROUND_HEIGHT, "period_s": PERIOD,
                   "population": "POPULATION", "buildings": "BUILDINGS", "cards": "CARDS"}
    CLI_OPTIONS = {"--ground-height": GROUND_HEIGHT, "--period": PERIOD, "--margin": MARGIN,
                   "--resolution": RESOLUTION, "--levels": LEVELS, "--rank-level": RANK_LEVEL, "--crs": CRS,
                   "--metric": METRIC, "--population": "POPULATION", "--buildings": "BUILDINGS", "--card": "CARDS"}
    PHRASES = {"a wider margin": "a wider margin (parameter MARGIN)",
               "gisnoise contour --dem": "the noise map (gisnoise:noisemap) with a DEM"}

    def name(self):
        return "compareroutes"

    def displayName(self):  # noqa: N802 - QGIS API
        return "Compare candidate routes by exposure"

    def shortHelpString(self):  # noqa: N802 - QGIS API
        return ("Evaluates every candidate route (flight CSV, GeoJSON LineString with times, waypoints) on one "
                "common grid and ranks them by the people above the ranking level (one of the levels), then "
                "person-dB above the lowest level, then the peak level at a dwelling. The grid spans the routes and "
                "the margin around them; counts above a level the grid's edge cuts are lower bounds (said in the "
                "log: widen the margin). Writes comparison.json, comparison.md, levels.tif (one band per route) and "
                "difference.tif (each route minus the best, dB) into the output folder.")

    def initAlgorithm(self, config=None):  # noqa: N802 - QGIS API
        self.addParameter(QgsProcessingParameterMultipleLayers(
            self.ROUTES, "Candidate routes (files)", layerType=QgsProcessing.TypeFile))
        self._layers()
        self.addParameter(QgsProcessingParameterEnum(self.METRIC, "Metric", options=list(METRICS), defaultValue=0))
        self.addParameter(QgsProcessingParameterString(
            self.LEVELS, "Levels for the people above (dB(A), comma separated, each within -50..200)",
            "45,50,55,60,65"))
        self.addParameter(QgsProcessingParameterNumber(
            self.RANK_LEVEL, "Rank by people above (dB(A), one of the levels)", QgsProcessingParameterNumber.Double,
            55.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.RESOLUTION, "Grid cell (m)", QgsProcessingParameterNumber.Double, 20.0, minValue=0.5))
        self.addParameter(QgsProcessingParameterNumber(
            self.MARGIN, "Margin around all routes (m; empty: from the cards, so every route's lowest level closes)",
            QgsProcessingParameterNumber.Double, None, optional=True, minValue=0.0))
        self.addParameter(QgsProcessingParameterCrs(
            self.CRS, "Grid CRS (projected, metres; empty: local UTM zone)", optional=True))
        self.addParameter(QgsProcessingParameterNumber(
            self.GROUND_HEIGHT, "Flat ground height (m, ellipsoidal; empty: stated by the routes, else a take-off "
            "or landing point; routes all in the air need it)", QgsProcessingParameterNumber.Double, optional=True))
        self.addParameter(QgsProcessingParameterNumber(
            self.PERIOD, "LAeq averaging period, the same for every route (s; metric LAeq only; empty: the longest "
            "route's duration)", QgsProcessingParameterNumber.Double, optional=True, minValue=0.0))
        self.addParameter(QgsProcessingParameterFolderDestination(self.OUTPUT_FOLDER, "Output folder"))
        self.addOutput(QgsProcessingOutputString(self.BEST, "best route"))

    def _levels(self, parameters, context):
        ensure_core()
        from gisnoise.errors import GisnoiseError
        from gisnoise.maps import parse_levels

        try:
            return parse_levels(self.parameterAsString(parameters, self.LEVELS, context), field="LEVELS")
        except GisnoiseError as exc:
            raise QgsProcessingException(self.core_error(exc)) from None

    def checkParameterValues(self, parameters, context):  # noqa: N802 - QGIS API
        ok, msg = super().checkParameterValues(parameters, context)
        if not ok:
            return ok, msg
        try:
            levels = self._levels(parameters, context)
        except QgsProcessingException as exc:
            return False, str(exc)
        rank = self.parameterAsDouble(parameters, self.RANK_LEVEL, context)
        if rank not in levels:
            return False, (f"RANK_LEVEL {rank:g} dB(A) is not one of the levels (parameter LEVELS: "
                           f"{', '.join(f'{v:g}' for v in levels)}): the people above a level are counted at the "
                           "levels only; rank by one of them, or add it to LEVELS")
        crs = self.parameterAsCrs(parameters, self.CRS, context)
        if crs.isValid() and crs.isGeographic():
            return False, (f"grid CRS (parameter CRS) must be projected in metres, got "
                           f"{crs.authid() or crs.description()}")
        return True, ""

    def compute(self, parameters, context, feedback):
        from gisnoise.planning import compare_routes, write_comparison

        routes = self.parameterAsFileList(parameters, self.ROUTES, context)
        out = self.parameterAsString(parameters, self.OUTPUT_FOLDER, context)
        levels = self._levels(parameters, context)
        crs = self.parameterAsCrs(parameters, self.CRS, context)
        population, buildings = self._exposure(parameters, context, feedback, 2.0, 10.0)
        feedback.pushInfo(f"comparing {len(routes)} routes on one grid")
        cmp = compare_routes(list(routes), _cards(self, parameters, context), population=population,
                             progress=lambda f: feedback.setProgress(10.0 + 80.0 * f), cancel=feedback.isCanceled,
                             buildings=buildings,
                             metric=METRICS[self.parameterAsEnum(parameters, self.METRIC, context)],
                             levels=levels, rank_level_db=self.parameterAsDouble(parameters, self.RANK_LEVEL, context),
                             resolution_m=self.parameterAsDouble(parameters, self.RESOLUTION, context),
                             margin_m=(None if parameters.get(self.MARGIN) in (None, "")
                                       else self.parameterAsDouble(parameters, self.MARGIN, context)),
                             crs=(crs.authid() or crs.toWkt(QgsCoordinateReferenceSystem.WKT_PREFERRED))
                             if crs.isValid() else None,
                             ground_h=(None if parameters.get(self.GROUND_HEIGHT) in (None, "")
                                       else self.parameterAsDouble(parameters, self.GROUND_HEIGHT, context)),
                             period_s=(None if parameters.get(self.PERIOD) in (None, "")
                                       else self.parameterAsDouble(parameters, self.PERIOD, context)))
        step(feedback, 90.0)
        write_comparison(cmp, out)
        for r in cmp.doc["ranking"]:
            feedback.pushInfo(f"{r['rank']}. {r['route']}")
        for w in cmp.doc["warnings"]:
            self.warn(feedback, w)
        feedback.setProgress(100.0)
        return {self.OUTPUT_FOLDER: out, self.BEST: cmp.best}


class QuieterRouteAlgorithm(_PlanningBase):
    """``gisnoise route optimize``: a least-exposure flyable route between two pads."""

    START = "START"
    GOAL = "GOAL"
    AVOID = "AVOID"
    ALTITUDE = "ALTITUDE"
    MAX_DETOUR = "MAX_DETOUR"
    RESOLUTION = "RESOLUTION"
    REDUCTION_PCT = "REDUCTION_PCT"
    ROUTE = "ROUTE"

    CORE_FIELDS = {"from": START, "to": GOAL, "avoid": AVOID, "altitude": ALTITUDE, "max_detour": MAX_DETOUR,
                   "resolution_m": RESOLUTION, "population": "POPULATION", "buildings": "BUILDINGS",
                   "cards": "CARDS"}
    CLI_OPTIONS = {"--from": START, "--to": GOAL, "--avoid": AVOID, "--altitude": ALTITUDE,
                   "--max-detour": MAX_DETOUR, "--resolution": RESOLUTION, "--population": "POPULATION",
                   "--buildings": "BUILDINGS", "--card": "CARDS"}

    def name(self):
        return "quieterroute"

    def displayName(self):  # noqa: N802 - QGIS API
        return "Find a quieter route"

    def shortHelpString(self):  # noqa: N802 - QGIS API
        return ("Least-exposure route from the take-off to the landing pad: graph search on a cost grid (people "
                "within the 55 dB(A) LAmax corridor per metre), no-fly polygons, a maximum detour, smoothed into "
                "fly-by waypoints that keep the vehicle's turn radius; re-evaluated with the full evaluator against "
                "the direct route. Writes route.geojson (waypoints), direct.geojson, optimize.json and the "
                "comparison into the output folder.")

    def initAlgorithm(self, config=None):  # noqa: N802 - QGIS API
        self.addParameter(QgsProcessingParameterPoint(self.START, "Take-off pad"))
        self.addParameter(QgsProcessingParameterPoint(self.GOAL, "Landing pad"))
        self._layers()
        self.addParameter(QgsProcessingParameterVectorLayer(
            self.AVOID, "No-fly polygons", types=[QgsProcessing.TypeVectorPolygon], optional=True))
        self.addParameter(QgsProcessingParameterNumber(
            self.ALTITUDE, "Cruise altitude above ground (m)", QgsProcessingParameterNumber.Double, 60.0,
            minValue=1.0, maxValue=1000.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.MAX_DETOUR, "Maximum detour (%)", QgsProcessingParameterNumber.Double, 30.0, minValue=0.0,
            maxValue=300.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.RESOLUTION, "Cost grid cell (m)", QgsProcessingParameterNumber.Double, 50.0, minValue=5.0))
        self.addParameter(QgsProcessingParameterFolderDestination(self.OUTPUT_FOLDER, "Output folder"))
        self.addOutput(QgsProcessingOutputNumber(self.REDUCTION_PCT, "fewer people above 55 dB(A) (%)"))
        self.addOutput(QgsProcessingOutputString(self.ROUTE, "waypoints file of the quieter route"))

    def _lonlat(self, parameters, name, context):
        wgs = QgsCoordinateReferenceSystem("EPSG:4326")
        p = self.parameterAsPoint(parameters, name, context, wgs)
        return (p.x(), p.y())

    def compute(self, parameters, context, feedback):
        from gisnoise.geo import shapes
        from gisnoise.planning import optimize_route, waypoints_geojson, write_comparison

        polys = []
        layer = self.parameterAsVectorLayer(parameters, self.AVOID, context)
        if layer is not None:
            tr = QgsCoordinateTransform(layer.crs(), QgsCoordinateReferenceSystem("EPSG:4326"), QgsProject.instance())
            total = max(layer.featureCount(), 1)
            for i, f in enumerate(layer.getFeatures()):
                step(feedback, 2.0 * (i + 1) / total)
                g = f.geometry()
                g.transform(tr)
                shp = shapes.from_wkb(bytes(g.asWkb()))
                polys.extend(list(shp.geoms) if shp.geom_type == "MultiPolygon" else [shp])
        population, buildings = self._exposure(parameters, context, feedback, 2.0, 10.0)
        feedback.pushInfo("searching the quieter route and comparing it with the direct one")
        res = optimize_route(self._lonlat(parameters, self.START, context),
                             self._lonlat(parameters, self.GOAL, context), _cards(self, parameters, context),
                             population=population, buildings=buildings, avoid=polys,
                             altitude_m=self.parameterAsDouble(parameters, self.ALTITUDE, context),
                             max_detour_pct=self.parameterAsDouble(parameters, self.MAX_DETOUR, context),
                             resolution_m=self.parameterAsDouble(parameters, self.RESOLUTION, context),
                             progress=lambda f: feedback.setProgress(10.0 + 80.0 * f), cancel=feedback.isCanceled)
        step(feedback, 90.0)
        for w in res.comparison.doc["warnings"]:  # each route checked as its map would be, and clipped counts
            self.warn(feedback, w)
        out = self.parameterAsString(parameters, self.OUTPUT_FOLDER, context)
        write_comparison(res.comparison, out)
        route = os.path.join(out, "route.geojson")
        for name, doc in ((route, res.optimized_doc), (os.path.join(out, "direct.geojson"), res.direct_doc)):
            with open(name, "w", encoding="utf-8") as fh:
                json.dump(waypoints_geojson(doc), fh, indent=1)
        with open(os.path.join(out, "optimize.json"), "w", encoding="utf-8") as fh:
            json.dump(res.summary, fh, indent=1)
        feedback.pushInfo(json.dumps(res.summary, indent=1))
        feedback.setProgress(100.0)
        return {self.OUTPUT_FOLDER: out, self.REDUCTION_PCT: float(res.summary["reduction_pct"]), self.ROUTE: route}
