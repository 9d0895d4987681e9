// Drives `splat view`'s page in headless Chromium (playwright-core): waits for the first frame,
// writes a screenshot of it with the camera the page rendered it from, drags to orbit and
// waits for the frame of the new camera. Prints a JSON line of what it saw.
// node view.mjs URL OUT_DIR  (CHROMIUM: the browser, default /usr/bin/chromium)
import { chromium } from "playwright-core";
import { writeFileSync } from "node:fs";

const [url, out] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
  args: ["--no-sandbox", "--disable-gpu"],
});
try {
  const page = await browser.newPage({ viewport: { width: 320, height: 240 }, deviceScaleFactor: 1 });
  await page.goto(url);
  const framesAtLeast = (n) => page.waitForFunction((n) => Number(document.body.dataset.frames ?? 0) >= n, n, { timeout: 30000 });
  await framesAtLeast(1);
  // The still camera's frame: wait until no camera is in flight any more.
  await page.waitForTimeout(500);
  const first = await page.textContent("#camera");
  const frames = Number(await page.evaluate(() => document.body.dataset.frames));
  writeFileSync(`${out}/camera.json`, first);
  // The frame alone, without the panel over it.
  await page.evaluate(() => { document.getElementById("panel").style.display = "none"; });
  await page.locator("#frame").screenshot({ path: `${out}/frame.png` });
  // A drag orbits: the camera changes and a frame of it arrives.
  await page.mouse.move(100, 200);
  await page.mouse.down();
  await page.mouse.move(160, 210, { steps: 5 });
  await page.mouse.up();
  await framesAtLeast(frames + 1);
  await page.waitForTimeout(500);
  const moved = await page.textContent("#camera");
  console.log(JSON.stringify({ frames, moved: moved !== first, stats: await page.textContent("#stats") }));
} finally {
  await browser.close();
}
