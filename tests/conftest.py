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


@pytest.fixture()
def omni_card(tmp_path):
    """A card file: 65 dB(A) at 40 m in every direction at 300 W, for every phase (maps of real logs)."""
    from gisnoise.model import ModelCard, save

    c = ModelCard(id="omni", vehicle="test", phase="hover", ansatz="paper-offset",
                  parameters=dict(p0=65.0, p1=10.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                  reference_power_w=300.0, phases=("horizontal", "climb", "sink", "transition"))
    return str(save(c, tmp_path / "omni.json"))
