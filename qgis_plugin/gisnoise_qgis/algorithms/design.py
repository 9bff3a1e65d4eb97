"""Optimize a measurement layout: ``gisnoise.design.run_design`` in QGIS."""

from __future__ import annotations

import math
import os

from qgis.core import (
    QgsFeature,
    QgsFeatureSink,
    QgsProcessing,
    QgsProcessingException,
    QgsProcessingOutputNumber,
    QgsProcessingParameterBoolean,
    QgsProcessingParameterEnum,
    QgsProcessingParameterFeatureSink,
    QgsProcessingParameterFile,
    QgsProcessingParameterFolderDestination,
    QgsProcessingParameterNumber,
    QgsVectorLayer,
    QgsWkbTypes,
)

from .base import GisnoiseAlgorithm

#: Objectives of the core (``gisnoise.design.OBJECTIVES``); the core checks them again.
OBJECTIVES = ("paper", "d-optimal")


class DesignLayoutAlgorithm(GisnoiseAlgorithm):
    """Microphone positions and flight altitudes that make the next campaign's fit identifiable."""

    PLAN = "PLAN"
    OBJECTIVES = "OBJECTIVES"
    STUDY = "STUDY"
    VERIFY_SEEDS = "VERIFY_SEEDS"
    REPORT = "REPORT"
    OUTPUT_FOLDER = "OUTPUT_FOLDER"
    OUTPUT_MICS = "OUTPUT_MICS"
    OUTPUT_TRACKS = "OUTPUT_TRACKS"
    PAPER_BASE = "PAPER_BASE"
    PAPER_OPTIMUM = "PAPER_OPTIMUM"
    DOPTIMAL_BASE = "DOPTIMAL_BASE"
    DOPTIMAL_OPTIMUM = "DOPTIMAL_OPTIMUM"

    GROUP = "Measurement design"
    GROUP_ID = "design"

    def name(self):
        return "designlayout"

    def displayName(self):  # noqa: N802 - QGIS API
        return "Optimize a measurement layout"

    def shortHelpString(self):  # noqa: N802 - QGIS API
        return (
            "Moves the microphones (within each one's allowed displacement, outside the exclusion polygons) and "
            "the altitude of each repetition of the flight pattern (within its range) of a design plan "
            "(JSON, schema gisnoise/design-plan/1) so that the next campaign's fit can tell the model's inputs "
            "apart. Objectives: 'paper' minimizes the largest absolute correlation among electric power, polar "
            "emission angle, distance and bank angle over the samples within the signal-to-noise distance; "
            "'d-optimal' maximizes the log-determinant of the fit's Fisher information.\n\n"
            "Outputs: design.json and layout.geojson in the output folder (and the report), the microphones and "
            "the tracks of the base and of each optimum as layers, and the objective values."
        )

    def initAlgorithm(self, config=None):  # noqa: N802 - QGIS API
        self.addParameter(QgsProcessingParameterFile(
            self.PLAN, "Design plan", behavior=QgsProcessingParameterFile.File, fileFilter="Design plan (*.json)"))
        self.addParameter(QgsProcessingParameterEnum(
            self.OBJECTIVES, "Objectives (empty: the plan's)", options=list(OBJECTIVES), allowMultiple=True,
            optional=True))
        self.addParameter(QgsProcessingParameterBoolean(
            self.STUDY, "Also run the plan's study of displacement and altitude range (slow)", False))
        self.addParameter(QgsProcessingParameterNumber(
            self.VERIFY_SEEDS, "Simulated campaigns that verify the d-optimal design (0: none; empty: the plan's)",
            QgsProcessingParameterNumber.Integer, optional=True, minValue=0, maxValue=1000))
        self.addParameter(QgsProcessingParameterBoolean(
            self.REPORT, "Write the report (plots, report.html)", True))
        self.addParameter(QgsProcessingParameterFolderDestination(
            self.OUTPUT_FOLDER, "Output folder"))
        self.addParameter(QgsProcessingParameterFeatureSink(
            self.OUTPUT_MICS, "Microphones (base and optima)", QgsProcessing.TypeVectorPoint, optional=True,
            createByDefault=True))
        self.addParameter(QgsProcessingParameterFeatureSink(
            self.OUTPUT_TRACKS, "Flight tracks (base and optima)", QgsProcessing.TypeVectorLine, optional=True,
            createByDefault=True))
        for key, label in ((self.PAPER_BASE, "largest |correlation| of the base design"),
                           (self.PAPER_OPTIMUM, "largest |correlation| of the 'paper' optimum"),
                           (self.DOPTIMAL_BASE, "-log det Fisher information of the base design"),
                           (self.DOPTIMAL_OPTIMUM, "-log det Fisher information of the 'd-optimal' optimum")):
            self.addOutput(QgsProcessingOutputNumber(key, label))

    def compute(self, parameters, context, feedback):
        from gisnoise.design import load_plan, run_design, write_outputs

        path = self.parameterAsFile(parameters, self.PLAN, context)
        if not path:
            raise QgsProcessingException("no design plan given (parameter PLAN)")
        plan = load_plan(path)
        chosen = self.parameterAsEnums(parameters, self.OBJECTIVES, context)
        objectives = [OBJECTIVES[i] for i in chosen] or None
        verify = None
        if parameters.get(self.VERIFY_SEEDS) not in (None, ""):
            verify = self.parameterAsInt(parameters, self.VERIFY_SEEDS, context)
        folder = self.parameterAsString(parameters, self.OUTPUT_FOLDER, context)
        os.makedirs(folder, exist_ok=True)

        def progress(fraction):
            feedback.setProgress(90.0 * min(max(float(fraction), 0.0), 1.0))

        result = run_design(plan, objectives=objectives, with_study=self.parameterAsBoolean(
            parameters, self.STUDY, context), verify_seeds=verify, progress=progress, cancel=feedback.isCanceled)
        files = write_outputs(result, folder, report=self.parameterAsBoolean(parameters, self.REPORT, context))
        feedback.setProgress(95.0)
        out = {self.OUTPUT_FOLDER: folder}
        base = result.base
        out[self.PAPER_BASE] = base.objective("paper")
        out[self.DOPTIMAL_BASE] = base.objective("d-optimal")
        out[self.PAPER_OPTIMUM] = result.optima["paper"].value if "paper" in result.optima else math.nan
        out[self.DOPTIMAL_OPTIMUM] = result.optima["d-optimal"].value if "d-optimal" in result.optima else math.nan
        for name, opt in result.optima.items():
            feedback.pushInfo(f"{name}: {opt.base_value:.4g} (base) -> {opt.value:.4g} (optimum); {opt.message}")
        layout = os.fspath(files["layout.geojson"])
        for key, geometry in ((self.OUTPUT_MICS, "Point"), (self.OUTPUT_TRACKS, "LineString")):
            dest = self._copy(parameters, key, layout, geometry, context, feedback)
            if dest:
                out[key] = dest
        feedback.setProgress(100.0)
        return out

    def _copy(self, parameters, key, layout, geometry, context, feedback):
        layer = QgsVectorLayer(f"{layout}|geometrytype={geometry}", geometry, "ogr")
        if not layer.isValid():
            raise QgsProcessingException(f"cannot read the layout the core wrote ({layout})")
        fields = layer.fields()
        sink, dest = self.parameterAsSink(parameters, key, context, fields, QgsWkbTypes.addZ(layer.wkbType()),
                                          layer.crs())
        if sink is None:
            if dest:
                raise QgsProcessingException(self.invalidSinkError(parameters, key))
            return None
        for feat in layer.getFeatures():
            if feedback.isCanceled():
                raise QgsProcessingException("cancelled by the user")
            sink.addFeature(QgsFeature(feat), QgsFeatureSink.FastInsert)
        return dest
