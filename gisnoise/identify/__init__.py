"""Identification: the output-error fit with the maximum-likelihood estimator, its result and report.
"""

from __future__ import annotations

