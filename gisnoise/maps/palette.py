"""The noise palette: one set of colours for every face (map.png, the web page, the QGIS styles).

Noise maps are drawn in 5 dB classes; the colours here are those of DIN 18005-2:1991
(the same as ISO 1996-2:1987 and UNI 9884), each fixed to an absolute level so that a
class has the same colour on every map:

========  ==============  =========
class      colour name     sRGB
========  ==============  =========
< 35      light green     ``#B7CE8E``
35-40     green           ``#1D8435``
40-45     dark green      ``#0E4C3C``
45-50     yellow          ``#ECD721``
50-55     ochre           ``#9F6F2C``
55-60     orange          ``#EF7926``
60-65     cinnabar        ``#C71932``
65-70     carmine         ``#8D1A27``
70-75     lilac           ``#88497B``
75-80     blue            ``#18558C``
>= 80     dark blue       ``#134367``
========  ==============  =========

A class ``[L_i, L_i+1)`` of arbitrary levels takes the colour of the 5 dB class that holds
its lower bound ``L_i``; legends name the metric and the unit (``LAmax 45-50 dB(A)``).

Examples
--------
>>> colour_for(45.0), colour_for(47.5), colour_for(30.0), colour_for(95.0)
('#ECD721', '#ECD721', '#B7CE8E', '#134367')
>>> class_labels([45, 50, 65], "LAmax")
['LAmax 45-50 dB(A)', 'LAmax 50-65 dB(A)', 'LAmax >= 65 dB(A)']
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

__all__ = ["NOISE_CLASSES", "PALETTE_NAME", "colour_for", "class_colours", "class_labels", "palette_doc",
           "ISOLINE_COLOUR", "PHASE_COLOURS"]

PALETTE_NAME = "DIN 18005-2:1991 (ISO 1996-2:1987) 5 dB classes"

NOISE_CLASSES: tuple[tuple[float, str, str], ...] = (
    (-math.inf, "light green", "#B7CE8E"),
    (35.0, "green", "#1D8435"),
    (40.0, "dark green", "#0E4C3C"),
    (45.0, "yellow", "#ECD721"),
    (50.0, "ochre", "#9F6F2C"),
    (55.0, "orange", "#EF7926"),
    (60.0, "cinnabar", "#C71932"),
    (65.0, "carmine", "#8D1A27"),
    (70.0, "lilac", "#88497B"),
    (75.0, "blue", "#18558C"),
    (80.0, "dark blue", "#134367"),
)
"""(lower bound dB, colour name, sRGB hex) of each class, ascending; the first is open below, the last above."""

PHASE_COLOURS = {"horizontal": "#1f77b4", "transition": "#9467bd", "climb": "#2ca02c", "sink": "#17becf",
                 "hover": "#d62728"}
"""Colours of the flight track by phase (map.png, the QGIS track layer)."""

ISOLINE_COLOUR = "#202020"
"""Colour of isolines (drawn over the classes)."""


def colour_for(level_db: float) -> str:
    """sRGB hex colour of the 5 dB class holding ``level_db`` (dB)."""
    lv = float(level_db)
    out = NOISE_CLASSES[0][2]
    for lo, _, hexcol in NOISE_CLASSES:
        if lv >= lo:
            out = hexcol
    return out


def class_colours(levels: Sequence[float]) -> list[str]:
    """One colour per class ``[levels[i], levels[i+1])`` (the last open upwards)."""
    return [colour_for(v) for v in levels]


def class_labels(levels: Sequence[float], metric: str, unit: str = "dB(A)") -> list[str]:
    """Legend labels naming metric, range and unit, one per class."""
    lv = [float(v) for v in levels]
    out = []
    for i, lo in enumerate(lv):
        if i + 1 < len(lv):
            out.append(f"{metric} {lo:g}-{lv[i + 1]:g} {unit}")
        else:
            out.append(f"{metric} >= {lo:g} {unit}")
    return out


def palette_doc() -> dict[str, Any]:
    """The palette as JSON for the web page: name, classes (lower bound or null, colour name, hex), isolines."""
    return {"name": PALETTE_NAME, "isoline": ISOLINE_COLOUR,
            "classes": [{"from_db": None if math.isinf(lo) else lo, "name": name, "colour": hexcol}
                        for lo, name, hexcol in NOISE_CLASSES]}
