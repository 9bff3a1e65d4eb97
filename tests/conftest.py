"""Fixtures every test module may take."""

import pytest

collect_ignore = ["conftest.py"]
"""This file holds fixtures, no doctests: collected as a module (``--doctest-modules``) it would clash with
``tests/api/conftest.py``, both named ``conftest`` outside a package."""


@pytest.fixture()
def no_geoid_grid(monkeypatch):
    """No geoid grid anywhere: neither ``GISNOISE_GEOID_GRID`` nor a grid in the search folders."""
    monkeypatch.delenv("GISNOISE_GEOID_GRID", raising=False)
    monkeypatch.setattr("gisnoise.geo.geoid.geoid_search_dirs", lambda: [])
