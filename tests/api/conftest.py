"""Fixtures of the service tests: an app on a fresh data folder, clients with and without keys."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("fastapi", reason="the service needs the 'api' extra")

with warnings.catch_warnings():  # starlette's notice about its httpx-based client; the client is what tests use
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from service_helpers import CARDS  # noqa: E402

from gisnoise.service import Settings, create_app  # noqa: E402


def make_settings(tmp_path: Path, **kw: Any) -> Settings:
    kw.setdefault("data_dir", tmp_path / "data")
    kw.setdefault("seed_cards_dir", CARDS)
    kw.setdefault("tile_url", "")
    return Settings(**kw)


@pytest.fixture
def make_client(tmp_path: Path) -> Iterator[Callable[..., TestClient]]:
    """``make_client(**settings)``: a started TestClient (workers running) on a fresh data folder."""
    opened: list[TestClient] = []

    def factory(start_workers: bool = True, **kw: Any) -> TestClient:
        app = create_app(make_settings(tmp_path, **kw), start_workers=start_workers)
        c = TestClient(app)
        c.__enter__()
        opened.append(c)
        return c

    yield factory
    for c in opened:
        c.__exit__(None, None, None)


@pytest.fixture
def client(make_client: Callable[..., TestClient]) -> TestClient:
    return make_client()
