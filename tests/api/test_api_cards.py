"""Model-card endpoints: list, get, versioned upload that never overwrites, delete, API keys."""

from __future__ import annotations

import json

from service_helpers import CARDS, KEY, assert_names_field


def _doc(name: str = "demo_horizontal") -> dict:
    return json.loads((CARDS / f"{name}.json").read_text())


def test_seeded_store_lists_the_sample_cards(client):
    r = client.get("/cards")
    assert r.status_code == 200
    ids = {c["id"] for c in r.json()["cards"]}
    assert ids == {json.loads(p.read_text())["id"] for p in CARDS.glob("*.json")}
    horiz = next(c for c in r.json()["cards"] if c["id"] == "demo-horizontal")
    assert horiz["phases"] == ["horizontal", "transition"]
    assert horiz["version"] == 1 and horiz["versions"] == [1]
    assert {c["id"] for c in client.get("/cards", params={"phase": "climb"}).json()["cards"]} == {
        "demo-climb", "published-climb"}


def test_get_returns_the_card_document_unchanged(client):
    r = client.get("/cards/demo-horizontal")
    assert r.status_code == 200
    assert r.headers["content-type"].startswith("application/json")
    assert r.headers["x-card-version"] == "1"
    assert r.json() == _doc()


def test_upload_new_identical_conflict_and_new_version(client):
    doc = _doc()
    doc["id"] = "uploaded"
    r = client.post("/cards", json=doc)
    assert r.status_code == 201 and r.json()["version"] == 1
    assert r.headers["location"].endswith("/cards/uploaded?version=1")
    # identical re-upload: nothing new
    r = client.post("/cards", json=doc)
    assert r.status_code == 200 and r.json()["version"] == 1
    # a different card under the same id is refused, the stored one kept
    p0 = doc["parameters"]["p0"]
    changed = dict(doc, parameters=dict(doc["parameters"], p0=p0 + 6.0))
    body = assert_names_field(client.post("/cards", json=changed), 409, "id")
    assert "new_version" in body["detail"]
    assert client.get("/cards/uploaded").json()["parameters"]["p0"] == p0
    # asked for: a new version; both stay readable
    r = client.post("/cards", params={"new_version": "true"}, json=changed)
    assert r.status_code == 201 and r.json()["version"] == 2 and r.json()["versions"] == [1, 2]
    assert client.get("/cards/uploaded").json()["parameters"]["p0"] == p0 + 6.0
    assert client.get("/cards/uploaded", params={"version": 1}).json()["parameters"]["p0"] == p0
    assert client.get("/cards/uploaded/versions").json() == {"id": "uploaded", "versions": [1, 2]}


def test_invalid_uploads_name_the_field(client):
    doc = _doc()
    assert_names_field(client.post("/cards", json={k: v for k, v in doc.items() if k != "phase"}), 422, "phase")
    assert_names_field(client.post("/cards", json=dict(doc, phase="cruise")), 422, "phase")
    assert_names_field(client.post("/cards", json=dict(doc, schema="gisnoise/model-card/9")), 422, "schema")
    assert_names_field(client.post("/cards", json=dict(doc, parameters={"p1": 1.0})), 422, "parameters")
    assert_names_field(client.post("/cards", json=dict(doc, reference_power_w=-3)), 422, "reference_power_w")
    assert_names_field(client.post("/cards", json=dict(doc, ansatz="nope")), 422, "ansatz")
    assert_names_field(client.post("/cards", json=dict(doc, covariance=[[1.0]])), 422, "covariance")
    assert_names_field(client.post("/cards", json=dict(doc, id="../evil")), 422, "id")
    bad = dict(doc, parameters=dict(doc["parameters"], p0="loud"))
    assert_names_field(client.post("/cards", json=bad), 422, "parameters.p0")
    r = client.post("/cards", content=b"{not json", headers={"content-type": "application/json"})
    assert_names_field(r, 422, "body")
    assert client.get("/cards/evil").status_code == 404


def test_cards_with_chained_effects_are_stored(client):
    """A card of a chain ``base+e1+e2`` (the names the model builds on demand) is stored like any card;
    a chain with an unknown or repeated effect is refused naming ``ansatz``."""
    doc = _doc()
    doc.pop("covariance")
    doc.update(id="chain", ansatz="paper-offset+bank_angle+ground_reflection+doppler")
    doc["parameters"].update(k_bank=3.0, r_ground=0.8, f_ground=300.0, q_doppler=1.0)
    r = client.post("/cards", json=doc)
    assert r.status_code == 201, r.text
    assert client.get("/cards/chain").json()["ansatz"] == doc["ansatz"]
    assert_names_field(client.post("/cards", json=dict(doc, id="c2", ansatz="paper-offset+bank_angle+nope")), 422,
                       "ansatz")
    assert_names_field(client.post("/cards", json=dict(doc, id="c3", ansatz="paper-offset+bank_angle+bank_angle")),
                       422, "ansatz")
    assert_names_field(client.post("/cards", json=dict(doc, id="c4", ansatz="hemisphere+wind")), 422, "ansatz")


def test_get_and_delete_errors(client):
    """Errors about the path parameter name it as the URL template does, card_id (they said 'id', a field of the
    card document; the job paths already said job_id)."""
    assert_names_field(client.get("/cards/nope"), 404, "card_id")
    assert_names_field(client.get("/cards/demo-sink", params={"version": 7}), 404, "version")
    assert_names_field(client.get("/cards/demo-sink", params={"version": 0}), 422, "version")
    assert_names_field(client.get("/cards/bad id!"), 422, "card_id")
    assert_names_field(client.delete("/cards/nope"), 404, "card_id")
    assert_names_field(client.get("/cards/nope/versions"), 404, "card_id")
    body = client.get("/cards/nope").json()
    assert body["detail"].startswith("card_id: ") and "nope" in body["detail"]


def test_delete_one_version_then_all(client):
    doc = _doc("demo_sink")
    client.post("/cards", params={"new_version": "true"}, json=dict(doc, notes="second"))
    assert client.get("/cards/demo-sink/versions").json()["versions"] == [1, 2]
    assert client.delete("/cards/demo-sink", params={"version": 2}).status_code == 204
    assert client.get("/cards/demo-sink").json()["notes"] == doc["notes"]
    assert client.delete("/cards/demo-sink").status_code == 204
    assert client.get("/cards/demo-sink").status_code == 404
    assert "demo-sink" not in {c["id"] for c in client.get("/cards").json()["cards"]}


def test_deleted_seed_cards_stay_deleted_after_restart(make_client):
    c1 = make_client()
    assert c1.delete("/cards/published-sink").status_code == 204
    c2 = make_client()  # same data folder: the store exists, nothing is re-seeded
    assert c2.get("/cards/published-sink").status_code == 404


def test_writes_need_a_key_when_keys_are_configured(make_client):
    c = make_client(api_keys=[KEY, "other"])
    doc = dict(_doc(), id="keyed")
    assert_names_field(c.post("/cards", json=doc), 401, "X-API-Key")
    assert_names_field(c.post("/cards", json=doc, headers={"X-API-Key": "wrong"}), 403, "X-API-Key")
    assert_names_field(c.delete("/cards/demo-sink"), 401, "X-API-Key")
    assert c.post("/cards", json=doc, headers={"X-API-Key": KEY}).status_code == 201
    assert c.delete("/cards/keyed", headers={"X-API-Key": "other"}).status_code == 204
    # reads need no key
    assert c.get("/cards").status_code == 200 and c.get("/cards/demo-sink").status_code == 200


def test_keys_from_the_environment(monkeypatch, tmp_path):
    from gisnoise.service import Settings

    monkeypatch.setenv("GISNOISE_API_KEYS", " k1 ,k2,, ")
    monkeypatch.setenv("GISNOISE_DATA_DIR", str(tmp_path / "d"))
    monkeypatch.setenv("GISNOISE_WORKERS", "3")
    s = Settings()
    assert s.api_keys == ["k1", "k2"] and s.workers == 3 and s.data_dir == tmp_path / "d"


def test_docs_and_page_are_served_without_any_network(client):
    docs = client.get("/docs")
    assert docs.status_code == 200 and "/static/vendor/swagger-ui/swagger-ui-bundle.js" in docs.text
    page = client.get("/")
    assert page.status_code == 200 and "/static/vendor/leaflet/leaflet.js" in page.text
    for html in (docs.text, page.text):
        assert "https://" not in html
    for asset in ("/static/vendor/swagger-ui/swagger-ui-bundle.js", "/static/vendor/leaflet/leaflet.js",
                  "/static/app.js", "/static/style.css"):
        assert client.get(asset).status_code == 200, asset
    assert client.get("/openapi.json").json()["info"]["title"] == "gisnoise"


def test_listing_by_an_unknown_phase_is_refused_naming_the_field(client):
    """GET /cards?phase= filters by one of the flight phases; a misspelt phase is a 422 naming 'phase', not an
    empty list that looks like 'no card serves it'."""
    hover = client.get("/cards?phase=hover")
    assert hover.status_code == 200 and "demo-climb" in [c["id"] for c in hover.json()["cards"]]
    assert_names_field(client.get("/cards?phase=Hover"), 422, "phase")
    assert_names_field(client.get("/cards?phase=cruise"), 422, "phase")


def test_store_keeps_a_settled_listing_and_sees_every_change(tmp_path, monkeypatch):
    """A card folder's listing is kept by its stat once its last change is SETTLED_S old (no folder read per
    request), and a version another writer adds is seen at once: after a settled listing (the folder's time moves)
    and within the timestamp granularity of a recent change (same folder time: such a listing is not kept)."""
    import os
    import time
    from pathlib import Path

    from gisnoise.model import cards as gcards
    from gisnoise.service.cardstore import SETTLED_S, CardStore

    store = CardStore(tmp_path / "cards")
    doc = _doc()
    card = gcards.from_dict(doc)
    store.put(card)
    folder = tmp_path / "cards" / card.id
    old = time.time_ns() - int(5 * SETTLED_S * 1e9)
    os.utime(folder, ns=(old, old))
    reads: list[Path] = []
    iterdir = Path.iterdir
    monkeypatch.setattr(Path, "iterdir", lambda self: (reads.append(self), iterdir(self))[1])
    assert store.versions(card.id) == [1] and store.versions(card.id) == [1]
    assert reads == [folder]  # the second listing is the kept one
    p0 = doc["parameters"]["p0"]

    def add(v: int) -> None:  # another writer adds version v
        (folder / f"v{v}.json").write_text(gcards.dumps(gcards.from_dict(
            dict(doc, parameters=dict(doc["parameters"], p0=p0 + v)))), encoding="utf-8")

    add(2)  # after a settled listing: the folder's time moves
    assert store.versions(card.id) == [1, 2] and store.get(card.id).card.parameters["p0"] == p0 + 2
    recent = os.stat(folder).st_mtime_ns
    add(3)  # within the timestamp granularity of the change before: the folder's time as it was
    os.utime(folder, ns=(recent, recent))
    assert store.versions(card.id) == [1, 2, 3] and store.get(card.id).card.parameters["p0"] == p0 + 3


def _notes(client, card_id: str, version: int):
    r = client.get(f"/cards/{card_id}", params={"version": version})
    return r.json()["notes"] if r.status_code == 200 else r.status_code


def test_a_deleted_version_number_is_never_issued_again(client):
    """``id@N`` names one content for good: version numbers of an id only increase, across deletes of the latest
    version and of the whole card (a user's sequence gave reuse@2, then reuse@1, new contents)."""
    doc = dict(_doc(), id="reuse")
    assert client.post("/cards", json=doc).json()["version"] == 1
    r = client.post("/cards", params={"new_version": "true"}, json=dict(doc, notes="A"))
    assert r.status_code == 201 and r.json()["version"] == 2
    assert client.delete("/cards/reuse", params={"version": 2}).status_code == 204
    body = assert_names_field(client.post("/cards", json=dict(doc, notes="B")), 409, "id")
    assert "add version 3" in body["detail"]
    r = client.post("/cards", params={"new_version": "true"}, json=dict(doc, notes="B"))
    assert r.status_code == 201 and r.json()["version"] == 3 and r.json()["versions"] == [1, 3]
    assert _notes(client, "reuse", 2) == 404 and _notes(client, "reuse", 3) == "B"
    # the whole card deleted: an upload of the id continues after the highest number issued (n + 1)
    assert client.delete("/cards/reuse").status_code == 204
    assert client.get("/cards/reuse").status_code == 404
    assert "reuse" not in {c["id"] for c in client.get("/cards").json()["cards"]}
    r = client.post("/cards", json=dict(doc, notes="C"))
    assert r.status_code == 201 and r.json()["version"] == 4 and r.json()["versions"] == [4]
    assert [_notes(client, "reuse", v) for v in (1, 2, 3, 4)] == [404, 404, 404, "C"]
    assert client.get("/cards/reuse/versions").json() == {"id": "reuse", "versions": [4]}


def test_the_highest_version_issued_survives_a_restart(make_client):
    c1 = make_client()
    doc = dict(_doc(), id="kept")
    c1.post("/cards", json=doc)
    c1.post("/cards", params={"new_version": "true"}, json=dict(doc, notes="A"))
    assert c1.delete("/cards/kept", params={"version": 2}).status_code == 204
    c2 = make_client()  # a new app on the same data folder
    r = c2.post("/cards", params={"new_version": "true"}, json=dict(doc, notes="B"))
    assert r.status_code == 201 and r.json()["version"] == 3
    assert c2.delete("/cards/kept").status_code == 204
    c3 = make_client()
    r = c3.post("/cards", json=dict(doc, notes="C"))
    assert r.status_code == 201 and r.json()["version"] == 4


def test_a_store_without_the_record_takes_it_from_its_versions_when_one_is_deleted(tmp_path):
    """A store written before the record existed: deleting its latest version records that number first."""
    from gisnoise.model import cards as gcards
    from gisnoise.service.cardstore import HIGHEST_FILE, CardStore

    store = CardStore(tmp_path / "cards")
    card = gcards.from_dict(dict(_doc(), id="old"))
    store.put(card)
    store.put(gcards.from_dict(dict(_doc(), id="old", notes="A")), new_version=True)
    (tmp_path / "cards" / "old" / HIGHEST_FILE).unlink()
    assert store.delete("old", 2) == [2]
    stored, created = store.put(gcards.from_dict(dict(_doc(), id="old", notes="B")), new_version=True)
    assert created and stored.version == 3
    assert json.loads((tmp_path / "cards" / "old" / HIGHEST_FILE).read_text()) == {"highest_version": 3}
    assert not list((tmp_path / "cards" / "old").glob(".*.tmp"))  # no temporary file left
