"""Styles of the outputs: graduated colours by level, the same classes for grid and contours.

The classes are the contour levels: ``[L_i, L_i+1)`` dB(A), the last one open
upwards, coloured with the core's noise palette (:mod:`gisnoise.maps.palette`,
DIN 18005-2 5 dB classes), the same as ``map.png`` and the web page.  Legends name
the metric and the unit.

QGIS's graduated ranges and discrete raster classes hold their upper bound
(``lower <= v <= upper``, the first match wins), so a class that ends at
``L_i+1`` would take the isoband whose ``level`` is ``L_i+1``: every band would
be drawn one class too low.  Each class therefore ends at the largest double
below the next level (:func:`class_top`): ``L_i <= v <= class_top(L_i+1)`` is
exactly ``L_i <= v < L_i+1``, and the bounds survive a saved style (QGIS writes
them with 15 decimals).  :func:`save_style` writes a style beside a file output
(``.qml``, and inside a GeoPackage as its default style), so the layer opens styled
however it is loaded: from ``qgis_process``, a model or a script.
"""

from __future__ import annotations

import math
import os

from qgis.core import (
    QgsCategorizedSymbolRenderer,
    QgsClassificationRange,
    QgsColorRampShader,
    QgsFillSymbol,
    QgsGradientColorRamp,
    QgsGradientStop,
    QgsGraduatedSymbolRenderer,
    QgsLineSymbol,
    QgsPalLayerSettings,
    QgsProcessingLayerPostProcessorInterface,
    QgsRasterShader,
    QgsRendererCategory,
    QgsRendererRange,
    QgsSingleBandPseudoColorRenderer,
    QgsTextFormat,
    QgsVectorLayerSimpleLabeling,
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


def class_top(next_level):
    """Upper bound of a QGIS class that ends just below ``next_level`` (dB): the largest double below it, so
    the class is ``[lower, next_level)``; ``inf`` stays ``inf``."""
    next_level = float(next_level)
    return next_level if math.isinf(next_level) else math.nextafter(next_level, -math.inf)


def level_ramp():
    """Green -> yellow -> orange -> red -> purple."""
    ramp = QgsGradientColorRamp(QColor("#1a9850"), QColor("#5e3c99"))
    ramp.setStops([QgsGradientStop(0.25, QColor("#d9ef8b")), QgsGradientStop(0.45, QColor("#fee08b")),
                   QgsGradientStop(0.65, QColor("#fc8d59")), QgsGradientStop(0.85, QColor("#d73027"))])
    return ramp


def _palette():
    from .._core import ensure_core

    ensure_core()
    from gisnoise.maps import palette

    return palette


def level_colours(levels):
    """One colour per class ``[L_i, L_i+1)``, dB(A) levels ascending: the core's noise palette."""
    return [QColor(c) for c in _palette().class_colours(list(levels))]


def class_label(levels, i, metric="", unit="dB(A)"):
    """``LAmax 45-50 dB(A)``, the last class ``LAmax >= 65 dB(A)``."""
    label = _palette().class_labels(list(levels), metric or "", unit)[i]
    return label.strip()


def graduated_renderer(levels, *, polygons, field="level", metric=""):
    """A graduated renderer on ``field`` with one class ``[L_i, L_i+1)`` per level (see :func:`class_top`)."""
    ranges = []
    for i, (lo, colour) in enumerate(zip(levels, level_colours(levels), strict=True)):
        hi = class_top(levels[i + 1]) if i + 1 < len(levels) else TOP_DB
        if polygons:
            symbol = QgsFillSymbol.createSimple({"color": colour.name(), "outline_color": "#404040",
                                                 "outline_width": "0.1"})
            symbol.setOpacity(0.6)
        else:
            symbol = QgsLineSymbol.createSimple({"color": colour.name(), "width": "0.5"})
        label = class_label(levels, i, metric) if polygons else f"{metric} {lo:g} dB(A)".strip()
        ranges.append(QgsRendererRange(QgsClassificationRange(label, lo, hi), symbol))
    renderer = QgsGraduatedSymbolRenderer(field, ranges)
    return renderer


def pseudocolor_renderer(provider, levels, band=1, metric=""):
    """Discrete pseudo-colour classes of a raster band at the levels; below the first level transparent
    (drawn white in legends, so a print layout shows no black box)."""
    items = [QgsColorRampShader.ColorRampItem(class_top(levels[0]), QColor(255, 255, 255, 0),
                                              f"{metric} < {levels[0]:g} dB(A)".strip())]
    colours = level_colours(levels)
    for i, colour in enumerate(colours):  # a discrete item holds the values up to and including its value
        hi = class_top(levels[i + 1]) if i + 1 < len(levels) else float("inf")
        items.append(QgsColorRampShader.ColorRampItem(hi, colour, class_label(levels, i, metric)))
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
        style_raster(layer, self.levels, self.metric, self.band)
        layer.triggerRepaint()


class ContourStyle(QgsProcessingLayerPostProcessorInterface):
    """Graduated colours on the contours' ``level`` property."""

    def __init__(self, levels, *, polygons, metric=""):
        super().__init__()
        self.levels = list(levels)
        self.polygons = polygons
        self.metric = metric

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802 - QGIS API
        if not layer.isValid():
            return
        style_contours(layer, self.levels, polygons=self.polygons, metric=self.metric)
        layer.triggerRepaint()


class TrackStyle(QgsProcessingLayerPostProcessorInterface):
    """The flight track coloured by phase."""

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802 - QGIS API
        if layer.isValid():
            style_track(layer)
            layer.triggerRepaint()


def style_raster(layer, levels, metric, band):
    """The noise grid's band ``band`` (``metric``) in the palette's classes."""
    layer.setRenderer(pseudocolor_renderer(layer.dataProvider(), list(levels), band=int(band), metric=metric))
    layer.setName(f"noise grid ({metric})")


def style_contours(layer, levels, *, polygons, metric=""):
    """Graduated palette colours on ``level``; isolines labelled with their level."""
    layer.setRenderer(graduated_renderer(list(levels), polygons=polygons, metric=metric))
    if not polygons:
        settings = QgsPalLayerSettings()
        settings.fieldName = "format_number(\"level\", 0) || ' dB(A)'"
        settings.isExpression = True
        settings.placement = QgsPalLayerSettings.Line
        fmt = QgsTextFormat()
        fmt.setSize(8)
        buffer = fmt.buffer()
        buffer.setEnabled(True)
        buffer.setSize(0.8)
        fmt.setBuffer(buffer)
        settings.setFormat(fmt)
        layer.setLabeling(QgsVectorLayerSimpleLabeling(settings))
        layer.setLabelsEnabled(True)


def style_track(layer, field="phase"):
    """Categories by flight phase in the core's phase colours."""
    _palette()
    from gisnoise.maps import PHASE_COLOURS

    cats = []
    for phase, colour in PHASE_COLOURS.items():
        symbol = QgsLineSymbol.createSimple({"color": colour, "width": "0.8"})
        cats.append(QgsRendererCategory(phase, symbol, f"track: {phase}"))
    layer.setRenderer(QgsCategorizedSymbolRenderer(field, cats))


def save_style(layer, path):
    """Save ``layer``'s style beside the file ``path`` (``<name>.qml``) and, for a GeoPackage, as the
    default style inside it; QGIS then opens the file styled.  Returns the ``.qml`` path or None."""
    if not path or not os.path.isfile(path):
        return None
    qml = os.path.splitext(path)[0] + ".qml"
    msg, ok = layer.saveNamedStyle(qml)
    if not ok:
        raise RuntimeError(f"cannot save the style {qml}: {msg}")
    if path.lower().endswith(".gpkg") and hasattr(layer, "saveStyleToDatabase"):
        layer.saveStyleToDatabase(layer.name() or "gisnoise", "gisnoise noise palette", True, "")
    return qml


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
            hi = class_top(levels[i + 1]) if i + 1 < len(levels) else TOP_DB
            symbol = QgsLineSymbol.createSimple({"color": colour.name(), "width": "1.2"})
            label = f">= {levels[i]:g} dB" if i == len(levels) - 1 else f"{levels[i]:g} - {levels[i + 1]:g} dB"
            ranges.append(QgsRendererRange(QgsClassificationRange(label, levels[i], hi), symbol))
        layer.setRenderer(QgsGraduatedSymbolRenderer(self.field, ranges))
        layer.triggerRepaint()
