"""Helpers of the service tests (imported by the test modules of this folder)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
CARDS = REPO / "sample_data" / "cards"
KEY = "test-key-0123456789"


def wait_job(client: TestClient, job_id: str, timeout: float = 60.0, until: tuple[str, ...] = (
        "succeeded", "failed", "cancelled"), headers: dict[str, str] | None = None) -> dict[str, Any]:
    """Poll a job until it reaches one of ``until``; returns its last JobInfo."""
    t_end = time.monotonic() + timeout
    while True:
        info = client.get(f"/jobs/{job_id}", headers=headers).json()
        if info["status"] in until:
            return info
        if time.monotonic() > t_end:
            raise AssertionError(f"job {job_id} still {info['status']} after {timeout} s: {info}")
        time.sleep(0.05)


def assert_names_field(resp: Any, status: int, field: str | None = None) -> dict[str, Any]:
    """The response has ``status`` and the common error body naming ``field`` (in 'field' and the message)."""
    assert resp.status_code == status, (resp.status_code, resp.text)
    body = resp.json()
    assert isinstance(body.get("detail"), str) and body["detail"]
    assert body.get("field"), body
    if field is not None:
        assert body["field"] == field, body
        assert field.split(".")[-1].split("[")[0] in body["detail"], body
    return body
