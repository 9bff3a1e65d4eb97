"""Measurements: the campaign reader and level writer, the samples a fit and a diagnosis take.
"""

from __future__ import annotations

from gisnoise.measure.campaign import (
    campaign_log_warnings,
    check_campaign,
    inspect_campaign,
    read_campaign,
)
from gisnoise.measure.document import (
    SCHEMA,
)
from gisnoise.measure.emission import (
    emission_time,
)
from gisnoise.measure.events import (
    DEFAULT_EVENT_DB,
    DEFAULT_SNR_DB,
    detect_events,
    fit_level_trend,
)
from gisnoise.measure.levels import (
    CLASS1_TOP_HZ,
    DEFAULT_BLOCK_S,
    band_column,
    band_limit_warnings,
    read_level_csv,
    wav_levels,
    write_level_csv,
    write_levels,
)
from gisnoise.measure.parts import (
    Campaign,
    Exclusion,
    Flight,
    LevelSeries,
    Microphone,
    Problem,
)
from gisnoise.measure.provenance import (
    SOURCE_SUFFIX,
    source_record_path,
    stale_source,
)
from gisnoise.measure.samples import (
    Samples,
    series_ids,
    series_key,
)
from gisnoise.measure.spreading import (
    OUTLIER_DB,
    WINDOW_S,
    spreading_notes,
    spreading_outliers,
)
from gisnoise.measure.table import (
    SIGNAL_BAND_MARGIN_DB,
    build_samples,
)

__all__ = ['CLASS1_TOP_HZ', 'DEFAULT_BLOCK_S', 'DEFAULT_EVENT_DB', 'DEFAULT_SNR_DB', 'OUTLIER_DB', 'SCHEMA', 'SIGNAL_BAND_MARGIN_DB', 'SOURCE_SUFFIX', 'WINDOW_S', 'Campaign', 'Exclusion', 'Flight', 'LevelSeries', 'Microphone', 'Problem', 'Samples', 'band_column', 'band_limit_warnings', 'build_samples', 'campaign_log_warnings', 'check_campaign', 'detect_events', 'emission_time', 'fit_level_trend', 'inspect_campaign', 'read_campaign', 'read_level_csv', 'series_ids', 'series_key', 'source_record_path', 'spreading_notes', 'spreading_outliers', 'stale_source', 'wav_levels', 'write_level_csv', 'write_levels']
