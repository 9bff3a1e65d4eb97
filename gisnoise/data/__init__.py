"""Data that ship inside the package: the bundled model cards and the sample route.

Read with :mod:`importlib.resources`, so they are found in a checkout, an editable
install and a wheel alike.

Examples
--------
>>> from gisnoise.data import bundled_card_ids, card_path
>>> "demo-horizontal" in bundled_card_ids()
True
>>> card_path("demo-horizontal").name
'demo_horizontal.json'
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["bundled_card_ids", "card_path", "sample_route_path", "data_path"]


def data_path(*parts: str) -> Path:
    """Path of a file or folder under the package's ``data`` folder."""
    root = resources.files(__name__)
    return Path(str(root.joinpath(*parts)))


def bundled_card_ids() -> list[str]:
    """Ids of the bundled cards (``demo-horizontal``, ``published-climb``, ...), sorted."""
    return sorted(p.stem.replace("_", "-") for p in data_path("cards").glob("*.json"))


def card_path(card_id: str) -> Path:
    """File of the bundled card ``card_id`` (``demo-horizontal`` or ``demo_horizontal``).

    Raises
    ------
    KeyError
        When no bundled card has that id; the message lists the ids there are.
    """
    p = data_path("cards", card_id.replace("-", "_") + ".json")
    if not p.is_file():
        raise KeyError(f"no bundled card {card_id!r} (bundled: {', '.join(bundled_card_ids())})")
    return p


def sample_route_path(name: str = "delivery_route.geojson") -> Path:
    """File of a bundled sample route (the web map's sample, the demo's route)."""
    return data_path("routes", name)
