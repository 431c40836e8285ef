// Screenshots of Lichtblick on a live `evopose view` with the shipped layout, in headless Chromium (docs/ros2.md,
// "Live view"): node screenshot.cjs 'http://127.0.0.1:PORT/?ds=foxglove-websocket&ds.url=ws://127.0.0.1:VIEWPORT&layoutUrl=URL' OUT 40
// writes OUT-full.png, OUT-panel<i>.png (one per panel) and OUT-alerts.png, and prints the panels and the page's text.
// Needs puppeteer-core (npm) and Chromium (Debian: apt-get install chromium).
const puppeteer = require("puppeteer-core");
const [url, out, waitS] = process.argv.slice(2);
(async () => {
  const browser = await puppeteer.launch({
    executablePath: "/usr/bin/chromium", headless: true,
    args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"],
  });
  const page = await browser.newPage();
  await page.setViewport({ width: 1600, height: 1000 });
  await page.goto(url, { waitUntil: "domcontentloaded", timeout: 120000 });
  await new Promise((r) => setTimeout(r, Number(waitS || 25) * 1000));
  await page.screenshot({ path: `${out}-full.png` });
  // each panel: the mosaic window that holds its title
  const boxes = await page.evaluate(() => [...document.querySelectorAll(".mosaic-window")].map((e) => {
    const r = e.getBoundingClientRect();
    return { title: e.innerText.split("\n")[0], x: r.x, y: r.y, width: r.width, height: r.height };
  }));
  console.log(JSON.stringify({ event: "panels", boxes }));
  let i = 0;
  for (const b of boxes) {
    await page.screenshot({ path: `${out}-panel${i}.png`, clip: { x: b.x, y: b.y, width: b.width, height: b.height } });
    i += 1;
  }
  // the Alerts tab of the left sidebar
  const tabs = await page.$$("button, [role=tab]");
  for (const t of tabs) {
    const label = await t.evaluate((e) => e.innerText || "");
    if (/^Alerts/.test(label.trim())) { await t.click(); break; }
  }
  await new Promise((r) => setTimeout(r, 2000));
  await page.screenshot({ path: `${out}-alerts.png` });
  const side = await page.evaluate(() => document.body.innerText.split("\n").filter((l) => l.trim()).slice(0, 60));
  console.log(JSON.stringify({ event: "text", lines: side }));
  await browser.close();
})().catch((e) => { console.error(e); process.exit(1); });
