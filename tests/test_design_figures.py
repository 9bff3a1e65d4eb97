"""design/layout.png: nothing drawn outside the canvas (axis labels, minus signs, legend) (issue 17)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gisnoise.design import layout_figure, load_plan, run_design
from gisnoise.jsonio import to_jsonable

pytest.importorskip("matplotlib")

PLAN = Path(__file__).resolve().parent.parent / "sample_data" / "plans" / "paper_racetrack.json"


def test_layout_figure_lies_inside_its_canvas(tmp_path):
    # both objectives: the long legend beside the axes pushed it and the y label off an 11 in canvas
    doc = json.loads(PLAN.read_text(encoding="utf-8"))
    doc["optimizer"] = {"maxiter": 3, "popsize": 4}
    (tmp_path / "plan.json").write_text(json.dumps(doc), encoding="utf-8")
    res = run_design(load_plan(tmp_path / "plan.json"), with_study=False, verify_seeds=0)
    assert set(res.optima) == {"paper", "d-optimal"}
    fig = layout_figure(res, to_jsonable(res.to_dict()))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    w, h = fig.get_size_inches()
    tight = fig.get_tightbbox(renderer)  # inches
    assert tight.x0 >= 0 and tight.y0 >= 0 and tight.x1 <= w and tight.y1 <= h, (tight, w, h)
    ax = fig.axes[0]
    canvas = fig.bbox  # pixels
    ticks = [t for loc, t in zip(ax.get_xticks(), ax.get_xticklabels(), strict=True)
             if min(ax.get_xlim()) <= loc <= max(ax.get_xlim())]
    ticks += [t for loc, t in zip(ax.get_yticks(), ax.get_yticklabels(), strict=True)
              if min(ax.get_ylim()) <= loc <= max(ax.get_ylim())]  # the drawn ones
    for artist in (ax.yaxis.label, ax.xaxis.label, ax.get_legend(), *ticks):
        if not artist.get_visible() or (hasattr(artist, "get_text") and not artist.get_text()):
            continue
        bb = artist.get_window_extent(renderer)
        assert bb.x0 >= canvas.x0 - 0.5 and bb.x1 <= canvas.x1 + 0.5, artist
        assert bb.y0 >= canvas.y0 - 0.5 and bb.y1 <= canvas.y1 + 0.5, artist
    assert any(t.get_text().startswith(("−", "-")) for t in ticks)
