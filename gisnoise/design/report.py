"""The design report: the paper's views of a measurement design as PNG, one HTML page.

:func:`write_report` writes into a folder

``study.png``
    optimum objective against the allowed microphone displacement for several
    altitude ranges (paper Fig. 18), one panel per objective studied;
``correlation.png``
    correlation matrices of power, polar angle, distance and bank angle for the base
    design and each optimum (paper Figs. 19-22);
``correlation_study.png``
    the same at the study's optima the paper shows (displacement 50 m with altitudes
    35-200 m, 200 m with 50-150 m) when the study has them, else at the largest
    displacement of each altitude range;
``layout.png``
    the track, the microphones of the base and of each optimum, their displacement
    limits and the exclusion polygons (local east/north metres);
``std.png``
    expected (Cramer-Rao) standard deviation of each parameter at each optimum
    relative to the base, and the measured ratio of the closing-the-loop campaigns;
``report.html``
    all of it on one page with the numbers.

The numbers come from :meth:`gisnoise.design.result.DesignResult.to_dict` (also written as
``design.json``); :func:`study_curves` and :func:`std_ratios` are the pure functions
behind the two line and bar views.  The plots use matplotlib's Agg canvas without
pyplot (reports can be written from worker threads).  Needs the ``plot`` extra.
"""

from __future__ import annotations

import html
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gisnoise.design.objectives import CORRELATION_VARIABLES
from gisnoise.jsonio import to_jsonable
from gisnoise.reporting import correlation_axes, figure

if TYPE_CHECKING:  # pragma: no cover
    from gisnoise.design.result import DesignResult

__all__ = ["write_report", "study_curves", "std_ratios", "layout_figure"]

_COLOURS = {"base": "0.25", "paper": "tab:orange", "d-optimal": "tab:blue"}
_LABELS = {"power": "power", "polar": "polar angle", "distance": "distance", "bank": "bank angle"}


# --------------------------------------------------------------------------- data


def study_curves(doc: dict[str, Any]) -> dict[str, dict[str, dict[str, list[float]]]]:
    """The study as curves: objective -> altitude range label -> ``{"shift_m": [...], "value": [...]}``.

    ``value`` is the optimizer's objective (``max |corr|`` for ``paper``, ``log det`` of the
    Fisher information for ``d-optimal``), sorted by displacement.
    """
    out: dict[str, dict[str, dict[str, list[float]]]] = {}
    for p in doc.get("study") or []:
        rng = p["altitude_range_m"]
        label = f"{rng[0]:g} m" if rng[0] == rng[1] else f"{rng[0]:g}-{rng[1]:g} m"
        value = p["max_abs_corr"] if p["objective"] == "paper" else p["log_det_fisher"]
        c = out.setdefault(p["objective"], {}).setdefault(label, {"shift_m": [], "value": []})
        c["shift_m"].append(float(p["max_shift_m"]))
        c["value"].append(float(value))
    for curves in out.values():
        for c in curves.values():
            order = np.argsort(c["shift_m"], kind="stable")
            c["shift_m"] = [c["shift_m"][i] for i in order]
            c["value"] = [c["value"][i] for i in order]
    return out


def std_ratios(doc: dict[str, Any]) -> dict[str, Any]:
    """Per parameter: expected std at each optimum / at the base, and the measured ratio of the verification.

    Returns ``{"parameters": [...], "expected": {objective: [...]}, "measured": {objective: [...]}}``
    (``measured`` only for designs the verification flew).
    """
    names = list(doc["base"]["expected_std"])
    base = np.array([doc["base"]["expected_std"][k] for k in names], dtype=float)
    out: dict[str, Any] = {"parameters": names, "expected": {}, "measured": {}}
    for obj, o in doc["optima"].items():
        e = np.array([o["design"]["expected_std"][k] for k in names], dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            out["expected"][obj] = (e / base).tolist()
    ver = doc.get("verify")
    if ver:
        for d, v in ver["designs"].items():
            if "empirical_std_ratio_to_base" in v:
                out["measured"][d] = list(v["empirical_std_ratio_to_base"])
    return out


_PAPER_POINTS = ((50.0, [35.0, 200.0]), (200.0, [50.0, 150.0]))
"""Study points whose correlation matrices the paper shows (Figs. 19-22): displacement (m), altitude range (m)."""


def _study_panels(doc: dict[str, Any]) -> list[tuple[str, np.ndarray]]:
    """Correlation matrices of the paper's Figs. 19-22 points when the study has them, else of the
    largest displacement of each altitude range."""
    pts = [p for p in doc["study"] if p["objective"] == doc["study"][0]["objective"]]
    chosen = [p for s, r in _PAPER_POINTS for p in pts if p["max_shift_m"] == s and p["altitude_range_m"] == r]
    if len(chosen) < len(_PAPER_POINTS):
        chosen = [p for p in pts if p["max_shift_m"] == max(q["max_shift_m"] for q in pts
                                                             if q["altitude_range_m"] == p["altitude_range_m"])]
    out = []
    for p in chosen:
        r = p["altitude_range_m"]
        out.append((f"{p['objective']}: displacement {p['max_shift_m']:g} m, altitudes {r[0]:g}-{r[1]:g} m",
                    np.array(p["correlation"])))
    return out


# --------------------------------------------------------------------------- plots


def _figure(w: float, h: float) -> Any:
    return figure(w, h, dpi=110, report="design")


def _plot_study(curves: dict[str, Any], path: Path) -> None:
    objs = list(curves)
    fig = _figure(5.2 * len(objs), 4.2)
    axes = fig.subplots(1, len(objs), squeeze=False)[0]
    for ax, obj in zip(axes, objs, strict=True):
        for label, c in curves[obj].items():
            ax.plot(c["shift_m"], c["value"], marker="o", label=f"altitudes {label}")
        ax.set_xlabel("allowed microphone displacement / m")
        if obj == "paper":
            ax.set_ylabel("largest |correlation| (target function)")
            ax.set_title("Paper objective (Fig. 18)")
        else:
            ax.set_ylabel("log det of the Fisher information")
            ax.set_title("D-optimal objective")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.savefig(path)


def _corr_panels(panels: list[tuple[str, np.ndarray]], variables: list[str], path: Path, title: str) -> None:
    fig = _figure(3.6 * len(panels) + 0.8, 3.9)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    labels = [_LABELS.get(v, v) for v in variables]
    im = None
    for ax, (name, c) in zip(axes, panels, strict=True):
        im = correlation_axes(ax, c, labels, fontsize=8, tick_fontsize=8)
        ax.set_title(name, fontsize=9)
    fig.colorbar(im, ax=list(axes), shrink=0.8, label="correlation coefficient")
    fig.suptitle(title, fontsize=10)
    fig.savefig(path)


def _plot_layout(result: DesignResult, doc: dict[str, Any], path: Path) -> None:
    layout_figure(result, doc).savefig(path)


def layout_figure(result: DesignResult, doc: dict[str, Any]) -> Any:
    """The layout figure (``layout.png``): track, exclusions, base and optimal microphones, limits.

    The legend sits beside the axes; the figure's width grows with it, so axis labels, tick
    labels (minus signs included) and legend all lie inside the canvas.
    """
    from matplotlib.patches import Polygon as MplPolygon
    from matplotlib.patches import Rectangle

    plan, model = result.plan, result.model
    fig = _figure(11.0, 6.5)
    ax = fig.subplots()
    ax.plot(model.track["e"], model.track["n"], color="0.6", lw=1.0, label="track (all repetitions)", zorder=1)
    for poly in plan.exclusions:
        geoms = getattr(poly, "geoms", [poly])
        for g in geoms:
            if hasattr(g, "exterior"):
                ax.add_patch(MplPolygon(np.asarray(g.exterior.coords), closed=True, facecolor="tab:red", alpha=0.2,
                                        edgecolor="tab:red", hatch="//", zorder=0))
    if plan.exclusions:
        ax.plot([], [], color="tab:red", alpha=0.4, lw=6, label="exclusion")
    for i, mid in enumerate(plan.mic_ids):
        se, sn = plan.max_shift[i]
        e0, n0 = plan.base.mic_e[i], plan.base.mic_n[i]
        ax.add_patch(Rectangle((e0 - se, n0 - sn), 2 * se, 2 * sn, fill=False, ls="--", ec="0.4", lw=0.8, zorder=2))
        ax.plot(e0, n0, "o", color=_COLOURS["base"], ms=7, zorder=4)
        ax.annotate(mid, (e0, n0), xytext=(4, 4), textcoords="offset points", fontsize=8)
    ax.plot([], [], "o", color=_COLOURS["base"], label=f"base, altitudes {_alts(doc['base'])}")
    for obj, o in result.optima.items():
        d = o.design
        col = _COLOURS.get(obj, "tab:green")
        for i in range(plan.n_mics):
            ax.annotate("", xy=(d.mic_e[i], d.mic_n[i]), xytext=(plan.base.mic_e[i], plan.base.mic_n[i]),
                        arrowprops={"arrowstyle": "->", "color": col, "lw": 1.0}, zorder=3)
        ax.plot(d.mic_e, d.mic_n, "s", color=col, ms=7, zorder=5,
                label=f"{obj} optimum, altitudes {_alts(doc['optima'][obj]['design'])}")
    ax.plot([], [], ls="--", color="0.4", lw=0.8, label="displacement limits")
    ax.set_aspect("equal")
    ax.set_xlabel("east / m")
    ax.set_ylabel("north / m")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    ax.set_title(f"Layout: signal-to-noise distance {plan.max_distance_m:.0f} m", fontsize=10)
    _fit_canvas(fig)
    return fig


def _fit_canvas(fig: Any, pad_in: float = 0.1) -> None:
    """Widen or heighten ``fig`` until its drawn extent (tight bounding box) lies inside the canvas."""
    for _ in range(4):
        fig.canvas.draw()
        tight = fig.get_tightbbox(fig.canvas.get_renderer())
        w, h = fig.get_size_inches()
        over_w = max(0.0, tight.x1 - w, -tight.x0) + pad_in
        over_h = max(0.0, tight.y1 - h, -tight.y0) + pad_in
        if over_w <= pad_in and over_h <= pad_in:
            return
        fig.set_size_inches(w + 2 * over_w, h + 2 * over_h)


def _alts(d: dict[str, Any]) -> str:
    return "/".join(f"{a:.0f}" for a in d["altitudes_m"]) + " m"


def _plot_std(ratios: dict[str, Any], path: Path) -> None:
    names = ratios["parameters"]
    series: list[tuple[str, Any, str, str | None]] = [
        (f"{k} (expected)", v, _COLOURS.get(k, "tab:green"), None) for k, v in ratios["expected"].items()]
    series += [(f"{k} (measured)", v, _COLOURS.get(k, "tab:green"), "//") for k, v in ratios["measured"].items()]
    fig = _figure(8.0, 4.2)
    ax = fig.subplots()
    width = 0.8 / max(1, len(series))
    x = np.arange(len(names))
    for j, (label, v, col, hatch) in enumerate(series):
        vals = np.asarray(v, dtype=float)
        ax.bar(x + (j - (len(series) - 1) / 2) * width, vals, width, label=label, color=col,
               alpha=0.55 if hatch else 0.9, hatch=hatch, edgecolor="k", lw=0.4)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_yscale("log")
    ax.set_xticks(x, names)
    ax.set_ylabel("standard deviation / base design's")
    ax.set_title("Parameter standard deviation relative to the base design", fontsize=10)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    fig.savefig(path)


# --------------------------------------------------------------------------- page


def write_report(result: DesignResult, out_dir: str | os.PathLike[str]) -> dict[str, Path]:
    """Write the design report (PNGs and ``report.html``) into ``out_dir``; returns name -> path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc = to_jsonable(result.to_dict())
    files: dict[str, Path] = {}
    variables = list(CORRELATION_VARIABLES)

    panels = [("base", np.array(doc["base"]["correlation"]["matrix"]))]
    panels += [(f"{k} optimum", np.array(o["design"]["correlation"]["matrix"])) for k, o in doc["optima"].items()]
    _corr_panels(panels, variables, out / "correlation.png", "Correlation of the inputs (paper Figs. 19-22)")
    files["correlation.png"] = out / "correlation.png"

    curves = study_curves(doc)
    if curves:
        _plot_study(curves, out / "study.png")
        files["study.png"] = out / "study.png"
        sp = _study_panels(doc)
        _corr_panels(sp, variables, out / "correlation_study.png", "Correlation at optima of the study")
        files["correlation_study.png"] = out / "correlation_study.png"

    _plot_layout(result, doc, out / "layout.png")
    files["layout.png"] = out / "layout.png"
    ratios = std_ratios(doc)
    if ratios["expected"]:
        _plot_std(ratios, out / "std.png")
        files["std.png"] = out / "std.png"
    (out / "report.html").write_text(_html(result, doc, ratios, files), encoding="utf-8")
    files["report.html"] = out / "report.html"
    return files


def _fmt(v: Any, spec: str = ".3g") -> str:
    return "n/a" if v is None else format(v, spec)


def _html(result: DesignResult, doc: dict[str, Any], ratios: dict[str, Any], files: dict[str, Path]) -> str:
    e = html.escape
    plan = result.plan
    designs = [("base", doc["base"])] + [(f"{k} optimum", o["design"]) for k, o in doc["optima"].items()]
    obj_rows = "\n".join(
        f"<tr><td>{e(n)}</td><td>{_fmt(d['objectives']['paper'])}</td><td>{_fmt(d['max_abs_corr_all_pairs'])}</td>"
        f"<td>{_fmt(d['objectives']['d-optimal'], '.2f')}</td><td>{e(_alts(d))}</td><td>{d['n_usable']}</td>"
        f"<td>{'yes' if d['feasible'] else 'no'}</td></tr>" for n, d in designs)
    mic_rows = []
    for i, mid in enumerate(plan.mic_ids):
        cells = "".join(f"<td>{d['microphones'][i]['de_m']:+.1f} / {d['microphones'][i]['dn_m']:+.1f}</td>"
                        for _, d in designs[1:])
        lim = plan.max_shift[i]
        mic_rows.append(f"<tr><td>{e(mid)}</td><td>{doc['base']['microphones'][i]['e_m']:.1f} / "
                        f"{doc['base']['microphones'][i]['n_m']:.1f}</td><td>&plusmn;{lim[0]:g} / &plusmn;{lim[1]:g}"
                        f"</td>{cells}</tr>")
    opt_heads = "".join(f"<th>{e(n)}: shift east / north, m</th>" for n, _ in designs[1:])
    names = ratios["parameters"]
    std_rows = "\n".join(
        f"<tr><td>{e(k)}</td>" + "".join(f"<td>{_fmt(d['expected_std'][k])}</td>" for _, d in designs) + "</tr>"
        for k in names)
    std_heads = "".join(f"<th>{e(n)}</th>" for n, _ in designs)
    opt_info = "".join(
        f"<li>{e(k)}: {o['nit']} generations, {o['nfev']} evaluations; {e(o['message'])} Altitudes at bounds: "
        f"{e(', '.join(a or 'interior' for a in o['at_altitude_bound']))}; microphones at a displacement limit: "
        f"{e(', '.join(m for m, v in o['at_shift_limit'].items() if v) or 'none')}.</li>"
        for k, o in doc["optima"].items())
    settings = next(iter(doc["optima"].values()))["settings"] if doc["optima"] else {}
    ver_html = _verify_html(doc)
    study_html = ""
    if "study.png" in files:
        st = plan.doc["study"]
        study_html = (f"<h2>Objective against allowed displacement (Fig. 18)</h2><img src=\"study.png\" alt=\"study\">"
                      f"<p>One optimization per point ({st['maxiter']} generations, population {st['popsize']} per "
                      f"variable); each run starts from the best design of a range inside its own.</p>"
                      f"<img src=\"correlation_study.png\" alt=\"correlation at the largest displacement\">")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Measurement design: {e(plan.doc['name'])}</title>
<style>body{{font-family:sans-serif;max-width:1150px;margin:2em auto;color:#222}}
table{{border-collapse:collapse;margin:0.5em 0}}td,th{{border:1px solid #bbb;padding:3px 8px;text-align:right}}
th{{background:#eee}}img{{max-width:100%}}</style></head><body>
<h1>Measurement design: {e(plan.doc['name'])}</h1>
{''.join(f"<p><b>Warning:</b> {e(w)}.</p>" for w in doc.get("warnings") or [])}
<p>{e(plan.doc.get('description', ''))}</p>
<p>Card {e(plan.card.id)} (ansatz {e(plan.card.ansatz)}); pattern: racetrack, {plan.doc['pattern']['straight_m']:g} m
straights, {plan.doc['pattern']['radius_m']:g} m turns at {plan.doc['pattern']['speed_m_s']:g} m/s, {plan.n_reps}
repetition(s) of {plan.doc['pattern']['laps']} lap(s), {result.model.duration_s:.0f} s. Signal-to-noise distance
{plan.max_distance_m:.0f} m (card level averaged over the lower hemisphere falls to background
{plan.background_db:.1f} dB(A) + {plan.margin_db:g} dB). Samples every {1 / plan.doc['evaluation']['rate_hz']:g} s per
microphone; Fisher information scaled to {plan.doc['evaluation']['block_s']:g} s blocks.</p>
<h2>Objectives</h2>
<table><tr><th>design</th><th>paper objective: max |corr| (design pairs)</th><th>max |corr| (all pairs)</th>
<th>log det Fisher information</th><th>altitudes</th><th>usable samples</th><th>feasible</th></tr>
{obj_rows}</table>
<p>The paper objective is the largest absolute correlation among power, polar angle, distance and bank angle over the
pairs a design can change: power and bank angle move together through the turns' load factor whatever the layout,
so that pair is reported (all pairs column), not minimized.</p>
<ul>{opt_info}</ul>
<p>Optimizer: {e(str(settings.get('method', '')))}, seed {e(str(settings.get('seed', '')))}, population
{e(str(settings.get('popsize', '')))} per variable, at most {e(str(settings.get('maxiter', '')))} generations.
Displacement limits and altitude ranges: {e(str(settings.get('limits', '')))}; exclusion polygons:
{e(str(settings.get('exclusions', '')))}.</p>
<h2>Layout</h2><img src="layout.png" alt="layout">
<table><tr><th>microphone</th><th>base east / north, m</th><th>limit east / north, m</th>{opt_heads}</tr>
{''.join(mic_rows)}</table>
<h2>Correlation of the inputs (Figs. 19-22)</h2><img src="correlation.png" alt="correlation matrices">
{study_html}
<h2>Expected standard deviation of each parameter (Cramer-Rao, white noise)</h2>
<table><tr><th>parameter</th>{std_heads}</tr>
{std_rows}</table>
{'<img src="std.png" alt="standard deviation ratios">' if 'std.png' in files else ''}
{ver_html}
<p>All numbers: design.json; microphones and tracks: layout.geojson.</p>
</body></html>
"""


def _verify_html(doc: dict[str, Any]) -> str:
    ver = doc.get("verify")
    if not ver:
        return ("<h2>Closing the loop</h2><p>Not run (set verify.seeds in the plan or pass --verify N).</p>")
    e = html.escape
    names = ver["param_names"]
    designs = list(ver["designs"])
    heads = "".join(f"<th>{e(d)}: empirical std</th><th>{e(d)}: expected std</th>" for d in designs)
    rows = "\n".join(
        f"<tr><td>{e(k)}</td><td>{ver['truth'][i]:.4g}</td>" + "".join(
            f"<td>{_fmt(ver['designs'][d]['empirical_std'][i])}</td><td>{_fmt(ver['designs'][d]['expected_std'][i])}"
            f"</td>" for d in designs) + "</tr>" for i, k in enumerate(names))
    lines = []
    for d, v in ver["designs"].items():
        if "geometric_mean_empirical_std_ratio" in v:
            g = v["geometric_mean_empirical_std_ratio"]
            r = np.asarray(v["empirical_std_ratio_to_base"], dtype=float)
            better = int(np.sum(r < 1))
            lines.append(
                f"<p><b>{e(d)}</b>: the campaigns flown with this design scatter {1 / g:.1f} times less than with the "
                f"base design (geometric mean over the parameters of the empirical standard deviation ratio "
                f"{g:.3f}; expected {_fmt(v['geometric_mean_expected_std_ratio'])}); smaller for {better} of "
                f"{len(r)} parameters (ratios {', '.join(f'{x:.2f}' for x in r)}); root mean square error ratio "
                f"{_fmt(v['geometric_mean_rms_error_ratio'])}"
                + (f"; without the background parameter {1 / v['geometric_mean_empirical_std_ratio_without_background']:.1f}"
                   f" times" if v.get("geometric_mean_empirical_std_ratio_without_background") else "") + ".</p>")
    fails = "".join(f"<p>{e(d)}: {len(v['failures'])} fit(s) failed: {e('; '.join(v['failures']))}</p>"
                    for d, v in ver["designs"].items() if v["failures"])
    dur = ", ".join(f"{e(d)} {v['duration_s']:.1f} s" for d, v in ver["designs"].items())
    return f"""<h2>Closing the loop</h2>
<p>{len(ver['seeds'])} campaigns per design simulated with the card as truth (same pattern and flight time: {dur};
same microphone noise and background; seeds {ver['seeds'][0]}-{ver['seeds'][-1]}) and refitted with the card's ansatz
(horizontal samples within the signal-to-noise distance).</p>
{''.join(lines)}{fails}
<table><tr><th>parameter</th><th>truth</th>{heads}</tr>
{rows}</table>"""
