// Headless-Chromium test of the exported follower.glb in a plain three.js
// glTF viewer (glb_view.html: GLTFLoader + AnimationMixer), run by run.sh.
//
//   node glb_test.mjs --glb DIR/follower.glb [--shot OUT.png]
//
// Serves glb_view.html, the .glb and three.js (node_modules/three) from a
// local HTTP server on 127.0.0.1 (ES modules do not load from file://) and
// checks: the file loads with one animation and two skinned meshes
// (leader, follower); the rendered canvas shows both mannequins (pixels in
// the dancer colours); two renders at different animation times differ; the
// follower's bones move; and the skinned mesh follows its bones (a vertex
// keeps its distance to the bone it is bound to). Exits 1 on any failure.
import { chromium } from "playwright-core";
import { createServer } from "node:http";
import { existsSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { dirname, join, normalize, resolve } from "node:path";
import { fileURLToPath } from "node:url";

const argv = process.argv.slice(2);
let glbPath = null, shot = null;
for (let i = 0; i < argv.length; i++) {
  if (argv[i] === "--glb") glbPath = argv[++i];
  else if (argv[i] === "--shot") shot = argv[++i];
  else { console.error(`unexpected argument ${argv[i]}`); process.exit(2); }
}
if (!glbPath) { console.error("usage: node glb_test.mjs --glb DIR/follower.glb"); process.exit(2); }

const LIMITS = {
  minDancerPixels: 300,   // each mannequin covers at least this many pixels of its colour
  maxCoverFraction: 0.5,  // the figures do not flood the view
  minChangedPixels: 300,  // renders 2 s apart differ in at least this many non-background pixels
  minBoneMoveM: 0.05,     // the follower's pelvis and a wrist move at least this far
  maxSkinDriftM: 1e-3,    // a rigidly skinned vertex keeps its distance to its bone
};

const here = dirname(fileURLToPath(import.meta.url));
const threeRoot = join(here, "node_modules", "three");
const routes = new Map([["/glb_view.html", join(here, "glb_view.html")], ["/follower.glb", resolve(glbPath)]]);
const types = { ".html": "text/html", ".js": "text/javascript", ".glb": "model/gltf-binary" };
const server = createServer((req, res) => {
  const path = decodeURIComponent(new URL(req.url, "http://x").pathname);
  if (path === "/favicon.ico") { res.writeHead(204); res.end(); return; }
  let file = routes.get(path);
  if (!file && path.startsWith("/three/")) {
    const rel = normalize(path.slice("/three/".length));
    if (!rel.startsWith("..") && (rel.startsWith("build/") || rel.startsWith("examples/jsm/"))) file = join(threeRoot, rel);
  }
  if (!file || !existsSync(file)) { res.writeHead(404); res.end(); return; }
  const ext = file.slice(file.lastIndexOf("."));
  res.writeHead(200, { "content-type": types[ext] || "application/octet-stream" });
  res.end(readFileSync(file));
});
await new Promise((r) => server.listen(0, "127.0.0.1", r));
const origin = `http://127.0.0.1:${server.address().port}`;

let failures = 0;
function check(name, ok, detail = "") {
  console.log(`${ok ? "PASS" : "FAIL"}  ${name}${detail ? "  (" + detail + ")" : ""}`);
  if (!ok) failures++;
}
const dist = (a, b) => Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);

const userDataDir = mkdtempSync(join(tmpdir(), "duolando-chromium-glb-"));
let context;
const watchdog = setTimeout(() => { console.error("FAIL  timed out after 180 s"); process.exit(1); }, 180_000);
try {
  context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    // WebGL without a GPU: ANGLE on SwiftShader (software).
    args: ["--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-quic",
      "--no-first-run", "--disable-background-networking", "--disable-component-update", "--disable-sync"],
    viewport: { width: 800, height: 600 },
    deviceScaleFactor: 1,
  });
  const page = context.pages()[0] || (await context.newPage());
  const consoleErrors = [], pageErrors = [], failedRequests = [], foreignRequests = [];
  page.on("console", (m) => { if (m.type() === "error") consoleErrors.push(m.text()); });
  page.on("pageerror", (e) => pageErrors.push(String(e)));
  page.on("requestfailed", (r) => failedRequests.push(`${r.url()} ${r.failure() && r.failure().errorText}`));
  page.on("request", (r) => { if (!r.url().startsWith(origin + "/") && !/^(data|blob):/.test(r.url())) foreignRequests.push(r.url()); });

  await page.goto(`${origin}/glb_view.html?glb=follower.glb`, { waitUntil: "load" });
  await page.waitForFunction(() => window.__glb && window.__glb.ready, null, { timeout: 60_000 });
  const info = await page.evaluate(() => ({ error: window.__glb.error, duration: window.__glb.duration, animations: window.__glb.animations, skinned: window.__glb.skinnedMeshes }));
  check("GLTFLoader loads follower.glb", info.error == null, info.error || "");
  check("one animation with a duration", info.animations === 1 && info.duration > 1, `${info.animations} animation(s), ${info.duration} s`);
  const meshes = info.skinned || [];
  const follower = meshes.find((m) => m.name.startsWith("follower")), leader = meshes.find((m) => m.name.startsWith("leader"));
  check("two skinned meshes (leader, follower) with 55 bones each", meshes.length === 2 && follower && leader && meshes.every((m) => m.bones === 55 && m.vertices > 100),
    JSON.stringify(meshes));

  const t0 = Math.min(1.0, info.duration / 4), t1 = Math.min(t0 + 2.0, info.duration);
  const a = await page.evaluate((t) => window.__glb.render(t), t0);
  const shotA = await page.screenshot();
  if (shot) writeFileSync(shot, shotA);
  const b = await page.evaluate((t) => window.__glb.render(t), t1);
  const shotB = await page.screenshot();
  for (const [t, s] of [[t0, a], [t1, b]]) {
    check(`renders both mannequins at t=${t.toFixed(2)} s`, s.orange >= LIMITS.minDancerPixels && s.blue >= LIMITS.minDancerPixels && s.fraction <= LIMITS.maxCoverFraction,
      `follower (orange) ${s.orange} px, leader (blue) ${s.blue} px, non-background ${s.other} px (${(100 * s.fraction).toFixed(1)} %)`);
  }
  // The two renders differ: compare the canvas pixels in the page.
  const changed = await page.evaluate(([ta, tb]) => {
    const grab = (t) => { window.__glb.render(t); const c = document.querySelector("canvas"); const gl = c.getContext("webgl2") || c.getContext("webgl");
      const px = new Uint8Array(c.width * c.height * 4); gl.readPixels(0, 0, c.width, c.height, gl.RGBA, gl.UNSIGNED_BYTE, px); return px; };
    const pa = grab(ta), pb = grab(tb);
    let n = 0;
    for (let i = 0; i < pa.length; i += 4) if (Math.abs(pa[i] - pb[i]) + Math.abs(pa[i + 1] - pb[i + 1]) + Math.abs(pa[i + 2] - pb[i + 2]) > 24) n++;
    return n;
  }, [t0, t1]);
  check("renders at two animation times differ (it moves)", changed >= LIMITS.minChangedPixels && !shotA.equals(shotB), `${changed} pixels changed`);

  for (const bone of ["follower_pelvis", "follower_right_wrist"]) {
    const [p0, p1] = await page.evaluate(([ta, tb, n]) => [window.__glb.bone(ta, n), window.__glb.bone(tb, n)], [t0, t1, bone]);
    check(`${bone} moves`, p0 && p1 && dist(p0, p1) >= LIMITS.minBoneMoveM, p0 && p1 ? `${dist(p0, p1).toFixed(3)} m` : "bone not found");
  }
  // Rigid skinning: a vertex keeps its distance to its bone at every time.
  if (follower) {
    const drift = await page.evaluate(([name, times]) => {
      let worst = 0, checked = 0;
      for (let i = 0; i < window.__glb.skinnedMeshes.find((m) => m.name === name).vertices; i += 97) {
        const bind = window.__glb.binding(name, i);
        const d = times.map((t) => { const v = window.__glb.vertex(t, name, i), b = window.__glb.bone(t, bind.bone);
          return Math.hypot(v[0] - b[0], v[1] - b[1], v[2] - b[2]); });
        worst = Math.max(worst, Math.max(...d) - Math.min(...d));
        checked++;
      }
      return { worst, checked };
    }, [follower.name, [t0, t1, info.duration * 0.8]]);
    check("the follower's mesh follows its bones (rigid skin)", drift.checked > 10 && drift.worst <= LIMITS.maxSkinDriftM, `${drift.checked} vertices, worst drift ${drift.worst.toExponential(2)} m`);
  }
  check("no console errors", consoleErrors.length === 0, consoleErrors.join(" | "));
  check("no page errors", pageErrors.length === 0, pageErrors.join(" | "));
  check("no failed requests", failedRequests.length === 0, failedRequests.join(" | "));
  check("no requests outside the local server", foreignRequests.length === 0, foreignRequests.join(" | "));
} catch (e) {
  check("test ran to the end", false, e && e.stack ? e.stack : String(e));
} finally {
  clearTimeout(watchdog);
  if (context) await context.close().catch(() => {});
  server.close();
  rmSync(userDataDir, { recursive: true, force: true });
}
console.log(failures === 0 ? "glb browser test: all checks passed" : `glb browser test: ${failures} check(s) failed`);
process.exit(failures === 0 ? 0 : 1);
