"""Route planners: scoring one candidate route against drawing its full map, and one route optimization.

Prints, measured in the same run on the same route and grid:

1. the full map of a 10 km delivery route over a 10 km x 10 km area at 20 m cells, the
   map pipeline's steps (LAmax, LAeq and SEL, GeoTIFF, contours), on the engine ``gisnoise
   contour`` picks for these cards (fast) and on the NumPy reference engine -- the baselines;
2. scoring the same route for a planner (``score_route``: LAmax on the fast engine in one
   kernel call, people above each level, person-dB and area above each level from a
   population raster, the population's sub-cells on the grid included) -- wall and CPU time,
   best of three, and the ratios to the baselines;
3. the agreement of the two: people above each level from the scorer and from the whole
   fast map's LAmax band through ``population_exposure``;
4. ``optimize_route`` on the synthetic town of ``tests/test_route_optimize.py``, wall time.

    python bench/bench_planning.py [--quick]

``--quick`` uses a 4 km x 4 km area.  The load average is printed before and after.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import rasterio
from affine import Affine
from pyproj import CRS

from gisnoise.exposure import LevelsRaster, population_exposure, population_points, read_population
from gisnoise.flight import read_route
from gisnoise.geo import GridSpec, LocalFrame
from gisnoise.maps import CardSet, evaluate_grid, write_geojson, write_geotiff
from gisnoise.planning import optimize_route, score_route

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)
CARDS = Path(__file__).resolve().parent.parent / "gisnoise" / "data" / "cards"


def route(half: float) -> dict:
    pts = [(-half, -half * 0.3, 0), (-half, -half * 0.3, 60), (0.0, half * 0.2, 80), (half, -half * 0.2, 60),
           (half, -half * 0.2, 0)]
    wps = []
    for e, n, alt in pts:
        lat, lon, _ = FRAME.to_wgs84(e, n, 0.0)
        wps.append({"lon": float(lon), "lat": float(lat), "alt": float(alt)})
    return {"schema": "gisnoise/waypoints/1", "altitude_reference": "agl", "ground_h_m": 0.0, "sample_dt_s": 1.0,
            "waypoints": wps}


def population(path: Path, half: float) -> Path:
    rng = np.random.default_rng(0)
    n = int(2 * half / 100)
    people = rng.gamma(0.5, 40.0, (n, n)).astype(np.float32)  # 100 m cells, about 20 people each
    with rasterio.open(path, "w", driver="GTiff", width=n, height=n, count=1, dtype="float32",
                       crs=CRS.from_epsg(32632).to_wkt(), transform=_utm_transform(half)) as d:
        d.write(people, 1)
    return path


def _utm_transform(half: float) -> Affine:
    from gisnoise.geo import WGS84, transformer

    x0, y0 = transformer(WGS84, CRS.from_epsg(32632)).transform(LON0, LAT0)
    return Affine(100.0, 0, x0 - half, 0, -100.0, y0 + half)


def optimize_sample() -> str:
    """``optimize_route`` between the pads of the bundled sample route with its cards (the defaults of
    ``gisnoise route optimize``) over a population raster in ETRS89 / UTM 32N (EPSG:25832): a suburban
    background of about 20 people per hectare and a dense block (200 per hectare) on the direct line."""
    import json

    from gisnoise.data import sample_route_path  # the bundled route

    feats = json.loads(Path(sample_route_path()).read_text())["features"]
    (lon0, lat0), (lon1, lat1) = feats[0]["geometry"]["coordinates"][:2], feats[-1]["geometry"]["coordinates"][:2]
    from gisnoise.geo import WGS84, transformer

    crs = CRS.from_epsg(25832)
    tr = transformer(WGS84, crs)
    (x0, x1), (y0, y1) = tr.transform([lon0, lon1], [lat0, lat1])
    xmin, ymax = min(x0, x1) - 3000.0, max(y0, y1) + 3000.0
    n_e, n_n = int((abs(x1 - x0) + 6000) / 100), int((abs(y1 - y0) + 6000) / 100)
    rng = np.random.default_rng(1)
    people = rng.gamma(0.5, 40.0, (n_n, n_e))
    xc = xmin + 100.0 * (np.arange(n_e) + 0.5)
    yc = ymax - 100.0 * (np.arange(n_n) + 0.5)
    xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    block = (np.abs(xc[None, :] - xm) < 400.0) & (np.abs(yc[:, None] - ym) < 400.0)
    people[block] = 200.0
    with tempfile.TemporaryDirectory() as tmpname:
        path = Path(tmpname) / "pop.tif"
        with rasterio.open(path, "w", driver="GTiff", width=n_e, height=n_n, count=1, dtype="float32",
                           crs=crs.to_wkt(), transform=Affine(100.0, 0, xmin, 0, -100.0, ymax)) as d:
            d.write(people.astype(np.float32), 1)
        pop = read_population(path)
    out = optimize_route((lon0, lat0), (lon1, lat1), [CARDS / f"demo_{p}.json" for p in ("horizontal", "climb", "sink")],
                         population=pop)
    sm = out.summary
    return (f"direct {sm['direct_length_m']:.0f} m, optimized {sm['optimized_length_m']:.0f} m "
            f"(+{sm['detour_pct']:.1f} %); people above 55 dB(A): direct {sm['people_above_55_direct']:.0f}, "
            f"optimized {sm['people_above_55_optimized']:.0f} ({sm['reduction_pct']:.1f} % fewer)")


def full_map(traj, cards, grid, tmp: Path, engine: str) -> tuple[Any, float, float]:
    t0, c0 = time.perf_counter(), time.process_time()
    res = evaluate_grid(traj, cards, grid, ground_h=0.0, engine=engine)  # the map pipeline's steps on this grid
    write_geotiff(res, tmp / f"levels-{engine}.tif")
    write_geojson(res, tmp / f"contours-{engine}.geojson", [45.0, 50.0, 55.0, 60.0])
    return res, time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    quick = "--quick" in sys.argv
    half = 2000.0 if quick else 5000.0
    print(f"load average before: {os.getloadavg()}; {os.cpu_count()} CPUs")
    cards = CardSet([CARDS / f"demo_{p}.json" for p in ("horizontal", "climb", "sink")])
    doc = route(half * 0.8)
    traj = read_route(doc).trajectory
    grid = GridSpec(TMERC, Affine(20.0, 0, -half, 0, -20.0, half), int(2 * half / 20), int(2 * half / 20))
    edges = [45.0, 50.0, 55.0, 60.0, 65.0]
    with tempfile.TemporaryDirectory() as tmpname:
        tmp = Path(tmpname)
        pop = read_population(population(tmp / "pop.tif", half))
        print(f"route: {len(traj)} samples, {traj.duration_s:.0f} s; grid {grid.width} x {grid.height} "
              f"= {grid.n_cells} cells of 20 m; population {pop.total:.0f} people on 100 m cells")
        # warm the numba kernel (compilation is not scoring)
        score_route(traj, cards, GridSpec(TMERC, Affine(20.0, 0, -100, 0, -20.0, 100), 10, 10), population=pop,
                    engine="fast")
        fast, fast_wall, fast_cpu = full_map(traj, cards, grid, tmp, "fast")
        print(f"full map, fast engine (3 metrics, GeoTIFF, contours): {fast_wall:.2f} s wall, {fast_cpu:.2f} s CPU")
        ref, ref_wall, ref_cpu = full_map(traj, cards, grid, tmp, "numpy")
        print(f"full map, numpy engine (3 metrics, GeoTIFF, contours): {ref_wall:.2f} s wall, {ref_cpu:.2f} s CPU")
        runs = []
        for _ in range(3):
            t0, c0 = time.perf_counter(), time.process_time()
            row, band = score_route(traj, cards, grid, population=pop, levels=edges, engine="fast")
            runs.append((time.perf_counter() - t0, time.process_time() - c0))
            print(f"  score: {runs[-1][0]:.3f} s wall, {runs[-1][1]:.3f} s CPU; load {os.getloadavg()[0]:.2f}")
        wall, cpu = min(runs)
        # a planner scores many candidates on one grid: the population's sub-cells on it once, then each route
        t0, c0 = time.perf_counter(), time.process_time()
        pts = population_points(pop, grid)
        print(f"  the population's sub-cells on the grid (once per grid, {pts[0].size} sub-cells): "
              f"{time.perf_counter() - t0:.3f} s wall, {time.process_time() - c0:.3f} s CPU")
        again = []
        for _ in range(3):
            t0, c0 = time.perf_counter(), time.process_time()
            row2, _ = score_route(traj, cards, grid, population=pop, levels=edges, engine="fast", points=pts)
            again.append((time.perf_counter() - t0, time.process_time() - c0))
        assert row2["people_above"] == row["people_above"]
        print(f"score one more candidate on the same grid, best of 3: {min(again)[0]:.3f} s wall, "
              f"{min(again)[1]:.3f} s CPU")
        kern = []
        for _ in range(3):  # of which the evaluator call alone (LAmax, fast engine)
            t0, c0 = time.perf_counter(), time.process_time()
            evaluate_grid(traj, cards, grid, metrics=("LAmax",), ground_h=0.0, engine="fast")
            kern.append((time.perf_counter() - t0, time.process_time() - c0))
        print(f"  of which the evaluator (LAmax, fast engine), best of 3: {min(kern)[0]:.3f} s wall, "
              f"{min(kern)[1]:.3f} s CPU")
        print(f"score one candidate (fast engine, LAmax, exposure), best of 3: {wall:.2f} s wall, {cpu:.2f} s CPU; "
              f"ratio to the fast full map {wall / fast_wall:.3f} (wall), {cpu / fast_cpu:.3f} (CPU); "
              f"to the numpy full map {wall / ref_wall:.3f} (wall), {cpu / ref_cpu:.3f} (CPU)")
        full = population_exposure(LevelsRaster({"LAmax": fast.bands["LAmax"]}, grid, {"LAmax": "dB(A)"}, {}), pop,
                                   edges=edges)["metrics"]["LAmax"]["above"]
        for a in full:
            key = f"{a['level_db']:g}"
            print(f"people above {key} dB(A) LAmax: scorer {row['people_above'][key]:.2f}, full map {a['people']:.2f}")
        print(f"largest LAmax difference scorer - fast full map {np.nanmax(np.abs(band - fast.bands['LAmax'])):.4f} dB,"
              f" - numpy full map {np.nanmax(np.abs(band - ref.bands['LAmax'])):.4f} dB")
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from test_route_optimize import omni, pad, town

    with tempfile.TemporaryDirectory() as tmpname:
        pop = read_population(town(Path(tmpname) / "town.tif"))
        t0 = time.perf_counter()
        out = optimize_route(pad(-1500.0), pad(1500.0), [omni()], population=pop, max_detour_pct=25.0,
                             resolution_m=40.0)
        print(f"optimize the synthetic town (3 km, 25 % detour): {time.perf_counter() - t0:.2f} s wall; "
              f"people above 55 dB(A): direct {out.summary['people_above_55_direct']:.0f}, "
              f"optimized {out.summary['people_above_55_optimized']:.0f} "
              f"({out.summary['reduction_pct']:.1f} % fewer), detour {out.summary['detour_pct']:.1f} %")
        t0 = time.perf_counter()
        sample = optimize_sample()
        print(f"optimize the sample case (gisnoise route optimize on the bundled route's pads, its cards, a "
              f"population raster around it): {time.perf_counter() - t0:.2f} s wall; {sample}")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
