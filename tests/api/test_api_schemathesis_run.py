"""schemathesis's own runner against a real server: all checks, all four phases, 0 failures.

The default suite runs a small budget (2 examples per operation and phase); the long run
(``scripts/schemathesis``, 200 examples) is marked slow and run by ``scripts/study``.  Expected answers
to schema-valid requests: ``scripts/schemathesis.toml`` (413/422 only on the operations whose rules
JSON Schema cannot state, each documented there).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from service_helpers import KEY, REPO, Server

pytest.importorskip("schemathesis")

CONFIG = REPO / "scripts" / "schemathesis.toml"


def _runner() -> list[str]:
    exe = Path(sys.executable).with_name("schemathesis")
    if exe.is_file():
        return [str(exe)]
    found = shutil.which("schemathesis")
    if found is None:
        pytest.skip("the schemathesis command is not installed")
    return [found]


def _run(tmp_path: Path, max_examples: int, timeout: float) -> subprocess.CompletedProcess[str]:
    env = {"GISNOISE_API_KEYS": KEY, "GISNOISE_SYNC_WORK_LIMIT": "20000", "GISNOISE_MAX_CELLS": "200000"}
    srv = Server(tmp_path / "data", env=env)
    try:
        e = {k: v for k, v in os.environ.items() if not k.startswith("GISNOISE_")}
        e["NO_COLOR"] = "1"
        return subprocess.run(
            [*_runner(), "--config-file", str(CONFIG), "run", srv.url + "/openapi.json", "--checks", "all",
             "--phases", "examples,coverage,fuzzing,stateful", "--header", f"X-API-Key: {KEY}",
             "--max-examples", str(max_examples), "--request-timeout", "60", "--workers", "1",
             "--generation-deterministic"],
            capture_output=True, text=True, timeout=timeout, env=e, cwd=str(tmp_path))
    finally:
        srv.stop()
        log = srv.log.read_text(errors="replace")
        assert "Traceback" not in log, log[-3000:]


def _assert_clean(res: subprocess.CompletedProcess[str]) -> None:
    out = res.stdout + res.stderr
    summary = out[out.rfind("SUMMARY"):] if "SUMMARY" in out else out[-3000:]
    assert res.returncode == 0, summary  # exit 1 on any failure or error
    for phase in ("Examples", "Coverage", "Fuzzing", "Stateful"):
        assert phase in summary, summary
    assert "Failures:" not in summary and "Errors:" not in summary, summary
    cases = [ln.strip() for ln in summary.splitlines() if "generated" in ln]
    print("schemathesis:", "; ".join(cases))  # the numbers of the run (shown with -s)


def test_schemathesis_all_checks_all_phases_small_budget(tmp_path):
    _assert_clean(_run(tmp_path, max_examples=2, timeout=600))


@pytest.mark.slow
def test_schemathesis_all_checks_all_phases_long(tmp_path):
    _assert_clean(_run(tmp_path, max_examples=200, timeout=3600))
