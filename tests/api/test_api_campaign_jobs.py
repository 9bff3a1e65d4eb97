"""Fit and diagnose jobs on an uploaded campaign: the library's result, the injected effect found."""

from __future__ import annotations

import io
import json
import zipfile

import pytest
from service_helpers import REPO, assert_names_field, wait_job

CAMPAIGN = REPO / "sample_data" / "campaign"
pytestmark = pytest.mark.skipif(not (CAMPAIGN / "campaign.json").is_file(), reason="no sample campaign")


def _campaign_zip(flights: tuple[str, ...] = ("f1",)) -> bytes:
    """The sample campaign (its simulated truth: a bank-angle effect) restricted to some flights, zipped."""
    doc = json.loads((CAMPAIGN / "campaign.json").read_text())
    doc["flights"] = [f for f in doc["flights"] if f["id"] in flights]
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr("sample/campaign.json", json.dumps(doc))
        for p in sorted(CAMPAIGN.rglob("*")):
            rel = p.relative_to(CAMPAIGN)
            if p.is_file() and rel.parts[0] in ("flights", "mics") and p.stem in flights:
                z.write(p, f"sample/{rel}")
    return buf.getvalue()


@pytest.fixture(scope="module")
def campaign_zip() -> bytes:
    return _campaign_zip()


def test_fit_job_returns_the_librarys_card(client, campaign_zip, tmp_path):
    from gisnoise.identify import fit_campaign
    from gisnoise.model import cards as gcards

    r = client.post("/jobs/fit", files={"campaign": ("c.zip", campaign_zip, "application/zip")},
                    data={"phase": "horizontal", "card_id": "fitted-horizontal", "report": "true"})
    assert r.status_code == 202, r.text
    info = wait_job(client, r.json()["id"], timeout=300)
    assert info["status"] == "succeeded", info
    assert {"card.json", "fit.json", "report/report.html"} <= set(info["files"])
    assert info["summary"]["report"] == "written"
    card = gcards.loads(client.get(info["result_url"]).content)
    assert card.id == "fitted-horizontal" and card.phase == "horizontal" and card.covariance is not None
    assert str(tmp_path) not in client.get(info["result_url"]).text  # no server paths leak
    with zipfile.ZipFile(io.BytesIO(campaign_zip)) as z:
        z.extractall(tmp_path / "direct")
    direct = fit_campaign(tmp_path / "direct" / "sample", "horizontal")
    assert card.parameters == pytest.approx(direct.params, rel=1e-9, abs=1e-9)
    # the fitted card can be published to the store as it is
    assert client.post("/cards", content=client.get(info["result_url"]).content,
                       headers={"content-type": "application/json"}).status_code == 201


def test_fit_job_warns_of_a_microphone_listed_50_m_off_as_gisnoise_fit_does(client, tmp_path):
    """tests/test_fit.py's campaign (the model's own levels, white noise) with m2 listed 50 m east of where its
    levels were measured: the fit names it (the model misses it alone); the job's summary says it too, in the
    words fit_campaign gives (before: only in card.json)."""
    from test_fit import make_campaign_folder

    from gisnoise.geo import LocalFrame
    from gisnoise.identify import fit_campaign

    folder = make_campaign_folder(tmp_path / "campaign")
    doc = json.loads((folder / "campaign.json").read_text())
    m = doc["microphones"][1]
    m["lat"], m["lon"], m["h"] = (float(v) for v in LocalFrame(m["lat"], m["lon"], m["h"]).to_wgs84(50.0, 0.0, 0.0))
    (folder / "campaign.json").write_text(json.dumps(doc))
    said = fit_campaign(folder, "horizontal").info["warnings"]
    assert len(said) == 1 and said[0].startswith("microphone 'm2'") and "gisnoise diagnose" in said[0]
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                z.write(p, f"campaign/{p.relative_to(folder)}")
    r = client.post("/jobs/fit", files={"campaign": ("c.zip", buf.getvalue(), "application/zip")},
                    data={"phase": "horizontal"})
    assert r.status_code == 202, r.text
    info = wait_job(client, r.json()["id"], timeout=300)
    assert info["status"] == "succeeded", info
    # after the campaign's own lines: the racetrack's legs are logged 5 s apart (holes the track bridges straight)
    *log_lines, last = info["summary"]["warnings"]
    assert last == said[0] and log_lines and all("the track has 3 holes without samples" in w for w in log_lines)


def test_fit_job_failing_in_the_core_reports_the_field(client, campaign_zip):
    r = client.post("/jobs/fit", files={"campaign": ("c.zip", campaign_zip, "application/zip")},
                    data={"phase": "transition"})  # a few transition samples cannot identify the model
    info = wait_job(client, r.json()["id"], timeout=120)
    assert info["status"] == "failed" and info["error"]["status"] == 422, info
    # with p7 held at the background (too few background-dominated rows), the rest either cannot be told apart
    # or fits with uncertainties the plausibility guard refuses: either way named, no card
    detail = info["error"]["detail"]
    assert "cannot be told apart" in detail or ("implausible card" in detail and "p0" in detail), detail
    assert info["error"]["field"] in ("p0", "p1", "p2", "p3", "p4", "p5", "p6", "p7", "parameters")
    body = assert_names_field(client.get(f"/jobs/{info['id']}/result"), 409, "job_id")
    assert body["detail"].startswith(f"job_id: job {info['id']} failed, it has no result: "), body
    assert info["message"] == "failed", info
    # it read the campaign (CSV flights: nothing to say of their logs): its summary says so, as the docs state;
    # it was null
    assert info["summary"] == {"warnings": []}, info


def test_a_job_failing_before_the_campaign_is_read_has_no_summary(client):
    """An unreadable campaign.json fails the job before any log is read: no summary (null), the error names it."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("campaign.json", "{not json")
    for kind, data in (("fit", {"phase": "horizontal"}), ("diagnose", {"card_id": "demo-horizontal"})):
        r = client.post(f"/jobs/{kind}", files={"campaign": ("c.zip", buf.getvalue(), "application/zip")}, data=data)
        assert r.status_code == 202, r.text
        info = wait_job(client, r.json()["id"], timeout=60)
        assert info["status"] == "failed" and info["error"]["status"] == 422, info
        assert info["summary"] is None, info


def test_diagnose_job_finds_the_injected_effect(client, campaign_zip, tmp_path):
    truth = json.loads((CAMPAIGN / "truth.json").read_text())
    injected = [e["name"] for e in truth["effects"]]
    r = client.post("/jobs/diagnose", files={"campaign": ("c.zip", campaign_zip, "application/zip")},
                    data={"card_id": "demo-horizontal"})
    assert r.status_code == 202, r.text
    info = wait_job(client, r.json()["id"], timeout=300)
    assert info["status"] == "succeeded", info
    doc = client.get(info["result_url"]).json()
    assert {"baseline", "segments", "effects", "verdict"} <= set(doc)
    assert doc["verdict"]["effect"] in injected
    assert info["summary"]["verdict"]["effect"] == doc["verdict"]["effect"]
    assert info["summary"]["report"] == "written" and "report.html" in info["files"]
    page = client.get(f"/jobs/{info['id']}/files/report.html")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    for text in (page.text, client.get(info["result_url"]).text):
        assert str(tmp_path) not in text  # no server paths leak


def test_diagnose_job_with_an_unknown_card_names_it_once(client, campaign_zip):
    """A store card that is not there: 422 with the common body, the field named once at the head of the
    message ('card_id: no card ...'), and no job queued."""
    before = client.get("/jobs").json()
    r = client.post("/jobs/diagnose", files={"campaign": ("c.zip", campaign_zip, "application/zip")},
                    data={"card_id": "no-such-card"})
    body = assert_names_field(r, 422, "card_id")
    assert body["detail"] == "card_id: no card with id 'no-such-card'", body
    assert client.get("/jobs").json() == before


def test_fit_job_summary_says_which_parameters_were_held_and_why(client):
    """Sink rows never come within 3 dB of the background: p7 is held at the campaign's background. Its std of 0
    in the summary is 'not estimated', and the summary says so with the card's reason."""
    both = _campaign_zip(("f1", "f2"))  # one flight's sink rows cannot identify the rest either
    r = client.post("/jobs/fit", files={"campaign": ("c.zip", both, "application/zip")},
                    data={"phase": "sink"})
    info = wait_job(client, r.json()["id"], timeout=120)
    assert info["status"] == "succeeded", info["error"]
    card = client.get(info["result_url"]).json()
    held = card["provenance"]["held_parameters"]
    assert "p7" in held and info["summary"]["std"]["p7"] == 0.0
    assert info["summary"]["held_parameters"] == held


def test_diagnose_job_summary_says_what_the_campaign_got_wrong(client, tmp_path):
    """The diagnosis base scenario (no effect injected) with m3 listed 30 m north of where it stood: the job's
    summary carries the diagnosis' sentence about it (as the command line prints it), not only the verdict."""
    from gisnoise import simulate

    scenario = REPO / "sample_data" / "scenarios" / "diagnosis_base.json"
    camp = simulate.simulate(json.loads(scenario.read_text()), tmp_path / "camp", base_dir=scenario.parent)
    doc = json.loads((camp / "campaign.json").read_text())
    m3 = next(m for m in doc["microphones"] if m["id"] == "m3")
    m3["lat"] += 30.0 / 111_200.0  # about 30 m north
    (camp / "campaign.json").write_text(json.dumps(doc))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for p in sorted(camp.rglob("*")):
            if p.is_file() and p.name != "truth.json":
                z.write(p, str(p.relative_to(camp)))
    r = client.post("/jobs/diagnose", files={"campaign": ("c.zip", buf.getvalue(), "application/zip")},
                    data={"card_id": "demo-horizontal", "report": "false"})
    info = wait_job(client, r.json()["id"], timeout=300)
    assert info["status"] == "succeeded", info["error"]
    said = client.get(info["result_url"]).json()["metadata"]["contradictions"]
    assert any("m3" in t and "not where the campaign lists it" in t for t in said), said
    assert info["summary"]["contradictions"] == said
