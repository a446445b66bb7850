// Headless-Chromium test of the live page of `duolando live` (run by run.sh).
//
//   node live_test.mjs --bin PATH/duolando [--shot OUT.png] [-- extra live flags]
//
// Starts `duolando live --port 0` (paced, 30 fps) with a short latency
// budget, reads the URL it prints, opens the page in Debian's chromium through
// playwright-core and checks, while the frames arrive: events come in order;
// the follower appears and, on PIXELS of screenshots of the canvas, moves
// between two moments; the overlay shows the latency (frames and ms, equal to
// the session's) and the step time as numbers; the page reports the end of the
// clip, and the server then exits 0 by itself. No console errors, page errors,
// failed requests, or requests to anything but the page's own server.
// Exits 1 on any failure.
import { chromium } from "playwright-core";
import { spawn } from "node:child_process";
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { inflateSync } from "node:zlib";

// ---- arguments ----
const argv = process.argv.slice(2);
const opt = { bin: null, shot: null, extra: [] };
for (let i = 0; i < argv.length; i++) {
  const a = argv[i];
  if (a === "--bin") opt.bin = argv[++i];
  else if (a === "--shot") opt.shot = argv[++i];
  else if (a === "--") { opt.extra = argv.slice(i + 1); break; }
  else { console.error(`unexpected argument ${a}`); process.exit(2); }
}
if (!opt.bin) { console.error("usage: node live_test.mjs --bin PATH/duolando [--shot OUT.png] [-- extra live flags]"); process.exit(2); }

// ---- named limits ----
const FRAMES = 300;          // leader frames streamed (10 s at 30 fps)
const LATENCY = 31;          // frames: --lookahead 4 --enc-future 2 --dec-future 2
const LIMITS = {
  colourDistance: 40,        // RGB distance counted as "a dancer colour"
  minDancerPixels: 300,      // a drawn skeleton covers at least this many pixels
  minChangedPixels: 150,     // follower-coloured pixels that differ between two screenshots 1 s apart
  minFollowerFrames: 30,     // follower frames received before the first screenshot
  minAdvance: 10,            // follower frames that arrive between the two screenshots (about 30 expected)
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
// Mask of the pixels within LIMITS.colourDistance of a colour.
function colourMask(png, hex) {
  const [tr, tg, tb] = hexRgb(hex), d2max = LIMITS.colourDistance ** 2;
  const mask = new Uint8Array(png.width * png.height);
  let count = 0;
  for (let k = 0; k < mask.length; k++) {
    const i = k * png.bpp, r = png.data[i], g = png.data[i + 1], b = png.data[i + 2];
    if ((r - tr) ** 2 + (g - tg) ** 2 + (b - tb) ** 2 <= d2max) { mask[k] = 1; count++; }
  }
  return { mask, count };
}

// ---- checks ----
let failures = 0;
function check(name, ok, detail = "") {
  console.log(`${ok ? "PASS" : "FAIL"}  ${name}${detail ? "  (" + detail + ")" : ""}`);
  if (!ok) failures++;
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// ---- the server ----
const args = ["live", "--port", "0", "--frames", String(FRAMES), "--lookahead", "4", "--enc-future", "2", "--dec-future", "2",
  "--linger", "60", "--wait", ...opt.extra];
console.log(`starting ${opt.bin} ${args.join(" ")}`);
const server = spawn(opt.bin, args, { stdio: ["ignore", "pipe", "pipe"] });
let serverErr = "", serverOut = "";
server.stderr.on("data", (d) => { serverErr += d; });
const exited = new Promise((res) => server.on("exit", (code, signal) => res({ code, signal })));
const url = await new Promise((res, rej) => {
  const t = setTimeout(() => rej(new Error("no URL on stdout within 120 s; stderr:\n" + serverErr)), 120_000);
  server.stdout.on("data", (d) => {
    serverOut += d;
    const m = serverOut.match(/^(http:\/\/127\.0\.0\.1:\d+\/)\n/);
    if (m) { clearTimeout(t); res(m[1]); }
  });
  server.on("exit", () => { clearTimeout(t); rej(new Error("duolando live exited early:\n" + serverErr)); });
}).catch((e) => { check("duolando live prints its URL", false, String(e)); process.exit(1); });
check("duolando live prints a 127.0.0.1 URL", /^http:\/\/127\.0\.0\.1:\d+\/$/.test(url), url);
const origin = new URL(url).origin;

const userDataDir = mkdtempSync(join(tmpdir(), "duolando-chromium-"));
const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
let context;
const watchdog = setTimeout(() => { console.error("FAIL  timed out after 240 s"); server.kill(); process.exit(1); }, 240_000);
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
  page.on("requestfailed", (r) => {
    // The event stream is closed by the page itself after the end event.
    if (!r.url().endsWith("/events")) failedRequests.push(`${r.url()} ${r.failure() && r.failure().errorText}`);
  });
  page.on("request", (r) => { if (!r.url().startsWith(origin + "/") && !/^(data|blob):/.test(r.url())) foreignRequests.push(r.url()); });

  await page.goto(url, { waitUntil: "load" });
  await page.waitForFunction(() => window.__duolandoLive && window.__duolandoLive.ready, null, { timeout: 10_000 });
  // One snapshot of the state and the overlay, taken in an animation frame
  // right after the page's own (which redraws the overlay from the state):
  // read between two frames, an event that arrived after the last redraw
  // makes the overlay look stale (a race of the test, not of the page).
  const live = () => page.evaluate(() => new Promise((resolve) => requestAnimationFrame(() => {
    const d = window.__duolandoLive;
    const t = (id) => document.getElementById(id).textContent;
    resolve({
      status: d.status, events: d.events, drainEvents: d.drainEvents, outOfOrder: d.outOfOrder, leaderFrame: d.leaderFrame, followerFrame: d.followerFrame,
      latencyFrames: d.latencyFrames, hello: d.hello, end: d.end,
      overlay: { latencyFrames: t("live-latency-frames"), latencyMs: t("live-latency-ms"), latencyWall: t("live-latency-wall"),
        stepMs: t("live-step-ms"), stepMean: t("live-step-mean"), stepMax: t("live-step-max"), leader: t("live-leader"), follower: t("live-follower") },
    });
  })));

  // The follower appears (after the latency) while the clip streams.
  await page.waitForFunction((n) => window.__duolandoLive.followerFrame >= n, LIMITS.minFollowerFrames, { timeout: 60_000 });
  const s1 = await live();
  check("hello received: frames and latency", s1.hello && s1.hello.frames === FRAMES && s1.hello.latency_frames === LATENCY && s1.hello.paced === true,
    s1.hello ? `frames ${s1.hello.frames}, latency ${s1.hello.latency_frames}, paced ${s1.hello.paced}` : "no hello");
  check("still streaming when the follower is checked (the page sees frames arrive)", !s1.end && s1.leaderFrame < FRAMES - 1, `leader frame ${s1.leaderFrame}`);
  check("the follower trails the leader", s1.followerFrame >= LIMITS.minFollowerFrames && s1.leaderFrame - s1.followerFrame >= LATENCY - 3 && s1.leaderFrame - s1.followerFrame <= LATENCY,
    `leader ${s1.leaderFrame}, follower ${s1.followerFrame}`);

  // Overlay: numbers for the latency (frames, ms) and the step time.
  const n = (s) => (/^-?\d+(\.\d+)?$/.test(s) ? Number(s) : NaN);
  const o = s1.overlay;
  check("overlay: latency in frames is the session's", n(o.latencyFrames) === s1.latencyFrames && n(o.latencyFrames) >= LATENCY - 3 && n(o.latencyFrames) <= LATENCY,
    `"${o.latencyFrames}"`);
  check("overlay: latency in ms = frames / 30 fps", Math.abs(n(o.latencyMs) - n(o.latencyFrames) * 1000 / 30) <= 1, `"${o.latencyMs}" ms for ${o.latencyFrames} frames`);
  check("overlay: measured latency is a number of ms near it", n(o.latencyWall) >= n(o.latencyMs) * 0.5 && n(o.latencyWall) <= n(o.latencyMs) + 2000, `"${o.latencyWall}"`);
  check("overlay: step time is a positive number of ms", n(o.stepMs) > 0 && n(o.stepMs) < 10_000 && n(o.stepMean) > 0 && n(o.stepMax) >= n(o.stepMean),
    `step "${o.stepMs}", mean "${o.stepMean}", max "${o.stepMax}"`);
  check("overlay: frame counters match the page's state", n(o.leader) === s1.leaderFrame && n(o.follower) === s1.followerFrame, `${o.leader} / ${o.follower}`);

  // Pixels: the follower figure is drawn and moves while frames arrive.
  const view = page.locator("#view");
  const shoot = async () => decodePng(await view.screenshot({ type: "png" }));
  const colors = await page.evaluate(() => window.__duolandoLive.colors);
  const shotA = await shoot();
  const fA = (await live()).followerFrame;
  await sleep(1000);
  const shotB = await shoot();
  const fB = (await live()).followerFrame;
  const a = colourMask(shotA, colors.follower), b = colourMask(shotB, colors.follower);
  const la = colourMask(shotA, colors.leader);
  let changed = 0;
  for (let k = 0; k < a.mask.length; k++) if (a.mask[k] !== b.mask[k]) changed++;
  check(`follower drawn in ${colors.follower}`, a.count >= LIMITS.minDancerPixels && b.count >= LIMITS.minDancerPixels, `${a.count} px, ${b.count} px`);
  check(`leader drawn in ${colors.leader}`, la.count >= LIMITS.minDancerPixels, `${la.count} px`);
  check("follower frames keep arriving (about 30 a second)", fB - fA >= LIMITS.minAdvance, `follower frame ${fA} -> ${fB} in 1 s`);
  check("the follower figure moves on screen", changed >= LIMITS.minChangedPixels, `${changed} follower pixels changed between frames ${fA} and ${fB}`);
  if (opt.shot) {
    const hb = await page.locator("header").boundingBox(), mb = await page.locator("main").boundingBox();
    await page.screenshot({ path: opt.shot, clip: { x: mb.x, y: hb.y, width: mb.width, height: mb.y + mb.height - hb.y } });
    console.log(`screenshot: ${opt.shot}`);
  }
  // Hiding the follower removes its colour (the pixels above are the follower's).
  await page.click("#show-follower");
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  const hidden = colourMask(await shoot(), colors.follower);
  check("hiding the follower removes its colour", hidden.count <= 25, `${hidden.count} px`);
  await page.click("#show-follower");

  // The end of the clip: every frame in order, the end event, the server exits 0.
  await page.waitForFunction(() => window.__duolandoLive.end != null, null, { timeout: 60_000 });
  const s2 = await live();
  check("every event arrived, in order (hello, a frame per leader frame, a drain per drained frame, end)",
    s2.outOfOrder === 0 && s2.events === FRAMES + 2 + s2.drainEvents && s2.drainEvents === s2.end.drained_frames && s2.leaderFrame === FRAMES - 1,
    `events ${s2.events}, drain events ${s2.drainEvents}, out of order ${s2.outOfOrder}`);
  check("end: follower frames as the session gave them, the drain included", s2.end.follower_frames === s2.followerFrame + 1 && s2.end.drained_frames > 0
    && s2.end.follower_frames >= FRAMES - LATENCY - 4 + s2.end.drained_frames, `${s2.end.follower_frames} follower frames (${s2.end.drained_frames} drained), last index ${s2.followerFrame}`);
  check("the page says the clip ended", /^clip ended/.test(s2.status), s2.status);
  const ex = await Promise.race([exited, sleep(30_000).then(() => null)]);
  check("duolando live exits 0 once the page has everything", ex && ex.code === 0, ex ? `code ${ex.code} signal ${ex.signal}` : "still running after 30 s");
  console.log(`info  engine: ${s2.end.late_ticks} late ticks, step mean ${s2.end.step_ms.mean} ms, max ${s2.end.step_ms.max} ms`);

  check("no console errors", consoleErrors.length === 0, consoleErrors.join(" | "));
  check("no page errors", pageErrors.length === 0, pageErrors.join(" | "));
  check("no failed requests", failedRequests.length === 0, failedRequests.join(" | "));
  check("no requests but the page's own server", foreignRequests.length === 0, foreignRequests.join(" | "));
} catch (e) {
  check("test ran to the end", false, e && e.stack ? e.stack : String(e));
} finally {
  clearTimeout(watchdog);
  if (context) await context.close().catch(() => {});
  rmSync(userDataDir, { recursive: true, force: true });
  if (server.exitCode == null) server.kill();
}
if (failures) console.log("server stderr:\n" + serverErr);
console.log(failures === 0 ? "live browser test: all checks passed" : `live browser test: ${failures} check(s) failed`);
process.exit(failures === 0 ? 0 : 1);
