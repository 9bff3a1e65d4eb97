"""Hemisphere cards in the service: the card store keeps them, contour requests use them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_api_contours import _read_tif, flyover_csv

from gisnoise.model import dumps, import_hemisphere

pytest.importorskip("openpyxl")
rasterio = pytest.importorskip("rasterio")

M300 = Path(__file__).resolve().parents[1] / "data" / "hemispheres" / "Hem_Ed_M3_10_F05_Y_W_dw_2.xlsx"


@pytest.fixture(scope="module")
def m300():
    return import_hemisphere(M300, card_id="m300")


def test_store_keeps_a_hemisphere_card_and_contours_use_it(client, m300):
    doc = json.loads(dumps(m300))
    r = client.post("/cards", json=doc)
    assert r.status_code == 201, r.text
    got = client.get("/cards/m300")
    assert got.status_code == 200 and got.json() == doc
    h = 20.0
    req = {"trajectory": {"format": "csv", "text": flyover_csv(h=h, speed=5.0, dt=0.2, length_m=200.0)},
           "cards": ["m300"], "grid": {"resolution_m": 5, "margin_m": 30}, "levels": [45, 50],
           "ground_h_m": 0.0, "output": "geotiff"}
    r = client.post("/contours", json=req)
    assert r.status_code == 200, r.text
    meta, bands = _read_tif(r.content)
    lamax = np.nanmax(bands[list(meta["descriptions"]).index("LAmax")])
    d = h - 1.5  # receivers 1.5 m above flat ground at 0 m
    below = float(m300.level(m300.inputs(d, 0.0, -math.pi / 2, 1.0)))
    loudest_node = float(m300.overall_a_db.max()) - 20 * math.log10(d)
    # under the track the level passes straight below; no direction is louder than the loudest node
    assert below - 0.3 <= lamax <= loudest_node
    inline = dict(req, cards=[doc])
    r2 = client.post("/contours", json=inline)
    assert r2.status_code == 200 and r2.content == r.content


def test_bad_hemisphere_upload_is_refused_naming_the_field(client, m300):
    doc = json.loads(dumps(m300))
    doc["id"] = "bad-hemi"
    doc["measured"] = doc["measured"][:-1]
    r = client.post("/cards", json=doc)
    assert r.status_code in (400, 422), r.text
    assert "measured" in r.text


def test_an_implausible_hemisphere_is_refused_on_upload_naming_levels_db_and_by_reference_in_a_map(client, m300):
    """Every band of the M300 table at 200 dB (211.9 dB(A) at 1 m, 179 dB(A) at 40 m): before, the upload was
    stored (201) and every map with it was 422 naming 'parameters', a field hemisphere cards do not have. The
    upload runs the map's guard and names the table; a stored one from before is named by the request's reference."""
    doc = json.loads(dumps(m300))
    doc["id"] = "hemi-bad1"
    doc["levels_db"] = np.full(np.shape(doc["levels_db"]), 200.0).tolist()
    body = client.post("/cards", json=doc).json()
    assert body["field"] == "levels_db" and "levels_db" in body["detail"], body
    assert client.get("/cards/hemi-bad1").status_code == 404          # nothing stored
    req = {"trajectory": {"format": "csv", "text": flyover_csv(h=20.0, speed=5.0, dt=0.2, length_m=200.0)},
           "grid": {"resolution_m": 5, "margin_m": 30}, "levels": [45, 50], "ground_h_m": 0.0}
    r = client.post("/contours", json=dict(req, cards=[doc]))
    assert r.status_code == 422 and r.json()["field"] == "cards[0].levels_db", r.text
    folder = client.app.state.gisnoise.cards.root / "hemi-bad1"  # a store written before the upload's guard
    folder.mkdir(parents=True)
    (folder / "v1.json").write_text(json.dumps(doc), encoding="utf-8")
    r = client.post("/contours", json=dict(req, cards=["hemi-bad1"]))
    assert r.status_code == 422 and r.json()["field"] == "cards[0]", r.text
    assert "levels_db" in r.json()["detail"] and "hemi-bad1@1" in r.json()["detail"]


@pytest.mark.parametrize("field, change, said", [
    ("phi_deg", lambda doc: [math.radians(a) for a in doc["phi_deg"]], "the range of radians"),
    ("theta_deg", lambda doc: [math.radians(a) for a in doc["theta_deg"]], "the range of radians"),
    ("bands_hz", lambda doc: [f / 1000.0 for f in doc["bands_hz"]], "band 0.02 Hz lies below 10 Hz"),
])
def test_a_hemisphere_in_radians_or_khz_is_refused_on_upload_and_nothing_is_stored(client, m300, field, change, said):
    """The M300 card with its angles turned into radians (or its bands into kHz), the rest as imported: 422 naming
    the field, the store's listing and folder as before; the same document inline in a map request is refused
    naming it as well."""
    doc = json.loads(dumps(m300))
    doc["id"] = "hemi-units"
    doc[field] = change(doc)
    before = client.get("/cards").json()
    r = client.post("/cards", json=doc)
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["field"] == field and f"field '{field}': " in body["detail"] and said in body["detail"], body
    assert client.get("/cards").json() == before
    assert client.get("/cards/hemi-units").status_code == 404
    assert not (client.app.state.gisnoise.cards.root / "hemi-units").exists()
    req = {"trajectory": {"format": "csv", "text": flyover_csv(h=20.0, speed=5.0, dt=0.2, length_m=200.0)},
           "cards": [doc], "grid": {"resolution_m": 5, "margin_m": 30}, "levels": [45, 50], "ground_h_m": 0.0}
    r = client.post("/contours", json=req)
    assert r.status_code == 422 and r.json()["field"] == f"cards[0].{field}", r.text


def test_diagnose_job_with_a_hemisphere_card_is_refused_at_submission(client, m300):
    """A measured hemisphere has no parameters to extend: POST /jobs/diagnose refuses it at once (422 naming card_id,
    or card for a card file), and no job is queued; before, it answered 202 and the job failed later."""
    from test_api_campaign_jobs import _campaign_zip

    doc = json.loads(dumps(m300))
    assert client.post("/cards", json=doc).status_code == 201
    zipped = _campaign_zip()
    for data, files, field in (
        ({"card_id": "m300"}, {}, "card_id"),
        ({}, {"card": ("m300.json", dumps(m300).encode(), "application/json")}, "card"),
    ):
        r = client.post("/jobs/diagnose", data=data,
                        files={"campaign": ("c.zip", zipped, "application/zip"), **files})
        assert r.status_code == 422, r.text
        body = r.json()
        assert body["field"] == field and body["detail"].startswith(f"{field}")
        assert "card 'm300' is a measured hemisphere" in body["detail"]
    assert client.get("/jobs").json()["total"] == 0

