// skyfix's operator page: what GPS_INPUT sends now (the header), video with the tracker's overlay, target
// selection, map, health. No status for 2 s: the page turns grey ("no status since …"), nothing on it green.
// Several UUVs ([[uuv]]): each in its colour (box, label, track, rows); the operator picks the UUV a selection,
// "Release" or "Await" applies to (the buttons above them, or the keys 1–9). With one, the page is as it was.
// Everything comes from this server (WebSocket /ws, POST /api/<command>, the map library Leaflet under
// /static/vendor/, the base map's tiles under /basemap/); nothing from the internet.
"use strict";

const $ = (id) => document.getElementById(id);
const video = $("video");
const vctx = video.getContext("2d");
const map = $("map");
const mctx = $("map-overlay").getContext("2d");

const page = {
  camera: { width: 0, height: 0 },
  shown: null,        // {bitmap, overlay}: the frame on screen
  frozen: null,       // the frame on screen when a drag began: a selection names it
  drag: null,         // {x0, y0, x1, y1} in image pixels (continuous: 0 is the left edge of pixel 0)
  received: 0,
  shownTimes: [],
  uuvs: [],           // per UUV: {id, colour, track: [[seq, north_m, east_m, h_acc_m, t]], gate, rates}
  sel: 0,             // the UUV the operator's commands apply to
  map: null,
  status: null,
  statusAt: 0,        // performance.now() when the status came
  frameAt: 0,         // performance.now() when the newest video frame came
  rates: {},
  settings: {},
};
const several = () => page.uuvs.length > 1;
// a UUV's own status sections (with one UUV, the status itself)
const own = (k) => (page.status && page.status.uuvs ? page.status.uuvs[page.uuvs[k].id] : page.status) || {};
const TRACK_KEEP = 3000;
const STALE_MS = 2000;  // no status (or no frame) for longer: the page (the video) turns grey
const HEARD_S = 3;      // the autopilot's HEARTBEAT comes once a second: not heard after three missed
const SENT_S = 1;       // GPS_INPUT goes out at 5 Hz or more: none for a second before the status is a fault
const FRESH_S = 1.5;    // a fix older than this (the status comes once a second) is not news: its word turns grey

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
    page.uuvs = msg.uuvs.map((u) => ({ id: u.id, colour: u.colour, track: u.track, gate: null, rates: {} }));
    page.sel = Math.min(page.sel, page.uuvs.length - 1);
    showBasemap(msg.basemap);
    showPicker();
    sizeVideo();
    return;
  }
  if (msg.type === "state") {
    page.status = msg.status;
    page.statusAt = performance.now();
    page.rates = msg.rates;
    page.map = msg.map;
    refreshLiveMosaic(msg.status.live_mosaic);
    msg.uuvs.forEach((u, k) => {
      const mine = page.uuvs[k];
      if (!mine) return;
      mine.gate = u.gate;
      mine.rates = u.rates;
      mine.track.push(...u.track);
      if (mine.track.length > TRACK_KEEP) mine.track.splice(0, mine.track.length - TRACK_KEEP);
    });
    showStatus();
    showSending();
    if (page.follow) fitView();
    drawMap();
    showHealth();
  }
}

async function onFrame(buf) {
  const n = new DataView(buf).getUint32(0);
  const overlay = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
  const bitmap = await createImageBitmap(new Blob([new Uint8Array(buf, 4 + n)], { type: "image/jpeg" }));
  page.received += 1;
  page.frameAt = performance.now();
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
  if (o.uuvs) drawUuvs(o, s, lw);
  else drawOne(o, s, lw);
  if (page.drag) {
    const d = page.drag;
    vctx.strokeStyle = several() ? page.uuvs[page.sel].colour : "#ff00ff";
    vctx.lineWidth = 1.5 * lw;
    vctx.strokeRect(Math.min(d.x0, d.x1) * s, Math.min(d.y0, d.y1) * s, Math.abs(d.x1 - d.x0) * s,
                    Math.abs(d.y1 - d.y0) * s);
  }
  if (!page.frozen && videoStale()) {  // the frame on screen is old: grey it, and say so
    vctx.fillStyle = "rgba(120, 120, 120, 0.7)";
    vctx.fillRect(0, 0, video.width, video.height);
    const text = `no new frame for ${((performance.now() - page.frameAt) / 1000).toFixed(0)} s`;
    vctx.font = `bold ${Math.round(14 * lw)}px system-ui, sans-serif`;
    vctx.fillStyle = "#fff";
    vctx.fillText(text, (video.width - vctx.measureText(text).width) / 2, video.height / 2);
  }
  video.dataset.frame = o.frame;
  video.dataset.t = o.t;
  video.dataset.status = o.status;
  video.dataset.uuvs = o.uuvs ? o.uuvs.map((u) => `${u.id}:${u.status}`).join(" ") : "";
  video.dataset.frozen = page.frozen ? "1" : "";
  const fps = page.shownTimes.length > 1
    ? (page.shownTimes.length - 1) / ((page.shownTimes.at(-1) - page.shownTimes[0]) / 1000) : 0;
  $("video-info").textContent = `frame ${o.frame} · shown ${fps.toFixed(1)} fps`
    + (page.frozen ? " · held while you select" : "");
}

const videoStale = () => page.frameAt > 0 && performance.now() - page.frameAt > STALE_MS;

function crosshair(u, v, s, lw) {
  const x = (u + 0.5) * s, y = (v + 0.5) * s, r = 6 * lw;
  vctx.strokeStyle = "#fff";
  vctx.lineWidth = lw;
  vctx.beginPath();
  vctx.moveTo(x - r, y); vctx.lineTo(x + r, y); vctx.moveTo(x, y - r); vctx.lineTo(x, y + r);
  vctx.stroke();
}

// several UUVs: each one's window (dashed) and box (solid when ok, dashed otherwise) in its colour, its id over
// its box, and a label line per UUV at the top-left
function drawUuvs(o, s, lw) {
  vctx.font = `bold ${Math.round(9 * lw)}px system-ui, sans-serif`;
  o.uuvs.forEach((u, k) => {
    const ok = u.status === "ok";
    if (u.window) {
      vctx.setLineDash([4 * lw, 4 * lw]);
      vctx.strokeStyle = u.colour;
      vctx.lineWidth = lw;
      vctx.strokeRect(u.window[0] * s, u.window[1] * s, u.window[2] * s, u.window[3] * s);
      vctx.setLineDash([]);
    }
    if (u.box) {
      vctx.setLineDash(ok ? [] : [6 * lw, 3 * lw]);
      vctx.strokeStyle = u.colour;
      vctx.lineWidth = (k === page.sel ? 2.2 : 1.5) * lw;
      vctx.strokeRect(u.box[0] * s, u.box[1] * s, u.box[2] * s, u.box[3] * s);
      vctx.setLineDash([]);
      const tw = vctx.measureText(u.id).width;
      const ty = Math.max(0, u.box[1] * s - 12 * lw);
      vctx.fillStyle = u.colour;
      vctx.fillRect(u.box[0] * s, ty, tw + 6 * lw, 12 * lw);
      vctx.fillStyle = "#fff";
      vctx.fillText(u.id, u.box[0] * s + 3 * lw, ty + 9.5 * lw);
    }
    if (u.u !== null && u.v !== null && ok) crosshair(u.u, u.v, s, lw);
    const label = `${k === page.sel ? "▶ " : ""}${u.id} ${u.status}`
      + `${u.h_acc_m !== null ? `  h_acc ${u.h_acc_m.toFixed(2)} m` : ""}${k === 0 ? `  #${o.frame}` : ""}`;
    const w = vctx.measureText(label).width;
    vctx.fillStyle = u.colour;
    vctx.fillRect(0, k * 13 * lw, w + 6 * lw, 13 * lw);
    vctx.fillStyle = "#fff";
    vctx.fillText(label, 3 * lw, k * 13 * lw + 10 * lw);
  });
}

// one UUV: as the page has always drawn it
function drawOne(o, s, lw) {
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
  if (o.u !== null && o.v !== null && o.status === "ok") crosshair(o.u, o.v, s, lw);
  const label = `${o.status}${o.h_acc_m !== null ? `  h_acc ${o.h_acc_m.toFixed(2)} m` : ""}  #${o.frame}`;
  vctx.font = `bold ${Math.round(9 * lw)}px system-ui, sans-serif`;
  const w = vctx.measureText(label).width;
  vctx.fillStyle = o.status === "ok" ? "#0b6e0b" : "#b00000";
  vctx.fillRect(0, 0, w + 6 * lw, 13 * lw);
  vctx.fillStyle = "#fff";
  vctx.fillText(label, 3 * lw, 10 * lw);
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
document.addEventListener("keydown", (ev) => {
  if (ev.key === "Escape" && page.drag) endDrag();
  const k = Number(ev.key) - 1;  // 1–9: the UUV the commands apply to
  if (several() && Number.isInteger(k) && k >= 0 && k < page.uuvs.length && !ev.ctrlKey && !ev.altKey && !ev.metaKey) {
    pick(k);
  }
});
window.addEventListener("resize", () => { sizeVideo(); drawMap(); });

// ---- commands -------------------------------------------------------------------------------------
async function command(name, body) {
  const out = $("cmd-result");
  const who = several() ? `${page.uuvs[page.sel].id} ` : "";  // several UUVs: the body names the one picked
  if (several()) body = { ...(body || {}), uuv: page.uuvs[page.sel].id };
  out.textContent = `${who}${name}: sent…`;
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
    out.textContent = who + (name === "select"
      ? `selected on frame ${answer.frame} (caught up ${answer.caught_up}): ${t.state}`
      : name === "confirm" ? `confirm: ${answer.why}`
      : `${name}: ${t.state} from frame ${answer.latest_frame + 1}`);
    out.className = "ok";
  } catch (e) {
    out.textContent = `${name}: ${e}`;
    out.className = "bad";
  }
}
$("release").onclick = () => command("release");
$("acquire").onclick = () => command("acquire");
$("confirm").onclick = () => command("confirm");

// several UUVs: one button per UUV, in its colour, picking the one the commands apply to
function showPicker() {
  const box = $("uuv-pick");
  box.hidden = !several();
  if (!several()) return;
  const buttons = page.uuvs.map((u, k) => {
    const b = document.createElement("button");
    b.type = "button";
    b.dataset.uuv = u.id;
    b.textContent = `${k + 1} ${u.id}`;
    b.style.borderColor = u.colour;
    b.onclick = () => pick(k);
    return b;
  });
  box.replaceChildren(Object.assign(document.createElement("span"), { textContent: "commands for" }), ...buttons);
  $("hint").textContent = "Pick the UUV (its button, or the keys 1–9), then drag a box around it, or click on it, "
    + "to select it (Esc cancels a drag); Release and Await apply to the UUV picked.";
  pick(page.sel);
}

function pick(k) {
  page.sel = k;
  $("uuv-pick").dataset.selected = page.uuvs[k].id;
  for (const b of $("uuv-pick").querySelectorAll("button")) {
    const mine = b.dataset.uuv === page.uuvs[k].id;
    b.setAttribute("aria-pressed", mine ? "true" : "false");
    b.style.background = mine ? page.uuvs[k].colour : "#fff";
    b.style.color = mine ? "#fff" : "#000";
  }
  if (page.status) showStatus();
  showSending();
  drawVideo();
}

// ---- status word, fix, target ---------------------------------------------------------------------
const fmt = (x, d = 2, unit = "") => (x === null || x === undefined ? "—" : `${Number(x).toFixed(d)}${unit}`);

function showStatus() {
  const s = page.status, k = page.sel, mine = own(k);
  const who = several() ? `${page.uuvs[k].id} ` : "";  // several UUVs: the header is the one picked
  const fix = mine.fix;
  const word = $("status-word");
  word.textContent = fix ? fix.status : "no frames";
  const old = fix && ageNow(fix.t) > FRESH_S;  // no newer fix since: an ok is not news, and never green
  word.className = `word ${fix && fix.status === "ok" ? (old ? "grey" : "ok") : "bad"}`;
  word.title = fix ? `the newest frame's fix (frame ${fix.frame}, exposed ${ago(ageNow(fix.t))}): ${fix.status}`
    : "no frame tracked yet";
  const h = s.height;  // the UAV's height above the water, as the fixes use it
  $("height").textContent = h ? `height ${fmt(h.height_m, 2)} ± ${fmt(h.sigma_m, 2, " m")} (${h.source})` : "height —";
  const t = mine.target;
  const ts = $("target-state");
  ts.textContent = `${who}target ${t.state}${t.origin ? ` (${t.origin})` : ""}`
    + (t.init_bbox ? ` · init_bbox ${t.init_bbox.split(":")[0]}` : "");  // kept, snapped, refused, unchecked
  ts.title = t.init_bbox ? `[tracker] init_bbox on the first frame: ${t.init_bbox}` : "";
  const g = mine.gps_input && mine.gps_input.gates;  // the safety gates: what GPS_INPUT lets through
  const gate = $("gate-state");
  const trackAge = g && g.track ? agedBy(g.track.age_s) : null;  // its last fix's, now
  gate.textContent = !g ? "gates —" : g.state === "acquiring" && g.chain
    ? `gates acquiring ${g.chain.span_s.toFixed(1)}/${g.chain.needed_s.toFixed(1)} s` : `gates ${g.state}`;
  gate.className = !g ? "" : g.state === "tracking" ? (trackAge > FRESH_S ? "grey" : "ok")  // green only when fresh
    : g.state === "diverged" ? "bad" : "warn";
  gate.title = trackAge === null ? "" : `the gates' track's last fix ${ago(trackAge)}`;
  const fixText = (f, name) => (f && f.status === "ok"
    ? `${name} ${f.lat.toFixed(7)}, ${f.lon.toFixed(7)} ± ${f.h_acc_m.toFixed(2)} m, depth ${fmt(f.depth_m)} m`
      + ` (frame ${f.frame}, ${(s.t - f.t).toFixed(1)} s ago)`
      + (f.ref_offset_n_m == null ? ""  // a surveyed marker's offset added (--reference)
        : ` · reference offset N ${fmt(f.ref_offset_n_m, 2)}, E ${fmt(f.ref_offset_e_m, 2)} m added`)
      + (f.pose_source !== "bottom" ? ""  // the pose corrected by the bottom's estimate (--pose-from-bottom)
        : ` · pose from the bottom: heading error ${fmt(f.cam_err_d_deg, 2)}° taken off, walk `
          + `N ${fmt(f.walk_n_m, 2)} E ${fmt(f.walk_e_m, 2)} m applied`)
    : `${several() ? `${name}: ` : ""}no fix: ${f ? f.status : "no frames yet"}`);
  if (!several()) {
    $("fix-text").textContent = fixText(fix, "UUV");
  } else {  // a line per UUV, in its colour
    $("fix-text").replaceChildren(...page.uuvs.map((u, j) => Object.assign(document.createElement("span"), {
      className: "uuv-line", textContent: fixText(own(j).fix, u.id), style: `border-left: 0.6rem solid ${u.colour}`,
    })));
  }
  showUuvTable();
}

// ---- the header: what GPS_INPUT sends now, how old it is, whether the autopilot is heard ---------------------
// Ages are the status's own (its clock when it was taken) plus the time since this page received it: the
// browser's clock need not agree with the station's.
const sinceStatus = () => (performance.now() - page.statusAt) / 1000;
const ageNow = (t) => (t === null || t === undefined ? null : page.status.t - t + sinceStatus());  // t: station clock
const agedBy = (a) => (a === null || a === undefined ? null : a + sinceStatus());  // an age in the status, now
const clock = (t) => new Date(t * 1000).toTimeString().slice(0, 8);  // HH:MM:SS
const ago = (a) => `${a.toFixed(1)} s ago`;

function setHead(id, text, cls, title) {
  const e = $(id);
  e.textContent = text;
  e.className = cls;
  e.title = title || "";
}

function showSending() {
  const stale = !page.status || performance.now() - page.statusAt > STALE_MS;
  document.body.classList.toggle("stale", stale);
  if (stale) {
    setHead("sending", "NO STATUS", "word grey", "no status from skyfix for over 2 s: what GPS_INPUT sends now is "
            + "not known (the service stopped, or this page lost it)");
    setHead("sending-why", page.status ? `no status since ${clock(page.status.t)}` : "no status yet", "");
    for (const id of ["sent-age", "autopilot"]) setHead(id, "", "");
    setHead("hacc", "accuracy —", "");
    return;
  }
  const mine = own(page.sel), g = mine.gps_input, fix = mine.fix;
  $("sending-to").textContent = several() ? `to ${page.uuvs[page.sel].id}` : "to the UUV";
  if (!g) {  // a run without --gps-input: nothing goes to a UUV
    setHead("sending", "NOT SENDING", "word warn", "skyfix runs without --gps-input: no GPS_INPUT to any autopilot");
    setHead("sending-why", "no GPS_INPUT configured", "");
    for (const id of ["sent-age", "autopilot"]) setHead(id, "", "");
    const ok = fix && fix.status === "ok";
    setHead("hacc", ok ? `accuracy ±${fmt(fix.h_acc_m, 2, " m")}` : "accuracy —", "",
            ok ? `h_acc ${fmt(fix.h_acc_m, 2, " m")} of the newest fix (not sent anywhere)` : "");
    return;
  }
  const link = g.link || {};
  const sent = ageNow(g.last_sent_t);
  const valid = g.last_fix_type === 3;
  const detail = `GPS_INPUT to ${g.url}: the last message fix_type ${g.last_fix_type ?? "—"}`
    + (valid ? " (3D fix)" : g.no_fix_reason ? ` (no fix: ${g.no_fix_reason})` : "")
    + ` · ${g.sent_valid}/${g.sent} valid · ${g.not_delivered} not delivered · link ${link.state ?? "—"}`;
  let word, cls, why;
  if (sent === null || page.status.t - g.last_sent_t > SENT_S) {  // judged at the status: it came once a second
    [word, cls, why] = ["NOT SENT", "bad", sent === null ? "no GPS_INPUT sent yet" : `no GPS_INPUT for ${sent.toFixed(1)} s`];
  } else if (link.state !== "up") {
    [word, cls, why] = ["NOT DELIVERED", "bad", `link ${link.state}${link.error ? `: ${link.error}` : ""}`];
  } else if (valid) {
    [word, cls, why] = ["3D fix", "ok", `position ${fmt(ageNow(g.sent_fix_t), 1, " s")} old`];
  } else {
    const last = fix && fix.status === "ok" && g.no_fix_reason === "no_new_fix" ? ` (last fix ${ago(ageNow(fix.t))})` : "";
    [word, cls, why] = ["NO FIX", "bad", `${g.no_fix_why || "no fix"}${last}`];
  }
  setHead("sending", word, `word ${cls}`, detail);
  setHead("sending-why", why, "", detail);
  setHead("sent-age", sent === null ? "" : `sent ${ago(sent)}`, "",
          sent === null ? "" : `the last GPS_INPUT left at ${clock(g.last_sent_t)} (station clock)`);
  const heard = agedBy(link.peer_age_s);
  const from = g.url.startsWith("zenoh:") ? "the autopilot's HEARTBEAT on mavlink/*/1/HEARTBEAT"
    : `any MAVLink message from the other end of ${g.url}`;
  setHead("autopilot", heard !== null && heard <= HEARD_S ? `autopilot heard ${ago(heard)}` : "autopilot NOT heard",
          heard !== null && heard <= HEARD_S ? "ok" : "bad",
          `${from}: ${heard === null ? "never heard" : `last heard ${ago(heard)}`}`);
  const acc = valid ? g.sent_h_acc_m : null;
  setHead("hacc", acc === null ? "accuracy —" : `accuracy ±${fmt(acc, 2, " m")}`, "",
          acc === null ? "no position sent" : `h_acc ${fmt(acc, 2, " m")}: GPS_INPUT's horiz_accuracy (hdop `
          + `${fmt(acc, 2)}) of the fix sent, exposed at ${clock(g.sent_fix_t)}`);
}

// between statuses: the ages grow, and a status or a frame that does not come greys the page or the video
setInterval(() => {
  const wasStale = video.dataset.stale === "1", isStale = videoStale();
  video.dataset.stale = isStale ? "1" : "";
  if (isStale || wasStale) drawVideo();
  showSending();
}, 250);

// several UUVs: a row each, in its colour: its target, fix, h_acc, depth's age, GPS_INPUT and gates
function showUuvTable() {
  const table = $("uuvs");
  table.hidden = !several();
  if (!several()) return;
  const rows = page.uuvs.map((u, k) => {
    const o = own(k), fix = o.fix, g = o.gps_input, gates = g && g.gates, d = o.depth || {};
    const tr = document.createElement("tr");
    tr.dataset.uuv = u.id;
    const gpsState = !g ? "—" : g.last_fix_type === 3 ? "ok: fix" : g.sent ? "warn: no fix" : "—";
    const cells = [
      [`${k === page.sel ? "▶ " : ""}${u.id}`, ""],
      [`${o.target.state}${o.target.origin ? ` (${o.target.origin})` : ""}`,
       o.target.state === "tracking" ? "ok" : o.target.state === "lost" ? "bad" : "warn"],
      [fix ? fix.status : "no frames", fix && fix.status === "ok" ? "ok" : "bad"],
      [fmt(fix && fix.h_acc_m, 2, " m"), ""],
      [d.age_s === null || d.age_s === undefined ? "never" : `${d.age_s.toFixed(2)} s`,
       o.problems && o.problems.depth ? "bad" : "ok"],
      [gpsState, gpsState.startsWith("ok") ? "ok" : gpsState === "—" ? "" : "warn"],
      [gates ? gates.state : "—", !gates ? "" : gates.state === "tracking" ? "ok" : gates.state === "diverged" ? "bad" : "warn"],
    ];
    cells.forEach(([text, cls], i) => {
      const td = document.createElement("td");
      td.textContent = text;
      if (i === 0) td.style.cssText = `background: ${u.colour}; color: #fff`;
      else if (cls) td.className = `state ${cls}`;
      tr.appendChild(td);
    });
    return tr;
  });
  table.tBodies[0].replaceChildren(...rows);
}

// ---- map ------------------------------------------------------------------------------------------
function niceLength(m) {  // 1, 2, 5 × 10^k not above m
  const p = Math.pow(10, Math.floor(Math.log10(m)));
  return [5, 2, 1].map((k) => k * p).find((x) => x <= m) || p;
}

// The map is Leaflet's (web Mercator, north up; served by skyfix, nothing from the internet) over the base map's
// tiles when the run has one (--basemap); what skyfix draws (footprint, tracks, accuracy circles and ellipses, the
// UAV, north arrow, scale bar) goes on a canvas above the tiles, placed by Leaflet's projection. The map follows the
// UAV, its footprint and the last 30 s of each track ("follow"); dragging or zooming it stops that. Without Leaflet
// (an installation that did not fetch it) the rest of the page works and the map says what is missing.
const MAX_ZOOM = 26;
const WGS84_A = 6378137.0, WGS84_E2 = 6.69437999014e-3;
const lmap = window.L ? L.map(map, { zoomSnap: 0, zoomDelta: 0.5, maxZoom: MAX_ZOOM, zoomControl: false,
                                     attributionControl: false, zoomAnimation: false, fadeAnimation: false })
  .setView([0, 0], 1) : null;
page.follow = true;
let fitting = false, baseLayer = null;
if (lmap) {
  L.control.zoom({ position: "bottomright" }).addTo(lmap);
  lmap.on("move zoom resize", () => drawMap());
  lmap.on("dragstart zoomstart", () => { if (!fitting) setFollow(false); });
}
$("follow").onchange = () => { setFollow($("follow").checked); if (page.follow) fitView(); drawMap(); };

function setFollow(on) {
  page.follow = on;
  $("follow").checked = on;
}

// The base map of the hello (its tiles' URL, bounds, zoom levels), or none: the map's white
function showBasemap(b) {
  if (baseLayer) baseLayer.remove();
  baseLayer = null;
  page.basemap = b;
  map.dataset.tiles = b ? "loading" : "";
  if (!b || !lmap) return;
  const [w, s, e, n] = b.bounds;
  if (!page.map || !page.map.origin) {  // nothing of the run to show yet: the base map
    fitting = true;
    lmap.fitBounds([[s, w], [n, e]], { animate: false });
    fitting = false;
  }
  // no tiles asked for far below the base map's own zooms (no minNativeZoom: a world view would ask for millions)
  baseLayer = L.tileLayer(b.url, { bounds: [[s, w], [n, e]], minZoom: Math.max(0, b.minzoom - 3),
                                   maxNativeZoom: b.maxzoom, maxZoom: MAX_ZOOM, keepBuffer: 1 });
  baseLayer.on("loading", () => { map.dataset.tiles = "loading"; });
  baseLayer.on("load", () => { map.dataset.tiles = "loaded"; });
  baseLayer.addTo(lmap);
}

// the live mosaic (live_mosaic = true) painted another frame: its tiles fetched anew (the version in their URL)
function refreshLiveMosaic(m) {
  if (!m || !baseLayer || m.painted === page.mosaicPainted) return;
  page.mosaicPainted = m.painted;
  baseLayer.setUrl(`${page.basemap.url}?v=${m.painted}`);
}

// metres north and east of the map's origin → [lat, lon] (degrees), with the WGS84 ellipsoid's radii of curvature
// at the origin (a local flat map: its error grows with the square of the distance over the earth's radius)
function toLatLng(n, e) {
  const o = page.map.origin, phi = o.lat * Math.PI / 180, s = 1 - WGS84_E2 * Math.sin(phi) ** 2;
  const meridian = WGS84_A * (1 - WGS84_E2) / s ** 1.5, normal = WGS84_A / Math.sqrt(s);
  return [o.lat + n / meridian * 180 / Math.PI, o.lon + e / (normal * Math.cos(phi)) * 180 / Math.PI];
}

// what must be in view: the UAV, its footprint, the last 30 s of each track; [north, east] metres
function inView() {
  const m = page.map, pts = [];
  if (!m || !m.origin) return pts;
  if (m.uav) pts.push(m.uav);
  if (m.footprint) pts.push(...m.footprint);
  for (const u of page.uuvs) {
    const recent = u.track.filter((p) => p[4] > (u.track.length ? u.track.at(-1)[4] : 0) - 30);
    recent.forEach((p) => pts.push([p[1], p[2]]));
    const gt = u.gate && u.gate.track;
    if (gt) pts.push([gt.n, gt.e]);
  }
  return pts;
}

// the view around what must be in view, 1.25 times its span (at least 4 m) across the map's shorter side
function fitView() {
  const pts = inView();
  if (!pts.length || !lmap) return;
  const ns = pts.map((p) => p[0]), es = pts.map((p) => p[1]);
  const n0 = (Math.min(...ns) + Math.max(...ns)) / 2, e0 = (Math.min(...es) + Math.max(...es)) / 2;
  const span = Math.max(Math.max(...ns) - Math.min(...ns), Math.max(...es) - Math.min(...es), 4);
  const size = lmap.getSize(), centre = toLatLng(n0, e0);
  const pxPerM = Math.min(size.x, size.y) / (span * 1.25);  // CSS pixels; at zoom z a pixel is 2πa cos(lat) / (256 2^z) m
  const zoom = Math.log2(pxPerM * 2 * Math.PI * WGS84_A * Math.cos(centre[0] * Math.PI / 180) / 256);
  fitting = true;
  lmap.setView(centre, Math.min(zoom, MAX_ZOOM), { animate: false });
  fitting = false;
}

function drawMap() {
  const m = page.map;
  map.dataset.points = page.uuvs.length ? page.uuvs[0].track.length : 0;  // the first UUV's
  map.dataset.tracks = page.uuvs.map((u) => `${u.id}:${u.track.length}`).join(" ");
  if (!m) return;
  const gate0 = page.uuvs.length ? page.uuvs[0].gate : null;
  map.dataset.gate = gate0 ? gate0.state : "";  // the first UUV's
  map.dataset.gates = page.uuvs.map((u) => `${u.id}:${u.gate ? u.gate.state : ""}`).join(" ");
  if (!lmap) {
    $("map-info").textContent = "no map: its library (Leaflet) is missing from this installation of skyfix "
      + "(./dev setup, or python -m groundstation.live.ui.vendor, fetches it)";
    return;
  }
  const dpr = window.devicePixelRatio || 1;
  const canvas = mctx.canvas, size = lmap.getSize();
  canvas.width = Math.max(1, Math.round(size.x * dpr));
  canvas.height = Math.max(1, Math.round(size.y * dpr));
  const W = canvas.width, H = canvas.height, ctx = mctx;
  ctx.clearRect(0, 0, W, H);
  if (!inView().length) {
    ctx.fillStyle = "#000";
    ctx.font = `bold ${16 * dpr}px system-ui, sans-serif`;
    ctx.fillText(`no UAV position (${m.pose})`, 10 * dpr, 24 * dpr);
    return;
  }
  // canvas pixels of a point metres east (X) and north (Y) of the origin: web Mercator's x is the longitude's, y the
  // latitude's alone
  const X = (e) => lmap.latLngToContainerPoint(toLatLng(0, e)).x * dpr;
  const Y = (n) => lmap.latLngToContainerPoint(toLatLng(n, 0)).y * dpr;
  const pxPerM = X(1) - X(0);
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
  // each UUV's track in its colour: accuracy circles, then the line, then the last fix
  for (const u of page.uuvs) drawTrack(ctx, u.track, u.colour, X, Y, pxPerM, dpr);
  // each UUV's safety gates' track: blue with one UUV, its colour with several
  for (const u of page.uuvs) {
    if (u.gate && u.gate.track) drawGateTrack(ctx, u.gate, X, Y, pxPerM, dpr, several() ? u.colour : "#0050c8");
  }
  if (several()) {  // the legend: each UUV's id in its colour
    ctx.font = `bold ${14 * dpr}px system-ui, sans-serif`;
    page.uuvs.forEach((u, k) => {
      ctx.fillStyle = u.colour;
      ctx.fillRect(10 * dpr, (8 + 20 * k) * dpr, 14 * dpr, 14 * dpr);
      ctx.fillStyle = "#000";
      ctx.fillText(u.id, 30 * dpr, (20 + 20 * k) * dpr);
    });
  }
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
  $("map-info").textContent = (several()
    ? `fixes on the tracks: ${page.uuvs.map((u) => `${u.id} ${u.track.length}`).join(", ")}`
    : `${page.uuvs[0].track.length} fixes on the track`) + ` · scale bar ${bar} m`
    + (m.height_m !== null ? ` · camera ${m.height_m.toFixed(1)} m above the water` : "")
    + (m.horizon ? " · horizon in view: footprint cut" : "")
    + (m.footprint ? "" : ` · no footprint (${m.pose})`)
    + (o ? ` · origin ${o.lat.toFixed(6)}, ${o.lon.toFixed(6)}` : "")
    + (!page.basemap ? " · no base map" : ` · base map ${page.basemap.name}`
       + (page.basemap.sigma_m !== null ? ` (placed to ±${page.basemap.sigma_m.toFixed(2)} m, 1σ)` : ""));
}

// "#b00000" and an opacity → "rgba(176, 0, 0, 0.35)"
function rgba(hex, alpha) {
  const n = parseInt(hex.slice(1), 16);
  return `rgba(${n >> 16}, ${(n >> 8) & 255}, ${n & 255}, ${alpha})`;
}

function drawTrack(ctx, track, colour, X, Y, pxPerM, dpr) {
  ctx.lineWidth = 1 * dpr;
  ctx.strokeStyle = rgba(colour, 0.35);
  for (const p of track) {
    ctx.beginPath();
    ctx.arc(X(p[2]), Y(p[1]), Math.max(p[3] * pxPerM, 1), 0, 2 * Math.PI);
    ctx.stroke();
  }
  ctx.strokeStyle = colour;
  ctx.lineWidth = 2 * dpr;
  ctx.beginPath();
  track.forEach((p, i) => (i ? ctx.lineTo(X(p[2]), Y(p[1])) : ctx.moveTo(X(p[2]), Y(p[1]))));
  ctx.stroke();
  const last = track.at(-1);
  if (last) {
    ctx.fillStyle = colour;
    ctx.beginPath();
    ctx.arc(X(last[2]), Y(last[1]), 5 * dpr, 0, 2 * Math.PI);
    ctx.fill();
    ctx.lineWidth = 3 * dpr;
    ctx.beginPath();
    ctx.arc(X(last[2]), Y(last[1]), Math.max(last[3] * pxPerM, 5 * dpr), 0, 2 * Math.PI);
    ctx.stroke();
  }
}

// The safety gates' track: a diamond (blue with one UUV), its 2-sigma ellipse (own and shared error), its velocity
// over the next second; while a target is being acquired, a dashed circle where the UUV can be by now.
function drawGateTrack(ctx, gate, X, Y, pxPerM, dpr, colour) {
  const t = gate.track;
  const x = X(t.e), y = Y(t.n);
  const a = t.sigma_n ** 2, b = t.cov_ne ?? 0, c = t.sigma_e ** 2;  // [[nn, ne], [ne, ee]]
  const mid = (a + c) / 2, half = Math.sqrt(((a - c) / 2) ** 2 + b * b);
  const angle = Math.atan2(half + (a - c) / 2, b || 1e-12);  // of the major axis, from east towards north
  ctx.strokeStyle = colour;
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
  ctx.fillStyle = colour;
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

// the problems to list: [input, text]; with several UUVs, one every UUV has (a shared input's) once, a UUV's own
// with its id
function problemList() {
  if (!several()) return Object.entries(page.status.problems || {});
  const out = [];
  page.uuvs.forEach((u, k) => {
    for (const [key, text] of Object.entries(own(k).problems || {})) {
      const everyones = page.uuvs.every((_, j) => (own(j).problems || {})[key] === text);
      if (!everyones) out.push([`${u.id}/${key}`, `${u.id}: ${text}`]);
      else if (k === 0) out.push([key, text]);
    }
  });
  return out;
}

function showHealth() {
  const s = page.status, rates = page.rates, problems = s.problems || {};
  const list = $("problems");
  const entries = problemList();
  list.replaceChildren(...(entries.length
    ? entries.map(([k, v]) => { const li = document.createElement("li"); li.className = "bad"; li.dataset.input = k; li.textContent = v; return li; })
    : [Object.assign(document.createElement("li"), { textContent: "every input OK" })]));
  const count = entries.length;
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
                  `${v.frames} frames · ` + (several()
                    ? page.uuvs.map((u, k) => `${u.id} tracked ${fmt(u.rates.processed, 1)} fps, dropped ${own(k).pipeline.dropped}`).join(" · ")
                    : `tracked ${fmt(rates.processed, 1)} fps · dropped ${s.pipeline.dropped}`)
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
  if (s.reference) {  // a surveyed marker in view: the drone's absolute offset added to every fix
    const r = s.reference;
    const state = r.state === "applied" ? "ok" : r.state === "lapsed" ? "warn: lapsed" : "—";
    rows.push(row("reference", state, age(r.age_s), "",
                  (r.state === "applied"
                    ? `offset N ${fmt(r.offset_n_m, 3, " m")} ± ${fmt(r.sigma_n_m, 3, " m")}, `
                      + `E ${fmt(r.offset_e_m, 3, " m")} ± ${fmt(r.sigma_e_m, 3, " m")} added to every fix`
                    : r.state === "lapsed" ? `not applied: too few sightings in the last ${r.window_s} s`
                    : "no offset yet")
                  + ` · ${r.sightings} sightings in ${r.window_s} s · ${r.seen}/${r.searched} frames found, `
                  + `${r.skipped} skipped · ${r.corrected} fixes corrected · ${r.file}`
                  + (r.buoy  // a buoy reporting its GNSS: its reports and those refused
                    ? ` · buoy system ${r.buoy.system_id}: ${r.buoy.reports} reports, `
                      + (r.buoy.last_report_age_s === null ? "none yet"
                        : `the last ${age(r.buoy.last_report_age_s)} ago`)
                      + `, ${r.buoy.refused} malformed and `
                      + `${Object.values(r.buoy.foreign).reduce((a, b) => a + b, 0)} of other systems refused`
                    : "")));
  }
  if (s.bottom) {  // the drone's pose biases from the static bottom (--pose-from-bottom)
    const b = s.bottom;
    const state = b.state === "applied" ? "ok" : b.state === "lapsed" ? "warn: lapsed" : "—";
    rows.push(row("pose from bottom", state, age(b.age_s), "",
                  (b.tilt_fwd_deg == null ? "no estimate yet"
                    : `tilt fwd ${fmt(b.tilt_fwd_deg, 2)}° right ${fmt(b.tilt_right_deg, 2)}° ± ${fmt(b.sigma_tilt_deg, 2)}°, `
                      + `heading ${fmt(b.heading_deg, 2)}° ± ${fmt(b.sigma_heading_deg, 2)}°, `
                      + `walk N ${fmt(b.walk_n_m, 2)} E ${fmt(b.walk_e_m, 2)} ± ${fmt(b.sigma_walk_m, 2, " m")} · `
                      + `${[b.tilt_applied && "tilt", b.heading_applied && "heading"].filter(Boolean).join(" and ")
                           || "the walk only"} applied · ${b.features} features`)
                  + ` · ${b.frames} frames in ${b.window_s} s, ${b.skipped} skipped · ${b.fits} estimates, `
                  + `${b.refused} gave none${b.last_refusal ? ` (${b.last_refusal})` : ""} · `
                  + `${b.corrected} fixes corrected, ${b.kept_own} kept their own`));
  }
  // a UUV's own rows: named with its id when there are several
  const each = (fn) => page.uuvs.forEach((u, k) => fn(own(k), several() ? `${u.id} ` : "", u.rates,
                                                      (key) => ((own(k).problems || {})[key] ? "problem" : "ok")));
  each((o, who, rates, st) => {
    const d = o.depth;
    const a = d.ardusub;
    rows.push(row(`${who}depth (${d.shape})`, st("depth"), age(d.age_s), hz(rates.depth),
                  `${d.key ?? d.url} · ${fmt(d.depth_m)} m ± ${fmt(d.sigma_m)} (${d.source ?? "—"})`
                  + (a ? ` · EKF ${fmt(a.ekf_depth_m)} m, Δ ${fmt(a.disagreement_m)} m, ${fmt(a.vertical_speed_mps)} m/s`
                         + (a.params.missing.length ? ` · waiting for ${a.params.missing.join(", ")}` : "") : "")
                  + ` · ${d.received} received, ${d.bad} bad, ${d.refused} refused (${d.jumps} jumps)`));
    const up = o.uuv_position;
    if (up.key || up.hint) {
      rows.push(row(`${who}UUV position`, up.received ? "ok" : "—", age(up.age_s), "",
                    `${up.key || "hint"} · ${up.received} received`));
    }
  });
  rows.push(row("Zenoh", st("zenoh"), "", "", `${s.zenoh ? s.zenoh.peers : "—"} peers/routers connected`));
  each((o, who, rates) => {
    if (o.gps_input) {
      const g = o.gps_input;
      const ft = g.last_fix_type === 3 ? "3 (fix)" : g.last_fix_type === 1 ? "1 (no fix)" : fmt(g.last_fix_type, 0);
      const link = g.link || {};
      const heard = link.peer_age_s === null || link.peer_age_s === undefined ? "never" : `${link.peer_age_s.toFixed(1)} s ago`;
      const state = link.state && link.state !== "up" ? `warn: link ${link.state}` : g.last_fix_type === 3 ? "ok" : g.sent ? "warn: no fix" : "—";
      rows.push(row(`${who}GPS_INPUT`, state, "", `${fmt(rates.gps_input, 1)} Hz`,
                    `last fix_type ${ft} · ${g.sent_valid}/${g.sent} valid · ${g.not_delivered} not delivered`
                    + ` · ${g.gates ? Object.values(g.gates.rejected).reduce((a, b) => a + b, 0) : 0} held by the gates · ${g.url}`
                    + ` · link ${link.state ?? "—"}${link.error ? ` (${link.error})` : ""} · autopilot last heard ${heard}`));
    }
    if (o.gps_input && o.gps_input.gates) {
      const g = o.gps_input.gates, t = g.track;
      const refused = Object.entries(g.rejected).filter(([, n]) => n).map(([k, n]) => `${k} ${n}`).join(", ");
      const state = g.state === "tracking" ? "ok" : g.state === "diverged" ? "bad: diverged" : "warn: acquiring";
      rows.push(row(`${who}safety gates`, state, t ? age(t.age_s) : "", "",
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
  });
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
  each((o, who) => {
    if (o.latency) {
      rows.push(row(`${who}latency`, null, "", "", `frame → GPS_INPUT p50 ${fmt(o.latency.p50_ms, 1, " ms")}, p99 `
                    + `${fmt(o.latency.p99_ms, 1, " ms")} over ${o.latency.n}`));
    }
  });
  if (s.process) {
    rows.push(row("CPU", null, "", "", `${fmt(s.process.cpu_pct, 0, " %")} of one core · ${fmt(s.process.rss_mb, 0)}`
                  + ` MB resident${s.ui ? ` · page video: ${s.ui.frames_encoded} JPEG, ${fmt(s.ui.encode_ms, 1)} ms CPU each` : ""}`));
  }
  $("health").tBodies[0].replaceChildren(...rows);
  $("health-time").textContent = new Date(s.t * 1000).toLocaleTimeString();
}

connect();
sizeVideo();
