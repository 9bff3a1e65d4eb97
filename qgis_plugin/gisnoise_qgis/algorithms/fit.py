"""Fit a model card to a measurement campaign: ``gisnoise.identify.fit.fit_campaign`` in QGIS."""

from __future__ import annotations

from qgis.core import (
    QgsProcessingException,
    QgsProcessingOutputNumber,
    QgsProcessingOutputString,
    QgsProcessingParameterEnum,
    QgsProcessingParameterFile,
    QgsProcessingParameterFileDestination,
    QgsProcessingParameterFolderDestination,
    QgsProcessingParameterNumber,
    QgsProcessingParameterString,
)

from .base import GisnoiseAlgorithm, output_path

#: Flight phases (SPEC section 1); the core checks them again.
PHASES = ("horizontal", "climb", "sink", "hover", "transition")


class FitCardAlgorithm(GisnoiseAlgorithm):
    """Output-error maximum-likelihood fit of one flight phase; writes a model card."""

    CAMPAIGN = "CAMPAIGN"
    PHASE = "PHASE"
    ANSATZ = "ANSATZ"
    MAX_ITER = "MAX_ITER"
    OUTPUT_CARD = "OUTPUT_CARD"
    OUTPUT_REPORT = "OUTPUT_REPORT"
    RMS_DB = "RMS_DB"
    N_SAMPLES = "N_SAMPLES"
    CARD_ID = "CARD_ID"

    GROUP = "Model cards"
    GROUP_ID = "cards"

    def name(self):
        return "fitcard"

    def displayName(self):  # noqa: N802 - QGIS API
        return "Fit a model card to a campaign"

    def shortHelpString(self):  # noqa: N802 - QGIS API
        return (
            "Identifies the emission model of one flight phase from a measurement campaign folder "
            "(campaign.json, flights/, mics/) with the output-error method and a maximum-likelihood "
            "estimator (one noise variance per microphone), and writes a model card (JSON) holding the "
            "parameters, their covariance, the fit statistics and the provenance.\n\n"
            "Outputs: the card file, the rms residual (dB) and the number of samples used."
        )

    def initAlgorithm(self, config=None):  # noqa: N802 - QGIS API
        self.addParameter(QgsProcessingParameterFile(
            self.CAMPAIGN, "Campaign folder", behavior=QgsProcessingParameterFile.Folder))
        self.addParameter(QgsProcessingParameterEnum(
            self.PHASE, "Flight phase", options=list(PHASES), defaultValue=0))
        self.addParameter(QgsProcessingParameterString(
            self.ANSATZ, "Ansatz (registry name)", defaultValue="paper-offset"))
        self.addParameter(QgsProcessingParameterNumber(
            self.MAX_ITER, "Maximum Gauss-Newton iterations", QgsProcessingParameterNumber.Integer, 100,
            minValue=1, maxValue=10000))
        self.addParameter(QgsProcessingParameterFileDestination(
            self.OUTPUT_CARD, "Model card", fileFilter="Model card (*.json)"))
        self.addParameter(QgsProcessingParameterFolderDestination(
            self.OUTPUT_REPORT, "Fit report (report.html and the paper's plots)", optional=True,
            createByDefault=False))
        self.addOutput(QgsProcessingOutputNumber(self.RMS_DB, "rms residual (dB)"))
        self.addOutput(QgsProcessingOutputNumber(self.N_SAMPLES, "samples used"))
        self.addOutput(QgsProcessingOutputString(self.CARD_ID, "card id"))

    def compute(self, parameters, context, feedback):
        from gisnoise.identify import fit_campaign
        from gisnoise.measure import campaign_log_warnings, read_campaign
        from gisnoise.model import cards as gcards

        folder = self.parameterAsFile(parameters, self.CAMPAIGN, context)
        if not folder:
            raise QgsProcessingException("no campaign folder given (parameter CAMPAIGN)")
        phase = PHASES[self.parameterAsEnum(parameters, self.PHASE, context)]
        ansatz = self.parameterAsString(parameters, self.ANSATZ, context).strip()
        max_iter = self.parameterAsInt(parameters, self.MAX_ITER, context)
        dest = output_path(self, parameters, self.OUTPUT_CARD, context)

        def progress(iteration, cost):
            feedback.setProgress(min(100.0 * iteration / max_iter, 99.0))
            feedback.pushDebugInfo(f"iteration {iteration}: negative log-likelihood {cost:.4f}")

        camp = read_campaign(folder)
        for w in campaign_log_warnings(camp):  # what the command line and the service say about the logs
            self.warn(feedback, w)
        feedback.pushInfo(f"fitting ansatz {ansatz!r} to the {phase} samples of {folder}")
        result = fit_campaign(camp, phase, ansatz=ansatz, max_iter=max_iter, progress=progress,
                              cancel=feedback.isCanceled)
        feedback.pushInfo(result.summary())
        for w in result.info.get("warnings") or []:  # a microphone the model misses alone, as the command line says
            self.warn(feedback, w)
        card = result.to_card()
        gcards.save(card, dest)
        out = {self.OUTPUT_CARD: dest, self.RMS_DB: result.rms_db, self.N_SAMPLES: int(result.n),
               self.CARD_ID: card.id}
        report = self.parameterAsString(parameters, self.OUTPUT_REPORT, context)
        if report and parameters.get(self.OUTPUT_REPORT) not in (None, ""):
            from gisnoise.identify import write_report

            feedback.pushInfo(f"writing the fit report into {report}")
            write_report(result, report)
            out[self.OUTPUT_REPORT] = report
        feedback.setProgress(100.0)
        return out
