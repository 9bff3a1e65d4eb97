"""The ground rule of maps: a track in the air needs --ground-height or --dem; with the ground given the
flyover map equals the closed form (point source, spherical spreading, straight track at constant speed)."""

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner
from pyproj import Transformer

from gisnoise.cli.main import cli
from gisnoise.flight import Trajectory, ground_from_track
from gisnoise.geo import LocalFrame
from gisnoise.model import ModelCard, save

FRAME = LocalFrame(52.27, 10.52, 0.0)
G0, HEIGHT, SPEED, X0, X1 = 70.0, 60.0, 10.0, -600.0, 600.0


def flyover(dt=0.1):
    t = np.arange(0.0, (X1 - X0) / SPEED + dt / 2, dt)
    x = X0 + SPEED * t
    lat, lon, h = FRAME.to_wgs84(x, np.zeros_like(t), np.full_like(t, HEIGHT))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=np.full_like(t, 90.0),
                      power_w=np.full_like(t, 3000.0), phase=np.full(t.size, "horizontal"))


@pytest.fixture()
def files(tmp_path):
    card = ModelCard(id="omni", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0)
    csv = tmp_path / "flyover.csv"
    flyover().to_csv(csv)
    return str(csv), str(save(card, tmp_path / "omni.json"))


def run(*args):
    return CliRunner().invoke(cli, ["-q", *args], catch_exceptions=False)


def test_airborne_track_without_ground_exits_2_naming_both_options(tmp_path, files):
    csv, card = files
    r = run("contour", csv, "--card", card, "--out", str(tmp_path / "m"))
    assert r.exit_code == 2
    assert "--ground-height" in r.output and "--dem" in r.output
    assert len(r.output.strip().splitlines()) == 1 and not (tmp_path / "m" / "levels.tif").exists()


def test_with_ground_height_the_map_equals_the_closed_form_flyover(tmp_path, files):
    csv, card = files
    out = tmp_path / "m"
    r = run("contour", csv, "--card", card, "--out", str(out), "--ground-height", "0", "--resolution", "25",
            "--margin", "150", "--metrics", "LAmax,SEL")
    assert r.exit_code == 0, r.output
    _assert_closed_form_flyover(out)


def _assert_closed_form_flyover(out):
    """LAmax and SEL of the map in ``out`` equal the closed form of the flyover (receivers 1.5 m above h = 0)."""
    with rasterio.open(out / "levels.tif") as ds:
        bands = {n: ds.read(i + 1) for i, n in enumerate(ds.descriptions)}
        rows, cols = np.mgrid[0:ds.height, 0:ds.width]
        xs, ys = rasterio.transform.xy(ds.transform, rows.ravel(), cols.ravel(), offset="center")
        to_ll = Transformer.from_crs(ds.crs, "EPSG:4326", always_xy=True)
    lon, lat = to_ll.transform(np.asarray(xs), np.asarray(ys))
    e, n, u = FRAME.to_enu(lat, lon, np.full(len(lat), 1.5))   # receivers 1.5 m above the ground at h = 0
    r_perp = np.hypot(n, HEIGHT - u)
    inside = (e > X0 + 100) & (e < X1 - 100)                    # closest approach within the track
    lamax = G0 - 20.0 * np.log10(r_perp / 40.0)                 # p1 log10(P/P_ref) = 0, p6 = 1
    # SEL = 10 log10 of the integral of 10^(L/10) dt with d^2 = r^2 + (x(t) - e)^2, x(t) = X0 + v t
    integral = 10 ** (G0 / 10) * 40.0 ** 2 / (SPEED * r_perp) * (np.arctan((X1 - e) / r_perp)
                                                                  - np.arctan((X0 - e) / r_perp))
    sel = 10.0 * np.log10(integral)
    np.testing.assert_allclose(bands["LAmax"].ravel()[inside], lamax[inside], atol=0.1)
    np.testing.assert_allclose(bands["SEL"].ravel(), sel, atol=0.1)
    assert inside.sum() > 100


def test_a_vehicle_lying_upside_down_after_the_flyover_is_silent_and_named(tmp_path, files):
    """The log resumes 30 s after the flyover with the vehicle upside down at rest on the ground below the track's end
    (roll 178 deg), motors still at 3000 W, no landing flag: it cannot hover inverted, so those 20 s make no sound,
    the map stays the closed-form flyover, and a warning names the samples."""
    _, card = files
    tr = flyover()
    tail = tr.t[-1] + 30.0 + np.arange(0.0, 20.0, 0.1)
    lat, lon, h = FRAME.to_wgs84(np.full_like(tail, X1), 0 * tail, 0 * tail)
    z = np.zeros_like(tail)
    crashed = Trajectory(t=np.concatenate([tr.t, tail]), lat=np.concatenate([tr.lat, lat]),
                         lon=np.concatenate([tr.lon, lon]), h=np.concatenate([tr.h, h]),
                         roll=np.concatenate([tr.roll, z + 178.0]), pitch=np.concatenate([tr.pitch, z - 3.0]),
                         yaw=np.concatenate([tr.yaw, z + 90.0]), power_w=np.concatenate([tr.power_w, z + 3000.0]),
                         phase=np.full(len(tr) + tail.size, "horizontal"))
    csv = tmp_path / "crashed.csv"
    crashed.to_csv(csv)
    out = tmp_path / "m"
    r = run("contour", str(csv), "--card", card, "--out", str(out), "--ground-height", "0", "--resolution", "25",
            "--margin", "150", "--metrics", "LAmax,SEL")
    assert r.exit_code == 0, r.output
    _assert_closed_form_flyover(out)
    named = f"{tail.size} samples from t = {tail[0]:.1f} s to {tail[-1]:.1f} s lie upside down at rest"
    assert named in r.output and named in " ".join(_map_meta(out)["warnings"])


def test_ground_from_track_takes_a_take_off_or_landing_only():
    tr = flyover()
    assert ground_from_track(tr) is None
    h = tr.h.copy()
    h[:50] = h[:50] - np.linspace(60.0, 0.0, 50)                 # climbs from the ground
    up = tr.with_(h=h, phase=np.where(np.arange(len(h)) < 50, "climb", "horizontal"))
    assert ground_from_track(up) == pytest.approx(float(h[0]))
    parked = tr.with_(on_ground=np.arange(len(h)) >= len(h) - 3)   # landed at the end (flag)
    assert ground_from_track(parked) == pytest.approx(float(tr.h[-1]))
    # a stretch cut from a log with a land detector that ends in a low hover, airborne by the detector, at its own
    # lowest point: no landing (the hover's height is no ground; a slice of a real log took it, 4.8 m too high)
    low = h.copy()
    low[-10:] = float(h.min())
    hover_end = tr.with_(h=low, phase=np.where(np.arange(len(h)) >= len(h) - 10, "hover", "horizontal"))
    assert ground_from_track(hover_end) == pytest.approx(float(h.min()))     # without a detector: at rest, lowest
    assert ground_from_track(hover_end.with_(on_ground=np.zeros(len(h), bool))) is None


def _hop(tmp_path, end_h):
    """Take-off from the ground (motors off at the first sample), climb to 60 m, fly, descend to ``end_h`` (m
    relative to the take-off point) still flying: a log whose GPS heights drift below the take-off point."""
    tr = flyover(dt=0.5)
    n = len(tr.t)
    k = np.arange(n)
    h0 = float(tr.h[0]) - HEIGHT
    h = tr.h.copy()
    h[:20] = h0 + np.linspace(0.0, HEIGHT, 20)
    h[-20:] = h0 + np.linspace(HEIGHT, end_h, 20)
    power = np.where(k == 0, 0.0, 3000.0)
    phase = np.where(k < 20, "climb", np.where(k >= n - 20, "sink", "horizontal"))
    csv = tmp_path / f"hop{end_h:g}.csv"
    tr.with_(h=h, power_w=power, phase=phase).to_csv(csv)
    card = ModelCard(id="omni", vehicle="test", phase="horizontal", phases=["climb", "sink"], ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0)
    return str(csv), str(save(card, tmp_path / "omni3.json")), h0


def _map_meta(out):
    import json

    with rasterio.open(out / "levels.tif") as ds:
        return json.loads(ds.tags()["gisnoise"])


@pytest.mark.parametrize("end_h, below", [(0.0, False), (-3.0, True)])
def test_ground_from_the_take_off_point_is_named_and_a_track_below_it_is_flagged(tmp_path, end_h, below):
    """The metadata say where the ground came from; a track that flies more than the height noise below the ground
    taken from its own take-off point (GPS heights drift) puts the UAV under the receivers: the map says so."""
    csv, card, h0 = _hop(tmp_path, end_h)
    out = tmp_path / "m"
    r = run("contour", csv, "--card", card, "--out", str(out), "--resolution", "50", "--margin", "100",
            "--metrics", "LAmax")
    assert r.exit_code == 0, r.output
    meta = _map_meta(out)
    assert meta["ground_h_m"] == pytest.approx(h0, abs=1e-6)
    assert meta["ground_h_source"] == "take-off or landing point of the track"
    flagged = [w for w in meta["warnings"] if "below the ground" in w]
    assert bool(flagged) == below
    if below:
        assert "3.0 m below" in flagged[0] and "--ground-height" in flagged[0]
        assert "warning:" in r.output and "below the ground" in r.output
    given = tmp_path / "g"
    r = run("contour", csv, "--card", card, "--out", str(given), "--resolution", "50", "--margin", "100",
            "--metrics", "LAmax", "--ground-height", str(h0 + end_h - 1.0))
    assert r.exit_code == 0, r.output
    meta = _map_meta(given)
    assert meta["ground_h_source"] == "given" and not [w for w in meta["warnings"] if "below the ground" in w]


def test_a_snapshot_outside_a_track_with_samples_on_the_ground_is_refused(tmp_path):
    """A snapshot after the end of a track that starts on the ground is refused naming snapshot_t, as for a track in
    the air throughout (it gave a band without a value and no word)."""
    csv, card, h0 = _hop(tmp_path, 0.0)
    end = float(flyover(dt=0.5).t[-1])
    out = tmp_path / "m"
    r = run("contour", csv, "--card", card, "--out", str(out), "--resolution", "50", "--margin", "100",
            "--metrics", "LAmax", "--snapshot", str(end + 100.0))
    assert r.exit_code == 2 and "snapshot_t" in r.output and len(r.output.strip().splitlines()) == 1
    assert not (out / "levels.tif").exists()
    r = run("contour", csv, "--card", card, "--out", str(out), "--resolution", "50", "--margin", "100",
            "--metrics", "LAmax", "--snapshot", str(end / 2))
    assert r.exit_code == 0, r.output
    assert f"LA@{end / 2:g}s" in _map_meta(out)["units"]


def test_the_laeq_period_must_cover_the_whole_track_also_with_samples_on_the_ground(tmp_path):
    """The LAeq period covers the trajectory's duration, samples on the ground included (its default); a shorter one
    is refused naming the track's duration, not that of its flying stretch."""
    csv, card, h0 = _hop(tmp_path, 0.0)
    end = float(flyover(dt=0.5).t[-1])
    r = run("contour", csv, "--card", card, "--out", str(tmp_path / "m"), "--resolution", "50", "--margin", "100",
            "--metrics", "LAeq", "--period", str(end - 0.25))
    assert r.exit_code == 2 and "period_s" in r.output and f"({end:g} s)" in r.output
    r = run("contour", csv, "--card", card, "--out", str(tmp_path / "m"), "--resolution", "50", "--margin", "100",
            "--metrics", "LAeq", "--period", str(end))
    assert r.exit_code == 0, r.output


def test_an_unserved_phase_is_named_by_its_times_in_the_file(tmp_path):
    """A track whose first sample stands on the ground and which has no card for its climb: the refusal names the
    climb's samples and times as the file has them (they were counted among the flying samples only)."""
    csv, _, _ = _hop(tmp_path, 0.0)
    card = ModelCard(id="omni", vehicle="test", phase="horizontal", phases=["sink"], ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0)
    r = run("contour", csv, "--card", str(save(card, tmp_path / "nc.json")), "--out", str(tmp_path / "m"),
            "--resolution", "50", "--margin", "100")
    assert r.exit_code == 2 and "phase 'climb'" in r.output
    assert "samples 1-19, t = 0.5-9.5 s" in r.output


def test_a_grid_crs_that_scales_distances_at_the_map_is_flagged(tmp_path, files):
    """Cells of --resolution metres in a CRS whose scale at the map is far from 1 are not that size on the ground:
    Web Mercator scales by sec(latitude), 1.63 at 52.27 deg N, and the map says so; the local UTM zone (scale within
    0.04 % of 1 in its zone) gives no such warning."""
    import json
    import math

    csv, card = files
    for crs, flagged in (("EPSG:3857", True), (None, False)):
        out = tmp_path / (crs or "utm").replace(":", "_")
        args = ["contour", csv, "--card", card, "--out", str(out), "--ground-height", "0", "--resolution", "50",
                "--margin", "150", "--metrics", "LAmax"] + (["--crs", crs] if crs else [])
        r = run(*args)
        assert r.exit_code == 0, r.output
        with rasterio.open(out / "levels.tif") as ds:
            warnings = json.loads(ds.tags()["gisnoise"])["warnings"]
        hit = [w for w in warnings if "on the ground" in w]
        assert bool(hit) == flagged, warnings
        if flagged:
            k = 1.0 / math.cos(math.radians(FRAME.lat0))
            assert f"scales distances by {k:.3f}" in hit[0] and f"{50.0 / k:.1f} m on the ground" in hit[0]
