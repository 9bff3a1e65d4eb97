"""An offline basemap: an MBTiles file served by the service at /basemap, drawn by the web page (issue 17)."""

from __future__ import annotations

import io
import sqlite3
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from gisnoise.cli.main import cli

Image = pytest.importorskip("PIL.Image")

#: One colour per XYZ tile of zoom 1 (x, y): north-west, north-east, south-west, south-east.
Z1 = {(0, 0): (200, 40, 40), (1, 0): (40, 200, 40), (0, 1): (40, 40, 200), (1, 1): (200, 200, 40)}
LAND = (90, 160, 210)  # every tile of zooms 0, 2 and 3
CREDIT = "Test tiles, CC0"


def _png(rgb: tuple[int, int, int]) -> bytes:
    buf = io.BytesIO()
    Image.new("RGB", (256, 256), rgb).save(buf, format="PNG")
    return buf.getvalue()


def make_mbtiles(path: Path, fmt: str = "png", *, z1: dict = Z1, credit: str = CREDIT) -> Path:
    """Zooms 0-3 of the whole world, in the TMS rows MBTiles stores (row 0 in the south)."""
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE metadata (name TEXT, value TEXT)")
    con.execute("CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, tile_row INTEGER, tile_data BLOB)")
    con.executemany("INSERT INTO metadata VALUES (?, ?)", [("name", "test"), ("format", fmt),
                                                           ("attribution", credit)])
    land = _png(LAND)
    for z in range(4):
        for x in range(1 << z):
            for y in range(1 << z):
                data = _png(z1[(x, y)]) if z == 1 else land
                con.execute("INSERT INTO tiles VALUES (?, ?, ?, ?)", (z, x, (1 << z) - 1 - y, data))
    con.commit()
    con.close()
    return path


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def make_pmtiles(path: Path, *, gzip_dirs: bool = False, tile_type: int = 2, internal: int | None = None,
                 z1: dict = Z1, credit: str = CREDIT) -> Path:
    """The same tiles as :func:`make_mbtiles` in a PMTiles v3 archive written by the specification's layout:
    tile ids along the Hilbert curve (the spec's own examples fix them: z1 (0,0) 1, (0,1) 2, (1,1) 3, (1,0) 4)."""
    import gzip
    import json
    import struct

    hilbert1 = {(0, 0): 1, (0, 1): 2, (1, 1): 3, (1, 0): 4}
    tiles = {0: _png(LAND)}
    for (x, y), rgb in z1.items():
        tiles[hilbert1[(x, y)]] = _png(rgb)
    from gisnoise.service.pmtiles import zxy_to_tileid

    assert all(zxy_to_tileid(1, x, y) == i for (x, y), i in hilbert1.items())
    for z in (2, 3):
        for x in range(1 << z):
            for y in range(1 << z):
                tiles[zxy_to_tileid(z, x, y)] = tiles[0]
    ids = sorted(tiles)
    blob, offsets = b"", []
    for i in ids:
        offsets.append(len(blob))
        blob += tiles[i]
    d = _varint(len(ids))
    last = 0
    for i in ids:
        d += _varint(i - last)
        last = i
    d += b"".join(_varint(1) for _ in ids) + b"".join(_varint(len(tiles[i])) for i in ids)
    d += b"".join(_varint(0 if k else offsets[k] + 1) for k in range(len(ids)))  # contiguous: 0 after the first
    meta = json.dumps({"attribution": credit}).encode()
    comp = internal or (2 if gzip_dirs else 1)
    if comp == 2:
        d, meta = gzip.compress(d), gzip.compress(meta)
    root_off = 127
    meta_off = root_off + len(d)
    data_off = meta_off + len(meta)
    header = struct.pack("<7sB11QBBBBBBiiiiBii", b"PMTiles", 3, root_off, len(d), meta_off, len(meta), data_off, 0,
                         data_off, len(blob), len(ids), len(ids), len(ids), 1, comp, 1, tile_type, 0, 3,
                         -1800000000, -850000000, 1800000000, 850000000, 0, 0, 0)
    path.write_bytes(header + d + meta + blob)
    return path


@pytest.mark.parametrize("kind", ["mbtiles", "pmtiles", "pmtiles-gzip"])
def test_tiles_are_served_in_the_xyz_scheme(make_client, tmp_path, kind):
    if kind == "mbtiles":
        path = make_mbtiles(tmp_path / "world.mbtiles")
    else:
        path = make_pmtiles(tmp_path / "world.pmtiles", gzip_dirs=kind.endswith("gzip"))
    client = make_client(basemap=path)
    cfg = client.get("/config.json").json()
    assert cfg["tile_url"] == "/basemap/{z}/{x}/{y}" and cfg["tile_attribution"] == CREDIT
    assert cfg["basemap_zoom"] == [0, 3]
    for (x, y), rgb in Z1.items():  # XYZ row 0 is the north: the TMS row flips
        r = client.get(f"/basemap/1/{x}/{y}")
        assert r.status_code == 200 and r.headers["content-type"] == "image/png"
        assert Image.open(io.BytesIO(r.content)).convert("RGB").getpixel((128, 128)) == rgb
    assert client.get("/basemap/4/0/0").status_code == 404  # beyond the file's zooms
    assert client.get("/basemap/1/2/0").status_code == 404  # no such tile at zoom 1


@pytest.mark.parametrize("kind", ["mbtiles", "pmtiles-gzip"])
def test_a_replaced_basemap_file_serves_its_new_tiles_and_an_unchanged_one_stays_open(make_client, tmp_path,
                                                                                      monkeypatch, kind):
    import os

    from gisnoise.service import basemap, pmtiles

    opened = {"connections": 0, "directories": 0}
    connect, parse = sqlite3.connect, pmtiles._parse_directory

    def counting_connect(*a, **kw):
        opened["connections"] += 1
        return connect(*a, **kw)

    def counting_parse(*a, **kw):
        opened["directories"] += 1
        return parse(*a, **kw)

    monkeypatch.setattr(basemap.sqlite3, "connect", counting_connect)
    monkeypatch.setattr(pmtiles, "_parse_directory", counting_parse)
    make = make_mbtiles if kind == "mbtiles" else lambda p, **kw: make_pmtiles(p, gzip_dirs=True, **kw)
    path = make(tmp_path / f"world.{kind[:7]}")
    client = make_client(basemap=path)
    opens = dict(opened)

    def colours():
        got = {}
        for x, y in Z1:
            r = client.get(f"/basemap/1/{x}/{y}")
            assert r.status_code == 200
            got[(x, y)] = Image.open(io.BytesIO(r.content)).convert("RGB").getpixel((128, 128))
        return got

    assert colours() == Z1 and colours() == Z1
    # eight tiles of an unchanged file: one connection (MBTiles), the root directory parsed at opening (PMTiles)
    assert opened == ({**opens, "connections": opens["connections"] + 1} if kind == "mbtiles" else opens)
    other = {k: tuple(255 - c for c in rgb) for k, rgb in Z1.items()}
    new = make(tmp_path / f"new.{kind[:7]}", z1=other, credit="Other tiles")
    os.replace(new, path)
    assert colours() == other
    assert client.get("/config.json").json()["tile_attribution"] == "Other tiles"
    path.unlink()
    for url in ("/basemap/1/0/0", "/config.json"):
        r = client.get(url)
        assert r.status_code == 503 and "no such file" in r.json()["detail"], url


def test_no_basemap_no_tiles(client):
    r = client.get("/basemap/0/0/0")
    assert r.status_code == 404 and "--basemap" in r.json()["detail"]


@pytest.mark.parametrize("kind,message", [
    ("missing", "no such file"), ("text", "is neither an MBTiles file"),
    ("pmtiles-brotli", "compresses its directories with brotli; the service reads none or gzip"),
    ("pmtiles-mvt", "holds mvt tiles; the web page draws raster tiles"),
    ("pbf", "holds pbf tiles; the web page draws raster tiles")])
def test_serve_refuses_a_bad_basemap_in_one_line(tmp_path, monkeypatch, kind, message):
    for name in ("GISNOISE_BASEMAP", "GISNOISE_DATA_DIR"):  # serve sets them; restored after the test
        monkeypatch.setenv(name, "")
    path = tmp_path / ("tiles.pmtiles" if kind.startswith("pmtiles") else "tiles.mbtiles")
    if kind == "text":
        path.write_text("not a database\n")
    elif kind == "pmtiles-brotli":
        make_pmtiles(path, internal=3)
    elif kind == "pmtiles-mvt":
        make_pmtiles(path, tile_type=1)
    elif kind == "pbf":
        make_mbtiles(path, fmt="pbf")
    r = CliRunner().invoke(cli, ["serve", "--data-dir", str(tmp_path / "data"), "--basemap", str(path)],
                           catch_exceptions=False)
    assert r.exit_code == 2
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: --basemap:") and message in lines[0], r.output


@pytest.mark.browser
@pytest.mark.server
def test_the_page_draws_the_served_basemap(tmp_path):
    from cdp_pipe import Browser, find_chromium
    from service_helpers import Server

    chromium = find_chromium()
    if chromium is None:
        pytest.skip("headless Chromium is not installed (scripts/install-system-deps installs it on CI)")
    srv = Server(tmp_path / "data", env={"GISNOISE_BASEMAP": str(make_mbtiles(tmp_path / "world.mbtiles")),
                                         "GISNOISE_TILE_URL": "http://127.0.0.1:9/{z}/{x}/{y}.png"})
    browser = Browser(chromium)
    try:
        browser.navigate(srv.url + "/")
        browser.wait_for("window.gisnoise && window.gisnoise.ready === true", 30)
        browser.wait_for("gisnoise.tilesLoaded > 0 || gisnoise.tilesFailed > 0", 30)
        assert browser.evaluate("gisnoise.tilesFailed") == 0
        assert browser.evaluate("document.getElementById('tile-notice').hidden") is True
        assert CREDIT in browser.evaluate("document.querySelector('.leaflet-control-attribution').textContent")
        # the map shows the file's tiles (zoom 6 over Germany: the zoom-3 land colour, scaled)
        # (tiles fade in: a screenshot during the fade shows the colour blended with the background)
        deadline = time.monotonic() + 15.0
        while True:
            img = Image.open(io.BytesIO(browser.screenshot())).convert("RGB")
            w, h = img.size
            px = img.getpixel((int(0.75 * w), h // 2))
            if all(abs(a - b) <= 3 for a, b in zip(px, LAND, strict=True)) or time.monotonic() > deadline:
                break
            time.sleep(0.25)
        assert all(abs(a - b) <= 3 for a, b in zip(px, LAND, strict=True)), px
    finally:
        browser.close()
        srv.stop()


def test_an_opened_pmtiles_archive_reads_its_own_file_after_a_replacement(tmp_path):
    # the directories parsed at opening index the file opened then: a file replaced at the path meanwhile
    # must not be read through them (the basemap reopens the path when it sees the change)
    import os

    from gisnoise.service.pmtiles import open_pmtiles

    path = make_pmtiles(tmp_path / "world.pmtiles")
    archive = open_pmtiles(path)
    other = {k: tuple(255 - c for c in rgb) for k, rgb in Z1.items()}
    os.replace(make_pmtiles(tmp_path / "new.pmtiles", z1=other, credit="Other tiles"), path)
    try:
        for (x, y), rgb in Z1.items():
            tile = archive.tile(1, x, y)
            assert tile is not None and Image.open(io.BytesIO(tile)).convert("RGB").getpixel((128, 128)) == rgb
        assert Image.open(io.BytesIO(open_pmtiles(path).tile(1, 0, 0))).convert("RGB").getpixel((9, 9)) == other[0, 0]
    finally:
        archive.close()
