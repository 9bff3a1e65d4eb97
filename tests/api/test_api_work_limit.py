"""The work bound of a map (grid cells x time steps), checked before a direct map is evaluated or a job queued."""

from __future__ import annotations

import pytest
from service_helpers import KEY, assert_names_field
from test_api_contours import _request, flyover_csv

pytest.importorskip("rasterio")


def test_work_above_the_limit_is_413_before_any_job_is_queued(make_client):
    c = make_client(start_workers=False, api_keys=[KEY], max_work=1000.0)
    hdr = {"X-API-Key": KEY}
    n = flyover_csv().count("\n") - 1  # 301 samples
    for path in ("/contours", "/contours?job=true", "/jobs/contours"):
        body = assert_names_field(c.post(path, json=_request(substeps=2), headers=hdr), 413, "grid.resolution_m")
        assert f"x {2 * n} time steps" in body["detail"] and "limit of 1000" in body["detail"], body
    assert c.get("/jobs").json()["total"] == 0  # nothing was queued


def test_work_within_the_limit_is_served(make_client):
    # 10 m cells over the 600 m track with a 200 m margin: about 101 x 41 cells, 301 samples: about 1.2e6 cell-steps
    c = make_client(start_workers=False, max_work=2e6)
    r = c.post("/contours", json=_request())
    assert r.status_code == 200, r.text
    tight = make_client(start_workers=False, max_work=1e6)
    assert_names_field(tight.post("/contours", json=_request()), 413, "grid.resolution_m")
