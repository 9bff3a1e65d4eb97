"""Fit and diagnose jobs say what the command line says about a campaign's flight logs (a log cut short).

The campaign is one real flight, the ArduCopter log171, cut at 90 % of its bytes (inside a message, as a dead
battery or a broken download leaves it) or whole, with levels from a known card (:mod:`log171_campaign`): fit
and diagnosis both run on it, so the jobs succeed and their results can be read.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner
from service_helpers import wait_job

pytest.importorskip("pymavlink", reason="DataFlash logs need the 'logs' extra")

from log171_campaign import LOG, TRUTH, campaign, cut_log, zip_campaign  # noqa: E402

from gisnoise.cli.main import cli  # noqa: E402
from gisnoise.model import cards as gcards  # noqa: E402

CUT = "the file was cut"


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, bytes, int]]:
    """``{"cut": ..., "whole": ...}``: the campaign folder, its zip and the log's bytes."""
    tmp = tmp_path_factory.mktemp("log171")
    cut, k = cut_log(tmp)
    out = {}
    for name, log, size in (("cut", cut, k), ("whole", LOG, LOG.stat().st_size)):
        folder = campaign(tmp / name, log)
        out[name] = (folder, zip_campaign(folder), size)
    return out


def _fit(client, data: bytes) -> dict:
    r = client.post("/jobs/fit", files={"campaign": ("c.zip", data, "application/zip")},
                    data={"phase": "horizontal", "card_id": "log171-horizontal"})
    assert r.status_code == 202, r.text
    return wait_job(client, r.json()["id"], timeout=120)


def _diagnose(client, data: bytes) -> dict:
    r = client.post("/jobs/diagnose", data={"report": "false"},
                    files={"campaign": ("c.zip", data, "application/zip"),
                           "card": ("card.json", gcards.dumps(TRUTH).encode(), "application/json")})
    assert r.status_code == 202, r.text
    return wait_job(client, r.json()["id"], timeout=120)


def _cli_warnings(*args: str) -> list[str]:
    r = CliRunner().invoke(cli, ["-q", *args], catch_exceptions=False)
    return [ln.removeprefix("warning: ") for ln in r.stderr.splitlines() if ln.startswith("warning: ")]


def test_jobs_on_a_cut_log_carry_its_one_warning(client, campaigns, tmp_path):
    folder, data, k = campaigns["cut"]
    fit, diag = _fit(client, data), _diagnose(client, data)
    for info in (fit, diag):
        assert info["status"] == "succeeded", info["error"]
        warnings = info["summary"]["warnings"]
        # one warning, naming the log as the upload holds it (no server folder), and where the file ends
        assert len(warnings) == 1, warnings
        assert warnings[0].startswith(f"upload/campaign/flights/f1.bin: the log ends mid-message at byte {k} of ")
        assert CUT in warnings[0] and str(tmp_path) not in warnings[0]
    # the fit's summary file says it too
    assert client.get(f"/jobs/{fit['id']}/files/fit.json").json()["warnings"] == fit["summary"]["warnings"]
    assert diag["summary"]["warnings"] == fit["summary"]["warnings"]
    # the line the command line prints for this campaign, its folder named as the client knows it
    said = _cli_warnings("campaign", "check", str(folder))
    assert [w.replace(str(folder), "upload/campaign") for w in said] == fit["summary"]["warnings"]


def test_jobs_on_the_whole_log_have_no_warnings(client, campaigns):
    folder, data, _ = campaigns["whole"]
    fit, diag = _fit(client, data), _diagnose(client, data)
    for info in (fit, diag):
        assert info["status"] == "succeeded", info["error"]
        assert info["summary"]["warnings"] == []
    assert client.get(f"/jobs/{fit['id']}/files/fit.json").json()["warnings"] == []
    assert _cli_warnings("campaign", "check", str(folder)) == []


def test_the_fit_of_the_cut_log_finds_the_card_its_levels_came_from(client, campaigns):
    """The campaign is a fair one: the fitted card is the truth within a few of its standard deviations (p7, the
    background, may be held at the campaign's background, which is the truth's)."""
    info = _fit(client, campaigns["cut"][1])
    assert info["status"] == "succeeded", info["error"]
    fitted, std = info["summary"]["parameters"], info["summary"]["std"]
    for name, truth in TRUTH.parameters.items():
        if std[name] > 0:
            assert abs(fitted[name] - truth) < 5 * std[name], (name, fitted[name], truth, std[name])
        else:
            assert fitted[name] == pytest.approx(truth), name


def test_a_job_that_fails_keeps_the_warnings_that_may_explain_it(client, campaigns):
    """A fit of a phase the quad never flies (transition) fails on the cut campaign: the job names the failure and
    its summary keeps the cut log's one warning, the same line as the succeeding fit's."""
    _, data, _ = campaigns["cut"]
    r = client.post("/jobs/fit", files={"campaign": ("c.zip", data, "application/zip")},
                    data={"phase": "transition", "card_id": "log171-transition"})
    assert r.status_code == 202, r.text
    job = wait_job(client, r.json()["id"], timeout=120)
    assert job["status"] == "failed" and job["error"]
    ok = _fit(client, data)
    assert job["summary"] == {"warnings": ok["summary"]["warnings"]} and len(ok["summary"]["warnings"]) == 1
