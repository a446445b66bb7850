// duolando viewer: plays leader and follower skeletons (SMPL-X, y-up, metres)
// on a canvas 2D with a hand-rolled perspective camera. No dependencies, no
// network. The data block is written by duolando::viewer (Rust).
"use strict";
(function () {
  const COLORS = { leader: "#3ea6ff", follower: "#ff7a1a" };
  const BODY_JOINTS = 25; // 0..24 body, 25..54 fingers
  const FOV = 40 * Math.PI / 180;
  const NEAR = 0.05;
  const HOME = { yaw: -0.62, pitch: 0.3 }; // a 3/4 view from the front-left, slightly above

  const data = JSON.parse(document.getElementById("duolando-data").textContent);

  // base64 little-endian float32 -> Float32Array (endianness fixed by DataView).
  function f32(b64) {
    const bin = atob(b64);
    const view = new DataView(new ArrayBuffer(bin.length));
    for (let i = 0; i < bin.length; i++) view.setUint8(i, bin.charCodeAt(i));
    const out = new Float32Array(bin.length >> 2);
    for (let i = 0; i < out.length; i++) out[i] = view.getFloat32(i * 4, true);
    return out;
  }

  const J = data.joints, ROW = J * 3, parents = data.parents;
  // A solo dancer (a Bailando model) has no leader: one dancer, drawn in
  // the follower's colour; the leader's entry stays, empty and hidden.
  const solo = !data.leader;
  const dancers = [
    { name: "leader", pos: solo ? new Float32Array(0) : f32(data.leader.f32), frames: solo ? 0 : data.leader.frames, color: COLORS.leader, visible: !solo },
    { name: solo ? "dancer" : "follower", pos: f32(data.follower.f32), frames: data.follower.frames, color: COLORS.follower, visible: true },
  ];
  if (solo) {
    const box = document.getElementById("show-leader");
    if (box && box.parentElement) box.parentElement.style.display = "none";
  }
  const beats = data.beats ? f32(data.beats.f32) : null;
  const tokens = data.tokens; // {rows, streams, frames_per_token, names, ids}
  const fps = data.fps;
  const frames = Math.max(dancers[0].frames, dancers[1].frames);
  const duration = frames / fps;

  // ---- scene bounds: floor height, centre and extent over every frame ----
  let minY = Infinity, x0 = Infinity, x1 = -Infinity, z0 = Infinity, z1 = -Infinity;
  for (const d of dancers) {
    for (let i = 0; i < d.pos.length; i += 3) {
      const x = d.pos[i], y = d.pos[i + 1], z = d.pos[i + 2];
      if (y < minY) minY = y;
      if (x < x0) x0 = x; if (x > x1) x1 = x;
      if (z < z0) z0 = z; if (z > z1) z1 = z;
    }
  }
  const floorY = minY;
  const centre = [(x0 + x1) / 2, floorY + 0.9, (z0 + z1) / 2];
  const radius = Math.max(1.2, Math.hypot(x1 - x0, z1 - z0) / 2 + 0.6);
  const homeDist = radius / Math.tan(FOV / 2) * 0.8 + 0.5;
  const cam = { yaw: HOME.yaw, pitch: HOME.pitch, dist: homeDist };

  // ---- DOM ----
  const view = document.getElementById("view");
  const ctx = view.getContext("2d");
  const timeline = document.getElementById("timeline");
  const tctx = timeline.getContext("2d");
  const playBtn = document.getElementById("play");
  const scrub = document.getElementById("scrub");
  const timeLabel = document.getElementById("time");
  const readout = document.getElementById("readout");
  const note = document.getElementById("note");
  const audio = document.getElementById("audio");
  scrub.max = String(frames - 1);

  // ---- playback state ----
  const state = { t: 0, playing: false, renders: 0, dirty: true };
  let lastTs = null;
  let audioClock = !!audio; // follow audio.currentTime while it advances
  let lastAudioT = -1, audioStall = 0;

  const frameAt = (t) => Math.max(0, Math.min(frames - 1, Math.floor(t * fps + 1e-6)));
  const currentFrame = () => frameAt(state.t);

  function audioPlaying() {
    return audio && audioClock && !audio.paused && !audio.ended && audio.readyState >= 2;
  }

  function play() {
    if (state.playing) return;
    if (state.t >= duration - 0.5 / fps) state.t = 0;
    state.playing = true;
    lastTs = null;
    if (audio && audio.error == null) {
      audioClock = true;
      lastAudioT = -1;
      audioStall = 0;
      if (state.t < audio.duration || isNaN(audio.duration)) audio.currentTime = state.t;
      const p = audio.play();
      if (p && p.catch) {
        p.catch((e) => {
          audioClock = false;
          note.textContent = "sound did not start (" + e.name + "); press play to retry";
        });
      }
    }
    state.dirty = true;
  }

  function pause() {
    if (!state.playing) return;
    state.playing = false;
    if (audio) audio.pause();
    state.dirty = true;
  }

  function seek(frame) {
    const f = Math.max(0, Math.min(frames - 1, Math.round(Number(frame) || 0)));
    state.t = f / fps;
    if (audio && audio.error == null && !isNaN(audio.duration) && state.t <= audio.duration) audio.currentTime = state.t;
    lastAudioT = -1;
    state.dirty = true;
  }

  if (audio) {
    audio.addEventListener("error", () => {
      audioClock = false;
      note.textContent = "audio file could not be loaded: " + audio.getAttribute("src");
    });
  }

  // ---- camera ----
  // Eye on a sphere around the centre; basis r (right), u (up), f (forward).
  let eye, r, u, f, focal, W = 1, H = 1;
  function setupCamera() {
    const cp = Math.cos(cam.pitch), sp = Math.sin(cam.pitch);
    eye = [centre[0] + cam.dist * cp * Math.sin(cam.yaw), centre[1] + cam.dist * sp, centre[2] + cam.dist * cp * Math.cos(cam.yaw)];
    f = norm([centre[0] - eye[0], centre[1] - eye[1], centre[2] - eye[2]]);
    r = norm(cross(f, [0, 1, 0]));
    u = cross(r, f);
    focal = (H / 2) / Math.tan(FOV / 2);
  }
  function norm(v) { const l = Math.hypot(v[0], v[1], v[2]) || 1; return [v[0] / l, v[1] / l, v[2] / l]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  // world -> camera space [x, y, depth]
  function toCam(x, y, z) {
    const dx = x - eye[0], dy = y - eye[1], dz = z - eye[2];
    return [dx * r[0] + dy * r[1] + dz * r[2], dx * u[0] + dy * u[1] + dz * u[2], dx * f[0] + dy * f[1] + dz * f[2]];
  }
  const sx = (c) => W / 2 + focal * c[0] / c[2];
  const sy = (c) => H / 2 - focal * c[1] / c[2];
  // Clip a camera-space segment to the near plane; null when wholly behind.
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
    const tw = Math.max(1, Math.round(timeline.clientWidth * dpr)), th = Math.max(1, Math.round(timeline.clientHeight * dpr));
    if (!timelineBase || timeline.width !== tw || timeline.height !== th) { timeline.width = tw; timeline.height = th; drawTimelineBase(); }
    W = view.width; H = view.height;
    state.dirty = true;
  }

  // ---- the 3D view ----
  function drawGrid() {
    const step = 0.5;
    const gx0 = Math.floor((x0 - 1) / step) * step, gx1 = Math.ceil((x1 + 1) / step) * step;
    const gz0 = Math.floor((z0 - 1) / step) * step, gz1 = Math.ceil((z1 + 1) / step) * step;
    ctx.lineWidth = Math.max(1, H / 900);
    ctx.strokeStyle = "#26313b";
    ctx.beginPath();
    for (let x = gx0; x <= gx1 + 1e-6; x += step) line(toCam(x, floorY, gz0), toCam(x, floorY, gz1));
    for (let z = gz0; z <= gz1 + 1e-6; z += step) line(toCam(gx0, floorY, z), toCam(gx1, floorY, z));
    ctx.stroke();
    ctx.strokeStyle = "#3a4753"; // world axes through the origin, if on the floor
    ctx.beginPath();
    if (gz0 <= 0 && gz1 >= 0) line(toCam(gx0, floorY, 0), toCam(gx1, floorY, 0));
    if (gx0 <= 0 && gx1 >= 0) line(toCam(0, floorY, gz0), toCam(0, floorY, gz1));
    ctx.stroke();
  }

  function drawDancers(frame) {
    const bones = []; // [depth, a, b, width, color]
    const heads = [];
    const px = H / 720; // line widths scale with the canvas
    for (const d of dancers) {
      if (!d.visible || d.frames === 0) continue;
      const base = Math.min(frame, d.frames - 1) * ROW;
      const p = d.pos;
      // floor shadow (joints dropped to the floor), drawn first
      ctx.strokeStyle = "rgba(0,0,0,0.45)";
      ctx.lineWidth = 6 * px;
      ctx.lineCap = "round";
      ctx.beginPath();
      for (let j = 1; j < BODY_JOINTS; j++) {
        const k = parents[j];
        line(toCam(p[base + 3 * j], floorY, p[base + 3 * j + 2]), toCam(p[base + 3 * k], floorY, p[base + 3 * k + 2]));
      }
      ctx.stroke();
      const cams = new Array(J);
      for (let j = 0; j < J; j++) cams[j] = toCam(p[base + 3 * j], p[base + 3 * j + 1], p[base + 3 * j + 2]);
      for (let j = 1; j < J; j++) {
        const a = cams[j], b = cams[parents[j]];
        bones.push([(a[2] + b[2]) / 2, a, b, (j < BODY_JOINTS ? 5 : 2) * px, d.color]);
      }
      heads.push([cams[15], d.color]);
    }
    bones.sort((x, y) => y[0] - x[0]); // far to near
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

  function render() {
    const frame = currentFrame();
    setupCamera();
    ctx.fillStyle = "#0e1318";
    ctx.fillRect(0, 0, W, H);
    drawGrid();
    drawDancers(frame);
    drawTimelineHead(frame);
    scrub.value = String(frame);
    timeLabel.textContent = (frame / fps).toFixed(2) + " s · frame " + frame + " / " + (frames - 1);
    playBtn.innerHTML = state.playing ? "&#10074;&#10074;" : "&#9654;";
    playBtn.setAttribute("aria-label", state.playing ? "pause" : "play");
    readout.textContent = readoutText(frame);
    state.renders++;
  }

  function readoutText(frame) {
    let s = "";
    if (beats) s += (beats[Math.min(frame, beats.length - 1)] > 0.5 ? "\u266a beat  " : "        ");
    if (tokens && tokens.rows > 0) {
      const k = Math.floor(frame / tokens.frames_per_token);
      if (k < tokens.rows) {
        s += "tokens[" + k + "]";
        for (let sIdx = 0; sIdx < tokens.streams; sIdx++) s += " " + tokens.names[sIdx] + "=" + tokens.ids[k * tokens.streams + sIdx];
      } else {
        s += "tokens: none past frame " + (tokens.rows * tokens.frames_per_token - 1);
      }
    }
    return s;
  }

  // ---- timeline: beats row + one row per token stream ----
  let timelineBase = null;
  const LABEL_W = 56;
  function timelineRows() {
    const rows = [];
    if (beats) rows.push("beats");
    if (tokens) for (const n of tokens.names) rows.push(n);
    return rows;
  }
  const frameX = (fr) => LABEL_W * (window.devicePixelRatio || 1) + (timeline.width - LABEL_W * (window.devicePixelRatio || 1)) * fr / frames;

  function tokenColor(id) {
    const h = (id * 137.508) % 360;
    const l = 42 + (id * 7 % 5) * 6;
    return "hsl(" + h.toFixed(1) + ",62%," + l + "%)";
  }

  function drawTimelineBase() {
    const off = document.createElement("canvas");
    off.width = timeline.width; off.height = timeline.height;
    const c = off.getContext("2d");
    const dpr = window.devicePixelRatio || 1;
    c.fillStyle = "#161d24";
    c.fillRect(0, 0, off.width, off.height);
    const rows = timelineRows();
    const rh = off.height / Math.max(1, rows.length);
    c.font = (11 * dpr) + "px system-ui, sans-serif";
    c.textBaseline = "middle";
    rows.forEach((name, i) => {
      const y = i * rh;
      c.fillStyle = "#7d8894";
      c.fillText(name, 6 * dpr, y + rh / 2);
      if (name === "beats") {
        c.fillStyle = "#e6e6e6";
        const w = Math.max(1.5 * dpr, (off.width - LABEL_W * dpr) / frames);
        for (let fr = 0; fr < beats.length; fr++) if (beats[fr] > 0.5) c.fillRect(frameX(fr), y + 2, w, rh - 4);
      } else {
        const s = i - (beats ? 1 : 0);
        for (let k = 0; k < tokens.rows; k++) {
          const a = frameX(k * tokens.frames_per_token), b = frameX(Math.min(frames, (k + 1) * tokens.frames_per_token));
          if (a >= off.width) break;
          c.fillStyle = tokenColor(tokens.ids[k * tokens.streams + s]);
          c.fillRect(a, y + 1, Math.max(1, b - a), rh - 2);
        }
      }
    });
    if (rows.length === 0) {
      c.fillStyle = "#7d8894";
      c.fillText("no beats or tokens in this file", LABEL_W * dpr, off.height / 2);
    }
    timelineBase = off;
  }

  function drawTimelineHead(frame) {
    if (!timelineBase) return;
    tctx.drawImage(timelineBase, 0, 0);
    const x = frameX(frame + 0.5);
    tctx.fillStyle = "#ffffff";
    tctx.fillRect(x - 1, 0, 2 * (window.devicePixelRatio || 1), timeline.height);
  }

  function timelineSeek(ev) {
    const rect = timeline.getBoundingClientRect();
    const fx = (ev.clientX - rect.left - LABEL_W) / Math.max(1, rect.width - LABEL_W);
    seek(fx * frames - 0.5);
  }

  // ---- input ----
  playBtn.addEventListener("click", () => (state.playing ? pause() : play()));
  scrub.addEventListener("input", () => { seek(scrub.valueAsNumber); });
  document.getElementById("show-leader").addEventListener("change", (e) => { dancers[0].visible = e.target.checked; state.dirty = true; });
  document.getElementById("show-follower").addEventListener("change", (e) => { dancers[1].visible = e.target.checked; state.dirty = true; });
  let scrubbingTimeline = false;
  timeline.addEventListener("pointerdown", (e) => { scrubbingTimeline = true; timeline.setPointerCapture(e.pointerId); timelineSeek(e); });
  timeline.addEventListener("pointermove", (e) => { if (scrubbingTimeline) timelineSeek(e); });
  timeline.addEventListener("pointerup", () => { scrubbingTimeline = false; });
  let drag = null;
  view.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY]; view.setPointerCapture(e.pointerId); view.classList.add("dragging"); });
  view.addEventListener("pointermove", (e) => {
    if (!drag) return;
    cam.yaw -= (e.clientX - drag[0]) * 0.008;
    cam.pitch = Math.max(-0.05, Math.min(1.45, cam.pitch + (e.clientY - drag[1]) * 0.006));
    drag = [e.clientX, e.clientY];
    state.dirty = true;
  });
  const endDrag = () => { drag = null; view.classList.remove("dragging"); };
  view.addEventListener("pointerup", endDrag);
  view.addEventListener("pointercancel", endDrag);
  view.addEventListener("wheel", (e) => {
    e.preventDefault();
    cam.dist = Math.max(1, Math.min(homeDist * 4, cam.dist * Math.exp(e.deltaY * 0.001)));
    state.dirty = true;
  }, { passive: false });
  view.addEventListener("dblclick", () => { cam.yaw = HOME.yaw; cam.pitch = HOME.pitch; cam.dist = homeDist; state.dirty = true; });
  document.addEventListener("keydown", (e) => {
    const tag = e.target && e.target.tagName;
    if (e.key === " " && tag !== "BUTTON" && tag !== "INPUT") { e.preventDefault(); state.playing ? pause() : play(); }
    else if (e.key === "ArrowRight" && tag !== "INPUT") { pause(); seek(currentFrame() + 1); }
    else if (e.key === "ArrowLeft" && tag !== "INPUT") { pause(); seek(currentFrame() - 1); }
  });
  window.addEventListener("resize", resize);

  // ---- clock ----
  function tick(ts) {
    if (state.playing) {
      const dt = lastTs == null ? 0 : Math.min(0.25, (ts - lastTs) / 1000);
      if (audioPlaying()) {
        const at = audio.currentTime;
        if (at !== lastAudioT) { lastAudioT = at; audioStall = 0; state.t = at; }
        else { state.t += dt; audioStall += dt; if (audioStall > 0.5) audioClock = false; } // no audio sink: use the wall clock
      } else {
        state.t += dt;
      }
      if (state.t >= duration) { // loop
        state.t %= duration;
        if (audio && audio.error == null) { audio.currentTime = state.t; if (audio.paused && audioClock) audio.play().catch(() => {}); }
        lastAudioT = -1;
      }
      state.dirty = true;
    }
    lastTs = ts;
    if (state.dirty) { state.dirty = false; render(); }
    requestAnimationFrame(tick);
  }

  // Test and scripting hook.
  window.__duolando = {
    get frame() { return currentFrame(); },
    get playing() { return state.playing; },
    get time() { return state.t; },
    get renders() { return state.renders; },
    frames, fps, colors: COLORS,
    leaderFrames: dancers[0].frames, followerFrames: dancers[1].frames, solo,
    tokenRows: tokens ? tokens.rows : 0, hasBeats: !!beats, hasAudio: !!audio,
    play, pause, seek,
    setVisible(name, on) {
      const d = dancers.find((x) => x.name === name);
      if (!d) throw new Error("no dancer " + name);
      d.visible = !!on;
      document.getElementById("show-" + name).checked = !!on;
      state.dirty = true;
    },
    ready: false,
  };

  resize();
  render();
  window.__duolando.ready = true;
  requestAnimationFrame(tick);
})();
