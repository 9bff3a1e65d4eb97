"""An offline basemap: an MBTiles file served by the service at /basemap, drawn by the web page (issue 17)."""

from __future__ import annotations

import io
import sqlite3
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


def make_mbtiles(path: Path, fmt: str = "png") -> Path:
    """Zooms 0-3 of the whole world, in the TMS rows MBTiles stores (row 0 in the south)."""
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE metadata (name TEXT, value TEXT)")
    con.execute("CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, tile_row INTEGER, tile_data BLOB)")
    con.executemany("INSERT INTO metadata VALUES (?, ?)", [("name", "test"), ("format", fmt),
                                                           ("attribution", CREDIT)])
    land = _png(LAND)
    for z in range(4):
        for x in range(1 << z):
            for y in range(1 << z):
                data = _png(Z1[(x, y)]) if z == 1 else land
                con.execute("INSERT INTO tiles VALUES (?, ?, ?, ?)", (z, x, (1 << z) - 1 - y, data))
    con.commit()
    con.close()
    return path


def test_tiles_are_served_in_the_xyz_scheme(make_client, tmp_path):
    client = make_client(basemap=make_mbtiles(tmp_path / "world.mbtiles"))
    cfg = client.get("/config.json").json()
    assert cfg["tile_url"] == "/basemap/{z}/{x}/{y}" and cfg["tile_attribution"] == CREDIT
    assert cfg["basemap_zoom"] == [0, 3]
    for (x, y), rgb in Z1.items():  # XYZ row 0 is the north: the TMS row flips
        r = client.get(f"/basemap/1/{x}/{y}")
        assert r.status_code == 200 and r.headers["content-type"] == "image/png"
        assert Image.open(io.BytesIO(r.content)).convert("RGB").getpixel((128, 128)) == rgb
    assert client.get("/basemap/4/0/0").status_code == 404  # beyond the file's zooms
    assert client.get("/basemap/1/2/0").status_code == 404  # no such tile at zoom 1


def test_no_basemap_no_tiles(client):
    r = client.get("/basemap/0/0/0")
    assert r.status_code == 404 and "--basemap" in r.json()["detail"]


@pytest.mark.parametrize("kind,message", [
    ("missing", "no such file"), ("text", "is not an MBTiles file"), ("pmtiles", "PMTiles"),
    ("pbf", "holds pbf tiles; the web page draws raster tiles")])
def test_serve_refuses_a_bad_basemap_in_one_line(tmp_path, monkeypatch, kind, message):
    for name in ("GISNOISE_BASEMAP", "GISNOISE_DATA_DIR"):  # serve sets them; restored after the test
        monkeypatch.setenv(name, "")
    path = tmp_path / ("tiles.pmtiles" if kind == "pmtiles" else "tiles.mbtiles")
    if kind == "text":
        path.write_text("not a database\n")
    elif kind == "pmtiles":
        path.write_bytes(b"PMTiles\x03" + bytes(120))
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
        img = Image.open(io.BytesIO(browser.screenshot())).convert("RGB")
        w, h = img.size
        px = img.getpixel((int(0.75 * w), h // 2))
        assert all(abs(a - b) <= 3 for a, b in zip(px, LAND, strict=True)), px
    finally:
        browser.close()
        srv.stop()
