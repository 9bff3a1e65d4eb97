"""Clocks of flight logs: GPS week time to UTC, and instants given as datetime, ISO 8601 text or number."""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Any

import numpy as np

from gisnoise.errors import InputError

__all__ = ["gps_to_unix", "as_unix_time"]

_GPS_EPOCH_UNIX = 315964800.0  # 1980-01-06T00:00:00Z
# (first unix second of validity, GPS - UTC in s); IERS bulletin C
_LEAP_SECONDS = (
    (820454400.0, 11),   # 1996-01-01
    (867715200.0, 12),   # 1997-07-01
    (915148800.0, 13),   # 1999-01-01
    (1136073600.0, 14),  # 2006-01-01
    (1230768000.0, 15),  # 2009-01-01
    (1341100800.0, 16),  # 2012-07-01
    (1435708800.0, 17),  # 2015-07-01
    (1483228800.0, 18),  # 2017-01-01
)


def gps_to_unix(week: Any, ms_of_week: Any) -> np.ndarray:
    """Unix time (UTC, s) of GPS week and milliseconds of week, leap seconds removed.

    Examples
    --------
    >>> float(gps_to_unix(1871, 603882400.0))  # 2015-11-21 23:44:25.4 UTC (GPS - UTC = 17 s)
    1448149465.4
    """
    g = _GPS_EPOCH_UNIX + np.asarray(week, dtype=float) * 604800.0 + np.asarray(ms_of_week, dtype=float) / 1000.0
    leap = np.zeros_like(g)
    for start, n in _LEAP_SECONDS:
        leap = np.where(g - n >= start, n, leap)
    return g - leap


def as_unix_time(value: Any, *, field: str = "start_utc") -> float:
    """Unix seconds (UTC) of a datetime, an ISO 8601 string (``Z`` allowed) or a number."""
    if isinstance(value, datetime):
        dt = value if value.tzinfo else value.replace(tzinfo=timezone.utc)
        return dt.timestamp()
    if isinstance(value, str):
        s = value.strip()
        if s.endswith(("Z", "z")):
            s = s[:-1] + "+00:00"
        try:
            dt = datetime.fromisoformat(s)
        except ValueError:
            raise InputError(f"{field}: not an ISO 8601 time: {value!r}", field=field) from None
        return as_unix_time(dt, field=field)
    if isinstance(value, (int, float, np.number)) and np.isfinite(value):
        return float(value)
    raise InputError(f"{field}: expected an ISO 8601 time, got {value!r}", field=field)
