// skyfix's operator page: video with the tracker's overlay, target selection, map, health.
// Everything comes from this server (WebSocket /ws, POST /api/<command>); nothing from the internet.
"use strict";

const $ = (id) => document.getElementById(id);
const video = $("video");
const vctx = video.getContext("2d");
const map = $("map");
const mctx = map.getContext("2d");

const page = {
  camera: { width: 0, height: 0 },
  shown: null,        // {bitmap, overlay}: the frame on screen
  frozen: null,       // the frame on screen when a drag began: a selection names it
  drag: null,         // {x0, y0, x1, y1} in image pixels (continuous: 0 is the left edge of pixel 0)
  received: 0,
  shownTimes: [],
  track: [],          // [seq, north_m, east_m, h_acc_m, t]
  map: null,
  status: null,
  rates: {},
  settings: {},
};
const TRACK_KEEP = 3000;

// ---- the WebSocket ------------------------------------------------------------------------------
function connect() {
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => setConn(true);
  ws.onclose = () => { setConn(false); setTimeout(connect, 1000); };
  ws.onmessage = (ev) => (typeof ev.data === "string" ? onText(JSON.parse(ev.data)) : onFrame(ev.data));
  document.onvisibilitychange = () => {
    if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ video: !document.hidden }));
  };
}

function setConn(up) {
  $("conn").textContent = up ? "connected" : "disconnected: retrying";
  $("conn").className = up ? "ok" : "bad";
}

function onText(msg) {
  if (msg.type === "hello") {
    page.camera = msg.camera;
    page.settings = msg.settings;
    page.track = msg.track;
    sizeVideo();
    return;
  }
  if (msg.type === "state") {
    page.status = msg.status;
    page.rates = msg.rates;
    page.map = msg.map;
    page.track.push(...msg.track);
    if (page.track.length > TRACK_KEEP) page.track.splice(0, page.track.length - TRACK_KEEP);
    showStatus();
    drawMap();
    showHealth();
  }
}

async function onFrame(buf) {
  const n = new DataView(buf).getUint32(0);
  const overlay = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
  const bitmap = await createImageBitmap(new Blob([new Uint8Array(buf, 4 + n)], { type: "image/jpeg" }));
  page.received += 1;
  video.dataset.received = page.received;
  if (page.frozen) { bitmap.close(); return; }  // the operator is selecting on the frozen frame
  if (page.shown) page.shown.bitmap.close();
  page.shown = { bitmap, overlay };
  const now = performance.now();
  page.shownTimes.push(now);
  while (page.shownTimes.length && now - page.shownTimes[0] > 2000) page.shownTimes.shift();
  drawVideo();
}

// ---- video ----------------------------------------------------------------------------------------
function sizeVideo() {
  const r = video.getBoundingClientRect();
  const dpr = window.devicePixelRatio || 1;
  const aspect = page.camera.height / page.camera.width || 9 / 16;
  video.width = Math.max(1, Math.round(r.width * dpr));
  video.height = Math.max(1, Math.round(r.width * aspect * dpr));
  drawVideo();
}

function drawVideo() {
  const f = page.frozen || page.shown;
  vctx.fillStyle = "#000";
  vctx.fillRect(0, 0, video.width, video.height);
  if (!f) return;
  const o = f.overlay;
  const s = video.width / o.width;  // canvas pixels per image pixel
  vctx.drawImage(f.bitmap, 0, 0, video.width, video.height);
  const lw = Math.max(2, video.width / 400);
  if (o.window) {
    vctx.setLineDash([8 * lw / 2, 6 * lw / 2]);
    vctx.strokeStyle = "#ffd400";
    vctx.lineWidth = lw;
    vctx.strokeRect(o.window[0] * s, o.window[1] * s, o.window[2] * s, o.window[3] * s);
    vctx.setLineDash([]);
  }
  if (o.box) {
    vctx.strokeStyle = o.status === "ok" ? "#00e000" : "#ff2020";
    vctx.lineWidth = 1.5 * lw;
    vctx.strokeRect(o.box[0] * s, o.box[1] * s, o.box[2] * s, o.box[3] * s);
  }
  if (o.u !== null && o.v !== null && o.status === "ok") {
    const x = (o.u + 0.5) * s, y = (o.v + 0.5) * s, r = 6 * lw;
    vctx.strokeStyle = "#fff";
    vctx.lineWidth = lw;
    vctx.beginPath();
    vctx.moveTo(x - r, y); vctx.lineTo(x + r, y); vctx.moveTo(x, y - r); vctx.lineTo(x, y + r);
    vctx.stroke();
  }
  const label = `${o.status}${o.h_acc_m !== null ? `  h_acc ${o.h_acc_m.toFixed(2)} m` : ""}  #${o.frame}`;
  vctx.font = `bold ${Math.round(9 * lw)}px system-ui, sans-serif`;
  const w = vctx.measureText(label).width;
  vctx.fillStyle = o.status === "ok" ? "#0b6e0b" : "#b00000";
  vctx.fillRect(0, 0, w + 6 * lw, 13 * lw);
  vctx.fillStyle = "#fff";
  vctx.fillText(label, 3 * lw, 10 * lw);
  if (page.drag) {
    const d = page.drag;
    vctx.strokeStyle = "#ff00ff";
    vctx.lineWidth = 1.5 * lw;
    vctx.strokeRect(Math.min(d.x0, d.x1) * s, Math.min(d.y0, d.y1) * s, Math.abs(d.x1 - d.x0) * s,
                    Math.abs(d.y1 - d.y0) * s);
  }
  video.dataset.frame = o.frame;
  video.dataset.t = o.t;
  video.dataset.status = o.status;
  video.dataset.frozen = page.frozen ? "1" : "";
  const fps = page.shownTimes.length > 1
    ? (page.shownTimes.length - 1) / ((page.shownTimes.at(-1) - page.shownTimes[0]) / 1000) : 0;
  $("video-info").textContent = `frame ${o.frame} · shown ${fps.toFixed(1)} fps`
    + (page.frozen ? " · held while you select" : "");
}

function imagePoint(ev) {  // image pixels (continuous) under the pointer
  const r = video.getBoundingClientRect();
  const o = (page.frozen || page.shown).overlay;
  return [(ev.clientX - r.left) / r.width * o.width, (ev.clientY - r.top) / r.height * o.height];
}

video.addEventListener("pointerdown", (ev) => {
  if (!page.shown || ev.button !== 0) return;
  page.frozen = page.shown;
  const [x, y] = imagePoint(ev);
  page.drag = { x0: x, y0: y, x1: x, y1: y };
  video.setPointerCapture(ev.pointerId);
  drawVideo();
});
video.addEventListener("pointermove", (ev) => {
  if (!page.drag) return;
  [page.drag.x1, page.drag.y1] = imagePoint(ev);
  drawVideo();
});
video.addEventListener("pointerup", (ev) => {
  if (!page.drag) return;
  [page.drag.x1, page.drag.y1] = imagePoint(ev);
  const d = page.drag, frame = page.frozen.overlay.frame;
  const r = video.getBoundingClientRect();
  const px = (x) => x / page.frozen.overlay.width * r.width;  // image pixels to screen pixels
  const round1 = (x) => Math.round(x * 10) / 10;
  let body;
  if (Math.hypot(px(d.x1 - d.x0), px(d.y1 - d.y0)) < 5) {  // a click: the pixel's centre
    body = { point: [round1(d.x0 - 0.5), round1(d.y0 - 0.5)], frame };
  } else {
    body = { box: [round1(Math.min(d.x0, d.x1)), round1(Math.min(d.y0, d.y1)), round1(Math.abs(d.x1 - d.x0)),
                   round1(Math.abs(d.y1 - d.y0))], frame };
  }
  endDrag();
  command("select", body);
});
function endDrag() {
  page.drag = null;
  page.frozen = null;
  drawVideo();
}
document.addEventListener("keydown", (ev) => { if (ev.key === "Escape" && page.drag) endDrag(); });
window.addEventListener("resize", () => { sizeVideo(); drawMap(); });

// ---- commands -------------------------------------------------------------------------------------
async function command(name, body) {
  const out = $("cmd-result");
  out.textContent = `${name}: sent…`;
  out.className = "";
  try {
    const resp = await fetch(`/api/${name}`, { method: "POST", headers: { "Content-Type": "application/json" },
                                               body: JSON.stringify(body || {}) });
    const answer = await resp.json();
    if (!resp.ok) {
      out.textContent = answer.error || `${name}: HTTP ${resp.status}`;
      out.className = "bad";
      return;
    }
    const t = answer.target;
    out.textContent = name === "select"
      ? `selected on frame ${answer.frame} (caught up ${answer.caught_up}): ${t.state}`
      : `${name}: ${t.state} from frame ${answer.latest_frame + 1}`;
    out.className = "ok";
  } catch (e) {
    out.textContent = `${name}: ${e}`;
    out.className = "bad";
  }
}
$("release").onclick = () => command("release");
$("acquire").onclick = () => command("acquire");

// ---- status word, fix, target ---------------------------------------------------------------------
const fmt = (x, d = 2, unit = "") => (x === null || x === undefined ? "—" : `${Number(x).toFixed(d)}${unit}`);

function showStatus() {
  const s = page.status;
  const fix = s.fix;
  const word = $("status-word");
  word.textContent = fix ? fix.status : "no frames";
  word.className = `word ${fix && fix.status === "ok" ? "ok" : "bad"}`;
  $("hacc").textContent = `h_acc ${fmt(fix && fix.h_acc_m, 2, " m")}`;
  const h = s.height;  // the UAV's height above the water, as the fixes use it
  $("height").textContent = h ? `height ${fmt(h.height_m, 2)} ± ${fmt(h.sigma_m, 2, " m")} (${h.source})` : "height —";
  const t = s.target;
  $("target-state").textContent = `target ${t.state}${t.origin ? ` (${t.origin})` : ""}`;
  const g = s.gps_input && s.gps_input.gates;  // the safety gates: what GPS_INPUT lets through
  const gate = $("gate-state");
  gate.textContent = !g ? "gates —" : g.state === "acquiring" && g.chain
    ? `gates acquiring ${g.chain.span_s.toFixed(1)}/${g.chain.needed_s.toFixed(1)} s` : `gates ${g.state}`;
  gate.className = !g ? "" : g.state === "tracking" ? "ok" : g.state === "diverged" ? "bad" : "warn";
  const okFix = fix && fix.status === "ok";
  $("fix-text").textContent = okFix
    ? `UUV ${fix.lat.toFixed(7)}, ${fix.lon.toFixed(7)} ± ${fix.h_acc_m.toFixed(2)} m, depth ${fmt(fix.depth_m)} m`
      + ` (frame ${fix.frame}, ${(s.t - fix.t).toFixed(1)} s ago)`
    : `no fix: ${fix ? fix.status : "no frames yet"}`;
}

// ---- map ------------------------------------------------------------------------------------------
function niceLength(m) {  // 1, 2, 5 × 10^k not above m
  const p = Math.pow(10, Math.floor(Math.log10(m)));
  return [5, 2, 1].map((k) => k * p).find((x) => x <= m) || p;
}

function drawMap() {
  const dpr = window.devicePixelRatio || 1;
  const r = map.getBoundingClientRect();
  map.width = Math.max(1, Math.round(r.width * dpr));
  map.height = Math.max(1, Math.round(r.height * dpr));
  const W = map.width, H = map.height, ctx = mctx;
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, W, H);
  const m = page.map;
  map.dataset.points = page.track.length;
  if (!m) return;
  // what must be in view: the UAV, its footprint, the last 30 s of the track
  const pts = [];
  if (m.uav) pts.push(m.uav);
  if (m.footprint) pts.push(...m.footprint);
  const recent = page.track.filter((p) => p[4] > (page.track.length ? page.track.at(-1)[4] : 0) - 30);
  recent.forEach((p) => pts.push([p[1], p[2]]));
  const gt = m.gate && m.gate.track;
  if (gt) pts.push([gt.n, gt.e]);
  map.dataset.gate = m.gate ? m.gate.state : "";
  if (!pts.length) {
    ctx.fillStyle = "#000";
    ctx.font = `bold ${16 * dpr}px system-ui, sans-serif`;
    ctx.fillText(`no UAV position (${m.pose})`, 10 * dpr, 24 * dpr);
    return;
  }
  const ns = pts.map((p) => p[0]), es = pts.map((p) => p[1]);
  const n0 = (Math.min(...ns) + Math.max(...ns)) / 2, e0 = (Math.min(...es) + Math.max(...es)) / 2;
  const span = Math.max(Math.max(...ns) - Math.min(...ns), Math.max(...es) - Math.min(...es), 4);
  const pxPerM = Math.min(W, H) / (span * 1.25);
  const X = (e) => W / 2 + (e - e0) * pxPerM, Y = (n) => H / 2 - (n - n0) * pxPerM;
  if (m.footprint) {
    ctx.beginPath();
    m.footprint.forEach((p, i) => (i ? ctx.lineTo(X(p[1]), Y(p[0])) : ctx.moveTo(X(p[1]), Y(p[0]))));
    ctx.closePath();
    ctx.fillStyle = "rgba(0, 90, 200, 0.15)";
    ctx.fill();
    ctx.strokeStyle = "#0050c8";
    ctx.lineWidth = 2 * dpr;
    ctx.stroke();
    const top = m.footprint.slice(0, (m.top_edge || 0) + 1);  // the image's top edge, thick
    if (top.length > 1) {
      ctx.beginPath();
      top.forEach((p, i) => (i ? ctx.lineTo(X(p[1]), Y(p[0])) : ctx.moveTo(X(p[1]), Y(p[0]))));
      ctx.lineWidth = 6 * dpr;
      ctx.stroke();
    }
  }
  // the UUV's track: accuracy circles, then the line, then the last fix
  ctx.lineWidth = 1 * dpr;
  ctx.strokeStyle = "rgba(176, 0, 0, 0.35)";
  for (const p of page.track) {
    ctx.beginPath();
    ctx.arc(X(p[2]), Y(p[1]), Math.max(p[3] * pxPerM, 1), 0, 2 * Math.PI);
    ctx.stroke();
  }
  ctx.strokeStyle = "#b00000";
  ctx.lineWidth = 2 * dpr;
  ctx.beginPath();
  page.track.forEach((p, i) => (i ? ctx.lineTo(X(p[2]), Y(p[1])) : ctx.moveTo(X(p[2]), Y(p[1]))));
  ctx.stroke();
  const last = page.track.at(-1);
  if (last) {
    ctx.fillStyle = "#b00000";
    ctx.beginPath();
    ctx.arc(X(last[2]), Y(last[1]), 5 * dpr, 0, 2 * Math.PI);
    ctx.fill();
    ctx.lineWidth = 3 * dpr;
    ctx.beginPath();
    ctx.arc(X(last[2]), Y(last[1]), Math.max(last[3] * pxPerM, 5 * dpr), 0, 2 * Math.PI);
    ctx.stroke();
  }
  if (gt) drawGateTrack(ctx, m.gate, X, Y, pxPerM, dpr);
  if (m.uav) {  // the UAV: a black cross in a ring
    const x = X(m.uav[1]), y = Y(m.uav[0]), s = 9 * dpr;
    ctx.strokeStyle = "#000";
    ctx.lineWidth = 3 * dpr;
    ctx.beginPath();
    ctx.moveTo(x - s, y); ctx.lineTo(x + s, y); ctx.moveTo(x, y - s); ctx.lineTo(x, y + s);
    ctx.arc(x, y, s * 0.7, 0, 2 * Math.PI);
    ctx.stroke();
  }
  // north arrow and scale bar
  ctx.fillStyle = "#000";
  ctx.strokeStyle = "#000";
  ctx.font = `bold ${16 * dpr}px system-ui, sans-serif`;
  ctx.lineWidth = 3 * dpr;
  ctx.beginPath();
  ctx.moveTo(W - 22 * dpr, 46 * dpr); ctx.lineTo(W - 22 * dpr, 14 * dpr);
  ctx.moveTo(W - 30 * dpr, 24 * dpr); ctx.lineTo(W - 22 * dpr, 14 * dpr); ctx.lineTo(W - 14 * dpr, 24 * dpr);
  ctx.stroke();
  ctx.fillText("N", W - 28 * dpr, 64 * dpr);
  const bar = niceLength(W * 0.3 / pxPerM);
  const x0 = 12 * dpr, y0 = H - 14 * dpr;
  ctx.fillRect(x0, y0 - 4 * dpr, bar * pxPerM, 6 * dpr);
  ctx.fillText(`${bar} m`, x0, y0 - 10 * dpr);
  map.dataset.scaleM = bar;
  const o = m.origin;
  $("map-info").textContent = `${page.track.length} fixes on the track · scale bar ${bar} m`
    + (m.height_m !== null ? ` · camera ${m.height_m.toFixed(1)} m above the water` : "")
    + (m.horizon ? " · horizon in view: footprint cut" : "")
    + (m.footprint ? "" : ` · no footprint (${m.pose})`)
    + (o ? ` · origin ${o.lat.toFixed(6)}, ${o.lon.toFixed(6)}` : "");
}

// The safety gates' track: a blue diamond, its 2-sigma ellipse (own and shared error), its velocity over the next
// second; while a target is being acquired, a dashed circle where the UUV can be by now.
function drawGateTrack(ctx, gate, X, Y, pxPerM, dpr) {
  const t = gate.track;
  const x = X(t.e), y = Y(t.n);
  const a = t.sigma_n ** 2, b = t.cov_ne ?? 0, c = t.sigma_e ** 2;  // [[nn, ne], [ne, ee]]
  const mid = (a + c) / 2, half = Math.sqrt(((a - c) / 2) ** 2 + b * b);
  const angle = Math.atan2(half + (a - c) / 2, b || 1e-12);  // of the major axis, from east towards north
  ctx.strokeStyle = "#0050c8";
  ctx.lineWidth = 2 * dpr;
  ctx.beginPath();
  ctx.ellipse(x, y, Math.max(2 * Math.sqrt(mid + half) * pxPerM, 2), Math.max(2 * Math.sqrt(Math.max(mid - half, 0)) * pxPerM, 2),
              -angle, 0, 2 * Math.PI);
  ctx.stroke();
  ctx.beginPath();
  ctx.moveTo(x, y);
  ctx.lineTo(X(t.e + t.ve), Y(t.n + t.vn));
  ctx.lineWidth = 3 * dpr;
  ctx.stroke();
  const s = 7 * dpr;
  ctx.fillStyle = "#0050c8";
  ctx.beginPath();
  ctx.moveTo(x, y - s); ctx.lineTo(x + s, y); ctx.lineTo(x, y + s); ctx.lineTo(x - s, y);
  ctx.closePath();
  ctx.fill();
  if (gate.state !== "tracking" && gate.reach_m !== null) {
    ctx.setLineDash([8 * dpr, 6 * dpr]);
    ctx.lineWidth = 2 * dpr;
    ctx.beginPath();
    ctx.arc(x, y, gate.reach_m * pxPerM, 0, 2 * Math.PI);
    ctx.stroke();
    ctx.setLineDash([]);
  }
}

// ---- health ---------------------------------------------------------------------------------------
function row(input, state, age, rate, details, sub) {
  const tr = document.createElement("tr");
  tr.dataset.input = input;
  if (sub) tr.className = "sub";
  const cells = [input, state === null ? "" : state, age, rate, details];
  cells.forEach((text, i) => {
    const td = document.createElement("td");
    td.textContent = text;
    if (i === 1 && state !== null) {
      td.className = `state ${state === "ok" ? "ok" : state === "—" ? "" : state.startsWith("warn") ? "warn" : "bad"}`;
    }
    tr.appendChild(td);
  });
  return tr;
}

// where the video's latency comes from: configured, or (auto) the image's motion once settled; the estimate beside
function videoLatency(v) {
  if (!v) return "";
  const m = v.latency_from_motion || {};
  const est = m.estimate_ms === null || m.estimate_ms === undefined ? "image motion: no estimate yet"
    : `image motion ${fmt(m.estimate_ms, 1, " ms")} ± ${fmt(m.sigma_ms, 1, " ms")} from ${m.pairs} pairs, ${m.state}`;
  if (m.configured_ms !== null && m.configured_ms !== undefined) {
    return ` · video latency ${fmt(v.latency_ms, 0, " ms")} (configured; ${est})`;
  }
  if (v.latency_ms === null) return ` · video latency not settled (auto: no valid fix yet; ${est})`;
  return ` · video latency ${fmt(v.latency_ms, 1, " ms")} (motion ± ${fmt(m.applied_sigma_ms, 1, " ms")}; ${est})`;
}

function showHealth() {
  const s = page.status, rates = page.rates, problems = s.problems || {};
  const list = $("problems");
  list.replaceChildren(...(Object.keys(problems).length
    ? Object.entries(problems).map(([k, v]) => { const li = document.createElement("li"); li.className = "bad"; li.dataset.input = k; li.textContent = v; return li; })
    : [Object.assign(document.createElement("li"), { textContent: "every input OK" })]));
  const count = Object.keys(problems).length;
  $("problem-count").textContent = count ? `${count} input problem${count > 1 ? "s" : ""}` : "inputs OK";
  $("problem-count").className = count ? "bad" : "ok";
  const st = (k) => (problems[k] ? "problem" : "ok");
  const hz = (x) => (x === null || x === undefined ? "—" : `${x.toFixed(1)}/s`);
  const age = (x) => (x === null || x === undefined ? "never" : `${x.toFixed(2)} s`);
  const rows = [];
  const uav = s.uav;
  const ages = Object.values(uav.age_s || {});
  rows.push(row("UAV MAVLink", st("uav"), age(ages.length ? Math.min(...ages) : null), hz(rates.uav),
                `${uav.url} · sys ${uav.sysid ?? "—"} · ${uav.received} msgs · ${uav.bad_data} bad`));
  for (const [name, a] of Object.entries(uav.age_s || {}).sort()) {
    const asked = uav.rate_requests && uav.rate_requests[name];
    rows.push(row(name, null, age(a), `${fmt(uav.rates_hz[name], 1)} Hz`, asked || "", true));
  }
  if (s.video) {
    const v = s.video;
    rows.push(row("video", st("video"), age(v.age_s), `${fmt(rates.video_frames, 1)} fps`,
                  `${v.frames} frames · tracked ${fmt(rates.processed, 1)} fps · dropped ${s.pipeline.dropped}`
                  + ` · decode errors ${v.decode_errors} · decoder backlog ${v.backlog}, skipped behind ${v.skipped_behind}${v.error ? ` · ${v.error}` : ""}`));
  }
  if (s.height_from_size) {  // the camera's height from the UUV's size: the configured height's bias
    const h = s.height_from_size;
    const off = h.sure && Math.abs(h.bias_m) > 2 * h.sigma_m;
    const state = !h.frames ? "—" : !h.sure ? "warn: not sure yet" : off ? "warn: configured height off" : "ok";
    rows.push(row("height from size", state, "", "",
                  (h.frames ? `configured − measured ${fmt(h.bias_m, 2, " m")} ± ${fmt(h.sigma_m, 2, " m")} over `
                    + `${h.frames} frames (${h.seconds} s, ${fmt(100 * h.at_surface_share, 0, " %")} at the surface)`
                    : "no measurement yet")
                  + ` · last ${fmt(h.last_height_m, 2, " m")} ± ${fmt(h.last_sigma_m, 2, " m")} · ${h.mode}`
                  + (h.mode === "auto" ? `, ${h.applied} applied` : "")
                  + ` · ${h.measured} measured, ${Object.values(h.rejected).reduce((a, b) => a + b, 0)} without`));
  }
  const d = s.depth;
  const a = d.ardusub;
  rows.push(row(`depth (${d.shape})`, st("depth"), age(d.age_s), hz(rates.depth),
                `${d.key ?? d.url} · ${fmt(d.depth_m)} m ± ${fmt(d.sigma_m)} (${d.source ?? "—"})`
                + (a ? ` · EKF ${fmt(a.ekf_depth_m)} m, Δ ${fmt(a.disagreement_m)} m, ${fmt(a.vertical_speed_mps)} m/s`
                       + (a.params.missing.length ? ` · waiting for ${a.params.missing.join(", ")}` : "") : "")
                + ` · ${d.received} received, ${d.bad} bad, ${d.refused} refused (${d.jumps} jumps)`));
  const up = s.uuv_position;
  if (up.key || up.hint) {
    rows.push(row("UUV position", up.received ? "ok" : "—", age(up.age_s), "",
                  `${up.key || "hint"} · ${up.received} received`));
  }
  rows.push(row("Zenoh", st("zenoh"), "", "", `${s.zenoh ? s.zenoh.peers : "—"} peers/routers connected`));
  if (s.gps_input) {
    const g = s.gps_input;
    const ft = g.last_fix_type === 3 ? "3 (fix)" : g.last_fix_type === 1 ? "1 (no fix)" : fmt(g.last_fix_type, 0);
    const link = g.link || {};
    const heard = link.peer_age_s === null || link.peer_age_s === undefined ? "never" : `${link.peer_age_s.toFixed(1)} s ago`;
    const state = link.state && link.state !== "up" ? `warn: link ${link.state}` : g.last_fix_type === 3 ? "ok" : g.sent ? "warn: no fix" : "—";
    rows.push(row("GPS_INPUT", state, "", `${fmt(rates.gps_input, 1)} Hz`,
                  `last fix_type ${ft} · ${g.sent_valid}/${g.sent} valid · ${g.not_delivered} not delivered`
                  + ` · ${g.gates ? Object.values(g.gates.rejected).reduce((a, b) => a + b, 0) : 0} held by the gates · ${g.url}`
                  + ` · link ${link.state ?? "—"}${link.error ? ` (${link.error})` : ""} · autopilot last heard ${heard}`));
  }
  if (s.gps_input && s.gps_input.gates) {
    const g = s.gps_input.gates, t = g.track;
    const refused = Object.entries(g.rejected).filter(([, n]) => n).map(([k, n]) => `${k} ${n}`).join(", ");
    const state = g.state === "tracking" ? "ok" : g.state === "diverged" ? "bad: diverged" : "warn: acquiring";
    rows.push(row("safety gates", state, t ? age(t.age_s) : "", "",
                  `${g.state}${g.chain ? ` (${g.chain.fixes} fixes over ${g.chain.span_s.toFixed(1)} of `
                    + `${g.chain.needed_s.toFixed(1)} s)` : ""}`
                  + (g.diverged_until_t !== null ? ` until ${new Date(g.diverged_until_t * 1000).toLocaleTimeString()}` : "")
                  + ` · ${g.accepted} accepted · refused: ${refused || "none"}`
                  + (t ? ` · track ${Math.hypot(t.vn_mps, t.ve_mps).toFixed(2)} m/s, ± ${fmt(Math.hypot(t.sigma_n_m, t.sigma_e_m), 2, " m")}`
                         + ` (own ${fmt(t.sigma_own_m, 3, " m")})` : " · no track yet")
                  + (g.reach_m !== null ? ` · UUV within ${fmt(g.reach_m, 1, " m")} of it` : "")
                  + ` · frame-to-frame share ${g.white_share === null ? "—" : fmt(100 * g.white_share, 2, " %")}`
                  + ` · limits ${g.max_speed_mps} m/s, ${g.max_accel_mps2} m/s²`
                  + (g.thrusters !== null ? ` · thrusters ${g.thrusters}` : "")
                  + (g.accel_bound_mps2 !== null && g.accel_bound_mps2 < g.max_accel_mps2
                     ? ` (bound ${fmt(g.accel_bound_mps2, 2, " m/s²")})` : "")
                  + (g.last_refusal ? ` · last: ${g.last_refusal}` : "")));
  }
  if (s.height) {
    const h = s.height;
    const used = Object.entries(h.sources || {}).map(([k, v]) => `${k} ${v.used} used`
      + `${v.refused ? `, ${v.refused} refused` : ""}, ${age(v.age_s)} ago`
      + `${v.disagrees_m !== null ? `, DISAGREES by ${fmt(v.disagrees_m, 2, " m")}` : ""}`).join(" · ");
    const disagree = Object.values(h.sources || {}).some((v) => v.disagrees_m !== null);
    rows.push(row("height", disagree ? "warn: sources disagree" : null, "", "",
                  `${fmt(h.height_m)} ± ${fmt(h.sigma_m, 2, " m")} above the water (${h.source}) · EKF ${fmt(h.ekf_height_m)} m,`
                  + ` bias ${fmt(h.bias_m, 2, " m")} · ${h.reference} reference set at ${h.reference_set_at}`
                  + ` ${fmt(h.since_reference_s, 0, " s")} ago${used ? ` · ${used}` : ""}`
                  + `${h.rangefinder_out_of_range ? ` · rangefinder out of range ${h.rangefinder_out_of_range}` : ""}`));
  }
  if (uav.gnss) {
    const g = uav.gnss;
    rows.push(row("GNSS", null, "", "", `fix_type ${g.fix_type} · horizontal ${fmt(g.sigma_horizontal_m, 2, " m")}`
                  + ` (h_acc ${fmt(g.h_acc_m, 2, " m")}, HDOP ${fmt(g.hdop, 1)}) · vertical ${fmt(g.sigma_vertical_m, 2, " m")}`
                  + ` (v_acc ${fmt(g.v_acc_m, 2, " m")}, VDOP ${fmt(g.vdop, 1)})`));
  }
  const c = uav.clocks;
  rows.push(row("clocks", null, "", "", `station − GNSS ${fmt(c.station_minus_gnss_s, 3, " s")} · UAV link `
                + `${fmt(c.uav_link_latency_ms, 1, " ms")} (${c.uav_link_latency_source} ± `
                + `${fmt(c.uav_link_latency_sigma_ms, 1, " ms")}; measured `
                + `${fmt(c.uav_link_latency_measured_ms, 1, " ms")}) · UUV − station `
                + `${fmt(c.uuv_clock_minus_station_s, 3, " s")} · depth by ${c.depth_aligned_by ?? "—"}`
                + videoLatency(s.video) + ` · reboots ${c.uav_reboots}`));
  if (s.latency) {
    rows.push(row("latency", null, "", "", `frame → GPS_INPUT p50 ${fmt(s.latency.p50_ms, 1, " ms")}, p99 `
                  + `${fmt(s.latency.p99_ms, 1, " ms")} over ${s.latency.n}`));
  }
  if (s.process) {
    rows.push(row("CPU", null, "", "", `${fmt(s.process.cpu_pct, 0, " %")} of one core · ${fmt(s.process.rss_mb, 0)}`
                  + ` MB resident${s.ui ? ` · page video: ${s.ui.frames_encoded} JPEG, ${fmt(s.ui.encode_ms, 1)} ms CPU each` : ""}`));
  }
  $("health").tBodies[0].replaceChildren(...rows);
  $("health-time").textContent = new Date(s.t * 1000).toLocaleTimeString();
}

connect();
sizeVideo();
