"""Fits real data can support: a steady-power flyover campaign (three passes at one power).

The levels are the paper-offset ansatz itself at emission time (one model definition) plus
seeded noise; the truth is known, so the fitted card is judged against it.
"""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame, emission_angles
from gisnoise.model import ImplausibleCardError, ModelCard, get_ansatz, load
from gisnoise.model.cards import dumps

FRAME = LocalFrame(52.27, 10.52, 80.0)
TRUTH = dict(p0=64.0, p1=20.0, p2=0.08, p3=-0.28, p4=-0.2, p5=1.05, p6=1.0, p7=40.0)
POWER_W, REF_W, C = 2400.0, 3000.0, 340.0
MICS = {"m1": (0.0, 0.0), "m2": (0.0, 60.0), "m3": (0.0, -130.0)}   # east, north of the origin (m), 1.2 m up


def _campaign(root, seed=3, half_m=450.0):
    """Three straight passes (60 m eastbound, 90 m westbound, 45 m eastbound, each from -half_m to half_m east)
    at one power."""
    rng = np.random.default_rng(seed)
    (root / "flights").mkdir(parents=True)
    # waypoints (t, east, north, up): passes of 60 s (at 15 m/s for 900 m) joined by 10 s links
    a = half_m
    wp = np.array([(0, -a, 10, 60), (60, a, 10, 60), (70, a, -20, 90), (130, -a, -20, 90),
                   (140, -a, 30, 45), (200, a, 30, 45)], dtype=float)
    t = np.arange(0.0, 200.0 + 1e-9, 0.1)
    e, n, u = (np.interp(t, wp[:, 0], wp[:, k]) for k in (1, 2, 3))
    yw = np.degrees(np.arctan2(np.gradient(e, t), np.gradient(n, t)))
    lat, lon, h = FRAME.to_wgs84(e, n, u)
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=yw, power_w=np.full_like(t, POWER_W),
                      phase=np.full(t.size, "horizontal"))
    traj.to_csv(root / "flights" / "f1.csv")
    model = get_ansatz("paper-offset")
    p = np.array([TRUTH[k] for k in model.params])
    mics = []
    for mid, (me, mn) in MICS.items():
        (root / "mics" / mid).mkdir(parents=True)
        r = np.stack([me - e, mn - n, 1.2 - u], axis=-1)
        d, phi, theta = emission_angles(r[:, 0], r[:, 1], r[:, 2], np.radians(yw), 0 * t, 0 * t)
        lv = model.level(p, {"d": d, "phi": phi, "theta": theta, "p_el": np.full_like(t, POWER_W / REF_W)})
        t_r = t + d / C                                            # reception times of these emissions
        grid = np.arange(0.5, t[-1], 0.125)
        la = np.interp(grid, t_r, lv) + rng.normal(0.0, 0.5, grid.size)
        rows = "".join(f"{a:.4f},{b:.3f}\n" for a, b in zip(grid, la, strict=True))
        (root / "mics" / mid / "f1.csv").write_text("t,LA\n" + rows)
        mlat, mlon, mh = FRAME.to_wgs84(me, mn, 1.2)
        mics.append({"id": mid, "lat": float(mlat), "lon": float(mlon), "h": float(mh), "mount": "free_field",
                     "background_db": 40.0})
    doc = {"schema": "gisnoise/campaign/1", "origin": {"lat": 52.27, "lon": 10.52, "h": 80.0},
           "speed_of_sound_m_s": C, "weather": {"temperature_c": 15.0},
           "vehicle": {"name": "steady", "reference_power_w": REF_W}, "microphones": mics,
           "flights": [{"id": "f1", "start_utc": "2024-05-04T10:00:00Z"}]}
    (root / "campaign.json").write_text(json.dumps(doc))
    return root


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    return _campaign(tmp_path_factory.mktemp("steady") / "camp")


def run(*args):
    return CliRunner().invoke(cli, ["-q", *args], catch_exceptions=False)


def _truth_level(d, phi, theta):
    model = get_ansatz("paper-offset")
    p = np.array([TRUTH[k] for k in model.params])
    return model.level_uav(p, {"d": d, "phi": phi, "theta": theta, "p_el": POWER_W / REF_W})


def test_fit_writes_the_identifiable_form_and_its_level_below_the_track(tmp_path, campaign):
    out = tmp_path / "card.json"
    r = run("fit", str(campaign), "--phase", "horizontal", "--out", str(out))
    assert r.exit_code == 0, r.output
    card = load(out)
    assert card.parameters["p1"] == 0.0                       # no power information: held, not fitted
    assert "p1" in card.provenance["held_parameters"]
    lo, hi = card.statistics["power_range_w"]
    assert lo == pytest.approx(POWER_W) and hi == pytest.approx(POWER_W)
    # the level straight below the track at 40 m and 60 m equals the truth within 0.3 dB
    for d in (40.0, 60.0):
        x = card.inputs(d, 0.0, -np.pi / 2, POWER_W)
        assert float(card.level_uav(x)) == pytest.approx(float(_truth_level(d, 0.0, -np.pi / 2)), abs=0.3)


def test_the_command_line_says_which_parameters_the_data_could_not_support_and_why(tmp_path, campaign):
    """A parameter the fit held by itself (p1 at steady power) is shown as held with the card's reason, not as
    'fixed' (which the user did not ask for); a parameter the user fixes stays 'fixed'."""
    out = tmp_path / "card.json"
    r = CliRunner().invoke(cli, ["fit", str(campaign), "--phase", "horizontal", "--out", str(out)],
                           catch_exceptions=False)
    assert r.exit_code == 0, r.output
    reason = load(out).provenance["held_parameters"]["p1"]
    p1_row = next(line for line in r.output.splitlines() if line.startswith("p1 "))
    assert p1_row.rstrip().endswith("held") and "fixed" not in p1_row
    assert f"held p1: {reason}" in r.output
    r = CliRunner().invoke(cli, ["fit", str(campaign), "--phase", "horizontal", "--out", str(out), "--fix", "p6=1",
                                 "--force"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    assert next(line for line in r.output.splitlines() if line.startswith("p6 ")).rstrip().endswith("fixed")


def test_card_show_says_held_and_fixed_parameters_have_no_uncertainty_of_their_own(tmp_path, campaign):
    """A parameter held by the fit or fixed by the user has a zero row in the covariance: not a value known
    exactly, but one that was not estimated. card show says which and why instead of '+- 0'."""
    out = tmp_path / "card.json"
    assert run("fit", str(campaign), "--phase", "horizontal", "--out", str(out), "--fix", "p6=1").exit_code == 0
    card = load(out)
    assert card.std["p1"] == 0.0 and card.std["p6"] == 0.0
    shown = {line.split("=")[0].strip(): line for line in run("card", "show", str(out)).output.splitlines()
             if line.startswith("  ") and "=" in line}
    assert "+- 0" not in shown["p1"] and "held: " + card.provenance["held_parameters"]["p1"] in shown["p1"]
    assert "+- 0" not in shown["p6"] and shown["p6"].rstrip().endswith("fixed")
    assert "+- " in shown["p0"]


def test_fit_never_writes_its_card_over_a_file_that_is_not_a_card(tmp_path, campaign):
    """--out naming the campaign's own campaign.json (or any file that is not a model card) is refused before
    the fit, naming --out, and the file is left byte for byte, --force or not; an existing card is replaced by
    the new fit only with --force (as the card commands)."""
    cj = campaign / "campaign.json"
    before = cj.read_bytes()
    r = CliRunner().invoke(cli, ["fit", str(campaign), "--phase", "horizontal", "--out", str(cj)])
    assert r.exit_code == 2 and cj.read_bytes() == before
    errors = [ln for ln in r.output.splitlines() if ln.startswith("Error: ")]
    assert len(errors) == 1 and "--out" in errors[0] and str(cj) in errors[0], r.output
    r = CliRunner().invoke(cli, ["fit", str(campaign), "--phase", "horizontal", "--out", str(cj), "--force"])
    assert r.exit_code == 2 and cj.read_bytes() == before and "not a model card" in r.output, r.output
    card = tmp_path / "card.json"
    assert run("fit", str(campaign), "--phase", "horizontal", "--out", str(card)).exit_code == 0
    first = card.read_bytes()
    r = CliRunner().invoke(cli, ["fit", str(campaign), "--phase", "horizontal", "--out", str(card), "--fix", "p6=1"])
    assert r.exit_code == 2 and card.read_bytes() == first, r.output
    errors = [ln for ln in r.output.splitlines() if ln.startswith("Error: ")]
    assert errors == [f"Error: --out {card}: exists; refusing to overwrite (--force overwrites it)"], r.output
    assert run("fit", str(campaign), "--phase", "horizontal", "--out", str(card), "--fix", "p6=1",
               "--force").exit_code == 0
    assert json.loads(first)["parameters"]["p6"] != 1.0 and load(card).parameters["p6"] == 1.0


@pytest.mark.parametrize("bad", ["my card", "cards/horizontal", ".hidden", "nul"])
def test_fit_refuses_a_card_id_the_card_store_cannot_hold(tmp_path, campaign, bad):
    """--id follows the identifier rule every face shares (gisnoise.limits.SAFE_ID_PATTERN): refused before the
    fit in one line naming --id, no card written."""
    out = tmp_path / "card.json"
    r = CliRunner().invoke(cli, ["fit", str(campaign), "--phase", "horizontal", "--out", str(out), "--id", bad])
    assert r.exit_code == 2 and not out.exists()
    errors = [ln for ln in r.output.splitlines() if ln.startswith("Error: ")]
    assert len(errors) == 1 and "--id" in errors[0] and repr(bad) in errors[0], r.output


@pytest.mark.parametrize("vehicle, expected", [("Drohne \u00c4/1 (Gr\u00fcn)", "drohne-a-1-grun-horizontal"),
                                               ("x" * 300, "x" * 100 + "-horizontal")])
def test_the_default_card_id_from_the_vehicle_name_is_a_valid_identifier(tmp_path, campaign, vehicle, expected):
    """Without --id the card is named <vehicle>-<phase>: letters folded to ASCII, other characters to '-', the
    vehicle part at most 100 characters, so the id meets the rule every face shares (SAFE_ID_PATTERN)."""
    import shutil

    from gisnoise.limits import check_id

    camp = tmp_path / "camp"
    shutil.copytree(campaign, camp)
    doc = json.loads((camp / "campaign.json").read_text())
    doc["vehicle"]["name"] = vehicle
    (camp / "campaign.json").write_text(json.dumps(doc))
    out = tmp_path / "card.json"
    assert run("fit", str(camp), "--phase", "horizontal", "--out", str(out)).exit_code == 0
    card = load(out)
    assert card.id == expected and check_id(card.id) == card.id and card.vehicle == vehicle


def test_p7_is_held_at_the_stated_background_without_background_dominated_rows(tmp_path):
    """Passes of +-120 m: the UAV stays more than 3 dB above the 40 dB(A) background at every microphone (no
    background-dominated row); a free fit gives p7 = 41.5 +- 2.4 dB(A), no better than the stated background, so
    p7 is held at the campaign's stated background and the card says so."""
    from gisnoise.identify import background_dominated_rows
    from gisnoise.measure import read_campaign

    camp = _campaign(tmp_path / "short", half_m=120.0)
    assert background_dominated_rows(read_campaign(camp).samples()) == 0
    out = tmp_path / "card.json"
    r = run("fit", str(camp), "--phase", "horizontal", "--out", str(out))
    assert r.exit_code == 0, r.output
    card = load(out)
    assert card.parameters["p7"] == 40.0
    reason = card.provenance["held_parameters"]["p7"]
    assert "held at the campaign's background 40.0 dB(A)" in reason and "0 rows within 3 dB" in reason
    x = card.inputs(60.0, 0.0, -np.pi / 2, POWER_W)
    assert float(card.level_uav(x)) == pytest.approx(float(_truth_level(60.0, 0.0, -np.pi / 2)), abs=0.3)


@pytest.mark.parametrize("args, names", [
    (["--fix", "p0=64"], ("p1", "p0", "fix p1 too")),                       # p1 would absorb the offset
    (["--ansatz", "paper"], ("p1", "--ansatz paper-offset")),             # p1 would scale the whole level
    (["--fix", "p2=0", "--fix", "p4=0"], ("p3", "p5")),                    # no amplitude: the phases are free
])
def test_identifiability_is_checked_again_after_fix(tmp_path, campaign, args, names):
    r = run("fit", str(campaign), "--phase", "horizontal", "--out", str(tmp_path / "c.json"), *args)
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1, r.output
    assert all(n in r.output for n in names) and not (tmp_path / "c.json").exists()


def test_fix_p1_gives_a_sane_card_or_refuses(tmp_path, campaign):
    from gisnoise.model import card_problems

    out = tmp_path / "fixed.json"
    r = run("fit", str(campaign), "--phase", "horizontal", "--fix", "p1=20", "--out", str(out))
    if r.exit_code == 0:
        card = load(out)
        assert card_problems(card) == []
        x = card.inputs(40.0, 0.0, -np.pi / 2, POWER_W)
        assert float(card.level_uav(x)) == pytest.approx(float(_truth_level(40.0, 0.0, -np.pi / 2)), abs=0.3)
    else:
        assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1


def _bad_card():
    good = load("demo-horizontal")
    return ModelCard(id="bad", vehicle="x", phase="horizontal", ansatz=good.ansatz,
                     parameters={**good.parameters, "p2": -2958.0, "p6": 2.01},
                     reference_power_w=good.reference_power_w)


def test_implausible_card_is_refused_by_load_and_the_map_naming_p2(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(dumps(_bad_card()))
    with pytest.raises(ImplausibleCardError, match="p2 = -2958"):
        load(path)
    assert load(path, force=True).parameters["p2"] == -2958.0   # inspection only
    r = run("card", "show", str(path))
    assert r.exit_code == 2 and "p2" in r.output
    # the map refuses it even when handed the card object
    from gisnoise.maps import make_map

    t = np.arange(0.0, 10.0, 1.0)
    lat, lon, h = FRAME.to_wgs84(10.0 * t, 0 * t, 0 * t + 60.0)
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t + 90.0,
                      power_w=0 * t + 3000.0, phase=np.full(t.size, "horizontal"))
    with pytest.raises(ImplausibleCardError, match="p2"):
        make_map(traj, [_bad_card()], tmp_path / "m", ground_h=80.0)
    assert not (tmp_path / "m").exists()
    # and the evaluator, given the card file or the card object, on every engine
    from gisnoise.maps import evaluate_grid, grid_for_trajectory

    grid = grid_for_trajectory(traj, 20.0, 100.0)
    for engine in ("numpy", "fast", "auto"):
        for c in (path, _bad_card()):
            with pytest.raises(ImplausibleCardError, match="p2 = -2958"):
                evaluate_grid(traj, [c], grid, ground_h=80.0, engine=engine)


def test_card_with_infinite_std_is_refused_naming_the_parameter():
    good = load("demo-horizontal")
    cov = np.diag([0.01] * 8)
    cov[1, 1] = 4.7e16 ** 2
    c = ModelCard(id="unsure", vehicle="x", phase="horizontal", ansatz=good.ansatz, parameters=dict(good.parameters),
                  reference_power_w=good.reference_power_w, covariance=tuple(map(tuple, cov)))
    from gisnoise.model import card_problems

    problems = card_problems(c)
    assert problems and "p1" in problems[0]


def test_no_traceback_from_any_effect_missing_its_inputs(tmp_path, campaign):
    """Every BASE+EFFECT on a campaign without the effect's inputs: a card or one line, exit 2."""
    from gisnoise.model import effect_names

    doc = json.loads((campaign / "campaign.json").read_text())
    plate = tmp_path / "plate"
    import shutil

    shutil.copytree(campaign, plate)
    for m in doc["microphones"]:
        m["height_agl_m"] = 0.0                      # ground plates
    (plate / "campaign.json").write_text(json.dumps(doc))
    for eff in effect_names():
        for base in ("paper-offset", "paper"):
            r = CliRunner().invoke(cli, ["-q", "fit", str(plate), "--phase", "horizontal", "--ansatz",
                                         f"{base}+{eff}", "--out", str(tmp_path / f"{base}+{eff}.json")])
            assert not (r.exception and not isinstance(r.exception, SystemExit)), (eff, r.exception)
            assert r.exit_code in (0, 2), (eff, r.output)
            if r.exit_code == 2:
                assert len(r.output.strip().splitlines()) == 1, r.output
            if eff == "rpm":
                assert r.exit_code == 2 and "rpm" in r.output
            if eff == "ground_reflection":   # a ground plate rules the reflection out, and the message says why
                assert r.exit_code == 2 and "on the ground" in r.output


def test_parameters_are_printed_with_their_units(tmp_path, campaign):
    """Units follow from Eq. 8-11: p0, p7 are levels (dB(A)); p1 multiplies log10(P_el) (dB(A) per decade of
    power); p3, p5 are subtracted from angles in radians (rad); p2 multiplies (theta + pi/2) in radians (1/rad);
    p4 and p6 multiply pure numbers (-). Extension parameters carry their effect's units (k_bank: dB)."""
    from gisnoise.model import get_ansatz

    expected = {"p0": "dB(A)", "p1": "dB(A)/decade", "p2": "1/rad", "p3": "rad", "p4": "-", "p5": "rad", "p6": "-",
                "p7": "dB(A)"}
    m = get_ansatz("paper-offset")
    assert dict(zip(m.params, m.units, strict=True)) == expected
    assert get_ansatz("paper").units == tuple(expected[k] for k in get_ansatz("paper").params)
    ext = get_ansatz("paper-offset+bank_angle")
    assert dict(zip(ext.params, ext.units, strict=True)) == {**expected, "k_bank": "dB"}
    out = tmp_path / "card.json"
    r = CliRunner().invoke(cli, ["fit", str(campaign), "--phase", "horizontal", "--out", str(out), "--report",
                                 str(tmp_path / "report")], catch_exceptions=False)
    table = json.loads((tmp_path / "report" / "parameters.json").read_text())["parameters"]
    assert {row["name"]: row["unit"] for row in table} == expected
    rows = {ln.split()[0]: ln.split() for ln in r.output.splitlines() if ln.split() and ln.split()[0] in expected}
    assert {k: v[4] for k, v in rows.items()} == expected
    shown = {ln.split("=")[0].strip(): ln for ln in run("card", "show", str(out)).output.splitlines()
             if ln.startswith("  ") and "=" in ln}
    for k, unit in expected.items():
        assert shown[k].split("=")[1].split()[1] == f"[{unit}]", shown[k]
