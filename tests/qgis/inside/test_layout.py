"""A print layout with the styled outputs: the legend shows the noise classes (no black box) and levels."""

import pytest
from conftest import MAP_OPTIONS, run_map

pytestmark = pytest.mark.qgis

LEVELS = [float(v) for v in MAP_OPTIONS["LEVELS"].split(",")]


@pytest.fixture(scope="module")
def layout_image(plugin, flight_csv, tmp_path_factory):
    """The map's files loaded from disk into a fresh project, a layout of a map and a legend, rendered."""
    from qgis.core import (
        QgsLayoutExporter,
        QgsLayoutItemLegend,
        QgsLayoutItemMap,
        QgsLayoutPoint,
        QgsLayoutSize,
        QgsPrintLayout,
        QgsProject,
        QgsRasterLayer,
        QgsUnitTypes,
        QgsVectorLayer,
    )

    tmp = tmp_path_factory.mktemp("layout")
    run_map(tmp, "map", TRAJECTORY_FILE=str(flight_csv), OUTPUT_LINES=str(tmp / "map" / "lines.gpkg"),
            OUTPUT_TRACK=str(tmp / "map" / "track.gpkg"))
    project = QgsProject.instance()
    project.clear()
    layers = [QgsRasterLayer(str(tmp / "map" / "grid.tif"), "noise grid", "gdal"),
              QgsVectorLayer(str(tmp / "map" / "lines.gpkg"), "isolines", "ogr")]
    for lyr in layers:
        assert lyr.isValid()
        project.addMapLayer(lyr)
    layout = QgsPrintLayout(project)
    layout.initializeDefaults()
    page = layout.pageCollection().page(0)
    page.setPageSize(QgsLayoutSize(120, 190, QgsUnitTypes.LayoutMillimeters))
    map_item = QgsLayoutItemMap(layout)
    map_item.attemptMove(QgsLayoutPoint(5, 5, QgsUnitTypes.LayoutMillimeters))
    map_item.attemptResize(QgsLayoutSize(110, 40, QgsUnitTypes.LayoutMillimeters))
    map_item.setLayers(layers)
    map_item.setExtent(layers[0].extent())
    layout.addLayoutItem(map_item)
    legend = QgsLayoutItemLegend(layout)
    legend.setLinkedMap(map_item)
    legend.setAutoUpdateModel(True)
    legend.attemptMove(QgsLayoutPoint(5, 50, QgsUnitTypes.LayoutMillimeters))
    layout.addLayoutItem(legend)
    legend.adjustBoxSize()
    image = QgsLayoutExporter(layout).renderPageToImage(0, dpi=150)
    image.save(str(tmp / "layout.png"))
    yield legend, image, tmp / "layout.png"
    project.clear()


def test_legend_items_name_the_classes_and_levels(layout_image):
    from qgis.core import QgsLayerTreeLayer

    legend, _image, _png = layout_image
    model = legend.model()
    labels = {}
    for node in model.rootGroup().findLayers():
        assert isinstance(node, QgsLayerTreeLayer)
        labels[node.layer().name()] = [n.data(0) for n in model.layerLegendNodes(node)]
    cls = [f"LAmax {a:g}-{b:g} dB(A)" for a, b in zip(LEVELS[:-1], LEVELS[1:], strict=True)] + [f"LAmax >= {LEVELS[-1]:g} dB(A)"]
    # the band, the (transparent, white-drawn) cells below the lowest level, then the classes
    assert labels["noise grid"][-len(cls) - 1:] == [f"LAmax < {LEVELS[0]:g} dB(A)", *cls]
    assert "LAmax" in labels["noise grid"][0]
    assert labels["isolines"] == [f"LAmax {lv:g} dB(A)" for lv in LEVELS]  # levels, not ranges


def test_legend_renders_the_palette_and_no_black_box(layout_image):
    from gisnoise.maps import class_colours

    _legend, image, png = layout_image
    w, h = image.width(), image.height()
    counts = {c: 0 for c in class_colours(LEVELS)}
    targets = {c: (int(c[1:3], 16), int(c[3:5], 16), int(c[5:7], 16)) for c in counts}
    import numpy as np

    top = int(h * 50 / 190)  # the legend's part of the page
    dark = np.zeros((h - top, w), dtype=bool)
    for y in range(top, h):
        for x in range(w):
            px = image.pixelColor(x, y)
            r, g, b = px.red(), px.green(), px.blue()
            for c, (tr, tg, tb) in targets.items():
                if abs(r - tr) <= 4 and abs(g - tg) <= 4 and abs(b - tb) <= 4:
                    counts[c] += 1
            dark[y - top, x] = r + g + b < 60
    # each class swatch is drawn in its palette colour (a swatch of about 7 x 4 mm at 150 dpi: ~900 pixels)
    assert all(n > 300 for n in counts.values()), (counts, str(png))
    # no filled dark box: text strokes and swatch frames are a few pixels wide; any 8 x 8 block all dark is a box
    s = np.pad(dark.astype(int).cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    blocks = s[8:, 8:] - s[:-8, 8:] - s[8:, :-8] + s[:-8, :-8]
    assert blocks.max() < 64, str(png)
