"""Property-based fuzzing of the service's requests: contours, cards, fit and diagnose uploads.

Property, for every generated request (a valid one with fields, values or bytes broken): the answer is
2xx, or a 4xx whose body names the field in one line; never a 500, never a server path in a message.
A 200 map holds only the contour levels asked for; a stored card reads back finite and plausible; an
accepted upload's job, run to its end, succeeds or fails with a 4xx status and a field (never an
internal error).  Default suite: a small budget; the slow study: 2,000 examples per request kind.
"""

from __future__ import annotations

import io
import json
import math
import tempfile
import warnings
import zipfile
from pathlib import Path

import pytest
from _jsonedit import put
from hypothesis import given
from hypothesis import strategies as st
from test_fuzz_campaigns import campaign_files
from test_fuzz_readers import _VALUE, CARD, STUDY_BUDGET, _budget, card_doc, event

fastapi = pytest.importorskip("fastapi")

with warnings.catch_warnings():  # the test client's transport warns about itself
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gisnoise.service.app import create_app  # noqa: E402
from gisnoise.service.settings import Settings  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
KEY = "fuzz-key-0123456789"
HDR = {"X-API-Key": KEY}
_CLIENT: dict[str, TestClient] = {}


def client() -> TestClient:
    """One service on a throw-away data folder; jobs are run by hand (:func:`_run_jobs`)."""
    if "c" not in _CLIENT:
        d = Path(tempfile.mkdtemp(prefix="fuzz-service-"))
        s = Settings(data_dir=d / "data", seed_cards_dir=REPO / "gisnoise" / "data" / "cards", tile_url="",
                     api_keys=[KEY], max_cells=200_000, sync_work_limit=2e7, max_work=1e9,
                     max_trajectory_samples=20_000)
        c = TestClient(create_app(s, start_workers=False))
        c.__enter__()
        _CLIENT["c"] = c
    return _CLIENT["c"]


def _flyover_rows(n: int = 31) -> list[dict]:
    return [{"t": float(i), "lat": 53.55, "lon": 9.99 + 3e-4 * i, "h": 60.0, "roll": 0.0, "pitch": 0.0, "yaw": 90.0,
             "power_w": 3000.0, "phase": "horizontal"} for i in range(n)]


def _valid_contour_request() -> dict:
    return {"trajectory": {"format": "rows", "rows": _flyover_rows()}, "cards": ["demo-horizontal"],
            "grid": {"resolution_m": 25.0, "margin_m": 150.0}, "levels": [45.0, 55.0], "ground_h_m": 0.0,
            "metrics": ["LAmax", "LAeq"]}


_REQ_KEYS = ["trajectory.format", "trajectory.rows", "cards", "cards.0", "grid.resolution_m", "grid.margin_m",
             "grid.crs", "levels", "levels.0", "metrics", "receiver_height_m", "ground_h_m", "period_s",
             "threshold_db", "snapshot_t", "substeps", "uncertainty", "background", "output", "phase_cards",
             "extra"]
_ROW_KEYS = ["t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w", "phase"]


@st.composite
def contour_request(draw) -> bytes:
    doc = _valid_contour_request()
    for _ in range(draw(st.integers(0, 3))):
        if draw(st.booleans()):
            i = draw(st.integers(0, 30))
            put(doc, ["trajectory", "rows", str(i), draw(st.sampled_from(_ROW_KEYS))],
                 draw(st.one_of(_VALUE, st.floats(-1e4, 1e4))), draw(st.integers(0, 5)) == 0)
        else:
            put(doc, draw(st.sampled_from(_REQ_KEYS)).split("."), draw(_VALUE), draw(st.booleans()))
    if draw(st.integers(0, 4)) == 0:  # an inline card, possibly broken
        try:
            inline = json.loads(draw(card_doc()).decode("utf-8", errors="replace"))
        except ValueError:
            inline = CARD
        doc["cards"] = [inline]
    text = json.dumps(doc, allow_nan=True)
    if draw(st.integers(0, 9)) == 0:
        k = draw(st.integers(0, len(text)))
        text = text[:k] + draw(st.text(max_size=3)) + text[k:]
    return text.encode("utf-8", errors="surrogatepass")


def _answer_ok(r) -> None:
    """2xx, or a 4xx naming a field in one line without a server path; never 5xx."""
    event(f"status {r.status_code}")
    assert r.status_code < 500, (r.status_code, r.text[:500])
    if r.status_code >= 400:
        body = r.json()
        assert isinstance(body.get("field"), str) and body["field"], body
        assert isinstance(body.get("detail"), str) and "\n" not in body["detail"].strip(), body
        assert not _shows_server_path(body["detail"]), body


def _shows_server_path(text: str) -> bool:
    """True when ``text`` names the server's temporary folder (its data folder lies there) or its checkout."""
    return tempfile.gettempdir() in text or str(REPO) in text


def _contour_property(raw: bytes) -> None:
    r = client().post("/contours", content=raw, headers={"content-type": "application/json", **HDR})
    _answer_ok(r)
    if r.status_code == 200 and r.headers["content-type"].startswith("application/geo+json"):
        from gisnoise.service.models import ContourRequest

        asked = json.loads(raw).get("levels", ContourRequest.model_fields["levels"].default)  # default when left out
        from gisnoise.maps import SEL_OFFSET_DB

        for f in r.json()["features"]:
            lv = f["properties"]["level"]
            lv = lv if isinstance(lv, list) else [lv]
            assert all(isinstance(v, (int, float)) and math.isfinite(v) for v in lv if v is not None), f
            # SEL is contoured SEL_OFFSET_DB above the asked levels (README: --levels 45,50 draw SEL at 55, 60)
            off = SEL_OFFSET_DB if f["properties"]["metric"] == "SEL" else 0.0
            assert all(any(math.isclose(v - off, a, rel_tol=1e-12, abs_tol=1e-9) for a in asked)
                       for v in lv if v is not None), (f["properties"]["metric"], lv, asked)


@st.composite
def card_request(draw) -> bytes:
    raw = draw(card_doc())
    if draw(st.booleans()):  # a fresh id, so that a valid card is stored (201) and read back
        try:
            doc = json.loads(raw)
            if isinstance(doc, dict):
                doc["id"] = f"fuzz-{draw(st.integers(0, 10**9))}"
                raw = json.dumps(doc, allow_nan=True).encode()
        except ValueError:
            pass
    return raw


def _card_property(raw: bytes) -> None:
    c = client()
    r = c.post("/cards", content=raw, headers={"content-type": "application/json", **HDR})
    _answer_ok(r)
    if r.status_code == 201:
        from gisnoise.model import cards as gcards
        from gisnoise.model.plausibility import LEVEL_RANGE_DB, card_level_range

        got = c.get(f"/cards/{r.json()['id']}", params={"version": r.json()["version"]})
        assert got.status_code == 200
        card = gcards.loads(got.text)  # reads back through the core's reader (plausibility guard included)
        assert all(math.isfinite(v) for v in card.parameters.values())
        lo, hi = card_level_range(card)
        assert LEVEL_RANGE_DB[0] <= lo <= hi <= LEVEL_RANGE_DB[1]


def _zip(files: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return buf.getvalue()


@st.composite
def campaign_zip(draw) -> bytes:
    """A zipped campaign folder (:func:`campaign_files`), one in ten archives broken."""
    data = _zip(draw(campaign_files()))
    if draw(st.integers(0, 9)) == 0:  # a broken archive
        k = draw(st.integers(0, len(data)))
        data = data[:k] + draw(st.binary(max_size=8)) + data[k + 8:]
    return data


@st.composite
def upload(draw) -> tuple[bytes, dict[str, str]]:
    """A fit upload: the archive and the fit's form fields (phase, ansatz, card_id), some of them bad."""
    data = draw(campaign_zip())
    form = {"phase": draw(st.sampled_from(["horizontal", "horizontal", "climb", "cruise", ""]))}
    if draw(st.integers(0, 4)) == 0:
        form["ansatz"] = draw(st.sampled_from(["paper", "paper-offset+bank_angle", "nope", ""]))
    if draw(st.integers(0, 4)) == 0:
        form["card_id"] = draw(st.sampled_from(["fit-1", "con", "a/b", "x\n", ".h"]))
    return data, form


def _run_jobs() -> list:
    """Run every queued job by hand, as a worker would; returns their final states."""
    state = client().app.state.gisnoise
    done = []
    while (job := state.jobs.claim_next()) is not None:
        state.pool.run(job)
        done.append(state.jobs.get(job.id))
    return done


def _job_ok(job) -> None:
    event(f"job {job.status} {job.error_status or ''}")
    assert job.status in ("succeeded", "failed"), job
    if job.status == "failed":
        assert job.error_status is not None and 400 <= job.error_status < 500, (job.error_status, job.error)
        assert job.error_field, job
        assert not _shows_server_path(job.error or ""), job.error


def _fit_property(req: tuple[bytes, dict[str, str]]) -> None:
    data, form = req
    r = client().post("/jobs/fit", files={"campaign": ("c.zip", data, "application/zip")}, data=form, headers=HDR)
    _answer_ok(r)
    for job in _run_jobs():
        _job_ok(job)
        if job.status == "succeeded":
            card = json.loads((client().app.state.gisnoise.jobs.result_dir(job.id) / "card.json").read_text())
            assert all(math.isfinite(v) for v in card["parameters"].values())


def _diagnose_property(data: bytes) -> None:
    r = client().post("/jobs/diagnose", files={"campaign": ("c.zip", data, "application/zip")},
                      data={"card_id": "demo-horizontal", "report": "false"}, headers=HDR)
    _answer_ok(r)
    for job in _run_jobs():
        _job_ok(job)
        if job.status == "succeeded":
            doc = json.loads((client().app.state.gisnoise.jobs.result_dir(job.id) / "diagnosis.json").read_text())
            rms = doc["baseline"]["rms_db"]
            assert rms is None or (math.isfinite(rms) and rms >= 0)


_PROPS = {"contours": (contour_request(), _contour_property, 40), "cards": (card_request(), _card_property, 40),
          "fit": (upload(), _fit_property, 6), "diagnose": (campaign_zip(), _diagnose_property, 3)}


def _fuzz(name: str, budget: int) -> None:
    strategy, prop, _ = _PROPS[name]
    _budget(budget)(given(strategy)(prop))()


def test_the_request_fuzzers_reach_both_outcomes():
    """The valid seeds are served (a map of the asked levels; a stored card), broken ones refused."""
    c = client()
    r = c.post("/contours", json=_valid_contour_request(), headers=HDR)
    assert r.status_code == 200, r.text
    levels = {f["properties"]["level"] for f in r.json()["features"] if not isinstance(f["properties"]["level"], list)}
    assert levels and levels <= {45.0, 55.0}
    bad = _valid_contour_request()
    bad["trajectory"]["rows"][3]["lon"] = 500.0
    r = c.post("/contours", json=bad, headers=HDR)
    assert r.status_code == 422 and r.json()["field"] == "trajectory.rows.3.lon"
    _card_property(json.dumps(dict(CARD, id="fuzz-seed")).encode())
    assert c.get("/cards/fuzz-seed").status_code == 200


@pytest.mark.parametrize("kind", sorted(_PROPS))
def test_requests_are_answered_with_a_field_never_a_500(kind):
    _fuzz(kind, _PROPS[kind][2])


@pytest.mark.slow
@pytest.mark.parametrize("kind", sorted(_PROPS))
def test_requests_fuzzed_at_the_study_budget(kind):
    _fuzz(kind, STUDY_BUDGET)
