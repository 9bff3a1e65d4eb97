"""Styles of the outputs: graduated colours by level, the same classes for grid and contours.

The classes are the contour levels: ``[L_i, L_i+1)`` dB(A), the last one open
upwards, coloured from green (quiet) through yellow and orange to red and
purple (loud), the order of the usual noise-map palettes.
"""

from __future__ import annotations

from qgis.core import (
    QgsClassificationRange,
    QgsColorRampShader,
    QgsFillSymbol,
    QgsGradientColorRamp,
    QgsGradientStop,
    QgsGraduatedSymbolRenderer,
    QgsLineSymbol,
    QgsProcessingLayerPostProcessorInterface,
    QgsRasterShader,
    QgsRendererRange,
    QgsSingleBandPseudoColorRenderer,
)
from qgis.PyQt.QtGui import QColor

#: Upper end of the last, open class, dB(A).
TOP_DB = 200.0

_kept = []


def keep(post):
    """Hold a post-processor until QGIS has run it (QGIS keeps no Python reference)."""
    _kept.append(post)
    del _kept[:-32]
    return post


def level_ramp():
    """Green -> yellow -> orange -> red -> purple."""
    ramp = QgsGradientColorRamp(QColor("#1a9850"), QColor("#5e3c99"))
    ramp.setStops([QgsGradientStop(0.25, QColor("#d9ef8b")), QgsGradientStop(0.45, QColor("#fee08b")),
                   QgsGradientStop(0.65, QColor("#fc8d59")), QgsGradientStop(0.85, QColor("#d73027"))])
    return ramp


def level_colours(levels):
    """One colour per class ``[L_i, L_i+1)``, dB(A) levels ascending."""
    ramp = level_ramp()
    n = len(levels)
    return [ramp.color(0.5 if n == 1 else i / (n - 1)) for i in range(n)]


def class_label(levels, i):
    lo = levels[i]
    return f">= {lo:g} dB(A)" if i == len(levels) - 1 else f"{lo:g} - {levels[i + 1]:g} dB(A)"


def graduated_renderer(levels, *, polygons, field="level"):
    """A graduated renderer on ``field`` with one class per level."""
    ranges = []
    for i, (lo, colour) in enumerate(zip(levels, level_colours(levels), strict=True)):
        hi = levels[i + 1] if i + 1 < len(levels) else TOP_DB
        if polygons:
            symbol = QgsFillSymbol.createSimple({"color": colour.name(), "outline_color": "#404040",
                                                 "outline_width": "0.1"})
            symbol.setOpacity(0.6)
        else:
            symbol = QgsLineSymbol.createSimple({"color": colour.darker(130).name(), "width": "0.5"})
        ranges.append(QgsRendererRange(QgsClassificationRange(class_label(levels, i), lo, hi), symbol))
    renderer = QgsGraduatedSymbolRenderer(field, ranges)
    return renderer


def pseudocolor_renderer(provider, levels, band=1):
    """Discrete pseudo-colour classes of a raster band at the levels; below the first level transparent."""
    items = [QgsColorRampShader.ColorRampItem(levels[0], QColor(0, 0, 0, 0), f"< {levels[0]:g} dB(A)")]
    colours = level_colours(levels)
    for i, colour in enumerate(colours):
        hi = levels[i + 1] if i + 1 < len(levels) else float("inf")
        items.append(QgsColorRampShader.ColorRampItem(hi, colour, class_label(levels, i)))
    shader_fn = QgsColorRampShader(levels[0], levels[-1], level_ramp(), QgsColorRampShader.Discrete)
    shader_fn.setColorRampItemList(items)
    shader = QgsRasterShader()
    shader.setRasterShaderFunction(shader_fn)
    return QgsSingleBandPseudoColorRenderer(provider, band, shader)


class RasterStyle(QgsProcessingLayerPostProcessorInterface):
    """Colours one band (metric) of the noise grid by level: the one the contours show."""

    def __init__(self, levels, metric, band):
        super().__init__()
        self.levels = list(levels)
        self.metric = metric
        self.band = int(band)

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802 - QGIS API
        if not layer.isValid():
            return
        layer.setRenderer(pseudocolor_renderer(layer.dataProvider(), self.levels, band=self.band))
        layer.setName(f"noise grid ({self.metric})")
        layer.triggerRepaint()


class ContourStyle(QgsProcessingLayerPostProcessorInterface):
    """Graduated colours on the contours' ``level`` property."""

    def __init__(self, levels, *, polygons):
        super().__init__()
        self.levels = list(levels)
        self.polygons = polygons

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802 - QGIS API
        if not layer.isValid():
            return
        layer.setRenderer(graduated_renderer(self.levels, polygons=self.polygons))
        layer.triggerRepaint()


#: Classes of residual levels, dB: the measurement noise of a good campaign is about 1 dB.
RESIDUAL_CLASSES = (0.0, 1.0, 2.0, 3.0, 5.0)


class ResidualStyle(QgsProcessingLayerPostProcessorInterface):
    """Graduated colours on a residual field (dB), thick lines: where the card misses."""

    def __init__(self, field):
        super().__init__()
        self.field = field

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802 - QGIS API
        if not layer.isValid():
            return
        levels = list(RESIDUAL_CLASSES)
        ranges = []
        for i, colour in enumerate(level_colours(levels)):
            hi = levels[i + 1] if i + 1 < len(levels) else TOP_DB
            symbol = QgsLineSymbol.createSimple({"color": colour.name(), "width": "1.2"})
            label = f">= {levels[i]:g} dB" if i == len(levels) - 1 else f"{levels[i]:g} - {hi:g} dB"
            ranges.append(QgsRendererRange(QgsClassificationRange(label, levels[i], hi), symbol))
        layer.setRenderer(QgsGraduatedSymbolRenderer(self.field, ranges))
        layer.triggerRepaint()
