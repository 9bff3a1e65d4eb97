"""The sim-to-real gap: where a card misses a campaign, which effect explains it, held-out shrinkage.
"""

from __future__ import annotations

from gisnoise.diagnose.candidates import (
    fold_labels,
)
from gisnoise.diagnose.diagnosis import (
    DIAGNOSIS_FILE,
    SCHEMA,
    Diagnosis,
    diagnose,
    run_diagnosis,
    write_diagnosis,
)
from gisnoise.diagnose.events import (
    residual_events,
)
from gisnoise.diagnose.evidence import (
    register_evidence,
)
from gisnoise.diagnose.localization import (
    localize,
    measurement_noise,
    sample_regimes,
)
from gisnoise.diagnose.report import (
    EFFECT_INPUT,
    before_after_data,
    candidate_inputs,
    inputs_data,
    timeline_data,
    write_report,
)
from gisnoise.diagnose.samples import (
    load_samples,
    with_mic_heights,
)
from gisnoise.diagnose.verdict import (
    MIN_IMPROVEMENT_DB2,
)

__all__ = ['DIAGNOSIS_FILE', 'Diagnosis', 'EFFECT_INPUT', 'MIN_IMPROVEMENT_DB2', 'SCHEMA', 'before_after_data',
           'candidate_inputs', 'diagnose', 'fold_labels', 'inputs_data', 'load_samples', 'localize',
           'measurement_noise', 'register_evidence', 'residual_events', 'run_diagnosis', 'sample_regimes',
           'timeline_data', 'with_mic_heights', 'write_diagnosis', 'write_report']
