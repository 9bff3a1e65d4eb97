"""Operations: schedules of many flights, periods, Lden, tiles, Dask.
"""

from __future__ import annotations

