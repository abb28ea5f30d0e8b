// Opens an HTML file in headless Chromium and prints, as JSON, the console
// errors, page errors and failed requests it saw and every image's decoded
// size; writes a screenshot of the first figure's image to SHOT.
// Usage: node check-page.mjs PAGE.html SHOT.png   (CHROMIUM overrides /usr/bin/chromium)
import path from "node:path";
import { chromium } from "playwright-core";

const [page_file, shot] = process.argv.slice(2);
if (!page_file || !shot) {
  console.error("usage: node check-page.mjs PAGE.html SHOT.png");
  process.exit(2);
}
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--no-sandbox"],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  const problems = [];
  page.on("console", (m) => { if (m.type() === "error") problems.push(`console: ${m.text()}`); });
  page.on("pageerror", (e) => problems.push(`page error: ${e}`));
  page.on("requestfailed", (r) => problems.push(`request failed: ${r.url().slice(0, 80)}`));
  await page.goto("file://" + path.resolve(page_file), { waitUntil: "load" });
  const images = await page.$$eval("img", (all) =>
    all.map((i) => ({ alt: i.alt, width: i.naturalWidth, height: i.naturalHeight, complete: i.complete })));
  const first = await page.$("figure img");
  if (first) {
    await first.scrollIntoViewIfNeeded();
    await first.screenshot({ path: shot });
  }
  const headings = await page.$$eval("h2", (all) => all.map((h) => h.textContent));
  console.log(JSON.stringify({ problems, images, headings }));
} finally {
  await browser.close();
}
