"""Measurements: the campaign reader and level writer, the samples a fit and a diagnosis take.
"""

from __future__ import annotations

from gisnoise.measure.campaign import (
    DEFAULT_EVENT_DB,
    DEFAULT_SNR_DB,
    Exclusion,
    check_campaign,
    emission_time,
    inspect_campaign,
    read_campaign,
    read_level_csv,
    write_level_csv,
    write_levels,
)
from gisnoise.measure.samples import (
    Samples,
    series_ids,
    series_key,
)

__all__ = ['DEFAULT_EVENT_DB', 'DEFAULT_SNR_DB', 'Exclusion', 'Samples', 'check_campaign', 'emission_time', 'inspect_campaign', 'read_campaign', 'read_level_csv', 'series_ids', 'series_key', 'write_level_csv', 'write_levels']
