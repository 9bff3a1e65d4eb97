"""Helpers of the service tests (imported by the test modules of this folder)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
CARDS = REPO / "gisnoise" / "data" / "cards"
KEY = "test-key-0123456789"


def wait_job(client: Any, job_id: str, timeout: float = 60.0, until: tuple[str, ...] = (
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


# ---------------------------------------------------------------- a real server on loopback
def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    """``gisnoise serve`` in a subprocess on 127.0.0.1 (killed by ``kill()`` or ``stop()``)."""

    def __init__(self, data_dir: Path, *, port: int | None = None, env: dict[str, str] | None = None,
                 workers: int = 1, log: Path | None = None, cli: bool = False) -> None:
        import os
        import subprocess
        import sys

        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        e = {k: v for k, v in os.environ.items() if not k.startswith("GISNOISE_")}
        e.update({"GISNOISE_SEED_CARDS_DIR": str(CARDS), "GISNOISE_TILE_URL": ""})
        e.update(env or {})
        self.log = log or (Path(data_dir).parent / f"server-{self.port}.log")
        self._logf = open(self.log, "ab")  # noqa: SIM115 - closed in stop/kill
        if cli:  # the product's command
            args = [sys.executable, "-m", "gisnoise.cli.main", "serve", "--host", "127.0.0.1", "--port",
                    str(self.port), "--data-dir", str(data_dir), "--workers", str(workers), "--log-level", "warning"]
        else:  # uvicorn itself on the app factory (settings from the environment, as `serve` does)
            e.update({"GISNOISE_DATA_DIR": str(data_dir), "GISNOISE_WORKERS": str(workers)})
            args = [sys.executable, "-m", "uvicorn", "gisnoise.service.app:create_app", "--factory", "--host", "127.0.0.1",
                    "--port", str(self.port), "--log-level", "warning"]
        self.proc = subprocess.Popen(args, env=e, stdout=self._logf, stderr=subprocess.STDOUT, cwd=str(REPO))
        self.wait_up()

    def wait_up(self, timeout: float = 30.0) -> None:
        import httpx

        end = time.monotonic() + timeout
        while True:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited with {self.proc.returncode}: {self.log.read_text()[-2000:]}")
            try:
                if httpx.get(self.url + "/health", timeout=1.0).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            if time.monotonic() > end:
                raise RuntimeError(f"server not up after {timeout} s: {self.log.read_text()[-2000:]}")
            time.sleep(0.1)

    def kill(self) -> None:
        """SIGKILL: the process dies at once, as in a crash or a power cut."""
        import signal

        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(10)
        self._logf.close()

    def stop(self) -> None:
        """SIGTERM: a graceful stop."""
        import signal
        import subprocess

        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        self._logf.close()
