"""Raster tiles of a PMTiles (version 3) archive, for the service's offline basemap.

An opened archive (:func:`open_pmtiles`) holds its header and root directory parsed, and
keeps the leaf directories it reads; a tile costs one read of its data.

The archive's layout (the PMTiles v3 specification): a 127-byte header (magic
``PMTiles``, version 3, little-endian offsets and lengths of the root directory, the
metadata, the leaf directories and the tile data, the compressions, the tile type and the
zoom range), directories of varint-coded entries ``(tile_id, run_length, length, offset)``
sorted by tile id (run length 0: a leaf directory), and tile ids along a Hilbert curve per
zoom level (:func:`zxy_to_tileid`).  Compressions read here: none and gzip (brotli and
zstd are refused by name).
"""

from __future__ import annotations

import gzip
import json
import os
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gisnoise.errors import InputError

__all__ = ["PMTiles", "open_pmtiles", "zxy_to_tileid", "MAGIC"]

MAGIC = b"PMTiles"
#: magic, version, 11 offsets/lengths/counts (root dir, metadata, leaf dirs, tile data, 3 counts), clustered,
#: internal and tile compression, tile type, min and max zoom, bounds (4 x int32 e7), centre zoom, lon, lat.
_HEADER = struct.Struct("<7sB11QBBBBBBiiiiBii")
_COMPRESSION = {1: "none", 2: "gzip", 3: "brotli", 4: "zstd"}
_TILE_TYPE = {1: "mvt", 2: "image/png", 3: "image/jpeg", 4: "image/webp", 5: "avif"}
_MAX_LEAVES = 256
"""Leaf directories an opened archive keeps parsed (then it starts afresh)."""


def zxy_to_tileid(z: int, x: int, y: int) -> int:
    """The PMTiles tile id: the tiles of all lower zooms, then the Hilbert index of ``(x, y)`` at zoom ``z``.

    >>> [zxy_to_tileid(*t) for t in [(0, 0, 0), (1, 0, 0), (1, 0, 1), (1, 1, 1), (1, 1, 0), (2, 0, 0)]]
    [0, 1, 2, 3, 4, 5]
    """
    n = 1 << z
    d = 0
    s = n >> 1
    while s > 0:
        rx = 1 if x & s else 0
        ry = 1 if y & s else 0
        d += s * s * ((3 * rx) ^ ry)
        if ry == 0:
            if rx == 1:
                x, y = n - 1 - x, n - 1 - y
            x, y = y, x
        s >>= 1
    return ((1 << (2 * z)) - 1) // 3 + d


def _varint(buf: bytes, pos: int) -> tuple[int, int]:
    out = shift = 0
    while True:
        b = buf[pos]
        pos += 1
        out |= (b & 0x7F) << shift
        if b < 0x80:
            return out, pos
        shift += 7


def _parse_directory(data: bytes, header: tuple[Any, ...]) -> list[tuple[int, int, int, int]]:
    """Entries of a directory's bytes as stored (gzip when the header's internal compression says so)."""
    return _entries(gzip.decompress(data) if header[14] == 2 else data)


def _entries(data: bytes) -> list[tuple[int, int, int, int]]:
    """Directory entries ``(tile_id, run_length, length, offset)``."""
    n, pos = _varint(data, 0)
    ids: list[int] = []
    runs: list[int] = []
    lengths: list[int] = []
    offsets: list[int] = []
    last = 0
    for _ in range(n):
        v, pos = _varint(data, pos)
        last += v
        ids.append(last)
    for dest in (runs, lengths):
        for _ in range(n):
            v, pos = _varint(data, pos)
            dest.append(v)
    for i in range(n):
        v, pos = _varint(data, pos)
        offsets.append(offsets[i - 1] + lengths[i - 1] if (v == 0 and i > 0) else v - 1)
    return list(zip(ids, runs, lengths, offsets, strict=True))


@dataclass
class PMTiles:
    """An opened PMTiles archive: path, tile media type, attribution, zoom range.

    It holds the file open (``_fd``) from its opening: tiles are read from the file whose
    directories it parsed, even when another file replaces it at ``path`` meanwhile.
    """

    path: Path
    media_type: str
    attribution: str
    min_zoom: int
    max_zoom: int
    _header: tuple[Any, ...] = field(repr=False, default=())
    _root: list[tuple[int, int, int, int]] = field(repr=False, default_factory=list)
    _leaves: dict[tuple[int, int], list[tuple[int, int, int, int]]] = field(repr=False, default_factory=dict)
    _fd: int = field(repr=False, default=-1)

    def _read(self, offset: int, length: int) -> bytes:
        return os.pread(self._fd, length, offset)

    def close(self) -> None:
        """Close the file."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

    def __del__(self) -> None:
        self.close()

    def _directory(self, offset: int, length: int) -> list[tuple[int, int, int, int]]:
        """The directory at ``offset``: the root parsed once at opening, leaf directories kept once read."""
        if (offset, length) == (self._header[2], self._header[3]):
            return self._root
        entries = self._leaves.get((offset, length))
        if entries is None:
            if len(self._leaves) >= _MAX_LEAVES:
                self._leaves.clear()
            entries = self._leaves[(offset, length)] = _parse_directory(self._read(offset, length), self._header)
        return entries

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        """The tile at XYZ ``z/x/y``, or None when the archive has none there."""
        if not (self.min_zoom <= z <= self.max_zoom and 0 <= x < (1 << z) and 0 <= y < (1 << z)):
            return None
        h = self._header
        tid = zxy_to_tileid(z, x, y)
        offset, length = h[2], h[3]
        for _depth in range(4):
            entries = self._directory(offset, length)
            found = None
            for e in entries:  # the last entry at or before tid
                if e[0] > tid:
                    break
                found = e
            if found is None:
                return None
            eid, run, elen, eoff = found
            if run == 0:  # a leaf directory
                offset, length = h[6] + eoff, elen
                continue
            if tid >= eid + run:
                return None
            data = self._read(h[8] + eoff, elen)
            return gzip.decompress(data) if h[15] == 2 else data
        return None


def open_pmtiles(path: Path) -> PMTiles:
    """Open and check a PMTiles v3 archive of raster tiles (:class:`InputError`, field ``basemap``)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        return _checked(path, fd)
    except BaseException:
        os.close(fd)
        raise


def _checked(path: Path, fd: int) -> PMTiles:
    """The archive open on ``fd``, its header, root directory and metadata read and checked."""
    raw = os.pread(fd, _HEADER.size, 0)
    if len(raw) < _HEADER.size or raw[:7] != MAGIC:
        raise InputError(f"basemap: {path.name} is not a PMTiles archive", field="basemap")
    h = _HEADER.unpack(raw)
    if h[1] != 3:
        raise InputError(f"basemap: {path.name} is PMTiles version {h[1]}; the service reads version 3",
                         field="basemap")
    internal, tile_comp, tile_type = h[14], h[15], h[16]
    for what, comp in (("directories", internal), ("tiles", tile_comp)):
        if comp not in (1, 2):
            raise InputError(f"basemap: {path.name} compresses its {what} with "
                             f"{_COMPRESSION.get(comp, f'code {comp}')}; the service reads none or gzip",
                             field="basemap")
    media = _TILE_TYPE.get(tile_type, f"type {tile_type}")
    if not media.startswith("image/"):
        raise InputError(f"basemap: {path.name} holds {media.replace('image/', '')} tiles; the web page draws "
                         "raster tiles (png, jpg, webp)", field="basemap")
    root_raw = os.pread(fd, h[3], h[2])
    meta_raw = os.pread(fd, h[5], h[4]) if h[5] else b""
    try:
        root = _parse_directory(root_raw, h)
    except (OSError, EOFError, IndexError, zlib.error) as exc:
        raise InputError(f"basemap: {path.name} has an unreadable root directory ({exc})", field="basemap") from None
    try:
        meta = json.loads((gzip.decompress(meta_raw) if internal == 2 else meta_raw) or b"{}")
    except (OSError, ValueError):
        meta = {}
    credit = str(meta.get("attribution", "")) if isinstance(meta, dict) else ""
    return PMTiles(path, media, credit, int(h[17]), int(h[18]), h, root, _fd=fd)
