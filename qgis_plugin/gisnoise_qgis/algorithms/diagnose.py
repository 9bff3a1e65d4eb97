"""Diagnose a model card against a campaign: ``gisnoise.diagnose.run_diagnosis`` in QGIS."""

from __future__ import annotations

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsFeature,
    QgsFeatureSink,
    QgsField,
    QgsFields,
    QgsGeometry,
    QgsLineString,
    QgsPoint,
    QgsProcessing,
    QgsProcessingException,
    QgsProcessingOutputNumber,
    QgsProcessingOutputString,
    QgsProcessingParameterFeatureSink,
    QgsProcessingParameterFile,
    QgsProcessingParameterFileDestination,
    QgsProcessingParameterFolderDestination,
    QgsProcessingParameterString,
    QgsWkbTypes,
)
from qgis.PyQt.QtCore import QVariant

from . import styles
from .base import GisnoiseAlgorithm, output_path

SEGMENT_FIELDS = (("flight", QVariant.String), ("mic", QVariant.String), ("t0", QVariant.Double),
                  ("t1", QVariant.Double), ("rms_db", QVariant.Double), ("mean_db", QVariant.Double),
                  ("excess_db", QVariant.Double), ("n", QVariant.Int), ("regime", QVariant.String),
                  ("range", QVariant.String), ("d_median_m", QVariant.Double),
                  ("bank_abs_mean_deg", QVariant.Double))
MIC_FIELDS = (("id", QVariant.String), ("mount", QVariant.String), ("n", QVariant.Int),
              ("rms_db", QVariant.Double), ("mean_db", QVariant.Double), ("flagged_fraction", QVariant.Double),
              ("noise_std_db", QVariant.Double))


def _fields(spec):
    fields = QgsFields()
    for name, kind in spec:
        fields.append(QgsField(name, kind))
    return fields


class DiagnoseAlgorithm(GisnoiseAlgorithm):
    """Where a card misses the measurements, which unmodelled effect explains it, how far the gap shrinks."""

    CAMPAIGN = "CAMPAIGN"
    CARD = "CARD"
    CANDIDATES = "CANDIDATES"
    OUTPUT_JSON = "OUTPUT_JSON"
    OUTPUT_REPORT = "OUTPUT_REPORT"
    OUTPUT_SEGMENTS = "OUTPUT_SEGMENTS"
    OUTPUT_MICS = "OUTPUT_MICS"
    VERDICT = "VERDICT"
    BASELINE_RMS_DB = "BASELINE_RMS_DB"
    HOLDOUT_SHRINKAGE_PCT = "HOLDOUT_SHRINKAGE_PCT"

    GROUP = "Model cards"
    GROUP_ID = "cards"

    def name(self):
        return "diagnose"

    def displayName(self):  # noqa: N802 - QGIS API
        return "Diagnose a model card against a campaign"

    def shortHelpString(self):  # noqa: N802 - QGIS API
        return (
            "Compares a model card with the measurements of a campaign folder: where the residual exceeds what "
            "the measurement noise explains (segments of the flights, per microphone), which unmodelled effect "
            "explains it (bank angle, atmospheric absorption, ground reflection, Doppler, emission time, wind, "
            "propeller speed, background events; each tested as a model extension), and how far the residual "
            "shrinks on data not used to fit it.\n\n"
            "Outputs: diagnosis.json, the flagged segments as lines along the flight tracks, the microphones "
            "with their residual statistics, and the verdict."
        )

    def initAlgorithm(self, config=None):  # noqa: N802 - QGIS API
        self.addParameter(QgsProcessingParameterFile(
            self.CAMPAIGN, "Campaign folder", behavior=QgsProcessingParameterFile.Folder))
        self.addParameter(QgsProcessingParameterFile(
            self.CARD, "Model card", behavior=QgsProcessingParameterFile.File, fileFilter="Model card (*.json)"))
        self.addParameter(QgsProcessingParameterString(
            self.CANDIDATES, "Effects to test (comma separated; empty: all)", optional=True))
        self.addParameter(QgsProcessingParameterFileDestination(
            self.OUTPUT_JSON, "Diagnosis", fileFilter="JSON (*.json)"))
        self.addParameter(QgsProcessingParameterFolderDestination(
            self.OUTPUT_REPORT, "Report (report.html and figures)", optional=True, createByDefault=False))
        self.addParameter(QgsProcessingParameterFeatureSink(
            self.OUTPUT_SEGMENTS, "Flagged segments", QgsProcessing.TypeVectorLine, optional=True,
            createByDefault=True))
        self.addParameter(QgsProcessingParameterFeatureSink(
            self.OUTPUT_MICS, "Microphones with residuals", QgsProcessing.TypeVectorPoint, optional=True,
            createByDefault=True))
        self.addOutput(QgsProcessingOutputString(self.VERDICT, "effect that explains the gap (empty: none)"))
        self.addOutput(QgsProcessingOutputNumber(self.BASELINE_RMS_DB, "rms residual of the card (dB)"))
        self.addOutput(QgsProcessingOutputNumber(self.HOLDOUT_SHRINKAGE_PCT, "held-out shrinkage of the verdict (%)"))

    def compute(self, parameters, context, feedback):
        from gisnoise.diagnose import run_diagnosis, write_diagnosis
        from gisnoise.measure import campaign_log_warnings, read_campaign
        from gisnoise.model import cards as gcards

        folder = self.parameterAsFile(parameters, self.CAMPAIGN, context)
        if not folder:
            raise QgsProcessingException("no campaign folder given (parameter CAMPAIGN)")
        card_path = self.parameterAsFile(parameters, self.CARD, context)
        if not card_path:
            raise QgsProcessingException("no model card given (parameter CARD)")
        card = gcards.load(card_path)
        text = self.parameterAsString(parameters, self.CANDIDATES, context) or ""
        candidates = [c.strip() for c in text.split(",") if c.strip()] or None
        dest = output_path(self, parameters, self.OUTPUT_JSON, context)

        def progress(done, total, what=""):
            feedback.setProgress(80.0 * min(float(done) / max(float(total), 1.0), 1.0))
            if what:
                feedback.pushInfo(str(what))

        campaign = read_campaign(folder)
        for w in campaign_log_warnings(campaign):  # what the command line and the service say about the logs
            self.warn(feedback, w)
        feedback.pushInfo(f"diagnosing {card.id} against the campaign {folder}")
        diag = run_diagnosis(campaign, card, candidates=candidates, progress=progress, cancel=feedback.isCanceled)
        write_diagnosis(diag, dest, campaign=folder)
        result = diag.result
        verdict = result.get("verdict") or {}
        effect = verdict.get("effect")
        shrink = verdict.get("holdout_shrinkage_pct")
        base = (result.get("baseline") or {}).get("rms_db")
        feedback.pushInfo(f"baseline rms {base} dB; verdict: {effect or 'no significant effect'}"
                          + (f", held-out shrinkage {shrink:.1f} %" if isinstance(shrink, (int, float)) else ""))
        judged = (verdict.get("candidates_judged_with") or {}).get("sentence")
        if judged:
            feedback.pushInfo(f"judged with offsets: {judged}")
        out = {self.OUTPUT_JSON: dest, self.VERDICT: effect or "",
               self.BASELINE_RMS_DB: base if base is not None else float("nan"),
               self.HOLDOUT_SHRINKAGE_PCT: shrink if isinstance(shrink, (int, float)) else float("nan")}
        report = self.parameterAsString(parameters, self.OUTPUT_REPORT, context)
        if report and parameters.get(self.OUTPUT_REPORT) not in (None, ""):
            from gisnoise.diagnose import write_report

            feedback.pushInfo(f"writing the report into {report}")
            write_report(diag, report)
            out[self.OUTPUT_REPORT] = report
        feedback.setProgress(90.0)
        seg_dest = self._segments(parameters, context, feedback, campaign, result.get("segments") or [])
        if seg_dest:
            out[self.OUTPUT_SEGMENTS] = seg_dest
        mic_dest = self._mics(parameters, context, campaign, result)
        if mic_dest:
            out[self.OUTPUT_MICS] = mic_dest
        self._style(out, context)
        feedback.setProgress(100.0)
        return out

    def _segments(self, parameters, context, feedback, campaign, segments):
        sink, dest = self.parameterAsSink(parameters, self.OUTPUT_SEGMENTS, context, _fields(SEGMENT_FIELDS),
                                          QgsWkbTypes.LineStringZ, QgsCoordinateReferenceSystem("EPSG:4326"))
        if sink is None:
            if dest:
                raise QgsProcessingException(self.invalidSinkError(parameters, self.OUTPUT_SEGMENTS))
            return None
        for seg in segments:
            if feedback.isCanceled():
                raise QgsProcessingException("cancelled by the user")
            traj = campaign.trajectories.get(seg["flight"])
            if traj is None:
                raise QgsProcessingException(f"diagnosis segment of unknown flight {seg['flight']!r}")
            t0, t1 = float(seg["t0"]), float(seg["t1"])
            inner = [float(t) for t in traj.t if t0 < t < t1]
            times = [t0, *inner, t1]
            state = traj.interpolate(times)
            line = QgsLineString([QgsPoint(float(lon), float(lat), float(h))
                                  for lon, lat, h in zip(state["lon"], state["lat"], state["h"], strict=True)])
            f = QgsFeature(_fields(SEGMENT_FIELDS))
            f.setGeometry(QgsGeometry(line))
            f.setAttributes([seg.get(name) for name, _ in SEGMENT_FIELDS])
            sink.addFeature(f, QgsFeatureSink.FastInsert)
        return dest

    def _mics(self, parameters, context, campaign, result):
        sink, dest = self.parameterAsSink(parameters, self.OUTPUT_MICS, context, _fields(MIC_FIELDS),
                                          QgsWkbTypes.PointZ, QgsCoordinateReferenceSystem("EPSG:4326"))
        if sink is None:
            if dest:
                raise QgsProcessingException(self.invalidSinkError(parameters, self.OUTPUT_MICS))
            return None
        stats = {row["bin"]: row for row in (result.get("statistics") or {}).get("by_mic", [])}
        noise = result.get("noise_std_db") or {}
        for mic in campaign.microphones:
            row = stats.get(mic.id, {})
            f = QgsFeature(_fields(MIC_FIELDS))
            f.setGeometry(QgsGeometry(QgsPoint(mic.lon, mic.lat, mic.h)))
            f.setAttributes([mic.id, mic.mount, row.get("n"), row.get("rms_db"), row.get("mean_db"),
                             row.get("flagged_fraction"), noise.get(mic.id)])
            sink.addFeature(f, QgsFeatureSink.FastInsert)
        return dest

    def _style(self, out, context):
        dest = out.get(self.OUTPUT_SEGMENTS)
        if dest and context.willLoadLayerOnCompletion(dest):
            context.layerToLoadOnCompletionDetails(dest).setPostProcessor(
                styles.keep(styles.ResidualStyle("rms_db")))
