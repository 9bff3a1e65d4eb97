"""The files of a design run: ``design.json``, ``layout.geojson`` (microphones and tracks) and the report."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.design.report import write_report
from gisnoise.design.result import DesignResult
from gisnoise.jsonio import write_json

__all__ = ["layout_geojson", "write_outputs"]


def layout_geojson(result: DesignResult) -> dict[str, Any]:
    """RFC 7946 FeatureCollection: microphones and track (lon, lat, ellipsoidal height) of the base and each optimum.

    A microphone with no usable sample has a ``warning`` property; the collection's ``warnings`` member
    holds :attr:`DesignResult.warnings`.
    """
    plan, model = result.plan, result.model
    feats: list[dict[str, Any]] = []
    designs = {"base": result.base, **{k: o.evaluation for k, o in result.optima.items()}}
    tr = model.track
    step = max(1, len(tr["t"]) // 2000)
    for name, ev in designs.items():
        d = ev.design
        deaf = (f"no sample within the signal-to-noise distance ({plan.max_distance_m:.0f} m) of the pattern: this "
                "microphone records nothing usable")
        lat, lon, h = plan.frame.to_wgs84(d.mic_e, d.mic_n, plan.mic_height_m)
        for i, mid in enumerate(plan.mic_ids):
            feats.append({"type": "Feature",
                          "geometry": {"type": "Point", "coordinates": [round(float(lon[i]), 9),
                                                                        round(float(lat[i]), 9),
                                                                        round(float(h[i]), 3)]},
                          "properties": {"kind": "microphone", "design": name, "id": mid,
                                         "e_m": round(float(d.mic_e[i]), 3), "n_m": round(float(d.mic_n[i]), 3),
                                         "de_m": round(float(d.mic_e[i] - plan.base.mic_e[i]), 3),
                                         "dn_m": round(float(d.mic_n[i] - plan.base.mic_n[i]), 3),
                                         "max_shift_m": [float(s) for s in plan.max_shift[i]],
                                         "n_usable": ev.n_usable_per_mic[mid],
                                         **({"warning": deaf} if ev.n_usable_per_mic[mid] == 0 else {})}})
        u = tr["weights"] @ d.altitudes
        idx = np.unique(np.append(np.arange(0, len(u), step), len(u) - 1))
        tlat, tlon, th = plan.frame.to_wgs84(tr["e"][idx], tr["n"][idx], u[idx])
        coords = [[round(float(a), 8), round(float(b), 8), round(float(c), 2)] for a, b, c in zip(tlon, tlat, th,
                                                                                                  strict=True)]
        feats.append({"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords},
                      "properties": {"kind": "track", "design": name,
                                     "altitudes_m": [round(float(a), 3) for a in d.altitudes],
                                     "duration_s": round(model.duration_s, 2)}})
    # RFC 7946 section 6.1: a foreign member, beside the microphones' own "warning" properties
    return {"type": "FeatureCollection", "features": feats, "warnings": result.warnings}


def write_outputs(result: DesignResult, out_dir: str | os.PathLike[str], *, report: bool = True) -> dict[str, Path]:
    """Write ``design.json`` (variables, objectives, correlations, expected standard deviations,
    study and verification), ``layout.geojson`` (microphones and tracks) and, with ``report``,
    the report (:func:`gisnoise.design.report.write_report`).  Returns name -> path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {"design.json": write_json(result.to_dict(), out / "design.json", indent=1),
             "layout.geojson": write_json(layout_geojson(result), out / "layout.geojson")}
    if report:
        files.update(write_report(result, out))
    return files
