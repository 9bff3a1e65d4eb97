"""Helpers shared by the report writers (:mod:`gisnoise.identify.report`, :mod:`gisnoise.diagnose.report`,
:mod:`gisnoise.design.report`): the Agg figure, broken time lines, file names, JSON numbers and
the annotated correlation matrix.

matplotlib (``gisnoise[plot]``) is imported on use, without pyplot, so reports can be
written from worker threads.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.jsonio import dumps


def figure(w: float, h: float, *, dpi: int, report: str) -> Any:
    """A matplotlib Figure of ``w`` x ``h`` inches on an Agg canvas, constrained layout.

    ``report`` names the report in the error raised when matplotlib is missing.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:  # pragma: no cover - depends on the install
        raise InputError(f"the {report} report needs matplotlib: install gisnoise[plot]", field="report") from None
    fig = Figure(figsize=(w, h), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def with_gaps(t: np.ndarray, *ys: np.ndarray, gap_s: float = 1.0) -> tuple[np.ndarray, ...]:
    """Insert NaN into ``t`` and every ``y`` where consecutive times are more than ``gap_s`` s apart,
    so plotted lines break there.

    Examples
    --------
    >>> t, y = with_gaps(np.array([0.0, 0.5, 3.0]), np.array([1.0, 2.0, 3.0]))
    >>> t.tolist()[:2], bool(np.isnan(t[2])), y.tolist()[3]
    ([0.0, 0.5], True, 3.0)
    """
    if len(t) < 2:
        return (t, *ys)
    cut = np.flatnonzero(np.diff(t) > gap_s) + 1
    return tuple(np.insert(np.asarray(a, dtype=float), cut, np.nan) for a in (t, *ys))


def safe_name(name: str) -> str:
    """``name`` usable in a file name: characters other than letters, digits and ``-_.`` become ``_``.

    Examples
    --------
    >>> safe_name("flight 1/a")
    'flight_1_a'
    """
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def dump_json(obj: Any, path: Path) -> None:
    """Write ``obj`` as one line of strict JSON (numpy values converted, no NaN) and a newline, UTF-8."""
    path.write_text(dumps(obj), encoding="utf-8")


def write_view(out: Path, name: str, data: Any, plot: Callable[[Any, Path], None], files: dict[str, Path]) -> None:
    """Write one view into ``out``: ``<name>.json`` (its numbers) and ``<name>.png`` (``plot(data, path)``),
    recording both in ``files`` (name -> path)."""
    dump_json(data, out / f"{name}.json")
    plot(data, out / f"{name}.png")
    files.update({f"{name}.json": out / f"{name}.json", f"{name}.png": out / f"{name}.png"})


def correlation_axes(ax: Any, c: np.ndarray, labels: Sequence[str], *, fontsize: float,
                     tick_fontsize: float | None = None) -> Any:
    """Draw the correlation matrix ``c`` on ``ax`` in [-1, 1], each cell labelled with its value.

    Returns the image (for a colorbar).  ``tick_fontsize`` None keeps matplotlib's tick size.
    """
    tick_kw = {} if tick_fontsize is None else {"fontsize": tick_fontsize}
    im = ax.imshow(c, vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(len(labels)), labels, rotation=45, ha="right", **tick_kw)
    ax.set_yticks(range(len(labels)), labels, **tick_kw)
    for i in range(len(labels)):
        for j in range(len(labels)):
            ax.text(j, i, f"{c[i, j]:.2f}", ha="center", va="center", fontsize=fontsize,
                    color="w" if abs(c[i, j]) > 0.6 else "k")
    return im
