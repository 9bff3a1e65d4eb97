"""Figures: the noise map (``map.png``) and a card's directivity (the paper's Fig. 7 and 9).

matplotlib is an optional dependency (``gisnoise[plot]``); it is imported on use
with the non-interactive Agg backend.  The numbers behind each figure come from a
pure function (:func:`directivity_grid`), so tests check the numbers, not pixels.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.maps.hemifill import has_hemisphere
from gisnoise.maps.palette import ISOLINE_COLOUR, PHASE_COLOURS, class_colours
from gisnoise.maps.sel import metric_levels

if TYPE_CHECKING:  # pragma: no cover
    from gisnoise.flight import Trajectory
    from gisnoise.maps.result import MapResult
    from gisnoise.model import ModelCard

__all__ = ["require_matplotlib", "plot_map", "directivity_grid", "plot_directivity", "PHASE_COLOURS"]



def require_matplotlib() -> Any:
    """Import matplotlib with the Agg backend; a clear error when it is not installed."""
    try:
        import matplotlib
    except ImportError:
        raise InputError("plotting needs matplotlib: pip install 'gisnoise[plot]'", field="plot") from None
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _nice_length(span_m: float) -> float:
    """A round scale-bar length near a fifth of ``span_m`` (m)."""
    target = max(span_m / 5.0, 1e-9)
    exp = 10 ** math.floor(math.log10(target))
    for f in (1, 2, 5, 10):
        if f * exp >= target * 0.7:
            return float(f * exp)
    return float(10 * exp)


def _scale_bar(ax: Any, left: float, bottom: float, width: float, height: float) -> None:
    from matplotlib.patches import Rectangle

    length = _nice_length(width)
    x0 = left + 0.05 * width
    y0 = bottom + 0.05 * height
    h = 0.012 * height
    half = length / 2
    ax.add_patch(Rectangle((x0, y0), half, h, facecolor="black", edgecolor="black", zorder=6))
    ax.add_patch(Rectangle((x0 + half, y0), half, h, facecolor="white", edgecolor="black", zorder=6))
    label = f"{length / 1000:g} km" if length >= 1000 else f"{length:g} m"
    ax.text(x0 + length / 2, y0 + 2.2 * h, label, ha="center", va="bottom", fontsize=9, zorder=6,
            bbox={"facecolor": "white", "alpha": 0.7, "edgecolor": "none", "pad": 1})


def _north_arrow(ax: Any) -> None:
    ax.annotate("N", xy=(0.95, 0.95), xytext=(0.95, 0.86), xycoords="axes fraction", ha="center", va="center",
                fontsize=11, fontweight="bold", arrowprops={"arrowstyle": "-|>", "color": "black", "lw": 1.5},
                zorder=7)


def _save_png(fig: Any, path: str | os.PathLike[str], dpi: int) -> Path:
    """Save ``fig`` as PNG at ``path`` (folders created), via a temporary file so a reader never sees half a file."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.stem + ".tmp.png")
    fig.savefig(tmp, dpi=dpi)
    os.replace(tmp, p)
    return p


def plot_map(result: MapResult, path: str | os.PathLike[str], *, levels: Sequence[float],
             trajectory: Trajectory | None = None, metric: str | None = None, dpi: int = 120,
             tracks: Sequence[tuple[str, Trajectory]] = ()) -> Path:
    """Draw a level band with its contours, the track, a scale bar, a north arrow and a legend.

    Parameters
    ----------
    result : MapResult
    path : path
        Output PNG.
    levels : sequence of float
        Contour levels, dB(A); the colours change at these levels (``SEL``'s lie higher:
        :func:`gisnoise.maps.sel.metric_levels`).
    trajectory : Trajectory, optional
        Drawn as the track, coloured by phase, with start and end marked.
    metric : str, optional
        Band to draw; default ``LAmax`` if present, else the first level band.
    tracks : sequence of (name, Trajectory)
        Several flights (a day of operations): each drawn as a thin line named at its start; the title then
        speaks of the flights.

    Returns
    -------
    Path
    """
    plt = require_matplotlib()
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.lines import Line2D

    names = result.level_bands()
    if metric is None:
        if not names:
            raise InputError("no level band to plot", field="metric")
        metric = "LAmax" if "LAmax" in names else names[0]
    z = np.asarray(result.band(metric), dtype=float)
    lv = sorted(metric_levels(metric, [float(v) for v in levels]))  # SEL lies 10 dB higher
    grid = result.grid
    left, bottom, right, top = grid.bounds
    aspect = (top - bottom) / (right - left)
    fig, ax = plt.subplots(figsize=(10.0, float(np.clip(8.0 * aspect + 1.6, 4.5, 11.0))), constrained_layout=True)
    try:
        bounds = lv + [max(lv[-1] + 5.0, float(np.nanmax(z)) + 1e-6 if np.isfinite(z).any() else lv[-1] + 5.0)]
        colours = class_colours(lv)  # the noise palette shared with the web page and QGIS
        cmap = ListedColormap(colours).with_extremes(under=(1, 1, 1, 0), over=colours[-1],
                                                     bad=(0.85, 0.85, 0.85, 1))
        norm = BoundaryNorm(bounds, cmap.N)
        im = ax.imshow(np.ma.masked_invalid(z), extent=(left, right, bottom, top), origin="upper", cmap=cmap,
                       norm=norm, interpolation="nearest", alpha=0.85, zorder=1)
        ax.set_facecolor("#f4f4f0")
        if np.isfinite(z).any() and min(z.shape) >= 2:
            cs = ax.contour(grid.xs, grid.ys, np.ma.masked_invalid(z), levels=lv, colors=ISOLINE_COLOUR,
                            linewidths=0.7, zorder=3)
            ax.clabel(cs, fmt=lambda v: f"{v:g}", fontsize=8)
        handles = []
        if trajectory is not None:
            x, y = grid.from_wgs84(trajectory.lon, trajectory.lat)
            ax.plot(x, y, color="0.2", lw=1.0, zorder=4)
            for ph in dict.fromkeys(trajectory.phase.tolist()):
                m = trajectory.phase == ph
                ax.scatter(x[m], y[m], s=6, color=PHASE_COLOURS.get(ph, "0.3"), zorder=5)
                handles.append(Line2D([], [], marker="o", ls="", color=PHASE_COLOURS.get(ph, "0.3"),
                                      label=f"track: {ph}"))
            ax.plot(x[0], y[0], marker="^", ms=9, color="black", ls="", zorder=6)
            ax.plot(x[-1], y[-1], marker="s", ms=8, color="black", ls="", zorder=6)
            handles += [Line2D([], [], marker="^", ls="", color="black", label="start"),
                        Line2D([], [], marker="s", ls="", color="black", label="end")]
        starts: dict[tuple[int, int], list[str]] = {}  # flights taking off within 10 m of each other: one label
        for name, tr in tracks:
            x, y = grid.from_wgs84(tr.lon, tr.lat)
            ax.plot(x, y, color="0.25", lw=0.8, zorder=4)
            starts.setdefault((round(float(x[0]) / 10.0), round(float(y[0]) / 10.0)), []).append(name)
        for (xs, ys), names_here in starts.items():
            ax.annotate(", ".join(names_here), (10.0 * xs, 10.0 * ys), xytext=(4, 4), textcoords="offset points",
                        fontsize=7, color="0.15", zorder=6)
        if tracks:
            handles.append(Line2D([], [], color="0.25", lw=0.8, label="flight tracks (named at take-off)"))
        handles.append(Line2D([], [], color="black", lw=0.7, label=f"{metric} contours, dB(A)"))
        # below the map, not over it: no corner of a map is sure to be empty
        fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4), fontsize=8,
                   frameon=False)
        cb = fig.colorbar(im, ax=ax, shrink=0.9, extend="max", ticks=bounds[:-1], aspect=30)
        cb.set_label(f"{metric}, dB(A) (colours of DIN 18005-2, 5 dB classes)")
        _scale_bar(ax, left, bottom, right - left, top - bottom)
        _north_arrow(ax)
        ax.set_xlim(left, right)
        ax.set_ylim(bottom, top)
        ax.set_aspect("equal")
        auth = grid.crs.to_authority()
        crs_name = ":".join(auth) if auth else grid.crs.name
        ax.set_xlabel(f"easting, m ({crs_name})")
        ax.set_ylabel("northing, m")
        ax.ticklabel_format(style="plain", useOffset=False)
        ax.tick_params(labelsize=8)
        md = result.metadata
        sub = f"grid {grid.resolution[0]:g} m, receivers {md.get('receiver_height_m', '?')} m above ground"
        if metric == "LAeq" and md.get("period_s"):
            sub += f", period {md['period_s']:.0f} s"
        what = f"the day's {len(tracks)} flight{'s' if len(tracks) != 1 else ''}" if tracks else "the UAV"
        ax.set_title(f"{metric} of {what}\n{sub}", fontsize=11)
        p = _save_png(fig, path, dpi)
    finally:
        plt.close(fig)
    return p


def directivity_grid(card: ModelCard, *, p_el: float = 1.1, distance_m: float = 30.0, n_phi: int = 361,
                     n_theta: int = 181, **extra: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``L_UAV`` over the emission angles at one distance and power (the paper's Fig. 7 and 9).

    Parameters
    ----------
    card : ModelCard
    p_el : float
        Nondimensional electric power.
    distance_m : float
        Source-observer distance, m.
    n_phi, n_theta : int
        Grid points in azimuth (-180..180 deg) and polar angle (-90..90 deg).
    **extra
        Further inputs an extended ansatz needs (e.g. ``bank`` in rad).

    Returns
    -------
    phi_deg : ndarray, shape (n_phi,)
    theta_deg : ndarray, shape (n_theta,)
    level : ndarray, shape (n_theta, n_phi)
        dB(A), background excluded.
    """
    for name, v in (("p_el", p_el), ("distance_m", distance_m)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"{name} must be a positive number, got {v!r}", field=name)
    phi = np.linspace(-180.0, 180.0, int(n_phi))
    theta = np.linspace(-90.0, 90.0, int(n_theta))
    ph, th = np.meshgrid(np.radians(phi), np.radians(theta))
    x = card.inputs(distance_m, ph, th, p_el * card.reference_power_w, **extra)
    return phi, theta, np.asarray(card.level_uav(x), dtype=float)


def plot_directivity(card: ModelCard, path: str | os.PathLike[str], *, p_el: float = 1.1,
                     distance_m: float = 30.0, dpi: int = 120, **extra: Any) -> Path:
    """Draw :func:`directivity_grid` as a map over azimuth and polar angle, the maximum marked."""
    plt = require_matplotlib()
    phi, theta, lvl = directivity_grid(card, p_el=p_el, distance_m=distance_m, **extra)
    fig, ax = plt.subplots(figsize=(8.5, 5.0), constrained_layout=True)
    try:
        pm = ax.pcolormesh(phi, theta, lvl, shading="auto", cmap="viridis")
        if np.ptp(lvl) > 1e-9:
            cs = ax.contour(phi, theta, lvl, levels=10, colors="white", linewidths=0.5)
            ax.clabel(cs, fmt=lambda v: f"{v:.1f}", fontsize=7)
        i, j = np.unravel_index(np.argmax(lvl), lvl.shape)
        ax.plot(phi[j], theta[i], marker="x", color="red", ms=10, mew=2)
        ax.annotate(f"max {lvl[i, j]:.1f} dB(A)\nat {phi[j]:.0f}°, {theta[i]:.0f}°", (phi[j], theta[i]),
                    xytext=(8, 8), textcoords="offset points", color="red", fontsize=8)
        cb = fig.colorbar(pm, ax=ax)
        cb.set_label("L_UAV, dB(A)")
        ax.set_xlabel("azimuth φ, deg (0 ahead, +90 starboard)")
        ax.set_ylabel("polar angle θ, deg (−90 below)")
        ax.set_xticks(np.arange(-180, 181, 45))
        ax.set_yticks(np.arange(-90, 91, 30))
        power = "measured hemisphere (no power term)" if has_hemisphere([card]) else f"P_el = {p_el:g}"
        ax.set_title(f"{card.id} ({card.phase}): level at {distance_m:g} m, {power}", fontsize=11)
        p = _save_png(fig, path, dpi)
    finally:
        plt.close(fig)
    return p
