"""schemathesis against the service's own OpenAPI schema: no 500, no response outside the schema.

A short property-based run per operation (the default suite); ``scripts/schemathesis``
runs a longer one against a real server.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
import warnings
from pathlib import Path

import pytest

schemathesis = pytest.importorskip("schemathesis")
from hypothesis import HealthCheck, settings  # noqa: E402
from schemathesis import checks as st_checks  # noqa: E402
from service_helpers import CARDS, KEY  # noqa: E402

from gisnoise.service import Settings, create_app  # noqa: E402

_tmp = Path(tempfile.mkdtemp(prefix="gisnoise-schema-"))
atexit.register(shutil.rmtree, _tmp, True)
# a tiny sync limit: generated contour requests become queued jobs (workers off) or fail fast
APP = create_app(Settings(data_dir=_tmp / "data", seed_cards_dir=CARDS, tile_url="", sync_work_limit=2e4,
                          max_cells=200_000, api_keys=[KEY]), start_workers=False)
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    schema = schemathesis.openapi.from_asgi("/openapi.json", APP)



@schema.auth()
class _ApiKey:
    """Writes carry the service's key (schemathesis still tries requests without it)."""

    def get(self, case, ctx):
        return KEY

    def set(self, case, data, ctx):
        case.headers = case.headers or {}
        case.headers["X-API-Key"] = data


CHECKS = [st_checks.not_a_server_error, st_checks.status_code_conformance, st_checks.content_type_conformance,
          st_checks.response_schema_conformance, st_checks.response_headers_conformance,
          st_checks.negative_data_rejection]


@pytest.fixture(scope="module", autouse=True)
def _lifespan():
    from fastapi.testclient import TestClient

    with TestClient(APP):  # runs start-up (seeds the card store) once for the module
        yield


@schema.parametrize()
@settings(max_examples=12, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large])
def test_openapi_conformance(case):
    case.call_and_validate(checks=CHECKS)
