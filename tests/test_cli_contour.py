"""``gisnoise contour``: outputs a GIS opens, and one-line errors that name the field (SPEC section 5)."""

import json

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame
from gisnoise.model import ModelCard, save

FRAME = LocalFrame(52.27, 10.52, 80.0)
G0 = 70.0


@pytest.fixture()
def card_path(tmp_path):
    card = ModelCard(id="omni", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0, phases=("hover", "transition"))
    return str(save(card, tmp_path / "omni.json"))


def write_csv(path, traj):
    traj.to_csv(path)
    return str(path)


def flyover(n=41, height=60.0):
    t = np.linspace(0.0, 40.0, n)
    lat, lon, h = FRAME.to_wgs84(-200.0 + 10.0 * t, np.zeros(n), np.full(n, height))  # eastwards
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=np.full(n, 90.0),
                      power_w=np.full(n, 3000.0), phase=np.full(n, "horizontal"))


def run(*args, env=None):
    return CliRunner().invoke(cli, ["-q", *args], env=env, catch_exceptions=False)


def test_contour_writes_a_geotiff_and_geojson_a_gis_opens(tmp_path, card_path):
    csv = write_csv(tmp_path / "flight.csv", flyover())
    out = tmp_path / "map"
    r = run("contour", csv, "--card", card_path, "--out", str(out), "--resolution", "20", "--margin", "200",
            "--levels", "55,60,65", "--ground-height", "80", "--threshold", "60")
    assert r.exit_code == 0, r.output
    with rasterio.open(out / "levels.tif") as ds:
        assert ds.crs.to_epsg() == 32632  # the local UTM zone of 10.5 E
        assert ds.descriptions == ("LAmax", "LAeq", "SEL", "TA60")
        assert ds.nodata == -9999.0
        assert ds.transform.a == 20.0 and ds.transform.e == -20.0
        assert ds.transform.c % 20.0 == 0 and ds.transform.f % 20.0 == 0  # snapped to the resolution
        lamax = ds.read(1)
        # the pixel centre is the receiver: LAmax at each centre equals the closed form for its
        # distance to the straight track (closest approach within the track)
        rows, cols = np.mgrid[0:ds.height, 0:ds.width]
        x, y = rasterio.transform.xy(ds.transform, rows.ravel(), cols.ravel(), offset="center")
        from pyproj import Transformer

        lon, lat = Transformer.from_crs(ds.crs.to_wkt(), "EPSG:4326", always_xy=True).transform(x, y)
        e, n, u = FRAME.to_enu(lat, lon, np.full(len(lat), 80.0 + 1.5))
        inside = np.abs(e) < 150.0
        d = np.sqrt(n ** 2 + (60.0 - u) ** 2)
        expected = G0 - 20 * np.log10(d / 40.0)
        np.testing.assert_allclose(lamax.ravel()[inside], expected[inside], atol=0.02)
    doc = json.loads((out / "contours.geojson").read_text())
    assert doc["type"] == "FeatureCollection"
    kinds = {(f["properties"]["metric"], f["properties"]["kind"], f["properties"]["level"]) for f in doc["features"]}
    assert ("LAmax", "isoband", 60.0) in kinds and ("LAmax", "isoline", 60.0) in kinds
    assert not any(m == "TA60" for m, _, _ in kinds)  # seconds are not contoured with dB levels
    assert "wrote" in r.output


def test_contour_plot_and_waypoints(tmp_path, card_path):
    route = {"schema": "gisnoise/waypoints/1", "sample_dt_s": 1.0, "waypoints": [
        {"lon": 10.52, "lat": 52.27, "alt": 60, "speed": 20},
        {"lon": 10.53, "lat": 52.27, "alt": 60, "speed": 20}]}
    p = tmp_path / "route.json"
    p.write_text(json.dumps(route))
    r = run("contour", str(p), "--card", card_path, "--out", str(tmp_path / "o"), "--resolution", "25",
            "--margin", "150", "--plot", "--ground-height", "0")
    assert r.exit_code == 0, r.output
    png = (tmp_path / "o" / "map.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000


def one_line_error(r, field):
    assert r.exit_code == 2, r.output
    err = r.stderr if hasattr(r, "stderr") else r.output
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("Error:") and field in lines[0], lines[0]
    assert "Traceback" not in r.output


def test_missing_column(tmp_path, card_path):
    csv = tmp_path / "f.csv"
    text = flyover().to_csv()
    header, *rows = text.splitlines()
    cols = header.split(",")
    i = cols.index("power_w")
    csv.write_text("\n".join(",".join(c for j, c in enumerate(line.split(",")) if j != i)
                             for line in text.splitlines()) + "\n")
    one_line_error(run("contour", str(csv), "--card", card_path, "--out", str(tmp_path / "o")), "power_w")


def test_nan_in_a_column(tmp_path, card_path):
    csv = tmp_path / "f.csv"
    lines = flyover().to_csv().splitlines()
    cols = lines[0].split(",")
    row = lines[5].split(",")
    row[cols.index("h")] = "nan"
    lines[5] = ",".join(row)
    csv.write_text("\n".join(lines) + "\n")
    one_line_error(run("contour", str(csv), "--card", card_path, "--out", str(tmp_path / "o")), "'h'")


def test_times_not_increasing(tmp_path, card_path):
    csv = tmp_path / "f.csv"
    lines = flyover().to_csv().splitlines()
    lines[3], lines[4] = lines[4], lines[3]
    csv.write_text("\n".join(lines) + "\n")
    one_line_error(run("contour", str(csv), "--card", card_path, "--out", str(tmp_path / "o")), "'t'")


def test_unknown_crs(tmp_path, card_path):
    csv = write_csv(tmp_path / "f.csv", flyover())
    one_line_error(run("contour", csv, "--card", card_path, "--out", str(tmp_path / "o"), "--crs", "EPSG:999999"),
                   "crs")
    one_line_error(run("contour", csv, "--card", card_path, "--out", str(tmp_path / "o"), "--crs", "EPSG:4326"),
                   "crs")


def test_empty_trajectory(tmp_path, card_path):
    csv = tmp_path / "f.csv"
    csv.write_text(flyover().to_csv().splitlines()[0] + "\n")
    one_line_error(run("contour", str(csv), "--card", card_path, "--out", str(tmp_path / "o")), "empty")


def test_grid_over_the_cell_limit(tmp_path, card_path):
    csv = write_csv(tmp_path / "f.csv", flyover())
    r = run("contour", csv, "--card", card_path, "--out", str(tmp_path / "o"), "--resolution", "1", "--ground-height", "80",
            env={"GISNOISE_MAX_CELLS": "10000"})
    one_line_error(r, "resolution")
    assert "GISNOISE_MAX_CELLS" in (r.stderr if hasattr(r, "stderr") else r.output)
    assert not (tmp_path / "o").exists()


def test_phase_without_card_and_bad_levels(tmp_path, card_path):
    traj = flyover()
    traj = traj.with_(phase=np.where(traj.t > 20, "sink", "horizontal"))
    csv = write_csv(tmp_path / "f.csv", traj)
    one_line_error(run("contour", csv, "--card", card_path, "--out", str(tmp_path / "o")), "'sink'")
    r = run("contour", csv, "--card", card_path, "--out", str(tmp_path / "o"), "--levels", "55,loud")
    assert r.exit_code == 2 and "--levels" in (r.stderr if hasattr(r, "stderr") else r.output)


def test_levels_outside_the_range_a_microphone_records_are_refused(tmp_path, card_path):
    """``--levels 60,45,45,-1000`` is a usage error whose one error line names --levels, the value and the range, and
    writes nothing (it drew a band 'LAmax -1000-45 dB(A)'); ``--threshold -1000`` likewise."""
    csv = write_csv(tmp_path / "f.csv", flyover())
    for option, value in (("--levels", "60,45,45,-1000"), ("--threshold", "-1000")):
        r = run("contour", csv, "--card", card_path, "--out", str(tmp_path / "o"), option, value)
        assert r.exit_code == 2, r.output
        err = r.stderr if hasattr(r, "stderr") else r.output
        said = [ln for ln in err.splitlines() if ln.startswith("Error:")]
        assert len(said) == 1 and option in said[0] and "-1000 dB(A) is outside [-50, 200] dB(A)" in said[0], err
        assert "Traceback" not in r.output
        assert not (tmp_path / "o").exists()


def test_missing_card_file(tmp_path):
    csv = write_csv(tmp_path / "f.csv", flyover())
    one_line_error(run("contour", csv, "--card", str(tmp_path / "nope.json"), "--out", str(tmp_path / "o")),
                   "nope.json")


def test_uncertainty_bands_and_contours(tmp_path):
    # covariance on p0 only (std 0.5 dB) of an omnidirectional card: dL/dp0 = 1 for every instant,
    # so LAmax_std = LAeq_std = 0.5 dB everywhere and the 95 % level is 1.645 * 0.5 dB lower
    cov = np.zeros((8, 8))
    cov[0, 0] = 0.25
    card = ModelCard(id="omni-fit", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0, covariance=tuple(map(tuple, cov)))
    cpath = str(save(card, tmp_path / "fit.json"))
    csv = write_csv(tmp_path / "flight.csv", flyover())
    out = tmp_path / "map"
    r = run("contour", csv, "--card", cpath, "--out", str(out), "--resolution", "25", "--margin", "150",
            "--levels", "55,60", "--ground-height", "80", "--uncertainty")
    assert r.exit_code == 0, r.output
    with rasterio.open(out / "levels.tif") as ds:
        names = ds.descriptions
        assert {"LAmax_std", "LAmax_p95", "LAeq_std", "LAeq_p95"} <= set(names)
        band = {n: ds.read(i + 1) for i, n in enumerate(names)}
    np.testing.assert_allclose(band["LAmax_std"], 0.5, atol=1e-6)
    np.testing.assert_allclose(band["LAeq_std"], 0.5, atol=1e-6)
    np.testing.assert_allclose(band["LAmax_p95"], band["LAmax"] - 1.6448536 * 0.5, atol=1e-4)
    doc = json.loads((out / "contours.geojson").read_text())
    metrics = {f["properties"]["metric"] for f in doc["features"]}
    assert {"LAmax_p95", "LAeq_p95"} <= metrics and "LAmax_std" not in metrics
    # cards without a covariance: a clear one-line error
    one_line_error(run("contour", csv, "--card", str(save(ModelCard(**{**card.__dict__, "covariance": None}),
                                                              tmp_path / "nocov.json")),
                       "--out", str(tmp_path / "o2"), "--ground-height", "80", "--uncertainty"), "covariance")


def test_receivers_on_a_dem(tmp_path, card_path):
    # a flat DEM at 100 m (ellipsoidal): receivers at 101.5 m, the track at 140 m
    from affine import Affine
    from pyproj import Transformer

    x0, y0 = Transformer.from_crs("EPSG:4326", "EPSG:32632", always_xy=True).transform(10.52, 52.27)
    dem = tmp_path / "dem.tif"
    with rasterio.open(dem, "w", driver="GTiff", width=200, height=200, count=1, dtype="float32",
                       crs="EPSG:32632", transform=Affine(10.0, 0, x0 - 1000.0, 0, -10.0, y0 + 1000.0)) as ds:
        ds.write(np.full((200, 200), 100.0, dtype=np.float32), 1)
    csv = write_csv(tmp_path / "flight.csv", flyover())
    out = tmp_path / "map"
    r = run("contour", csv, "--card", card_path, "--out", str(out), "--resolution", "20", "--margin", "100",
            "--dem", str(dem), "--metrics", "LAmax")
    assert r.exit_code == 0, r.output
    flat = tmp_path / "flat"
    r = run("contour", csv, "--card", card_path, "--out", str(flat), "--resolution", "20", "--margin", "100",
            "--ground-height", "100", "--metrics", "LAmax")
    assert r.exit_code == 0, r.output
    with rasterio.open(out / "levels.tif") as a, rasterio.open(flat / "levels.tif") as b:
        assert a.descriptions == ("LAmax",)
        on_dem, on_flat = a.read(1), b.read(1)
        rows, cols = np.mgrid[0:a.height, 0:a.width]
        x, y = rasterio.transform.xy(a.transform, rows.ravel(), cols.ravel(), offset="center")
        lon, lat = Transformer.from_crs(a.crs.to_wkt(), "EPSG:4326", always_xy=True).transform(x, y)
    # a constant DEM is flat ground at its height
    np.testing.assert_allclose(on_dem, on_flat, atol=1e-4)
    # receivers 1.5 m above the 100 m DEM, the straight track at 80 + 60 m: spherical spreading from the
    # closest approach r (inside the track for |e| < 150 m).  LAmax is the maximum over the samples,
    # 10 m apart along the track: the nearest one is at most 5 m from the closest point, so
    # L(sqrt(r^2 + 5^2)) <= LAmax <= L(r); a receiver 20 m too low or high would leave this band
    e, n, u = FRAME.to_enu(np.asarray(lat), np.asarray(lon), np.full(len(lat), 100.0 + 1.5))
    inside = np.abs(e) < 150.0
    r2 = n[inside] ** 2 + (60.0 - u[inside]) ** 2
    got = on_dem.ravel()[inside]
    assert np.all(got <= G0 - 10 * np.log10(r2 / 40.0 ** 2) + 1e-4)  # float32 band
    assert np.all(got >= G0 - 10 * np.log10((r2 + 5.0 ** 2) / 40.0 ** 2) - 1e-4)



def test_a_track_below_the_dem_is_named_with_its_depth(tmp_path, card_path):
    # the straight track at 140 m crosses a 400 m wide plateau at 170 m on a 100 m plain: its samples over the
    # plateau fly 30 m inside the terrain (a route's legs are straight between its waypoints' heights above
    # ground).  The map says so with the depth, the times and where; over the plain alone it says nothing
    from affine import Affine
    from pyproj import Transformer

    x0, y0 = Transformer.from_crs("EPSG:4326", "EPSG:32632", always_xy=True).transform(10.52, 52.27)
    z = np.full((200, 200), 100.0, dtype=np.float32)
    xc = x0 - 1000.0 + 10.0 * (np.arange(200) + 0.5)
    for name, top in (("plain", 100.0), ("plateau", 170.0)):
        z[:, np.abs(xc - x0) < 200.0] = top
        dem = tmp_path / f"{name}.tif"
        with rasterio.open(dem, "w", driver="GTiff", width=200, height=200, count=1, dtype="float32",
                           crs="EPSG:32632", transform=Affine(10.0, 0, x0 - 1000.0, 0, -10.0, y0 + 1000.0)) as ds:
            ds.write(z, 1)
        csv = write_csv(tmp_path / "flight.csv", flyover())
        r = run("contour", csv, "--card", card_path, "--out", str(tmp_path / name), "--resolution", "20",
                "--margin", "100", "--dem", str(dem), "--metrics", "LAmax")
        assert r.exit_code == 0, r.output
        said = [w for w in r.output.splitlines() if "below the DEM's ground" in w]
        if top == 100.0:
            assert not said, said
        else:
            assert len(said) == 1 and "up to 30.0 m" in said[0] and "--dem-offset" in said[0], said


def test_receivers_beyond_the_dem_are_a_map_warning_said_once(tmp_path, card_path):
    """A grid reaching past the DEM: the count of receivers without ground is a map warning (metadata, GeoJSON,
    one stderr line), not a log line."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from affine import Affine

    from gisnoise.maps import grid_for_trajectory, make_map

    traj = flyover()
    grid = grid_for_trajectory(traj, 20.0, 100.0)  # the grid `contour --resolution 20 --margin 100` makes
    t = grid.transform
    keep = grid.width // 2  # the DEM covers the western columns 0..keep-1 and 5 cells beyond the other sides
    dem = tmp_path / "dem.tif"
    with rasterio.open(dem, "w", driver="GTiff", width=keep + 5, height=grid.height + 10, count=1,
                       dtype="float32", crs=grid.crs.to_wkt(),
                       transform=Affine(t.a, 0, t.c - 5 * t.a, 0, t.e, t.f - 5 * t.e)) as ds:
        ds.write(np.full((grid.height + 10, keep + 5), 100.0, dtype=np.float32), 1)
    missing = (grid.width - keep) * grid.height
    expected = (f"dem: {missing} of {grid.width * grid.height} receivers lie outside the DEM or on its nodata; "
                f"they get nodata (no level) on the map")

    paths = make_map(str(write_csv(tmp_path / "flight.csv", traj)), [card_path], tmp_path / "lib",
                     resolution_m=20.0, margin_m=100.0, dem=str(dem), metrics=("LAmax",), levels=(55.0, 60.0))
    res = paths["result"]
    assert res.grid.shape == grid.shape and res.metadata["dem_nodata_receivers"] == missing
    assert int(np.isnan(res.bands["LAmax"]).sum()) == missing  # the cells the warning counts are the nodata ones
    assert res.metadata["warnings"].count(expected) == 1 and paths["warnings"].count(expected) == 1
    doc = json.loads((tmp_path / "lib" / "contours.geojson").read_text())
    assert doc["gisnoise"]["warnings"].count(expected) == 1

    out = tmp_path / "cli"
    r = subprocess.run([sys.executable, "-m", "gisnoise.cli.main", "contour", str(tmp_path / "flight.csv"), "--card",
                        card_path, "--out", str(out), "--resolution", "20", "--margin", "100", "--dem", str(dem),
                        "--metrics", "LAmax", "--levels", "55,60"], capture_output=True, text=True, timeout=600,
                       env=dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1])))
    assert r.returncode == 0, r.stderr
    assert r.stderr.count("outside the DEM") == 1, r.stderr
    assert f"warning: {expected}" in r.stderr.splitlines()
    assert json.loads((out / "contours.geojson").read_text())["gisnoise"]["warnings"].count(expected) == 1


def test_contours_cut_where_the_dem_ends_are_clipped(tmp_path, card_path):
    """A DEM covering the western half of the grid: the track (38.5 m above the receivers, 70.3 dB(A) under it)
    crosses where the levels end, so the LAmax 65 and 68 contours stop there, cut as by the grid's edge: they
    carry "clipped": true and a clip warning says so.  The grid's own edge stays below 65 dB(A) (100 m beside the
    track: 70 - 20 lg(sqrt(100^2 + 38.5^2) / 40) = 61.4), so over a DEM that covers the grid nothing is clipped."""
    from affine import Affine

    from gisnoise.maps import grid_for_trajectory, make_map

    traj = flyover()
    csv = write_csv(tmp_path / "flight.csv", traj)
    grid = grid_for_trajectory(traj, 20.0, 100.0)
    t = grid.transform
    flags = {}
    for name, cols in (("half", grid.width // 2), ("whole", grid.width)):
        dem = tmp_path / f"{name}.tif"
        with rasterio.open(dem, "w", driver="GTiff", width=cols + 5, height=grid.height + 10, count=1,
                           dtype="float32", crs=grid.crs.to_wkt(),
                           transform=Affine(t.a, 0, t.c - 5 * t.a, 0, t.e, t.f - 5 * t.e)) as ds:
            ds.write(np.full((grid.height + 10, cols + 5), 100.0, dtype=np.float32), 1)
        paths = make_map(csv, [card_path], tmp_path / name, resolution_m=20.0, margin_m=100.0, dem=str(dem),
                         metrics=("LAmax",), levels=(65.0, 68.0))
        doc = json.loads(paths["contours"].read_text())
        flags[name] = {(f["properties"]["kind"], f["properties"]["level"]): f["properties"]["clipped"]
                       for f in doc["features"]}
        clip = [w for w in paths["warnings"] if "contours are clipped" in w]
        assert clip == [w for w in doc["gisnoise"]["warnings"] if "contours are clipped" in w]
        if name == "half":
            assert len(clip) == 1 and clip[0].startswith("LAmax 65, 68 dB(A) contours are clipped: the cells next "
                                                         "to cells without a level"), clip
            assert "grid's edge" not in clip[0]
        else:
            assert clip == []
    assert set(flags["half"]) == set(flags["whole"]) == {("isoband", 65.0), ("isoband", 68.0), ("isoline", 65.0),
                                                          ("isoline", 68.0)}
    assert all(flags["half"].values()) and not any(flags["whole"].values())


def test_fast_engine_map_equals_the_reference_within_0_01_db(tmp_path):
    """`gisnoise contour --engine fast` writes the same LAmax/LAeq/SEL as the NumPy reference (issue 9: 0.01 dB)."""
    root = __import__("pathlib").Path(__file__).resolve().parents[1]
    route = root / "gisnoise/data/routes/delivery_route.geojson"
    cards = [str(root / f"gisnoise/data/cards/demo_{p}.json") for p in ("horizontal", "climb", "sink")]
    bands = {}
    for engine in ("numpy", "fast"):
        args = ["-q", "contour", str(route), "--out", str(tmp_path / engine), "--resolution", "40",
                "--margin", "300", "--engine", engine]
        for c in cards:
            args += ["--card", c]
        res = CliRunner().invoke(cli, args)
        assert res.exit_code == 0, res.output
        with rasterio.open(tmp_path / engine / "levels.tif") as ds:
            bands[engine] = {d: ds.read(i + 1) for i, d in enumerate(ds.descriptions)}
    assert set(bands["fast"]) == set(bands["numpy"]) == {"LAmax", "LAeq", "SEL"}
    for name in ("LAmax", "LAeq", "SEL"):
        np.testing.assert_allclose(bands["fast"][name], bands["numpy"][name], atol=0.01)


def test_product_files_of_an_earlier_run_are_named_and_kept(tmp_path, card_path):
    """A reused --out folder: the map.png and exposure.json/.md an earlier run left there describe that run; the
    warning names exactly the product files this run does not write, and keeps them byte for byte."""
    from gisnoise.maps import make_map

    csv = write_csv(tmp_path / "flight.csv", flyover())
    out = tmp_path / "map"
    out.mkdir()
    earlier = {"map.png": b"old png", "exposure.json": b"{}", "exposure.md": b"# old", "levels.tif": b"old",
               "notes.txt": b"mine"}
    for name, data in earlier.items():
        (out / name).write_bytes(data)
    kw = dict(resolution_m=40.0, margin_m=100.0, ground_h=80.0, metrics=("LAmax",), levels=(60.0,))
    paths = make_map(csv, [card_path], out, **kw)
    stale = [w for w in paths["warnings"] if w.startswith("out:")]
    assert stale == [f"out: {out} holds map.png, exposure.json, exposure.md from an earlier run: they describe "
                     "that run, not this map (kept; remove them or use a new folder)"]
    assert all((out / n).read_bytes() == d for n, d in earlier.items() if n != "levels.tif")
    # the exposure the command line writes after the map is not stale; contours only leaves levels.tif stale
    paths = make_map(csv, [card_path], out, outputs=("contours",), also_written=("exposure.json", "exposure.md"),
                     **kw)
    assert [w for w in paths["warnings"] if w.startswith("out:")] == [
        f"out: {out} holds levels.tif, map.png from an earlier run: they describe that run, not this map (kept; "
        "remove them or use a new folder)"]
    r = run("contour", csv, "--card", card_path, "--out", str(tmp_path / "fresh"), "--resolution", "40",
            "--margin", "100", "--ground-height", "80", "--metrics", "LAmax")
    assert r.exit_code == 0 and "earlier run" not in r.output


def test_an_output_folder_that_cannot_be_made_is_named(tmp_path, card_path):
    """--out under a plain file cannot be a folder: the error names field out and the folder (it was "cannot read
    the input (FileNotFoundError ...)"), for the map and for its exposure."""
    csv = write_csv(tmp_path / "flight.csv", flyover())
    (tmp_path / "afile").write_text("not a folder")
    bad = tmp_path / "afile" / "map"
    r = run("contour", csv, "--card", card_path, "--out", str(bad), "--resolution", "40", "--margin", "100",
            "--ground-height", "80", "--metrics", "LAmax")
    one_line_error(r, "out")
    line = r.stderr.strip()
    assert line.startswith(f"Error: out: cannot create the output folder {bad}"), line
    assert "cannot read the input" not in line
    from gisnoise.errors import InputError
    from gisnoise.exposure import write_exposure

    with pytest.raises(InputError, match="cannot create the output folder") as err:
        write_exposure({"area_above": {}}, bad)
    assert err.value.field == "out"


def test_plain_progress_prints_every_tenth_or_ten_seconds():
    """Off a terminal, progress is plain lines: one when the work passes a further 10 % at least 2 s after the last
    line, or when 10 s passed since the last line (a slow stretch between two tenths, or before the first report,
    still says it is alive); 100 % when a line came before; quick work prints none."""
    from gisnoise.cli.options import PlainProgress

    lines, now = [], [100.0]
    update = PlainProgress("evaluating", 1.0, echo=lines.append, clock=lambda: now[0])
    for t, done in ((100.5, 0.05), (101.0, 0.10), (101.5, 0.12), (111.0, 0.13), (111.5, 0.14), (112.0, 0.35),
                    (114.0, 0.5), (114.5, 1.0)):
        now[0] = t
        update(done)
    assert lines == ["evaluating: 13 % after 11 s", "evaluating: 50 % after 14 s", "evaluating: 100 % after 14 s"]
    lines.clear()
    now[0] = 125.0
    update.tick()  # the heartbeat: 10.5 s without a report
    now[0] = 125.5
    update.tick()
    assert lines == ["evaluating: 100 % after 25 s"]
    quick = PlainProgress("evaluating", 1.0, echo=lines.append, clock=lambda: now[0])
    for t, done in ((125.7, 0.3), (125.9, 0.7), (126.0, 1.0)):      # done within 2 s: no line
        now[0] = t
        quick(done)
    assert lines == ["evaluating: 100 % after 25 s"]
    lines.clear()
    update = PlainProgress("reading", None, echo=lines.append, clock=lambda: now[0])
    for t in (127.0, 130.0, 137.0, 138.0):                          # created at 126 s
        now[0] = t
        update.tick()
    assert lines == ["reading: running after 11 s"]


def test_the_grid_line_comes_before_the_evaluation_and_progress_is_plain_off_a_terminal(tmp_path, card_path,
                                                                                         monkeypatch):
    """Without a terminal on stderr (a log), the grid line (cells, instants, engine) is printed before the
    evaluation's first progress line, and progress lines reach 100 %; -q prints no progress, the grid line still.
    (Every tenth is printed here: this map takes well under the 2 s a further tenth waits for.)"""
    import gisnoise.cli.options as options

    monkeypatch.setattr(options, "PLAIN_MIN_GAP_S", 0.0)
    csv = write_csv(tmp_path / "flight.csv", flyover())
    args = ["contour", csv, "--card", card_path, "--resolution", "40", "--margin", "100", "--ground-height", "80",
            "--metrics", "LAmax", "--engine", "numpy"]
    r = CliRunner().invoke(cli, [*args, "--out", str(tmp_path / "a")], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    lines = r.output.splitlines()
    grid = [i for i, ln in enumerate(lines) if ln.startswith("grid:")]
    prog = [i for i, ln in enumerate(lines) if ln.startswith("evaluating: ")]
    assert len(grid) == 1 and prog and grid[0] < prog[0], r.output
    assert lines[grid[0]].endswith("; 41 instants; engine numpy")  # 41 samples, flying throughout
    assert r.stdout.splitlines()[0] == lines[grid[0]] and "evaluating" not in r.stdout
    assert r.stderr.splitlines()[-1 - len([w for w in r.stderr.splitlines() if w.startswith("warning:")])] \
        .startswith("evaluating: 100 % after ")
    q = run(*args, "--out", str(tmp_path / "b"))
    assert q.exit_code == 0 and "evaluating" not in q.output and q.stdout.startswith("grid: ")
