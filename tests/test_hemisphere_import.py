"""Import of measured hemispheres: obvious mistakes are refused or said, before a card is written.

Known truths by construction: a table in radians has every angle within +-pi/2; a table of the behind half
(phi 0..90) lacks half the lower hemisphere and a quarter table (phi and theta 0..90) three quarters (phi_t and
theta_t are each uniform in solid angle; the four quadrants are congruent); the one-third-octave band after 800 Hz
is 1000 Hz; a table of levels ``f(phi, theta)`` written with its rows in any order is the same table; a table whose
rows are all equal has no row that repeats a different measured one.

A card document written or edited by hand passes the same checks of units and bands when it is read (file,
``--card``, ``card show``, a map given its path): the same table with its axes in degrees and Hz is taken, in
radians or kHz refused naming the field.
"""

import json
import math
import re

import numpy as np
import pytest
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.errors import CardError
from gisnoise.model import (
    HEMISPHERE_SCHEMA,
    SALFORD_ATMOSPHERE,
    ImplausibleCardError,
    fit_hemisphere,
    import_hemisphere,
    import_warnings,
    load,
)

openpyxl = pytest.importorskip("openpyxl")

ATM = dict(SALFORD_ATMOSPHERE)
THIRDS = [800.0, 1000.0, 1250.0]


def level(band, a, b):
    """A smooth table, distinct at every node (dB at 1 m): 80 dB at 1 kHz straight below."""
    return 80.0 - 3.0 * abs(math.log2(band / 1000.0)) + a / 10.0 + b / 100.0


def write_csv(path, phi, theta, bands=THIRDS, column="level_db", radius=None):
    rows = [f"band,phi_deg,theta_deg,{column}" + (",radius_m" if radius is not None else "")]
    rows += [f"{f:g},{a:g},{b:g},{level(f, a, b)!r}" + (f",{radius:g}" if radius is not None else "")
             for f in bands for a in phi for b in theta]
    path.write_text("\n".join(rows) + "\n")
    return path


def write_xlsx(path, phi, theta, bands=THIRDS, cell=None):
    """A Salford-layout workbook: one sheet per band, 'Phi' in A1, theta across row 1, phi down column A; ``cell``:
    ``(sheet, ref, value)`` written over one cell."""
    wb = openpyxl.Workbook()
    wb.remove(wb.active)
    for f in bands:
        ws = wb.create_sheet(f"band_{f:g}")
        ws.append(["Phi", *theta])
        for a in phi:
            ws.append([a, *[level(f, a, b) for b in theta]])
    if cell is not None:
        wb[cell[0]][cell[1]] = cell[2]
    wb.save(path)
    return path


FULL = [-90.0, -45.0, 0.0, 45.0, 90.0]


def run(*args):
    return CliRunner().invoke(cli, ["-q", *args])


# --------------------------------------------------------------------------- angles


def test_angles_in_radians_are_refused_naming_degrees(tmp_path):
    rad = [round(math.radians(a), 4) for a in FULL]  # -1.5708 .. 1.5708, as a file would give them
    p = write_csv(tmp_path / "rad.csv", rad, rad)
    with pytest.raises(CardError, match=r"phi_deg: all 5 angles lie within \+-1.571 \(-1.5708..1.5708\), the range "
                                        r"of radians; table angles are degrees") as e:
        import_hemisphere(p, atmosphere=ATM)
    assert e.value.field == "phi_deg"
    p = write_csv(tmp_path / "rad_theta.csv", FULL, rad)  # one axis in radians is refused as well
    with pytest.raises(CardError, match="theta_deg: all 5 angles"):
        import_hemisphere(p, atmosphere=ATM)
    r = run("card", "import-hemisphere", str(tmp_path / "rad.csv"), "--out", str(tmp_path / "c.json"),
            "--temperature", "20", "--humidity", "50")
    assert r.exit_code == 2 and "radians" in r.output and not (tmp_path / "c.json").exists()
    # one node gives no range to judge by: taken (a source of one level in every direction)
    assert import_hemisphere(write_csv(tmp_path / "one.csv", [0.0], [0.0]), atmosphere=ATM).phi_deg.size == 1


def test_a_table_short_of_the_horizon_is_said_at_import(tmp_path):
    half = import_hemisphere(write_csv(tmp_path / "half.csv", [0.0, 45.0, 90.0], FULL), atmosphere=ATM)
    assert half.uncovered()["share"] == pytest.approx(0.5, abs=1e-12)
    (w,) = import_warnings(half)
    assert "phi -90..0 deg (ahead) not covered (50 % of the lower hemisphere's solid angle)" in w
    quarter = import_hemisphere(write_csv(tmp_path / "q.csv", [0.0, 45.0, 90.0], [0.0, 45.0, 90.0]), atmosphere=ATM)
    assert quarter.uncovered()["share"] == pytest.approx(0.75, abs=1e-12)
    (w,) = import_warnings(quarter)
    assert "phi -90..0 deg (ahead), theta -90..0 deg (port) not covered (75 %" in w
    assert import_warnings(import_hemisphere(write_csv(tmp_path / "f.csv", FULL, FULL), atmosphere=ATM)) == []
    r = run("card", "import-hemisphere", str(tmp_path / "q.csv"), "--out", str(tmp_path / "q.json"),
            "--temperature", "25", "--humidity", "70")
    assert r.exit_code == 0 and (tmp_path / "q.json").exists()
    assert "warning: hemisphere 'q': the table does not reach the horizon" in r.output
    r = run("card", "show", str(tmp_path / "q.json"))
    assert "coverage  hemisphere 'q'" in r.output


# --------------------------------------------------------------------------- bands


def test_a_missing_band_is_refused_naming_it(tmp_path):
    p = write_csv(tmp_path / "gap.csv", FULL, FULL, bands=[630.0, 800.0, 1250.0, 2000.0])
    with pytest.raises(CardError, match=r"bands 630-2000 Hz lack 1000, 1600 Hz") as e:
        import_hemisphere(p, atmosphere=ATM)
    assert e.value.field == "band"
    x = write_xlsx(tmp_path / "gap.xlsx", FULL, FULL, bands=[800.0, 1250.0])
    with pytest.raises(CardError, match="lack 1000 Hz"):
        import_hemisphere(x)


def test_bands_in_khz_are_refused_below_the_audio_range(tmp_path):
    p = write_csv(tmp_path / "khz.csv", FULL, FULL, bands=[0.02, 0.025, 0.0315])
    with pytest.raises(CardError, match=r"band '0.02' Hz lies below 10 Hz, the lowest band of the A-weighting "
                                        r"\(IEC 61672-1\): bands are nominal frequencies in Hz \(kHz given\?\)") as e:
        import_hemisphere(p, atmosphere=ATM)
    assert e.value.field == "band"
    infra = [10.0, 12.5, 16.0, 20.0, 25.0, 31.5, 40.0, 50.0, 63.0, 80.0, 100.0, 125.0, 160.0, 200.0, 250.0, 315.0,
             400.0, 500.0, 630.0, 800.0, 1000.0]
    assert import_hemisphere(write_csv(tmp_path / "low.csv", FULL, FULL, bands=infra),
                             atmosphere=ATM).bands_hz.tolist() == infra  # from 10 Hz on: taken


# --------------------------------------------------------------------------- the plausibility guard at import


@pytest.mark.parametrize("args, fld", [(["--radius", "0.5"], "reference_distance_m = 0.5 m"),
                                       (["--radius", "2000"], "reference_distance_m = 2000 m")])
def test_import_refuses_what_the_maps_refuse(tmp_path, args, fld):
    p = write_csv(tmp_path / "h.csv", FULL, FULL)
    r = run("card", "import-hemisphere", str(p), "--out", str(tmp_path / "c.json"), "--temperature", "25",
            "--humidity", "70", *args)
    assert r.exit_code == 2 and f"implausible card: {fld}" in r.output, r.output
    assert len(r.output.strip().splitlines()) == 1 and not (tmp_path / "c.json").exists()


def test_levels_200_db_too_high_are_refused_naming_levels_db(tmp_path):
    p = tmp_path / "loud.csv"
    write_csv(p, FULL, FULL)
    lines = p.read_text().splitlines()
    p.write_text("\n".join([lines[0]] + [",".join([*r.split(",")[:3], str(float(r.split(",")[3]) + 200)])
                                         for r in lines[1:]]) + "\n")
    with pytest.raises(ImplausibleCardError, match="implausible card: levels_db") as e:
        import_hemisphere(p, atmosphere=ATM)
    assert e.value.field == "levels_db"


# --------------------------------------------------------------------------- messages


def test_fit_of_a_table_with_too_few_measured_nodes_names_the_counts(tmp_path):
    one = import_hemisphere(write_csv(tmp_path / "one.csv", [0.0], [0.0]), atmosphere=ATM)
    with pytest.raises(CardError, match=r"1 measured node below the horizon for the 5 free parameters of "
                                        r"paper-offset \(p0, p2, p3, p4, p5\); the fit needs at least 5") as e:
        fit_hemisphere(one)
    assert e.value.field == "measured"
    r = run("card", "import-hemisphere", str(tmp_path / "one.csv"), "--out", str(tmp_path / "one.json"),
            "--temperature", "25", "--humidity", "70")
    assert r.exit_code == 0, r.output
    r = run("card", "fit-hemisphere", str(tmp_path / "one.json"), "--out", str(tmp_path / "fit.json"))
    assert r.exit_code == 2 and "1 measured node below the horizon" in r.output and "ValueError" not in r.output


def test_workbook_rows_and_columns_in_any_order_are_sorted_with_their_angles(tmp_path):
    card = import_hemisphere(write_xlsx(tmp_path / "desc.xlsx", FULL[::-1], [0.0, -45.0, 90.0, 45.0, -90.0]))
    assert card.phi_deg.tolist() == FULL and card.theta_deg.tolist() == FULL
    for k, f in enumerate(THIRDS):
        np.testing.assert_array_equal(card.levels_db[k], [[level(f, a, b) for b in FULL] for a in FULL])
    p = write_xlsx(tmp_path / "twice.xlsx", [-90.0, 0.0, 0.0, 90.0], FULL)
    with pytest.raises(CardError, match=r"twice.xlsx: sheet 'band_800': phi 0 deg given twice \(cells A3 and A4\)"):
        import_hemisphere(p)


@pytest.mark.parametrize("value, what", [(None, "cell C4 is blank (level in dB expected)"),
                                         ("abc", "cell C4 holds 'abc', not a number (level in dB)"),
                                         ("nan", "cell C4 holds 'nan', not a finite number (level in dB)")])
def test_a_bad_workbook_cell_is_named_by_its_reference(tmp_path, value, what):
    p = write_xlsx(tmp_path / "bad.xlsx", FULL, FULL, cell=("band_1000", "C4", value))
    with pytest.raises(CardError, match=re.escape(f"bad.xlsx: sheet 'band_1000': {what}")) as e:
        import_hemisphere(p)
    assert e.value.field == "sheet band_1000"


def test_a_level_column_at_1_m_with_another_radius_is_refused(tmp_path):
    p = write_csv(tmp_path / "r2.csv", FULL, FULL, column="spl_db_at_1m", radius=2.0)
    with pytest.raises(CardError, match=r"column 'spl_db_at_1m' gives levels at 1 m, column 'radius_m' a radius of "
                                        r"2 m") as e:
        import_hemisphere(p, atmosphere=ATM)
    assert e.value.field == "radius_m"
    p = write_csv(tmp_path / "r1.csv", FULL, FULL, column="spl_db_at_1m")
    assert import_hemisphere(p, atmosphere=ATM).reference_distance_m == 1.0
    with pytest.raises(CardError, match=r"radius_m = 2 m contradicts the file's radius of 1 m") as e:
        import_hemisphere(p, atmosphere=ATM, radius_m=2.0)
    assert e.value.field == "radius_m"
    p = write_csv(tmp_path / "r3.csv", FULL, FULL, radius=3.0)  # level_db at the radius the file states
    assert import_hemisphere(p, atmosphere=ATM).reference_distance_m == 3.0


# --------------------------------------------------------------------------- the measured cells of a constant table


def test_a_table_whose_rows_are_all_equal_counts_every_row_as_measured(tmp_path):
    """70 dB at every node: no row repeats a different, measured one, so no row is fill; without a 'measured'
    column only the columns beyond --measured-theta-max (60 deg: theta +-90 of FULL) count as filled."""
    p = tmp_path / "flat.csv"
    p.write_text("band,phi_deg,theta_deg,level_db\n" + "".join(f"{f:g},{a:g},{b:g},70\n" for f in THIRDS
                                                                 for a in FULL for b in FULL))
    card = import_hemisphere(p, atmosphere=ATM)
    expect = np.broadcast_to((np.abs(np.array(FULL)) <= 60.0)[None, :], (len(FULL), len(FULL)))
    np.testing.assert_array_equal(card.measured, expect)
    r = run("card", "import-hemisphere", str(p), "--out", str(tmp_path / "flat.json"), "--temperature", "25",
            "--humidity", "70")
    assert r.exit_code == 0 and f"{expect.sum()} nodes measured" in r.output, r.output
    r = run("card", "show", str(tmp_path / "flat.json"))
    assert f"measured  {expect.sum()} of {expect.size} nodes" in r.output, r.output


# --------------------------------------------------------------------------- the same checks for a card read


def card_doc(phi=FULL, theta=FULL, bands=THIRDS):
    """A hemisphere card written by hand: the table of ``level`` at 1 m on angles in degrees and bands in Hz, every
    node measured; ``phi``, ``theta``, ``bands`` are what the document states for them."""
    return {"schema": HEMISPHERE_SCHEMA, "id": "by-hand", "vehicle": "v", "phase": "horizontal",
            "reference_distance_m": 1.0, "atmosphere": ATM, "phi_deg": list(phi), "theta_deg": list(theta),
            "bands_hz": list(bands),
            "levels_db": [[[level(f, a, b) for b in FULL] for a in FULL] for f in THIRDS],
            "measured": [[True] * len(FULL) for _ in FULL]}


def write_card(path, doc):
    path.write_text(json.dumps(doc))
    return path


RAD = [math.radians(a) for a in FULL]


@pytest.mark.parametrize("axis", ["phi_deg", "theta_deg"])
def test_a_card_written_by_hand_with_angles_in_radians_is_refused_on_load(tmp_path, axis):
    ok = load(write_card(tmp_path / "deg.json", card_doc()))  # the same table in degrees is taken
    assert ok.phi_deg.tolist() == FULL and ok.theta_deg.tolist() == FULL
    p = write_card(tmp_path / "rad.json", {**card_doc(), axis: RAD})
    with pytest.raises(CardError, match=rf"rad.json: field '{axis}': all 5 angles lie within \+-1.571 "
                                        r"\(-1.5708..1.5708\), the range of radians") as e:
        load(p)
    assert e.value.field == axis and "\n" not in str(e.value)
    r = run("card", "show", str(p))  # the command line: one usage line naming the field
    assert r.exit_code == 2 and axis in r.output and "radians" in r.output, r.output
    assert len(r.output.strip().splitlines()) == 1


def test_a_map_given_a_card_file_in_radians_refuses_it_naming_the_field(tmp_path):
    from gisnoise.maps import make_map

    rows = ["t,lat,lon,h,roll,pitch,yaw,power_w,phase"] + [
        f"{t},{52.0 + 1e-5 * t:.7f},10.0,20,0,0,0,1000,horizontal" for t in range(0, 11)]
    traj = tmp_path / "fly.csv"
    traj.write_text("\n".join(rows) + "\n")
    p = write_card(tmp_path / "rad.json", {**card_doc(), "phi_deg": RAD})
    with pytest.raises(CardError, match="radians") as e:
        make_map(str(traj), [str(p)], tmp_path / "map", resolution_m=20.0, margin_m=60.0, ground_h=0.0,
                 metrics=["LAmax"], engine="numpy")
    assert e.value.field == "phi_deg" and not (tmp_path / "map" / "levels.tif").exists()


@pytest.mark.parametrize("bands, said", [
    ([f / 1000.0 for f in THIRDS], "band 0.8 Hz lies below 10 Hz"),                       # kHz
    ([630.0, 800.0, 1250.0], "the bands 630-1250 Hz lack 1000 Hz"),                       # 1000 Hz left out
    ([800.0, 1100.0, 1250.0], "band 1100 Hz is no one-third-octave mid-band frequency"),  # no band's frequency
])
def test_a_card_written_by_hand_with_bands_not_in_hz_thirds_is_refused_on_load(tmp_path, bands, said):
    assert load(write_card(tmp_path / "hz.json", card_doc())).bands_hz.tolist() == THIRDS
    p = write_card(tmp_path / "bad.json", card_doc(bands=bands))
    with pytest.raises(CardError, match=re.escape(f"bad.json: field 'bands_hz': {said}")) as e:
        load(p)
    assert e.value.field == "bands_hz"
    r = run("card", "plot", str(p), "--out", str(tmp_path / "bad.png"))
    assert r.exit_code == 2 and "bands_hz" in r.output and not (tmp_path / "bad.png").exists(), r.output
