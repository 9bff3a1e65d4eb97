"""Request limits, the error table and the upload checks: 4xx naming the field, never a 500."""

from __future__ import annotations

import io
import json
import zipfile

import pytest
from service_helpers import CARDS, KEY, assert_names_field

from gisnoise import errors as ge
from gisnoise.service.errors import STATUS, status_for


def test_every_core_error_has_a_4xx_status_and_specific_beats_general():
    core = [getattr(ge, n) for n in dir(ge) if isinstance(getattr(ge, n), type)
            and issubclass(getattr(ge, n), ge.GisnoiseError)]
    for cls in core:
        assert 400 <= status_for(cls("x", field="f")) < 500, cls
    assert status_for(ge.GridTooLargeError("x")) == 413  # before its base InvalidGridError (422)
    assert status_for(ge.InvalidGridError("x")) == 422
    assert status_for(ge.NotIdentifiableError("x")) == 422
    assert status_for(ge.Cancelled("x")) == 409
    assert status_for(MemoryError()) == 413
    assert status_for(ZeroDivisionError()) == 500
    assert all(isinstance(k, type) for k in STATUS)


def test_body_over_the_limit_is_413_before_it_is_read(make_client):
    limit = 16384
    c = make_client(max_request_bytes=limit)
    doc = json.loads((CARDS / "demo_horizontal.json").read_text())
    assert len(json.dumps(doc)) < limit
    doc["notes"] = "x" * limit
    assert_names_field(c.post("/cards", json=doc), 413, "body")
    # chunked (no Content-Length): counted as it arrives
    def chunks():
        data = json.dumps(doc).encode()
        for i in range(0, len(data), 512):
            yield data[i:i + 512]

    r = c.post("/cards", content=chunks(), headers={"content-type": "application/json"})
    assert_names_field(r, 413, "body")
    doc["notes"] = "short"
    doc["id"] = "small"
    assert c.post("/cards", json=doc).status_code == 201


def _zip(files: dict[str, bytes | str]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return buf.getvalue()


def _campaign_zip(prefix: str = "") -> bytes:
    return _zip({f"{prefix}campaign.json": json.dumps({"schema": "gisnoise/campaign/1"}),
                 f"{prefix}flights/f1.csv": "t,lat,lon,h,roll,pitch,yaw,power_w\n"})


@pytest.fixture
def idle_client(make_client):
    return make_client(start_workers=False, max_upload_bytes=50_000, max_unzipped_bytes=100_000)


def test_fit_upload_checks(idle_client):
    c = idle_client
    ok = {"campaign": ("c.zip", _campaign_zip("mycampaign/"), "application/zip")}
    r = c.post("/jobs/fit", files=ok, data={"phase": "horizontal"})
    assert r.status_code == 202, r.text
    job = r.json()
    assert job["status"] == "queued" and job["kind"] == "fit" and r.headers["location"].endswith(job["id"])
    st = c.app.state.gisnoise
    # the campaign folder itself is stored with the job, unzipped
    assert (st.jobs.input_dir(job["id"]) / "campaign" / "campaign.json").is_file()
    assert (st.jobs.input_dir(job["id"]) / "campaign" / "flights" / "f1.csv").is_file()
    assert_names_field(c.post("/jobs/fit", files=ok, data={"phase": "cruise"}), 422, "phase")
    assert_names_field(c.post("/jobs/fit", files=ok, data={"phase": "climb", "ansatz": "nope"}), 422, "ansatz")
    assert_names_field(c.post("/jobs/fit", files=ok, data={"phase": "climb", "card_id": "a/b"}), 422, "card_id")
    assert_names_field(c.post("/jobs/fit", data={"phase": "horizontal"}), 422, "campaign")
    bad = {"campaign": ("c.zip", b"not a zip at all", "application/zip")}
    assert_names_field(c.post("/jobs/fit", files=bad, data={"phase": "horizontal"}), 422, "campaign")
    nocamp = {"campaign": ("c.zip", _zip({"readme.txt": "hi"}), "application/zip")}
    body = assert_names_field(c.post("/jobs/fit", files=nocamp, data={"phase": "horizontal"}), 422, "campaign")
    assert "campaign.json" in body["detail"]
    slip = {"campaign": ("c.zip", _zip({"../evil.txt": "x", "campaign.json": "{}"}), "application/zip")}
    assert_names_field(c.post("/jobs/fit", files=slip, data={"phase": "horizontal"}), 422, "campaign")
    bomb = {"campaign": ("c.zip", _zip({"campaign.json": "{}", "big.bin": b"\0" * 200_000}), "application/zip")}
    assert_names_field(c.post("/jobs/fit", files=bomb, data={"phase": "horizontal"}), 413, "campaign")
    huge = {"campaign": ("c.zip", b"\0" * 60_000, "application/zip")}
    assert_names_field(c.post("/jobs/fit", files=huge, data={"phase": "horizontal"}), 413, "body")
    # nothing half-made stays behind: only the one accepted job's folder
    assert [p.name for p in st.jobs.jobs_dir.iterdir()] == [job["id"]]
    assert c.get("/jobs").json()["total"] == 1


def test_diagnose_upload_checks(idle_client):
    c = idle_client
    camp = {"campaign": ("c.zip", _campaign_zip(), "application/zip")}
    r = c.post("/jobs/diagnose", files=camp, data={"card_id": "demo-horizontal"})
    assert r.status_code == 202 and r.json()["kind"] == "diagnose"
    stored = c.app.state.gisnoise.jobs.input_dir(r.json()["id"]) / "card.json"
    assert json.loads(stored.read_text())["id"] == "demo-horizontal"
    card = {"card": ("card.json", (CARDS / "demo_climb.json").read_bytes(), "application/json")}
    r = c.post("/jobs/diagnose", files={**camp, **card})
    assert r.status_code == 202
    assert_names_field(c.post("/jobs/diagnose", files=camp), 422, "card_id")
    assert_names_field(c.post("/jobs/diagnose", files={**camp, **card}, data={"card_id": "demo-climb"}), 422,
                       "card_id")
    assert_names_field(c.post("/jobs/diagnose", files=camp, data={"card_id": "nope"}), 422, "card_id")
    bad_card = {"card": ("card.json", b'{"schema": "gisnoise/model-card/1", "id": "x"}', "application/json")}
    body = assert_names_field(c.post("/jobs/diagnose", files={**camp, **bad_card}), 422)
    assert body["field"].startswith("card")


def test_uploads_need_a_key(make_client):
    c = make_client(start_workers=False, api_keys=[KEY])
    camp = {"campaign": ("c.zip", _campaign_zip(), "application/zip")}
    assert_names_field(c.post("/jobs/fit", files=camp, data={"phase": "horizontal"}), 401, "X-API-Key")
    r = c.post("/jobs/fit", files=camp, data={"phase": "horizontal"}, headers={"X-API-Key": KEY})
    assert r.status_code == 202


def test_unknown_paths_and_methods_name_what_is_wrong(client):
    assert_names_field(client.get("/nowhere"), 404, "path")
    assert_names_field(client.put("/cards"), 405, "method")


def test_strings_with_lone_surrogates_are_echoed_not_500(client):
    # JSON may carry \ud800-style escapes that no UTF-8 encoder accepts; responses escape them
    doc = json.loads((CARDS / "demo_sink.json").read_text())
    text = json.dumps(dict(doc, id="odd", vehicle="van \ud800 x")).replace("\\\\ud800", "\\ud800")
    r = client.post("/cards", content=text.encode("ascii"), headers={"content-type": "application/json"})
    assert r.status_code == 201 and r.json()["vehicle"] == "van \ud800 x"
    bad = '{"cards": ["\\udb5f"], "trajectory": {"format": "csv", "text": "t\\uda18"}}'
    r = client.post("/contours", content=bad.encode("ascii"), headers={"content-type": "application/json"})
    body = assert_names_field(r, 422)
    assert {e["field"] for e in body["errors"]} == {"cards.0", "trajectory.text"}  # no union member names


def test_validation_fields_leave_out_union_tags(client):
    r = client.post("/contours", json={"trajectory": {"format": "csv"}, "cards": ["demo-sink"]})
    assert_names_field(r, 422, "trajectory.text")
    r = client.post("/contours", json={"trajectory": {"format": "columns", "columns": {"Lat": [None]}},
                                       "cards": ["demo-sink"]})
    body = assert_names_field(r, 422)
    assert {e["field"] for e in body["errors"]} >= {"trajectory.columns.Lat", "trajectory.columns.t"}, body


def test_csv_text_with_old_mac_newlines_reads_like_a_file(client):
    from test_api_contours import _request, flyover_csv

    text = flyover_csv(length_m=100.0, dt=1.0)
    a = client.post("/contours", json=_request(trajectory={"format": "csv", "text": text}, output="geotiff"))
    b = client.post("/contours", json=_request(trajectory={"format": "csv", "text": text.replace("\n", "\r")},
                                               output="geotiff"))
    assert a.status_code == b.status_code == 200 and a.content == b.content
    r = client.post("/contours", json=_request(trajectory={"format": "csv", "text": 't,"lat\n'}))
    assert_names_field(r, 422)
