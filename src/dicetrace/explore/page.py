"""The explorer's page: one HTML document with a small script (no framework) around the map PNG.

The script keeps the view in the URL (``history.pushState``: the browser's
back button and the page's back/reset walk the history of views), loads a
preview (about 1/16 of the resolution), a coarse map (about 1/4) and then the
refined one, drawn into one canvas strip by strip as the server computes it (a
newer view cancels the older on the server), zooms on a dragged box or the
mouse wheel, pans with the arrow buttons, shows hover info under the map, and
on click shows that throw's details beside the map and loads it into Rerun's
web viewer below them (shift-click adds a throw to compare), its camera framed
for the shape of the viewer's 3-D view.
"""

from __future__ import annotations

import html
import json

from dicetrace.explore.compare import MAX_THROWS
from dicetrace.explore.view import View
from dicetrace.ics import SLICES
from dicetrace.integrators import INTEGRATORS
from dicetrace.params import PRESETS
from dicetrace.scan.colours import OUTCOME_NAMES, OUTCOME_RGB, outcome_rgb_table
from dicetrace.sinks.rerun_web import FAVICON_LINK


def _options(names, selected) -> str:
    return "".join(
        f'<option value="{html.escape(n)}"{" selected" if n == selected else ""}>{html.escape(n)}</option>' for n in names
    )


def page_html(default: View, *, can_save: bool, device: str = "cpu") -> str:
    """The page; ``default`` is the view of a URL without parameters; ``device``: where its maps run (a label)."""
    legend = "".join(
        f'<span class="key"><span class="sw" style="background:rgb{OUTCOME_RGB[o]}"></span>{html.escape(OUTCOME_NAMES[o])}</span>'
        for o in (1, 2, 3, 4, 5, 6, 0, -1)
    )
    cfg = {"default": default.to_query(), "canSave": can_save, "palette": outcome_rgb_table().tolist(),
           "maxCompare": MAX_THROWS}
    return (
        _TEMPLATE.replace("%LEGEND%", legend)
        .replace("%SLICES%", _options(SLICES, default.slice))
        .replace("%PRESETS%", _options(PRESETS, default.preset))
        .replace("%INTEGRATORS%", '<option value="">(preset\'s)</option>' + _options(INTEGRATORS, default.integrator))
        .replace("%DEVICE%", html.escape(device))
        .replace("%FAVICON%", FAVICON_LINK)
        .replace("%CONFIG%", json.dumps(cfg))
    )


_TEMPLATE = r"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>dicetrace explore</title>
<meta http-equiv="Content-Security-Policy" content="connect-src 'self'">
%FAVICON%
<style>
 body{font-family:system-ui,sans-serif;margin:8px;font-size:13px;color:#222}
 #top{display:flex;gap:8px;flex-wrap:wrap;align-items:center;margin-bottom:6px}
 #top label{white-space:nowrap} input.num{width:6em}
 #main{display:flex;flex-wrap:wrap;gap:10px;align-items:flex-start}
 #mapbox{position:relative;width:512px;height:512px;border:1px solid #888;background:#ddd;cursor:crosshair;user-select:none}
 #map{width:100%;height:100%;image-rendering:pixelated;display:block}
 #sel{position:absolute;border:1px dashed #000;background:rgba(255,255,255,.25);display:none;pointer-events:none}
 .ax{font-family:monospace;font-size:11px}
 #plot{display:grid;grid-template-columns:72px 514px;grid-template-rows:514px 22px;margin-top:8px}
 #yaxis,#xaxis{position:relative;overflow:visible}
 .tick{position:absolute;white-space:nowrap;line-height:12px}
 #yaxis .tick{right:0;padding-right:5px;transform:translateY(-50%);background:linear-gradient(#666,#666) right center/4px 1px no-repeat}
 #xaxis .tick{top:0;padding-top:5px;transform:translateX(-50%);background:linear-gradient(#666,#666) center top/1px 4px no-repeat}
 #axisnote{width:586px;padding-left:0;color:#444;overflow-wrap:anywhere}
 #error{color:#b00;font-weight:bold;white-space:pre-wrap}
 #status{display:inline-block;width:22em;white-space:nowrap;overflow:hidden;text-overflow:ellipsis;vertical-align:middle} .busy::before{content:"⏳ "}
 .key{margin-right:8px;white-space:nowrap}.sw{display:inline-block;width:11px;height:11px;border:1px solid #555;margin-right:3px;vertical-align:middle}
 .panel{font-family:monospace;font-size:11px;white-space:pre-wrap;overflow-wrap:anywhere;border:1px solid #ccc;padding:4px;box-sizing:border-box;overflow-x:hidden;overflow-y:auto}
 #hover{min-height:5em;max-height:24em;width:576px}
 #side{flex:1 1 600px;min-width:600px;display:flex;flex-direction:column;gap:6px}
 #info{max-height:max(7em,30vh);flex:none}
 #info:empty{display:none}
 #viewerbox{width:100%;height:420px;overflow:hidden;border:1px solid #888;box-sizing:border-box;flex:none}
 #viewerhint{margin:0;height:100%;display:flex;align-items:center;justify-content:center;color:#666;font-size:15px;background:#f4f4f4}
</style></head><body>
<div id="top">
 <label>slice <select id="slice">%SLICES%</select></label>
 <label>z <input id="z" class="num" placeholder="0"></label>
 <label>preset <select id="preset">%PRESETS%</select></label>
 <label>integrator <select id="integrator">%INTEGRATORS%</select></label>
 <label>γ <input id="gamma" class="num" placeholder="preset's"></label>
 <label>dt <input id="dt" class="num" placeholder="default"></label>
 <label>die <input id="die" class="num" placeholder="cube" title="the box's sides X,Y,Z in cm (e.g. 2,2,3); a box or loaded die needs the physical preset"></label>
 <label>load <input id="load" class="num" placeholder="none" title="W@X,Y,Z: a share W of the mass at the body-frame point X,Y,Z (cm)"></label>
 <label>res <input id="res" class="num"></label>
 <button id="apply">apply</button>
 <button id="back">back</button><button id="reset">reset</button>
 <button id="zout">zoom out</button>
 <button data-pan="-1,0">◀</button><button data-pan="1,0">▶</button><button data-pan="0,1">▲</button><button data-pan="0,-1">▼</button>
 <span id="savebox"><input id="scanname" placeholder="scan name" size="10"><button id="save">save view as scan</button></span>
 <a id="download" href="#" download hidden>download this throw (.rrd)</a>
 <span id="status"></span>
</div>
<div id="error" role="alert"></div>
<div>%LEGEND% <span class="ax" id="dieshown" aria-label="the die shown"></span> <span class="ax" id="device">maps on %DEVICE%;</span> <span class="ax">drag a box to zoom, wheel to zoom, click a point to see its throw, shift-click to compare more throws with it</span></div>
<div id="main">
 <div>
  <div id="plot"><div id="yaxis" class="ax" aria-label="y axis"></div>
   <div id="mapbox"><canvas id="map" aria-label="outcome map"></canvas><div id="sel"></div></div>
   <div></div><div id="xaxis" class="ax" aria-label="x axis"></div></div>
  <div id="axisnote" class="ax"></div>
  <div id="hover" class="panel"></div>
 </div>
 <div id="side">
  <div id="info" class="panel" aria-label="picked throws"></div>
  <div id="viewerbox"><p id="viewerhint">click a point on the map to see its throw here (shift-click to compare)</p></div>
 </div>
</div>
<script type="module">
const CFG = %CONFIG%;
const $ = (id) => document.getElementById(id);
// The page connects to its own server only (the policy above); what the policy blocked is kept for the tests.
document.addEventListener("securitypolicyviolation", (ev) => {
  document.body.dataset.blocked = (document.body.dataset.blocked ? document.body.dataset.blocked + " " : "") + ev.blockedURI;
  console.warn("dicetrace: blocked a request to", ev.blockedURI);
});
const client = Math.random().toString(36).slice(2);
let view = null;          // the current view's query (an object of strings)
let window4 = null;       // [x0, x1, y0, y1] numbers
let res = [256, 256];
let seq = 0;              // the newest load; older responses are dropped
let throws = [];          // the throws shown in the viewer: {x, y, info}
let viewer = null;        // the Rerun viewer (a promise of it) once a throw is picked

// Inside a frame (the notebook widget, dicetrace.explore.widget), the picks and the view go to the parent.
function tellParent(type, data) {
  if (window.parent !== window) window.parent.postMessage({source: "dicetrace-explore", type, ...data}, "*");
}
function readUrl() {
  const q = Object.fromEntries(new URLSearchParams(location.search));
  return Object.keys(q).length ? q : {...CFG.default};
}
function qs(q, extra) { return new URLSearchParams({...q, ...(extra || {})}).toString(); }
function showError(msg) { $("error").textContent = msg || ""; }
function setStatus(text, busy) { $("status").textContent = text; $("status").className = busy ? "busy" : ""; }

async function load(q, push) {
  const my = ++seq;
  document.body.dataset.state = "computing";  // at once: the back button changes the URL before this load asks for its view
  showError("");
  let r = await fetch("/api/view?" + qs(q));
  let j = await r.json();
  if (my !== seq) return;                        // a newer view took over while this one was checked
  if (!r.ok) { showError("Bad view parameter " + (j.param || "") + ": " + j.error); setStatus("", false); document.body.dataset.state = "error"; return; }
  view = j.query; window4 = [j.window[0][0], j.window[0][1], j.window[1][0], j.window[1][1]]; res = j.res;
  $("dieshown").textContent = "die: " + j.die + ";";
  if (push) history.pushState(view, "", "?" + qs(view));
  else history.replaceState(view, "", "?" + qs(view));
  fillControls();
  tellParent("view", {view});
  document.body.dataset.strips = "";
  const c = $("map");
  if (c.width !== res[0] || c.height !== res[1]) { c.width = res[0]; c.height = res[1]; }
  const t0 = performance.now();
  for (const pass of ["preview", "coarse"]) {
    setStatus(`computing a ${pass} map…`, true);
    r = await fetch("/api/map.png?" + qs(view, {pass, client}));
    if (my !== seq) return;                      // a newer view took over
    if (r.status === 409) return;
    if (!r.ok) { j = await r.json(); return fail(j.error); }
    const img = await createImageBitmap(await r.blob());
    if (my !== seq) return;
    const g = c.getContext("2d"); g.imageSmoothingEnabled = false;
    g.drawImage(img, 0, 0, c.width, c.height);   // its pixels as blocks of the full grid
    c.dataset.pass = pass; c.dataset.res = r.headers.get("X-Dicetrace-Res");
  }
  if (!await refine(my, c, t0)) return;
  c.dataset.pass = "fine"; c.dataset.res = res.join(","); c.dataset.query = qs(view);
  document.body.dataset.state = "ready";
}
function fail(msg) { showError(msg); setStatus("", false); document.body.dataset.state = "error"; return false; }

// The refined map, strip by strip as the server computes it (NDJSON: rows row0..row1 as outcome bytes, then "done").
async function refine(my, c, t0) {
  setStatus("refining…", true);
  const r = await fetch("/api/map.strips?" + qs(view, {client}));
  if (!r.ok) { const j = await r.json(); return fail(j.error); }
  const reader = r.body.pipeThrough(new TextDecoderStream()).getReader();
  const g = c.getContext("2d");
  let buf = "";
  for (;;) {
    const {value, done} = await reader.read();
    if (my !== seq) { reader.cancel(); return false; }
    if (done) return fail("the map stream ended early");
    buf += value;
    let nl;
    while ((nl = buf.indexOf("\n")) >= 0) {
      const msg = JSON.parse(buf.slice(0, nl)); buf = buf.slice(nl + 1);
      if (msg.error) { if (msg.status !== 409) fail(msg.error); return false; }
      if (msg.done) {
        setStatus(`refined ${msg.res.join("×")} in ${((performance.now() - t0) / 1000).toFixed(2)} s`, false);
        return true;
      }
      const bytes = Uint8Array.from(atob(msg.outcome), (ch) => ch.charCodeAt(0));
      const img = g.createImageData(c.width, msg.row1 - msg.row0);
      for (let k = 0; k < bytes.length; k++) {
        const rgb = CFG.palette[bytes[k]];
        img.data[4 * k] = rgb[0]; img.data[4 * k + 1] = rgb[1]; img.data[4 * k + 2] = rgb[2]; img.data[4 * k + 3] = 255;
      }
      g.putImageData(img, 0, msg.row0);
      document.body.dataset.strips += (document.body.dataset.strips ? "," : "") + msg.row1;
      setStatus(`refining… ${msg.row1}/${c.height} rows`, true);
    }
  }
}

function fillControls() {
  for (const k of ["slice", "preset", "integrator"]) $(k).value = view[k] || "";
  for (const k of ["gamma", "dt", "z", "die", "load"]) $(k).value = view[k] || "";
  $("res").value = view.res;
  drawAxes();
  $("savebox").style.display = CFG.canSave ? "" : "none";
}
function fmt(v) { return Number(v).toPrecision(12).replace(/\.?0+$/, ""); }

// Axis ticks at round values (1, 2 or 5 times a power of ten, about `n` of them in [lo, hi]), labelled with
// the decimals that step needs.  Where such a label would pass MAX_TICK_CHARS (a deep zoom), the ticks are
// labelled as whole multiples of the power of ten from a base tick, and the base goes in the note below
// the map.  The axes' boxes have a fixed size: the map stays in place whatever the labels.
const MAX_TICK_CHARS = 9;
function ticks(lo, hi, n) {
  const raw = (hi - lo) / n, e = Math.floor(Math.log10(raw)), mag = Math.pow(10, e), norm = raw / mag;
  const [m, ex] = norm < 1.5 ? [1, e] : norm < 3.5 ? [2, e] : norm < 7.5 ? [5, e] : [1, e + 1];
  const step = m * Math.pow(10, ex), decimals = Math.max(0, -ex);
  const k0 = Math.ceil(lo / step - 1e-9), k1 = Math.floor(hi / step + 1e-9);
  const values = []; for (let k = k0; k <= k1; k++) values.push(k * step);
  let labels = values.map((v) => (v === 0 ? 0 : v).toFixed(decimals)), base = null;
  if (labels.some((t) => t.length > MAX_TICK_CHARS)) {   // whole multiples of 10^ex from the first tick
    base = labels[0];
    labels = values.map((v, k) => String(k * m));
  }
  return {values, labels, step, base, unit: ex};
}
function drawAxes() {
  const [x0, x1, y0, y1] = window4, notes = [];
  for (const [id, lo, hi, n, name] of [["xaxis", x0, x1, 5, "x"], ["yaxis", y0, y1, 6, "y"]]) {
    const t = ticks(lo, hi, n), box = $(id);
    box.textContent = "";
    t.values.forEach((v, k) => {
      const f = (v - lo) / (hi - lo), el = document.createElement("span");
      el.className = "tick"; el.textContent = t.labels[k];
      if (id === "xaxis") el.style.left = (1 + f * 512) + "px"; else el.style.top = (1 + (1 - f) * 512) + "px";
      box.append(el);
    });
    box.dataset.step = String(t.step); box.dataset.base = t.base === null ? "" : t.base;
    notes.push(t.base === null ? `${name} ${fmt(lo)} … ${fmt(hi)}`
                               : `${name} ${fmt(lo)} … ${fmt(hi)}: ticks at ${name} = ${t.base} + label × 1e${t.unit}`);
  }
  $("axisnote").textContent = notes.join(";  ");
}

function toSlice(ev) {
  const b = $("mapbox").getBoundingClientRect();
  const fx = Math.min(Math.max((ev.clientX - b.left) / b.width, 0), 1), fy = Math.min(Math.max((ev.clientY - b.top) / b.height, 0), 1);
  return [window4[0] + fx * (window4[1] - window4[0]), window4[3] - fy * (window4[3] - window4[2]), fx, fy];
}
function zoomTo(x0, x1, y0, y1) { load({...view, window: [x0, x1, y0, y1].map(String).join(",")}, true); }

let drag = null, hoverTimer = null;
$("mapbox").addEventListener("mousedown", (ev) => { ev.preventDefault(); drag = {ev, p: toSlice(ev)}; });
window.addEventListener("mouseup", (ev) => {
  if (!drag) return;
  const a = drag.p, b = toSlice(ev), start = drag.ev; drag = null; $("sel").style.display = "none";
  const moved = Math.abs(ev.clientX - start.clientX) + Math.abs(ev.clientY - start.clientY);
  if (moved < 6) { pick(b[0], b[1], ev.shiftKey); return; }
  zoomTo(Math.min(a[0], b[0]), Math.max(a[0], b[0]), Math.min(a[1], b[1]), Math.max(a[1], b[1]));
});
$("mapbox").addEventListener("mousemove", (ev) => {
  if (drag) {
    const bx = $("mapbox").getBoundingClientRect(), s = $("sel").style;
    s.display = "block"; s.left = Math.min(drag.ev.clientX, ev.clientX) - bx.left + "px"; s.top = Math.min(drag.ev.clientY, ev.clientY) - bx.top + "px";
    s.width = Math.abs(ev.clientX - drag.ev.clientX) + "px"; s.height = Math.abs(ev.clientY - drag.ev.clientY) + "px";
    return;
  }
  clearTimeout(hoverTimer);
  const p = toSlice(ev);
  hoverTimer = setTimeout(() => hover(p[0], p[1]), 120);
});
$("mapbox").addEventListener("wheel", (ev) => {
  ev.preventDefault();
  const p = toSlice(ev), f = ev.deltaY < 0 ? 0.5 : 2;
  const w = (window4[1] - window4[0]) * f, h = (window4[3] - window4[2]) * f;
  zoomTo(p[0] - p[2] * w, p[0] + (1 - p[2]) * w, p[1] - (1 - p[3]) * h, p[1] + p[3] * h);
}, {passive: false});

function describe(j) {
  const c = Object.entries(j.coords).map(([k, v]) => `${k} = ${v}`).join(", ");
  const ic = Object.entries(j.ic).map(([k, v]) => `${k}=${v}`).join(" ");
  return `${c}   (pixel ${j.i}, ${j.j})\nIC: ${ic}  [L: ${j.l_convention}]\noutcome ${j.outcome}  status ${j.status}  steps ${j.steps}  settle ${j.t_settle_s.toFixed(3)} s\ncontact sequence ${j.contact_sequence}`;
}
async function hover(x, y) {
  const r = await fetch("/api/hover?" + qs(view, {x, y}));
  const j = await r.json();
  if (!r.ok) { $("hover").textContent = j.error; return; }
  $("hover").dataset.hover = JSON.stringify(j);
  $("hover").textContent = "hover: " + describe(j);
}

function ensureViewer() {  // one viewer, however many picks come while it loads
  viewer = viewer || makeViewer().catch((e) => { viewer = null; throw e; });
  return viewer;
}
// Rerun's web viewer asks api.github.com for its latest release when it starts, unless its own setting
// "check for updates on startup" is off.  It keeps its settings in this origin's localStorage ("app", in
// RON), read when it starts: turn that one off there first, so the viewer makes no request beyond this server.
function viewerOffline() {
  const key = "app", off = "check_for_updates_on_startup:false";
  try {
    const state = localStorage.getItem(key) || "";
    localStorage.setItem(key, /check_for_updates_on_startup:/.test(state) ? state.replace(/check_for_updates_on_startup:true/g, off)
                              : state.includes("(app_options:(") ? state.replace("(app_options:(", `(app_options:(${off},`)
                              : `(app_options:(${off}))`);
  } catch (e) { console.warn("dicetrace: cannot turn off the Rerun viewer's update check:", e); }
}
async function makeViewer() {
  viewerOffline();
  const mod = await import("/rerun/widget.js");
  const handlers = {};
  const box = $("viewerbox");
  const model = {
    get: (k) => ({_url: null, _panel_states: {top: "collapsed", time: "collapsed"}, _width: box.clientWidth, _height: box.clientHeight,
                  _fallback_token: null, _theme: "light"})[k],
    on: (ev, f) => { (handlers[ev] = handlers[ev] || []).push(f); },
    send: (m) => { if (m === "ready") model.ready = true; else viewerEvent(m); },
  };
  $("viewerhint").remove();
  mod.default.render({model, el: box});
  // the viewer takes the page's width beside the map (8:7, as tall as the page allows): it follows the window
  new ResizeObserver(() => {
    (handlers["change:_width"] || []).forEach((f) => f(null, box.clientWidth));
    (handlers["change:_height"] || []).forEach((f) => f(null, box.clientHeight));
  }).observe(box);
  for (let k = 0; k < 600 && !model.ready; k++) await new Promise((r) => setTimeout(r, 100));
  return {open: (url) => handlers["msg:custom"].forEach((f) => f({type: "open_url", url})),
          close: (url) => handlers["msg:custom"].forEach((f) => f({type: "close_url", url}))};
}
// The viewer's events (JSON): the recording each names is the one on screen (kept for the tests).  A recording
// the page closed before any of it had arrived is still loading and opens later ("nothing is loaded" then):
// each time one opens, the page closes again what it has closed.
let closed = new Set();   // URLs the page has closed in the viewer
function viewerEvent(text) {
  let ev; try { ev = JSON.parse(text); } catch (e) { return; }
  if (ev.recording_id) document.body.dataset.viewerRecording = ev.recording_id;
  if (ev.type === "recording_open" && closed.size) viewer.then((v) => closed.forEach((u) => v.close(u)));
}
// A click shows that throw in the viewer (record's recording); a shift-click adds it to the picked ones, and the
// viewer is given one compare recording of them all (record --ic A --ic B's: every die, their divergence from
// throw 1), in place of what it showed.  Throws are compared under one configuration: a shift-click after the
// preset, integrator, γ, dt or die changed starts again from that throw.
const MAX_COMPARE = CFG.maxCompare;
const CONFIG_KEYS = ["preset", "integrator", "gamma", "dt", "die", "load"];
let opened = [];          // the URLs open in the viewer
function sameConfig(a, b) { return CONFIG_KEYS.every((k) => (a[k] || "") === (b[k] || "")); }
function absolute(path) { return new URL(path, location.href).href; }
let picks = 0;            // the newest pick: an older one still waiting for the viewer opens nothing
async function pick(x, y, add) {
  if (add && throws.length >= MAX_COMPARE) { showError(`at most ${MAX_COMPARE} throws in one comparison: click (without shift) to start again`); return; }
  const r = await fetch("/api/hover?" + qs(view, {x, y}));
  const info = await r.json();
  if (!r.ok) { showError(info.error); return; }
  showError("");
  const q = qs(view, {i: info.i, j: info.j});
  if (add && throws.length && !sameConfig(throws[0].view, view)) {
    add = false;
    setStatus("another configuration: a new comparison", false);
  }
  const my = ++picks;
  if (!add) throws = [];
  throws.push({x, y, info, view: {...view}, q, url: absolute("/api/throw.rrd?" + q)});
  const base = throws.length > 1 ? absolute("/api/compare.rrd?" + throws.map((t) => "t=" + encodeURIComponent(t.q)).join("&"))
                                 : throws[0].url;
  $("download").href = base + "&download=1";
  $("download").textContent = throws.length > 1 ? `download these ${throws.length} throws (.rrd)` : "download this throw (.rrd)";
  $("download").hidden = false;
  $("info").dataset.throws = JSON.stringify(throws.map((t) => t.info));
  tellParent("throws", {throws: throws.map((t) => t.info)});
  $("info").textContent = throws.map((t, k) => `throw ${k + 1}: ` + describe(t.info)).join("\n\n") + compare();
  fitViewer();   // the details above it took their room: the viewer's size, then its 3-D view's shape
  const url = base + "&aspect=" + view3dAspect().toFixed(3);   // its camera frames the dice for that shape
  $("info").dataset.viewer = url;
  const v = await ensureViewer().catch((e) => { showError("Rerun viewer: " + e); return null; });
  if (!v || my !== picks) return;
  const gone = opened.filter((u) => u !== url);
  opened = [url]; closed.delete(url); gone.forEach((u) => closed.add(u));
  for (const u of closed) { if (closed.size <= 8) break; closed.delete(u); }  // the few latest are enough
  gone.forEach((u) => v.close(u));
  v.open(url);
}
function compare() {  // each later throw against throw 1, as the compare recording plots it
  if (throws.length < 2) return "";
  const a = throws[0].info;
  return throws.slice(1).map((t, n) => {
    const b = t.info;
    const sa = a.contact_sequence.split("-"), sb = b.contact_sequence.split("-");
    let k = 0; while (k < Math.min(sa.length, sb.length) && sa[k] === sb[k]) k++;
    const d = Math.hypot(...Object.keys(a.ic).map((c) => a.ic[c] - b.ic[c]));
    return `\n\ndivergence${throws.length > 2 ? ` of throw ${n + 2} from throw 1` : ""}: |ΔIC| = ${d.toExponential(3)}; ` +
           `contact sequences agree for ${k} sets, then ` +
           (k < Math.max(sa.length, sb.length) ? `${sa[k] || "(end)"} vs ${sb[k] || "(end)"}` : "never differ") +
           `; outcomes ${a.outcome} vs ${b.outcome}`;
  }).join("") + "\n\nthe viewer shows them in one recording: every die, and each one's divergence from throw 1";
}

// The viewer: the width of the column beside the map (below it on a narrow page; at least 600 px wide: Rerun's
// viewer hides its time panel, the throw's replay, when narrower), 8:7, no taller than what the window shows below
// its top (at least VIEWER_MIN_H).  Its 3-D view is the recording's layout's left 3/5 (the blueprint's column
// shares 3:2) under its title bar, above the time panel: the shape its camera frames for.
const VIEWER_MIN_H = 420, VIEW3D = {share: 3 / 5, bars: 60};
function fitViewer() {
  const box = $("viewerbox"), w = box.getBoundingClientRect().width, top = box.getBoundingClientRect().top + scrollY;
  const room = innerHeight - 8 - (top < innerHeight / 2 ? top : 0);   // below the map: as tall as the window
  box.style.height = Math.round(Math.max(VIEWER_MIN_H, Math.min(w * 7 / 8, room))) + "px";
}
function view3dAspect() {
  const box = $("viewerbox");
  return Math.min(5, Math.max(0.2, (box.clientWidth * VIEW3D.share) / Math.max(1, box.clientHeight - VIEW3D.bars)));
}
window.addEventListener("resize", fitViewer);
fitViewer();

$("apply").onclick = () => {
  const q = {...view};
  for (const k of ["slice", "preset", "integrator", "gamma", "dt", "z", "res"]) { const v = $(k).value.trim(); if (v) q[k] = v; else delete q[k]; }
  for (const k of ["die", "load"]) q[k] = $(k).value.trim();   // empty: none (the cube, no load), not the start view's
  load(q, true);
};
$("back").onclick = () => history.back();
$("reset").onclick = () => load({...CFG.default}, true);
$("zout").onclick = () => { const w = window4[1] - window4[0], h = window4[3] - window4[2]; zoomTo(window4[0] - w / 2, window4[1] + w / 2, window4[2] - h / 2, window4[3] + h / 2); };
document.querySelectorAll("[data-pan]").forEach((b) => b.onclick = () => {
  const [dx, dy] = b.dataset.pan.split(",").map(Number), w = window4[1] - window4[0], h = window4[3] - window4[2];
  zoomTo(window4[0] + dx * w / 4, window4[1] + dx * w / 4, window4[2] + dy * h / 4, window4[3] + dy * h / 4);
});
$("save").onclick = async () => {
  setStatus("saving the scan…", true);
  const r = await fetch("/api/save?" + qs(view, {name: $("scanname").value}), {method: "POST"});
  const j = await r.json();
  if (!r.ok) { showError(j.error); setStatus("", false); return; }
  setStatus(`saved ${j.n_ics} ICs to ${j.path}`, false);
};
window.addEventListener("popstate", (ev) => load(ev.state || readUrl(), false));
load(readUrl(), false);
</script></body></html>
"""
