"""A basemap from a local MBTiles file or PMTiles archive, served by the service for the web page (offline maps).

``gisnoise serve --basemap tiles.mbtiles`` (or ``GISNOISE_BASEMAP``) serves the raster
tiles of a PMTiles v3 archive (:mod:`gisnoise.service.pmtiles`) or of an MBTiles file (an SQLite database: table ``tiles`` with ``zoom_level``,
``tile_column``, ``tile_row`` in the TMS scheme, and ``metadata`` with ``format`` and
``attribution``) at ``/basemap/{z}/{x}/{y}`` in the XYZ scheme the web page's tile layer
asks for; the page's basemap is then that source, credited with the file's attribution.
Vector tiles (``pbf``, ``mvt``) cannot be drawn by the page and are refused, as are files
that are neither.
"""

from __future__ import annotations

import sqlite3
from dataclasses import dataclass
from pathlib import Path

from fastapi import APIRouter, Response

from gisnoise.errors import InputError
from gisnoise.service.deps import StateDep
from gisnoise.service.errors import ApiError
from gisnoise.service.pmtiles import MAGIC as PMTILES_MAGIC
from gisnoise.service.pmtiles import PMTiles, open_pmtiles

__all__ = ["MBTiles", "open_basemap", "router", "TILE_URL"]

router = APIRouter()

#: The tile URL template of a served basemap (relative to the service).
TILE_URL = "/basemap/{z}/{x}/{y}"

_MEDIA = {"png": "image/png", "jpg": "image/jpeg", "jpeg": "image/jpeg", "webp": "image/webp"}


@dataclass(frozen=True)
class MBTiles:
    """An opened MBTiles file: its path, tile media type, attribution and zoom range."""

    path: Path
    media_type: str
    attribution: str
    min_zoom: int
    max_zoom: int

    def _connect(self) -> sqlite3.Connection:
        return sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro", uri=True)

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        """The tile at XYZ ``z/x/y`` (row flipped to TMS), or None when the file has none there."""
        if not (0 <= z <= 30 and 0 <= x < (1 << z) and 0 <= y < (1 << z)):
            return None
        con = self._connect()
        try:
            row = con.execute("SELECT tile_data FROM tiles WHERE zoom_level = ? AND tile_column = ? AND tile_row = ?",
                              (z, x, (1 << z) - 1 - y)).fetchone()
        finally:
            con.close()
        return bytes(row[0]) if row else None


def open_basemap(path: str | Path) -> MBTiles | PMTiles:
    """Open and check an MBTiles or PMTiles basemap; :class:`~gisnoise.errors.InputError` (field ``basemap``) names
    what is wrong."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"basemap: no such file {p}", field="basemap")
    with open(p, "rb") as fh:
        head = fh.read(16)
    if head.startswith(PMTILES_MAGIC) or p.suffix.lower() == ".pmtiles":
        return open_pmtiles(p)
    if head != b"SQLite format 3\x00":
        raise InputError(f"basemap: {p.name} is neither an MBTiles file (an SQLite database) nor a PMTiles archive",
                         field="basemap")
    m = MBTiles(p, "", "", 0, 0)
    try:
        con = m._connect()
        try:
            meta = dict(con.execute("SELECT name, value FROM metadata").fetchall())
            zooms = con.execute("SELECT MIN(zoom_level), MAX(zoom_level) FROM tiles").fetchone()
        finally:
            con.close()
    except sqlite3.Error as exc:
        raise InputError(f"basemap: {p.name} is not an MBTiles file ({exc})", field="basemap") from None
    fmt = str(meta.get("format", "png")).lower()
    if fmt not in _MEDIA:
        raise InputError(f"basemap: {p.name} holds {fmt} tiles; the web page draws raster tiles (png, jpg, webp)",
                         field="basemap")
    if zooms is None or zooms[0] is None:
        raise InputError(f"basemap: {p.name} holds no tiles", field="basemap")
    return MBTiles(p, _MEDIA[fmt], str(meta.get("attribution", "")), int(zooms[0]), int(zooms[1]))


@router.get("/basemap/{z}/{x}/{y}", include_in_schema=False)
def basemap_tile(z: int, x: int, y: int, state: StateDep) -> Response:
    """A tile of the served basemap (404 where it has none, or when the service serves no basemap)."""
    mb = state.basemap
    if mb is None:
        raise ApiError(404, "path: this service serves no basemap (gisnoise serve --basemap FILE.mbtiles)",
                       field="path")
    data = mb.tile(z, x, y)
    if data is None:
        raise ApiError(404, f"path: the basemap has no tile {z}/{x}/{y}", field="path")
    return Response(data, media_type=mb.media_type, headers={"Cache-Control": "public, max-age=3600"})
