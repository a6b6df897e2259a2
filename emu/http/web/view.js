// rollcam live view: frames and truth from one WebSocket, overlays drawn here (they cost the device nothing).
// Each binary message is uint32 n (big-endian), n bytes of JSON, then a JPEG. Only the newest frame waits to be
// drawn: a tab slower than the stream skips frames (counted) instead of queueing them.
"use strict";

const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.search).get("token");
const withToken = (path) => (token ? `${path}?token=${encodeURIComponent(token)}` : path);
const COLORS = { gs: "#00e5ff", rs: "#ff3df2", det: "#ffd400", ruler: "#ffffff" };
const PLOT_N = 150;

const view = {
  stats: { frames: 0, drawn: 0, skippedHere: 0, lastSeq: null, gaps: 0, errors: 0 },
  meta: null, image: null, state: null, held: false, lastError: null, applied: {},
  intervals: [], // [interval ms, sequence gap] per frame, newest last
};
window.rollcamView = view;

let ws = null, pending = null, decoding = false, lastTs = null, nextId = 1;

function connect() {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  ws = new WebSocket(`${scheme}//${location.host}${withToken("/view/ws")}`);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => setConn("live", true);
  ws.onclose = () => { setConn("disconnected: retrying", false); setTimeout(connect, 1000); };
  ws.onmessage = (ev) => (typeof ev.data === "string" ? onText(JSON.parse(ev.data)) : onFrame(ev.data));
}

function setConn(text, ok) { const c = $("conn"); c.textContent = text; c.className = ok ? "good" : "bad"; }

function onFrame(buf) {
  const n = new DataView(buf).getUint32(0);
  const meta = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
  view.stats.frames += 1;
  const gap = view.stats.lastSeq === null ? 0 : Math.max(meta.seq - view.stats.lastSeq - 1, 0);
  view.stats.gaps += gap;
  view.stats.lastSeq = meta.seq;
  if (meta.timestamp_ns !== undefined) {
    const ts = BigInt(meta.timestamp_ns);
    if (lastTs !== null) view.intervals.push([Number(ts - lastTs) / 1e6, gap]);
    if (view.intervals.length > PLOT_N) view.intervals.shift();
    lastTs = ts;
  }
  if (view.held) return;
  if (pending) view.stats.skippedHere += 1;
  pending = { meta, blob: new Blob([new Uint8Array(buf, 4 + n)], { type: "image/jpeg" }) };
  if (!decoding) decodeNext();
}

async function decodeNext() {
  decoding = true;
  while (pending) {
    const { meta, blob } = pending;
    pending = null;
    try {
      const image = await createImageBitmap(blob);
      if (view.image) view.image.close();
      view.image = image;
      view.meta = meta;
      draw();
      view.stats.drawn += 1;
    } catch (e) { view.stats.errors += 1; }
  }
  decoding = false;
  showMeta();
  plot();
}

function on(id) { return $(id).checked; }

function draw() {
  const cv = $("view"), img = view.image, m = view.meta;
  if (!img) return;
  if (cv.width !== img.width || cv.height !== img.height) { cv.width = img.width; cv.height = img.height; }
  const g = cv.getContext("2d");
  g.drawImage(img, 0, 0);
  const px = Math.max(cv.width / 900, 1); // line widths that read at the shown size
  g.lineWidth = 2 * px;
  g.font = `${Math.round(12 * px)}px sans-serif`;
  for (const o of m.objects || []) {
    if (on("ov-gs") && o.box_gs) box(g, o.box_gs, COLORS.gs, [6 * px, 4 * px]);
    if (on("ov-rs") && o.box_rs) box(g, o.box_rs, COLORS.rs, []);
    const b = o.box_rs || o.box_gs;
    if (on("ov-ids") && b) label(g, `#${o.id} ${o.speed_mps.toFixed(1)} m/s`, b[0], b[1] - 3 * px, COLORS.rs);
  }
  const det = m.detections;
  if (on("ov-det") && det) {
    for (const d of det.boxes || []) {
      box(g, d.box, COLORS.det, [2 * px, 2 * px]);
      label(g, `${d.class_name ?? d.cls ?? ""} ${(d.score ?? 0).toFixed(2)}`, d.box[0], d.box[3] + 12 * px, COLORS.det);
    }
  }
  if (on("ov-ruler")) ruler(g, m, px);
}

function box(g, b, color, dash) {
  g.strokeStyle = color; g.setLineDash(dash);
  g.strokeRect(b[0], b[1], b[2] - b[0], b[3] - b[1]);
  g.setLineDash([]);
}

function label(g, text, x, y, color) {
  const w = g.measureText(text).width, h = parseInt(g.font, 10);
  g.fillStyle = "rgba(0,0,0,0.6)"; g.fillRect(x, y - h, w + 4, h + 2);
  g.fillStyle = color; g.fillText(text, x + 2, y);
}

// The ruler: each tick is an image line at its read-out time (ms after the first line read); the arrow runs
// from the first line read to the last, so the skew between two objects can be read off the picture.
function ruler(g, m, px) {
  const rows = m.rows || [];
  if (!rows.length) return;
  const col = m.by_column, len = col ? m.width : m.height, band = 58 * px;
  g.fillStyle = "rgba(0,0,0,0.55)";
  if (col) g.fillRect(0, 0, m.width, band * 0.6); else g.fillRect(0, 0, band, m.height);
  g.strokeStyle = COLORS.ruler; g.fillStyle = COLORS.ruler; g.lineWidth = 1.5 * px;
  for (const [line, t] of rows) {
    const pos = Math.min(Math.max(line, 1), len - 1);
    g.beginPath();
    if (col) { g.moveTo(pos, 0); g.lineTo(pos, 10 * px); } else { g.moveTo(0, pos); g.lineTo(10 * px, pos); }
    g.stroke();
    const text = `${(t / 1e6).toFixed(2)} ms`;
    if (col) g.fillText(text, Math.min(pos + 2 * px, m.width - 60 * px), 22 * px);
    else g.fillText(text, 12 * px, Math.min(Math.max(pos + 4 * px, 12 * px), m.height - 2 * px));
  }
  const first = rows.reduce((a, b) => (b[1] < a[1] ? b : a)), last = rows.reduce((a, b) => (b[1] > a[1] ? b : a));
  if (last[1] > first[1]) arrow(g, col, first[0], last[0], px);
  const what = m.shutter === "global" ? "global shutter: every line at once"
    : `${m.readout}, line ${(m.line_time_ns / 1e3).toFixed(2)} us, skew ${((last[1] - first[1]) / 1e6).toFixed(2)} ms`;
  label(g, what, col ? 4 * px : band + 4 * px, col ? band * 0.6 + 14 * px : 16 * px, COLORS.ruler);
}

function arrow(g, col, from, to, px) {
  const a = 50 * px, dir = Math.sign(to - from), head = 8 * px;
  g.beginPath();
  if (col) { g.moveTo(from, a * 0.5); g.lineTo(to, a * 0.5); g.moveTo(to, a * 0.5); g.lineTo(to - dir * head, a * 0.5 - head / 2); g.moveTo(to, a * 0.5); g.lineTo(to - dir * head, a * 0.5 + head / 2); }
  else { g.moveTo(a, from); g.lineTo(a, to); g.moveTo(a, to); g.lineTo(a - head / 2, to - dir * head); g.moveTo(a, to); g.lineTo(a + head / 2, to - dir * head); }
  g.stroke();
}

function showMeta() {
  const m = view.meta;
  if (!m) return;
  const iv = view.intervals.length ? view.intervals[view.intervals.length - 1][0] : null;
  const rows = [
    ["sequence", m.seq], ["timestamp", `${m.timestamp_ns} ns`], ["exposure", `${(m.exposure_ns / 1e3).toFixed(1)} us`],
    ["line time", `${m.line_time_ns} ns`], ["readout", `${m.shutter}, ${m.readout}`],
    ["format", `${m.format} ${m.width}x${m.height}`], ["interval", iv === null ? "-" : `${iv.toFixed(2)} ms`],
    ["drops", `${view.stats.gaps} missed (${m.dropped} server, ${view.stats.skippedHere} here), ${m.skipped} device`],
    ["objects", m.objects ? m.objects.length : "-"],
    ["detections", m.detections ? `${m.detections.boxes.length} on #${m.detections.seq} (${m.detections.ms} ms)` : "-"],
  ];
  const table = $("meta");
  for (const [k, v] of rows) {
    const id = `meta-${k.replace(" ", "-")}`;
    let cell = $(id);
    if (!cell) { // rows are made once and updated in place
      const tr = table.insertRow();
      tr.insertCell().textContent = k;
      cell = tr.insertCell(); cell.id = id;
    }
    cell.textContent = String(v);
  }
}

function plot() {
  const cv = $("plot"), g = cv.getContext("2d"), w = cv.width, h = cv.height, data = view.intervals;
  g.clearRect(0, 0, w, h);
  if (!data.length) return;
  const top = Math.max(...data.map((d) => d[0])) * 1.25 || 1;
  g.fillStyle = "#9aa4ae"; g.font = "11px sans-serif";
  g.fillText(`frame interval (ms, device clock), 0..${top.toFixed(1)}; red: dropped frames`, 6, 12);
  g.strokeStyle = "#3fb950"; g.lineWidth = 1.5; g.beginPath();
  data.forEach(([ms, gap], i) => {
    const x = (i / (PLOT_N - 1)) * w, y = h - (ms / top) * (h - 16);
    if (i) g.lineTo(x, y); else g.moveTo(x, y);
  });
  g.stroke();
  g.fillStyle = "#f85149";
  data.forEach(([, gap], i) => { if (gap) g.fillRect((i / (PLOT_N - 1)) * w - 1, h - 6 - 4 * Math.min(gap, 8), 3, 6 + 4 * Math.min(gap, 8)); });
}

function onText(msg) {
  if (msg.type === "state") return showState(msg);
  if (msg.type === "error") {
    view.lastError = msg; view.stats.errors += 1;
    const e = $("error"); e.hidden = false; e.textContent = `${msg.name}: ${msg.message}`;
  } else if (msg.type === "applied") {
    view.applied[msg.name] = msg.value; $("error").hidden = true;
    const input = $(`ctl-${msg.name}`);
    if (input) { input.classList.add("ok"); setTimeout(() => input.classList.remove("ok"), 800); }
  }
}

function showState(state) {
  view.state = state;
  const src = state.source || {};
  $("source").textContent = [src.sensor, src.uri].filter(Boolean).join(" · ") || "live view";
  $("ov-det").disabled = !state.detector;
  const form = $("controls");
  for (const [name, c] of Object.entries(state.controls)) {
    let input = $(`ctl-${name}`);
    if (!input) { form.appendChild(controlRow(name, c)); input = $(`ctl-${name}`); }
    if (document.activeElement === input) continue; // do not overwrite what a person is typing
    if (c.kind === "bool") input.checked = c.value === "on"; else input.value = c.value;
  }
  if (!Object.keys(state.controls).length) form.textContent = "this source has no controls";
}

function controlRow(name, c) {
  const row = document.createElement("div"); row.className = "row";
  const label = Object.assign(document.createElement("label"), { textContent: c.label + (c.unit ? ` (${c.unit})` : "") });
  let input;
  if (c.kind === "choice") {
    input = document.createElement("select");
    for (const v of c.choices) input.append(new Option(v, v));
  } else if (c.kind === "bool") {
    input = Object.assign(document.createElement("input"), { type: "checkbox" });
  } else {
    input = Object.assign(document.createElement("input"), { type: "text", inputMode: c.kind === "number" ? "decimal" : "text" });
    if (c.choices) {
      const list = Object.assign(document.createElement("datalist"), { id: `list-${name}` });
      for (const v of c.choices) list.append(new Option(v, v));
      row.append(list); input.setAttribute("list", list.id);
    }
  }
  input.id = `ctl-${name}`; input.name = name; label.htmlFor = input.id;
  input.addEventListener("change", () => {
    if (c.kind === "bool") send(name, input.checked ? "on" : "off");
    else if (input.value.trim() !== "") send(name, input.value.trim());
    else input.value = view.state.controls[name].value; // an emptied field goes back to the value in effect
  });
  row.append(label, input);
  return row;
}

function send(name, value) {
  if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ type: "set", id: nextId++, name, value }));
}
view.send = send;

$("controls").addEventListener("submit", (e) => e.preventDefault());
for (const id of ["ov-gs", "ov-rs", "ov-ids", "ov-det", "ov-ruler"]) $(id).addEventListener("change", draw);
$("hold").addEventListener("click", () => {
  view.held = !view.held; $("hold").classList.toggle("on", view.held); $("hold").textContent = view.held ? "live" : "hold";
});
$("snapshot").addEventListener("click", async () => {
  const r = await fetch(withToken("/view/snapshot.json"));
  if (!r.ok) { onText({ type: "error", name: "snapshot", message: await r.text() }); return; }
  const doc = await r.json();
  const png = Uint8Array.from(atob(doc.png_base64), (ch) => ch.charCodeAt(0));
  save(new Blob([png], { type: "image/png" }), `${doc.name}.png`);
  save(new Blob([JSON.stringify(doc.truth, null, 1)], { type: "application/json" }), `${doc.name}.json`);
});

function save(blob, name) {
  const a = Object.assign(document.createElement("a"), { href: URL.createObjectURL(blob), download: name });
  document.body.append(a); a.click(); a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}

connect();
