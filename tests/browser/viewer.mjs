// The viewer (`/view/{id}`) in a real browser: Debian's Chromium, headless, with WebGPU on the
// SwiftShader Vulkan device Chromium ships (the flags below; Chromium does not take Mesa's
// lavapipe here), behind a path prefix. Waits for `data-state="complete"` (every tree in and
// that frame drawn), saves the canvas, times a few frames, shift-drags the light across the
// canvas and saves the frame after. With `--cut-trees N` the proxy cuts the first N tree
// responses mid-body (a dropped link): the viewer must ask for those chunks again and still
// complete. With `--webgpu no` Chromium starts without the flags that give it WebGPU: the page
// must find no adapter and draw on its CPU path.
//
//   node viewer.mjs --url http://127.0.0.1:PORT --id ID --width W --height H --mode vertex|pixel
//                   --out DIR [--chromium /usr/bin/chromium] [--cut-trees N] [--drag no]
//                   [--webgpu no]
//
// Writes DIR/web.png and DIR/web-moved.png; prints one JSON line with what it saw (graphics
// path, time to first frame, ms per frame, bytes fetched); exits non-zero on any failure.
// client/cli/tests/browser_viewer.rs compares the PNGs with `bspvt render`.

import { writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { open, parseArgs } from './proxy.mjs';

const args = parseArgs(process.argv.slice(2), ['url', 'id', 'width', 'height', 'mode', 'out']);
// WebGPU on Chromium's own SwiftShader (Vulkan on the CPU): the canvas presents through
// ANGLE on the same Vulkan device. Without these the adapter is missing or the device is lost
// at the first present (seen here).
const WEBGPU_FLAGS = [
  '--enable-unsafe-webgpu',
  '--enable-features=Vulkan',
  '--use-vulkan=swiftshader',
  '--use-angle=vulkan',
  '--enable-unsafe-swiftshader',
];

function fail(msg) {
  throw new Error(msg);
}

const { proxy, base, browser } = await open(args.url, args.chromium, args.webgpu === 'no' ? [] : WEBGPU_FLAGS, {
  cutTrees: Number(args['cut-trees'] ?? 0),
});
const problems = [];
try {
  const page = await browser.newPage({ viewport: { width: Number(args.width) + 80, height: Number(args.height) + 400 } });
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('response', (r) => {
    if (r.status() >= 400) problems.push(`${r.status()} for ${r.url()}`);
  });
  const t0 = Date.now();
  const url = `${base}view/${args.id}?width=${args.width}&height=${args.height}&mode=${args.mode}&bench=3`;
  const response = await page.goto(url);
  if (!response.headers()['content-security-policy']) fail('the viewer page has no CSP header');
  const state = () => page.evaluate(() => ({ ...document.documentElement.dataset }));
  await page
    .waitForFunction(() => ['complete', 'error', 'unsupported'].includes(document.documentElement.dataset.state), null, {
      timeout: 240_000,
    })
    .catch(async () => fail(`no complete frame after 240 s: ${JSON.stringify(await state())}`));
  const seen = await state();
  seen.page_ms = Date.now() - t0;
  if (seen.state !== 'complete') fail(`viewer: ${seen.state}: ${await page.textContent('#message')}`);
  await page.waitForFunction(() => document.documentElement.dataset.benchMs !== undefined, null, { timeout: 120_000 });
  seen.bench_ms = Number(await page.evaluate(() => document.documentElement.dataset.benchMs));
  const canvasPng = async (name) => {
    const data = await page.evaluate(() => document.getElementById('frame').toDataURL('image/png'));
    writeFileSync(join(args.out, name), Buffer.from(data.split(',')[1], 'base64'));
  };
  await canvasPng('web.png');

  // Shift-drag from the canvas's centre 40 % of its width to the right: the light moves
  // (`--drag no`: a scene whose lamps have no region to move in).
  if (args.drag !== 'no') {
    const box = await (await page.$('#frame')).boundingBox();
    const frames = Number(await page.evaluate(() => document.documentElement.dataset.frames));
    const [x, y] = [box.x + box.width / 2, box.y + box.height / 2];
    await page.keyboard.down('Shift');
    await page.mouse.move(x, y);
    await page.mouse.down();
    await page.mouse.move(x + box.width * 0.4, y, { steps: 4 });
    await page.mouse.up();
    await page.keyboard.up('Shift');
    await page.waitForFunction(
      (f) => Number(document.documentElement.dataset.frames) > f && document.documentElement.dataset.drawing !== 'true',
      frames,
      { timeout: 60_000 },
    );
    // The last frame of the drag, once nothing more is to be drawn.
    await page.waitForFunction(() => document.documentElement.dataset.idle === 'true', null, { timeout: 60_000 });
    await canvasPng('web-moved.png');
    seen.light_offset = await page.evaluate(() => document.documentElement.dataset.lightOffset);
  }
  if (problems.length) fail(problems.join('\n'));
  seen.cut_tree_responses = proxy.faults.cut;
  seen.browser = browser.version();
  console.log(JSON.stringify(seen));
} finally {
  await browser.close();
  proxy.close();
}
