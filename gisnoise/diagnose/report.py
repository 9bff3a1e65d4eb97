"""The diagnosis report: figures, the numbers behind them and ``report.html``.

:func:`write_report` turns a :class:`gisnoise.diagnose.Diagnosis` into

``timeline_<flight>.png``
    Residual of the card against emission time, one axis per microphone, flight
    regimes shaded (turns, climb, sink, hover), flagged segments marked.
``inputs.png``
    Held-out baseline residual against each candidate input (binned means with
    standard errors): |bank|, distance, polar and azimuth angle, Mach number
    towards the observer, reflection delay, downwind range, rpm.
``before_after.png``
    Held-out residual before and after adding each of the top candidates,
    against that candidate's input.
``report.html``
    Verdict, candidate table (significance, RMS on fitted and held-out data,
    shrinkage, evidence, biased base parameters), segment table, statistics by
    regime, microphone and geometry, and the figures.

Each figure's numbers are written as JSON beside it (``timeline.json``,
``inputs.json``, ``before_after.json``) so tests check numbers, not pixels.
matplotlib (``gisnoise[plot]``) is imported on use with the Agg canvas.
"""

from __future__ import annotations

import html
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.diagnose.diagnosis import Diagnosis
from gisnoise.errors import InputError
from gisnoise.model import effects as _effects
from gisnoise.reporting import dump_json, figure, safe_name, with_gaps, write_view

__all__ = ["write_report", "timeline_data", "inputs_data", "before_after_data", "candidate_inputs",
           "EFFECT_INPUT"]

_REGIME_COLOURS = {"turn": "#ffbf80", "climb": "#a6d96a", "sink": "#80cdc1", "hover": "#d9a6e0",
                   "transition": "#c6c6c6"}

EFFECT_INPUT = {
    "bank_angle": "bank_abs_deg",
    "atmospheric_absorption": "distance_m",
    "ground_reflection": "reflection_delay_ms",
    "doppler": "mach_towards",
    "emission_time": "mach_towards",
    "wind": "downwind_range_100m",
    "rpm": "rpm",
    "background_event": "time_s",
}
"""The input each effect's before/after figure is drawn against."""

_LABELS = {
    "bank_abs_deg": "|bank| (deg)",
    "distance_m": "distance (m)",
    "polar_deg": "polar angle (deg)",
    "azimuth_deg": "azimuth (deg)",
    "mach_towards": "Mach number towards the microphone",
    "reflection_delay_ms": "ground-reflection delay (ms)",
    "downwind_range_100m": "downwind range (100 m, reported wind)",
    "rpm": "propeller speed (1/min)",
    "time_s": "emission time (s)",
}


def candidate_inputs(diag: Diagnosis) -> dict[str, np.ndarray]:
    """The per-sample inputs of the candidate effects that the data hold (NaN where undefined)."""
    s = diag.samples
    x = dict(s.inputs(1.0))
    x["mic"] = s.mic.astype(str)
    out: dict[str, np.ndarray] = {
        "bank_abs_deg": np.abs(s.roll),
        "distance_m": s.d,
        "polar_deg": np.degrees(s.theta),
        "azimuth_deg": np.degrees(s.phi),
        "time_s": s.t_e,
    }
    if _effects.speed_of_sound(s.meta) is not None:
        out["mach_towards"] = _effects.mach_towards(x)
        if _effects.mic_height_agl(x) is not None:
            try:
                out["reflection_delay_ms"] = 1000.0 * _effects.reflection_delay(x)
            except InputError:
                pass
    w = (s.meta or {}).get("weather") or {}
    if w.get("wind_from_deg") is not None:
        to = math.radians(float(w["wind_from_deg"]) + 180.0)
        h = s.mic_enu[:, :2] - s.uav_enu[:, :2]
        rh = np.linalg.norm(h, axis=1)
        out["downwind_range_100m"] = (h[:, 0] * math.sin(to) + h[:, 1] * math.cos(to)) / 100.0
        out["downwind_range_100m"][rh < 1.0] = 0.0
    if s.rpm is not None:
        out["rpm"] = np.asarray(s.rpm, dtype=float)
    return out


def _binned(v: np.ndarray, r: np.ndarray, bins: int = 12) -> dict[str, list[float]]:
    ok = np.isfinite(v) & np.isfinite(r)
    v, r = v[ok], r[ok]
    if len(v) < 2 * bins or np.ptp(v) == 0:
        return {"centre": [], "mean_db": [], "sem_db": [], "n": []}
    edges = np.unique(np.quantile(v, np.linspace(0.0, 1.0, bins + 1)))
    idx = np.clip(np.searchsorted(edges, v, side="right") - 1, 0, len(edges) - 2)
    out: dict[str, list[float]] = {"centre": [], "mean_db": [], "sem_db": [], "n": []}
    for i in range(len(edges) - 1):
        m = idx == i
        if m.sum() < 2:
            continue
        out["centre"].append(float(np.mean(v[m])))
        out["mean_db"].append(float(np.mean(r[m])))
        out["sem_db"].append(float(np.std(r[m], ddof=1) / math.sqrt(m.sum())))
        out["n"].append(int(m.sum()))
    return out


def timeline_data(diag: Diagnosis) -> dict[str, Any]:
    """Per flight and microphone: emission time, card residual, flagged; regime intervals per flight."""
    s = diag.samples
    a = diag.arrays
    out: dict[str, Any] = {"flights": {}}
    for fl in sorted(set(s.flight.astype(str).tolist())):
        mf = s.flight.astype(str) == fl
        mics = {}
        for m in sorted(set(s.mic[mf].astype(str).tolist())):
            rows = np.flatnonzero(mf & (s.mic.astype(str) == m))
            rows = rows[np.argsort(s.t_e[rows])]
            mics[m] = {"t_s": s.t_e[rows].tolist(), "resid_db": a["resid_card"][rows].tolist(),
                       "flagged": a["flagged"][rows].astype(bool).tolist()}
        rows = np.flatnonzero(mf)
        rows = rows[np.argsort(s.t_e[rows])]
        reg = a["regime"][rows]
        spans = []
        if len(rows):
            cut = np.flatnonzero(reg[1:] != reg[:-1]) + 1
            for i0, i1 in zip(np.r_[0, cut], np.r_[cut, len(rows)], strict=True):
                spans.append({"regime": str(reg[i0]), "t0": float(s.t_e[rows[i0]]), "t1": float(s.t_e[rows[i1 - 1]])})
        out["flights"][fl] = {"microphones": mics, "regimes": spans,
                              "segments": [g for g in diag.result["segments"] if g["flight"] == fl]}
    return out


def inputs_data(diag: Diagnosis) -> dict[str, Any]:
    """Binned held-out baseline residual against each candidate input."""
    r = diag.arrays["oof_baseline"]
    return {"residual": "held-out baseline residual (measured - model), dB",
            "inputs": {k: {"label": _LABELS[k], **_binned(v, r)} for k, v in candidate_inputs(diag).items()}}


def before_after_data(diag: Diagnosis, *, top: int = 3) -> dict[str, Any]:
    """For the top-ranked fitted candidates: held-out residual before and after, against the effect's input."""
    inputs = candidate_inputs(diag)
    ranked = [e for e in diag.result["effects"] if e.get("rank") is not None and f"oof/{e['name']}" in diag.arrays]
    ranked.sort(key=lambda e: e["rank"])
    out: dict[str, Any] = {"candidates": []}
    base = diag.arrays["oof_baseline"]
    for e in ranked[:top]:
        key = EFFECT_INPUT.get(e["name"], "time_s")
        if key not in inputs:
            key = "time_s"
        ext = diag.arrays[f"oof/{e['name']}"]
        out["candidates"].append({
            "name": e["name"], "rank": e["rank"], "input": key, "label": _LABELS[key],
            "before": _binned(inputs[key], base), "after": _binned(inputs[key], ext),
            "rms_db_holdout_before": float(np.sqrt(np.mean(base ** 2))),
            "rms_db_holdout_after": float(np.sqrt(np.mean(ext ** 2))),
        })
    return out


# --------------------------------------------------------------------------- figures


def _figure(w: float, h: float) -> Any:
    return figure(w, h, dpi=100, report="diagnosis")


def _plot_timeline(fl: str, d: dict[str, Any], path: Path) -> None:
    mics = d["microphones"]
    fig = _figure(11, 1.0 + 2.0 * len(mics))
    axes = fig.subplots(len(mics), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (m, v) in zip(axes, mics.items(), strict=True):
        for sp in d["regimes"]:
            c = _REGIME_COLOURS.get(sp["regime"])
            if c:
                ax.axvspan(sp["t0"], sp["t1"], color=c, alpha=0.5, lw=0)
        t, r = with_gaps(np.asarray(v["t_s"]), np.asarray(v["resid_db"]))
        ax.plot(t, r, lw=0.6, color="#333333")
        f = np.asarray(v["flagged"], dtype=bool)
        ax.plot(np.asarray(v["t_s"])[f], np.asarray(v["resid_db"])[f], ".", ms=1.5, color="#d62728")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(f"{m}: resid. (dB)")
    axes[-1].set_xlabel("emission time (s)")
    handles = [_patch(c, k) for k, c in _REGIME_COLOURS.items()]
    axes[0].legend(handles=handles, loc="upper right", fontsize=7, ncol=len(handles))
    axes[0].set_title(f"flight {fl}: card residual (measured - model); red: flagged segments")
    fig.savefig(path)


def _patch(colour: str, label: str) -> Any:
    from matplotlib.patches import Patch

    return Patch(color=colour, alpha=0.5, label=label)


def _plot_inputs(d: dict[str, Any], path: Path) -> None:
    items = [(k, v) for k, v in d["inputs"].items() if v["centre"]]
    ncol = 3
    nrow = max(1, math.ceil(len(items) / ncol))
    fig = _figure(11, 2.6 * nrow)
    axes = fig.subplots(nrow, ncol, squeeze=False).ravel()
    for ax, (_k, v) in zip(axes, items, strict=False):
        ax.errorbar(v["centre"], v["mean_db"], yerr=v["sem_db"], fmt="o-", ms=3, lw=1)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel(v["label"])
        ax.set_ylabel("held-out residual (dB)")
    for ax in axes[len(items):]:
        ax.set_visible(False)
    fig.savefig(path)


def _plot_before_after(d: dict[str, Any], path: Path) -> None:
    c = d["candidates"]
    fig = _figure(11, 3.0)
    axes = fig.subplots(1, max(len(c), 1), squeeze=False)[0]
    for ax, e in zip(axes, c, strict=False):
        for key, col in (("before", "#d62728"), ("after", "#1f77b4")):
            b = e[key]
            ax.errorbar(b["centre"], b["mean_db"], yerr=b["sem_db"], fmt="o-", ms=3, lw=1, color=col,
                        label=f"{key}: rms {e[f'rms_db_holdout_{key}']:.2f} dB")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(f"#{e['rank']} {e['name']}", fontsize=9)
        ax.set_xlabel(e["label"])
        ax.set_ylabel("held-out residual (dB)")
        ax.legend(fontsize=7)
    fig.savefig(path)


# --------------------------------------------------------------------------- page


def _num(v: Any, fmt: str = ".3g") -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, float)):
        return format(v, fmt)
    return html.escape(str(v))


def _regime(seg: dict[str, Any]) -> str:
    """A segment's regime, with the shares of its regimes when it is mixed (``mixed: turn 55 %, straight 45 %``)."""
    if seg["regime"] != "mixed":
        return str(seg["regime"])
    return "mixed: " + ", ".join(f"{k} {100 * v:.0f} %" for k, v in (seg.get("regime_shares") or {}).items())


def write_report(diag: Diagnosis, out_dir: str | os.PathLike[str], *, title: str | None = None,
                 progress: Callable[[int, int], None] | None = None) -> dict[str, Path]:
    """Write figures, their numbers and ``report.html`` of a diagnosis into ``out_dir``.

    Returns name -> path of every file written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}
    tl = timeline_data(diag)
    dump_json(tl, out / "timeline.json")
    files["timeline.json"] = out / "timeline.json"
    total = len(tl["flights"]) + 2
    done = 0
    pngs = []
    for fl, d in tl["flights"].items():
        p = out / f"timeline_{safe_name(fl)}.png"
        _plot_timeline(fl, d, p)
        files[p.name] = p
        pngs.append((fl, p.name))
        done += 1
        if progress:
            progress(done, total)
    ip = inputs_data(diag)
    write_view(out, "inputs", ip, _plot_inputs, files)
    ba = before_after_data(diag)
    write_view(out, "before_after", ba, _plot_before_after, files)
    if progress:
        progress(total, total)
    (out / "report.html").write_text(_html(diag.result, pngs, title), encoding="utf-8")
    files["report.html"] = out / "report.html"
    return files


def _html(r: dict[str, Any], pngs: list[tuple[str, str]], title: str | None) -> str:
    e = html.escape
    v = r["verdict"]
    title = title or f"Diagnosis of card {r['card']['id']} ({r['card']['ansatz']}, {r['card']['phase']})"
    if v["effect"]:
        head = (f"<p class=verdict>Verdict: <b>{e(v['effect'])}</b>. Held-out RMS residual "
                f"{v['rms_db_holdout_baseline']:.2f} dB &rarr; {v['rms_db_holdout_extended']:.2f} dB "
                f"(shrinkage {v['holdout_shrinkage_pct']:.1f} %). {e(v.get('reason', ''))}.</p>"
                f"<p>Evidence: {e(v.get('evidence') or '')}.</p>")
        biased = v.get("biased_parameters") or []
        if biased:
            head += "<p>Base parameters the effect had biased: " + ", ".join(
                f"{e(b['name'])} {b['baseline']:.4g} &rarr; {b['extended']:.4g} ({b['shift_in_std']:+.1f} std)"
                for b in biased) + ".</p>"
    else:
        head = f"<p class=verdict>Verdict: <b>no effect</b> ({e(v.get('reason', ''))}).</p>"
    if len(v.get("effects") or []) > 1:
        head += "<p>Effects found together (forward selection): " + "; ".join(
            f"{e(x['effect'])} ({x['holdout_shrinkage_pct']:.1f} % held-out shrinkage)" for x in v["effects"]) + ".</p>"
    for sentence in (r.get("metadata") or {}).get("contradictions", []):
        head += f"<p>The data contradict the campaign's metadata: {e(sentence)}.</p>"
    for sentence in v.get("level_offsets") or []:
        head += f"<p>Not explained by any effect: {e(sentence)}.</p>"
    judged = (v.get("candidates_judged_with") or {}).get("sentence")
    if judged:
        head += f"<p>Judged with level offsets: {e(judged)}.</p>"
    eff_rows = []
    for x in r["effects"]:
        ev = x.get("evidence") or {}
        eff_rows.append(
            "<tr>" + "".join(f"<td>{c}</td>" for c in (
                _num(x.get("rank")), e(x["name"]), _num(x.get("testable")), _num(x.get("significant")),
                _num(x.get("p_value"), ".2e"), _num(x.get("rms_db_fit"), ".3f"),
                _num(x.get("rms_db_holdout"), ".3f"), _num(x.get("shrinkage_pct"), ".2f"),
                e(", ".join(b["name"] for b in x.get("biased_parameters", []))),
                e(ev.get("summary", "") or x.get("reason", "")))) + "</tr>")
    seg_rows = "\n".join(
        "<tr>" + "".join(f"<td>{c}</td>" for c in (
            e(g["flight"]), e(g["mic"]), _num(g["t0"], ".1f"), _num(g["t1"], ".1f"), e(_regime(g)), e(g["range"]),
            _num(g["rms_db"], ".2f"), _num(g["excess_db"], "+.2f"), _num(g.get("rms_db_holdout_baseline"), ".2f"),
            _num(g.get("rms_db_holdout_extended"), ".2f"), _num(g.get("shrinkage_pct"), ".1f"))) + "</tr>"
        for g in r["segments"])
    stat_html = []
    for key, label in (("by_regime", "regime"), ("by_mic", "microphone"), ("by_flight", "flight"),
                       ("by_distance", "distance"),
                       ("by_polar", "polar angle"), ("by_azimuth", "azimuth")):
        rows = "".join(f"<tr><td>{e(b['bin'])}</td><td>{b['n']}</td><td>{b['mean_db']:+.2f}</td>"
                       f"<td>{b['rms_db']:.2f}</td><td>{100 * b['flagged_fraction']:.0f} %</td></tr>"
                       for b in r["statistics"][key])
        stat_html.append(f"<h3>By {label}</h3><table><tr><th>{label}</th><th>n</th><th>mean (dB)</th>"
                         f"<th>rms (dB)</th><th>flagged</th></tr>{rows}</table>")
    corr = r["statistics"]["correlation_with_residual"]
    corr_txt = ", ".join(f"{e(k)} {c:+.2f}" for k, c in corr.items() if c is not None)
    timelines = "\n".join(f"<h3>Flight {e(f)}</h3><img src=\"{e(p)}\" alt=\"residual timeline of flight {e(f)}\">"
                          for f, p in pngs)
    b = r["baseline"]
    noise = ", ".join(f"{e(m)} {s:.2f} dB" for m, s in r["noise_std_db"].items())
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{e(title)}</title>
<style>body{{font-family:sans-serif;max-width:1150px;margin:2em auto;color:#222}}
table{{border-collapse:collapse;margin-bottom:1em}}td,th{{border:1px solid #bbb;padding:3px 7px}}
th{{background:#eee}}img{{max-width:100%}}.verdict{{font-size:1.2em}}</style></head><body>
<h1>{e(title)}</h1>
{head}
<p>{r['data']['n_samples']} samples of flights {e(', '.join(r['data']['flights']))} at microphones
{e(', '.join(r['data']['microphones']))}; held-out data: {e(r['data']['holdout'])}.
Card residual rms {b['rms_db_card']:.2f} dB; refitted baseline rms {b['rms_db_fit']:.2f} dB on the fitted data,
{b['rms_db_holdout']:.2f} dB held out. Measurement noise (fast scatter): {noise}.</p>
<h2>Candidate effects</h2>
<p>Significance: Wald test of the extension parameters with the autocorrelation-corrected covariance at
{r['alpha_per_test']:.1e} per candidate (family-wise {r['alpha']:g}); ranked by the held-out improvement of the
mean squared residual.</p>
<table><tr><th>rank</th><th>effect</th><th>testable</th><th>significant</th><th>p</th><th>rms fit (dB)</th>
<th>rms held out (dB)</th><th>shrinkage (%)</th><th>biased base parameters</th><th>evidence / reason</th></tr>
{''.join(eff_rows)}</table>
<h2>Before and after the top candidates</h2><img src="before_after.png" alt="held-out residual before and after">
<h2>Where the model misses</h2>
<p>Segments where the smoothed card residual exceeds what measurement noise explains
(window {r['data']['window_s']:g} s):</p>
<table><tr><th>flight</th><th>mic</th><th>t0 (s)</th><th>t1 (s)</th><th>regime</th><th>range</th>
<th>rms (dB)</th><th>mean excess (dB)</th><th>held-out rms before</th><th>after</th><th>shrinkage (%)</th></tr>
{seg_rows}</table>
{timelines}
<h2>Residual against candidate inputs</h2><img src="inputs.png" alt="residual against candidate inputs">
<p>Correlation of the card residual with: {corr_txt}.</p>
{''.join(stat_html)}
<p>The numbers behind the figures: timeline.json, inputs.json, before_after.json; everything else: diagnosis.json.</p>
</body></html>
"""
