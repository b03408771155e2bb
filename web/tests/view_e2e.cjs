// End-to-end test of the viewer page (`fewview view`), driven by crates/cli/tests/view_e2e.rs.
// Environment: VIEW_URL (server base URL), VIEW_OUT (folder for the pictures and result.json),
// VIEW_MODE:
//   run      the page of a trained run: not blank, camera CAMERA (default 0) rendered exactly
//            at its resolution (camera.png), a drag orbits and changes the picture
//            (before.png, after.png), the lists of cameras, metrics, renders and videos filled;
//   surface  the same for a surface run's mesh and cameras, plus the cameras' groups and a
//            screenshot of the whole page (page.png);
//   broken   the model stream ends early: the page shows a one-line error;
//   timing   time to the first picture and to the whole model (a large PLY), and the time of a
//            redraw after an orbit.
// Headless Chromium has no GPU here: WebGL2 runs on SwiftShader. Needs playwright-core
// (scripts/setup.sh installs it into .cache/browser; run with NODE_PATH pointing there).
"use strict";
const fs = require("fs");
const os = require("os");
const path = require("path");
const { chromium } = require("playwright-core");

const base = process.env.VIEW_URL;
const out = process.env.VIEW_OUT;
const mode = process.env.VIEW_MODE || "run";
const cameraIndex = Number(process.env.CAMERA || "0");

function check(cond, message) {
  if (!cond) throw new Error(message);
}

function savePng(dataUrl, name) {
  const file = path.join(out, name);
  fs.writeFileSync(file, Buffer.from(dataUrl.split(",")[1], "base64"));
  return file;
}

// Mean absolute difference (0–255) of two PNG data URLs, and the fraction of pixels of `a`
// that differ from `background` (0–1 RGB) by more than 2/255.
async function compare(page, a, b, background) {
  return page.evaluate(async ([a, b, bg]) => {
    const load = (url) => new Promise((resolve, reject) => {
      const img = new Image();
      img.onload = () => {
        const c = document.createElement("canvas");
        c.width = img.width; c.height = img.height;
        const ctx = c.getContext("2d");
        ctx.drawImage(img, 0, 0);
        resolve(ctx.getImageData(0, 0, img.width, img.height).data);
      };
      img.onerror = reject;
      img.src = url;
    });
    const pa = await load(a);
    const pb = b ? await load(b) : pa;
    let diff = 0, lit = 0;
    for (let i = 0; i < pa.length; i += 4) {
      let off = 0;
      for (let k = 0; k < 3; k++) {
        diff += Math.abs(pa[i + k] - pb[i + k]);
        off = Math.max(off, Math.abs(pa[i + k] - 255 * bg[k]));
      }
      if (off > 2) lit++;
    }
    return { meanDiff: diff / (pa.length / 4 * 3), litFraction: lit / (pa.length / 4) };
  }, [a, b, background]);
}

async function main() {
  const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), "fewview-view-"));
  const context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    viewport: { width: 1100, height: 800 },
    args: ["--headless", "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
      "--ignore-gpu-blocklist", "--disable-quic", "--no-first-run", "--disable-background-networking",
      "--disable-component-update", "--disable-sync"],
  });
  const page = context.pages()[0] || (await context.newPage());
  const consoleErrors = [];
  page.on("pageerror", (e) => consoleErrors.push(String(e)));
  const result = { mode };
  try {
    const t0 = Date.now();
    await page.goto(base + "/");
    if (mode === "broken") {
      await page.waitForSelector("#error:not([hidden])", { timeout: 60000 });
      result.error = (await page.textContent("#error")).trim();
      check(!result.error.includes("\n"), `error is not one line: ${result.error}`);
      return;
    }
    await page.waitForFunction(() => window.fewviewView && window.fewviewView.stats.firstPicture !== null, null, { timeout: 120000 });
    result.firstPictureMs = await page.evaluate(() => window.fewviewView.stats.firstPicture);
    await page.waitForFunction(() => window.fewviewView.stats.fullPicture !== null, null, { timeout: 240000 });
    const stats = await page.evaluate(() => ({ ...window.fewviewView.stats }));
    result.firstPictureMs = stats.firstPicture;
    result.fullPictureMs = stats.fullPicture;
    result.loadedMs = stats.loadedAt;
    result.firstPictureScale = stats.firstPictureScale;
    result.firstPictureGaussians = stats.firstPictureGaussians;
    result.timeline = stats.timeline;
    result.stages = { parseMs: stats.parseMs, uploadMs: stats.uploadMs, sortMs: stats.sortMs, sorts: stats.sorts };
    result.frames = stats.frames;
    result.wallMs = Date.now() - t0;
    const shown = await page.$eval("#error", (e) => (e.hidden ? "" : e.textContent));
    check(!shown, `the page shows an error: ${shown}`);
    const background = await page.evaluate(() => window.fewviewView.background);
    // The interactive canvas, then an orbit by dragging on it.
    const canvas = await page.$("#canvas");
    const box = await canvas.boundingBox();
    const before = await page.evaluate(() => window.fewviewView.capture());
    result.interactive = await compare(page, before, null, background);
    savePng(before, "before.png");
    const tDrag = Date.now();
    await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
    await page.mouse.down();
    await page.mouse.move(box.x + box.width / 2 + 120, box.y + box.height / 2 + 30, { steps: 6 });
    await page.mouse.up();
    const after = await page.evaluate(() => window.fewviewView.capture());
    result.orbitRedrawMs = Date.now() - tDrag;
    savePng(after, "after.png");
    result.orbit = await compare(page, before, after, background);
    result.lastFrameMs = await page.evaluate(() => window.fewviewView.stats.lastFrameMs);
    if (mode === "timing") return;

    result.cameras = await page.$$eval("#cameras li", (ls) => ls.length);
    result.metricsRows = await page.$$eval("#metrics tr", (rs) => rs.length);
    result.images = await page.$$eval("#images figure img", (is) => is.length);
    result.videos = await page.$$eval("#videos video, #videos img", (vs) => vs.length);
    // Clicking a camera in the list looks through it.
    await page.click("#cameras li:nth-child(2)");
    result.selected = await page.$eval("#cameras li.selected", (l) => l.dataset.index);
    const url = await page.evaluate((i) => window.fewviewView.renderCamera(i), cameraIndex);
    result.camera = savePng(url, "camera.png");
    result.cameraStats = await compare(page, url, null, background);
    if (mode === "surface") {
      result.groups = await page.evaluate(() => window.fewviewView.cameras.map((c) => c.group));
      await page.evaluate(() => window.fewviewView.capture());
      await page.screenshot({ path: path.join(out, "page.png"), fullPage: true });
    }
  } finally {
    result.pageErrors = consoleErrors;
    fs.writeFileSync(path.join(out, "result.json"), JSON.stringify(result, null, 2));
    await context.close();
    fs.rmSync(userDataDir, { recursive: true, force: true });
  }
}

main().catch((e) => {
  console.error(e.stack || String(e));
  process.exit(1);
});
