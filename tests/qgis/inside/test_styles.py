"""Each isoband and isoline is drawn in the colour of its own class, as the grid is.

The bands of a map are the classes ``[L_i, L_i+1)``: the band with ``level = L_i`` covers
``L_i`` up to ``L_i+1``, and the palette (gisnoise.maps.palette, DIN 18005-2) gives that class
the colour of the 5 dB class holding ``L_i``.  QGIS's graduated ranges hold their upper bound,
so a range that ended at ``L_i+1`` drew the band of ``L_i+1`` one class too low.  The symbol and
legend entry QGIS picks for each feature are checked here, for styles saved beside the files
(GeoPackage, shapefile: opened by anyone) and for the post-processor of layers loaded after a run.
"""

import math

import pytest
from conftest import CARDS, REPO

pytestmark = pytest.mark.qgis

ROUTE = REPO / "gisnoise" / "data" / "routes" / "delivery_route.geojson"
DEMO = [str(CARDS / f"demo_{p}.json") for p in ("horizontal", "climb", "sink")]
LEVELS = [45.0, 50.0, 55.0, 60.0, 65.0]
OPTIONS = {"TRAJECTORY_FILE": str(ROUTE), "CARDS": DEMO, "RESOLUTION": 20.0, "MARGIN": 500.0,
           "LEVELS": ",".join(f"{v:g}" for v in LEVELS)}


def _expected(level, polygons):
    """(colour, legend label) of the class that starts at ``level``, from the palette's definition."""
    from gisnoise.maps import palette

    i = LEVELS.index(level)
    label = palette.class_labels(LEVELS, "LAmax")[i] if polygons else f"LAmax {level:g} dB(A)"
    return palette.colour_for(level).upper(), label


def _drawn(layer):
    """Per feature: (level, colour of the symbol QGIS picks, label of the legend entry it falls in)."""
    from qgis.core import QgsRenderContext

    renderer = layer.renderer()
    labels = {item.ruleKey(): item.label() for item in renderer.legendSymbolItems()}
    ctx = QgsRenderContext()
    renderer.startRender(ctx, layer.fields())
    out = []
    try:
        for f in layer.getFeatures():
            symbol = renderer.symbolForFeature(f, ctx)
            keys = renderer.legendKeysForFeature(f, ctx)
            assert symbol is not None and len(keys) == 1, f"level {f['level']}: no class"
            out.append((float(f["level"]), symbol.color().name().upper(), labels[next(iter(keys))]))
    finally:
        renderer.stopRender(ctx)
    return out


def _check(layer, polygons):
    assert layer.isValid() and layer.renderer().type() == "graduatedSymbol"
    drawn = _drawn(layer)
    assert {lv for lv, _, _ in drawn} == set(LEVELS)  # the flight reaches every class: each one is checked
    for level, colour, label in drawn:
        assert (colour, label) == _expected(level, polygons), f"level {level:g}"


def test_saved_styles_draw_each_band_and_isoline_in_its_class(plugin, tmp_path):
    """Styles saved into the GeoPackage and beside the shapefile, read by a layer opened from the file."""
    import processing
    from qgis.core import QgsRasterLayer, QgsVectorLayer

    res = processing.run("gisnoise:noisemap", {
        **OPTIONS, "OUTPUT_RASTER": str(tmp_path / "grid.tif"), "OUTPUT_BANDS": str(tmp_path / "bands.gpkg"),
        "OUTPUT_LINES": str(tmp_path / "lines.shp")})
    _check(QgsVectorLayer(res["OUTPUT_BANDS"], "bands", "ogr"), polygons=True)
    _check(QgsVectorLayer(res["OUTPUT_LINES"], "lines", "ogr"), polygons=False)
    # the grid in the same classes: a cell at exactly a level, or just below the next, takes that level's class
    raster = QgsRasterLayer(res["OUTPUT_RASTER"], "grid", "gdal")
    shader = raster.renderer().shader().rasterShaderFunction()
    items = shader.colorRampItemList()
    for i, level in enumerate(LEVELS):
        colour, label = _expected(level, polygons=True)
        top = LEVELS[i + 1] if i + 1 < len(LEVELS) else 120.0
        for value in (level, (level + top) / 2, math.nextafter(top, -math.inf)):
            ok, r, g, b, alpha = shader.shade(value)
            assert ok and alpha == 255 and f"#{r:02X}{g:02X}{b:02X}" == colour, (level, value)
        assert items[i + 1].label == label
    ok, *_, alpha = shader.shade(math.nextafter(LEVELS[0], -math.inf))
    assert ok and alpha == 0  # below the lowest level: no class


def test_loaded_outputs_draw_each_band_and_isoline_in_its_class(plugin, tmp_path):
    """The post-processor styles the layers a run loads (here a shapefile of bands and a GeoPackage of lines)."""
    import processing
    from qgis.core import QgsProject

    res = processing.runAndLoadResults("gisnoise:noisemap", {
        **OPTIONS, "OUTPUT_RASTER": str(tmp_path / "grid.tif"), "OUTPUT_BANDS": str(tmp_path / "bands.shp"),
        "OUTPUT_LINES": str(tmp_path / "lines.gpkg"), "OUTPUT_TRACK": "TEMPORARY_OUTPUT"})
    project = QgsProject.instance()
    try:
        loaded = {}
        for key in ("OUTPUT_BANDS", "OUTPUT_LINES"):
            found = [lyr for lyr in project.mapLayers().values() if lyr.source().split("|")[0] == res[key]]
            assert len(found) == 1, key
            loaded[key] = found[0]
        _check(loaded["OUTPUT_BANDS"], polygons=True)
        _check(loaded["OUTPUT_LINES"], polygons=False)
    finally:
        project.removeAllMapLayers()
