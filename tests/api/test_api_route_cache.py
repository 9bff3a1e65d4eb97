"""The route cache of POST /contours: a route sent again gives exactly what building it anew gives."""

from __future__ import annotations

import json

import numpy as np
import pytest
from service_helpers import REPO

from gisnoise.flight import routes
from gisnoise.service.routes_contours import ROUTE_CACHE
from gisnoise.service.trajcache import TrajectoryCache, route_key

ROUTE = json.loads((REPO / "gisnoise" / "data" / "routes" / "delivery_route.geojson").read_text())
ARRAYS = ("t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w", "phase", "rpm", "airspeed_m_s", "on_ground")
LEVELS = ((45, 55, 65), (50, 60))


def _request(levels=(45, 55, 65), **kw):
    req = {"trajectory": {"format": "waypoints", "data": ROUTE}, "cards": ["demo-horizontal", "demo-climb", "demo-sink"],
           "grid": {"resolution_m": 40, "margin_m": 200}, "levels": list(levels)}
    req.update(kw)
    return req


def _assert_same(a, b):
    for name in ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=name)
    assert a.metadata == b.metadata and a.source == b.source


def test_a_cached_route_gives_the_map_of_a_route_built_anew(client):
    size = ROUTE_CACHE.size
    try:
        ROUTE_CACHE.size = 0  # nothing kept: every request builds its trajectory anew (the truth)
        ROUTE_CACHE.clear()
        fresh = {lv: client.post("/contours", json=_request(lv)) for lv in LEVELS}
        fresh_tif = client.post("/contours", json=_request(output="geotiff"))
        assert len(ROUTE_CACHE) == 0
        ROUTE_CACHE.size = size
        hits0 = ROUTE_CACHE.hits
        client.post("/contours", json=_request())  # builds and keeps
        again = {lv: client.post("/contours", json=_request(lv)) for lv in LEVELS}
        again_tif = client.post("/contours", json=_request(output="geotiff"))
    finally:
        ROUTE_CACHE.size = size
    assert ROUTE_CACHE.hits == hits0 + 3  # the later requests used the kept trajectory
    for lv in LEVELS:
        assert again[lv].status_code == 200 and fresh[lv].status_code == 200, again[lv].text
        assert again[lv].content == fresh[lv].content  # byte-identical GeoJSON
    assert again_tif.status_code == 200 and again_tif.content == fresh_tif.content


def test_a_hit_is_a_copy_equal_to_the_route_built_anew():
    cache = TrajectoryCache(4)
    built = []

    def build():
        built.append(1)
        return routes.read_trajectory(json.loads(json.dumps(ROUTE)))

    key = route_key(ROUTE, "waypoints")
    first = cache.get(key, build)
    with pytest.raises(ValueError):
        first.h[:] = -1.0  # a trajectory's arrays are read-only: no caller changes what another one gets
    first.metadata["ground_h_m"] = 1e6  # its metadata is its own
    second = cache.get(key, build)
    assert len(built) == 1
    _assert_same(second, routes.read_trajectory(ROUTE))
    assert second.metadata is not first.metadata and second.metadata["ground_h_m"] != 1e6
    assert not second.h.flags.writeable  # shared safely: nobody can write into it


def test_the_key_is_the_canonical_json_and_the_cache_is_bounded():
    reordered = json.loads(json.dumps(ROUTE, sort_keys=True))
    assert route_key(ROUTE, "waypoints", 10) == route_key(reordered, "waypoints", 10)
    assert route_key(ROUTE, "waypoints", 10) != route_key(ROUTE, "waypoints", 11)
    moved = json.loads(json.dumps(ROUTE))
    moved["features"][1]["geometry"]["coordinates"][0] += 1e-6
    assert route_key(moved, "waypoints") != route_key(ROUTE, "waypoints")
    cache = TrajectoryCache(2)
    traj = routes.read_trajectory(ROUTE)
    for k in ("a", "b", "a", "c"):  # "a" used again, so "b" is the least recently used when "c" comes
        cache.get(k, lambda: traj)
    assert len(cache) == 2 and cache.hits == 1
    calls = []
    cache.get("b", lambda: calls.append(1) or traj)
    assert calls == [1]  # "b" was evicted
    cache.get("a", lambda: calls.append(2) or traj)
    assert calls == [1, 2]  # "b" coming back pushed out "a", the least recently used of "a" and "c"


def test_contours_in_memory_are_the_bytes_of_the_file(tmp_path):
    import pytest

    from gisnoise.errors import InputError
    from gisnoise.maps import make_map
    from gisnoise.model import cards as gcards

    cards = [gcards.load(REPO / "gisnoise" / "data" / "cards" / f"demo_{p}.json") for p in ("horizontal", "climb", "sink")]
    kw = dict(resolution_m=40, margin_m=200, levels=(45, 55, 65), outputs=("contours",))
    text = make_map(ROUTE, cards, None, **kw)["contours_text"]
    path = make_map(ROUTE, cards, tmp_path / "out", **kw)["contours"]
    assert text.encode("utf-8") == path.read_bytes()
    with pytest.raises(InputError) as err:  # a GeoTIFF needs a folder: refused, naming the field
        make_map(ROUTE, cards, None, **dict(kw, outputs=("levels", "contours")))
    assert err.value.field == "out"
