"""Operations: schedules of many flights, periods, Lden, tiles, Dask.
"""

from __future__ import annotations

from gisnoise.ops.operations import (
    # noqa: E402     Flight,
    Flight,
    Schedule,
    evaluate_operations,
    lden,
    load_schedule,
    period_of,
    schedule_from_dict,
    tile_windows,
    write_operations,
)
from gisnoise.ops.scale import (
    local_cluster,
)

__all__ = ['# noqa: E402     Flight', 'Flight', 'Schedule', 'evaluate_operations', 'lden', 'load_schedule', 'local_cluster', 'period_of', 'schedule_from_dict', 'tile_windows', 'write_operations']
