"""Route planners: scoring one candidate route against drawing its full map, and one route optimization.

Prints, measured in the same run on the same route and grid:

1. the full map of a 10 km delivery route over a 10 km x 10 km area at 20 m cells
   (the map pipeline's steps: NumPy reference engine, LAmax, LAeq and SEL, GeoTIFF and contours) -- the baseline;
2. scoring the same route for a planner (``score_route``: LAmax on the fast engine, people above
   each level, person-dB and area above each level from a population raster) -- wall time and
   the ratio to the baseline;
3. the agreement of the two: people above 55 dB(A) from the scorer and from the baseline's LAmax band;
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

import numpy as np
import rasterio
from affine import Affine
from pyproj import CRS

from gisnoise.exposure import LevelsRaster, population_exposure, read_population
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


def main() -> None:
    quick = "--quick" in sys.argv
    half = 2000.0 if quick else 5000.0
    print(f"load average before: {os.getloadavg()}")
    cards = CardSet([CARDS / f"demo_{p}.json" for p in ("horizontal", "climb", "sink")])
    doc = route(half * 0.8)
    traj = read_route(doc).trajectory
    grid = GridSpec(TMERC, Affine(20.0, 0, -half, 0, -20.0, half), int(2 * half / 20), int(2 * half / 20))
    with tempfile.TemporaryDirectory() as tmp:
        pop = read_population(population(Path(tmp) / "pop.tif", half))
        print(f"route: {len(traj)} samples, {traj.duration_s:.0f} s; grid {grid.width} x {grid.height} "
              f"= {grid.n_cells} cells of 20 m; population {pop.total:.0f} people")
        # warm the numba kernel (compilation is not scoring)
        score_route(traj, cards, GridSpec(TMERC, Affine(20.0, 0, -100, 0, -20.0, 100), 10, 10), population=pop,
                    engine="fast")
        t0 = time.perf_counter()
        c0 = time.process_time()
        res = evaluate_grid(traj, cards, grid, ground_h=0.0)  # the map pipeline's steps on this grid
        write_geotiff(res, Path(tmp) / "levels.tif")
        write_geojson(res, Path(tmp) / "contours.geojson", [45.0, 50.0, 55.0, 60.0])
        full = {"result": res}
        base_wall, base_cpu = time.perf_counter() - t0, time.process_time() - c0
        print(f"full map (numpy engine, 3 metrics, GeoTIFF, contours): {base_wall:.2f} s wall, {base_cpu:.2f} s CPU "
              f"on {full['result'].grid.n_cells} cells")
        t0 = time.perf_counter()
        c0 = time.process_time()
        row, band = score_route(traj, cards, full["result"].grid, population=pop, engine="fast")
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        print(f"score one candidate (fast engine, LAmax, exposure): {wall:.2f} s wall, {cpu:.2f} s CPU; "
              f"ratio to the full map {wall / base_wall:.3f} (wall), {cpu / base_cpu:.3f} (CPU)")
        ref = population_exposure(LevelsRaster({"LAmax": full["result"].bands["LAmax"]}, full["result"].grid,
                                               {"LAmax": "dB(A)"}, {}), pop, edges=[45.0, 50.0, 55.0, 60.0, 65.0])
        ref55 = ref["metrics"]["LAmax"]["above"][2]["people"]
        print(f"people above 55 dB(A) LAmax: scorer {row['people_above']['55']:.1f}, full map {ref55:.1f}; "
              f"largest LAmax difference {np.nanmax(np.abs(band - full['result'].bands['LAmax'])):.4f} dB")
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from test_route_optimize import omni, pad, town

    with tempfile.TemporaryDirectory() as tmp:
        pop = read_population(town(Path(tmp) / "town.tif"))
        t0 = time.perf_counter()
        out = optimize_route(pad(-1500.0), pad(1500.0), [omni()], population=pop, max_detour_pct=25.0,
                             resolution_m=40.0)
        print(f"optimize the synthetic town (3 km, 25 % detour): {time.perf_counter() - t0:.2f} s wall; "
              f"people above 55 dB(A): direct {out.summary['people_above_55_direct']:.0f}, "
              f"optimized {out.summary['people_above_55_optimized']:.0f} "
              f"({out.summary['reduction_pct']:.1f} % fewer), detour {out.summary['detour_pct']:.1f} %")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
