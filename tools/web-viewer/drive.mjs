// Test driver: opens a served nasset web export in headless Chromium (Debian's /usr/bin/chromium, never a
// downloaded browser), sets a fixed camera and light, waits for the refinement to finish and writes what the
// page shows.
//
//   node drive.mjs JOB.json
//
// JOB.json: {"url": "http://127.0.0.1:P/?size=N", "camera": {"eye": [..], "target": [..], "fovDeg": f},
//            "settings": {"light": [..], "irradiance": E, "ambient": 0, ...}, "out": "result.json",
//            "screenshot": "shot.png" (optional), "repeat": K (optional: K more full renders, timed),
//            "extraArgs": [more Chromium flags] (optional),
//            "queries": true (optional: also the graph queries of the last unjittered pass),
//            "canvas": true (optional: also the displayed canvas pixels, RGBA 8-bit)}
// result.json: {"error": message or null, "linear": {width, height, rgb, mask}, "stats": {...}, "frameMs": [..]}
import { chromium } from "playwright-core";
import { mkdtempSync, readFileSync, renameSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { dirname, join, resolve } from "node:path";

const jobPath = resolve(process.argv[2] ?? "");
const job = JSON.parse(readFileSync(jobPath, "utf8"));
const base = dirname(jobPath);
const FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--enable-unsafe-swiftshader"];
const profile = mkdtempSync(join(tmpdir(), "nasset-chromium-"));
const ctx = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.NASSET_CHROMIUM ?? "/usr/bin/chromium", headless: true, args: [...FLAGS, ...(job.extraArgs ?? [])],
  viewport: { width: 1000, height: 800 },
});
const result = { error: null, console: [] };
try {
  const page = await ctx.newPage();
  page.on("console", (m) => result.console.push(`${m.type()}: ${m.text()}`));
  page.on("pageerror", (e) => result.console.push(`pageerror: ${e.message}`));
  await page.goto(job.url);
  await page.waitForFunction(() => window.nassetViewer && (window.nassetViewer.error || window.nassetViewer.viewer), null,
                             { timeout: (job.timeoutS ?? 120) * 1000 });
  result.error = await page.evaluate(() => window.nassetViewer.error);
  result.message = await page.evaluate(() => document.getElementById("message").textContent);
  if (!result.error) {
    result.frameMs = await page.evaluate(async ({ camera, settings, repeat }) => {
      const v = window.nassetViewer;
      await v.idle();
      if (camera) v.setCamera(camera);
      if (settings) v.set(settings);
      const times = [];
      const t0 = performance.now();
      await v.idle();
      times.push(performance.now() - t0);
      for (let k = 0; k < (repeat ?? 0); k++) {
        v.viewer.restart();
        const t = performance.now();
        await v.idle();
        times.push(performance.now() - t);
      }
      return times;
    }, { camera: job.camera, settings: job.settings, repeat: job.repeat });
    result.stats = await page.evaluate(() => ({ ...window.nassetViewer.viewer.stats, samples: window.nassetViewer.viewer.samples }));
    result.linear = await page.evaluate(() => window.nassetViewer.linear());
    if (job.canvas) { // the displayed 8-bit pixels (what the user sees), rows top-down
      result.canvas = await page.evaluate(() => {
        const src = document.getElementById("canvas"), c = document.createElement("canvas");
        c.width = src.width;
        c.height = src.height;
        const ctx = c.getContext("2d");
        ctx.drawImage(src, 0, 0);
        return { width: c.width, height: c.height, rgba: Array.from(ctx.getImageData(0, 0, c.width, c.height).data) };
      });
    }
    if (job.queries) result.queries = await page.evaluate(() => window.nassetViewer.queries());
  }
  if (job.screenshot) await page.screenshot({ path: resolve(base, job.screenshot) });
} catch (e) {
  result.error = `driver: ${e.message}`;
} finally {
  await ctx.close();
  rmSync(profile, { recursive: true, force: true });
}
const out = resolve(base, job.out ?? "result.json");
writeFileSync(`${out}.tmp-${process.pid}`, JSON.stringify(result));
renameSync(`${out}.tmp-${process.pid}`, out);
