// kinloop view: draws the frames the server pushes over one WebSocket (see server/src/view/messages.rs).
// Planar scenes on a 2-D canvas; spatial scenes with a small perspective projection and an orbiting camera.
// No library, no build step: the server embeds this file.
"use strict";

const $ = (id) => document.getElementById(id);
const canvas = $("canvas");
const ctx = canvas.getContext("2d");
const COLORS = ["#1565c0", "#6a1b9a", "#00838f", "#ef6c00", "#2e7d32", "#ad1457", "#4e342e", "#283593"];
const BODY_COLORS = ["#546e7a", "#78909c", "#8d6e63", "#607d8b", "#5d4037", "#455a64"];
const DRAG_EVERY_MS = 16; // the server takes at most 100 drag events per second
const GRAB_RADIUS_PX = 18;

const view = {
  ws: null, hello: null, welcome: null, scene: null, planar: true, frame: null,
  frames: 0, frameTimes: [], framesPerS: null, firstFrameMs: null, drawPending: false, panelAt: -Infinity,
  cam2: { cx: 0, cy: 0, scale: 1 },
  cam3: { yaw: -0.9, pitch: 0.45, dist: 1, target: [0, 0, 0] },
  grab: null, // { op, user, target, dragging }
  orbit: null,
  lastDragSent: 0, pendingTarget: null,
  replay: { t: 0, playing: false, last: 0, lastSeek: 0 },
  error: null, refused: null,
  token: "", rooms: null, // the token the page gave, and the rooms it may watch (`/rooms`)
};

// The room this page shows: `/room/NAME`, or (`/`) the server's front room.
const ROOM = (() => {
  const m = location.pathname.match(/^\/room\/([^/]+)/);
  return m ? decodeURIComponent(m[1]) : null;
})();

// ---------- rooms ----------
// The server's rooms this page's token may watch, as links (the token travels in the link's hash, as here).
function listRooms() {
  const headers = view.token ? { Authorization: `Bearer ${view.token}` } : {};
  fetch("/rooms", { headers, cache: "no-store" })
    .then((r) => r.json())
    .then((list) => {
      view.rooms = list.rooms.map((r) => r.name);
      const nav = $("rooms");
      nav.replaceChildren(...list.rooms.map((r) => {
        const a = document.createElement("a");
        a.href = `/room/${encodeURIComponent(r.name)}${location.hash}`;
        a.textContent = `${r.name} (${r.scene})`;
        if (r.name === ROOM) a.className = "here";
        return a;
      }));
      nav.hidden = list.rooms.length < 2;
      updateStatus();
    })
    .catch(() => {});
}

// ---------- connection ----------
function connect() {
  const path = ROOM === null ? "/ws" : `/room/${encodeURIComponent(ROOM)}/ws`;
  const ws = new WebSocket(`ws://${location.host}${path}`);
  view.ws = ws;
  ws.onmessage = (e) => {
    let m;
    try { m = JSON.parse(e.data); } catch (_) { return; }
    handlers[m.type] && handlers[m.type](m);
  };
  ws.onclose = () => {
    $("conn").textContent = view.refused ? "refused" : "disconnected";
    $("conn").className = "bad";
    view.grab = null;
    updateStatus();
  };
}

function send(message) {
  if (view.ws && view.ws.readyState === WebSocket.OPEN) view.ws.send(JSON.stringify(message));
}

const handlers = {
  hello(m) {
    view.hello = m;
    $("mode").textContent = m.mode;
    if (m.auth === "token") {
      const fromUrl = new URLSearchParams(location.hash.slice(1)).get("token");
      if (fromUrl !== null) { view.token = fromUrl; send({ type: "auth", token: fromUrl }); }
      else { $("auth").hidden = false; $("token").focus(); }
    } else {
      send({ type: "auth" });
    }
  },
  welcome(m) {
    view.welcome = m;
    view.scene = m.scene;
    view.planar = m.scene.kind === "planar";
    $("auth").hidden = true;
    $("conn").textContent = `connected (${m.role})`;
    $("scene-name").textContent = m.scene.name;
    $("hint").textContent = m.can_grab ? "drag an operational point to pull it" : "watching";
    listRooms();
    fitCamera();
    if (m.replay) {
      $("timeline").hidden = false;
      view.replay.t = m.replay.t0;
      seek(m.replay.t0, true);
    }
    resize();
  },
  refused(m) {
    view.refused = m.message;
    $("auth").hidden = true;
    $("refused").hidden = false;
    $("refused").textContent = `Refused: ${m.message}`;
    updateStatus();
  },
  frame(m) {
    view.frame = m;
    view.frames += 1;
    const now = performance.now();
    if (view.firstFrameMs === null) view.firstFrameMs = now;
    view.frameTimes.push(now);
    while (view.frameTimes.length && view.frameTimes[0] < now - 1000) view.frameTimes.shift();
    view.framesPerS = frameRate(view.frameTimes);
    if (!view.drawPending) { view.drawPending = true; requestAnimationFrame(draw); }
    if (now - view.panelAt > 250) { view.panelAt = now; updatePanel(); }
    updateStatus();
  },
  grabbed(m) {
    if (view.grab) view.grab.user = m.user;
    message(`holding ${m.op} as user ${m.user}`);
  },
  released(m) { message(`released (${m.reason})`); },
  error(m) { view.error = m.message; message(m.message); updateStatus(); },
};

function message(text) { $("messages").textContent = text; }

$("auth").addEventListener("submit", (e) => {
  e.preventDefault();
  view.token = $("token").value;
  send({ type: "auth", token: view.token });
});

// ---------- geometry helpers ----------
const dim = () => (view.planar ? 2 : 3);
const sub = (a, b) => a.map((v, i) => v - b[i]);
const add = (a, b) => a.map((v, i) => v + b[i]);
const mul = (a, s) => a.map((v) => v * s);
const dot = (a, b) => a.reduce((s, v, i) => s + v * b[i], 0);
const norm = (a) => Math.sqrt(dot(a, a));
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const unit = (a) => { const n = norm(a) || 1; return mul(a, 1 / n); };

function size() { return [canvas.clientWidth, canvas.clientHeight]; }

function fitCamera() {
  const [lo, hi] = view.scene.bounds;
  const center = lo.map((v, i) => 0.5 * (v + hi[i]));
  const extent = Math.max(...hi.map((v, i) => v - lo[i]), 1e-3);
  if (view.planar) {
    const [w, h] = size();
    const span = Math.max(hi[0] - lo[0], hi[1] - lo[1], 1e-3) * 1.6;
    view.cam2 = { cx: center[0], cy: center[1], scale: Math.min(w, h) / span };
  } else {
    view.cam3.target = center;
    view.cam3.dist = extent * 2.6;
  }
}

// Camera basis for spatial scenes (z up).
function basis() {
  const c = view.cam3;
  const dir = [Math.cos(c.pitch) * Math.cos(c.yaw), Math.cos(c.pitch) * Math.sin(c.yaw), Math.sin(c.pitch)];
  const eye = add(c.target, mul(dir, c.dist));
  const forward = unit(sub(c.target, eye));
  const right = unit(cross(forward, [0, 0, 1]));
  const up = cross(right, forward);
  const [w, h] = size();
  return { eye, forward, right, up, f: 0.9 * Math.min(w, h), w, h };
}

// World point -> [x px, y px, depth, px per metre].
function project(p, b) {
  const [w, h] = size();
  if (view.planar) {
    const c = view.cam2;
    return [w / 2 + (p[0] - c.cx) * c.scale, h / 2 - (p[1] - c.cy) * c.scale, 0, c.scale];
  }
  const d = sub(p, b.eye);
  const z = Math.max(dot(d, b.forward), 1e-4);
  return [w / 2 + (b.f * dot(d, b.right)) / z, h / 2 - (b.f * dot(d, b.up)) / z, z, b.f / z];
}

// Screen point -> world point: the plane z = 0 (planar) or the plane through `through` facing the camera.
function unproject(x, y, through, b) {
  const [w, h] = size();
  if (view.planar) {
    const c = view.cam2;
    return [c.cx + (x - w / 2) / c.scale, c.cy - (y - h / 2) / c.scale];
  }
  const ray = unit(add(b.forward, add(mul(b.right, (x - w / 2) / b.f), mul(b.up, -(y - h / 2) / b.f))));
  const t = dot(sub(through, b.eye), b.forward) / Math.max(dot(ray, b.forward), 1e-6);
  return add(b.eye, mul(ray, t));
}

// ---------- drawing ----------
function resize() {
  const dpr = window.devicePixelRatio || 1;
  const [w, h] = size();
  canvas.width = Math.round(w * dpr);
  canvas.height = Math.round(h * dpr);
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  if (view.scene && view.planar && !view.fitted) { fitCamera(); view.fitted = true; }
  draw();
}
window.addEventListener("resize", resize);

function line(a, b, color, width, dash) {
  ctx.strokeStyle = color;
  ctx.lineWidth = width;
  ctx.setLineDash(dash || []);
  ctx.beginPath();
  ctx.moveTo(a[0], a[1]);
  ctx.lineTo(b[0], b[1]);
  ctx.stroke();
  ctx.setLineDash([]);
}

function disc(p, r, fill, stroke) {
  ctx.beginPath();
  ctx.arc(p[0], p[1], Math.max(r, 1), 0, 2 * Math.PI);
  if (fill) { ctx.fillStyle = fill; ctx.fill(); }
  if (stroke) { ctx.strokeStyle = stroke; ctx.lineWidth = 2; ctx.stroke(); }
}

function arrow(from, to, color, label) {
  line(from, to, color, 3);
  const a = Math.atan2(to[1] - from[1], to[0] - from[0]);
  ctx.fillStyle = color;
  ctx.beginPath();
  ctx.moveTo(to[0], to[1]);
  ctx.lineTo(to[0] - 10 * Math.cos(a - 0.4), to[1] - 10 * Math.sin(a - 0.4));
  ctx.lineTo(to[0] - 10 * Math.cos(a + 0.4), to[1] - 10 * Math.sin(a + 0.4));
  ctx.fill();
  if (label) { ctx.font = "11px system-ui"; ctx.fillText(label, to[0] + 6, to[1] - 6); }
}

function drawObstacles(b) {
  const lo = view.scene.bounds[0], hi = view.scene.bounds[1];
  const extent = 4 * Math.max(...hi.map((v, i) => v - lo[i]), 0.05);
  for (const o of view.scene.obstacles) {
    ctx.fillStyle = "#d7ccc8";
    if (o.shape === "ball") {
      const p = project(o.center, b);
      disc(p, o.radius * p[3], "#d7ccc8", "#8d6e63");
    } else if (view.planar) {
      const n = o.normal, t = [-n[1], n[0]];
      const base = mul(n, o.offset);
      const corners = [add(base, mul(t, extent)), add(base, mul(t, -extent)),
        add(add(base, mul(t, -extent)), mul(n, -extent)), add(add(base, mul(t, extent)), mul(n, -extent))];
      ctx.beginPath();
      corners.map((c) => project(c, b)).forEach((p, i) => (i ? ctx.lineTo(p[0], p[1]) : ctx.moveTo(p[0], p[1])));
      ctx.fill();
    } else {
      // A grid patch of the plane around the scene's centre.
      const n = unit(o.normal);
      const t1 = unit(cross(n, Math.abs(n[2]) < 0.9 ? [0, 0, 1] : [1, 0, 0])), t2 = cross(n, t1);
      const c0 = view.cam3.target;
      const base = add(c0, mul(n, o.offset - dot(n, c0)));
      for (let i = -4; i <= 4; i++) {
        const s = (i / 4) * extent * 0.5;
        line(project(add(base, add(mul(t1, s), mul(t2, -extent / 2))), b), project(add(base, add(mul(t1, s), mul(t2, extent / 2))), b), "#bcaaa4", 1);
        line(project(add(base, add(mul(t2, s), mul(t1, -extent / 2))), b), project(add(base, add(mul(t2, s), mul(t1, extent / 2))), b), "#bcaaa4", 1);
      }
    }
  }
}

// Planar: keeps the linkage in view (it may travel far from where it started): when its drawing leaves the
// canvas, the camera recentres on it, zooming out if it no longer fits.
function keepInView(f) {
  if (!view.planar || view.grab || !f.linkage.capsules.length) return;
  const [w, h] = size();
  const margin = 20;
  let lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
  for (const c of f.linkage.capsules) {
    for (const p of [c.slice(0, 2), c.slice(2, 4)]) {
      lo = [Math.min(lo[0], p[0] - c[4]), Math.min(lo[1], p[1] - c[4])];
      hi = [Math.max(hi[0], p[0] + c[4]), Math.max(hi[1], p[1] + c[4])];
    }
  }
  const a = project(lo, null), z = project(hi, null);
  const inside = a[0] >= margin && z[0] <= w - margin && z[1] >= margin && a[1] <= h - margin;
  if (inside) return;
  const c = view.cam2;
  c.cx = 0.5 * (lo[0] + hi[0]);
  c.cy = 0.5 * (lo[1] + hi[1]);
  c.scale = Math.min(c.scale, (w - 2 * margin) / Math.max(hi[0] - lo[0], 1e-6), (h - 2 * margin) / Math.max(hi[1] - lo[1], 1e-6));
}

function drawLinkage(f, b) {
  const d = dim();
  const parts = [];
  for (const c of f.linkage.capsules) {
    const p = project(c.slice(0, d), b), q = project(c.slice(d, 2 * d), b);
    parts.push({ z: (p[2] + q[2]) / 2, draw: () => {
      ctx.lineCap = "round";
      line(p, q, BODY_COLORS[c[2 * d + 1] % BODY_COLORS.length], Math.max(2, 2 * c[2 * d] * (p[3] + q[3]) / 2));
      ctx.lineCap = "butt";
    } });
  }
  for (const c of f.linkage.balls) {
    const p = project(c.slice(0, d), b);
    parts.push({ z: p[2], draw: () => disc(p, c[d] * p[3], BODY_COLORS[c[d + 1] % BODY_COLORS.length]) });
  }
  parts.sort((x, y) => y.z - x.z).forEach((part) => part.draw());
  ctx.font = "11px system-ui";
  view.scene.ops.forEach((name, i) => {
    const pose = f.linkage.ops[i];
    if (!pose) return;
    const p = project(pose.slice(0, d), b);
    disc(p, 5, "#fff", "#333");
    ctx.fillStyle = "#333";
    ctx.fillText(name, p[0] + 8, p[1] + 14);
  });
}

function drawUsers(f, b) {
  const d = dim();
  const L = view.scene.length_scale;
  f.users.forEach((u, i) => {
    const color = COLORS[i % COLORS.length];
    if (!u.pose.length) return;
    const op = project(u.pose.slice(0, d), b);
    // Constraint directions: the linear part of each singular direction, through the OP.
    const k = u.sv.length;
    for (let j = 0; j < k && u.dirs.length === k * k; j++) {
      const col = u.dirs.slice(j * k, j * k + d);
      const len = norm(col);
      if (len < 0.2) continue; // mostly a rotation: no line to draw
      const constrained = j >= k - u.count;
      const reach = (constrained ? 40 : 26) * len;
      const e = view.planar ? [col[0], -col[1]] : sub(project(add(u.pose.slice(0, d), mul(col, 0.05 * L / len)), b), op).slice(0, 2);
      const s = reach / (Math.hypot(e[0], e[1]) || 1);
      line([op[0] - e[0] * s, op[1] - e[1] * s], [op[0] + e[0] * s, op[1] + e[1] * s], constrained ? "#c62828" : "#2e7d32", constrained ? 2.5 : 1);
    }
    if (u.device_pose) {
      const dev = project(u.device_pose.slice(0, d), b);
      line(op, dev, color, 1, [4, 3]);
      ctx.strokeStyle = color; ctx.lineWidth = 2;
      ctx.strokeRect(dev[0] - 5, dev[1] - 5, 10, 10);
    }
    if (u.model_pose) {
      const m = project(u.model_pose.slice(0, d), b);
      line([m[0] - 4, m[1] - 4], [m[0] + 4, m[1] + 4], color, 1.5);
      line([m[0] - 4, m[1] + 4], [m[0] + 4, m[1] - 4], color, 1.5);
    }
    const force = u.wrench.slice(0, d);
    const magnitude = norm(force);
    if (magnitude > 1e-3) {
      const px = Math.min(200, 30 * Math.sqrt(magnitude));
      const tipWorld = add(u.pose.slice(0, d), mul(force, 1e-3 / magnitude));
      const tip = project(tipWorld, b);
      const e = [tip[0] - op[0], tip[1] - op[1]];
      const s = px / (Math.hypot(e[0], e[1]) || 1);
      arrow(op, [op[0] + e[0] * s, op[1] + e[1] * s], "#e65100", `${magnitude.toFixed(2)} N`);
    }
    disc(op, 6, u.present ? color : "#bbb", "#fff");
  });
  if (view.grab && view.grab.target) {
    const t = project(view.grab.target, b);
    line([t[0] - 8, t[1]], [t[0] + 8, t[1]], "#000", 1.5);
    line([t[0], t[1] - 8], [t[0], t[1] + 8], "#000", 1.5);
  }
}

function drawAxes(b) {
  if (view.planar) return;
  const o = view.cam3.target, s = 0.3 * view.cam3.dist;
  const p0 = project(o, b);
  [[1, 0, 0], [0, 1, 0], [0, 0, 1]].forEach((a, i) => line(p0, project(add(o, mul(a, s)), b), ["#e57373", "#81c784", "#64b5f6"][i], 1));
}

function draw() {
  view.drawPending = false;
  const [w, h] = size();
  ctx.clearRect(0, 0, w, h);
  if (!view.scene) return;
  const b = view.planar ? null : basis();
  drawObstacles(b);
  drawAxes(b);
  const f = view.frame;
  if (!f) return;
  keepInView(f);
  drawLinkage(f, b);
  drawUsers(f, b);
  ctx.fillStyle = "#333";
  ctx.font = "12px system-ui";
  const err = f.closure_error == null ? "" : `   closure error ${f.closure_error.toExponential(2)} m`;
  ctx.fillText(`t ${f.t.toFixed(3)} s${err}`, 10, 18);
}

// ---------- panel and status ----------
function fmt(v, digits, unit) { return v == null ? "–" : `${v.toFixed(digits)}${unit || ""}`; }

function updatePanel() {
  const f = view.frame;
  if (!f) return;
  const rows = [
    ["VE time", `${f.t.toFixed(3)} s (step ${f.step})`],
    ["closure error", f.closure_error == null ? "–" : `${f.closure_error.toExponential(2)} m`],
    ["frames/s", fmt(view.framesPerS, 1)],
  ];
  if (f.loop) rows.push(["VE tick p50 / p99", `${f.loop.p50_us.toFixed(1)} / ${f.loop.p99_us.toFixed(1)} µs`], ["VE deadline misses", `${f.loop.misses}`]);
  $("summary").innerHTML = "";
  for (const [k, v] of rows) {
    const div = document.createElement("div");
    div.innerHTML = "<span></span><span></span>";
    div.children[0].textContent = k;
    div.children[1].textContent = v;
    if (k === "frames/s") div.children[1].id = "frame-rate";
    $("summary").appendChild(div);
  }
  const body = $("users").tBodies[0];
  body.innerHTML = "";
  f.users.forEach((u, i) => {
    const tr = body.insertRow();
    const cells = [
      `${u.id} ${u.name || ""}${u.role === "observer" ? " (obs)" : ""}`, u.device || "–", u.op || "–",
      fmt(u.rtt_ms, 1, " ms"), u.clamped == null ? "–" : `${(100 * u.clamped).toFixed(1)} %`,
      `${norm(u.wrench.slice(0, dim())).toFixed(2)} N`, `${u.count}`,
    ];
    cells.forEach((text, j) => {
      const td = tr.insertCell();
      if (j === 0) { const dot = document.createElement("span"); dot.className = "dot"; dot.style.background = COLORS[i % COLORS.length]; td.appendChild(dot); }
      td.appendChild(document.createTextNode(text));
    });
  });
}

// Frames per second over the arrival times `t` (ms) of the last second's frames; null before two arrived.
// The one rate the panel and the status bar both show.
function frameRate(t) {
  return t.length < 2 ? null : (1000 * (t.length - 1)) / Math.max(t[t.length - 1] - t[0], 1);
}

// The state tests read: frames, rate, first frame time, and the drawn OPs (world and canvas pixels).
function updateStatus() {
  const f = view.frame;
  const state = {
    frames: view.frames, fps: view.framesPerS, first_frame_ms: view.firstFrameMs, refused: view.refused, error: view.error,
    role: view.welcome ? view.welcome.role : null, can_grab: view.welcome ? view.welcome.can_grab : false,
    size: size(), grabbed: view.grab ? view.grab.user : null, target: view.grab ? view.grab.target : null,
    scene: view.scene ? view.scene.name : null, room: ROOM, rooms: view.rooms, camera: view.planar ? null : [view.cam3.yaw, view.cam3.pitch], replay_t: view.welcome && view.welcome.replay ? view.replay.t : null,
  };
  if (f) {
    const b = view.planar ? null : basis();
    state.seq = f.seq; state.t = f.t; state.step = f.step; state.closure_error = f.closure_error;
    state.ops = {}; state.ops_px = {};
    view.scene.ops.forEach((name, i) => {
      const pose = f.linkage.ops[i];
      if (!pose) return;
      state.ops[name] = pose.slice(0, dim());
      state.ops_px[name] = project(pose.slice(0, dim()), b).slice(0, 2);
    });
    state.users = f.users.map((u) => ({ id: u.id, pos: u.pose.slice(0, dim()), browser: u.browser, device: u.device }));
  }
  // The panel's rate follows every frame, as the status bar does (the rest of the panel every 250 ms).
  const rate = $("frame-rate");
  if (rate) rate.textContent = fmt(view.framesPerS, 1);
  const el = $("status");
  el.dataset.state = JSON.stringify(state);
  el.textContent = view.refused ? `refused: ${view.refused}` :
    `frames ${state.frames}  fps ${fmt(state.fps, 1)}  t ${f ? f.t.toFixed(3) : "–"}  ` +
    (f ? Object.entries(state.ops).map(([n, p]) => `${n} ${p.map((v) => v.toFixed(5)).join(",")}`).join("  ") : "");
}

// ---------- mouse: grab, drag, orbit, zoom ----------
function nearestOp(x, y) {
  const f = view.frame;
  if (!f) return null;
  const b = view.planar ? null : basis();
  let best = null;
  view.scene.ops.forEach((name, i) => {
    const pose = f.linkage.ops[i];
    if (!pose) return;
    const p = project(pose.slice(0, dim()), b);
    const dist = Math.hypot(p[0] - x, p[1] - y);
    if (dist <= GRAB_RADIUS_PX && (!best || dist < best.dist)) best = { name, dist, pose: pose.slice(0, dim()) };
  });
  return best;
}

function local(e) {
  const r = canvas.getBoundingClientRect();
  return [e.clientX - r.left, e.clientY - r.top];
}

canvas.addEventListener("pointerdown", (e) => {
  const [x, y] = local(e);
  const op = e.button === 0 ? nearestOp(x, y) : null;
  if (op && view.welcome && view.welcome.can_grab) {
    view.grab = { op: op.name, user: null, through: op.pose, target: op.pose };
    send({ type: "grab", op: op.name });
    canvas.setPointerCapture(e.pointerId);
    dragTo(x, y);
  } else if (op && view.welcome) {
    message(view.welcome.role === "observer" ? "this page watches: grabbing needs a manipulator token" : "grabbing is off on this view");
  } else if (!view.planar) {
    view.orbit = { x, y, yaw: view.cam3.yaw, pitch: view.cam3.pitch };
    canvas.setPointerCapture(e.pointerId);
  }
});

function dragTo(x, y) {
  const b = view.planar ? null : basis();
  view.grab.target = unproject(x, y, view.grab.through, b);
  view.pendingTarget = view.grab.target;
  flushDrag();
}

function flushDrag() {
  const now = performance.now();
  if (!view.pendingTarget || !view.grab) return;
  if (now - view.lastDragSent < DRAG_EVERY_MS) {
    setTimeout(flushDrag, DRAG_EVERY_MS - (now - view.lastDragSent) + 1);
    return;
  }
  view.lastDragSent = now;
  send({ type: "drag", target: view.pendingTarget });
  view.pendingTarget = null;
}

canvas.addEventListener("pointermove", (e) => {
  const [x, y] = local(e);
  if (view.grab) { dragTo(x, y); draw(); }
  else if (view.orbit) {
    view.cam3.yaw = view.orbit.yaw - (x - view.orbit.x) * 0.01;
    view.cam3.pitch = Math.max(-1.5, Math.min(1.5, view.orbit.pitch + (y - view.orbit.y) * 0.01));
    draw();
  }
});

function endPointer() {
  if (view.grab) { send({ type: "release" }); view.grab = null; updateStatus(); }
  view.orbit = null;
}
canvas.addEventListener("pointerup", endPointer);
canvas.addEventListener("pointercancel", endPointer);

canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  const factor = Math.exp(0.001 * e.deltaY);
  if (view.planar) view.cam2.scale /= factor; else view.cam3.dist *= factor;
  draw();
}, { passive: false });

// ---------- replay ----------
function seek(t, force) {
  const now = performance.now();
  view.replay.t = t;
  if (!force && now - view.replay.lastSeek < DRAG_EVERY_MS) return;
  view.replay.lastSeek = now;
  send({ type: "seek", t });
  const r = view.welcome.replay;
  $("slider").value = String(Math.round((1000 * (t - r.t0)) / Math.max(r.t1 - r.t0, 1e-9)));
  $("clock").textContent = `${t.toFixed(3)} / ${r.t1.toFixed(3)} s`;
}

$("slider").addEventListener("input", () => {
  const r = view.welcome.replay;
  view.replay.playing = false;
  $("play").textContent = "▶";
  seek(r.t0 + (Number($("slider").value) / 1000) * (r.t1 - r.t0), true);
});

$("play").addEventListener("click", () => {
  const r = view.welcome.replay;
  view.replay.playing = !view.replay.playing;
  $("play").textContent = view.replay.playing ? "❚❚" : "▶";
  if (view.replay.playing) {
    if (view.replay.t >= r.t1) view.replay.t = r.t0;
    view.replay.last = performance.now();
    requestAnimationFrame(play);
  }
});

function play(now) {
  if (!view.replay.playing) return;
  const r = view.welcome.replay;
  const dt = (now - view.replay.last) / 1000;
  view.replay.last = now;
  const t = Math.min(r.t1, view.replay.t + dt * Number($("speed").value));
  seek(t, t >= r.t1);
  if (t >= r.t1) { view.replay.playing = false; $("play").textContent = "▶"; return; }
  requestAnimationFrame(play);
}

resize();
connect();
