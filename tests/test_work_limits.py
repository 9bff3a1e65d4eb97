"""The shared rule set's sample and work bounds, applied by every reader and before any map is evaluated.

* at least two samples (one sample has no duration: no LAeq, SEL or time above);
* no gap between samples longer than ``max_gap_s`` (600 s): refused with the gap's place, never split;
* grid cells x time steps of one map within ``max_work``: refused before evaluating (exit 2 naming
  ``resolution_m``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_cli_contour import flyover, write_csv
from test_limits import card, refused, run  # noqa: F401 - the card fixture

from gisnoise import limits
from gisnoise.errors import TrajectoryError
from gisnoise.flight import from_columns, read_flight, read_flight_csv, read_trajectory

DATA = Path(__file__).resolve().parent / "data"


def _columns(t):
    n = len(t)
    return dict(t=np.asarray(t, dtype=float), lat=np.full(n, 52.2), lon=10.5 + 1e-4 * np.arange(n),
                h=np.full(n, 150.0), roll=np.zeros(n), pitch=np.zeros(n), yaw=np.full(n, 90.0),
                power_w=np.full(n, 3000.0))


def _timed_linestring(times):
    coords = [[10.5 + 1e-4 * i, 52.2, 150.0] for i in range(len(times))]
    return {"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords},
            "properties": {"times": list(times)}}


def test_at_least_two_samples_in_every_reader(tmp_path, card):  # noqa: F811
    with pytest.raises(TrajectoryError, match=r"t: 1 sample; a trajectory needs at least 2") as e:
        from_columns(_columns([0.0]))
    assert e.value.field == "t"
    with pytest.raises(TrajectoryError, match="at least 2") as e:
        read_trajectory(_timed_linestring([0.0]))
    assert e.value.field == "t"
    csv = tmp_path / "one.csv"
    csv.write_text("t,lat,lon,h,roll,pitch,yaw,power_w\n0,52.2,10.5,150,0,0,90,3000\n")
    with pytest.raises(TrajectoryError, match="at least 2"):
        read_flight_csv(csv)
    refused(run("contour", str(csv), "--card", card, "--out", str(tmp_path / "m"), "--resolution", "50"),
            "t", "1 sample", "at least 2")
    assert not (tmp_path / "m").exists()
    assert len(from_columns(_columns([0.0, 1.0]))) == 2  # two are enough


def test_a_gap_longer_than_the_limit_is_refused_by_every_reader(tmp_path):
    t = [0.0, 1.0, 2.0, 603.0, 604.0]  # a gap of 601 s before sample 3
    msg = r"t: gap of 601 s before sample 3 \(t=603 s\) is longer than 600 s"
    with pytest.raises(TrajectoryError, match=msg) as e:
        from_columns(_columns(t))
    assert e.value.field == "t"
    with pytest.raises(TrajectoryError, match=msg):
        read_trajectory(_timed_linestring(t))
    rows = ["t,lat,lon,h,roll,pitch,yaw,power_w"] + [f"{ti},52.2,{10.5 + 1e-4 * i},150,0,0,90,3000"
                                                     for i, ti in enumerate(t)]
    (tmp_path / "gap.csv").write_text("\n".join(rows) + "\n")
    with pytest.raises(TrajectoryError, match=msg):
        read_flight_csv(tmp_path / "gap.csv")
    # exactly at the limit is accepted; the limit has an override
    assert len(from_columns(_columns([0.0, 600.0]))) == 2
    with limits.override(max_gap_s=1000.0):
        assert len(from_columns(_columns(t))) == 5


def test_flight_logs_are_held_to_the_same_gap_rule():
    """A real PX4 log (samples 0.2 s apart on the reader's 5 Hz timeline) passes the 600 s rule and is refused
    by the same check once the limit is set below its sample spacing."""
    log = DATA / "pyulog_sample_log_small_vtol.ulg"
    tr = read_flight(log, power_w=3000.0)
    spacing = float(np.diff(tr.t).max())
    assert 0 < spacing <= limits.current().max_gap_s
    with limits.override(max_gap_s=spacing / 2), pytest.raises(TrajectoryError, match="gap of") as e:
        read_flight(log, power_w=3000.0)
    assert e.value.field == "t"


def test_map_work_is_bounded_before_evaluating(tmp_path, card):  # noqa: F811
    tr = flyover()  # 41 samples
    csv = write_csv(tmp_path / "f.csv", tr)
    out = tmp_path / "m"
    # 50 m cells over the 400 m track with a 200 m margin: a grid of some hundred cells; x 41 samples x 4 substeps
    r = _run_env(["contour", csv, "--card", card, "--out", str(out), "--resolution", "50", "--margin", "200",
                          "--ground-height", "0", "--substeps", "4"], env={"GISNOISE_MAX_WORK": "1000"})
    line = refused(r, "resolution_m", "x 164 time steps", "more than the limit of 1000", "GISNOISE_MAX_WORK")
    cells = int(line.split("needs ")[1].split(" cells")[0])
    assert 100 < cells < 1000  # (400 + 2 x 200) / 50 = 16 columns, (0 + 2 x 200) / 50 = 8 rows, plus snapping
    assert not out.exists()
    # the same map within the limit is made
    r = _run_env(["contour", csv, "--card", card, "--out", str(out), "--resolution", "50", "--margin", "200",
                          "--ground-height", "0", "--substeps", "4"], env={"GISNOISE_MAX_WORK": str(cells * 164)})
    assert r.exit_code == 0, r.output
    assert (out / "levels.tif").is_file()


def _run_env(args, env):
    from click.testing import CliRunner

    from gisnoise.cli.main import cli

    return CliRunner().invoke(cli, ["-q", *args], env=env)


def test_waypoint_longitudes_are_never_wrapped():
    """A waypoint at longitude 200 was flown at -160 (PROJ wraps); the shared rule refuses it, naming lon."""
    wps = [{"lon": 10.5, "lat": 52.2, "alt": 60.0}, {"lon": 200.0, "lat": 52.2, "alt": 60.0}]
    doc = {"schema": "gisnoise/waypoints/1", "altitude_reference": "agl", "waypoints": wps}
    with pytest.raises(TrajectoryError, match=r"waypoint 1: lon: 200 deg is outside \[-180, 180\] deg") as e:
        read_trajectory(doc)
    assert e.value.field == "lon"
    wps[1]["lon"] = 10.51
    assert np.all(np.abs(read_trajectory(doc).lon - 10.505) <= 0.0051)  # flown between the two waypoints
