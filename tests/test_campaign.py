"""The campaign reader: emission time against the closed form, samples against known
geometry, masks against injected truth, and every problem named with file and field.

Tiny campaigns are written into ``tmp_path`` by the helpers below (also used by
``test_cli_campaign.py``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gisnoise import acoustics
from gisnoise.errors import CampaignError
from gisnoise.geo import LocalFrame
from gisnoise.measure import (
    Exclusion,
    campaign_log_warnings,
    check_campaign,
    emission_time,
    inspect_campaign,
    read_campaign,
    read_level_csv,
    write_level_csv,
)

ORIGIN = {"lat": 52.3, "lon": 10.4, "h": 80.0}
FRAME = LocalFrame(ORIGIN["lat"], ORIGIN["lon"], ORIGIN["h"])
C = 340.0            # speed of sound given in campaign.json, m/s
V = np.array([30.0, 0.0, 0.0])   # straight level flight east, m/s
X0 = np.array([-900.0, 0.0, 50.0])  # position at t = 0, m (ENU)
L40 = 70.0           # UAV level at 40 m, dB(A)
BG = 40.0            # background, dB(A)
START = "2023-05-04T10:00:00Z"


# ----------------------------------------------------------------------------- helpers
def straight_track(t0: float = -10.0, t1: float = 60.0, dt: float = 0.5) -> dict[str, np.ndarray]:
    """Flight-CSV columns of the straight constant-speed flyover (exact ENU line)."""
    t = np.arange(t0, t1 + dt / 2, dt)
    enu = X0 + t[:, None] * V
    lat, lon, h = FRAME.to_wgs84(enu[:, 0], enu[:, 1], enu[:, 2])
    n = len(t)
    return {"t": t, "lat": lat, "lon": lon, "h": h, "roll": np.zeros(n), "pitch": np.zeros(n),
            "yaw": np.full(n, 90.0), "power_w": np.full(n, 3000.0), "phase": np.full(n, "horizontal")}


def closed_form_te(t_r: np.ndarray, mic: np.ndarray, c: float = C) -> np.ndarray:
    """t_r - t_e = |x0 + v t_e - m| / c for x = x0 + v t: the positive root of a quadratic."""
    a = X0 - mic + np.outer(t_r, V)               # x(t_r) - m
    av = a @ V
    vv = V @ V
    tau = (-av + np.sqrt(av**2 + (c**2 - vv) * np.sum(a * a, axis=1))) / (c**2 - vv)
    return t_r - tau


def uav_level(d: np.ndarray, extra: np.ndarray | float = 0.0) -> np.ndarray:
    """Spherical spreading from L40 at 40 m, power-summed with the background."""
    return 10 * np.log10(10 ** ((L40 - 20 * np.log10(d / 40.0) + extra) / 10) + 10 ** (BG / 10))


def write_flight_csv(path: Path, cols: dict[str, np.ndarray]) -> None:
    names = list(cols)
    lines = [",".join(names)]
    for i in range(len(cols["t"])):
        lines.append(",".join(str(cols[k][i]) if k == "phase" else repr(float(cols[k][i])) for k in names))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def write_levels(path: Path, t: np.ndarray, la: np.ndarray, bands: dict[str, np.ndarray] | None = None) -> None:
    bands = bands or {}
    lines = [",".join(["t", "LA", *bands])]
    for i in range(len(t)):
        lines.append(",".join([repr(float(t[i])), repr(float(la[i]))] + [repr(float(b[i])) for b in bands.values()]))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def mic_entry(mid: str, enu: np.ndarray, **kw) -> dict:
    lat, lon, h = FRAME.to_wgs84(*enu)
    return {"id": mid, "lat": float(lat), "lon": float(lon), "h": float(h), "mount": "free_field", **kw}


MICS = {"m1": np.array([20.0, 35.0, 1.5]), "m2": np.array([-40.0, -60.0, 1.2]), "m3": np.array([150.0, 10.0, 1.5])}


def make_campaign(root: Path, *, mics: dict[str, np.ndarray] | None = None, t_r: np.ndarray | None = None,
                  level_fn=None, doc_changes: dict | None = None, track: dict | None = None) -> Path:
    """A flyover campaign: levels from spherical spreading at the solved emission geometry."""
    mics = MICS if mics is None else mics
    t_r = np.arange(3.0, 58.0, 0.125) if t_r is None else t_r
    doc = {"schema": "gisnoise/campaign/1", "origin": ORIGIN, "speed_of_sound_m_s": C,
           "weather": {"temperature_c": 15.0, "humidity_pct": 50.0, "pressure_kpa": 101.325},
           "vehicle": {"name": "test", "reference_power_w": 3000.0},
           "microphones": [mic_entry(k, v) for k, v in mics.items()],
           "flights": [{"id": "f1", "start_utc": START}]}
    doc.update(doc_changes or {})
    root.mkdir(parents=True, exist_ok=True)
    (root / "campaign.json").write_text(json.dumps(doc, indent=1))
    write_flight_csv(root / "flights" / "f1.csv", track or straight_track())
    for k, m in mics.items():
        t_e = closed_form_te(t_r, m)
        d = np.linalg.norm(X0 + np.outer(t_e, V) - m, axis=1)
        la = uav_level(d) if level_fn is None else level_fn(k, t_r, d)
        write_levels(root / "mics" / k / "f1.csv", t_r, la)
    return root


# ----------------------------------------------------------------------------- emission time
def test_emission_time_equals_closed_form_straight_flyover(tmp_path):
    camp = read_campaign(make_campaign(tmp_path / "c"))
    s = camp.samples()
    for k, m in MICS.items():
        sel = s.mic == k
        ref = closed_form_te(s.t_r[sel], m)
        assert np.max(np.abs(s.t_e[sel] - ref)) < 1e-6
    # the delay is d / c: up to 2.7 s at 900 m
    assert np.max(s.t_r - s.t_e) > 2.5


def test_emission_time_kernel_on_the_line_directly():
    t_nodes = np.arange(-10.0, 61.0, 2.0)
    enu = X0 + t_nodes[:, None] * V
    t_r = np.linspace(3.0, 55.0, 400)
    m = MICS["m3"]
    t_e = emission_time(t_r, t_nodes, enu, m, C)
    assert np.max(np.abs(t_e - closed_form_te(t_r, m))) < 1e-9
    # the defining equation holds
    x = X0 + np.outer(t_e, V)
    np.testing.assert_allclose(t_e + np.linalg.norm(x - m, axis=1) / C, t_r, rtol=0, atol=1e-9)


def test_emission_time_supersonic_track_is_refused():
    with pytest.raises(CampaignError, match="speed of sound"):
        emission_time([1.0], [0.0, 1.0], [[0, 0, 0], [400.0, 0, 0]], [0, 0, 0], 340.0)


# ----------------------------------------------------------------------------- samples
def test_samples_geometry_state_and_fields(tmp_path):
    camp = read_campaign(make_campaign(tmp_path / "c"))
    s = camp.samples()
    n = len(MICS) * len(np.arange(3.0, 58.0, 0.125))
    assert len(s) == n
    x_true = X0 + s.t_e[:, None] * V
    np.testing.assert_allclose(s.uav_enu, x_true, atol=1e-6)
    for k, m in MICS.items():
        np.testing.assert_allclose(s.mic_enu[s.mic == k], np.broadcast_to(m, ((s.mic == k).sum(), 3)), atol=1e-6)
    r = s.mic_enu - s.uav_enu
    np.testing.assert_allclose(s.d, np.linalg.norm(r, axis=1), rtol=1e-12)
    # heading east, level: body x = east, y = south (right wing), z = down
    phi = np.arctan2(-r[:, 1], r[:, 0])
    theta = np.arctan2(r[:, 2], np.hypot(r[:, 0], r[:, 1]))
    np.testing.assert_allclose(s.phi, phi, atol=1e-9)
    np.testing.assert_allclose(s.theta, theta, atol=1e-9)
    np.testing.assert_allclose(s.vel_enu, np.broadcast_to(V, (n, 3)), atol=1e-6)
    np.testing.assert_allclose(s.yaw, 90.0, atol=1e-9)
    np.testing.assert_allclose(s.power_w, 3000.0)
    assert set(s.phase) == {"horizontal"}
    assert s.meta["speed_of_sound_m_s"] == C and s.meta["reference_power_w"] == 3000.0
    assert s.bands is None and s.rpm is None
    inputs = s.inputs(camp.reference_power_w)
    np.testing.assert_allclose(inputs["p_el"], 1.0)


def test_speed_of_sound_from_temperature(tmp_path):
    root = make_campaign(tmp_path / "c", doc_changes={"speed_of_sound_m_s": None})
    camp = read_campaign(root)
    # c = 331.3 sqrt(1 + T / 273.15) at 15 degC
    assert abs(camp.speed_of_sound_m_s - 331.3 * np.sqrt(1 + 15.0 / 273.15)) < 0.05


def test_low_snr_masks_where_the_uav_is_below_background(tmp_path):
    # out to 2.9 km, where the UAV is 7 dB below the background
    root = make_campaign(tmp_path / "c", track=straight_track(-10.0, 130.0), t_r=np.arange(3.0, 128.0, 0.125))
    s = read_campaign(root).samples()
    l_uav = L40 - 20 * np.log10(s.d / 40.0)
    assert np.all(np.abs(s.background_db - BG) < 0.05)
    assert (l_uav < BG - 1.0).sum() > 300
    assert np.all(s.mask_reason[l_uav < BG - 1.0] == "low_snr")
    assert np.all(s.valid[l_uav > BG + 0.5])   # level > background + 3.3 dB
    assert set(s.mask_reason) == {"", "low_snr"}


def test_background_never_reached_is_not_guessed(tmp_path):
    """Within 900 m the UAV stays 5 dB or more above the 40 dB background: not determined, nothing masked."""
    s = read_campaign(make_campaign(tmp_path / "c")).samples()
    assert np.all(np.isnan(s.background_db))
    assert np.all(s.valid)
    assert {b["source"] for b in s.meta["background"]} == {"none"}


def hover_track(enu: np.ndarray, yaw_deg_per_s: float = 0.0, t0: float = -10.0, t1: float = 60.0,
                dt: float = 0.5) -> dict[str, np.ndarray]:
    """Flight-CSV columns of a hover at ``enu`` (m), turning at ``yaw_deg_per_s``."""
    t = np.arange(t0, t1 + dt / 2, dt)
    lat, lon, h = FRAME.to_wgs84(np.full(t.size, enu[0]), np.full(t.size, enu[1]), np.full(t.size, enu[2]))
    n = len(t)
    return {"t": t, "lat": lat, "lon": lon, "h": h, "roll": np.zeros(n), "pitch": np.zeros(n),
            "yaw": (yaw_deg_per_s * t) % 360.0, "power_w": np.full(n, 3000.0), "phase": np.full(n, "hover")}


@pytest.mark.parametrize("turning", [False, True])
def test_a_hover_at_a_steady_distance_does_not_take_the_uav_for_the_background(tmp_path, turning):
    """A hover 50 m up holds each microphone at one distance: a steady level there is the UAV's as well as a
    plateau's, and the quiet directions of a turning UAV are no background.  The levels stand 30-38 dB above the
    true 40 dB background, so no row is low_snr; without background_db and quiet blocks the background is not
    determined.  (Before, the plateau fit took 80 dB, or the turning UAV's quiet directions at 70.9 dB, for the
    background and masked most rows low_snr.)"""
    rng = np.random.default_rng(3)
    pos = np.array([0.0, 0.0, 50.0])

    def levels(mic, t_r, d):
        yaw = np.radians(6.0 * t_r) if turning else 0.0
        return 75.0 + (3.0 * np.cos(yaw) if turning else 0.0) + rng.normal(0.0, 0.5, t_r.size)

    root = make_campaign(tmp_path / "c", track=hover_track(pos, 6.0 if turning else 0.0), level_fn=levels)
    s = read_campaign(root).samples()
    assert np.all(np.isnan(s.background_db))
    assert {b["source"] for b in s.meta["background"]} == {"none"}
    assert np.all(s.valid)


def test_background_from_blocks_before_the_flight(tmp_path):
    """Blocks whose emission precedes the log (UAV not yet flying) hold the background only."""
    rng = np.random.default_rng(5)

    def levels(mic, t_r, d):
        before = closed_form_te(t_r, MICS[mic]) < -10.0       # the log starts at -10 s
        return np.where(before, BG, uav_level(d)) + rng.normal(0.0, 0.5, len(t_r))

    root = make_campaign(tmp_path / "c", t_r=np.arange(-12.0, 58.0, 0.125), level_fn=levels)
    s = read_campaign(root).samples()
    assert np.all(np.abs(s.background_db - BG) < 0.2)       # median of ~12 blocks of N(40, 0.5)
    assert {b["source"] for b in s.meta["background"]} == {"outside_flight"}
    assert set(s.mask_reason[s.t_e < -10.0]) == {"outside_flight"}
    l_uav = L40 - 20 * np.log10(s.d / 40.0)
    assert np.all(s.mask_reason[(s.t_e > -10.0) & (l_uav > BG + 5.0)] == "")  # 6 noise std clear


def test_background_from_campaign_json(tmp_path):
    root = make_campaign(tmp_path / "c")
    doc = json.loads((root / "campaign.json").read_text())
    doc["microphones"][0]["background_db"] = 47.0
    (root / "campaign.json").write_text(json.dumps(doc))
    s = read_campaign(root).samples()
    m1 = s.mic == "m1"
    np.testing.assert_allclose(s.background_db[m1], 47.0)
    # rows of m1 within 3 dB of a 47 dB background are low_snr; there the UAV is below 49.3 dB
    np.testing.assert_array_equal(s.mask_reason[m1] == "low_snr", s.level[m1] < 50.0)


def test_a_microphone_whose_airborne_blocks_are_all_masked_is_named(tmp_path):
    """m1 states a background of 80 dB(A); the UAV reaches at most 66.5 dB(A) there (70 dB at 40 m, nearest
    59.8 m): every block is below background + 3 dB and masked low_snr, lost to the fit.  The campaign's warnings
    name m1 (only), the masks and the stated background; before, check said "no problems found"."""
    root = make_campaign(tmp_path / "c")
    doc = json.loads((root / "campaign.json").read_text())
    doc["microphones"][0]["background_db"] = 80.0
    (root / "campaign.json").write_text(json.dumps(doc))
    camp = read_campaign(root)
    lines = [w for w in campaign_log_warnings(camp) if "airborne blocks are masked" in w]
    n = int(np.sum(camp.samples().mic == "m1"))
    assert len(lines) == 1 and lines[0].startswith(f"microphone 'm1', flight 'f1': {n} of its {n} airborne blocks")
    assert f"low_snr {n}" in lines[0] and "the background 80.0 dB(A) (campaign.json)" in lines[0]
    assert not [w for w in campaign_log_warnings(read_campaign(make_campaign(tmp_path / "clean")))
                if "masked" in w]


def test_a_hole_in_the_flight_csv_is_named_not_bridged_silently(tmp_path):
    """Rows 5.0-14.5 s cut from the flight CSV (a 10 s hole, the track's step 0.5 s): the campaign is read (the
    state is interpolated straight across) and its warnings name the hole, 4.5 -> 15.0 s."""
    track = straight_track()
    keep = (track["t"] < 4.9) | (track["t"] > 14.9)
    root = make_campaign(tmp_path / "c", track={k: v[keep] for k, v in track.items()})
    (line,) = [w for w in campaign_log_warnings(read_campaign(root)) if "hole" in w]
    assert "f1.csv: the track has a hole without samples (10.5 s from t = 4.5 s)" in line
    assert not [w for w in campaign_log_warnings(read_campaign(make_campaign(tmp_path / "whole"))) if "hole" in w]


def test_joint_rise_on_all_mics_is_an_event_one_mic_is_not(tmp_path):
    def levels(mic, t_r, d):
        la = uav_level(d)
        joint = (t_r >= 20.0) & (t_r < 22.0)                    # a passing aircraft: all mics, +15 dB
        la = np.where(joint, 10 * np.log10(10 ** (la / 10) + 10 ** ((la + 15) / 10)), la)
        if mic == "m2":                                          # a car near m2 only
            one = (t_r >= 40.0) & (t_r < 42.0)
            la = np.where(one, la + 15.0, la)
        turn = (t_r >= 45.0) & (t_r < 52.0)                      # louder UAV (a turn): +4 dB everywhere
        return np.where(turn, la + 4.0, la)

    s = read_campaign(make_campaign(tmp_path / "c", level_fn=levels)).samples()
    inside = (s.t_r >= 20.3) & (s.t_r <= 21.7)
    assert np.all(s.mask_reason[inside] == "event")
    far = (s.t_r < 19.5) | (s.t_r > 22.5)
    assert not np.any(s.mask_reason[far] == "event")
    assert np.all(s.mask_reason[(s.mic == "m2") & (s.t_r > 40.3) & (s.t_r < 41.7)] != "event")
    assert not np.any(s.mask_reason[(s.t_r > 44.0) & (s.t_r < 53.0)] == "event")   # below event_db = 6 dB


def test_exclusions_from_file_and_argument(tmp_path):
    root = make_campaign(tmp_path / "c", doc_changes={
        "exclusions": [{"flight": "f1", "t0": 10.0, "t1": 11.0, "mic": "m1", "reason": "dog"}]})
    camp = read_campaign(root, exclusions=[("f1", 30.0, 31.0), Exclusion("f1", 35.0, 35.5, "m3")])
    s = camp.samples()
    r = s.mask_reason
    assert np.all(r[(s.mic == "m1") & (s.t_r >= 10.0) & (s.t_r <= 11.0)] == "excluded")
    assert not np.any(r[(s.mic == "m2") & (s.t_r >= 10.0) & (s.t_r <= 11.0)] == "excluded")
    assert np.all(r[(s.t_r >= 30.0) & (s.t_r <= 31.0)] == "excluded")
    assert np.all(r[(s.mic == "m3") & (s.t_r >= 35.0) & (s.t_r <= 35.5)] == "excluded")
    assert (r == "excluded").sum() == 9 + 3 * 9 + 5
    assert np.array_equal(s.valid, r == "")


def test_exclusion_of_unknown_flight_or_mic(tmp_path):
    root = make_campaign(tmp_path / "c")
    with pytest.raises(CampaignError, match="exclusion 0 names unknown flight 'f9'"):
        read_campaign(root, exclusions=[("f9", 1.0, 2.0)])
    with pytest.raises(CampaignError, match="exclusion 0 names unknown microphone 'm9'"):
        read_campaign(root, exclusions=[("f1", 1.0, 2.0, "m9")])
    with pytest.raises(CampaignError, match=r"needs flight \(name\) and t0 <= t1"):
        read_campaign(root, exclusions=[("f1", 2.0, 1.0)])


def test_samples_outside_the_flight_log(tmp_path):
    # log covers -10..60 s; reception times up to 64 s: emission after the log's end is masked
    root = make_campaign(tmp_path / "c", t_r=np.arange(3.0, 64.0, 0.125))
    s = read_campaign(root).samples()
    t_end = 60.0
    assert np.all(s.mask_reason[s.t_e > t_end] == "outside_flight")
    assert np.all(s.mask_reason[s.t_e <= t_end] != "outside_flight")
    assert (s.t_e > t_end).sum() > 10


def test_absorption_corrects_signal_bands_only(tmp_path):
    """One strong 4 kHz band plus background bands: only the 4 kHz energy is scaled by 10^(alpha d / 10)."""
    f_sig, f_bg = 10 ** 3.6, 10 ** 2.0   # exact mid-band of the 4 kHz and 100 Hz bands

    def bands_for(d):
        l4k = 80.0 - 20 * np.log10(d / 40.0)
        l4k = np.where(d > 400.0, 30.0, l4k)     # far: the band drops to its background
        l100 = np.full_like(d, 45.0)
        return l4k, l100

    store = {}

    def levels(mic, t_r, d):
        l4k, l100 = bands_for(d)
        la = 10 * np.log10(10 ** ((l4k + acoustics.a_weighting(f_sig)) / 10)
                           + 10 ** ((l100 + acoustics.a_weighting(f_bg)) / 10))
        store[mic] = (t_r, la, l4k, l100)
        return la

    root = make_campaign(tmp_path / "c", level_fn=levels)
    for mic, (t_r, la, l4k, l100) in store.items():
        write_levels(root / "mics" / mic / "f1.csv", t_r, la, {"L_100": l100, "L_4000": l4k})
    plain = read_campaign(root).samples()
    corr = read_campaign(root, absorption=True).samples()
    alpha = float(acoustics.atmospheric_absorption(f_sig, 15.0, 50.0, 101.325))
    assert 0.01 < alpha < 0.05   # dB/m at 4 kHz, 15 degC, 50 % (ISO 9613-1 order of magnitude)
    l4k, l100 = bands_for(plain.d)
    e4k = 10 ** ((l4k + acoustics.a_weighting(f_sig)) / 10)
    e100 = 10 ** ((l100 + acoustics.a_weighting(f_bg)) / 10)
    signal = plain.d <= 400.0
    expected = np.where(signal, 10 * np.log10(e4k * 10 ** (alpha * plain.d / 10) + e100), plain.level)
    np.testing.assert_allclose(corr.level, expected, atol=1e-6)
    np.testing.assert_allclose(plain.level, 10 * np.log10(e4k + e100), atol=1e-9)
    # bands are kept as measured, at the exact mid-band frequencies
    np.testing.assert_allclose(corr.band_f, [f_bg, f_sig])
    np.testing.assert_allclose(corr.bands[:, 1], l4k, atol=1e-9)
    assert corr.meta["absorption_corrected"] is True


def test_absorption_band_background_from_blocks_before_the_flight(tmp_path):
    """Before the log starts the 4 kHz band reads its 30 dB background; in flight it never drops below
    48 dB, so every in-flight row is >= 10 dB clear and is corrected."""
    f_sig, f_bg = 10 ** 3.6, 10 ** 2.0
    store = {}

    def levels(mic, t_r, d):
        before = closed_form_te(t_r, MICS[mic]) < -10.0
        l4k = np.where(before, 30.0, np.maximum(80.0 - 20 * np.log10(d / 40.0), 48.0))
        l100 = np.full_like(d, 45.0)
        la = 10 * np.log10(10 ** ((l4k + acoustics.a_weighting(f_sig)) / 10)
                           + 10 ** ((l100 + acoustics.a_weighting(f_bg)) / 10))
        store[mic] = (t_r, la, l4k, l100)
        return la

    root = make_campaign(tmp_path / "c", t_r=np.arange(-12.0, 58.0, 0.125), level_fn=levels)
    for mic, (t_r, la, l4k, l100) in store.items():
        write_levels(root / "mics" / mic / "f1.csv", t_r, la, {"L_100": l100, "L_4000": l4k})
    plain = read_campaign(root).samples()
    corr = read_campaign(root, absorption=True).samples()
    alpha = float(acoustics.atmospheric_absorption(f_sig, 15.0, 50.0, 101.325))
    flying = plain.mask_reason != "outside_flight"
    e4k = 10 ** ((plain.bands[:, 1] + acoustics.a_weighting(f_sig)) / 10)
    expected = 10 * np.log10(10 ** (plain.level / 10) + e4k * (10 ** (alpha * plain.d / 10) - 1))
    np.testing.assert_allclose(corr.level[flying], expected[flying], atol=1e-6)
    np.testing.assert_allclose(corr.level[~flying], plain.level[~flying], atol=1e-9)   # background: as is


def test_absorption_needs_humidity(tmp_path):
    root = make_campaign(tmp_path / "c", doc_changes={"weather": {"temperature_c": 15.0}})
    with pytest.raises(CampaignError, match=r"campaign\.json: field 'weather\.humidity_pct'"):
        read_campaign(root, absorption=True)


def test_absorption_without_band_levels_is_refused_not_skipped(tmp_path):
    """Absorption is a per-band correction (SPEC 2): a level file without band columns cannot be corrected. Asked
    for, it is refused naming the file and the field, never read uncorrected beside corrected ones."""
    from gisnoise.measure import check_campaign

    root = make_campaign(tmp_path / "c")   # t and LA only
    with pytest.raises(CampaignError, match=r"mics/m1/f1\.csv: .*absorption.*band") as e:
        read_campaign(root, absorption=True)
    assert e.value.field == "bands" and "\n" not in str(e.value)
    problems = check_campaign(root, absorption=True)
    assert sorted(str(p.file).split("/mics/")[1] for p in problems if p.field == "bands") == [
        "m1/f1.csv", "m2/f1.csv", "m3/f1.csv"]
    read_campaign(root)   # without the correction the same files read


# ----------------------------------------------------------------------------- flight logs
DATA = Path(__file__).parent / "data"


def vtol_campaign(root: Path, t_r: np.ndarray) -> Path:
    """A campaign of the real PX4 VTOL log (flights/f1.ulg) with one microphone 10 m east of its site hearing a
    steady 60 dB(A) at the reception times ``t_r``."""
    import shutil

    (root / "flights").mkdir(parents=True)
    shutil.copy(DATA / "pyulog_sample_log_small_vtol.ulg", root / "flights" / "f1.ulg")
    frame = LocalFrame(63.4170, 10.4082, 100.0)   # the log's site
    lat, lon, h = frame.to_wgs84(10.0, 0.0, 1.5)
    doc = {"schema": "gisnoise/campaign/1", "origin": {"lat": 63.4170, "lon": 10.4082, "h": 100.0},
           "speed_of_sound_m_s": 340.0, "weather": {"temperature_c": 10.0},
           "vehicle": {"name": "vtol", "reference_power_w": 500.0},
           "microphones": [{"id": "m1", "lat": float(lat), "lon": float(lon), "h": float(h), "mount": "free_field"}],
           "flights": [{"id": "f1", "start_utc": "2021-04-21T06:30:58Z"}]}
    (root / "campaign.json").write_text(json.dumps(doc))
    write_levels(root / "mics" / "m1" / "f1.csv", t_r, np.full(len(t_r), 60.0))
    return root


def test_campaign_with_a_px4_log_aligned_by_gps_time(tmp_path):
    """flights/f1.ulg is read with the flight's start_utc: t = GPS UTC - start_utc."""
    camp = read_campaign(vtol_campaign(tmp_path / "c", np.arange(0.0, 7.0, 0.125)))
    tr = camp.trajectories["f1"]
    # first GPS fix inside the attitude/battery span: 06:30:58.80 UTC (time_utc_usec of the log)
    assert abs(tr.t[0] - 0.800) < 0.03 and abs(tr.t[-1] - 6.600) < 0.03
    s = camp.samples()
    assert np.all((s.t_r - s.t_e) > 0) and np.all((s.t_r - s.t_e) < 0.2)   # 10-60 m at 340 m/s
    np.testing.assert_allclose(s.t_r - s.t_e, s.d / 340.0, atol=1e-9)
    # outside the log; within it while the log's landed flag says the vehicle stands on the ground
    out = (s.t_e < tr.t[0]) | (s.t_e > tr.t[-1])
    ground = ~out & ~tr.flying_at(s.t_e)
    assert out.sum() >= 8 and set(s.mask_reason[out]) == {"outside_flight"}
    assert ground.sum() >= 8 and set(s.mask_reason[ground]) == {"on_ground"}
    assert not np.any(np.isin(s.mask_reason[~out & ~ground], ("outside_flight", "on_ground")))
    assert s.power_w.min() > 0.0 and s.power_w.max() > 100.0   # the hop, then idle after landing


def test_a_recording_that_ends_before_take_off_is_not_blamed_on_the_clock(tmp_path):
    """The real VTOL log: its GPS time is right, the log spans 0.8-6.6 s of the campaign's clock and the vehicle
    flies at about 3.0-3.8 s.  A recording of 2.5 s falls within the log but finds the vehicle on the ground: the
    check says so and names the airborne stretch, not "check start_utc"."""
    camp, problems = inspect_campaign(vtol_campaign(tmp_path / "c", np.arange(0.0625, 2.5, 0.125)))
    tr = camp.trajectories["f1"]
    fly = tr.t[tr.flying]
    assert fly.min() > 2.5  # the vehicle takes off after the recording ends
    (msg,) = [p.message for p in problems if "airborne" in p.message]
    assert "start_utc" in msg and "find the vehicle on the ground" in msg
    assert f"flies at {fly.min():.1f}-" in msg and "check start_utc" not in msg.split(";")[0]


def test_campaign_with_an_ardupilot_log_needs_the_geoid_undulation(tmp_path, no_geoid_grid):
    import shutil

    root = tmp_path / "c"
    (root / "flights").mkdir(parents=True)
    shutil.copy(DATA / "dronekit_la_testdata_log171_copter.bin", root / "flights" / "f1.bin")
    doc = {"schema": "gisnoise/campaign/1", "origin": {"lat": -35.3623, "lon": 149.1659, "h": 600.0},
           "speed_of_sound_m_s": 340.0, "weather": {},
           "vehicle": {"name": "quad", "reference_power_w": 300.0},
           "microphones": [{"id": "m1", "lat": -35.3623, "lon": 149.1659, "h": 600.0}],
           "flights": [{"id": "f1", "start_utc": "2015-11-21T23:44:00Z"}]}
    (root / "campaign.json").write_text(json.dumps(doc))
    t_r = np.arange(30.0, 200.0, 0.125)
    write_levels(root / "mics" / "m1" / "f1.csv", t_r, np.full(len(t_r), 60.0))
    with pytest.raises(CampaignError, match=r"f1\.bin: message 'GPS' gives heights above mean sea level only") as e:
        read_campaign(root)
    assert e.value.field == "geoid_undulation_m"
    doc["flights"][0]["geoid_undulation_m"] = 20.0
    (root / "campaign.json").write_text(json.dumps(doc))
    camp = read_campaign(root)
    tr = camp.trajectories["f1"]
    # first 3D fix at 23:44:25.4 UTC (GPS week/ms of the log minus 17 leap seconds); boot and GPS clocks are
    # tied by the median over all fixes, so a single fix may sit a few tens of milliseconds off
    assert abs(tr.t[0] - 25.4) < 0.1
    assert len(camp.samples()) == len(t_r)


# ----------------------------------------------------------------------------- WAV input
def write_wav(path: Path, x: np.ndarray, fs: int) -> None:
    from scipy.io import wavfile

    path.parent.mkdir(parents=True, exist_ok=True)
    wavfile.write(str(path), fs, x)


def sine_volts(fs: int, seconds: float, p_rms: float = 1.0, sens: float = 0.05, f: float = 1000.0) -> np.ndarray:
    t = np.arange(int(fs * seconds)) / fs
    return np.sqrt(2) * p_rms * sens * np.sin(2 * np.pi * f * t)


def make_wav_campaign(root: Path, *, fs: dict[str, int] | None = None, mount: str = "ground_plate",
                      int16: bool = True, seconds: float = 3.0) -> Path:
    fs = fs or {"m1": 48000, "m2": 48000}
    mics = {k: MICS[k] for k in fs}
    make_campaign(root, mics=mics)
    doc = json.loads((root / "campaign.json").read_text())
    for m in doc["microphones"]:
        m["mount"] = mount
        m["sensitivity_v_per_pa"] = 0.05
    (root / "campaign.json").write_text(json.dumps(doc))
    for k, rate in fs.items():
        (root / "mics" / k / "f1.csv").unlink()
        v = sine_volts(rate, seconds)
        write_wav(root / "mics" / k / "f1.wav", np.round(v * 32767).astype(np.int16) if int16 else
                  v.astype(np.float32), rate)
    return root


@pytest.mark.parametrize("int16", [True, False])
def test_wav_sine_94_db_on_a_ground_plate_reads_88_dba(tmp_path, int16):
    """1 Pa RMS at 1 kHz is 94.0 dB; A(1 kHz) = 0; the ground plate's +6 dB is taken off."""
    camp = read_campaign(make_wav_campaign(tmp_path / "c", int16=int16))
    lv = camp.levels[0]
    steady = (lv.t > 0.5) & (lv.t < 2.5)
    np.testing.assert_allclose(lv.la[steady], 88.0, atol=0.1)
    k1 = int(np.argmin(np.abs(lv.band_f - 1000.0)))
    np.testing.assert_allclose(lv.bands[steady, k1], 88.0, atol=0.1)
    assert abs(np.median(np.diff(lv.t)) - 0.125) < 1e-9


# ----------------------------------------------------------------------------- problems
def test_missing_microphone_file(tmp_path):
    root = make_campaign(tmp_path / "c")
    (root / "mics" / "m2" / "f1.csv").unlink()
    with pytest.raises(CampaignError, match=r"mics/m2/f1\.wav: missing microphone file") as e:
        read_campaign(root)
    assert e.value.field == "mics"


def test_unknown_mount(tmp_path):
    root = make_campaign(tmp_path / "c")
    doc = json.loads((root / "campaign.json").read_text())
    doc["microphones"][1]["mount"] = "on_a_stick"
    (root / "campaign.json").write_text(json.dumps(doc))
    with pytest.raises(CampaignError, match=r"campaign\.json: field 'microphones\[1\]\.mount': unknown mount "
                                            r"'on_a_stick'") as e:
        read_campaign(root)
    assert e.value.field == "microphones[1].mount"
    assert "ground_plate" in str(e.value)


@pytest.mark.parametrize("h", [-2.99e56, 1e7])
def test_an_origin_height_beyond_the_height_limits_is_refused(tmp_path, h):
    """The origin's height follows the microphones' rule (limits.min_height_m..max_height_m): 3e56 m below the
    ellipsoid put every position of the local frame near 1e56 m, where the microphone-drone distances of whole
    flights round to 0 m (found by the campaign fuzzer)."""
    root = make_campaign(tmp_path / "c")
    doc = json.loads((root / "campaign.json").read_text())
    doc["origin"]["h"] = h
    (root / "campaign.json").write_text(json.dumps(doc, allow_nan=True))
    with pytest.raises(CampaignError, match=r"campaign\.json: origin\.h: .* m is outside \[-500, ") as e:
        read_campaign(root)
    assert e.value.field == "origin.h"


def test_wav_of_the_wrong_sample_rate(tmp_path):
    root = make_wav_campaign(tmp_path / "c", fs={"m1": 48000, "m2": 48000, "m3": 44100}, seconds=0.5)
    with pytest.raises(CampaignError, match=r"mics/m3/f1\.wav: sample_rate_hz is 44100 Hz, the campaign's other "
                                            r"WAV files have 48000 Hz") as e:
        read_campaign(root)
    assert e.value.field == "sample_rate_hz"
    doc = json.loads((root / "campaign.json").read_text())
    doc["sample_rate_hz"] = 44100
    (root / "campaign.json").write_text(json.dumps(doc))
    with pytest.raises(CampaignError, match=r"mics/m1/f1\.wav: sample_rate_hz is 48000 Hz, campaign\.json states "
                                            r"44100 Hz"):
        read_campaign(root)


def test_flight_csv_without_power(tmp_path):
    track = straight_track()
    del track["power_w"]
    root = make_campaign(tmp_path / "c", track=track)
    with pytest.raises(CampaignError, match=r"flights/f1\.csv: missing column\(s\) power_w") as e:
        read_campaign(root)
    assert e.value.field == "power_w"


def test_level_csv_problems(tmp_path):
    p = tmp_path / "l.csv"
    write_levels(p, np.array([0.0, 0.25, 0.125]), np.array([50.0, 51.0, 52.0]))
    with pytest.raises(CampaignError, match=r"l\.csv: column 't' is not strictly increasing at line 4"):
        read_level_csv(p)
    p.write_text("t,LA\n0.0,50\n0.125,nan\n")
    with pytest.raises(CampaignError, match=r"l\.csv: column 'LA' line 3: NaN"):
        read_level_csv(p)
    p.write_text("t,L_1000\n0.0,50\n")
    with pytest.raises(CampaignError, match=r"l\.csv: missing column 'LA'"):
        read_level_csv(p)
    p.write_text("t,LA,L_1000\n0.0,inf,40\n")
    with pytest.raises(CampaignError, match=r"l\.csv: column 'LA' line 2: NaN or infinite"):
        read_level_csv(p)
    p.write_text("t,LA,L_1000,L_25\n0.0,50,40,-inf\n")   # digital silence in a band is a level
    assert read_level_csv(p).bands[0, 0] == -np.inf
    p.write_text("t,LA,L_1100\n0.0,50,40\n")
    with pytest.raises(CampaignError, match=r"column 'L_1100' is not a one-third-octave band"):
        read_level_csv(p)


def test_level_csv_separated_by_semicolons_or_tabs_is_named_as_such(tmp_path):
    """A spreadsheet's export with ';' or tabs between fields is named as such, not reported as a missing column."""
    p = tmp_path / "l.csv"
    for sep, name in ((";", "';'"), ("\t", "tab")):
        p.write_text(f"t{sep}LA\n0{sep}50,5\n0,125{sep}51\n")
        with pytest.raises(CampaignError, match=f"separated by {name}") as err:
            read_level_csv(p)
        assert err.value.field == "csv"


def test_level_csv_round_trip_with_bands(tmp_path):
    f = np.array([10 ** 1.5, 10 ** 2.2, 10 ** 3.0, 10 ** 4.3])  # 31.5, 160, 1000, 20000 Hz bands
    text = write_level_csv(tmp_path / "x.csv", [0.0625, 0.1875], [61.234, 62.0], f, [[1, 2, 3, 4], [5, 6, 7, 8]])
    assert text.splitlines()[0] == "t,LA,L_31.5,L_160,L_1000,L_20000"
    lv = read_level_csv(tmp_path / "x.csv")
    np.testing.assert_allclose(lv.band_f, f, rtol=1e-12)
    np.testing.assert_allclose(lv.bands, [[1, 2, 3, 4], [5, 6, 7, 8]])
    np.testing.assert_allclose(lv.la, [61.234, 62.0])


def test_check_campaign_collects_every_problem(tmp_path):
    root = make_wav_campaign(tmp_path / "c", fs={"m1": 48000, "m2": 48000, "m3": 44100}, seconds=0.5)
    doc = json.loads((root / "campaign.json").read_text())
    doc["microphones"][0]["mount"] = "on_a_stick"
    doc["microphones"].append(mic_entry("m4", np.array([0.0, 100.0, 1.5])))
    (root / "campaign.json").write_text(json.dumps(doc))
    track = straight_track()
    del track["power_w"]
    write_flight_csv(root / "flights" / "f1.csv", track)
    problems = check_campaign(root)
    fields = sorted(p.field for p in problems)
    assert fields == ["microphones[0].mount", "mics", "power_w", "sample_rate_hz"]
    # m1 is left out for its mount; m2 (48 kHz) against m3 (44.1 kHz) is still decided by all WAVs
    rate = next(p for p in problems if p.field == "sample_rate_hz")
    assert rate.file.endswith("mics/m3/f1.wav")
    for p in problems:
        assert "\n" not in p.message and p.file in p.message


def test_check_campaign_clean(tmp_path):
    assert check_campaign(make_campaign(tmp_path / "c")) == []


def test_spreading_puts_every_microphone_at_one_source_level(tmp_path):
    """Levels by spherical spreading: L + 20 lg d over each microphone's loudest 20 s is the same source level
    (the background, 30 dB below the peaks, moves the median of the window by less than 0.01 dB)."""
    from gisnoise.measure import read_campaign, spreading_outliers

    s = read_campaign(make_campaign(tmp_path / "c")).samples()
    assert spreading_outliers(s, limit_db=0.01) == []


def test_a_microphone_listed_km_off_is_named(tmp_path):
    """m3's levels were made at its true position; campaign.json lists it 0.05 deg (5.6 km) north. Over its loudest
    20 s, its levels from the listed position imply a source louder than the others hear by the median of
    20 lg(d_listed / d_true)."""
    from gisnoise.measure import WINDOW_S, inspect_campaign, read_campaign

    true = read_campaign(make_campaign(tmp_path / "true")).samples()
    root = make_campaign(tmp_path / "c")
    doc = json.loads((root / "campaign.json").read_text())
    doc["microphones"][2]["lat"] += 0.05
    (root / "campaign.json").write_text(json.dumps(doc))
    camp, problems = inspect_campaign(root)
    named = [p for p in problems if p.field == "microphones"]
    assert len(named) == 1 and "microphone 'm3'" in named[0].message and named[0].file in named[0].message
    s = camp.samples()
    rows = np.flatnonzero((s.mic == "m3") & s.valid)  # 16 s fewer: the listed position is 16 s of sound farther
    loud = rows[np.argsort(-s.level[rows])[:int(round(WINDOW_S / 0.125))]]
    at = {t: i for i, t in zip(np.flatnonzero(true.mic == "m3"), true.t_r[true.mic == "m3"], strict=True)}
    d_true = true.d[[at[t] for t in s.t_r[loud]]]  # the same blocks at the true position
    off = float(named[0].message.split("puts the source ")[1].split(" dB")[0])
    # the others' source level is L40 + 20 lg 40 (spreading); m3's levels are L40 + 20 lg(40 / d_true)
    assert off > 20.0
    assert off == pytest.approx(np.median(20 * np.log10(s.d[loud] / d_true)), abs=0.5)


def test_the_sample_campaign_names_no_microphone():
    """The shipped sample campaign (three honest microphones): nothing contradicts a listed position."""
    from gisnoise.measure import read_campaign, spreading_outliers

    s = read_campaign(Path(__file__).resolve().parents[1] / "sample_data" / "campaign").samples()
    assert spreading_outliers(s) == []


def test_unknown_schema_and_missing_files(tmp_path):
    root = make_campaign(tmp_path / "c", doc_changes={"schema": "gisnoise/campaign/9"})
    with pytest.raises(CampaignError, match="unknown version 'gisnoise/campaign/9'"):
        read_campaign(root)
    with pytest.raises(CampaignError, match="no such campaign folder"):
        read_campaign(tmp_path / "nowhere")
    root = make_campaign(tmp_path / "d")
    (root / "flights" / "f1.csv").unlink()
    with pytest.raises(CampaignError, match=r"flights/f1\.csv: missing flight log for flight 'f1'"):
        read_campaign(root)


def test_microphone_height_above_ground_reaches_the_samples(tmp_path):
    """campaign.json's height_agl_m is passed to Samples.meta, where the ground-reflection effect reads it."""
    import json

    from gisnoise.measure import read_campaign
    from gisnoise.model import mic_height_agl
    from gisnoise.simulate import simulate

    root = __import__("pathlib").Path(__file__).resolve().parents[1]
    scen = json.loads((root / "sample_data/scenarios/diagnosis_base.json").read_text())
    out = simulate(scen, tmp_path / "c", base_dir=root / "sample_data/scenarios")
    doc = json.loads((out / "campaign.json").read_text())
    stated = {m["id"]: m["height_agl_m"] for m in doc["microphones"] if "height_agl_m" in m}
    assert stated, "the scenario states microphone heights"
    s = read_campaign(out).samples()
    h = mic_height_agl({**s.inputs(3000.0), "mic": s.mic})
    for mid, hm in stated.items():
        assert np.all(h[s.mic == mid] == hm)


def test_a_byte_order_mark_in_campaign_json_is_accepted(tmp_path):
    """campaign.json saved by an editor with a UTF-8 byte-order mark reads as without one, as every JSON input does
    (the microphones' height_agl_m included, which the diagnosis takes from campaign.json)."""
    from gisnoise.diagnose.samples import with_mic_heights

    plain = make_campaign(tmp_path / "plain")
    doc = json.loads((plain / "campaign.json").read_text())
    doc["microphones"][0]["height_agl_m"] = 1.5
    (plain / "campaign.json").write_text(json.dumps(doc))
    bom = make_campaign(tmp_path / "bom")
    (bom / "campaign.json").write_bytes(b"\xef\xbb\xbf" + (plain / "campaign.json").read_bytes())
    assert check_campaign(bom) == []
    a, b = read_campaign(plain).samples(), read_campaign(bom).samples()
    np.testing.assert_array_equal(a.t_e, b.t_e)
    np.testing.assert_array_equal(a.level, b.level)
    hb = with_mic_heights(b, bom).meta["microphones"]
    assert hb["m1"]["height_agl_m"] == 1.5


# ----------------------------------------------------------------------------- heights, clocks, places, backgrounds
def _take_off_track(dh: float = 0.0) -> dict[str, np.ndarray]:
    """The straight flyover preceded by a vertical take-off from the origin's ground (h 80 m): on the ground
    (no power) at t = -20 s, climbing to 50 m by -10 s; every height shifted by ``dh``."""
    tr = straight_track()
    t_up = np.arange(-20.0, -10.0, 0.5)
    enu = np.stack([np.full(t_up.size, X0[0] - 10 * V[0]), np.zeros(t_up.size), 5.0 * (t_up + 20.0)], axis=-1)
    lat, lon, _ = FRAME.to_wgs84(enu[:, 0], enu[:, 1], enu[:, 2])
    up = {"t": t_up, "lat": lat, "lon": lon, "h": ORIGIN["h"] + enu[:, 2],   # from the ground at 80 m
          "roll": np.zeros(t_up.size), "pitch": np.zeros(t_up.size),
          "yaw": np.full(t_up.size, 90.0), "power_w": np.where(t_up == -20.0, 0.0, 3000.0),
          "phase": np.full(t_up.size, "climb")}
    out = {k: np.concatenate([up[k], tr[k]]) for k in tr}
    out["h"] = out["h"] + dh
    return out




def test_heights_125_m_low_put_the_vehicle_below_the_ground_and_are_refused(tmp_path):
    """A log 125 m below ellipsoidal heights (its take-off at -45 m, the microphones' ground at 80 m): the
    vehicle is underground for its whole airborne time; check names flight, field h and the 125 m, read refuses."""
    mics = {k: v for k, v in MICS.items()}
    doc = {"microphones": [mic_entry(k, v, height_agl_m=float(v[2])) for k, v in mics.items()]}
    good = make_campaign(tmp_path / "good", track=_take_off_track(), doc_changes=doc)
    assert check_campaign(good) == []
    bad = make_campaign(tmp_path / "bad", track=_take_off_track(-125.0), doc_changes=doc)
    problems = check_campaign(bad)
    assert [p.field for p in problems] == ["h"]
    msg = problems[0].message
    assert "flight 'f1'" in msg and "field 'h'" in msg and "for 100 % of its airborne time" in msg
    assert "take-off or landing at -45.0 m lies 125.0 m below that ground" in msg
    assert "ellipsoidal" in msg and "geoid_undulation_m" in msg
    with pytest.raises(CampaignError, match="125.0 m below") as e:
        read_campaign(bad)
    assert e.value.field == "h"


def test_heights_within_gps_noise_of_the_ground_are_not_a_problem(tmp_path):
    """A vehicle 0.9 m (within GROUND_TOLERANCE_M) below the microphones' stated ground is GPS noise, not a datum."""
    from gisnoise.limits import GROUND_TOLERANCE_M

    track = straight_track()
    track["h"] = np.full(track["t"].size, 80.0 - 0.9 * GROUND_TOLERANCE_M)
    doc = {"microphones": [mic_entry(k, v, height_agl_m=float(v[2])) for k, v in MICS.items()]}
    root = make_campaign(tmp_path / "c", track=track, doc_changes=doc)
    assert not [p for p in check_campaign(root) if p.field == "h"]


def test_levels_10_db_low_against_the_stated_background_are_named(tmp_path):
    """m1's levels 10 dB low (a calibration error): its quietest blocks, the 16 before the log (pure 40 dB
    background), read 30 dB(A), 10.0 dB under its stated background_db; the others are silent."""
    from gisnoise.measure import campaign_log_warnings

    def levels(mic, t_r, d):
        before = closed_form_te(t_r, MICS[mic]) < -10.0
        la = np.where(before, BG, uav_level(d))
        return la - 10.0 if mic == "m1" else la

    doc = {"microphones": [mic_entry(k, v, background_db=BG) for k, v in MICS.items()]}
    root = make_campaign(tmp_path / "c", t_r=np.arange(-12.0, 58.0, 0.125), level_fn=levels, doc_changes=doc)
    camp = read_campaign(root)
    warnings = campaign_log_warnings(camp)
    assert len(warnings) == 1, warnings
    assert warnings[0].startswith("microphone 'm1': the quietest 2 % of its 560 levels lie below 30.0 dB(A), "
                                  "10.0 dB under the background_db 40 dB(A)")
    assert "calibration" in warnings[0]
    assert check_campaign(root) == []     # a warning, not a problem
    root_ok = make_campaign(tmp_path / "ok", t_r=np.arange(-12.0, 58.0, 0.125),
                            level_fn=lambda mic, t_r, d: levels("m2", t_r, d) if mic == "m1" else levels(mic, t_r, d),
                            doc_changes=doc)
    assert campaign_log_warnings(read_campaign(root_ok)) == []


def test_sample_campaign_has_no_background_warning():
    from gisnoise.measure import campaign_log_warnings

    root = Path(__file__).resolve().parents[1] / "sample_data" / "campaign"
    assert campaign_log_warnings(read_campaign(root)) == []


def test_a_flight_with_no_block_in_its_log_is_refused_by_the_reader(tmp_path):
    """Audio 1000 s after the log (a wrong start_utc): check reports it, read_campaign (fit, diagnose) refuses."""
    root = make_campaign(tmp_path / "c", t_r=np.arange(1003.0, 1058.0, 0.125))
    problems = check_campaign(root)
    assert len(problems) == 3 and all("no block falls within the flight log of 'f1' (check start_utc)"
                                      in p.message for p in problems)
    with pytest.raises(CampaignError, match=r"no block falls within the flight log of 'f1' \(check start_utc\)"):
        read_campaign(root)
    from gisnoise.identify import fit_campaign

    with pytest.raises(CampaignError, match="no block falls within the flight log of 'f1'"):
        fit_campaign(root, "horizontal")    # fit (and diagnose) read the campaign as check does: refused


def test_a_track_33_km_from_the_microphones_names_the_distance_not_the_clock(tmp_path):
    """The log 0.3 deg north (33.4 km) of the microphones, right clock: the message gives the distance."""
    track = straight_track()
    track["lat"] = track["lat"] + 0.3
    root = make_campaign(tmp_path / "c", track=track)
    problems = check_campaign(root)
    assert problems and all("the flight track is 33 km from the microphones" in p.message for p in problems)
    assert not any("start_utc" in p.message for p in problems)


def test_a_microphone_without_lat_is_said_missing(tmp_path):
    root = make_campaign(tmp_path / "c")
    doc = json.loads((root / "campaign.json").read_text())
    del doc["microphones"][1]["lat"]
    (root / "campaign.json").write_text(json.dumps(doc))
    msgs = [p.message for p in check_campaign(root)]
    assert any("field 'microphones[1].lat' is missing" in m for m in msgs), msgs
    assert not any("None" in m for m in msgs)


def test_a_misspelt_key_of_a_microphone_or_flight_is_named_not_left_out(tmp_path):
    """`background_DB` (for background_db) was left out without a word: the background was then estimated instead of
    the stated one.  A key gisnoise does not read is a problem naming it and the nearest known key; free-text keys
    (name, notes, description) stay allowed."""
    root = make_campaign(tmp_path / "c")
    doc = json.loads((root / "campaign.json").read_text())
    doc["microphones"][0]["background_DB"] = 47.0
    doc["microphones"][1]["notes"] = "on the roof"
    doc["flights"][0]["start_ut"] = START
    (root / "campaign.json").write_text(json.dumps(doc))
    msgs = [p.message for p in check_campaign(root)]
    assert any("'microphones[0].background_DB' is not one gisnoise reads (did you mean 'background_db'?)" in m
               for m in msgs)
    assert any("'flights[0].start_ut' is not one gisnoise reads (did you mean 'start_utc'?)" in m for m in msgs)
    assert not any("notes" in m.split(";")[0] for m in msgs)
