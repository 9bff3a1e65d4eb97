"""Fixtures every test module may take."""

import pytest


@pytest.fixture()
def no_geoid_grid(monkeypatch):
    """No geoid grid anywhere: neither ``GISNOISE_GEOID_GRID`` nor a grid in the search folders."""
    monkeypatch.delenv("GISNOISE_GEOID_GRID", raising=False)
    monkeypatch.setattr("gisnoise.geo.geoid.geoid_search_dirs", lambda: [])
