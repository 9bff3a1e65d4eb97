"""The sim-to-real gap: where a card misses a campaign, which effect explains it, held-out shrinkage.
"""

from __future__ import annotations

from gisnoise.diagnose.diagnosis import (
    run_diagnosis,
)
from gisnoise.diagnose.report import (
    write_report,
)

__all__ = ['run_diagnosis', 'write_report']
