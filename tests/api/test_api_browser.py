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


# ---------------------------------------------------------------- what the page shows of the drawn map
def _compute(b: Browser, timeout: float = 120) -> None:
    """Click "Compute contours" and wait for the answer drawn or an error in the status."""
    b.evaluate("gisnoise.contourCount = 0; document.getElementById('btn-compute').click(); true")
    b.wait_for("gisnoise.contourCount > 0 || document.getElementById('status').classList.contains('error')", timeout)
    assert not b.evaluate("document.getElementById('status').classList.contains('error')"), \
        b.evaluate("document.getElementById('status').textContent")


def _visible_text(b: Browser) -> str:
    """The panel's text as rendered: hidden elements and closed disclosures are not in it."""
    return b.evaluate("document.getElementById('panel').innerText")


def _set_metric(b: Browser, metric: str) -> None:
    b.evaluate(f"{{ const m = document.getElementById('metric'); m.value = '{metric}';"
               "m.dispatchEvent(new Event('change')); } true")


def _drawn_metrics(b: Browser) -> list[str]:
    """The metric of every contour feature on the map (none when no contour layer is on it)."""
    return b.evaluate("gisnoise.contourLayer && gisnoise.map.hasLayer(gisnoise.contourLayer)"
                      " ? gisnoise.contourLayer.getLayers().map((l) => l.feature.properties.metric) : []")


def _legend_title(b: Browser) -> str | None:
    return b.evaluate("(document.querySelector('#legend .legend-title') || {}).textContent || null")


def _wait_job_shown(b: Browser) -> str:
    """After a job was queued from the page: its id, once it succeeded and its contours are drawn."""
    job = b.wait_for("gisnoise.shownJob", 20)
    b.wait_for(f"(document.querySelector('#jobs tr[data-job=\"{job}\"]') || {{dataset: {{}}}}).dataset.status"
               " === 'succeeded'", 120)
    # its map shown (the status names the job; a map drawn before may still be on screen until then)
    b.wait_for(f"document.getElementById('status').textContent.startsWith('Job {job[:8]}: ')", 30)
    assert b.evaluate("gisnoise.contourCount") > 0
    return job


def test_every_warning_of_the_answer_is_shown_one_line_each(page):
    """The power-range warning of the sample route (and every other line of ``gisnoise.warnings``) is visible
    text of the panel, one line each; the clipping notice of a narrow margin is shown once, not twice."""
    import httpx

    b = page
    if b.evaluate("document.getElementById('btn-sample').disabled"):
        pytest.skip("this checkout has no sample route")
    origin = b.evaluate("location.origin")
    b.evaluate("document.getElementById('btn-sample').click(); true")
    b.wait_for("gisnoise.trajectory !== null", 20)
    b.evaluate("document.getElementById('resolution').value = 30; true")
    _compute(b)
    # the answer to the same request, asked here: it warns that demo-horizontal flies outside its powers
    route = httpx.get(origin + "/samples/route").json()
    req = {"trajectory": {"format": "geojson", "data": route}, "cards": ["demo-horizontal", "demo-climb", "demo-sink"],
           "grid": {"resolution_m": 30}, "metrics": ["LAmax"], "levels": [45, 50, 55, 60, 65]}
    answer = httpx.post(origin + "/contours", json=req, timeout=120).json()["gisnoise"]["warnings"]
    power = [w for w in answer if "card 'demo-horizontal' is used at" in w and "it was fitted at" in w]
    assert len(power) == 1, answer
    text = _visible_text(b)
    lines = text.split("\n")
    assert f"warning: {power[0]}" in lines, text
    shown = b.evaluate("gisnoise.lastContours.gisnoise.warnings")
    for w in shown:
        assert f"warning: {w}" in lines and text.count(w) == 1, (w, text)

    # a margin that cuts the contours: the clipping line joins the power-range one, each shown once
    b.evaluate("document.getElementById('margin').value = 100; true")
    _compute(b)
    shown = b.evaluate("gisnoise.lastContours.gisnoise.warnings")
    clip = [w for w in shown if " contours are clipped: " in w]
    assert clip and any("card 'demo-horizontal' is used at" in w for w in shown), shown
    text = _visible_text(b)
    for w in shown:
        assert f"warning: {w}" in text.split("\n") and text.count(w) == 1, (w, text)
    # a new route clears the drawn map and its warnings
    b.evaluate("document.getElementById('btn-clear').click(); true")
    assert not any(w in _visible_text(b) for w in shown)


def test_a_jobs_warnings_are_shown_with_its_contours(page):
    """A drawn route run as a job: every warning of the job's result GeoJSON is visible text once it is shown."""
    import httpx

    b = page
    _draw_route(b)
    b.evaluate("document.getElementById('as-job').checked = true; document.getElementById('btn-compute').click();"
               "true")
    job = _wait_job_shown(b)
    result = httpx.get(f"{b.evaluate('location.origin')}/jobs/{job}/result", timeout=30).json()
    warnings = result["gisnoise"]["warnings"]
    assert any("card 'demo-" in w and "it was fitted at" in w for w in warnings), warnings
    lines = _visible_text(b).split("\n")
    for w in warnings:
        assert f"warning: {w}" in lines, (w, lines)


def test_a_metric_switch_never_relabels_the_drawn_contours(page):
    """Contours drawn under a legend are of the legend's metric: a metric the map lacks draws nothing and says
    to compute again; a map with several metrics draws each one's own features."""
    import httpx

    b = page
    _draw_route(b)
    _compute(b)
    assert set(_drawn_metrics(b)) == {"LAmax"} and _legend_title(b) == "LAmax, dB(A)"
    _set_metric(b, "SEL")
    drawn = _drawn_metrics(b)
    assert all(m == "SEL" for m in drawn), drawn  # was: the LAmax features under "SEL, dB(A)"
    assert not drawn and contour_fraction(b.screenshot()) < 0.005
    assert b.evaluate("document.querySelectorAll('#legend .item').length") == 0
    text = _visible_text(b)
    assert "SEL" in text and "compute" in text.lower() and "LAmax" in text, text
    # nothing drawn: nothing to download
    assert b.evaluate("document.getElementById('downloads').hidden"
                      " || document.getElementById('btn-geotiff').disabled")
    # back to the computed metric: its contours again
    _set_metric(b, "LAmax")
    assert set(_drawn_metrics(b)) == {"LAmax"} and _legend_title(b) == "LAmax, dB(A)"
    assert contour_fraction(b.screenshot()) > 0.2
    assert not b.evaluate("document.getElementById('downloads').hidden"
                          " || document.getElementById('btn-geotiff').disabled")
    # computed for SEL: SEL's features under SEL's legend
    _set_metric(b, "SEL")
    _compute(b)
    assert set(_drawn_metrics(b)) == {"SEL"} and _legend_title(b) == "SEL, dB(A)"

    # a job of two metrics, shown: each metric draws its own features
    origin = b.evaluate("location.origin")
    req = {"trajectory": b.evaluate("gisnoise.trajectory"), "cards": ["demo-horizontal", "demo-climb", "demo-sink"],
           "grid": {"resolution_m": 20}, "metrics": ["LAmax", "LAeq"], "levels": [45, 50, 55, 60, 65]}
    r = httpx.post(origin + "/jobs/contours", json=req, timeout=60)
    assert r.status_code == 202, r.text
    job = r.json()["id"]
    row = f"document.querySelector('#jobs tr[data-job=\"{job}\"]')"
    b.wait_for(f"!!({row} && {row}.dataset.status === 'succeeded' && {row}.querySelector('button'))", 120)
    b.evaluate(f"gisnoise.contourCount = 0; {row}.querySelector('button').click(); true")
    b.wait_for("gisnoise.contourCount > 0", 30)
    shown = _legend_title(b).split(",")[0]
    assert shown in ("LAmax", "LAeq") and set(_drawn_metrics(b)) == {shown}
    for metric in ("LAeq", "LAmax", "LAeq"):
        _set_metric(b, metric)
        assert set(_drawn_metrics(b)) == {metric} and _legend_title(b) == f"{metric}, dB(A)"
    _set_metric(b, "SEL")
    assert _drawn_metrics(b) == [] and b.evaluate("document.querySelectorAll('#legend .item').length") == 0


_SAVE_HOOK = ("window._saved = null; gisnoise.save = (blob, name) => { const r = new FileReader();"
              " r.onload = () => { window._saved = {name: name, data: r.result.split(',')[1]}; };"
              " r.readAsDataURL(blob); }; true")


def _download_geotiff(b: Browser) -> bytes:
    """Click "Download GeoTIFF" and return the bytes the page saves (its save function caught)."""
    import base64

    b.evaluate(_SAVE_HOOK)
    assert b.evaluate("!document.getElementById('downloads').hidden && !document.getElementById('btn-geotiff').disabled")
    b.evaluate("document.getElementById('status').classList.remove('error');"
               "document.getElementById('btn-geotiff').click(); true")
    b.wait_for("window._saved !== null || document.getElementById('status').classList.contains('error')", 120)
    assert b.evaluate("window._saved !== null"), b.evaluate("document.getElementById('status').textContent")
    assert b.evaluate("window._saved.name") == "levels.tif"
    return base64.b64decode(b.evaluate("window._saved.data"))


def _assert_geotiff_of(data: bytes, grid: dict, metrics: tuple[str, ...]) -> None:
    from rasterio.io import MemoryFile

    with MemoryFile(data) as mf, mf.open() as ds:
        assert (ds.width, ds.height) == (grid["width"], grid["height"])
        assert list(ds.transform)[:6] == pytest.approx(grid["transform"])
        assert ds.crs.to_string() == grid["crs"]
        assert ds.descriptions == metrics


def test_the_geotiff_download_is_the_drawn_map(page):
    """"Download GeoTIFF" saves the raster of the contours on screen: after a failed recompute, with the form
    changed since, and for a shown job (its own map, not the form's)."""
    pytest.importorskip("rasterio")
    b = page
    _draw_route(b)
    _compute(b)
    grid = b.evaluate("gisnoise.lastContours.gisnoise.grid")
    assert grid["transform"][0] == 20.0
    # a recompute that fails (a level that is no number): the drawn map stays, and so does its download
    b.evaluate("document.getElementById('levels').value = '45,abc'; document.getElementById('btn-compute').click();"
               "true")
    b.wait_for("document.getElementById('status').classList.contains('error')", 60)
    assert set(_drawn_metrics(b)) == {"LAmax"}
    b.evaluate("document.getElementById('resolution').value = 50; document.getElementById('metric').value = 'SEL';"
               "true")  # the form, not the map, changes (no change event: the select keeps the map drawn)
    _assert_geotiff_of(_download_geotiff(b), grid, ("LAmax",))

    # a job, shown: its own map, whatever the form says now
    b.evaluate("document.getElementById('levels').value = '45,50,55,60,65';"
               "document.getElementById('metric').value = 'LAmax';"
               "document.getElementById('resolution').value = 25; document.getElementById('as-job').checked = true;"
               "document.getElementById('btn-compute').click(); true")
    job = _wait_job_shown(b)
    job_grid = b.evaluate("gisnoise.lastContours.gisnoise.grid")
    assert job_grid["transform"][0] == 25.0
    # the form changes, then the job is shown again from its row
    b.evaluate("document.getElementById('resolution').value = 40; document.getElementById('as-job').checked = false;"
               "true")
    row = f"document.querySelector('#jobs tr[data-job=\"{job}\"]')"
    b.evaluate(f"gisnoise.contourCount = 0; {row}.querySelector('button').click(); true")
    b.wait_for("gisnoise.contourCount > 0", 30)
    assert b.evaluate("gisnoise.lastContours.gisnoise.grid") == job_grid
    _assert_geotiff_of(_download_geotiff(b), job_grid, ("LAmax",))
    # nothing drawn: no download offered
    b.evaluate("document.getElementById('btn-clear').click(); true")
    assert b.evaluate("document.getElementById('downloads').hidden"
                      " || document.getElementById('btn-geotiff').disabled")
