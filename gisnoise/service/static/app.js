// gisnoise web page: draw or load a route, ask the service for contours, list the jobs.
// Plain JavaScript on Leaflet; every call goes to the service's own JSON API.
"use strict";

// The noise palette comes from the service (/config.json: one definition for map.png, this page and QGIS).
const BASEMAP_KEY = "gisnoise.basemap";

const app = {
  config: null,
  map: null,
  routeLayer: null,
  contourLayer: null,
  drawing: false,
  drawn: [],          // [lat, lng] of clicked waypoints
  trajectory: null,   // the request's trajectory object
  lastContours: null, // the GeoJSON of the map on screen (every metric it holds)
  mapSource: null,    // where that map came from: {request: body} (POST /contours) or {job: id}
  drawnMetric: null,  // the metric whose contours are drawn; null when the map does not hold the chosen one
  shownJob: null,
  jobs: [],
};
window.gisnoise = app;  // for the browser test and the curious

const $ = (id) => document.getElementById(id);

function setStatus(text, error = false) {
  const el = $("status");
  el.textContent = text;
  el.classList.toggle("error", error);
}

function headers(extra = {}) {
  const h = Object.assign({}, extra);
  const key = $("api-key").value.trim();
  if (key) h["X-API-Key"] = key;
  return h;
}

async function errorText(resp) {
  try {
    const body = await resp.json();
    return `${resp.status}: ${body.detail}`;
  } catch (e) {
    return `${resp.status} ${resp.statusText}`;
  }
}

// ------------------------------------------------------------------ start-up
async function init() {
  app.config = await (await fetch("/config.json")).json();
  $("version").textContent = "gisnoise " + app.config.version;
  $("key-label").hidden = !app.config.api_key_required;
  $("btn-sample").disabled = !app.config.sample_route;
  app.map = L.map("map", { doubleClickZoom: false, zoomSnap: 0.25 }).setView([51.0, 10.0], 6);
  $("basemap").value = localStorage.getItem(BASEMAP_KEY) || "";
  setBasemap($("basemap").value.trim() || app.config.tile_url);
  $("btn-basemap").onclick = () => {
    const url = $("basemap").value.trim();
    if (url) localStorage.setItem(BASEMAP_KEY, url); else localStorage.removeItem(BASEMAP_KEY);
    setBasemap(url || app.config.tile_url);
  };
  $("btn-geojson").onclick = downloadGeoJSON;
  $("btn-geotiff").onclick = downloadGeoTIFF;
  L.control.scale({ imperial: false }).addTo(app.map);
  app.map.on("click", onMapClick);
  $("btn-sample").onclick = loadSample;
  $("btn-draw").onclick = toggleDraw;
  $("btn-clear").onclick = clearAll;
  $("btn-compute").onclick = compute;
  $("metric").onchange = () => app.lastContours && drawMetric($("metric").value);
  await loadCards();
  pollJobs();
  app.ready = true;
}

// ------------------------------------------------------------------ basemap
function tileNotice(text) {
  const el = $("tile-notice");
  el.textContent = text;
  el.hidden = !text;
}

function setBasemap(url) {
  if (app.tiles) { app.tiles.remove(); app.tiles = null; }
  app.tilesLoaded = 0;
  app.tilesFailed = 0;
  tileNotice("");
  if (!url) { tileNotice("No basemap is set: contours are drawn on a blank map."); return; }
  const credit = url === app.config.tile_url ? (app.config.tile_attribution || "") : "";
  const opts = { maxZoom: 19, attribution: credit };
  const zooms = url === app.config.tile_url ? app.config.basemap_zoom : null;  // a served MBTiles file
  if (zooms) { opts.minNativeZoom = zooms[0]; opts.maxNativeZoom = zooms[1]; }
  const layer = L.tileLayer(url, opts);
  layer.on("tileload", () => { app.tilesLoaded += 1; if (app.tilesLoaded === 1) tileNotice(""); });
  layer.on("tileerror", () => {
    app.tilesFailed += 1;
    if (app.tilesLoaded === 0 && app.tilesFailed === 1) {
      let host = url;
      try { host = new URL(url.replace(/[{}]/g, "")).host || url; } catch (e) { /* keep the URL */ }
      tileNotice(`Map tiles from ${host} cannot be loaded (offline, or the source is down): the basemap is `
        + "blank. Contours and the track still show; set a local or self-hosted tile URL under Basemap.");
      if (app.map.attributionControl) app.map.attributionControl.removeAttribution(credit);
    }
  });
  app.tiles = layer.addTo(app.map);
}

async function loadCards() {
  const resp = await fetch("/cards");
  const box = $("cards");
  box.textContent = "";
  if (!resp.ok) { box.textContent = await errorText(resp); return; }
  const { cards } = await resp.json();
  for (const c of cards) {
    const label = document.createElement("label");
    const cb = document.createElement("input");
    cb.type = "checkbox";
    cb.value = c.id;
    cb.checked = c.id.startsWith("demo-");
    label.append(cb, ` ${c.id} `);
    const small = document.createElement("span");
    small.className = "hint";
    small.textContent = `(${c.phases.join(", ")})`;
    label.append(small);
    box.append(label);
  }
}

// ------------------------------------------------------------------ route
async function loadSample() {
  const resp = await fetch("/samples/route");
  if (!resp.ok) { setStatus(await errorText(resp), true); return; }
  const geo = await resp.json();
  stopDrawing();
  app.drawn = [];
  app.trajectory = { format: "geojson", data: geo };
  const layer = L.featureGroup();
  L.geoJSON(geo, { pointToLayer: (f, ll) => L.circleMarker(ll, { radius: 4, color: "#0047ab" }),
                   style: { color: "#0047ab", weight: 3 } }).addTo(layer);
  const points = (geo.features || []).filter((f) => f.geometry && f.geometry.type === "Point")
    .map((f) => [f.geometry.coordinates[1], f.geometry.coordinates[0]]);
  if (points.length > 1) L.polyline(points, { color: "#0047ab", weight: 3 }).addTo(layer);  // waypoints in order
  showRoute(layer);
  $("route-info").textContent = "Sample route loaded.";
}

function showRoute(layer) {
  if (app.routeLayer) app.routeLayer.remove();
  app.routeLayer = layer.addTo(app.map);
  const b = layer.getBounds();
  if (b.isValid()) app.map.fitBounds(b.pad(0.4));
}

function toggleDraw() {
  if (app.drawing) { finishDrawing(); return; }
  app.drawing = true;
  app.drawn = [];
  app.trajectory = null;
  $("btn-draw").textContent = "Finish";
  $("btn-draw").classList.add("active");
  $("route-info").textContent = "Click waypoints on the map, then Finish.";
  redrawDrawn();
}

function stopDrawing() {
  app.drawing = false;
  $("btn-draw").textContent = "Draw route";
  $("btn-draw").classList.remove("active");
}

function onMapClick(ev) {
  if (!app.drawing) return;
  app.drawn.push([ev.latlng.lat, ev.latlng.lng]);
  redrawDrawn();
}

function redrawDrawn() {
  const g = L.featureGroup();
  if (app.drawn.length > 1) L.polyline(app.drawn, { color: "#0047ab", weight: 3, dashArray: "6 4" }).addTo(g);
  app.drawn.forEach((ll) => L.circleMarker(ll, { radius: 4, color: "#0047ab" }).addTo(g));
  if (app.routeLayer) app.routeLayer.remove();
  app.routeLayer = g.addTo(app.map);
}

function waypointsDocument(points, altitude, speed) {
  // GeoJSON waypoints (SPEC section 7, gisnoise.routes): vertical take-off at the first point, the drawn
  // points at the cruise altitude above ground, vertical landing at the last point.
  const point = ([lat, lng], alt) => ({
    type: "Feature",
    geometry: { type: "Point", coordinates: [lng, lat] },
    properties: { alt: alt, speed: speed },
  });
  const first = points[0], last = points[points.length - 1];
  return {
    type: "FeatureCollection",
    route: { altitude_reference: "agl" },
    features: [point(first, 0), ...points.map((p) => point(p, altitude)), point(last, 0)],
  };
}

function finishDrawing() {
  stopDrawing();
  if (app.drawn.length < 2) {
    $("route-info").textContent = "A route needs at least two waypoints.";
    app.trajectory = null;
    return;
  }
  const alt = Number($("alt").value), speed = Number($("speed").value);
  app.trajectory = { format: "waypoints", data: waypointsDocument(app.drawn, alt, speed) };
  $("route-info").textContent = `${app.drawn.length} waypoints at ${alt} m, ${speed} m/s.`;
}

function clearAll() {
  stopDrawing();
  app.drawn = [];
  app.trajectory = null;
  if (app.routeLayer) app.routeLayer.remove();
  if (app.contourLayer) app.contourLayer.remove();
  app.routeLayer = app.contourLayer = app.lastContours = app.mapSource = app.drawnMetric = null;
  app.contourCount = 0;
  $("legend").textContent = "";
  showWarnings([]);
  updateDownloads();
  setStatus("");
}

// ------------------------------------------------------------------ contours
function request() {
  const cards = [...document.querySelectorAll("#cards input:checked")].map((cb) => cb.value);
  const levels = $("levels").value.split(",").map((s) => s.trim()).filter((s) => s).map(Number);
  const grid = { resolution_m: Number($("resolution").value) };
  if ($("margin").value.trim() !== "") grid.margin_m = Number($("margin").value);
  return {
    trajectory: app.trajectory,
    cards,
    grid,
    metrics: [$("metric").value],
    levels,
  };
}

async function compute() {
  if (app.drawing) finishDrawing();
  if (!app.trajectory) { setStatus("Load or draw a route first.", true); return; }
  const asJob = $("as-job").checked;
  setStatus("Computing…");
  const t0 = performance.now();
  // the request as sent: kept with the map it gives (the form may change meanwhile), for the GeoTIFF download
  const body = JSON.stringify(request());
  const resp = await fetch("/contours" + (asJob ? "?job=true" : ""), {
    method: "POST",
    headers: headers({ "Content-Type": "application/json", Accept: "application/geo+json" }),
    body: body,
  });
  // a failed request leaves the map on screen as it is: contours, warnings, downloads
  if (resp.status === 202) {
    const job = await resp.json();
    app.shownJob = job.id;
    app.shownDone = false;
    setStatus(`Queued as job ${job.id.slice(0, 8)}; the map appears when it is done.`);
    refreshJobs();
    return;
  }
  if (!resp.ok) { setStatus(await errorText(resp), true); return; }
  const geo = await resp.json();
  showMap(geo, { request: JSON.parse(body) });
  setStatus(`Contours in ${((performance.now() - t0) / 1000).toFixed(1)} s: ${geo.features.length} features`
    + warningCount(geo) + ".");
}

function mapWarnings(geo) {
  return (geo.gisnoise && geo.gisnoise.warnings) || [];
}

function warningCount(geo) {
  const n = mapWarnings(geo).length;
  return n ? `, ${n} warning${n > 1 ? "s" : ""} below` : "";
}

// The warnings of the map on screen (gisnoise.warnings of its GeoJSON: power ranges, clipped contours, ...),
// one line each, as plain text; they stay while the map is drawn.
function showWarnings(warnings) {
  const box = $("map-warnings");
  box.textContent = "";
  for (const w of warnings) {
    const line = document.createElement("div");
    line.textContent = `warning: ${w}`;
    box.append(line);
  }
  box.hidden = warnings.length === 0;
}

function mapMetrics(geo) {
  const listed = geo.gisnoise && geo.gisnoise.metrics;
  return listed && listed.length ? listed : [...new Set(geo.features.map((f) => f.properties.metric))];
}

// A new map on screen: its warnings, the chosen metric's contours (or, when the map lacks it, its first
// metric's, the Metric list set to it), and where it came from for the downloads.
function showMap(geo, source) {
  app.lastContours = geo;
  app.mapSource = source;
  showWarnings(mapWarnings(geo));
  const metrics = mapMetrics(geo);
  const select = $("metric");
  if (!metrics.includes(select.value) && metrics.length
      && [...select.options].some((o) => o.value === metrics[0])) select.value = metrics[0];
  drawMetric(metrics.includes(select.value) || !metrics.length ? select.value : metrics[0]);
  const b = app.contourLayer ? app.contourLayer.getBounds() : null;
  // at once: a layer added during a zoom animation (a quick switch of Metric) would be drawn at the old scale
  if (b && b.isValid()) app.map.fitBounds(b.pad(0.05), { animate: false });
}

function colourFor(level) {
  const classes = app.config.palette.classes;
  let c = classes[0].colour;
  for (const k of classes) if (k.from_db === null || level >= k.from_db) c = k.colour;
  return c;
}

function unitOf(feats) {
  const f = feats.find((x) => x.properties.unit);
  return f ? f.properties.unit : "dB(A)";
}

// Draw the contours of one metric of the map on screen, and its legend. Only that metric's features are
// drawn under its name: a metric the map does not hold draws nothing and says to compute it.
function drawMetric(metric) {
  const geo = app.lastContours;
  if (app.contourLayer) app.contourLayer.remove();
  app.contourLayer = null;
  const legend = $("legend");
  legend.textContent = "";
  const metrics = mapMetrics(geo);
  if (!metrics.includes(metric)) {
    app.drawnMetric = null;
    app.contourCount = 0;
    const note = document.createElement("div");
    note.className = "legend-note";
    note.textContent = `${metric} is not in the map on screen (computed: ${metrics.join(", ") || "none"}). `
      + `Click "Compute contours" to compute ${metric}.`;
    legend.append(note);
    updateDownloads();
    return;
  }
  const feats = geo.features.filter((f) => f.properties.metric === metric);
  const levels = [...new Set(feats.map((f) => f.properties.level))].sort((a, b) => a - b);
  app.contourLayer = L.geoJSON({ type: "FeatureCollection", features: feats }, {
    style: (f) => {
      const c = colourFor(f.properties.level);
      return f.properties.kind === "isoline"
        ? { color: app.config.palette.isoline, weight: 1, opacity: 0.8, fill: false }
        : { color: c, weight: 0.5, fillColor: c, fillOpacity: 0.55 };
    },
    onEachFeature: (f, layer) => layer.bindTooltip(
      `${f.properties.metric} ${f.properties.level}${f.properties.level_max != null ? "–" + f.properties.level_max : ""} dB(A)`
      + (f.properties.clipped ? " (clipped by the grid's edge)" : "")),
  }).addTo(app.map);
  if (app.routeLayer) app.routeLayer.bringToFront();
  const unit = unitOf(feats);
  const title = document.createElement("div");
  title.className = "legend-title";
  title.textContent = `${metric}, ${unit}`;
  title.title = app.config.palette.name;
  legend.append(title);
  levels.forEach((lv, i) => {
    const item = document.createElement("span");
    item.className = "item";
    const sw = document.createElement("span");
    sw.className = "swatch";
    sw.style.background = colourFor(lv);
    const range = i + 1 < levels.length ? `${lv}–${levels[i + 1]}` : `≥ ${lv}`;
    item.append(sw, `${range} ${unit}`);
    legend.append(item);
  });
  if (!feats.length) {
    const note = document.createElement("div");
    note.className = "legend-note";
    note.textContent = `No ${metric} contours: no receiver reaches the lowest level.`;
    legend.append(note);
  }
  app.drawnMetric = metric;
  app.contourCount = feats.length;
  updateDownloads();
}

// ------------------------------------------------------------------ downloads
function saveBlob(blob, name) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = name;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}

app.save = saveBlob;  // the downloads save through this (the browser test catches the bytes here)

// The downloads are offered while a map is on screen, and enabled while its chosen metric is drawn:
// they save that map (its GeoJSON; its GeoTIFF from its own request or job), never the form's.
function updateDownloads() {
  $("downloads").hidden = !app.lastContours;
  const off = app.drawnMetric === null;
  for (const id of ["btn-geojson", "btn-geotiff"]) {
    $(id).disabled = off;
    $(id).title = off ? "Nothing is drawn: compute the map for the chosen metric first" : "";
  }
}

function downloadGeoJSON() {
  if (!app.lastContours || app.drawnMetric === null) return;
  app.save(new Blob([JSON.stringify(app.lastContours)], { type: "application/geo+json" }), "contours.geojson");
}

async function fetchGeoTIFF() {
  const source = app.mapSource;
  if (!source) throw new Error("No map on screen: compute one first.");
  let resp;
  if (source.job) {  // the job's own levels.tif
    resp = await fetch(`/jobs/${source.job}/result?format=geotiff`, { headers: { Accept: "image/tiff" } });
  } else {  // the request that gave the drawn contours, as a GeoTIFF
    resp = await fetch("/contours", {
      method: "POST",
      headers: headers({ "Content-Type": "application/json", Accept: "image/tiff" }),
      body: JSON.stringify({ ...source.request, output: "geotiff" }),
    });
  }
  if (resp.status === 202) {
    const job = await resp.json();
    refreshJobs();
    throw new Error(`The GeoTIFF is large: it was queued as job ${job.id.slice(0, 8)}; its levels.tif `
      + "is its result under Jobs.");
  }
  if (!resp.ok) throw new Error(await errorText(resp));
  return resp.blob();
}

async function downloadGeoTIFF() {
  if (!app.mapSource || app.drawnMetric === null) {
    setStatus("Nothing is drawn: compute a map first.", true);
    return;
  }
  setStatus("Preparing the GeoTIFF…");
  try {
    const blob = await fetchGeoTIFF();
    app.save(blob, "levels.tif");
    setStatus(`GeoTIFF of ${blob.size} bytes saved as levels.tif.`);
  } catch (e) { setStatus(String(e.message || e), true); }
}
window.gisnoiseFetchGeoTIFF = fetchGeoTIFF;  // for the browser test

// ------------------------------------------------------------------ jobs
async function pollJobs() {
  await refreshJobs();
  const busy = app.jobs.some((j) => j.status === "queued" || j.status === "running");
  setTimeout(pollJobs, busy ? 400 : 2000);
}

async function refreshJobs() {
  let resp;
  try { resp = await fetch("/jobs?limit=20"); } catch (e) { return; }
  if (!resp.ok) return;
  const { jobs } = await resp.json();
  app.jobs = jobs;
  const tbody = document.querySelector("#jobs tbody");
  tbody.textContent = "";
  for (const j of jobs) {
    const tr = document.createElement("tr");
    tr.dataset.job = j.id;
    tr.dataset.status = j.status;
    const cells = [j.id.slice(0, 8), j.kind, j.status];
    for (const text of cells) {
      const td = document.createElement("td");
      td.textContent = text;
      tr.append(td);
    }
    const tdp = document.createElement("td");
    const bar = document.createElement("progress");
    bar.max = 1;
    bar.value = j.progress;
    bar.title = `${Math.round(j.progress * 100)} % ${j.message}`;
    const pct = document.createElement("span");
    pct.className = "hint";
    pct.textContent = ` ${Math.round(j.progress * 100)} %`;
    tdp.append(bar, pct);
    tr.append(tdp);
    const tda = document.createElement("td");
    if (j.status === "queued" || j.status === "running") {
      const b = document.createElement("button");
      b.textContent = "cancel";
      b.onclick = () => fetch(`/jobs/${j.id}/cancel`, { method: "POST", headers: headers() }).then(refreshJobs);
      tda.append(b);
    } else if (j.status === "succeeded" && j.kind === "contours") {
      const b = document.createElement("button");
      b.textContent = "show";
      b.onclick = () => showJob(j.id);
      tda.append(b);
    } else if (j.status === "succeeded") {
      const a = document.createElement("a");
      a.href = j.result_url;
      a.textContent = "result";
      tda.append(a);
    } else if (j.error) {
      tda.textContent = j.error.detail.slice(0, 60);
    }
    tr.append(tda);
    tbody.append(tr);
    const warnings = (j.summary && j.summary.warnings) || [];  // a failed job keeps them too
    if (warnings.length) tbody.append(warningsRow(j.id, warnings));
    if (j.id === app.shownJob && j.status === "succeeded" && !app.shownDone) {
      app.shownDone = true;
      showJob(j.id);
    }
  }
}

// A job's warnings (fit and diagnose: the campaign's flight logs), one line each, as plain text.
function warningsRow(id, warnings) {
  const tr = document.createElement("tr");
  tr.className = "job-warnings";
  tr.dataset.warningsOf = id;
  const td = document.createElement("td");
  td.colSpan = 5;
  for (const w of warnings) {
    const line = document.createElement("div");
    line.textContent = `warning: ${w}`;
    td.append(line);
  }
  tr.append(td);
  return tr;
}

async function showJob(id) {
  const resp = await fetch(`/jobs/${id}/result`, { headers: { Accept: "application/geo+json" } });
  if (!resp.ok) { setStatus(await errorText(resp), true); return; }
  const geo = await resp.json();
  showMap(geo, { job: id });
  setStatus(`Job ${id.slice(0, 8)}: ${geo.features.length} features${warningCount(geo)}.`);
}

init().catch((e) => setStatus(String(e), true));
