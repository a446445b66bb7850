// Headless-Chromium test of the duolando viewer page (run by run.sh).
//
//   node viewer_test.mjs --page DIR/index.html [--frames N] [--audio] [--shot OUT.png]
//
// Loads the page from file:// in Debian's chromium through playwright-core and
// checks: no console errors, page errors, failed or non-file requests; the
// animation advances after play, stops on pause, follows the scrub bar, the
// timeline and the arrow keys; and, on PIXELS of real screenshots, that two
// skeletons in the two dancer colours are drawn, that each disappears when its
// checkbox is cleared, that they move between frames, and that dragging orbits
// the camera. Exits 1 on any failure.
import { chromium } from "playwright-core";
import { mkdtempSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join, resolve } from "node:path";
import { pathToFileURL } from "node:url";
import { inflateSync } from "node:zlib";

// ---- arguments ----
const argv = process.argv.slice(2);
const opt = { page: null, frames: null, audio: false, shot: null };
for (let i = 0; i < argv.length; i++) {
  const a = argv[i];
  if (a === "--page") opt.page = argv[++i];
  else if (a === "--frames") opt.frames = Number(argv[++i]);
  else if (a === "--audio") opt.audio = true;
  else if (a === "--shot") opt.shot = argv[++i];
  else { console.error(`unexpected argument ${a}`); process.exit(2); }
}
if (!opt.page) { console.error("usage: node viewer_test.mjs --page DIR/index.html [--frames N] [--audio] [--shot OUT.png]"); process.exit(2); }

// ---- named limits ----
const LIMITS = {
  colourDistance: 40,        // RGB distance counted as "a dancer colour"
  minDancerPixels: 400,      // each skeleton covers at least this many pixels of the view
  maxDancerFraction: 0.15,   // ... and not a flood of the whole view
  maxHiddenPixels: 25,       // a hidden dancer leaves at most this many pixels of its colour
  minAdvanceFraction: 0.5,   // frames advanced >= this share of fps * elapsed seconds
  scrubSlackFrames: 0.04,    // a click on the scrub bar lands within this share of the frames
  minMovePx: 15,             // a dancer's pixel centroid moves this far between distant frames / after an orbit drag
};

// ---- a small PNG decoder (8-bit RGB/RGBA, non-interlaced: what Chromium writes) ----
function decodePng(buf) {
  const sig = [137, 80, 78, 71, 13, 10, 26, 10];
  if (!sig.every((b, i) => buf[i] === b)) throw new Error("not a PNG");
  let pos = 8, w = 0, h = 0, depth = 0, type = 0, interlace = 0;
  const idat = [];
  while (pos < buf.length) {
    const len = buf.readUInt32BE(pos), kind = buf.toString("latin1", pos + 4, pos + 8);
    const body = buf.subarray(pos + 8, pos + 8 + len);
    if (kind === "IHDR") { w = body.readUInt32BE(0); h = body.readUInt32BE(4); depth = body[8]; type = body[9]; interlace = body[12]; }
    else if (kind === "IDAT") idat.push(body);
    else if (kind === "IEND") break;
    pos += 12 + len;
  }
  if (depth !== 8 || (type !== 2 && type !== 6) || interlace !== 0) throw new Error(`unsupported PNG: depth ${depth} type ${type} interlace ${interlace}`);
  const bpp = type === 6 ? 4 : 3, stride = w * bpp;
  const raw = inflateSync(Buffer.concat(idat));
  if (raw.length !== h * (stride + 1)) throw new Error("PNG data length mismatch");
  const out = Buffer.alloc(h * stride);
  for (let y = 0; y < h; y++) {
    const filter = raw[y * (stride + 1)], src = y * (stride + 1) + 1, row = y * stride, up = row - stride;
    for (let x = 0; x < stride; x++) {
      const a = x >= bpp ? out[row + x - bpp] : 0, b = y > 0 ? out[up + x] : 0, c = x >= bpp && y > 0 ? out[up + x - bpp] : 0;
      let v = raw[src + x];
      if (filter === 1) v += a;
      else if (filter === 2) v += b;
      else if (filter === 3) v += (a + b) >> 1;
      else if (filter === 4) { const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c); v += pa <= pb && pa <= pc ? a : pb <= pc ? b : c; }
      else if (filter !== 0) throw new Error(`bad PNG filter ${filter}`);
      out[row + x] = v & 255;
    }
  }
  return { width: w, height: h, bpp, data: out };
}

const hexRgb = (hex) => [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16));

// Pixels within LIMITS.colourDistance of each colour: count and centroid.
function colourStats(png, colours) {
  const stats = Object.fromEntries(Object.keys(colours).map((k) => [k, { count: 0, cx: 0, cy: 0 }]));
  const targets = Object.entries(colours).map(([k, hex]) => [stats[k], hexRgb(hex)]);
  const d2max = LIMITS.colourDistance ** 2;
  for (let y = 0; y < png.height; y++) {
    for (let x = 0; x < png.width; x++) {
      const i = (y * png.width + x) * png.bpp;
      const r = png.data[i], g = png.data[i + 1], b = png.data[i + 2];
      for (const [s, [tr, tg, tb]] of targets) {
        if ((r - tr) ** 2 + (g - tg) ** 2 + (b - tb) ** 2 <= d2max) { s.count++; s.cx += x; s.cy += y; }
      }
    }
  }
  for (const s of Object.values(stats)) if (s.count) { s.cx /= s.count; s.cy /= s.count; }
  return stats;
}

// ---- checks ----
let failures = 0;
function check(name, ok, detail = "") {
  console.log(`${ok ? "PASS" : "FAIL"}  ${name}${detail ? "  (" + detail + ")" : ""}`);
  if (!ok) failures++;
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

const userDataDir = mkdtempSync(join(tmpdir(), "duolando-chromium-"));
const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
let context;
const watchdog = setTimeout(() => { console.error("FAIL  timed out after 180 s"); process.exit(1); }, 180_000);
try {
  context = await chromium.launchPersistentContext(userDataDir, {
    executablePath,
    headless: true,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync"],
    viewport: { width: 1280, height: 960 },
    deviceScaleFactor: 1,
  });
  const page = context.pages()[0] || (await context.newPage());
  const consoleErrors = [], pageErrors = [], failedRequests = [], foreignRequests = [];
  page.on("console", (m) => { if (m.type() === "error") consoleErrors.push(m.text()); });
  page.on("pageerror", (e) => pageErrors.push(String(e)));
  page.on("requestfailed", (r) => failedRequests.push(`${r.url()} ${r.failure() && r.failure().errorText}`));
  page.on("request", (r) => { if (!/^(file|data|blob):/.test(r.url())) foreignRequests.push(r.url()); });

  const url = pathToFileURL(resolve(opt.page)).href;
  await page.goto(url, { waitUntil: "load" });
  await page.waitForFunction(() => window.__duolando && window.__duolando.ready, null, { timeout: 10_000 });
  const info = await page.evaluate(() => {
    const d = window.__duolando;
    return { frames: d.frames, fps: d.fps, colors: d.colors, tokenRows: d.tokenRows, hasBeats: d.hasBeats, hasAudio: d.hasAudio, frame: d.frame, playing: d.playing, title: document.getElementById("title").textContent };
  });
  console.log(`page: ${url}\n  ${info.frames} frames at ${info.fps} fps, ${info.tokenRows} token rows, beats ${info.hasBeats}, audio ${info.hasAudio}, title ${JSON.stringify(info.title)}`);
  if (opt.frames != null) check("frame count matches the fixture", info.frames === opt.frames, `${info.frames} vs ${opt.frames}`);
  check("beats and tokens are on the timeline", info.hasBeats && info.tokenRows === Math.floor(info.frames / 4), `tokenRows ${info.tokenRows}`);
  check("opens paused on frame 0", info.playing === false && info.frame === 0, `playing ${info.playing}, frame ${info.frame}`);
  check("audio element present iff the fixture wrote audio", info.hasAudio === opt.audio);
  if (opt.audio) {
    const a = await page.waitForFunction(() => { const el = document.getElementById("audio"); return (el.error || el.readyState >= 1) && { error: el.error && el.error.code, duration: el.duration }; }, null, { timeout: 10_000 }).then((h) => h.jsonValue());
    const want = info.frames / info.fps;
    check("audio file loads from the page's directory", a.error == null && Math.abs(a.duration - want) < 0.1, `error ${a.error}, duration ${a.duration} s vs ${want} s`);
  }

  // Play: the frame advances steadily.
  const state = () => page.evaluate(() => ({ frame: window.__duolando.frame, playing: window.__duolando.playing }));
  await page.click("#play");
  const t0 = Date.now();
  const samples = [];
  for (let i = 0; i < 6; i++) { await sleep(250); samples.push((await state()).frame); }
  const elapsed = (Date.now() - t0) / 1000;
  const s1 = await state();
  const monotone = samples.every((f, i) => i === 0 || f >= samples[i - 1]);
  check("play starts playback", s1.playing === true);
  check("animation advances over time", monotone && samples[samples.length - 1] >= LIMITS.minAdvanceFraction * info.fps * elapsed,
    `frames ${samples.join(",")} over ${elapsed.toFixed(2)} s`);

  // Pause: the frame stays put.
  await page.click("#play");
  const p0 = await state();
  await sleep(600);
  const p1 = await state();
  check("pause stops the animation", p0.playing === false && p1.frame === p0.frame, `frame ${p0.frame} -> ${p1.frame}`);

  // Scrub bar: a click at a fraction of its width sets the frame there.
  const bar = await page.locator("#scrub").boundingBox();
  for (const frac of [0.25, 0.75]) {
    await page.mouse.click(bar.x + bar.width * frac, bar.y + bar.height / 2);
    const f = (await state()).frame, want = frac * (info.frames - 1);
    check(`scrub at ${frac * 100}% sets the frame`, Math.abs(f - want) <= LIMITS.scrubSlackFrames * info.frames + 8, `frame ${f}, expected about ${want.toFixed(0)}`);
  }
  // Arrow key steps one frame.
  await page.evaluate(() => document.activeElement && document.activeElement.blur());
  const k0 = (await state()).frame;
  await page.keyboard.press("ArrowRight");
  const k1 = (await state()).frame;
  check("ArrowRight steps one frame", k1 === k0 + 1, `${k0} -> ${k1}`);
  // Timeline: a click halfway along the track seeks there.
  const tl = await page.locator("#timeline").boundingBox();
  const labelW = 56;
  await page.mouse.click(tl.x + labelW + (tl.width - labelW) * 0.5, tl.y + tl.height / 2);
  const tf = (await state()).frame;
  check("timeline click seeks", Math.abs(tf - info.frames / 2) <= 2, `frame ${tf}, expected about ${info.frames / 2}`);

  // Pixels: screenshots of the 3D view.
  const view = page.locator("#view");
  const shoot = async () => decodePng(await view.screenshot({ type: "png" }));
  const seek = async (f) => { await page.evaluate((f) => window.__duolando.seek(f), f); await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)))); };
  const frameA = Math.floor(info.frames * 0.1), frameB = Math.floor(info.frames * 0.5);
  await seek(frameA);
  const shotA = await shoot();
  const area = shotA.width * shotA.height;
  const a = colourStats(shotA, info.colors);
  for (const who of ["leader", "follower"]) {
    check(`${who} skeleton drawn in ${info.colors[who]}`, a[who].count >= LIMITS.minDancerPixels && a[who].count <= LIMITS.maxDancerFraction * area,
      `${a[who].count} px of ${area}`);
  }
  for (const [hide, keep] of [["follower", "leader"], ["leader", "follower"]]) {
    await page.click(`#show-${hide}`);
    await seek(frameA);
    const s = colourStats(await shoot(), info.colors);
    check(`hiding the ${hide} removes its colour and keeps the ${keep}`,
      s[hide].count <= LIMITS.maxHiddenPixels && s[keep].count >= LIMITS.minDancerPixels, `${hide} ${s[hide].count} px, ${keep} ${s[keep].count} px`);
    await page.click(`#show-${hide}`);
  }
  await seek(frameB);
  const b = colourStats(await shoot(), info.colors);
  for (const who of ["leader", "follower"]) {
    const move = Math.hypot(b[who].cx - a[who].cx, b[who].cy - a[who].cy);
    check(`${who} moves between frames ${frameA} and ${frameB}`, b[who].count >= LIMITS.minDancerPixels && move >= LIMITS.minMovePx, `centroid moved ${move.toFixed(1)} px`);
  }
  // Orbit: a horizontal drag turns the camera, so the dancers land elsewhere on screen.
  const vb = await view.boundingBox();
  await page.mouse.move(vb.x + vb.width * 0.5, vb.y + vb.height * 0.5);
  await page.mouse.down();
  await page.mouse.move(vb.x + vb.width * 0.8, vb.y + vb.height * 0.45, { steps: 8 });
  await page.mouse.up();
  await seek(frameB);
  const o = colourStats(await shoot(), info.colors);
  const orbitMove = Math.hypot(o.leader.cx - b.leader.cx, o.leader.cy - b.leader.cy);
  check("dragging orbits the camera", o.leader.count >= LIMITS.minDancerPixels && orbitMove >= LIMITS.minMovePx, `leader centroid moved ${orbitMove.toFixed(1)} px`);
  await view.dblclick();
  await seek(frameB);
  const back = colourStats(await shoot(), info.colors);
  check("double-click restores the home view", Math.abs(back.leader.count - b.leader.count) <= 0.02 * b.leader.count + 5 && Math.hypot(back.leader.cx - b.leader.cx, back.leader.cy - b.leader.cy) < 2,
    `leader ${back.leader.count} px vs ${b.leader.count} px`);

  if (opt.shot) {
    await page.click("#play");
    await sleep(1500);
    await page.click("#play");
    await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
    const hb = await page.locator("header").boundingBox(), mb = await page.locator("main").boundingBox();
    const x = Math.min(hb.x, mb.x), right = Math.max(hb.x + hb.width, mb.x + mb.width);
    await page.screenshot({ path: opt.shot, clip: { x, y: hb.y, width: right - x, height: mb.y + mb.height - hb.y } });
    console.log(`screenshot: ${opt.shot}`);
  }

  check("no console errors", consoleErrors.length === 0, consoleErrors.join(" | "));
  check("no page errors", pageErrors.length === 0, pageErrors.join(" | "));
  check("no failed requests", failedRequests.length === 0, failedRequests.join(" | "));
  check("no network requests (everything is in the page)", foreignRequests.length === 0, foreignRequests.join(" | "));
} catch (e) {
  check("test ran to the end", false, e && e.stack ? e.stack : String(e));
} finally {
  clearTimeout(watchdog);
  if (context) await context.close().catch(() => {});
  rmSync(userDataDir, { recursive: true, force: true });
}
console.log(failures === 0 ? "viewer browser test: all checks passed" : `viewer browser test: ${failures} check(s) failed`);
process.exit(failures === 0 ? 0 : 1);
