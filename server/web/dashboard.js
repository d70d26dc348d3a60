// The service's dashboard (docs/service.md, "Dashboard"): the scenes newest first with their
// live bake progress, submission by dropping files, deletion. It reads and writes through the
// public API only, at URLs relative to this module, so it works behind a path prefix.

import { classify, droppedFiles, pickedFiles, submit } from './upload.js';

const root = new URL('../', import.meta.url);
const api = (path) => new URL(path, root).href;
const KEY = 'bspvt.apiKey';
const TERMINAL = new Set(['done', 'failed', 'cancelled']);
// Live event streams at once: each holds one of the browser's ~6 connections to the host.
const MAX_STREAMS = 3;
const REFRESH_MS = 3000;

const $ = (id) => document.getElementById(id);
const rows = new Map(); // id → {tr, cells, status, stream, detailed}
let olderCursor = null;

function authHeaders() {
  const k = sessionStorage.getItem(KEY);
  return k ? { Authorization: `Bearer ${k}` } : {};
}

async function call(method, path) {
  const r = await fetch(api(path), { method, headers: authHeaders(), cache: 'no-store' });
  const body = await r.json().catch(() => null);
  if (!r.ok) {
    const e = new Error(body?.detail ?? `${r.status} ${r.statusText}`);
    e.status = r.status;
    throw e;
  }
  return body;
}

function say(el, text, isError = false) {
  el.textContent = text;
  el.classList.toggle('error', isError);
}

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'class') e.className = v;
    else e.setAttribute(k, v);
  }
  e.append(...children);
  return e;
}

function bytes(n) {
  if (n == null) return '';
  const units = ['B', 'KiB', 'MiB', 'GiB'];
  let i = 0;
  while (n >= 1024 && i < units.length - 1) {
    n /= 1024;
    i += 1;
  }
  return `${n.toFixed(i === 0 ? 0 : 1)} ${units[i]}`;
}

// ---- rows

function rowFor(id) {
  let row = rows.get(id);
  if (row) return row;
  const cells = {
    scene: el('td'),
    state: el('td'),
    progress: el('td'),
    vertices: el('td', { class: 'num' }),
    stored: el('td', { class: 'num' }),
    created: el('td', { class: 'date' }),
    actions: el('td'),
  };
  const tr = el('tr', { 'data-id': id }, ...Object.values(cells));
  const del = el('button', { type: 'button', class: 'delete' }, 'delete');
  let armed = null;
  del.addEventListener('click', async () => {
    // Two clicks, no modal dialog: the first arms the button for three seconds.
    if (!armed) {
      del.textContent = 'really delete?';
      armed = setTimeout(() => {
        armed = null;
        del.textContent = 'delete';
      }, 3000);
      return;
    }
    clearTimeout(armed);
    armed = null;
    del.disabled = true;
    try {
      update(await call('DELETE', `v1/scenes/${id}`));
    } catch (e) {
      say($('list-msg'), `delete ${id}: ${e.message}`, true);
    } finally {
      del.disabled = false;
      del.textContent = 'delete';
    }
  });
  cells.actions.append(del);
  row = { tr, cells, status: null, stream: null, detailed: false };
  rows.set(id, row);
  return row;
}

/** Shows a status document or a listing item (which lacks sizes and warnings). */
function update(incoming) {
  const row = rowFor(incoming.id);
  row.status = { ...row.status, ...incoming };
  const s = row.status;
  const c = row.cells;
  row.tr.dataset.state = s.state;
  c.scene.replaceChildren(
    el('span', { class: 'id', title: s.id }, s.id.slice(0, 12)),
    el('br'),
    el('span', { class: 'source' }, s.source ?? ''),
  );
  c.state.replaceChildren(el('span', { class: `state-${s.state}` }, s.state));
  if (s.reason) c.state.append(el('div', { class: 'reason' }, s.reason));
  if (s.warnings?.length) {
    const list = el('ul', {}, ...s.warnings.map((w) => el('li', {}, w)));
    const n = s.warnings.length;
    c.state.append(
      el('details', { class: 'warnings' }, el('summary', {}, `${n} warning${n > 1 ? 's' : ''}`), list),
    );
  }
  // A listing item has chunk counts but no `progress`: never show an older status' fraction.
  const frac =
    'progress' in incoming ? incoming.progress : s.chunks_total ? s.chunks_done / s.chunks_total : 0;
  const bar = el('progress', { max: '1', value: String(frac) });
  let text = `${Math.round(frac * 100)} %`;
  if (s.chunks_total) text += ` · ${s.chunks_done}/${s.chunks_total} chunks`;
  if (s.state === 'baking' && s.eta_s != null) text += ` · ${Math.ceil(s.eta_s)} s left`;
  if (s.state === 'queued' && s.queue_position != null) text += ` · ${s.queue_position} ahead`;
  c.progress.replaceChildren(bar, el('div', { class: 'progress-text' }, text));
  c.vertices.textContent = (s.vertices_total ?? 0).toLocaleString('en');
  c.stored.textContent = s.sizes ? bytes(s.sizes.stored_bytes) : '';
  c.stored.title = s.sizes ? `uploaded ${bytes(s.sizes.upload_bytes)}` : '';
  // The viewer streams while the bake runs: offered as soon as the scene can be read.
  const viewable = s.state === 'done' || s.state === 'baking' || s.state === 'queued';
  const link = c.actions.querySelector('a.view');
  if (viewable && !link) {
    c.actions.prepend(el('a', { class: 'view', href: api(`view/${s.id}`) }, 'view'), ' ');
  } else if (!viewable && link) {
    link.remove();
  }
  c.created.textContent = s.created_ms
    ? new Date(s.created_ms).toLocaleString(undefined, { dateStyle: 'short', timeStyle: 'short' })
    : '';
  if (TERMINAL.has(s.state) && row.stream) {
    row.stream.close();
    row.stream = null;
  }
}

/** Puts the rows in listing order (newest first), the table's only order. */
function place(ids) {
  $('scenes').tBodies[0].prepend(...ids.map((id) => rowFor(id).tr));
}

/** Live updates: event streams for the newest unfinished scenes, full status for the rest once. */
function follow() {
  let open = [...rows.values()].filter((r) => r.stream).length;
  for (const [id, row] of rows) {
    const s = row.status;
    if (!s) continue;
    if (!TERMINAL.has(s.state) && !row.stream && open < MAX_STREAMS) {
      const es = new EventSource(api(`v1/scenes/${id}/events`));
      es.addEventListener('status', (e) => {
        row.detailed = true;
        update(JSON.parse(e.data));
      });
      // The stream ends after a terminal state; otherwise the browser reconnects by itself.
      row.stream = es;
      open += 1;
    } else if (!row.detailed && (TERMINAL.has(s.state) || open >= MAX_STREAMS)) {
      row.detailed = true;
      call('GET', `v1/scenes/${id}`)
        .then(update)
        .catch(() => {
          row.detailed = false;
        });
    }
  }
}

// ---- listing

async function refresh() {
  try {
    const page = await call('GET', 'v1/scenes?limit=50');
    for (const s of page.scenes) update(s);
    place(page.scenes.map((s) => s.id));
    if (olderCursor === null) olderCursor = page.next_cursor;
    $('more').hidden = !olderCursor;
    say($('list-msg'), rows.size ? '' : 'No scenes yet: drop a mesh above.');
    follow();
  } catch (e) {
    const hint = e.status === 401 ? ' Enter the API key above.' : '';
    say($('list-msg'), `Cannot list the scenes: ${e.message}.${hint}`, true);
  }
}

async function older() {
  if (!olderCursor) return;
  try {
    const page = await call('GET', `v1/scenes?limit=50&after=${encodeURIComponent(olderCursor)}`);
    const body = $('scenes').tBodies[0];
    for (const s of page.scenes) {
      update(s);
      body.append(rowFor(s.id).tr);
    }
    olderCursor = page.next_cursor;
    $('more').hidden = !olderCursor;
    follow();
  } catch (e) {
    say($('list-msg'), `Cannot list older scenes: ${e.message}`, true);
  }
}

// ---- submitting

async function send(files) {
  const msg = $('submit-msg');
  const form = classify(files);
  if (form.error) {
    say(msg, form.error, true);
    return;
  }
  const parts = [form.mesh, form.scene].filter(Boolean).map((f) => f.path.split('/').pop());
  if (form.others.length) parts.push(`${form.others.length} more file${form.others.length > 1 ? 's' : ''}`);
  say(msg, `Uploading ${parts.join(' + ')}…`);
  $('upload').hidden = false;
  const bar = $('upload-bar');
  const text = $('upload-text');
  try {
    const r = await submit(api('v1/scenes'), form, authHeaders(), (sent, total) => {
      bar.value = total ? sent / total : 0;
      text.textContent = total ? `${bytes(sent)} of ${bytes(total)}` : bytes(sent);
    });
    if (r.status === 202 || r.status === 200) {
      const skipped = form.skipped.length ? ` (left out, same name twice: ${form.skipped.join(', ')})` : '';
      say(msg, `Submitted as ${r.body.id}: ${r.body.state}${skipped}.`);
      update({ ...r.body, source: parts.join(' + ') });
      await refresh();
    } else {
      const hint = r.status === 401 ? ' Enter the API key above.' : '';
      say(msg, `Refused (${r.status} ${r.body?.error ?? ''}): ${r.body?.detail ?? ''}${hint}`, true);
    }
  } catch (e) {
    say(msg, e.message, true);
  } finally {
    $('upload').hidden = true;
  }
}

function wireDrop() {
  const zone = $('drop');
  // The whole window takes the drop, so a near miss does not open the file in the tab.
  window.addEventListener('dragover', (e) => {
    e.preventDefault();
    zone.classList.add('over');
  });
  window.addEventListener('dragleave', (e) => {
    if (e.relatedTarget === null) zone.classList.remove('over');
  });
  window.addEventListener('drop', async (e) => {
    e.preventDefault();
    zone.classList.remove('over');
    await send(await droppedFiles(e.dataTransfer));
  });
  for (const id of ['pick-files', 'pick-folder']) {
    const input = $(id);
    input.addEventListener('change', async () => {
      const files = pickedFiles(input);
      input.value = '';
      if (files.length) await send(files);
    });
  }
}

function wireKey() {
  const input = $('api-key');
  input.value = sessionStorage.getItem(KEY) ?? '';
  input.addEventListener('change', () => {
    const k = input.value.trim();
    if (k) sessionStorage.setItem(KEY, k);
    else sessionStorage.removeItem(KEY);
    refresh();
  });
  $('key-form').addEventListener('submit', (e) => e.preventDefault());
  $('key-forget').addEventListener('click', () => {
    sessionStorage.removeItem(KEY);
    input.value = '';
    refresh();
  });
}

wireKey();
wireDrop();
$('more-button').addEventListener('click', older);
await refresh();
setInterval(refresh, REFRESH_MS);
document.documentElement.dataset.ready = 'true';
