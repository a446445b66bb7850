// duolando live viewer: draws the leader and the follower (SMPL-X, y-up,
// metres) as their frames arrive from `duolando live` over server-sent events
// (/events on the page's own server), with the latency and the step time in
// an overlay. Canvas 2D and a hand-rolled perspective camera (as viewer.js);
// no dependencies, no request but the page and the event stream.
"use strict";
(function () {
  const COLORS = { leader: "#3ea6ff", follower: "#ff7a1a" };
  const BODY_JOINTS = 25; // 0..24 body, 25..54 fingers
  const FOV = 40 * Math.PI / 180;
  const NEAR = 0.05;
  const HOME = { yaw: -0.62, pitch: 0.3 };
  const $ = (id) => document.getElementById(id);

  // ---- stream state ----
  const live = {
    hello: null, end: null, status: "connecting",
    events: 0, lastId: -1, outOfOrder: 0,
    leaderFrame: -1, followerFrame: -1, followerFrames: 0,
    drainEvents: 0, latencyFrames: null, latencyMs: null, stepMs: null, tickMs: null, steps: 0, late: 0, refusedFrom: null,
    stepSum: 0, stepCount: 0, stepMax: 0,
  };
  let J = 55, ROW = 165, parents = null, fps = 30;
  let leaderHist = []; // Float32Array per leader frame (for "leader in step")
  const dancers = [
    { name: "leader", pos: null, color: COLORS.leader, visible: true },
    { name: "follower", pos: null, color: COLORS.follower, visible: true },
  ];

  // ---- scene bounds, grown as frames arrive ----
  let floorY = Infinity, x0 = Infinity, x1 = -Infinity, z0 = Infinity, z1 = -Infinity;
  let centre = [0, 0.9, 0], radius = 1.2, homeDist = 4;
  const cam = { yaw: HOME.yaw, pitch: HOME.pitch, zoom: 1 };
  function grow(p) {
    let changed = false;
    for (let i = 0; i < p.length; i += 3) {
      const x = p[i], y = p[i + 1], z = p[i + 2];
      if (y < floorY) { floorY = y; changed = true; }
      if (x < x0) { x0 = x; changed = true; } if (x > x1) { x1 = x; changed = true; }
      if (z < z0) { z0 = z; changed = true; } if (z > z1) { z1 = z; changed = true; }
    }
    if (changed) {
      centre = [(x0 + x1) / 2, floorY + 0.9, (z0 + z1) / 2];
      radius = Math.max(1.2, Math.hypot(x1 - x0, z1 - z0) / 2 + 0.6);
      homeDist = radius / Math.tan(FOV / 2) * 0.8 + 0.5;
    }
  }

  // ---- DOM ----
  const view = $("view");
  const ctx = view.getContext("2d");
  const note = $("note");
  let dirty = true, renders = 0;

  // ---- camera (as viewer.js) ----
  let eye, r, u, f, focal, W = 1, H = 1;
  function setupCamera() {
    const dist = homeDist * cam.zoom;
    const cp = Math.cos(cam.pitch), sp = Math.sin(cam.pitch);
    eye = [centre[0] + dist * cp * Math.sin(cam.yaw), centre[1] + dist * sp, centre[2] + dist * cp * Math.cos(cam.yaw)];
    f = norm([centre[0] - eye[0], centre[1] - eye[1], centre[2] - eye[2]]);
    r = norm(cross(f, [0, 1, 0]));
    u = cross(r, f);
    focal = (H / 2) / Math.tan(FOV / 2);
  }
  function norm(v) { const l = Math.hypot(v[0], v[1], v[2]) || 1; return [v[0] / l, v[1] / l, v[2] / l]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function toCam(x, y, z) {
    const dx = x - eye[0], dy = y - eye[1], dz = z - eye[2];
    return [dx * r[0] + dy * r[1] + dz * r[2], dx * u[0] + dy * u[1] + dz * u[2], dx * f[0] + dy * f[1] + dz * f[2]];
  }
  const sx = (c) => W / 2 + focal * c[0] / c[2];
  const sy = (c) => H / 2 - focal * c[1] / c[2];
  function clip(a, b) {
    if (a[2] < NEAR && b[2] < NEAR) return null;
    if (a[2] >= NEAR && b[2] >= NEAR) return [a, b];
    const s = (NEAR - a[2]) / (b[2] - a[2]);
    const m = [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), NEAR];
    return a[2] < NEAR ? [m, b] : [a, m];
  }
  function line(a, b) {
    const seg = clip(a, b);
    if (!seg) return;
    ctx.moveTo(sx(seg[0]), sy(seg[0]));
    ctx.lineTo(sx(seg[1]), sy(seg[1]));
  }
  function resize() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(view.clientWidth * dpr)), h = Math.max(1, Math.round(view.clientHeight * dpr));
    if (view.width !== w || view.height !== h) { view.width = w; view.height = h; }
    W = view.width; H = view.height;
    dirty = true;
  }

  // ---- drawing ----
  function drawGrid() {
    if (!isFinite(floorY)) return;
    const step = 0.5;
    const gx0 = Math.floor((x0 - 1) / step) * step, gx1 = Math.ceil((x1 + 1) / step) * step;
    const gz0 = Math.floor((z0 - 1) / step) * step, gz1 = Math.ceil((z1 + 1) / step) * step;
    ctx.lineWidth = Math.max(1, H / 900);
    ctx.strokeStyle = "#26313b";
    ctx.beginPath();
    for (let x = gx0; x <= gx1 + 1e-6; x += step) line(toCam(x, floorY, gz0), toCam(x, floorY, gz1));
    for (let z = gz0; z <= gz1 + 1e-6; z += step) line(toCam(gx0, floorY, z), toCam(gx1, floorY, z));
    ctx.stroke();
  }
  function drawDancers() {
    const bones = [], heads = [];
    const px = H / 720;
    for (const d of dancers) {
      const p = d === dancers[0] && $("sync").checked && live.followerFrame >= 0 ? leaderHist[live.followerFrame] || d.pos : d.pos;
      if (!d.visible || !p) continue;
      ctx.strokeStyle = "rgba(0,0,0,0.45)";
      ctx.lineWidth = 6 * px;
      ctx.lineCap = "round";
      ctx.beginPath();
      for (let j = 1; j < BODY_JOINTS; j++) {
        const k = parents[j];
        line(toCam(p[3 * j], floorY, p[3 * j + 2]), toCam(p[3 * k], floorY, p[3 * k + 2]));
      }
      ctx.stroke();
      const cams = new Array(J);
      for (let j = 0; j < J; j++) cams[j] = toCam(p[3 * j], p[3 * j + 1], p[3 * j + 2]);
      for (let j = 1; j < J; j++) {
        const a = cams[j], b = cams[parents[j]];
        bones.push([(a[2] + b[2]) / 2, a, b, (j < BODY_JOINTS ? 5 : 2) * px, d.color]);
      }
      heads.push([cams[15], d.color]);
    }
    bones.sort((x, y) => y[0] - x[0]);
    ctx.lineCap = "round";
    for (const [, a, b, w, c] of bones) {
      const seg = clip(a, b);
      if (!seg) continue;
      const depth = Math.max(NEAR, (seg[0][2] + seg[1][2]) / 2);
      ctx.strokeStyle = c;
      ctx.lineWidth = Math.max(1.2, w * 5 / depth);
      ctx.beginPath();
      ctx.moveTo(sx(seg[0]), sy(seg[0]));
      ctx.lineTo(sx(seg[1]), sy(seg[1]));
      ctx.stroke();
    }
    for (const [c, color] of heads) {
      if (c[2] < NEAR) continue;
      ctx.fillStyle = color;
      ctx.beginPath();
      ctx.arc(sx(c), sy(c), focal * 0.085 / c[2], 0, 2 * Math.PI);
      ctx.fill();
    }
  }

  const num = (v, digits) => (v == null || !isFinite(v) ? "-" : Number(v).toFixed(digits));
  function setText(id, text) { const el = $(id); if (el.textContent !== text) el.textContent = text; }
  function drawOverlay() {
    const st = $("live-status");
    st.textContent = live.status;
    st.className = "status " + (live.end ? "ended" : live.events > 1 ? "streaming" : "");
    setText("live-leader", live.leaderFrame >= 0 ? String(live.leaderFrame) : "-");
    setText("live-frames", live.hello ? String(live.hello.frames) : "-");
    setText("live-follower", live.followerFrame >= 0 ? String(live.followerFrame) : "-");
    setText("live-latency-frames", live.latencyFrames == null ? "-" : String(live.latencyFrames));
    setText("live-latency-ms", live.latencyFrames == null ? "-" : num(live.latencyFrames * 1000 / fps, 0));
    setText("live-latency-wall", num(live.latencyMs, 0));
    setText("live-step-ms", num(live.stepMs, 2));
    setText("live-step-mean", live.stepCount ? num(live.stepSum / live.stepCount, 2) : "-");
    setText("live-step-max", live.stepCount ? num(live.stepMax, 2) : "-");
    setText("live-tick-ms", num(live.tickMs, 2));
    setText("live-budget", num(1000 / fps, 1));
    setText("live-steps", String(live.steps));
    setText("live-late", String(live.late));
  }

  function render() {
    setupCamera();
    ctx.fillStyle = "#0e1318";
    ctx.fillRect(0, 0, W, H);
    if (parents) { drawGrid(); drawDancers(); }
    drawOverlay();
    renders++;
  }

  // ---- the event stream ----
  function onHello(h) {
    live.hello = h;
    J = h.joints; ROW = J * 3; parents = h.parents; fps = h.fps;
    $("title").textContent = h.title;
    document.title = h.title + " \u00b7 duolando";
    const b = h.budget;
    setText("live-budget-text", b.preset + " (a " + b.lookahead + ", e " + b.enc_future + ", d " + b.dec_future + ", shift " + b.shift +
      "), latency " + h.latency_frames + " frames" + (h.paced ? ", 30 fps" : ", not paced (--no-pace)"));
  }
  function onFrame(ev) {
    if (ev.i !== live.leaderFrame + 1) live.outOfOrder++;
    const lp = Float32Array.from(ev.leader);
    leaderHist[ev.i] = lp;
    dancers[0].pos = lp;
    grow(lp);
    for (const fr of ev.follower) {
      if (fr.index !== live.followerFrame + 1) live.outOfOrder++;
      const fp = Float32Array.from(fr.pos);
      dancers[1].pos = fp;
      live.followerFrame = fr.index;
      grow(fp);
    }
    live.leaderFrame = ev.i;
    live.followerFrames = ev.follower_frames;
    live.latencyFrames = ev.latency_frames;
    live.latencyMs = ev.latency_ms;
    live.tickMs = ev.tick_ms;
    live.steps = ev.steps;
    if (ev.late) live.late++;
    if (ev.refused && live.refusedFrom == null) {
      live.refusedFrom = ev.i;
      note.textContent = "the session refuses leader frames from frame " + ev.i + " on: its steps wait for music past the end of the track";
    }
    if (ev.stepped > 0) {
      live.stepMs = ev.tick_ms;
      live.stepSum += ev.tick_ms; live.stepCount++; live.stepMax = Math.max(live.stepMax, ev.tick_ms);
    }
    live.status = live.followerFrame >= 0 ? "streaming" : "streaming (the follower starts after the latency)";
  }
  function onDrain(ev) {
    for (const fr of ev.follower) {
      if (fr.index !== live.followerFrame + 1) live.outOfOrder++;
      const fp = Float32Array.from(fr.pos);
      dancers[1].pos = fp;
      live.followerFrame = fr.index;
      grow(fp);
    }
    live.drainEvents++;
    live.followerFrames = ev.follower_frames;
    live.steps = ev.steps;
    live.latencyFrames = live.leaderFrame - live.followerFrame;
    live.status = "the leader ended: the follower finishes (drain)";
  }
  function onEnd(e) {
    live.end = e;
    live.status = "clip ended: " + e.follower_frames + " follower frames for " + e.frames + " leader frames";
    if (e.drained_frames > 0 && live.refusedFrom == null) note.textContent = "after the leader ended, the drain gave the follower's last " + e.drained_frames + " frames";
    source.close();
  }

  const source = new EventSource("events");
  function handler(kind, fn) {
    source.addEventListener(kind, (m) => {
      const id = Number(m.lastEventId);
      if (id !== live.lastId + 1) live.outOfOrder++;
      live.lastId = id;
      live.events++;
      try { fn(JSON.parse(m.data)); } catch (err) { note.textContent = "bad " + kind + " event: " + err; throw err; }
      dirty = true;
    });
  }
  handler("hello", onHello);
  handler("frame", onFrame);
  handler("drain", onDrain);
  handler("end", onEnd);
  source.onerror = () => {
    if (live.end) return;
    live.status = source.readyState === EventSource.CLOSED ? "disconnected" : "reconnecting";
    dirty = true;
  };

  // ---- input ----
  $("show-leader").addEventListener("change", (e) => { dancers[0].visible = e.target.checked; dirty = true; });
  $("show-follower").addEventListener("change", (e) => { dancers[1].visible = e.target.checked; dirty = true; });
  $("sync").addEventListener("change", () => { dirty = true; });
  let drag = null;
  view.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY]; view.setPointerCapture(e.pointerId); view.classList.add("dragging"); });
  view.addEventListener("pointermove", (e) => {
    if (!drag) return;
    cam.yaw -= (e.clientX - drag[0]) * 0.008;
    cam.pitch = Math.max(-0.05, Math.min(1.45, cam.pitch + (e.clientY - drag[1]) * 0.006));
    drag = [e.clientX, e.clientY];
    dirty = true;
  });
  const endDrag = () => { drag = null; view.classList.remove("dragging"); };
  view.addEventListener("pointerup", endDrag);
  view.addEventListener("pointercancel", endDrag);
  view.addEventListener("wheel", (e) => {
    e.preventDefault();
    cam.zoom = Math.max(0.25, Math.min(4, cam.zoom * Math.exp(e.deltaY * 0.001)));
    dirty = true;
  }, { passive: false });
  view.addEventListener("dblclick", () => { cam.yaw = HOME.yaw; cam.pitch = HOME.pitch; cam.zoom = 1; dirty = true; });
  window.addEventListener("resize", resize);

  function tick() {
    if (dirty) { dirty = false; render(); }
    requestAnimationFrame(tick);
  }

  // Test and scripting hook.
  window.__duolandoLive = {
    get status() { return live.status; },
    get hello() { return live.hello; },
    get end() { return live.end; },
    get events() { return live.events; },
    get drainEvents() { return live.drainEvents; },
    get outOfOrder() { return live.outOfOrder; },
    get leaderFrame() { return live.leaderFrame; },
    get followerFrame() { return live.followerFrame; },
    get followerFrames() { return live.followerFrames; },
    get latencyFrames() { return live.latencyFrames; },
    get stepMs() { return live.stepMs; },
    get renders() { return renders; },
    followerPose() { return dancers[1].pos ? Array.from(dancers[1].pos) : null; },
    colors: COLORS,
    setVisible(name, on) {
      const d = dancers.find((x) => x.name === name);
      if (!d) throw new Error("no dancer " + name);
      d.visible = !!on;
      $("show-" + name).checked = !!on;
      dirty = true;
    },
    ready: false,
  };

  resize();
  render();
  window.__duolandoLive.ready = true;
  requestAnimationFrame(tick);
})();
