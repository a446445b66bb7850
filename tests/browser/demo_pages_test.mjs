// Headless-Chromium test of the bare demo's two pages (run by run.sh):
// `duolando dance --out DIR` writes the duet (DIR/index.html) and the solo
// dancer (DIR/solo/index.html), each linking to the other.
//
//   node demo_pages_test.mjs --dir DIR [--shot OUT.png]
//
// Checks: the duet page loads (30 fps) with a visible link in its
// header; clicking the link opens the solo page (one dancer, 60 fps, its
// audio), whose link leads back to the duet; no console errors, page
// errors, failed or non-file requests on either. Exits 1 on any failure.
import { chromium } from "playwright-core";
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join, resolve } from "node:path";
import { pathToFileURL } from "node:url";

const argv = process.argv.slice(2);
const opt = { dir: null, shot: null };
for (let i = 0; i < argv.length; i++) {
  if (argv[i] === "--dir") opt.dir = argv[++i];
  else if (argv[i] === "--shot") opt.shot = argv[++i];
  else { console.error(`unexpected argument ${argv[i]}`); process.exit(2); }
}
if (!opt.dir) { console.error("usage: node demo_pages_test.mjs --dir DIR [--shot OUT.png]"); process.exit(2); }

let failures = 0;
function check(name, ok, detail = "") {
  console.log(`${ok ? "PASS" : "FAIL"}  ${name}${detail ? "  (" + detail + ")" : ""}`);
  if (!ok) failures++;
}

const userDataDir = mkdtempSync(join(tmpdir(), "duolando-chromium-"));
const watchdog = setTimeout(() => { console.error("FAIL  timed out after 120 s"); process.exit(1); }, 120_000);
let context;
try {
  context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync"],
    viewport: { width: 1280, height: 960 },
  });
  const page = context.pages()[0] || (await context.newPage());
  const errors = [];
  page.on("console", (m) => { if (m.type() === "error") errors.push(`console: ${m.text()}`); });
  page.on("pageerror", (e) => errors.push(`page: ${e}`));
  page.on("requestfailed", (r) => errors.push(`failed: ${r.url()}`));
  page.on("request", (r) => { if (!/^(file|data|blob):/.test(r.url())) errors.push(`foreign: ${r.url()}`); });

  const state = () => page.evaluate(() => {
    const d = window.__duolando, a = document.getElementById("see-also"), box = a && a.getBoundingClientRect();
    return {
      path: location.pathname, fps: d.fps, frames: d.frames, hasAudio: d.hasAudio,
      title: document.getElementById("title").textContent,
      link: a ? { href: a.getAttribute("href"), text: a.textContent, w: box.width, h: box.height, x: box.x } : null,
    };
  });
  const ready = () => page.waitForFunction(() => window.__duolando && window.__duolando.ready, null, { timeout: 10_000 });

  await page.goto(pathToFileURL(resolve(opt.dir, "index.html")).href, { waitUntil: "load" });
  await ready();
  const duet = await state();
  console.log(`duet: ${JSON.stringify(duet)}`);
  check("the duet page plays at 30 fps", duet.fps === 30 && duet.frames > 0, `${duet.fps} fps, ${duet.frames} frames`);
  check("the duet page links to the solo dancer", duet.link && duet.link.href === "solo/index.html" && /solo/.test(duet.link.text), JSON.stringify(duet.link));
  check("the link is visible in the header", duet.link && duet.link.w > 20 && duet.link.h > 8 && duet.link.x >= 0 && duet.link.x + duet.link.w <= 1280);
  if (opt.shot) { await page.screenshot({ path: opt.shot }); console.log(`screenshot: ${opt.shot}`); }

  await Promise.all([page.waitForNavigation({ waitUntil: "load" }), page.click("#see-also")]);
  await ready();
  const solo = await state();
  console.log(`solo: ${JSON.stringify(solo)}`);
  check("the link opens the solo page", solo.path.endsWith("/solo/index.html"), solo.path);
  check("the solo page plays one dancer at 60 fps with its music", solo.fps === 60 && solo.frames > 0 && solo.hasAudio, `${solo.fps} fps, ${solo.frames} frames, audio ${solo.hasAudio}`);
  check("the solo page links back to the duet", solo.link && solo.link.href === "../index.html", JSON.stringify(solo.link));

  await Promise.all([page.waitForNavigation({ waitUntil: "load" }), page.click("#see-also")]);
  await ready();
  const back = await state();
  check("and back to the duet", back.path === duet.path, back.path);
  check("no console errors, page errors, failed or foreign requests", errors.length === 0, errors.join(" | "));
} catch (e) {
  check("ran without an exception", false, String(e && e.stack || e));
} finally {
  clearTimeout(watchdog);
  if (context) await context.close();
  rmSync(userDataDir, { recursive: true, force: true });
}
console.log(failures === 0 ? "demo pages browser test: all checks passed" : `demo pages browser test: ${failures} check(s) failed`);
process.exit(failures === 0 ? 0 : 1);
