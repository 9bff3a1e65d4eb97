"""Measurement design: plans, the design model, objectives (paper section 6, D-optimal), optimizer, study.
"""

from __future__ import annotations

from gisnoise.design.design import (
    load_plan,
    resolve_plan,
    run_design,
    write_outputs,
)

__all__ = ['load_plan', 'resolve_plan', 'run_design', 'write_outputs']
