// The dashboard in a real browser (Debian's Chromium, headless, driven by playwright-core):
// served behind a path prefix by a small reverse proxy, as a deployment would; a mesh and its
// material library dropped on the page; the scene followed to `done` on the page; the row's
// figures against the API's; deletion; no console error or policy violation on the way.
//
//   node dashboard.mjs --url http://127.0.0.1:PORT --mesh A.obj [--file A.mtl] --out DIR
//                      [--key KEY] [--chromium /usr/bin/chromium]
//
// Prints one JSON line with what it saw; exits non-zero with a message on any failure.
// server/tests/browser_dashboard.rs starts the server and runs this.

import { readFileSync } from 'node:fs';
import { basename, join } from 'node:path';
import { open, parseArgs } from './proxy.mjs';

const args = parseArgs(process.argv.slice(2), ['url', 'mesh', 'out']);

function fail(msg) {
  throw new Error(msg);
}

const { proxy, base, browser } = await open(args.url, args.chromium, ['--disable-gpu']);
const problems = [];
const seen = {};
try {
  const page = await browser.newPage({ viewport: { width: 1100, height: 520 } });
  page.on('console', (m) => {
    // Chromium logs every 4xx answer as a console error; those are checked by status above.
    if (m.type() === 'error' && !m.text().startsWith('Failed to load resource')) {
      problems.push(`console: ${m.text()}`);
    }
  });
  page.on('response', (r) => {
    // 401 is the listing's answer before the key is entered.
    if (r.status() >= 400 && r.status() !== 401) problems.push(`${r.status()} for ${r.url()}`);
  });
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('requestfailed', (r) => {
    // An event stream closed by the page after its last event is not a failure.
    if (!r.url().endsWith('/events')) problems.push(`request failed: ${r.url()} ${r.failure()?.errorText}`);
  });

  const t0 = Date.now();
  const response = await page.goto(base);
  seen.csp = response.headers()['content-security-policy'] ?? fail('the page has no CSP header');
  await page.waitForSelector('html[data-ready="true"]', { timeout: 20_000 });
  seen.ready_ms = Date.now() - t0;

  if (args.key) {
    // Without the key the listing is refused and the page says so.
    await page.waitForFunction(() => document.getElementById('list-msg').textContent.includes('API key'));
    await page.fill('#api-key', args.key);
    await page.dispatchEvent('#api-key', 'change');
    const stored = await page.evaluate(() => sessionStorage.getItem('bspvt.apiKey'));
    if (stored !== args.key) fail('the key is not kept in sessionStorage');
    if (page.url().includes(args.key)) fail('the key shows in the URL');
  }

  // Drop the mesh and its companions on the page, as files dragged from a file manager.
  const files = [args.mesh, ...args.file].map((p) => ({
    name: basename(p),
    b64: readFileSync(p).toString('base64'),
  }));
  await page.evaluate((files) => {
    const dt = new DataTransfer();
    for (const f of files) {
      const bytes = Uint8Array.from(atob(f.b64), (c) => c.charCodeAt(0));
      dt.items.add(new File([bytes], f.name));
    }
    for (const type of ['dragover', 'drop']) {
      window.dispatchEvent(new DragEvent(type, { dataTransfer: dt, bubbles: true, cancelable: true }));
    }
  }, files);
  await page.waitForFunction(() => /Submitted as [0-9a-f]{32}/.test(document.getElementById('submit-msg').textContent), null, {
    timeout: 30_000,
  });
  const msg = await page.textContent('#submit-msg');
  const id = msg.match(/[0-9a-f]{32}/)[0];
  seen.id = id;

  // The row follows the bake through the event stream until it is done.
  const row = `tr[data-id="${id}"]`;
  const states = new Set();
  const t1 = Date.now();
  for (;;) {
    const s = await page.getAttribute(row, 'data-state').catch(() => null);
    if (s) states.add(s);
    if (s === 'done') break;
    if (s === 'failed' || s === 'cancelled') fail(`the scene ended ${s}: ${await page.textContent(row)}`);
    if (Date.now() - t1 > 240_000) fail(`not done after 240 s (states seen: ${[...states]})`);
    await page.waitForTimeout(100);
  }
  seen.states = [...states];
  seen.bake_ms = Date.now() - t1;
  // The row's figures are the API's.
  const api = await (await fetch(`${args.url}/v1/scenes/${id}`)).json();
  const cells = await page.$$eval(`${row} td`, (tds) => tds.map((td) => td.textContent.trim()));
  seen.row = cells;
  if (!cells[2].startsWith('100 %')) fail(`progress cell: ${cells[2]}`);
  if (cells[3] !== api.vertices_total.toLocaleString('en')) fail(`vertices ${cells[3]} vs ${api.vertices_total}`);
  if (!cells[4].match(/\d/)) fail(`stored bytes cell: ${cells[4]}`);
  seen.warnings = api.warnings.length;
  if (api.warnings.length && !cells[1].includes(`${api.warnings.length} warning`)) {
    fail(`the API has ${api.warnings.length} warnings, the row says ${cells[1]}`);
  }
  // The row offers the viewer, under the same prefix.
  const view = await page.getAttribute(`${row} a.view`, 'href');
  if (view !== `${base}view/${id}`) fail(`the row's viewer link is ${view}, not ${base}view/${id}`);
  await page.screenshot({ path: join(args.out, 'dashboard.png') });

  // A bad drop is refused on the page, with a reason, and nothing is sent.
  await page.evaluate(() => {
    const dt = new DataTransfer();
    dt.items.add(new File(['hello'], 'notes.txt'));
    window.dispatchEvent(new DragEvent('drop', { dataTransfer: dt, bubbles: true, cancelable: true }));
  });
  await page.waitForFunction(() => document.getElementById('submit-msg').textContent.startsWith('no mesh'));

  // Delete: two clicks, then the row turns into the tombstone.
  await page.click(`${row} button.delete`);
  await page.click(`${row} button.delete`);
  await page.waitForSelector(`${row}[data-state="cancelled"]`, { timeout: 10_000 });
  const after = await (await fetch(`${args.url}/v1/scenes/${id}`)).json();
  if (after.state !== 'cancelled') fail(`after delete the API says ${after.state}`);

  // Nothing outside the prefix was asked for (every URL of the page is relative).
  if (problems.length) fail(problems.join('\n'));
  seen.browser = browser.version();
  console.log(JSON.stringify(seen));
} finally {
  await browser.close();
  proxy.close();
}
