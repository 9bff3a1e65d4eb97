"""A basemap from a local MBTiles file or PMTiles archive, served by the service for the web page (offline maps).

``gisnoise serve --basemap tiles.mbtiles`` (or ``GISNOISE_BASEMAP``) serves the raster
tiles of a PMTiles v3 archive (:mod:`gisnoise.service.pmtiles`) or of an MBTiles file (an SQLite database: table ``tiles`` with ``zoom_level``,
``tile_column``, ``tile_row`` in the TMS scheme, and ``metadata`` with ``format`` and
``attribution``) at ``/basemap/{z}/{x}/{y}`` in the XYZ scheme the web page's tile layer
asks for; the page's basemap is then that source, credited with the file's attribution.
Vector tiles (``pbf``, ``mvt``) cannot be drawn by the page and are refused, as are files
that are neither.

The served file (:class:`Basemap`) stays open between tiles: an MBTiles file keeps one
SQLite connection, a PMTiles archive its parsed directories.  Each tile checks the file's
path, modification time, size and inode; a file replaced while the service runs is opened
afresh, so its new tiles (and attribution and zooms) are served.
"""

from __future__ import annotations

import os
import sqlite3
import threading
from dataclasses import dataclass, field
from pathlib import Path

from fastapi import APIRouter, Response

from gisnoise.errors import InputError
from gisnoise.service.deps import StateDep
from gisnoise.service.errors import ApiError
from gisnoise.service.pmtiles import MAGIC as PMTILES_MAGIC
from gisnoise.service.pmtiles import PMTiles, open_pmtiles

__all__ = ["Basemap", "MBTiles", "open_basemap", "router", "TILE_URL"]

router = APIRouter()

#: The tile URL template of a served basemap (relative to the service).
TILE_URL = "/basemap/{z}/{x}/{y}"

_MEDIA = {"png": "image/png", "jpg": "image/jpeg", "jpeg": "image/jpeg", "webp": "image/webp"}


@dataclass
class MBTiles:
    """An opened MBTiles file: its path, tile media type, attribution and zoom range.

    Its tiles are read through one connection, opened at the first tile and kept until
    :meth:`close`; one thread at a time (:class:`Basemap` holds a lock).
    """

    path: Path
    media_type: str
    attribution: str
    min_zoom: int
    max_zoom: int
    _con: sqlite3.Connection | None = field(default=None, repr=False, compare=False)

    def _connect(self) -> sqlite3.Connection:
        return sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro", uri=True, check_same_thread=False)

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        """The tile at XYZ ``z/x/y`` (row flipped to TMS), or None when the file has none there."""
        if not (0 <= z <= 30 and 0 <= x < (1 << z) and 0 <= y < (1 << z)):
            return None
        if self._con is None:
            self._con = self._connect()
        row = self._con.execute("SELECT tile_data FROM tiles WHERE zoom_level = ? AND tile_column = ? AND tile_row = ?",
                                (z, x, (1 << z) - 1 - y)).fetchone()
        return bytes(row[0]) if row else None

    def close(self) -> None:
        """Close the connection (a later tile opens another)."""
        if self._con is not None:
            self._con.close()
            self._con = None


def _file_key(p: Path) -> tuple[str, int, int, int]:
    """What tells a replaced file from the one opened: path, modification time (ns), size, inode."""
    try:
        st = os.stat(p)
    except OSError:
        raise InputError(f"basemap: no such file {p}", field="basemap") from None
    return str(p.resolve()), st.st_mtime_ns, st.st_size, st.st_ino


class Basemap:
    """The basemap file the service serves: the tiles (:meth:`tile`), attribution and zooms (:meth:`opened`) of the
    file now at ``path``.

    The opened file (:class:`MBTiles` or :class:`PMTiles`) is kept while the file's
    :func:`_file_key` stays the same and opened afresh when it changes; a lock lets the
    service's threads share it.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._lock = threading.Lock()
        self._key: tuple[str, int, int, int] | None = None
        self._src: MBTiles | PMTiles | None = None
        self._current()

    def _current(self) -> MBTiles | PMTiles:
        """The opened file, opened afresh when the file changed; call with the lock held or from ``__init__``."""
        key = _file_key(self.path)
        if key != self._key or self._src is None:
            src = _open_file(self.path)
            self.close()
            self._src, self._key = src, key
        return self._src

    def opened(self) -> MBTiles | PMTiles:
        """The file as now opened (its media type, attribution, zooms: read them from one call, so they belong
        together); :class:`~gisnoise.errors.InputError` when the file is gone or no longer a basemap."""
        with self._lock:
            return self._current()

    def tile(self, z: int, x: int, y: int) -> tuple[bytes, str] | None:
        """The tile at XYZ ``z/x/y`` and its media type, or None when the file has none there."""
        with self._lock:
            src = self._current()
            data = src.tile(z, x, y)
            return None if data is None else (data, src.media_type)

    def close(self) -> None:
        """Close what the opened file holds (an MBTiles connection, a PMTiles file)."""
        if self._src is not None:
            self._src.close()


def open_basemap(path: str | Path) -> Basemap:
    """Open and check an MBTiles or PMTiles basemap; :class:`~gisnoise.errors.InputError` (field ``basemap``) names
    what is wrong."""
    return Basemap(path)


def _open_file(path: str | Path) -> MBTiles | PMTiles:
    """Open and check the file at ``path`` as it is now."""
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
        con = m._connect()  # only for the checks: the tiles get their own connection
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
    try:
        found = mb.tile(z, x, y)
    except InputError as exc:  # the served file was removed or replaced by one that is not a basemap
        raise ApiError(503, f"path: the basemap cannot be read now: {exc}", field="path") from None
    if found is None:
        raise ApiError(404, f"path: the basemap has no tile {z}/{x}/{y}", field="path")
    data, media_type = found
    return Response(data, media_type=media_type, headers={"Cache-Control": "public, max-age=3600"})
