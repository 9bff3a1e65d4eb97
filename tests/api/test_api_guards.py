"""The service applies the core's guards: implausible cards (422 naming the parameter) and the ground rule."""

from __future__ import annotations

import json

import pytest
from service_helpers import CARDS, assert_names_field, wait_job
from test_api_contours import _omni_card, _request


def _bad_card() -> dict:
    doc = _omni_card("bad")
    doc["parameters"] = dict(doc["parameters"], p2=-2958.0, p6=2.01)
    return doc


def test_implausible_card_upload_is_422_naming_p2(client):
    body = assert_names_field(client.post("/cards", json=_bad_card()), 422)
    assert "p2" in body["detail"]
    assert client.get("/cards/bad").status_code == 404          # nothing stored


def test_contour_with_an_implausible_inline_card_is_422_naming_p2(client):
    body = assert_names_field(client.post("/contours", json=_request(cards=[_bad_card()])), 422)
    assert "p2" in body["detail"]


def test_contour_of_an_airborne_track_without_ground_is_422_naming_ground_h_m(client):
    """The refusal names the request's field, not the command line's options (it said 'give --ground-height M
    (field ground_h_m) or --dem DEM.tif'; a request has no DEM)."""
    req = _request()
    del req["ground_h_m"]
    body = assert_names_field(client.post("/contours", json=req), 422, "ground_h_m")
    assert body["detail"].endswith("give ground_h_m"), body
    assert "--" not in body["detail"] and "dem" not in body["detail"].lower(), body


def _stored_without_the_guard(client, doc: dict) -> None:
    """Put ``doc`` into the store as version 1 as a store written before the guard refused it would hold it."""
    folder = client.app.state.gisnoise.cards.root / doc["id"]
    folder.mkdir(parents=True)
    (folder / "v1.json").write_text(json.dumps(doc), encoding="utf-8")


def test_a_card_stated_at_1e_9_m_is_refused_by_upload_and_map_naming_reference_distance_m(client):
    """A user's card: demo-horizontal with reference_distance_m 1e-9 was stored (201) and mapped at -168 to
    -149 dB(A) without a word. Upload and inline use are 422 naming it; a store that holds one from before
    refuses it by the request's reference."""
    doc = json.loads((CARDS / "demo_horizontal.json").read_text())
    doc.update(id="absurd6", reference_distance_m=1e-9)
    body = assert_names_field(client.post("/cards", json=doc), 422, "reference_distance_m")
    assert "1e-09" in body["detail"] and "\n" not in body["detail"]
    assert client.get("/cards/absurd6").status_code == 404          # nothing stored
    assert_names_field(client.post("/contours", json=_request(cards=[doc])), 422, "cards[0].reference_distance_m")
    _stored_without_the_guard(client, doc)
    body = assert_names_field(client.post("/contours", json=_request(cards=["demo-horizontal", "absurd6@1"])), 422,
                              "cards[1]")
    assert "reference_distance_m" in body["detail"] and "absurd6@1" in body["detail"]
    assert str(client.app.state.gisnoise.settings.data_dir) not in body["detail"]
    # a plausible card under that id is a new version, not a conflict with the refused one
    fixed = dict(doc, reference_distance_m=40.0)
    r = client.post("/cards", params={"new_version": "true"}, json=fixed)
    assert r.status_code == 201 and r.json()["version"] == 2, r.text
    assert client.post("/contours", json=_request(cards=["absurd6"])).status_code == 200


def test_linestring_without_ground_names_ground_h_m_not_the_command_line(client):
    """A LineString in the air without ground_h_m: 422 on ground_h_m saying to give it (it said --ground-height or
    --dem); the same request as a job fails with the same detail, field and status."""
    line = {"type": "Feature", "properties": {"times": [0, 60]},
            "geometry": {"type": "LineString", "coordinates": [[10.54, 52.243, 60], [10.55, 52.25, 60]]}}
    req = {"trajectory": {"format": "geojson", "data": line}, "cards": ["demo-horizontal"],
           "grid": {"resolution_m": 20, "margin_m": 100}}
    body = assert_names_field(client.post("/contours", json=req), 422, "ground_h_m")
    assert "give ground_h_m" in body["detail"] and "--" not in body["detail"], body
    r = client.post("/jobs/contours", json=req)
    assert r.status_code == 202, r.text
    info = wait_job(client, r.json()["id"])
    assert info["status"] == "failed"
    assert info["error"] == {"detail": body["detail"], "field": "ground_h_m", "status": 422}


@pytest.mark.parametrize("distance", [0.5, 1500.0])
def test_the_schema_states_the_reference_distance_range_the_guard_keeps(client, distance):
    """The OpenAPI schema says which reference distances a card may have; the plausibility guard refuses one
    outside exactly that range, naming the field."""
    from gisnoise.model.plausibility import REFERENCE_DISTANCE_RANGE_M

    spec = client.get("/openapi.json").json()
    prop = spec["components"]["schemas"]["CardDocument"]["properties"]["reference_distance_m"]
    assert (prop["minimum"], prop["maximum"]) == REFERENCE_DISTANCE_RANGE_M == (1.0, 1000.0)
    doc = json.loads((CARDS / "demo_horizontal.json").read_text())
    doc.update(id="range", reference_distance_m=distance)
    assert_names_field(client.post("/cards", json=doc), 422, "reference_distance_m")
