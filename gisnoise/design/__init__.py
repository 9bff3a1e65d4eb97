"""Measurement design: plans, the design model, objectives (paper section 6, D-optimal), optimizer, study.
"""

from __future__ import annotations

