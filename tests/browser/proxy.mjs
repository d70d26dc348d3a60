// What both browser scripts share: a reverse proxy that serves a service under a path prefix
// (and nothing else), streaming both ways, as a deployment behind nginx or a gateway would;
// Chromium started headless; the scripts' arguments.

import http from 'node:http';
import { chromium as launcher } from 'playwright-core';

export const PREFIX = '/bspvt/';

/**
 * Listens on a free loopback port; resolves to the server (`.address().port`). `faults.cutTrees`:
 * the first that many tree-stream responses (`…/trees?…`) are cut mid-body — their first bytes
 * sent, then the connection reset, as a dropped link does; `server.faults.cut` counts them.
 */
export function prefixProxy(upstream, faults = {}) {
  const up = new URL(upstream);
  let toCut = faults.cutTrees ?? 0;
  const stats = { cut: 0 };
  const server = http.createServer((req, res) => {
    if (!req.url.startsWith(PREFIX)) {
      res.writeHead(404).end('outside the prefix');
      return;
    }
    const p = http.request(
      {
        host: up.hostname,
        port: up.port,
        method: req.method,
        path: `/${req.url.slice(PREFIX.length)}`,
        headers: req.headers,
      },
      (r) => {
        res.writeHead(r.statusCode, r.headers);
        if (toCut > 0 && r.statusCode === 200 && /\/trees\?/.test(req.url)) {
          toCut -= 1;
          stats.cut += 1;
          r.once('data', (d) => {
            res.write(d.subarray(0, Math.min(d.length, 256)));
            res.destroy();
            r.destroy();
          });
          return;
        }
        r.pipe(res);
      },
    );
    p.on('error', (e) => {
      if (!res.headersSent) res.writeHead(502).end(String(e));
    });
    req.pipe(p);
  });
  server.faults = stats;
  return new Promise((ok) => server.listen(0, '127.0.0.1', () => ok(server)));
}

/** `--key value` pairs; `--file` may repeat. */
export function parseArgs(argv, required) {
  const out = { file: [] };
  for (let i = 0; i < argv.length; i += 2) {
    const k = argv[i].replace(/^--/, '');
    const v = argv[i + 1];
    if (v === undefined) throw new Error(`--${k} needs a value`);
    if (k === 'file') out.file.push(v);
    else out[k] = v;
  }
  for (const need of required) {
    if (!out[need]) throw new Error(`--${need} is required`);
  }
  return out;
}

/** Flags every headless run needs on this closed network. */
const BASE_FLAGS = [
  '--no-sandbox',
  '--disable-background-networking',
  '--disable-component-update',
  '--no-first-run',
  '--disable-sync',
];

/**
 * Debian's Chromium (`chromium`: its path), headless with `flags`, on a fresh profile of
 * playwright-core's own (deleted at close); the proxy that serves `url` under PREFIX (with
 * `faults`, see prefixProxy); and the page's base URL through it.
 */
export async function open(url, chromium, flags, faults = {}) {
  const proxy = await prefixProxy(url, faults);
  const base = `http://127.0.0.1:${proxy.address().port}${PREFIX}`;
  const browser = await launcher.launch({
    executablePath: chromium ?? '/usr/bin/chromium',
    headless: true,
    args: [...BASE_FLAGS, ...flags],
  });
  return { proxy, base, browser };
}
