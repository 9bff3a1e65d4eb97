"""The measurement-design study (slow; run with ``scripts/study -k design``).

The sample plan (the paper's base solution: three repetitions of a racetrack at 60 m,
three microphones near the centre) is optimized for both objectives with the plan's
settings, the paper's Fig. 18 grid (displacements 0-200 m x altitude ranges 60, 50-150,
35-200 m) is run, and the loop is closed: campaigns simulated with the base, the paper
and the D-optimal designs (card as truth, same pattern and noise, many seeds) are
refitted and the scatter of the estimates compared.  The numbers are written into
``docs/design.md`` between the ``design-study`` markers.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest

from gisnoise.design import load_plan, run_design

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "sample_data" / "plans" / "paper_racetrack.json"
DOC = ROOT / "docs" / "design.md"
SEEDS = 60


def _tables(res, seconds: float) -> str:
    plan = res.plan
    lines = [f"Sample plan `{plan.doc['name']}`, card `{plan.card.id}`, signal-to-noise distance "
             f"{plan.max_distance_m:.0f} m, {res.model.duration_s:.0f} s of pattern; {seconds:.0f} s on 2 shared cores.",
             "", "| design | max abs corr (design pairs) | max abs corr (all pairs) | log det Fisher | altitudes, m "
             "| microphones at a displacement limit |", "|---|---|---|---|---|---|"]
    rows = [("base", res.base, None)] + [(f"{k} optimum", o.evaluation, o) for k, o in res.optima.items()]
    for name, ev, o in rows:
        lim = "-" if o is None else (", ".join(m for m, v in o.at_shift_limit.items() if v) or "none")
        lines.append(f"| {name} | {ev.max_abs_corr:.3f} | {ev.max_abs_corr_all:.3f} | {ev.log_det_fisher:.2f} | "
                     f"{' / '.join(f'{a:.0f}' for a in ev.design.altitudes)} | {lim} |")
    lines += ["", "Fig. 18 (paper objective, optimum per point):", "",
              "| altitude range, m | " + " | ".join(f"{s:g} m" for s in plan.doc["study"]["displacements_m"]) + " |",
              "|---|" + "---|" * len(plan.doc["study"]["displacements_m"])]
    for rng in plan.doc["study"]["altitude_ranges_m"]:
        pts = sorted((p for p in res.study if list(p.altitude_range_m) == rng), key=lambda p: p.max_shift_m)
        lines.append(f"| {rng[0]:g}-{rng[1]:g} | " + " | ".join(f"{p.value:.3f}" for p in pts) + " |")
    n_bounds = sum(p.altitudes_at_bounds for p in res.study)
    n_limit = sum(p.at_shift_limit for p in res.study if p.max_shift_m > 0)
    lines += ["", f"Altitudes within 1 % of the range from a bound in {n_bounds} of {len(res.study)} study optima; "
                  f"a microphone within 1 % of its limit in {n_limit} of "
                  f"{sum(p.max_shift_m > 0 for p in res.study)} with a displacement allowed "
                  f"({plan.doc['study']['maxiter']} generations per point)."]
    ver = res.verify
    names = list(ver.param_names)
    lines += ["", f"Closing the loop: {len(ver.seeds)} seeds per design, flight time "
                  f"{ver.duration_s['base']:.1f} s each, fits failed: "
                  + ", ".join(f"{d} {len(f)}" for d, f in ver.failures.items()) + ".", "",
              "| parameter | truth | base: empirical std | base: expected std | "
              + " | ".join(f"{d}: empirical std | {d}: expected std | {d}: ratio to base" for d in ver.estimates
                           if d != "base") + " |",
              "|---|---|---|---|" + "---|---|---|" * (len(ver.estimates) - 1)]
    for i, k in enumerate(names):
        cells = [f"{ver.truth[i]:.4g}", f"{ver.empirical_std['base'][i]:.3g}", f"{ver.expected_std['base'][i]:.3g}"]
        for d in ver.estimates:
            if d != "base":
                cells += [f"{ver.empirical_std[d][i]:.3g}", f"{ver.expected_std[d][i]:.3g}", f"{ver.ratio(d)[i]:.3f}"]
        lines.append(f"| {k} | " + " | ".join(cells) + " |")
    lines.append("")
    for d in ver.estimates:
        if d != "base":
            g = ver.geometric_mean_ratio(d)
            bg = res.plan.card.model.background
            g_nb = ver.geometric_mean_ratio(d, exclude=(bg,))
            lines.append(f"* {d}: the estimates scatter {1 / g:.1f} times less than with the base design (geometric "
                         f"mean of the empirical std ratio {g:.3f}; expected from the design model "
                         f"{ver.geometric_mean_ratio(d, what='expected_std'):.3f}; rms error ratio "
                         f"{ver.geometric_mean_ratio(d, what='rms_error'):.3f}); without the background {bg}, whose "
                         f"base-design estimate is far from Gaussian: {1 / g_nb:.1f} times ({g_nb:.3f}).")
    return "\n".join(lines)


def test_design_study_and_closing_the_loop():
    plan = load_plan(PLAN)
    t0 = time.perf_counter()
    res = run_design(plan, verify_seeds=SEEDS)
    seconds = time.perf_counter() - t0

    # the paper's qualitative results at the plan's optimum (35-200 m, +-200 m)
    paper = res.optima["paper"]
    assert all(a in ("min", "max") for a in paper.at_altitude_bound), paper.design.altitudes
    assert {"min", "max"} <= set(paper.at_altitude_bound)
    assert any(paper.at_shift_limit.values())
    assert paper.value < 0.6 * paper.base_value
    dopt = res.optima["d-optimal"]
    assert dopt.evaluation.log_det_fisher > res.base.log_det_fisher + 10.0

    # Fig. 18: the objective falls with the allowed displacement and with the altitude spread
    st = plan.doc["study"]
    val = {(tuple(p.altitude_range_m), p.max_shift_m): p.value for p in res.study}
    for rng in st["altitude_ranges_m"]:
        v = [val[(tuple(rng), s)] for s in st["displacements_m"]]
        assert np.all(np.diff(v) <= 1e-12) and v[0] - v[-1] > 0.15, (rng, v)
    for s in st["displacements_m"]:
        v = [val[(tuple(r), s)] for r in st["altitude_ranges_m"]]
        assert np.all(np.diff(v) <= 1e-12) and v[0] - v[-1] > 0.05, (s, v)

    # closing the loop: the D-optimal design's refitted campaigns scatter less for every parameter,
    # and as much less as the design model's Cramer-Rao bounds say
    ver = res.verify
    assert all(len(f) == 0 for f in ver.failures.values()), ver.failures
    ratio = ver.ratio("d-optimal")
    assert np.all(ratio < 1.0), ratio
    assert ver.geometric_mean_ratio("d-optimal") < 0.5
    names = list(ver.param_names)
    for k in ("p0", "p1", "p2", "p3", "p4", "p5", "p6"):
        i = names.index(k)
        assert ver.empirical_std["d-optimal"][i] == pytest.approx(ver.expected_std["d-optimal"][i], rel=0.3), k

    text = DOC.read_text(encoding="utf-8")
    block = f"<!-- design-study:begin -->\n{_tables(res, seconds)}\n<!-- design-study:end -->"
    new = re.sub(r"<!-- design-study:begin -->.*?<!-- design-study:end -->", lambda _: block, text, flags=re.S)
    assert new != text or block in text
    DOC.write_text(new, encoding="utf-8")
