"""The web page in headless Chromium: draw a route, get contours drawn, follow a job's progress."""

from __future__ import annotations

import io

import pytest
from cdp_pipe import Browser, find_chromium
from service_helpers import Server

from gisnoise.maps import NOISE_CLASSES, colour_for

pytestmark = [pytest.mark.browser, pytest.mark.server]

CHROMIUM = find_chromium()
if CHROMIUM is None:
    pytest.skip("headless Chromium is not installed (scripts/install-system-deps installs it on CI)",
                allow_module_level=True)

Image = pytest.importorskip("PIL.Image")

# the shared noise palette (gisnoise.maps.palette) drawn at fill-opacity 0.55 over the map background #e8eef2
PALETTE = [hexcol for _, _, hexcol in NOISE_CLASSES]
BACKGROUND = (0xE8, 0xEE, 0xF2)
PANEL_WIDTH = 360


def _blend(hex_colour: str, alpha: float = 0.55) -> tuple[int, ...]:
    c = tuple(int(hex_colour[i:i + 2], 16) for i in (1, 3, 5))
    return tuple(round(alpha * a + (1 - alpha) * b) for a, b in zip(c, BACKGROUND, strict=True))


def contour_fraction(png: bytes) -> float:
    """Fraction of the map's pixels that show one of the contour fills."""
    img = Image.open(io.BytesIO(png)).convert("RGB")
    w, h = img.size
    targets = [_blend(c) for c in PALETTE]
    px = img.load()
    hits = total = 0
    for y in range(0, h, 4):
        for x in range(PANEL_WIDTH + 5, w, 4):
            total += 1
            r, g, b = px[x, y]
            if any(abs(r - t[0]) <= 6 and abs(g - t[1]) <= 6 and abs(b - t[2]) <= 6 for t in targets):
                hits += 1
    return hits / total


@pytest.fixture
def page(tmp_path):
    srv = Server(tmp_path / "data")
    browser = Browser(CHROMIUM)
    try:
        browser.navigate(srv.url + "/")
        browser.wait_for("window.gisnoise && window.gisnoise.ready === true", 30)
        yield browser
    finally:
        browser.close()
        srv.stop()


def _draw_route(b: Browser) -> None:
    b.evaluate("gisnoise.map.setView([53.55, 10.0], 15); true")
    b.evaluate("document.getElementById('btn-draw').click(); true")
    for x, y in [(560, 300), (820, 360), (1000, 560)]:
        b.click(x, y)
    b.evaluate("document.getElementById('btn-draw').click(); true")
    assert b.evaluate("gisnoise.trajectory.format") == "waypoints"
    assert b.evaluate("gisnoise.trajectory.data.features.length") == 5  # take-off, 3 drawn, landing


def test_draw_a_route_and_see_the_contours(page, tmp_path):
    b = page
    assert b.evaluate("document.querySelectorAll('#cards input:checked').length") == 3  # the demo cards
    _draw_route(b)
    before = contour_fraction(b.screenshot())
    b.evaluate("document.getElementById('btn-compute').click(); true")
    b.wait_for("gisnoise.contourCount > 0 || document.getElementById('status').classList.contains('error')", 60)
    assert not b.evaluate("document.getElementById('status').classList.contains('error')"), \
        b.evaluate("document.getElementById('status').textContent")
    png = b.screenshot()
    (tmp_path / "contours.png").write_bytes(png)
    after = contour_fraction(png)
    assert before < 0.005
    assert after > 0.2, f"contour fills cover {after:.1%} of the map"
    assert b.evaluate("document.querySelectorAll('#legend .item').length") == 5
    # the legend names metric and unit and uses the shared palette
    assert b.evaluate("document.querySelector('#legend .legend-title').textContent") == "LAmax, dB(A)"
    items = b.evaluate("[...document.querySelectorAll('#legend .item')].map((i) => i.textContent)")
    assert items == ["45–50 dB(A)", "50–55 dB(A)", "55–60 dB(A)", "60–65 dB(A)", "≥ 65 dB(A)"]
    swatches = b.evaluate("[...document.querySelectorAll('#legend .swatch')].map((s) => s.style.background)")
    assert swatches == [_rgb(colour_for(lv)) for lv in (45, 50, 55, 60, 65)]
    # the GeoTIFF download: the same request as a GeoTIFF, one band of the metric
    size = b.evaluate("gisnoiseFetchGeoTIFF().then((blob) => blob.arrayBuffer())"
                            ".then((buf) => { window._tif = Array.from(new Uint8Array(buf)); return buf.byteLength; })",
                            60)
    data = bytes(b.evaluate("window._tif"))
    assert size == len(data) > 1000
    pytest.importorskip("rasterio")
    from rasterio.io import MemoryFile

    with MemoryFile(data) as mf, mf.open() as ds:
        assert ds.descriptions == ("LAmax",) and ds.crs.is_projected
        assert ds.read(1).max() > 65.0


def _rgb(hexcol: str) -> str:
    r, g, b = (int(hexcol[i:i + 2], 16) for i in (1, 3, 5))
    return f"rgb({r}, {g}, {b})"


def test_unreachable_tiles_show_a_notice(tmp_path):
    # tiles from a loopback port nobody listens on: every tile fails
    srv = Server(tmp_path / "data", env={"GISNOISE_TILE_URL": "http://127.0.0.1:9/{z}/{x}/{y}.png"})
    browser = Browser(CHROMIUM)
    try:
        browser.navigate(srv.url + "/")
        browser.wait_for("window.gisnoise && window.gisnoise.ready === true", 30)
        browser.wait_for("!document.getElementById('tile-notice').hidden", 30)
        text = browser.evaluate("document.getElementById('tile-notice').textContent")
        assert "127.0.0.1:9" in text and "cannot be loaded" in text
        assert "OpenStreetMap" not in browser.evaluate("document.querySelector('.leaflet-control-attribution')"
                                                        ".textContent")
    finally:
        browser.close()
        srv.stop()


def test_a_job_shows_its_progress_then_its_contours(page):
    b = page
    _draw_route(b)
    # a fine grid: a job of a few seconds on the fast engine
    b.evaluate("document.getElementById('resolution').value = 1; document.getElementById('margin').value = 1000;"
               "document.getElementById('as-job').checked = true; document.getElementById('btn-compute').click();"
               "true")
    b.wait_for("gisnoise.shownJob != null", 20)
    row = "document.querySelector('#jobs tr[data-job=\"' + gisnoise.shownJob + '\"]')"
    b.wait_for(f"{row} !== null", 20)
    seen = b.wait_for(f"(() => {{ const r = {row}; if (!r) return false; const p = r.querySelector('progress');"
                      f"return r.dataset.status === 'running' && p.value > 0 && p.value < 1 ? p.value : false; }})()",
                      60)
    assert 0 < seen < 1
    b.wait_for(f"{row}.dataset.status === 'succeeded'", 120)
    b.wait_for("gisnoise.contourCount > 0", 30)
    assert contour_fraction(b.screenshot()) > 0.2


def test_load_the_sample_route_and_see_its_contours(page):
    b = page
    if b.evaluate("document.getElementById('btn-sample').disabled"):
        pytest.skip("this checkout has no sample route")
    b.evaluate("document.getElementById('btn-sample').click(); true")
    b.wait_for("gisnoise.trajectory !== null", 20)
    assert b.evaluate("gisnoise.trajectory.data.features.length") > 4
    assert contour_fraction(b.screenshot()) < 0.005
    b.evaluate("document.getElementById('resolution').value = 30; document.getElementById('btn-compute').click();"
               "true")
    b.wait_for("gisnoise.contourCount > 0 || document.getElementById('status').classList.contains('error')", 120)
    assert not b.evaluate("document.getElementById('status').classList.contains('error')"), \
        b.evaluate("document.getElementById('status').textContent")
    assert contour_fraction(b.screenshot()) > 0.05  # an L-shaped route leaves much of its frame empty


def test_a_fit_job_on_a_cut_log_lists_its_warning_as_text(tmp_path):
    """The jobs table shows a succeeded fit job's warnings (the campaign's log cut short) under its row, as
    plain text: the job's summary, line for line."""
    import httpx

    pytest.importorskip("pymavlink", reason="DataFlash logs need the 'logs' extra")
    from log171_campaign import campaign, cut_log, zip_campaign

    cut, k = cut_log(tmp_path)
    data = zip_campaign(campaign(tmp_path / "camp", cut))
    srv = Server(tmp_path / "data")
    browser = Browser(CHROMIUM)
    try:
        browser.navigate(srv.url + "/")
        browser.wait_for("window.gisnoise && window.gisnoise.ready === true", 30)
        r = httpx.post(srv.url + "/jobs/fit", files={"campaign": ("c.zip", data, "application/zip")},
                       data={"phase": "horizontal"}, timeout=60)
        assert r.status_code == 202, r.text
        job = r.json()["id"]
        row = f"document.querySelector('#jobs tr[data-warnings-of=\"{job}\"]')"
        browser.wait_for(f"{row} !== null", 60)
        warnings = httpx.get(f"{srv.url}/jobs/{job}").json()["summary"]["warnings"]
        assert len(warnings) == 1 and f"flights/f1.bin: the log ends mid-message at byte {k} of " in warnings[0]
        lines = browser.evaluate(f"[...{row}.querySelectorAll('td > div')].map((d) => d.textContent)")
        assert lines == [f"warning: {w}" for w in warnings]
        assert browser.evaluate(f"{row}.querySelectorAll('td > div > *').length") == 0   # text, no markup
    finally:
        browser.close()
        srv.stop()
