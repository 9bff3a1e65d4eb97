"""Identification: the output-error fit with the maximum-likelihood estimator, its result and report.
"""

from __future__ import annotations

from gisnoise.identify.fit import (
    FitResult,
    fit_arrays,
    fit_campaign,
    usable_rows,
)
from gisnoise.identify.report import (
    correlation_data,
    directivity_data,
    write_report,
)

__all__ = ['FitResult', 'correlation_data', 'directivity_data', 'fit_arrays', 'fit_campaign', 'usable_rows', 'write_report']
