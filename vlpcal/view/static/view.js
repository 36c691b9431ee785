// vlpcal view: the plan, the cameras' latest frames and the tracks, drawn from /scene and
// /events (server-sent events). No library, no build step: this file is all there is.
"use strict";

const TRAIL = 150;          // points of a track's trail kept
const LATENCIES = 600;      // latency samples kept for p50 / p95
const TILE_SCALE = 2;       // a camera's pixels drawn this many screen pixels wide
const GAP_SECONDS = 0.5;    // rows of a track further apart in time: its trail is broken
const STALE_SECONDS = 1.0;  // a track with no row for this long is drawn faded …
const GONE_SECONDS = 5.0;   // … and after this long not at all

const state = {
  scene: null, view: null, live: false,
  // keyed by ids from files and messages: no prototype, so an id such as "toString" or
  // "__proto__" is an id like any other
  tracks: Object.create(null),  // id → {xyz, sigma, status, yaw, t, trail: [[x, y]], rows}
  survey: {},               // a survey's progress: stop, coverage (survey capture --view)
  tiles: Object.create(null),   // id → {seq, shownSeq, skipped, spots, t, drawnAt, ...}
  updates: 0, rows: 0, missed: 0, lastUpdate: 0,
  latency: {frame: [], row: []},
  dirty: true,
};
window.vlpcalView = state;  // for a person's console and the browser tests

function $(id) { return document.getElementById(id); }

// -- the plan ------------------------------------------------------------------------------
function fitView(scene, width) {
  const pts = scene.room.concat(...scene.cameras.map(c => c.footprints.flat()));
  const xs = scene.room.map(p => p[0]), ys = scene.room.map(p => p[1]);
  const x0 = Math.min(...xs), x1 = Math.max(...xs), y0 = Math.min(...ys), y1 = Math.max(...ys);
  const pad = 0.04 * Math.max(x1 - x0, y1 - y0, 1e-9);
  const scale = width / (x1 - x0 + 2 * pad);
  const height = Math.ceil((y1 - y0 + 2 * pad) * scale);
  return {
    scale, width, height, pts,
    px: (x, y) => [(x - x0 + pad) * scale, height - (y - y0 + pad) * scale],
    world: (u, v) => [u / scale + x0 - pad, (height - v) / scale + y0 - pad],
  };
}

function colourViews(n, need) {
  if (n < 0) return null;
  if (n === 0) return "rgb(235,235,235)";
  if (n < need) return "rgb(250,200,170)";
  const g = Math.min(1, (n - need) / 3);
  return `rgb(${Math.round(200 - 120 * g)},${Math.round(230 - 60 * g)},${Math.round(190 - 40 * g)})`;
}

function colourError(e, top) {
  if (e === null || e === undefined) return null;
  const f = Math.min(1, e / top);        // viridis-like, dark = small error
  const r = Math.round(68 + f * (253 - 68)), g = Math.round(1 + f * (231 - 1));
  const b = Math.round(84 + f * (37 - 84));
  return `rgb(${r},${g},${b})`;
}

function errorTop() {
  // one scale for every height: the site's requirement when a site file states it, else the
  // 95th percentile over all the maps
  const r = state.scene.requirements;
  if (r.stated) return r.max_error_p95;
  const v = state.scene.maps.flatMap(m => m.error.filter(e => e !== null)).sort((a, b) => a - b);
  return v.length ? v[Math.floor(0.95 * (v.length - 1))] || 1e-9 : 1e-9;
}

function drawPlan() {
  const s = state.scene, view = state.view, cv = $("plan");
  const ctx = cv.getContext("2d");
  ctx.clearRect(0, 0, cv.width, cv.height);
  const layer = $("layer").value, map = s.maps[+$("height").value];
  const g = s.grid, need = s.requirements.min_cameras;
  const top = errorTop();
  if (map && layer !== "none") {
    for (let j = 0; j < g.ny; j++) {
      for (let i = 0; i < g.nx; i++) {
        const k = j * g.nx + i;
        const col = layer === "views" ? colourViews(map.views[k], need)
          : (map.views[k] < 0 ? null : colourError(map.error[k], top) || "rgb(235,235,235)");
        if (!col) continue;
        const [u, v] = view.px(g.x0 + (i - 0.5) * g.step, g.y0 + (j + 0.5) * g.step);
        ctx.fillStyle = col;
        ctx.fillRect(u, v, g.step * view.scale + 0.5, g.step * view.scale + 0.5);
      }
    }
  }
  legend(layer, top, need);
  const poly = (p, close = true) => {
    ctx.beginPath();
    p.forEach(([x, y], i) => { const [u, v] = view.px(x, y); i ? ctx.lineTo(u, v) : ctx.moveTo(u, v); });
    if (close) ctx.closePath();
  };
  ctx.lineWidth = 2; ctx.strokeStyle = "#333"; poly(s.room); ctx.stroke();
  ctx.fillStyle = "rgba(90,90,90,0.55)";
  s.keep_out.forEach(p => { poly(p); ctx.fill(); });
  s.obstacles.forEach(o => { poly(o.polygon); ctx.fillStyle = "rgba(40,40,40,0.8)"; ctx.fill(); });
  if ($("footprints").checked) {
    ctx.save(); poly(s.room); ctx.clip();   // the room sets the frame: footprints inside it
    s.cameras.forEach((c, n) => {
      const hue = (n * 137) % 360;
      ctx.strokeStyle = `hsl(${hue},60%,40%)`;
      c.footprints.forEach((f, k) => {
        if (f.length < 3) return;
        ctx.setLineDash(k ? [6, 4] : []); ctx.lineWidth = 1.2; poly(f); ctx.stroke();
      });
      ctx.setLineDash([]);
    });
    ctx.restore();
  }
  ctx.font = "12px system-ui, sans-serif";
  s.cameras.forEach((c, n) => {
    const [u, v] = view.px(c.xyz[0], c.xyz[1]);
    ctx.fillStyle = `hsl(${(n * 137) % 360},60%,35%)`;
    ctx.beginPath(); ctx.arc(u, v, 5, 0, 2 * Math.PI); ctx.fill();
    ctx.fillStyle = "#111"; ctx.fillText(c.id, u + 7, v - 7);
  });
}

function legend(layer, top, need) {
  const el = $("legend"), lines = "footprints: solid at the lowest LED height, dashed at the highest";
  if (layer === "views") {
    el.textContent = `green: ≥ ${need} cameras (darker: more); orange: fewer; grey: none · ${lines}`;
  } else if (layer === "error") {
    const what = state.scene.requirements.stated ? "the site's p95 requirement" : "the 95th percentile of every height";
    el.textContent = `predicted error: dark 0 → yellow ≥ ${(top * 1000).toFixed(1)} mm (${what}); grey: fewer than ${need} cameras`;
  } else el.textContent = "";
}

function hover(ev) {
  const s = state.scene, view = state.view, tip = $("tip");
  const r = $("overlay").getBoundingClientRect();
  const [x, y] = view.world(ev.clientX - r.left, ev.clientY - r.top);
  const g = s.grid, map = s.maps[+$("height").value];
  const i = Math.round((x - g.x0) / g.step), j = Math.round((y - g.y0) / g.step);
  let text = `x ${x.toFixed(2)} m, y ${y.toFixed(2)} m`;
  if (map && i >= 0 && j >= 0 && i < g.nx && j < g.ny) {
    const k = j * g.nx + i;
    if (map.views[k] >= 0) {
      const ids = map.cameras[k].map(c => s.cameras[c].id);
      text += `\nat ${map.height.toFixed(2)} m: seen by ${ids.length ? ids.join(", ") : "no camera"}`;
      if (map.error[k] !== null) text += `\npredicted error ${(map.error[k] * 1000).toFixed(1)} mm`;
    } else text += "\nnot floor";
  }
  tip.textContent = text; tip.hidden = false;
  tip.style.left = `${ev.clientX - r.left + 14}px`; tip.style.top = `${ev.clientY - r.top + 14}px`;
}

// -- the tracks ----------------------------------------------------------------------------
function addRows(rows) {
  const now = Date.now() / 1000;
  for (const r of rows) {
    state.rows += 1;
    if (!r.xyz || r.xyz[0] === null) continue;
    const id = r.id || (r.kind === "fix" ? "fix" : "?");
    const tr = state.tracks[id] || (state.tracks[id] = {trail: [], rows: 0});
    Object.assign(tr, {xyz: r.xyz, sigma: r.sigma, status: r.status, t: r.t,
                       yaw: Object.hasOwn(r, "yaw") ? r.yaw : null,
                       cameras: r.cameras, kind: r.kind});
    tr.rows += 1;
    // a gap in time starts a new stroke: a track that came back is not joined across the room
    const gap = tr.trail.length && r.t - tr.trail[tr.trail.length - 1][2] > GAP_SECONDS;
    tr.trail.push([r.xyz[0], r.xyz[1], r.t, gap]);
    if (tr.trail.length > TRAIL) tr.trail.shift();
    state.newest = Math.max(state.newest || 0, r.t);
    push(state.latency.row, now - r.t);
  }
  // a track with no row for a while is gone (its LED dark, out of view, or named anew)
  for (const [id, tr] of Object.entries(state.tracks)) {
    if (state.newest - tr.t > GONE_SECONDS) delete state.tracks[id];
  }
  state.dirty = true;
}

function showSurvey(survey) {
  state.survey = survey;
  $("survey").hidden = false;
  const stop = survey.stop;
  if (stop) {
    const at = stop.xyz[0] === null ? "on its mark (see the survey plan)"
      : `at (${stop.xyz.map(v => v.toFixed(2)).join(", ")}) m`;
    $("survey-stop").textContent = `next: point ${stop.id} (${stop.number} of ${stop.total}) ${at}`;
  }
  const cov = survey.coverage;
  if (cov) {
    const pairs = cov.pairs.map(([a, b, n]) => `${a}–${b} ${n}`).join(", ");
    const seen = Object.entries(cov.cameras).map(([id, c]) => `${id} ${c.sightings}`).join(", ");
    $("survey-pairs").textContent = `sightings: ${seen}. Pairs linked (sets both saw): ${pairs || "none yet"}`;
  }
  state.dirty = true;
}

function drawOverlay() {
  const cv = $("overlay"), ctx = cv.getContext("2d"), view = state.view;
  ctx.clearRect(0, 0, cv.width, cv.height);
  const stop = state.survey.stop;
  if (stop && stop.xyz[0] !== null) {   // the point to capture next: a star on the plan
    const [u, v] = view.px(stop.xyz[0], stop.xyz[1]);
    ctx.fillStyle = "#d62"; ctx.strokeStyle = "#fff"; ctx.lineWidth = 1.5;
    ctx.beginPath();
    for (let k = 0; k < 10; k++) {
      const r = k % 2 ? 5 : 12, a = -Math.PI / 2 + k * Math.PI / 5;
      ctx.lineTo(u + r * Math.cos(a), v + r * Math.sin(a));
    }
    ctx.closePath(); ctx.fill(); ctx.stroke();
    ctx.fillStyle = "#111"; ctx.font = "bold 12px system-ui, sans-serif";
    ctx.fillText(`next: ${stop.id}`, u + 14, v - 8);
  }
  ctx.font = "12px system-ui, sans-serif";
  const ids = Object.keys(state.tracks).sort();
  const labels = [];   // boxes of the labels drawn so far: the next one moves clear of them
  ids.forEach(id => {
    const tr = state.tracks[id];
    const col = colourOf(id);
    ctx.globalAlpha = state.newest - tr.t > STALE_SECONDS ? 0.35 : 1.0;
    ctx.strokeStyle = col; ctx.lineWidth = 1.5;
    ctx.beginPath();
    tr.trail.forEach(([x, y, , gap], i) => {
      const [u, v] = view.px(x, y);
      (i && !gap) ? ctx.lineTo(u, v) : ctx.moveTo(u, v);
    });
    ctx.stroke();
    const [u, v] = view.px(tr.xyz[0], tr.xyz[1]);
    const rad = Math.max(4, (tr.sigma || 0) * view.scale);
    ctx.fillStyle = tr.status === "ok" ? col : "#999";
    ctx.beginPath(); ctx.arc(u, v, 4, 0, 2 * Math.PI); ctx.fill();
    ctx.beginPath(); ctx.arc(u, v, rad, 0, 2 * Math.PI); ctx.stroke();
    if (tr.yaw !== undefined && tr.yaw !== null) {   // a body: its heading
      const L = 22;
      ctx.beginPath(); ctx.moveTo(u, v);
      ctx.lineTo(u + L * Math.cos(tr.yaw), v - L * Math.sin(tr.yaw)); ctx.lineWidth = 3; ctx.stroke();
    }
    ctx.fillStyle = "#111";
    const text = `${id} z ${tr.xyz[2].toFixed(3)} m`, w = ctx.measureText(text).width;
    let lx = u + 8, ly = v + 14;
    for (const dy of [0, 14, -28, 28, -42, 42, 56]) {   // the first place clear of the others
      if (!labels.some(b => lx < b[0] + b[2] && lx + w > b[0] && ly + dy - 11 < b[1] + 14 && ly + dy + 3 > b[1])) {
        ly += dy; break;
      }
    }
    labels.push([lx, ly - 11, w]);
    ctx.fillText(text, lx, ly);
    ctx.globalAlpha = 1.0;
  });
  const live = ids.map(id => {
    const tr = state.tracks[id], old = state.newest - tr.t > STALE_SECONDS;
    return `${id}: ${old ? `no row for ${(state.newest - tr.t).toFixed(1)} s` : tr.status}, σ ${((tr.sigma || 0) * 1000).toFixed(1)} mm`;
  });
  $("tracks-line").textContent = (live.length ? live.join("; ") : (state.tracking ? "no track yet" : ""))
    + (state.missed ? `; ${state.missed} rows not shown (the page fell behind)` : "");
}

function colourOf(id) {   // one colour per id, the same whenever it comes back
  let h = 0;
  for (const ch of id) h = (h * 31 + ch.charCodeAt(0)) % 360;
  return `hsl(${h},75%,38%)`;
}

// -- the cameras ---------------------------------------------------------------------------
function tileOf(id, size) {
  let t = state.tiles[id];
  if (t) return t;
  const el = document.createElement("div");
  el.className = "tile"; el.dataset.camera = id;
  const cv = document.createElement("canvas");
  cv.width = size[0] * TILE_SCALE; cv.height = size[1] * TILE_SCALE;
  const name = document.createElement("div");   // text, never markup: ids come from files
  name.className = "name"; name.textContent = id; el.appendChild(name);
  el.appendChild(cv);
  const facts = document.createElement("div"); facts.className = "facts"; el.appendChild(facts);
  $("tiles").appendChild(el);
  t = state.tiles[id] = {el, cv, facts, size, seq: 0, shownSeq: 0, skipped: 0, loading: false,
                         spots: [], drawn: 0, summary: {}};
  return t;
}

async function showFrame(t, c) {
  // the frame came in the update with its own spots and time (base64 JPEG)
  const bytes = Uint8Array.from(atob(c.jpeg), ch => ch.charCodeAt(0));
  const img = await createImageBitmap(new Blob([bytes], {type: "image/jpeg"}));
  if (c.jpeg_seq <= t.shownSeq) return;
  if (t.shownSeq) t.skipped += Math.max(0, c.jpeg_seq - t.shownSeq - 1);
  t.shownSeq = c.jpeg_seq;
  t.image = img;
  drawTile(t, img, c.jpeg_uv);
  t.drawn += 1;
  push(state.latency.frame, Date.now() / 1000 - c.jpeg_t);
}

function drawTile(t, img, spots) {
  const ctx = t.cv.getContext("2d");
  ctx.imageSmoothingEnabled = false;
  if (img) ctx.drawImage(img, 0, 0, t.cv.width, t.cv.height);
  else { ctx.fillStyle = "#000"; ctx.fillRect(0, 0, t.cv.width, t.cv.height); }
  const all = state.survey.coverage && state.survey.coverage.cameras;
  const cov = all && Object.hasOwn(all, t.el.dataset.camera) ? all[t.el.dataset.camera] : null;
  if (cov) {   // where the survey's LED has been in this image: red cells still empty
    const [cols, rows] = state.survey.coverage.grid;
    const w = t.cv.width / cols, h = t.cv.height / rows;
    const most = Math.max(1, ...cov.counts);
    cov.counts.forEach((n, k) => {
      ctx.fillStyle = n ? `rgba(40,200,80,${0.05 + 0.15 * Math.log1p(n) / Math.log1p(most)})`
                        : "rgba(230,40,40,0.22)";
      ctx.fillRect((k % cols) * w, Math.floor(k / cols) * h, w, h);
    });
  }
  ctx.strokeStyle = "#0f0"; ctx.lineWidth = 1.5;
  for (const [u, v] of spots) {  // pixel centres run 0 … width − 1
    ctx.beginPath();
    ctx.arc((u + 0.5) * TILE_SCALE, (v + 0.5) * TILE_SCALE, 6, 0, 2 * Math.PI); ctx.stroke();
  }
  t.spots = spots;
}

function updateCamera(id, c) {
  if (!state.tiles[id] && !c.seq && !c.stopped) return;   // a tile once the camera has data
  $("no-cameras").hidden = true;
  const t = tileOf(id, [c.width, c.height]);
  t.summary = c; t.seq = c.seq;
  if (c.jpeg) showFrame(t, c);
  else if (!c.frame && c.seq !== t.shownSeq) {   // spots without frames (over MQTT)
    if (t.shownSeq) t.skipped += Math.max(0, c.seq - t.shownSeq - 1);
    t.shownSeq = c.seq; drawTile(t, null, c.uv); t.drawn += 1;
    if (c.t !== null) push(state.latency.frame, Date.now() / 1000 - c.t);
  }
  const facts = [
    c.rate !== null ? `${c.rate.toFixed(1)} fps` : "– fps",
    `${c.uv.length} spot${c.uv.length === 1 ? "" : "s"}`,
    c.clock_offset !== null ? `clock ${c.clock_offset >= 0 ? "+" : ""}${c.clock_offset.toFixed(3)} s` : "no clock stamp",
    `${c.dropped} dropped by the command`,
  ];
  if (c.frame) facts.push(`${t.drawn} shown here (10 a second at most)`);
  if (c.stopped) facts.push(`stopped: ${c.stopped}`);
  t.el.classList.toggle("stopped", !!c.stopped);
  t.facts.textContent = facts.join(" · ");
}

// the latest frame drawn on a tile, at its own size, in grey levels, with the spots drawn on
// it: what a person (or a test) can check the spots against
state.tileFrame = id => {
  const t = state.tiles[id];
  if (!t || !t.image) return null;
  const cv = document.createElement("canvas");
  cv.width = t.image.width; cv.height = t.image.height;
  const ctx = cv.getContext("2d");
  ctx.drawImage(t.image, 0, 0);
  const rgba = ctx.getImageData(0, 0, cv.width, cv.height).data, grey = [];
  for (let i = 0; i < rgba.length; i += 4) grey.push(Math.round((rgba[i] + rgba[i + 1] + rgba[i + 2]) / 3));
  return {width: cv.width, height: cv.height, grey, spots: t.spots, seq: t.shownSeq};
};

// -- plumbing ------------------------------------------------------------------------------
function push(list, v) { list.push(v); if (list.length > LATENCIES) list.shift(); }

function quantile(list, q) {
  if (!list.length) return null;
  const v = list.slice().sort((a, b) => a - b);
  return v[Math.min(v.length - 1, Math.floor(q * v.length))];
}
state.latencies = () => ({
  frame_p50: quantile(state.latency.frame, 0.5), frame_p95: quantile(state.latency.frame, 0.95),
  row_p50: quantile(state.latency.row, 0.5), row_p95: quantile(state.latency.row, 0.95),
});

function frameLoop() {
  if (state.dirty && state.view) { drawOverlay(); state.dirty = false; }
  requestAnimationFrame(frameLoop);
}

function layout() {
  const wrap = $("plan-wrap");
  let width = Math.max(320, wrap.parentElement.clientWidth - 4);
  state.view = fitView(state.scene, width);
  const most = 0.8 * window.innerHeight;   // the whole plan in view: no taller than the window
  if (state.view.height > most) {
    width = Math.max(320, Math.floor(width * most / state.view.height));
    state.view = fitView(state.scene, width);
  }
  for (const id of ["plan", "overlay"]) { $(id).width = width; $(id).height = state.view.height; }
  wrap.style.height = `${state.view.height}px`;
  drawPlan(); state.dirty = true;
}

// -- a calibrated deployment's report ------------------------------------------------------
function showCalibration(cal) {
  if (!cal) return;
  $("calibration").hidden = false;
  $("calibration-source").textContent = `from ${cal.report}, beside the deployment`;
  const mm = v => (v === null || v === undefined) ? "–" : (v * 1000).toFixed(1);
  const row = (cells) => {
    const tr = document.createElement("tr");
    for (const c of cells) { const td = document.createElement("td"); td.textContent = c; tr.appendChild(td); }
    return tr;
  };
  const cams = $("calibration-cameras").querySelector("tbody");
  for (const c of cal.cameras) cams.appendChild(row([c.id, c.moved_mm.toFixed(1), c.turned_deg.toFixed(2), c.lens]));
  const held = $("calibration-held").querySelector("tbody");
  for (const [label, v] of Object.entries(cal.held_out)) {
    held.appendChild(row([label, mm(v.mean_m), mm(v.p95_m),
                          v.fixed === null || v.fixed === undefined ? "–" : `${(v.fixed * 100).toFixed(0)} %`]));
  }
  if (cal.figure) { const img = $("calibration-figure"); img.src = "report.png"; img.hidden = false; }
}

async function start() {
  const res = await fetch("scene", {cache: "no-store"});
  state.scene = await res.json();
  $("title").textContent = `vlpcal view — ${state.scene.name}`;
  const sel = $("height");
  state.scene.maps.forEach((m, i) => {
    const o = document.createElement("option"); o.value = i; o.textContent = `${m.height.toFixed(2)} m`;
    sel.appendChild(o);
  });
  for (const id of ["layer", "height", "footprints"]) $(id).addEventListener("change", drawPlan);
  $("overlay").addEventListener("mousemove", hover);
  $("overlay").addEventListener("mouseleave", () => { $("tip").hidden = true; });
  window.addEventListener("resize", layout);
  layout();
  showCalibration(state.scene.calibration);
  const events = new EventSource("events");
  events.addEventListener("hello", ev => {
    const h = JSON.parse(ev.data);
    state.live = h.live; state.tracking = h.tracking;
    $("source").textContent = h.source || (h.live ? "" : "the plan (no live source)");
    if (!h.live) { events.close(); $("cameras-panel").hidden = true; }
  });
  events.addEventListener("update", ev => {
    const u = JSON.parse(ev.data);
    state.updates += 1; state.lastUpdate = Date.now() / 1000;
    state.missed += u.missed;
    for (const [id, c] of Object.entries(u.cameras)) updateCamera(id, c);
    if (u.rows.length) addRows(u.rows);
    if (u.survey) showSurvey(u.survey);
    $("status").textContent = u.status || "";
    if (u.ended) state.ended = true;
  });
  events.onerror = () => {
    if (state.ended) { events.close(); return; }
    $("status").textContent = "the command is not answering (stopped?)";
  };
  requestAnimationFrame(frameLoop);
  state.ready = true;
}

start();
