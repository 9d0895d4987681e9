// Drives `splat view`'s page in headless Chromium (playwright-core): waits for the first frame,
// writes a screenshot of it with the camera the page rendered it from, drags to orbit and
// waits for the frame of the new camera, then turns a knob (P_max) and screenshots the frame it
// brings, then saves a camera path of two keyframes (path.json). Prints a JSON line of what it
// saw.
// node view.mjs URL OUT_DIR  (CHROMIUM: the browser, default /usr/bin/chromium)
import { chromium } from "playwright-core";
import { writeFileSync } from "node:fs";

const [url, out] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
  args: ["--no-sandbox", "--disable-gpu"],
});
try {
  const page = await browser.newPage({ viewport: { width: 640, height: 400 }, deviceScaleFactor: 1 });
  await page.goto(url);
  const frames = () => page.evaluate(() => Number(document.body.dataset.frames ?? 0));
  const framesAtLeast = (n) => page.waitForFunction((n) => Number(document.body.dataset.frames ?? 0) >= n, n, { timeout: 30000 });
  // The frame alone, without the panel over it.
  const screenshot = async (name) => {
    await page.evaluate(() => { document.getElementById("panel").style.display = "none"; });
    await page.locator("#frame").screenshot({ path: `${out}/${name}` });
    await page.evaluate(() => { document.getElementById("panel").style.display = ""; });
  };
  await framesAtLeast(1);
  // The still camera's frame: wait until no camera is in flight any more.
  await page.waitForTimeout(500);
  const first = await page.textContent("#camera");
  const seen = await frames();
  writeFileSync(`${out}/camera.json`, first);
  await screenshot("frame.png");
  // A drag orbits (right of the panel): the camera changes and a frame of it arrives.
  await page.mouse.move(500, 300);
  await page.mouse.down();
  await page.mouse.move(560, 310, { steps: 5 });
  await page.mouse.up();
  await framesAtLeast(seen + 1);
  await page.waitForTimeout(500);
  const moved = await page.textContent("#camera");
  writeFileSync(`${out}/moved.json`, moved);
  // A knob: the panel says so and the frame changes.
  const before = await frames();
  await page.fill("#p_max", "2");
  await page.dispatchEvent("#p_max", "change");
  await framesAtLeast(before + 1);
  await page.waitForTimeout(500);
  await screenshot("knob.png");
  const knobCamera = await page.textContent("#camera");
  // A camera path: two keyframes with a drag between them, saved as the page downloads it.
  await page.click("#key");
  await page.mouse.move(500, 300);
  await page.mouse.down();
  await page.mouse.move(420, 280, { steps: 5 });
  await page.mouse.up();
  await page.click("#key");
  const [download] = await Promise.all([page.waitForEvent("download"), page.click("#save")]);
  await download.saveAs(`${out}/path.json`);
  console.log(JSON.stringify({
    frames: seen,
    moved: moved !== first,
    knobSameCamera: knobCamera === moved,
    pMax: await page.inputValue("#p_max"),
    stats: await page.textContent("#stats"),
    explain: await page.textContent("#explain"),
  }));
} finally {
  await browser.close();
}
