"""Real flight logs end to end: the one trajectory reader, on-ground samples, maps and campaigns.

Expectations come from pyulog and pymavlink directly, not from gisnoise.
"""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.flight import LOG_MAP_RATE_HZ, flying_segments, read_route

pyulog = pytest.importorskip("pyulog")
DFReader = pytest.importorskip("pymavlink.DFReader")

from test_logs import _coulomb_power  # noqa: E402  (pyulog read directly: V x 3.6 dQ/dt)

DATA = Path(__file__).parent / "data"
VTOL = DATA / "pyulog_sample_log_small_vtol.ulg"
QUAD = DATA / "robologs_test_quad_fmuv5.ulg"
COPTER = DATA / "dronekit_la_testdata_log171_copter.bin"
N_SITE = 22.0   # geoid undulation given for the ArduPilot log (Canberra), m


def run(*args):
    return CliRunner().invoke(cli, ["-q", *args], catch_exceptions=False)


def _ulog_expect(path):
    """Time base start, position, power and landed flag as pyulog reads them (boot time, s)."""
    u = pyulog.ULog(str(path))
    d, batteries = {}, []
    for x in u.data_list:
        d.setdefault(x.name, x.data)
        if x.name == "battery_status":
            batteries.append(x.data)
    if "vehicle_global_position" in d:
        g = d["vehicle_global_position"]
        tp, lat = g["timestamp"] / 1e6, g["lat"]
    else:
        g = d["vehicle_gps_position"]
        ok = g["fix_type"] >= 3
        tp, lat = g["timestamp"][ok] / 1e6, g["lat"][ok] / 1e7
    bats = [_coulomb_power(b) for b in batteries]
    ta = d["vehicle_attitude"]["timestamp"] / 1e6
    ld = d["vehicle_land_detected"]
    t0 = max([tp[0], ta[0]] + [tb[0] for tb, _ in bats])
    return t0, (tp, lat), bats, (ld["timestamp"] / 1e6, ld["landed"].astype(bool))


@pytest.mark.parametrize("path", [VTOL, QUAD])
def test_ulog_through_the_one_reader_equals_pyulog(path):
    tr = read_route(path).trajectory
    t0, (tp, lat), bats, (tl, landed) = _ulog_expect(path)
    t_abs = t0 + tr.t
    assert np.allclose(np.diff(tr.t), 1.0 / LOG_MAP_RATE_HZ)
    np.testing.assert_allclose(tr.lat, np.interp(t_abs, tp, lat), atol=1e-9)
    power = sum(np.interp(t_abs, tb, pw) for tb, pw in bats)   # every battery instance, V x mean I
    np.testing.assert_allclose(tr.power_w, power, rtol=1e-6, atol=1e-6)
    expect_landed = landed[np.clip(np.searchsorted(tl, t_abs, side="right") - 1, 0, len(tl) - 1)]
    np.testing.assert_array_equal(tr.on_ground, expect_landed)
    assert tr.metadata["height_datum"].startswith("ellipsoid")


def test_quad_with_zero_current_on_the_ground_is_read_not_refused():
    tr = read_route(QUAD).trajectory
    assert tr.power_w.min() == 0.0 and tr.on_ground.any()          # 0 A on the ground, kept
    assert not tr.flying[tr.power_w <= 0].any()                      # zero power never flies


def test_dataflash_on_ground_until_not_landed_event_and_power_equal_pymavlink():
    tr = read_route(COPTER, geoid_undulation_m=N_SITE).trajectory
    r = DFReader.DFReader_binary(str(COPTER), zero_time_base=True)
    curr, last, not_landed = [], 0.0, None
    while True:
        m = r.recv_match(type=["CURR", "ATT", "EV"])
        if m is None:
            break
        if m.get_type() == "EV":
            if m.Id == 28 and not_landed is None:   # NOT_LANDED
                not_landed = last
            continue
        last = m.TimeMS / 1e3
        if m.get_type() == "CURR":
            curr.append((last, m.Volt / 100.0 * m.Curr / 100.0))   # hundredths of V and A
    r.close()
    c = np.array(curr)
    assert not_landed is not None
    # boot time of the trajectory's first sample: the first instant where GPS, ATT and CURR are all logged
    gps_t = []
    r = DFReader.DFReader_binary(str(COPTER), zero_time_base=True)
    while (m := r.recv_match(type=["GPS", "ATT"])) is not None:
        if m.get_type() == "GPS" and m.Status >= 3:
            gps_t.append(m.T / 1e3)
    r.close()
    att0 = None
    r = DFReader.DFReader_binary(str(COPTER), zero_time_base=True)
    while (m := r.recv_match(type=["ATT"])) is not None:
        att0 = m.TimeMS / 1e3
        break
    r.close()
    t0 = max(gps_t[0], att0, c[0, 0])
    t_abs = t0 + tr.t
    np.testing.assert_allclose(tr.power_w, np.interp(t_abs, c[:, 0], c[:, 1]), rtol=1e-6)
    np.testing.assert_array_equal(tr.on_ground, t_abs < not_landed)
    assert tr.metadata["geoid_undulation_m"] == N_SITE and "mean sea level" in tr.metadata["height_datum"]


def _copter_end_raw():
    """log171 as pymavlink reads it (boot time, s): the trajectory's first sample (GPS 3D fix, ATT and CURR all
    logged), the take-off (the message before EV NOT_LANDED, 28), and the instant from which on the copter lies
    upside down at rest until the log ends: ATT inverted (cos(Roll) cos(Pitch) < 0) and the GPS receiver's own
    speed, horizontal Spd and vertical VZ, below 0.3 m/s at every fix."""
    r = DFReader.DFReader_binary(str(COPTER), zero_time_base=True)
    last, take_off, gps, att, curr0 = 0.0, None, [], [], None
    while (m := r.recv_match(type=["GPS", "ATT", "CURR", "EV"])) is not None:
        kind = m.get_type()
        if kind == "EV":
            if m.Id == 28 and take_off is None:
                take_off = last
        elif kind == "GPS":
            if m.Status >= 3:
                gps.append((m.T / 1e3, float(np.hypot(m.Spd, m.VZ))))
        else:
            last = m.TimeMS / 1e3
            if kind == "ATT":
                att.append((last, m.Roll, m.Pitch))
            elif curr0 is None:
                curr0 = last
    r.close()
    g, a = np.array(gps), np.array(att)
    up = np.cos(np.radians(a[:, 1])) * np.cos(np.radians(a[:, 2])) >= 0
    upright_near = np.interp(g[:, 0], a[:, 0], up.astype(float)) > 0     # an upright ATT sample at or next to the fix
    moving = upright_near | (g[:, 1] >= 0.3)
    t_rest = float(g[np.flatnonzero(moving)[-1] + 1, 0])
    return {"t0": max(g[0, 0], a[0, 0], curr0), "take_off": take_off, "t_rest": t_rest,
            "first_inverted": float(a[~up, 0][0])}


def test_copter_lying_upside_down_at_the_end_does_not_fly():
    """log171 ends with the quad upside down on the ground (ATT roll about 179 deg) for 12 s, drawing about 320 W, no
    landing or disarming logged (ACRO mode: ArduCopter 3.3 runs no crash check there).  It flies from the take-off
    event until it comes to rest inverted, 159.2 s by the log's own messages, and not after."""
    raw = _copter_end_raw()
    assert 238.0 < raw["first_inverted"] < raw["t_rest"] < 243.0      # tumbles at 239 s, at rest from 242 s
    tr = read_route(COPTER, geoid_undulation_m=N_SITE).trajectory
    t_abs = raw["t0"] + tr.t
    segs = flying_segments(tr)
    assert len(segs) == 1
    (i0, i1), = segs
    assert abs(t_abs[i0] - raw["take_off"]) <= 0.1 + 1e-6           # the sample at or after the event
    assert abs(t_abs[i1 - 1] - raw["t_rest"]) <= 0.5                 # the 1 s mean speed: half a window
    assert abs((tr.t[i1 - 1] - tr.t[i0]) - (raw["t_rest"] - raw["take_off"])) <= 0.5
    end = t_abs >= raw["t_rest"] + 0.5
    assert end.sum() >= 110 and not tr.flying[end].any() and tr.lying[end].all()
    assert np.all(np.abs(tr.roll[end]) > 170.0) and tr.power_w[end].min() > 250.0 and not tr.on_ground[end].any()
    assert not tr.lying[t_abs < raw["first_inverted"]].any()


def test_copter_map_names_the_upside_down_samples_and_is_silent_there(tmp_path, omni_card):
    raw = _copter_end_raw()
    out = tmp_path / "m"
    r = CliRunner().invoke(cli, ["-q", "contour", str(COPTER), "--card", omni_card, "--out", str(out), "--resolution", "20",
                                 "--margin", "100", "--geoid-undulation", str(N_SITE)])
    assert r.exit_code == 0, r.output
    tr = read_route(COPTER, geoid_undulation_m=N_SITE).trajectory
    with rasterio.open(out / "levels.tif") as ds:
        meta = json.loads(ds.tags()["gisnoise"])
    named = f"{int(tr.lying.sum())} samples from t = {tr.t[tr.lying][0]:.1f} s"
    assert named in r.stderr and "lie upside down" in r.stderr
    assert any(named in w for w in meta["warnings"])
    (t_a, t_b), = meta["flying_stretches"]
    assert abs(t_b - (raw["t_rest"] - raw["t0"])) <= 0.5 and t_b < tr.t[-1] - 11.0


@pytest.mark.parametrize("name,extra", [(VTOL, ()), (QUAD, ()), (COPTER, ("--geoid-undulation", str(N_SITE)))])
def test_every_log_makes_a_map_and_on_ground_samples_are_silent(tmp_path, omni_card, name, extra):
    log = tmp_path / (name.stem + name.suffix.upper())        # .ULG / .BIN as some autopilots write them
    shutil.copy(name, log)
    out = tmp_path / "map"
    r = run("contour", str(log), "--card", omni_card, "--out", str(out), "--resolution", "20", "--margin", "100",
            *extra)
    assert r.exit_code == 0, r.output
    with rasterio.open(out / "levels.tif") as ds:
        lamax = ds.read(list(ds.descriptions).index("LAmax") + 1)
    tr = read_route(log, geoid_undulation_m=N_SITE).trajectory
    # the loudest cell: 65 dB + 10 log10(P/300 W) at 40 m scaled by distance; never above the closest approach
    # of the flying samples to a receiver 1.5 m above the take-off point
    fly = tr.flying
    ground = float(tr.h[0])
    d_min = max(float(np.min(tr.h[fly] - ground - 1.5)), 0.1)
    bound = 65.0 + 10.0 * np.log10(tr.power_w[fly].max() / 300.0) - 20.0 * np.log10(d_min / 40.0)
    assert np.isfinite(lamax[lamax != -9999.0]).all()
    assert 30.0 < lamax.max() <= bound + 1e-6


def test_quad_airborne_samples_without_current_are_silent_and_named(tmp_path, omni_card):
    """The quad's land detector says airborne for about a second after each 0.2 m hop while the battery's
    coulomb count stands still (no current): those samples are silent, and the warning counts them."""
    tr = read_route(QUAD).trajectory
    t0, _, bats, (tl, landed) = _ulog_expect(QUAD)
    t_abs = t0 + tr.t
    airborne = ~landed[np.clip(np.searchsorted(tl, t_abs, side="right") - 1, 0, len(tl) - 1)]
    unpowered = airborne & (sum(np.interp(t_abs, tb, pw) for tb, pw in bats) <= 0)
    assert 0 < unpowered.sum() < airborne.sum()
    r = CliRunner().invoke(cli, ["-q", "contour", str(QUAD), "--card", omni_card, "--out", str(tmp_path / "m"),
                                 "--resolution", "20", "--margin", "100"])
    assert r.exit_code == 0, r.output
    named = f"{int(unpowered.sum())} of {int(airborne.sum())} airborne samples draw no battery current"
    assert named in r.stderr
    np.testing.assert_array_equal(tr.flying, airborne & ~unpowered)
    # the contours carry the map's warnings too (a service answering with GeoJSON alone shows them there)
    doc = json.loads((tmp_path / "m" / "contours.geojson").read_text())
    assert any(named in w for w in doc["gisnoise"]["warnings"])


def test_track_without_current_in_flight_names_power_w(tmp_path, omni_card):
    """A log that measures no current in flight (every airborne sample at 0 W): one line naming --power-w."""
    tr = read_route(VTOL).trajectory
    csv = tmp_path / "no_current.csv"
    tr.with_(power_w=np.zeros(len(tr))).to_csv(csv)
    r = run("contour", str(csv), "--card", omni_card, "--out", str(tmp_path / "m"), "--ground-height", str(tr.h.min()))
    assert r.exit_code == 2
    assert "--power-w" in r.output and "all" in r.output and len(r.output.strip().splitlines()) == 1


def test_copter_log_without_undulation_or_geoid_grid_names_the_option(tmp_path, omni_card, no_geoid_grid):
    r = run("contour", str(COPTER), "--card", omni_card, "--out", str(tmp_path / "m"))
    assert r.exit_code == 2 and "--geoid-undulation" in r.output


@pytest.mark.parametrize("name", [VTOL, QUAD, COPTER])
def test_campaign_check_reads_every_log(tmp_path, name):
    root = tmp_path / "camp"
    (root / "flights").mkdir(parents=True)
    (root / "mics" / "m1").mkdir(parents=True)
    shutil.copy(name, root / "flights" / ("f1" + name.suffix.upper()))
    from datetime import datetime, timezone

    from gisnoise.flight import read_flight

    tr = read_flight(name, geoid_undulation_m=N_SITE, start_utc=0.0)   # t in unix seconds (GPS clock of the log)
    start = datetime.fromtimestamp(float(tr.t[0]) - 1.0, tz=timezone.utc).isoformat().replace("+00:00", "Z")
    lat, lon = float(tr.lat[0]), float(tr.lon[0])
    doc = {"schema": "gisnoise/campaign/1", "origin": {"lat": lat, "lon": lon, "h": float(tr.h.min())},
           "speed_of_sound_m_s": 340.0, "weather": {"temperature_c": 10.0},
           "vehicle": {"name": "v", "reference_power_w": 300.0},
           "microphones": [{"id": "m1", "lat": lat + 1e-4, "lon": lon, "h": float(tr.h.min()) + 1.5,
                            "mount": "free_field"}],
           "flights": [{"id": "f1", "start_utc": start, "geoid_undulation_m": N_SITE}]}
    if name == QUAD:
        # the quad's battery draws current for 0.2 s of the second its land detector calls airborne (the 0.2 m hops
        # mostly happen while it still says landed): too little flight for levels; the flight states a constant power
        doc["flights"][0]["power_w"] = 150.0
    (root / "campaign.json").write_text(json.dumps(doc))
    t_r = np.arange(0.0, tr.duration_s + 2.0, 0.125)
    (root / "mics" / "m1" / "f1.csv").write_text("t,LA\n" + "".join(f"{t:.3f},60.0\n" for t in t_r))
    r = run("campaign", "check", str(root))
    assert r.exit_code == 0, r.output


def test_copter_with_the_demo_cards_warns_naming_each_card_and_its_powers(tmp_path):
    """log171 is a 1 kg quad drawing at most about 430 W (V x I of its CURR messages); the demo cards were fitted
    on a 35 kg eVTOL's campaign at 2.3-9.9 kW: every flying sample of every phase lies below the card it uses, and
    the map names each card with the powers it is used at."""
    from gisnoise.data import card_path
    from gisnoise.model import load, stated_power_range_w

    ids = ("demo-horizontal", "demo-climb", "demo-sink")
    out = tmp_path / "m"
    r = CliRunner().invoke(cli, ["-q", "contour", str(COPTER), *sum((["--card", c] for c in ids), []), "--out",
                                 str(out), "--resolution", "20", "--margin", "100", "--geoid-undulation", str(N_SITE)])
    assert r.exit_code == 0, r.output
    with rasterio.open(out / "levels.tif") as ds:
        meta = json.loads(ds.tags()["gisnoise"])
    tr = read_route(COPTER, geoid_undulation_m=N_SITE).trajectory
    cards = {c: load(card_path(c)) for c in ids}
    lowest = min(stated_power_range_w(c)[0] for c in cards.values())
    assert tr.power_w[tr.flying].max() < 0.25 * lowest
    outside = meta["power_outside_card_range"]
    served = {c: (card.phase, *card.phases) for c, card in cards.items()}
    used = [c for c in ids if np.isin(tr.phase[tr.flying], served[c]).any()]
    assert sorted(outside) == sorted(used) and len(used) >= 2
    for c in used:
        pw = tr.power_w[tr.flying & np.isin(tr.phase, served[c])]
        lo, hi = stated_power_range_w(cards[c])
        assert outside[c] == {"range_w": [lo, hi], "used_w": [pw.min(), pw.max()], "samples": pw.size}
        line = (f"card {c!r} is used at {pw.min():.4g}-{pw.max():.4g} W: {pw.size} flying sample(s) outside the "
                f"{lo:.4g}-{hi:.4g} W it was fitted at")
        assert line in r.stderr and any(line in w for w in meta["warnings"])
