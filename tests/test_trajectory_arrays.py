"""A trajectory owns read-only copies of its arrays; time columns in dates are refused, durations converted;
columns of the wrong shape are named, however the trajectory is built."""

from __future__ import annotations

import datetime

import numpy as np
import pytest

from gisnoise.errors import TrajectoryError
from gisnoise.flight import Trajectory, from_columns

N = 61
FIELDS = ("t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w", "phase", "rpm", "airspeed_m_s", "on_ground")


def columns(n: int = N) -> dict[str, np.ndarray]:
    t = np.arange(n) * 1.0
    return dict(t=t, lat=52.25 + 20 * t / 111_250.0, lon=np.full(n, 10.53), h=np.full(n, 150.0), roll=np.zeros(n),
                pitch=np.zeros(n), yaw=np.zeros(n), power_w=np.full(n, 3000.0), phase=np.array(["horizontal"] * n),
                rpm=np.full(n, 4000.0), airspeed_m_s=np.full(n, 20.0), on_ground=np.zeros(n, dtype=bool))


@pytest.mark.parametrize("build", [from_columns, lambda c: Trajectory(**c)], ids=["from_columns", "Trajectory"])
def test_editing_the_callers_arrays_leaves_the_trajectory_unchanged(build):
    c = columns()
    kept = {k: v.copy() for k, v in c.items()}
    tr = build(c)
    lying = tr.lying.copy()
    for k, v in c.items():
        assert not np.shares_memory(getattr(tr, k), v), k
    c["h"][:] = 110.0
    c["t"][10] = 5.0                       # no longer increasing
    c["roll"][:] = 180.0                   # upside down
    c["phase"][:] = "hover"
    c["on_ground"][:] = True
    for k in FIELDS:
        np.testing.assert_array_equal(getattr(tr, k), kept[k], err_msg=k)
    np.testing.assert_array_equal(tr.lying, lying)


def test_editing_a_dataframes_columns_leaves_the_trajectory_unchanged():
    pd = pytest.importorskip("pandas")
    df = pd.DataFrame(columns())
    tr = from_columns(df)
    assert not np.shares_memory(tr.h, df["h"].to_numpy())
    df.loc[:, "h"] = 110.0
    df.loc[:, "power_w"] = 10.0
    np.testing.assert_array_equal(tr.h, np.full(N, 150.0))
    np.testing.assert_array_equal(tr.power_w, np.full(N, 3000.0))


@pytest.mark.parametrize("name", FIELDS)
def test_writing_into_a_trajectorys_arrays_raises(name):
    tr = from_columns(columns())
    arr = getattr(tr, name)
    assert not arr.flags.writeable
    with pytest.raises(ValueError):
        arr[0] = arr[1]
    for derived in (tr.select(np.ones(N, dtype=bool)), tr.with_(h=np.full(N, 160.0))):
        assert not getattr(derived, name).flags.writeable


DATETIMES = {
    "numpy datetime64[m]": lambda n: np.arange("2024-05-04T10:00", "2024-05-04T11:01", dtype="datetime64[m]")[:n],
    "numpy datetime64[s]": lambda n: np.arange(n).astype("datetime64[s]"),
    "datetime objects": lambda n: [datetime.datetime(2024, 5, 4, 10, 0) + datetime.timedelta(seconds=i)
                                   for i in range(n)],
}


@pytest.mark.parametrize("make", list(DATETIMES.values()), ids=list(DATETIMES))
@pytest.mark.parametrize("build", [from_columns, lambda c: Trajectory(**c)], ids=["from_columns", "Trajectory"])
def test_dates_and_times_as_t_are_refused_naming_t_and_the_way_to_seconds(build, make):
    c = columns()
    c["t"] = make(N)
    with pytest.raises(TrajectoryError) as e:
        build(c)
    msg = str(e.value)
    assert e.value.field == "t" and len(msg.splitlines()) == 1
    assert "field 't'" in msg and "dates and times" in msg and '(t - t[0]) / np.timedelta64(1, "s")' in msg


def test_pandas_datetime_columns_are_refused_naming_t():
    pd = pytest.importorskip("pandas")
    t = np.arange(N) * 1.0
    for times in (pd.Timestamp("2024-05-04T10:00") + pd.to_timedelta(t, unit="s"),
                  pd.Timestamp("2024-05-04T10:00Z") + pd.to_timedelta(t, unit="s")):     # naive and tz-aware
        df = pd.DataFrame({**columns(), "t": times})
        with pytest.raises(TrajectoryError, match="field 't' holds dates and times") as e:
            from_columns(df)
        assert e.value.field == "t"


def test_durations_as_t_are_seconds():
    """A timedelta64 column carries its unit: one-minute steps are 60 s steps, an hour is 3600 s."""
    c = columns()
    c["t"] = np.arange(N).astype("timedelta64[m]")
    tr = from_columns(c)
    np.testing.assert_array_equal(tr.t, 60.0 * np.arange(N))
    assert tr.duration_s == 3600.0
    c["t"] = [datetime.timedelta(milliseconds=500 * i) for i in range(N)]
    np.testing.assert_array_equal(Trajectory(**c).t, 0.5 * np.arange(N))


def test_pandas_timedelta_column_is_seconds():
    pd = pytest.importorskip("pandas")
    df = pd.DataFrame({**columns(), "t": pd.to_timedelta(np.arange(N) * 250, unit="ms")})
    np.testing.assert_array_equal(from_columns(df).t, 0.25 * np.arange(N))


def test_durations_or_dates_in_another_field_are_refused_naming_it():
    c = columns()
    c["power_w"] = np.arange(N).astype("timedelta64[s]")
    with pytest.raises(TrajectoryError, match="field 'power_w' holds durations") as e:
        from_columns(c)
    assert e.value.field == "power_w"


@pytest.mark.parametrize("build", [from_columns, lambda c: Trajectory(**c)], ids=["from_columns", "Trajectory"])
@pytest.mark.parametrize("name", ["t", "h", "power_w", "rpm"])
def test_a_column_of_the_wrong_shape_is_named(build, name):
    c = columns()
    c[name] = c[name][:, None]             # (n, 1)
    with pytest.raises(TrajectoryError, match=rf"field '{name}' must be one-dimensional, got shape \({N}, 1\)") as e:
        build(c)
    assert e.value.field == name


@pytest.mark.parametrize("build", [from_columns, lambda c: Trajectory(**c)], ids=["from_columns", "Trajectory"])
def test_a_column_of_the_wrong_length_is_named(build):
    c = columns()
    c["h"] = c["h"][:-1]
    with pytest.raises(TrajectoryError, match=f"'h' has {N - 1} samples") as e:
        build(c)
    assert e.value.field == "h"
