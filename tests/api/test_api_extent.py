"""The web page's default map (sample route, 20 m cells, no margin): its lowest contour closes (issue 17)."""

from __future__ import annotations

import numpy as np
import pytest

rasterio = pytest.importorskip("rasterio")

WEB_DEFAULT = {"cards": ["demo-horizontal", "demo-climb", "demo-sink"], "grid": {"resolution_m": 20},
               "metrics": ["LAmax"], "levels": [45, 50, 55, 60, 65]}


def _extent_warnings(doc: dict) -> list[str]:
    """The map's warnings but the one that says the route flies demo-horizontal below the sample campaign's powers
    (README, "Powers a card was fitted at"; tests/test_cards_demo_power_range.py)."""
    warnings = doc["gisnoise"]["warnings"]
    assert sum("flying sample(s) outside the" in w for w in warnings) == 1
    return [w for w in warnings if "flying sample(s) outside the" not in w]


def _edge(a: np.ndarray) -> np.ndarray:
    return np.concatenate([a[0], a[-1], a[:, 0], a[:, -1]])


def test_web_default_closes_the_lowest_level_and_a_small_margin_is_flagged(client):
    route = client.get("/samples/route").json()
    req = {"trajectory": {"format": "geojson", "data": route}, **WEB_DEFAULT}
    r = client.post("/contours", json={**req, "output": "geotiff"})
    assert r.status_code == 200, r.text
    from rasterio.io import MemoryFile

    with MemoryFile(r.content) as mf, mf.open() as ds:
        lamax = ds.read(list(ds.descriptions).index("LAmax") + 1)
    assert lamax.max() > 65.0  # the map reaches the loudest level ...
    assert _edge(lamax).max() < 45.0  # ... and no edge cell reaches the lowest
    doc = client.post("/contours", json=req).json()
    assert _extent_warnings(doc) == []
    assert not any(f["properties"]["clipped"] for f in doc["features"])
    # the margin the page used to send: the 45 dB contour is cut, flagged and named
    small = client.post("/contours", json={**req, "grid": {"resolution_m": 20, "margin_m": 400}}).json()
    cut = {f["properties"]["level"] for f in small["features"] if f["properties"]["clipped"]}
    assert 45.0 in cut and 65.0 not in cut
    assert _extent_warnings(small)[0].startswith("LAmax 45")


def test_sel_asked_of_the_service_closes_its_lowest_contour(client):
    """SEL is contoured 10 dB above the map's levels and the default extent closes the lowest of them."""
    route = client.get("/samples/route").json()
    req = {"trajectory": {"format": "geojson", "data": route}, **WEB_DEFAULT, "metrics": ["LAmax", "SEL"],
           "grid": {"resolution_m": 40}}
    r = client.post("/contours", json={**req, "output": "geotiff"})
    assert r.status_code == 200, r.text
    from rasterio.io import MemoryFile

    with MemoryFile(r.content) as mf, mf.open() as ds:
        sel = ds.read(list(ds.descriptions).index("SEL") + 1)
    assert sel.max() > 75.0 and _edge(sel).max() < 45.0 + 10.0
    doc = client.post("/contours", json=req).json()
    assert _extent_warnings(doc) == []
    assert {f["properties"]["level"] for f in doc["features"] if f["properties"]["metric"] == "SEL"} == {
        55.0, 60.0, 65.0, 70.0, 75.0}
    assert not any(f["properties"]["clipped"] for f in doc["features"])
