"""The service applies the core's guards: implausible cards (422 naming the parameter) and the ground rule."""

from __future__ import annotations

from service_helpers import assert_names_field
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
    req = _request()
    del req["ground_h_m"]
    body = assert_names_field(client.post("/contours", json=req), 422, "ground_h_m")
    assert "--dem" in body["detail"] or "dem" in body["detail"]
