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
    check_diagnosable,
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
    REGIME_SHARE,
    localize,
    measurement_noise,
    sample_regimes,
)
from gisnoise.diagnose.metadata import (
    CLOCK_RANGE_S,
    HEIGHT_RANGE_M,
    clocks_disagree,
    estimate_clock_offsets,
    estimate_mic_heights,
    mic_clock_effect,
    shift_inputs,
)
from gisnoise.diagnose.offsets import (
    OFFSET_Z,
    competing_effects,
    judged_with,
    level_offsets,
    offset_groups,
    with_offsets,
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
from gisnoise.diagnose.selection import (
    MAX_EFFECTS,
    forward_selection,
    metadata_overrides,
)
from gisnoise.diagnose.verdict import (
    MIN_IMPROVEMENT_DB2,
)

__all__ = ['CLOCK_RANGE_S', 'DIAGNOSIS_FILE', 'Diagnosis', 'EFFECT_INPUT', 'HEIGHT_RANGE_M', 'MAX_EFFECTS',
           'MIN_IMPROVEMENT_DB2', 'OFFSET_Z', 'REGIME_SHARE', 'SCHEMA', 'before_after_data', 'candidate_inputs', 'check_diagnosable', 'clocks_disagree', 'competing_effects', 'diagnose',
           'estimate_clock_offsets', 'estimate_mic_heights', 'fold_labels', 'forward_selection', 'inputs_data',
           'judged_with', 'level_offsets', 'load_samples', 'localize', 'measurement_noise', 'metadata_overrides', 'mic_clock_effect',
           'offset_groups', 'register_evidence', 'residual_events', 'run_diagnosis', 'sample_regimes', 'shift_inputs',
           'timeline_data', 'with_mic_heights', 'with_offsets', 'write_diagnosis', 'write_report']
