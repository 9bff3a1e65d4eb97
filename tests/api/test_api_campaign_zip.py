"""Campaign uploads: what a zip may hold (compression ratio, names given twice, names as given), what is unzipped
(the campaign's own files only), and the field of an error found in its files."""

from __future__ import annotations

import io
import json
import struct
import zipfile

import pytest
from service_helpers import REPO, assert_names_field, wait_job

from gisnoise.service.routes_campaign import MAX_RATIO, RATIO_FLOOR

CAMPAIGN = REPO / "sample_data" / "campaign"
pytestmark = pytest.mark.skipif(not (CAMPAIGN / "campaign.json").is_file(), reason="no sample campaign")


def _zip(extra: dict[str, bytes] | None = None, *, drop: tuple[str, ...] = (), dup: bool = False) -> bytes:
    """The sample campaign's flight f1 under ``campaign/``, with ``extra`` members (a name given twice when
    ``dup``: a second campaign.json)."""
    import warnings

    doc = json.loads((CAMPAIGN / "campaign.json").read_text())
    doc["flights"] = [f for f in doc["flights"] if f["id"] == "f1"]
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=9) as z:
        z.writestr("campaign/campaign.json", json.dumps(doc))
        for p in sorted(CAMPAIGN.rglob("f1.csv")):
            name = f"campaign/{p.relative_to(CAMPAIGN)}"
            if name not in drop:
                z.write(p, name)
        for name, data in (extra or {}).items():
            z.writestr(name, data)
        if dup:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # zipfile warns of the duplicate name, as it should
                z.writestr("campaign/campaign.json", "{not json")
    return buf.getvalue()


def _post_fit(client, data: bytes):
    return client.post("/jobs/fit", files={"campaign": ("c.zip", data, "application/zip")},
                       data={"phase": "horizontal"})


def test_a_member_of_zeros_compressed_past_the_ratio_is_413_naming_it(make_client):
    c = make_client(start_workers=False)
    padding = bytes(20 * RATIO_FLOOR)  # 20 MiB of zeros: about 1000:1
    r = _post_fit(c, _zip({"campaign/notes/padding.bin": padding}))
    body = assert_names_field(r, 413, "campaign")
    assert "'campaign/notes/padding.bin'" in body["detail"] and f"{MAX_RATIO}:1" in body["detail"], body
    assert c.get("/jobs").json()["total"] == 0
    assert [p.name for p in c.app.state.gisnoise.settings.jobs_dir.iterdir()] == []  # nothing kept


def test_an_archive_of_small_members_compressed_past_the_ratio_is_413(make_client):
    """Each member at the 1 MiB floor (not held to the ratio alone), the archive 40 MiB from about 40 KiB."""
    c = make_client(start_workers=False)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=9) as z:
        z.writestr("campaign/campaign.json", (CAMPAIGN / "campaign.json").read_text())
        for i in range(40):
            z.writestr(f"campaign/mics/m1/pad{i}.bin", bytes(RATIO_FLOOR))
    r = _post_fit(c, buf.getvalue())
    body = assert_names_field(r, 413, "campaign")
    assert body["detail"].startswith("campaign: the archive unzips to") and f"{MAX_RATIO}:1" in body["detail"]


def test_a_real_campaign_passes_and_only_its_own_files_are_unzipped(make_client):
    """The sample campaign (CSV compresses about 5:1) is queued; a notes file and a stray file beside the
    campaign folder are not unzipped: the job's input holds campaign.json, flights/ and mics/ only."""
    c = make_client(start_workers=False)
    r = _post_fit(c, _zip({"campaign/notes/readme.txt": b"field notes\n" * 100, "stray.txt": b"x",
                           "campaign/mics/m1/README": b"calibrated 2024-05-03"}))
    assert r.status_code == 202, r.text
    st = c.app.state.gisnoise
    folder = st.jobs.input_dir(r.json()["id"]) / "campaign"
    held = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())
    assert held == ["campaign.json", "flights/f1.csv", "mics/m1/README", "mics/m1/f1.csv", "mics/m2/f1.csv",
                    "mics/m3/f1.csv"], held
    assert not (folder.parent / "stray.txt").exists()


def test_a_member_given_twice_is_refused_at_upload(make_client):
    c = make_client(start_workers=False)
    body = assert_names_field(_post_fit(c, _zip(dup=True)), 422, "campaign")
    assert "'campaign/campaign.json' is in the archive more than once" in body["detail"], body
    assert c.get("/jobs").json()["total"] == 0


def test_an_absolute_member_is_named_as_the_zip_gives_it(make_client):
    """A member in the server's temporary folder was cut to 'evil_abs.txt', as a server path would be."""
    import tempfile

    c = make_client(start_workers=False)
    name = f"{tempfile.gettempdir()}/evil_abs.txt"
    body = assert_names_field(_post_fit(c, _zip({name: b"x"})), 422, "campaign")
    assert body["detail"] == f"campaign: member {name!r} leaves the archive folder", body
    body = assert_names_field(_post_fit(c, _zip({"campaign/flights/../../../evil2.txt": b"x"})), 422, "campaign")
    assert "'campaign/flights/../../../evil2.txt'" in body["detail"], body


def _truncated_wav(frames_stated: int = 48_000, frames_held: int = 1000, rate: int = 48_000) -> bytes:
    """A mono 16-bit WAV whose header states ``frames_stated`` frames, holding ``frames_held``."""
    data = bytes(2 * frames_held)
    fmt = struct.pack("<HHIIHH", 1, 1, rate, rate * 2, 2, 16)
    return (b"RIFF" + struct.pack("<I", 36 + 2 * frames_stated) + b"WAVE" + b"fmt " + struct.pack("<I", 16) + fmt
            + b"data" + struct.pack("<I", 2 * frames_stated) + data)


def test_a_truncated_wav_fails_the_job_on_the_campaign_field(client):
    """The WAV reader names its header's 'length'; the request's field is campaign (the detail names the file),
    as for every fault found inside the upload."""
    z = _zip({"campaign/mics/m1/f1.wav": _truncated_wav()}, drop=("campaign/mics/m1/f1.csv",))
    r = _post_fit(client, z)
    assert r.status_code == 202, r.text
    info = wait_job(client, r.json()["id"], timeout=120)
    assert info["status"] == "failed", info
    err = info["error"]
    assert (err["field"], err["status"]) == ("campaign", 422), err
    assert "f1.wav" in err["detail"] and "truncated WAV" in err["detail"], err
