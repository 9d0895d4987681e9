// Plays a video in headless Chromium (playwright-core) from a page beside it: writes its first
// frame as a PNG (drawn from the <video> element on a canvas), then plays it to the end and
// prints a JSON line: duration, whether it ended, how many frames Chromium decoded.
// node video.mjs VIDEO.mp4 OUT_DIR  (CHROMIUM: the browser, default /usr/bin/chromium)
import { chromium } from "playwright-core";
import { writeFileSync } from "node:fs";
import { basename, dirname, resolve } from "node:path";

const [video, out] = process.argv.slice(2);
const page_file = resolve(dirname(video), "play.html");
writeFileSync(page_file, `<!doctype html><video id="v" muted playsinline src="${basename(video)}"></video>`);
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
  args: ["--no-sandbox", "--disable-gpu", "--autoplay-policy=no-user-gesture-required", "--allow-file-access-from-files"],
});
try {
  const page = await browser.newPage();
  await page.goto(`file://${page_file}`);
  // A video that never loads or ends fails the test in two minutes, rather than hanging it.
  let timer;
  const late = new Promise((_, fail) => {
    timer = setTimeout(() => fail(new Error("the video did not play to its end in 120 s")), 120_000);
  });
  const seen = await Promise.race([late, page.evaluate(async () => {
    const v = document.getElementById("v");
    if (v.readyState < 2) {
      await new Promise((ok, fail) => { v.onloadeddata = ok; v.onerror = () => fail(new Error(`cannot play: ${v.error?.message}`)); });
    }
    // The first frame, as the browser decoded it, once it is on screen. One already on screen
    // at time 0 is not presented again (no callback comes): wait a second at most.
    const presentedFirst = new Promise((ok) => v.requestVideoFrameCallback(ok));
    v.currentTime = 0;
    await Promise.race([presentedFirst, new Promise((ok) => setTimeout(ok, 1000))]);
    const canvas = document.createElement("canvas");
    canvas.width = v.videoWidth; canvas.height = v.videoHeight;
    canvas.getContext("2d").drawImage(v, 0, 0);
    const first = canvas.toDataURL("image/png");
    // Count every frame presented while it plays to the end, slowly enough that none is dropped.
    let presented = 0;
    const count = (_, meta) => { presented = meta.presentedFrames; v.requestVideoFrameCallback(count); };
    v.requestVideoFrameCallback(count);
    v.playbackRate = 0.5;
    const ended = new Promise((ok) => { v.onended = ok; });
    await v.play();
    await ended;
    const quality = v.getVideoPlaybackQuality();
    return { width: v.videoWidth, height: v.videoHeight, duration: v.duration, ended: v.ended,
             decoded: quality.totalVideoFrames, dropped: quality.droppedVideoFrames, presented, first };
  })]).finally(() => clearTimeout(timer));
  writeFileSync(`${out}/first.png`, Buffer.from(seen.first.split(",")[1], "base64"));
  delete seen.first;
  console.log(JSON.stringify(seen));
} finally {
  await browser.close();
}
