"""Identification: the output-error fit with the maximum-likelihood estimator, its result and report.
"""

from __future__ import annotations

from gisnoise.identify.estimate import (
    DEFAULT_BOUNDS,
    DEFAULT_RCOND,
    MIN_DIRECTIVITY_FACTOR,
    CancelFn,
    ProgressFn,
    fit_arrays,
    start_values,
)
from gisnoise.identify.fit import (
    BACKGROUND_DOMINATED_DB,
    P7_MAX_STD_DB,
    STEADY_POWER_DEX,
    background_dominated_rows,
    fit,
    fit_campaign,
    identifiable_form,
    usable_rows,
)
from gisnoise.identify.report import (
    CORRELATION_VARIABLES,
    correlation_data,
    directivity_data,
    parameter_table,
    residual_data,
    timeseries_data,
    write_report,
)
from gisnoise.identify.result import FitResult

__all__ = ['BACKGROUND_DOMINATED_DB', 'background_dominated_rows', 'P7_MAX_STD_DB', 'STEADY_POWER_DEX', 'identifiable_form', 'CORRELATION_VARIABLES', 'CancelFn', 'DEFAULT_BOUNDS', 'DEFAULT_RCOND', 'MIN_DIRECTIVITY_FACTOR', 'FitResult', 'ProgressFn',
           'correlation_data', 'directivity_data', 'fit', 'fit_arrays', 'fit_campaign', 'parameter_table',
           'residual_data', 'start_values', 'timeseries_data', 'usable_rows', 'write_report']
