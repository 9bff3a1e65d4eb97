"""Operations: schedules of many flights, periods, Lden, tiles, Dask.
"""

from __future__ import annotations

from gisnoise.ops.accumulate import (
    add_flight,
    new_accumulators,
    period_bands,
)
from gisnoise.ops.operations import (
    GROUND_SHIFT_DB,
    evaluate_operations,
    ground_shift_db,
    schedule_findings,
)
from gisnoise.ops.output import (
    write_operations,
)
from gisnoise.ops.periods import (
    PENALTY_DB,
    PERIOD_HOURS,
    PERIODS,
    lden,
    period_of,
)
from gisnoise.ops.scale import (
    local_cluster,
)
from gisnoise.ops.schedule import (
    SCHEMA,
    Flight,
    Schedule,
    load_schedule,
    schedule_from_dict,
)
from gisnoise.ops.tiles import (
    tile_windows,
)

__all__ = ['Flight', 'GROUND_SHIFT_DB', 'PENALTY_DB', 'PERIODS', 'PERIOD_HOURS', 'SCHEMA', 'Schedule', 'add_flight', 'evaluate_operations', 'ground_shift_db', 'lden', 'load_schedule', 'local_cluster', 'new_accumulators', 'period_bands', 'period_of', 'schedule_findings', 'schedule_from_dict', 'tile_windows', 'write_operations']
