"""Measurement design: plans, the design model, objectives (paper section 6, D-optimal), optimizer, study.

Microphone positions and flight altitudes for an identifiable next campaign: when
distance, polar emission angle, bank angle and power move together in the data, the
maximum-likelihood estimate cannot tell their effects apart.  The modules, in the order
of a run (:func:`run_design`):

``plan``
    read and check a plan (:func:`load_plan`, :func:`resolve_plan`); :class:`Design`, :class:`Plan`
``snr``
    the signal-to-noise distance within which a sample counts (:func:`snr_distance`)
``designmodel``
    the pattern flown once by the simulator, the samples of any design (:class:`DesignModel`)
``objectives``
    the ``paper`` and ``d-optimal`` objectives of a design (:func:`evaluate`)
``optimizer``
    differential evolution within the plan's limits (:func:`optimize`)
``sweep``
    the optimum against the allowed displacement, paper Fig. 18 (:func:`study`)
``verification``
    campaigns simulated with each design and refitted (:func:`verify`)
``result``, ``run``
    the outcome of a run (:class:`DesignResult`) and the run itself (:func:`run_design`)
``output``, ``report``
    ``design.json``, ``layout.geojson`` (:func:`write_outputs`) and the report (:func:`write_report`)
"""

from __future__ import annotations

from gisnoise.design.designmodel import (
    DesignModel,
)
from gisnoise.design.objectives import (
    CORRELATION_VARIABLES,
    PATTERN_PAIRS,
    Evaluation,
    correlation_matrix,
    evaluate,
    fisher_information,
    max_abs_correlation,
)
from gisnoise.design.optimizer import (
    Optimum,
    optimize,
)
from gisnoise.design.output import (
    layout_geojson,
    write_outputs,
)
from gisnoise.design.plan import (
    OBJECTIVES,
    SCHEMA,
    Design,
    Plan,
    load_plan,
    resolve_plan,
)
from gisnoise.design.report import (
    layout_figure,
    std_ratios,
    study_curves,
    write_report,
)
from gisnoise.design.result import (
    RESULT_SCHEMA,
    DesignResult,
)
from gisnoise.design.run import (
    run_design,
)
from gisnoise.design.snr import (
    snr_distance,
)
from gisnoise.design.sweep import (
    StudyPoint,
    study,
)
from gisnoise.design.verification import (
    VerifyResult,
    campaign_scenario,
    verify,
)

__all__ = ['CORRELATION_VARIABLES', 'Design', 'DesignModel', 'DesignResult', 'Evaluation', 'OBJECTIVES', 'Optimum',
           'PATTERN_PAIRS', 'Plan', 'RESULT_SCHEMA', 'SCHEMA', 'StudyPoint', 'VerifyResult', 'campaign_scenario',
           'correlation_matrix', 'evaluate', 'fisher_information', 'layout_geojson', 'load_plan',
           'max_abs_correlation', 'optimize', 'resolve_plan', 'run_design', 'snr_distance', 'std_ratios',
           'layout_figure', 'study', 'study_curves', 'verify', 'write_outputs', 'write_report']
