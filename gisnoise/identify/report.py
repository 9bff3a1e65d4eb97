"""The fit report: the paper's views of a fit as PNG, the numbers behind them as JSON, one HTML page.

:func:`write_report` writes into a folder

``timeseries.png/.json``
    measured vs model level per microphone over time (paper Fig. 6);
``directivity.png/.json``
    ``L_UAV`` over azimuth and polar angle at 30 m and a stated ``P_el`` (Fig. 7);
``correlation.png/.json``
    correlation matrix (Eq. 12-14) of UAV speed, propeller speed, electric power,
    bank angle, distance, polar angle, azimuth and residual (Fig. 15);
``residuals_<flight>.png`` and ``residuals.json``
    residual against time with bank angle, distance, power and speed (Figs. 11-14);
``parameters.json``
    the parameter table with Cramer-Rao and corrected standard deviations;
``report.html``
    all of it on one page.

The data functions (:func:`timeseries_data`, :func:`directivity_data`,
:func:`correlation_data`, :func:`residual_data`, :func:`parameter_table`) are
pure and return what is plotted; the plots use matplotlib's Agg canvas without
pyplot, so reports can be written from worker threads.  Needs the ``plot`` extra.
"""

from __future__ import annotations

import html
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.identify.result import FitResult
from gisnoise.model import get_ansatz
from gisnoise.reporting import correlation_axes, dump_json, figure, safe_name, with_gaps, write_view

__all__ = ["write_report", "timeseries_data", "directivity_data", "correlation_data", "residual_data",
           "parameter_table", "CORRELATION_VARIABLES"]

CORRELATION_VARIABLES = ("speed", "rpm", "power", "bank", "distance", "polar", "azimuth", "residual")
"""Variables of the correlation analysis (paper section 5.3.2), in this order."""

_UNITS = {"speed": "m/s", "rpm": "1/min", "power": "W", "bank": "deg", "distance": "m", "polar": "deg",
          "azimuth": "deg", "residual": "dB"}


def _require_samples(result: FitResult) -> None:
    if len(result.samples) != result.n:
        raise InputError("the fit result carries no samples (fit it with gisnoise.identify.fit.fit)", field="result")


def _flight_order(result: FitResult) -> list[str]:
    return [str(f) for f in dict.fromkeys(result.samples.flight.tolist())]


# --------------------------------------------------------------------------- data


def timeseries_data(result: FitResult) -> dict[str, Any]:
    """Measured and model level per microphone in time order (paper Fig. 6).

    Returns ``{"microphones": {mic: {"flight": [...], "t_s": [...], "measured_db": [...],
    "model_db": [...]}}, "flights": [...]}``; ``t_s`` is the emission time since the
    flight's start.
    """
    _require_samples(result)
    s = result.samples
    out: dict[str, Any] = {"flights": _flight_order(result), "microphones": {}}
    for mic in sorted(set(s.mic.tolist())):
        idx = np.nonzero(s.mic == mic)[0]
        fl = s.flight[idx].astype(str)
        rank = {f: i for i, f in enumerate(out["flights"])}
        order = idx[np.lexsort((s.t_e[idx], np.array([rank[f] for f in fl])))]
        out["microphones"][str(mic)] = {
            "flight": s.flight[order].astype(str).tolist(),
            "t_s": s.t_e[order].tolist(),
            "measured_db": result.measured[order].tolist(),
            "model_db": result.fitted[order].tolist(),
        }
    return out


def directivity_data(result: FitResult, *, distance_m: float = 30.0, p_el: float | None = None,
                     step_deg: float = 1.0) -> dict[str, Any]:
    """``L_UAV`` (background excluded) over azimuth x polar angle at one distance and power (Fig. 7).

    Parameters
    ----------
    result : FitResult
    distance_m : float
        Source-observer distance, m (the paper uses 30 m).
    p_el : float, optional
        Nondimensional power; default the median of the fitted samples.
    step_deg : float
        Grid step, deg; azimuth -180..180, polar -90..90.

    Returns
    -------
    dict
        ``phi_deg`` (na,), ``theta_deg`` (nt,), ``level_db`` (nt, na), the location of the
        maximum and, for the paper ansatzes, the analytic azimuth of the maximum
        ``p3 +- 90 deg`` (sign of ``p2 (p0 + p1 log10 P_el)``).  For an extended
        ansatz (``base+effect``) the base model's directivity is shown.
    """
    if not (distance_m > 0 and math.isfinite(distance_m)):
        raise InputError(f"distance_m must be a positive number, got {distance_m!r}", field="distance_m")
    model = get_ansatz(result.ansatz)
    params = result.params
    if "+" in model.name:  # an extended ansatz: the view shows its base model's directivity
        model = get_ansatz(model.name.split("+", 1)[0])
    p = np.array([params[k] for k in model.params])
    if p_el is None:
        _require_samples(result)
        p_el = float(np.median(result.samples.power_w)) / result.reference_power_w
    if not (p_el > 0 and math.isfinite(p_el)):
        raise InputError(f"p_el must be a positive number, got {p_el!r}", field="p_el")
    phi = np.arange(-180.0, 180.0 + step_deg / 2, step_deg)
    theta = np.arange(-90.0, 90.0 + step_deg / 2, step_deg)
    ph, th = np.meshgrid(np.radians(phi), np.radians(theta))
    x: dict[str, Any] = {"d": np.full(ph.shape, float(distance_m)), "phi": ph, "theta": th,
                         "p_el": np.full(ph.shape, float(p_el))}
    lvl = model.level_uav(p, x)
    it, ia = np.unravel_index(int(np.argmax(lvl)), lvl.shape)
    out: dict[str, Any] = {
        "distance_m": float(distance_m), "p_el": float(p_el), "ansatz": model.name,
        "phi_deg": phi.tolist(), "theta_deg": theta.tolist(), "level_db": lvl.tolist(),
        "max": {"phi_deg": float(phi[ia]), "theta_deg": float(theta[it]), "level_db": float(lvl[it, ia])},
    }
    prm = params
    if all(k in prm for k in ("p2", "p3")):
        gain = prm.get("p0", 0.0) + prm.get("p1", 0.0) * math.log10(p_el)
        sign = 1.0 if prm["p2"] * gain >= 0 else -1.0
        a = math.degrees(math.remainder(prm["p3"] + sign * math.pi / 2, 2 * math.pi))
        out["analytic_max_phi_deg"] = a
    return out


def _columns(result: FitResult) -> tuple[list[str], list[np.ndarray], list[str]]:
    s = result.samples
    cols = {
        "speed": s.speed_m_s if s.airspeed_m_s is None or not np.all(np.isfinite(s.airspeed_m_s))
        else np.asarray(s.airspeed_m_s, dtype=float),
        "rpm": None if s.rpm is None else np.asarray(s.rpm, dtype=float),
        "power": np.asarray(s.power_w, dtype=float),
        "bank": np.asarray(s.roll, dtype=float),
        "distance": np.asarray(s.d, dtype=float),
        "polar": np.degrees(s.theta),
        "azimuth": np.degrees(s.phi),
        "residual": result.residuals,
    }
    names, arrays, left_out = [], [], []
    for k in CORRELATION_VARIABLES:
        v = cols[k]
        if v is None:
            left_out.append(f"{k}: not in the data")
        elif not np.all(np.isfinite(v)):
            left_out.append(f"{k}: has missing values")
        elif np.ptp(v) == 0:
            left_out.append(f"{k}: constant")
        else:
            names.append(k)
            arrays.append(v)
    return names, arrays, left_out


def correlation_data(result: FitResult) -> dict[str, Any]:
    """Correlation matrix of the inputs and the residual (paper Eq. 12-14, Fig. 15).

    ``Corr_ij = Cov(X_i, X_j) / sqrt(Var X_i Var X_j)`` with the 1/N moments over all
    fitted samples.  Speed is the airspeed when the log has it, else the ground
    speed; bank, polar angle and azimuth in degrees.  Variables absent from the
    data or constant are left out and listed with the reason.
    """
    _require_samples(result)
    names, arrays, left_out = _columns(result)
    x = np.vstack(arrays)
    xc = x - x.mean(axis=1, keepdims=True)
    cov = xc @ xc.T / x.shape[1]  # Eq. 13
    var = np.diag(cov)  # Eq. 14
    corr = cov / np.sqrt(np.outer(var, var))  # Eq. 12
    np.fill_diagonal(corr, 1.0)
    return {"variables": names, "units": [_UNITS[k] for k in names], "matrix": corr.tolist(),
            "left_out": left_out, "n": int(x.shape[1])}


def residual_data(result: FitResult) -> dict[str, Any]:
    """Per flight: residual per microphone, bank angle, distance, power and speed over time (Figs. 11-14)."""
    _require_samples(result)
    s = result.samples
    out: dict[str, Any] = {"flights": {}}
    for fl in _flight_order(result):
        f_idx = np.nonzero(s.flight == fl)[0]
        mics = {}
        for mic in sorted(set(s.mic[f_idx].tolist())):
            idx = f_idx[s.mic[f_idx] == mic]
            idx = idx[np.argsort(s.t_e[idx], kind="stable")]
            mics[str(mic)] = {"t_s": s.t_e[idx].tolist(), "residual_db": result.residuals[idx].tolist(),
                              "distance_m": s.d[idx].tolist()}
        # flight state: one row per distinct emission time
        t_all, first = np.unique(s.t_e[f_idx], return_index=True)
        rows = f_idx[first]
        out["flights"][fl] = {
            "microphones": mics,
            "t_s": t_all.tolist(),
            "bank_deg": s.roll[rows].tolist(),
            "power_w": s.power_w[rows].tolist(),
            "speed_m_s": s.speed_m_s[rows].tolist(),
            "rms_db": float(np.sqrt(np.mean(result.residuals[f_idx] ** 2))),
        }
    return out


def parameter_table(result: FitResult) -> dict[str, Any]:
    """Parameters with Cramer-Rao and autocorrelation-corrected standard deviations, plus fit statistics."""
    rows = []
    try:
        units = dict(zip(result.param_names, get_ansatz(result.ansatz).units, strict=False))
    except InputError:  # an ansatz passed as an object, not in the registry: units not stated
        units = {}
    for i, k in enumerate(result.param_names):
        rows.append({"name": k, "unit": units.get(k, ""), "value": float(result.p[i]),
                     "std_cramer_rao": float(result.std_array[i]),
                     "std_corrected": float(result.std_corrected_array[i]),
                     "fixed": k in result.fixed, "at_bound": k in result.at_bounds})
    return {
        "ansatz": result.ansatz, "phase": result.phase, "reference_power_w": result.reference_power_w,
        "parameters": rows, "correlation": result.corr.tolist(), "noise_std_db": dict(result.noise_std),
        "n": result.n, "cost_neg_log_likelihood": result.cost, "aic": result.aic, "bic": result.bic,
        "rms_db": result.rms_db, "iterations": result.iterations, "success": result.success,
        "message": result.message, "autocorrelation_lag_samples": result.autocorr_lag,
    }


# --------------------------------------------------------------------------- plots


def _figure(w: float, h: float) -> Any:
    return figure(w, h, dpi=110, report="fit")


def _plot_timeseries(data: dict[str, Any], path: Path) -> None:
    mics = data["microphones"]
    fig = _figure(10, 1.0 + 2.2 * len(mics))
    axes = fig.subplots(len(mics), 1, sharex=True, squeeze=False)[:, 0]
    # flights side by side on one axis: each offset by the previous ones' end + 10 s
    offsets, end = {}, 0.0
    for fl in data["flights"]:
        offsets[fl] = end
        ts = [max((t for t, f in zip(m["t_s"], m["flight"], strict=True) if f == fl), default=0.0)
              for m in mics.values()]
        end += max(ts) + 10.0
    for ax, (mic, m) in zip(axes, mics.items(), strict=True):
        fl = np.array(m["flight"])
        t = np.array(m["t_s"]) + np.array([offsets[f] for f in fl]) if len(fl) else np.array([])
        tm, meas, mod = with_gaps(t, np.array(m["measured_db"]), np.array(m["model_db"]))
        ax.plot(tm, meas, color="0.45", lw=0.7, label="measured")
        ax.plot(tm, mod, color="tab:red", lw=1.0, label="model")
        ax.set_ylabel(f"{mic}\nL_A / dB(A)")
        ax.grid(alpha=0.3)
        for f, o in offsets.items():
            if len(data["flights"]) > 1:
                ax.axvline(o, color="0.7", lw=0.6)
                ax.text(o, 1.0, f" {f}", transform=ax.get_xaxis_transform(), va="top", fontsize=7)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title("Measured vs model level (paper Fig. 6)")
    axes[-1].set_xlabel("emission time / s" + (" (flights one after the other)" if len(offsets) > 1 else ""))
    fig.savefig(path)


def _plot_directivity(data: dict[str, Any], path: Path) -> None:
    fig = _figure(8, 4.8)
    ax = fig.subplots()
    lvl = np.array(data["level_db"])
    pc = ax.pcolormesh(data["phi_deg"], data["theta_deg"], lvl, shading="nearest", cmap="viridis")
    cs = ax.contour(data["phi_deg"], data["theta_deg"], lvl, colors="w", linewidths=0.5)
    ax.clabel(cs, fontsize=7, fmt="%.0f")
    ax.plot(data["max"]["phi_deg"], data["max"]["theta_deg"], "r+", ms=12, mew=2, label="maximum")
    if "analytic_max_phi_deg" in data:
        ax.axvline(data["analytic_max_phi_deg"], color="r", ls="--", lw=0.8, label="p3 + 90 deg")
    fig.colorbar(pc, ax=ax, label="L_UAV / dB(A)")
    ax.set_xlabel("azimuth phi / deg (0 ahead, +90 starboard)")
    ax.set_ylabel("polar angle theta / deg (-90 below)")
    ax.set_title(f"Directivity at {data['distance_m']:g} m, P_el = {data['p_el']:.2f} (paper Fig. 7)")
    ax.legend(loc="lower left", fontsize=8)
    fig.savefig(path)


def _plot_correlation(data: dict[str, Any], path: Path) -> None:
    fig = _figure(6.4, 5.6)
    ax = fig.subplots()
    im = correlation_axes(ax, np.array(data["matrix"]), data["variables"], fontsize=7)
    fig.colorbar(im, ax=ax, label="correlation coefficient")
    ax.set_title("Correlation of inputs and residual (paper Fig. 15)")
    fig.savefig(path)


def _plot_residuals(fl: str, data: dict[str, Any], path: Path) -> None:
    fig = _figure(10, 8)
    ax = fig.subplots(4, 1, sharex=True)
    for mic, m in data["microphones"].items():
        t, r, d = with_gaps(np.array(m["t_s"]), np.array(m["residual_db"]), np.array(m["distance_m"]))
        ax[0].plot(t, r, lw=0.7, label=mic)
        ax[2].plot(t, d, lw=0.8, label=mic)
    ax[0].axhline(0.0, color="k", lw=0.6)
    ax[0].set_ylabel("residual\nmeasured - model / dB")
    ax[0].legend(fontsize=7, ncol=4, loc="upper right")
    t, bank, pw, sp = with_gaps(np.array(data["t_s"]), np.array(data["bank_deg"]), np.array(data["power_w"]),
                                 np.array(data["speed_m_s"]))
    ax[1].plot(t, bank, color="tab:purple", lw=0.8)
    ax[1].set_ylabel("bank angle / deg")
    ax[2].set_ylabel("distance / m")
    ax[3].plot(t, pw, color="tab:orange", lw=0.8)
    ax[3].set_ylabel("power / W", color="tab:orange")
    a2 = ax[3].twinx()
    a2.plot(t, sp, color="tab:green", lw=0.8)
    a2.set_ylabel("speed / (m/s)", color="tab:green")
    ax[3].set_xlabel("emission time / s")
    for a in ax:
        a.grid(alpha=0.3)
    ax[0].set_title(f"Flight {fl}: residual with bank angle, distance, power and speed (paper Figs. 11-14); "
                    f"rms {data['rms_db']:.2f} dB")
    fig.savefig(path)


def write_report(result: FitResult, out_dir: str | os.PathLike[str], *, distance_m: float = 30.0,
                 p_el: float | None = None, title: str | None = None) -> dict[str, Path]:
    """Write the fit report (PNGs, JSON numbers, ``report.html``) into ``out_dir``.

    Parameters
    ----------
    result : FitResult
        A fit made from :class:`gisnoise.measure.samples.Samples` (it carries them).
    out_dir : path
        Folder, created when missing.
    distance_m, p_el : float
        Distance (m) and nondimensional power of the directivity view; ``p_el``
        defaults to the median of the data.
    title : str, optional
        Page title.

    Returns
    -------
    dict
        Name -> path of every file written.
    """
    _require_samples(result)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}

    ts = timeseries_data(result)
    write_view(out, "timeseries", ts, _plot_timeseries, files)

    dr = directivity_data(result, distance_m=distance_m, p_el=p_el)
    write_view(out, "directivity", dr, _plot_directivity, files)

    cr = correlation_data(result)
    write_view(out, "correlation", cr, _plot_correlation, files)

    rs = residual_data(result)
    dump_json(rs, out / "residuals.json")
    files["residuals.json"] = out / "residuals.json"
    res_pngs = []
    for fl, d in rs["flights"].items():
        p = out / f"residuals_{safe_name(fl)}.png"
        _plot_residuals(fl, d, p)
        files[p.name] = p
        res_pngs.append((fl, p.name))

    pt = parameter_table(result)
    dump_json(pt, out / "parameters.json")
    files["parameters.json"] = out / "parameters.json"

    page = _html(result, pt, cr, dr, res_pngs, title)
    (out / "report.html").write_text(page, encoding="utf-8")
    files["report.html"] = out / "report.html"
    return files


def _html(result: FitResult, pt: dict[str, Any], cr: dict[str, Any], dr: dict[str, Any],
          res_pngs: list[tuple[str, str]], title: str | None) -> str:
    e = html.escape
    title = title or f"Fit report: {result.ansatz}, phase {result.phase or 'mixed'}"
    rows = "\n".join(
        f"<tr><td>{e(r['name'])}</td><td>{e(r['unit'] or '?')}</td><td>{r['value']:.5g}</td>"
        f"<td>{r['std_cramer_rao']:.3g}</td>"
        f"<td>{r['std_corrected']:.3g}</td><td>{'fixed' if r['fixed'] else ('at bound' if r['at_bound'] else '')}"
        f"</td></tr>" for r in pt["parameters"])
    noise = ", ".join(f"{e(m)}: {s:.2f} dB" for m, s in result.noise_std.items())
    left = ("<p>Left out of the correlation matrix: " + e("; ".join(cr["left_out"])) + "</p>") if cr["left_out"] else ""
    res = "\n".join(f"<h3>Flight {e(f)}</h3><img src=\"{e(p)}\" alt=\"residuals of flight {e(f)}\">"
                    for f, p in res_pngs)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{e(title)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}}
table{{border-collapse:collapse}}td,th{{border:1px solid #bbb;padding:3px 8px;text-align:right}}
th{{background:#eee}}img{{max-width:100%}}</style></head><body>
<h1>{e(title)}</h1>
<p>Output-error maximum-likelihood fit, one noise variance per microphone. {e(result.message)}.</p>
<p>n = {result.n} samples, negative log-likelihood {result.cost:.2f}, AIC {result.aic:.1f}, BIC {result.bic:.1f},
rms residual {result.rms_db:.2f} dB, reference power {result.reference_power_w:g} W.</p>
<p>Measurement noise (standard deviation per microphone): {noise}.</p>
<h2>Parameters</h2>
<table><tr><th>parameter</th><th>unit</th><th>value</th><th>std (Cramer-Rao)</th><th>std (corrected for residual
autocorrelation)</th><th></th></tr>
{rows}</table>
<p>Corrected: Morelli &amp; Klein sandwich with the residual autocorrelation up to lag
{2 * result.autocorr_lag} (first zero crossing {result.autocorr_lag} samples).</p>
<h2>Measured vs model (Fig. 6)</h2><img src="timeseries.png" alt="measured vs model per microphone">
<h2>Directivity (Fig. 7)</h2><img src="directivity.png" alt="directivity">
<p>L_UAV at {dr['distance_m']:g} m and P_el = {dr['p_el']:.3f}, background excluded; maximum at azimuth
{dr['max']['phi_deg']:.0f} deg, polar angle {dr['max']['theta_deg']:.0f} deg.</p>
<h2>Correlation analysis (Eq. 12-14, Fig. 15)</h2><img src="correlation.png" alt="correlation matrix">
{left}
<h2>Residual against time (Figs. 11-14)</h2>
{res}
<p>The numbers behind each figure: timeseries.json, directivity.json, correlation.json, residuals.json,
parameters.json.</p>
</body></html>
"""
