"""A population made from an array holds the rules of a population raster read from a file: the same counts give
the same population, the same exposure and the same refusals (gisnoise.exposure.population_cells)."""

import json

import numpy as np
import pytest
import rasterio
from affine import Affine
from pyproj import CRS

from gisnoise.errors import InputError
from gisnoise.exposure import LevelsRaster, Population, map_exposure, read_population
from gisnoise.geo import GridSpec

UTM = CRS.from_epsg(32632)
X0, Y0 = 600000.0, 5790000.0
CELL = 100.0  # population cells of 1 ha
T = Affine(CELL, 0, X0, 0, -CELL, Y0)
SHAPE = (12, 12)
EDGES = [50.0, 55.0, 60.0, 65.0]


def tif(path, values, nodata=None, transform=T):
    values = np.asarray(values, dtype=np.float64)
    with rasterio.open(path, "w", driver="GTiff", width=values.shape[1], height=values.shape[0], count=1,
                       dtype="float64", crs=UTM.to_wkt(), transform=transform, nodata=nodata) as dst:
        dst.write(values, 1)
    return path


def people():
    """Up to 80 people per hectare, a cell in seven empty."""
    k = np.arange(SHAPE[0] * SHAPE[1], dtype=float).reshape(SHAPE)
    return np.where(k % 7 == 0, 0.0, 10.0 + (k * 37.0) % 70.0)


def cone():
    """A map on 20 m cells under the population: 75 dB(A) at its centre, 1 dB less every 30 m."""
    grid = GridSpec(UTM, Affine(20.0, 0, X0 + 100.0, 0, -20.0, Y0 - 100.0), 50, 50)
    x, y = np.meshgrid(grid.xs, grid.ys)
    band = 75.0 - np.hypot(x - (X0 + 600.0), y - (Y0 - 600.0)) / 30.0
    return LevelsRaster({"LAmax": band}, grid, {"LAmax": "dB(A)"}, {})


def same(a, b):
    assert np.array_equal(a.counts, b.counts) and a.counts.dtype == b.counts.dtype == np.float64
    assert (a.covered is None) == (b.covered is None)
    if a.covered is not None:
        assert np.array_equal(a.covered, b.covered)
    assert a.total == b.total and a.warnings == b.warnings
    assert a.crs == b.crs and a.transform == b.transform


def exposure(pop):
    return json.dumps(map_exposure(cone(), population=pop, edges=EDGES), sort_keys=True, default=str)


@pytest.mark.parametrize("case", ["whole", "nodata", "nan nodata", "covered"])
def test_the_same_counts_from_a_file_and_an_array_give_the_same_population_and_exposure(tmp_path, case):
    """Cells without data are a raster's nodata value in a file and masked (or covered=False) in an array: either way
    they count nobody and are not covered, so the map's classes reaching them are lower bounds in both alike."""
    values = people()
    hole = np.zeros(SHAPE, dtype=bool)
    hole[3:6, 4:9] = True
    path = tmp_path / "people.tif"
    if case == "whole":
        from_file = read_population(tif(path, values))
        from_array = Population(values, T, UTM, source=str(path))
    elif case == "nodata":
        from_file = read_population(tif(path, np.where(hole, -9999.0, values), nodata=-9999.0))
        from_array = Population(np.ma.masked_array(values, mask=hole), T, "EPSG:32632", source=str(path))
    elif case == "nan nodata":
        with_nan = np.where(hole, np.nan, values)
        from_file = read_population(tif(path, with_nan, nodata=np.nan))
        from_array = Population(np.ma.masked_invalid(with_nan), T, UTM, source=str(path))
    else:
        from_file = read_population(tif(path, np.where(hole, -1.0, values), nodata=-1.0))
        from_array = Population(np.where(hole, np.nan, values), T, UTM, source=str(path), covered=~hole)
    same(from_file, from_array)
    if case != "whole":
        assert from_array.total == float(values[~hole].sum()) and not from_array.covered[hole].any()
    doc = exposure(from_array)
    assert doc == exposure(from_file)
    if case != "whole":
        assert json.loads(doc)["population"]["coverage"]["uncovered_share"]["LAmax"] > 0.0


@pytest.mark.parametrize(("bad", "shown"), [(np.nan, "nan"), (np.inf, "inf"), (-np.inf, "-inf"), (-2.0, "-2")])
def test_cells_that_are_not_counts_are_refused_alike(tmp_path, bad, shown):
    """A NaN, infinite or negative cell not marked as no data refuses the array as it refuses the file, in the same
    line: an array's NaN cells were dropped without a word (a hole counted as nobody), negative ones counted 0."""
    values = people()
    values[4, 7] = bad
    path = tif(tmp_path / "people.tif", values)
    with pytest.raises(InputError) as from_file:
        read_population(path)
    with pytest.raises(InputError) as from_array:
        Population(values, T, UTM, source=str(path))
    assert from_file.value.field == from_array.value.field == "population"
    assert str(from_file.value) == str(from_array.value)
    assert f"first {shown} at row 4, column 7" in str(from_array.value) and str(tmp_path) not in str(from_array.value)


def test_a_density_is_refused_alike_and_a_thin_one_said_alike(tmp_path):
    """20 000 people per km² given as people per 1 ha cell are 2 million per km², more than any city block: refused
    from the file and from the array in the same line; 4 000 per km² so given (400 000 per km²) is said in the same
    warning.  Before, the array gave tens of millions of people above a level on a few km² without a word."""
    for density, refused in ((20000.0, True), (4000.0, False)):
        values = np.full(SHAPE, density)
        path = tif(tmp_path / f"d{density:g}.tif", values)
        if refused:
            with pytest.raises(InputError) as from_file:
                read_population(path)
            with pytest.raises(InputError) as from_array:
                Population(values, T, UTM, source=str(path))
            assert str(from_file.value) == str(from_array.value) and "looks like a density" in str(from_array.value)
        else:
            from_array = Population(values, T, UTM, source=str(path))
            same(read_population(path), from_array)
            (said,) = from_array.warnings
            assert said.startswith(f"population: d{density:g}.tif holds up to ") and "give people per cell" in said


def test_a_window_of_a_raster_names_the_cell_as_the_file_holds_it(tmp_path):
    """read_population(within=grid) reads a window: a bad cell is named at its row and column in the file, by the
    same check an array gets (whose rows start at 0)."""
    values = np.ones((40, 40))
    values[25, 30] = -5.0
    path = tif(tmp_path / "big.tif", values)
    grid = GridSpec(UTM, Affine(20.0, 0, X0 + 2500.0, 0, -20.0, Y0 - 2000.0), 40, 40)
    with pytest.raises(InputError) as err:
        read_population(path, within=grid)
    assert "first -5 at row 25, column 30" in str(err.value)


@pytest.mark.parametrize(("kw", "said"), [
    (dict(counts=np.ones(5)), "2-D array"),
    (dict(counts=np.array([["a", "b"]])), "must be numbers"),
    (dict(crs=None), "has no CRS"),
    (dict(transform=(CELL, 0, X0, 0, -CELL, Y0)), "affine.Affine"),
    (dict(transform=Affine(CELL, 0, X0, 0, CELL, Y0 - 12 * CELL)), "north-up"),
    (dict(covered=np.ones((2, 2), dtype=bool)), "covered must be a boolean array"),
])
def test_an_array_that_is_no_north_up_population_raster_is_refused(kw, said):
    args = {"counts": people(), "transform": T, "crs": UTM, **kw}
    with pytest.raises(InputError) as err:
        Population(**args)
    assert err.value.field == "population" and said in str(err.value)


def test_a_density_on_small_cells_is_refused_as_a_block_a_tower_is_not(tmp_path):
    # 10 m cells (100 m², a hundred to the hectare).  3 000 people per km² given as people per cell puts 3 000 in
    # each: one cell judged over a hectare is 300 000 per km² (only a warning), but any hectare of them holds
    # 300 000 people, 30 million per km².  The same town as counts is 0.3 per cell; a 2 000-resident tower in one
    # cell of it makes a hectare of 2 030 people, 203 000 per km²: a dense block, no density
    t10 = Affine(10.0, 0, X0, 0, -10.0, Y0)
    density = np.full((40, 40), 3000.0)
    with pytest.raises(InputError, match=r"people in 10 x 10 cells .* looks like a density") as e:
        Population(density, t10, UTM)
    assert e.value.field == "population"
    with pytest.raises(InputError, match=r"people in 10 x 10 cells .* looks like a density"):
        read_population(tif(tmp_path / "density.tif", density, transform=t10))
    town = np.full((40, 40), 0.3)
    town[20, 20] = 2000.0
    assert Population(town, t10, UTM).counts.sum() == pytest.approx(0.3 * 1599 + 2000.0)
