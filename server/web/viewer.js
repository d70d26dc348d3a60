// The browser viewer (docs/service.md, "Viewer"): WebGPU running the project's own WGSL (the
// shaders the native client compiles, served by the service from bspvt-shaders) on buffers the
// service builds with the native client's code (`gpu-scene`), the trees streamed as GPU words
// (`trees?format=gpu`), the camera's chunks first; vertices whose trees have not arrived are
// shaded unshadowed. Without WebGPU (or with `graphics=cpu`) the CPU path of cpu.js draws the
// same frame per vertex. Every URL is relative to this module, so it works behind a path
// prefix.

import { interpolate, shadeVertex, toneMap, vertexSides, visibilityBuffer } from './cpu.js';

const root = new URL('../', import.meta.url);
const api = (path) => new URL(path, root).href;
const $ = (id) => document.getElementById(id);
const html = document.documentElement;

const ABSENT = 0xffffffff;
const NO_TREES = 0xfffffffe;
// Tree requests at once (each holds one of the browser's ~6 connections to the host).
const PARALLEL = 3;

const query = new URLSearchParams(location.search);
const sceneId = decodeURIComponent(location.pathname.split('/').filter(Boolean).pop() ?? '');

function say(text, isError = false) {
  $('message').textContent = text;
  $('message').classList.toggle('error', isError);
}

function fail(text) {
  say(text, true);
  html.dataset.state = 'error';
}

/** Bytes that came over the wire for `url` (compressed), by the Resource Timing entry. */
function transferred(url, fallback) {
  const e = performance.getEntriesByName(url).at(-1);
  return e && e.transferSize > 0 ? e.transferSize : fallback;
}

function bytes(n) {
  if (n < 1024) return `${n} B`;
  if (n < 1024 * 1024) return `${(n / 1024).toFixed(1)} KiB`;
  return `${(n / 1024 / 1024).toFixed(2)} MiB`;
}

async function errorOf(r) {
  const body = await r.json().catch(() => null);
  return `${r.status} ${body?.error ?? r.statusText}: ${body?.detail ?? ''}`;
}

// ---- vectors (f64, as the native View computes them)

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
function normalizeOr(a, fallback) {
  const l = Math.hypot(...a);
  return l > 0 && Number.isFinite(l) ? scale(a, 1 / l) : fallback;
}

/** client/src/frame/camera.rs `View::new`. */
function makeView(eye, target, up, fovDeg, width, height) {
  const forward = normalizeOr(sub(target, eye), [0, 0, -1]);
  const right = normalizeOr(cross(forward, up), [1, 0, 0]);
  return {
    eye,
    forward,
    right,
    up: cross(right, forward),
    tanHalf: Math.tan(0.5 * (fovDeg * Math.PI) / 180),
    width,
    height,
  };
}

/** client/src/gpu/frame.rs `view_proj`: reversed infinite Z, near = 1e-4 of the diagonal. */
function viewProj(v, diagonal) {
  const { right: r, up: u, forward: f, eye: e } = v;
  const look = [r[0], u[0], -f[0], 0, r[1], u[1], -f[1], 0, r[2], u[2], -f[2], 0, -dot(r, e), -dot(u, e), dot(f, e), 1];
  const aspect = v.width / v.height;
  const fy = 1 / v.tanHalf;
  const near = 1e-4 * Math.max(diagonal, 1e-12);
  const proj = [fy / aspect, 0, 0, 0, 0, fy, 0, 0, 0, 0, 0, -1, 0, 0, near, 0];
  const out = new Float32Array(16);
  for (let c = 0; c < 4; c++) {
    for (let rr = 0; rr < 4; rr++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += proj[k * 4 + rr] * look[c * 4 + k];
      out[c * 4 + rr] = s;
    }
  }
  return out;
}

// ---- the scene

async function fetchScene() {
  const url = api(`v1/scenes/${sceneId}/gpu-scene`);
  const r = await fetch(url);
  if (!r.ok) throw new Error(`the scene: ${await errorOf(r)}`);
  const buf = await r.arrayBuffer();
  const dv = new DataView(buf);
  if (buf.byteLength < 8 || new TextDecoder().decode(new Uint8Array(buf, 0, 4)) !== 'BVGS') {
    throw new Error('the scene bundle does not start with BVGS');
  }
  const len = dv.getUint32(4, true);
  const doc = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 8, len)));
  const base = 8 + len;
  doc.sectionBytes = {};
  for (const [name, [offset, size]] of Object.entries(doc.sections)) {
    doc.sectionBytes[name] = new Uint8Array(buf, base + offset, size);
  }
  doc.decoded = buf.byteLength;
  doc.fetched = transferred(url, buf.byteLength);
  return doc;
}

async function fetchShader(name) {
  const r = await fetch(api(`ui/wgsl/${name}`));
  if (!r.ok) throw new Error(`shader ${name}: ${await errorOf(r)}`);
  return r.text();
}

// ---- the viewer

/**
 * What both graphics paths share: the scene bundle, the camera and the lights as the user
 * moved them, and the trees streamed in (the camera's chunks first). A path takes the trees'
 * words through `putLineNormals`, `putNodes` and `putRoots`.
 */
class Frames {
  constructor(doc, size) {
    this.doc = doc;
    this.n = doc.vertices;
    this.width = size.width;
    this.height = size.height;
    this.method = query.get('method') === 'ltc' ? 'ltc' : 'bspvt';
    this.mode = query.get('mode') === 'pixel' ? 'pixel' : 'vertex';
    this.exposure = Number(query.get('exposure') ?? '1') || 1;
    // Every lamp is drawn (one shading pass each, added up); the one picked is dragged.
    this.lightIndex = 0;
    this.lightOffsets = doc.lights.map(() => [0, 0, 0]);
    this.fetched = doc.fetched;
    this.decoded = doc.decoded;
    this.treesIn = 0;
    this.chunksIn = 0;
    this.chunkCount = Math.ceil(this.n / doc.chunk_vertices);
    this.codec = null;
    this.nodeLen = 0;
    this.dirty = true;
    const b = doc.bounds;
    this.diagonal = Math.hypot(...sub(b.max, b.min));
    const cam = doc.camera;
    this.camera = { eye: cam.position, target: cam.target, up: cam.up, fov: cam.fov_y_deg };
    // The vertex records (16 floats a vertex). A normal-mapped scene (`frames` holds more than
    // one zero vec4: per vertex its unbent normal and tangent) has them bent as seen from the
    // side its normals face; `vertexRecords` turns them to the viewer's side.
    const vb = doc.sectionBytes.verts;
    this.baseRecords = new Float32Array(vb.buffer, vb.byteOffset, vb.byteLength / 4);
    const fb = doc.sectionBytes.frames;
    this.tangentFrames = fb && fb.byteLength > 16 ? new Float32Array(fb.buffer, fb.byteOffset, fb.byteLength / 4) : null;
    this.records = this.tangentFrames ? this.baseRecords.slice() : this.baseRecords;
    this.recordsEye = null;
    this.setView();
  }

  /**
   * The vertex records for the current eye, and whether they changed since the last call.
   * Where normal maps bend the normals, a vertex seen from behind has its frame turned over
   * and a bent normal is kept facing the viewer (Renderer::vertex_surface, NormalMaps::facing:
   * n′ ← normalize(n′ + (ε − n′·ω_o) ω_o) below n′·ω_o = ε = 0.02).
   */
  vertexRecords() {
    const eye = this.view.eye;
    if (!this.tangentFrames || (this.recordsEye && eye.every((x, i) => x === this.recordsEye[i]))) {
      return { records: this.records, changed: false };
    }
    this.recordsEye = [...eye];
    const B = this.baseRecords;
    const F = this.tangentFrames;
    const R = this.records;
    const EPS = 0.02;
    for (let v = 0; v < this.n; v++) {
      const p = [B[16 * v], B[16 * v + 1], B[16 * v + 2]];
      const n = normalizeOr([F[8 * v], F[8 * v + 1], F[8 * v + 2]], [0, 1, 0]);
      const front = [B[16 * v + 4], B[16 * v + 5], B[16 * v + 6]];
      const wo = normalizeOr(sub(eye, p), n);
      const side = dot(n, wo) < 0 ? -1 : 1;
      let bent = scale(front, side);
      const d = dot(bent, wo);
      if (d < EPS && side * dot(n, wo) > EPS) bent = normalizeOr(add(bent, scale(wo, EPS - d)), scale(n, side));
      // Stored on the mesh's side: shade.wgsl turns it over for a vertex seen from behind
      // (sides.wgsl; records::seen_from_behind).
      R.set(scale(bent, side), 16 * v + 4);
    }
    return { records: R, changed: true };
  }

  setView() {
    const c = this.camera;
    this.view = makeView(c.eye, c.target, c.up, c.fov, this.width, this.height);
    this.dirty = true;
  }

  /**
   * `LightRecord` of bspvt_shaders::gpu::lights for light k, as the service built it, moved by
   * the offset the user dragged it by (a polygon's corners, a sphere's centre; a sun stays):
   * 40 words, and the count the shaders take (0: none).
   */
  lightRecord(k) {
    const words = new Float32Array(40);
    const l = this.doc.lights[k];
    if (!l) return { words, count: 0 };
    words.set(l.record.flat());
    const o = this.lightOffsets[k];
    const moving = l.kind === 'polygon' ? l.count : l.kind === 'sphere' ? 1 : 0;
    for (let i = 0; i < moving; i++) for (let a = 0; a < 3; a++) words[8 + 4 * i + a] += o[a];
    const finite = words.every(Number.isFinite);
    return { words, count: finite ? l.count : 0 };
  }

  // ---- trees

  /** The `format=gpu` header: codec and line normals (server/src/service/stream.rs). */
  takeHeader(buf, at) {
    const dv = new DataView(buf);
    if (new TextDecoder().decode(new Uint8Array(buf, at, 4)) !== 'BVGT') throw new Error('tree stream: no BVGT header');
    const angles = dv.getUint32(at + 20, true);
    const end = at + 28 + angles * 8;
    if (!this.codec) {
      this.codec = { offsets: dv.getUint32(at + 16, true), halfStep: dv.getFloat32(at + 24, true) };
      this.putLineNormals(new Uint8Array(buf, at + 28, angles * 8).slice());
    }
    return end;
  }

  /** One `BVGC` chunk: its nodes appended, its vertices' roots pointed at them. */
  takeChunk(buf, at) {
    const dv = new DataView(buf);
    if (new TextDecoder().decode(new Uint8Array(buf, at, 4)) !== 'BVGC') throw new Error('tree stream: no BVGC chunk');
    const first = dv.getUint32(at + 4, true);
    const count = dv.getUint32(at + 8, true);
    const nodes = dv.getUint32(at + 12, true);
    const roots = new Uint32Array(buf, at + 16, count * 6).slice();
    const words = new Uint32Array(buf, at + 16 + count * 24, nodes * 2).slice();
    for (let i = 0; i < roots.length; i++) if (roots[i] !== ABSENT) roots[i] += this.nodeLen;
    this.putNodes(this.nodeLen, words);
    this.putRoots(first, roots);
    this.nodeLen += nodes;
    this.treesIn += count;
    this.chunksIn += 1;
    this.dirty = true;
    return at + 16 + count * 24 + nodes * 8;
  }

  /** Chunks in the order to fetch them: most vertices in the camera's view first. */
  chunkOrder() {
    const m = viewProj(this.view, this.diagonal);
    const p = new Float32Array(this.doc.sectionBytes.verts.buffer, this.doc.sectionBytes.verts.byteOffset, this.n * 16);
    const seen = new Array(this.chunkCount).fill(0);
    for (let v = 0; v < this.n; v++) {
      const [x, y, z] = [p[v * 16], p[v * 16 + 1], p[v * 16 + 2]];
      const cx = m[0] * x + m[4] * y + m[8] * z + m[12];
      const cy = m[1] * x + m[5] * y + m[9] * z + m[13];
      const cw = m[3] * x + m[7] * y + m[11] * z + m[15];
      if (cw > 0 && Math.abs(cx) <= cw && Math.abs(cy) <= cw) seen[Math.floor(v / this.doc.chunk_vertices)] += 1;
    }
    return [...seen.keys()].sort((a, b) => seen[b] - seen[a] || a - b);
  }

  /** Streams every chunk, `PARALLEL` requests at a time; a dropped request is retried. */
  async stream() {
    const order = this.chunkOrder();
    const cv = this.doc.chunk_vertices;
    const next = () => order.shift();
    const worker = async () => {
      for (let c = next(); c !== undefined; c = next()) {
        const range = `${c * cv}..${Math.min(this.n, (c + 1) * cv)}`;
        for (let attempt = 0; ; attempt++) {
          try {
            const url = api(`v1/scenes/${sceneId}/trees?format=gpu&vertices=${range}`);
            const r = await fetch(url);
            if (r.status === 409 || r.status === 410) throw Object.assign(new Error(await errorOf(r)), { final: true });
            if (!r.ok) throw new Error(await errorOf(r));
            const buf = await r.arrayBuffer();
            this.decoded += buf.byteLength;
            this.fetched += transferred(url, buf.byteLength);
            let at = this.takeHeader(buf, 0);
            while (at < buf.byteLength) at = this.takeChunk(buf, at);
            break;
          } catch (e) {
            if (e.final) throw e;
            // Resume: the chunk is asked for again (a chunk is whole or not at all).
            say(`trees: ${e.message}; retrying`);
            await new Promise((ok) => setTimeout(ok, Math.min(5000, 250 * 2 ** attempt)));
          }
        }
      }
    };
    await Promise.all(Array.from({ length: PARALLEL }, worker));
  }
}

class GpuViewer extends Frames {
  constructor(device, context, format, doc, sources, size) {
    super(doc, size);
    this.device = device;
    this.context = context;

    const S = GPUBufferUsage.STORAGE;
    const D = GPUBufferUsage.COPY_DST;
    const init = (bytesIn, usage = S) => {
      const size = Math.max(16, Math.ceil(bytesIn.byteLength / 4) * 4);
      const buf = device.createBuffer({ size, usage: usage | D });
      device.queue.writeBuffer(buf, 0, bytesIn);
      return buf;
    };
    const zeros = (size, usage = S) => device.createBuffer({ size: Math.max(16, size), usage: usage | D });
    const s = doc.sectionBytes;
    this.verts = init(s.verts);
    this.tris = init(s.tris);
    this.materials = init(s.materials);
    this.surfaceTextures = init(s.surface_textures);
    this.cut = init(s.cut);
    this.ltc = init(s.ltc);
    this.frames = init(s.frames);
    // Each textured lamp's prefiltered pyramid (LightTexture::gpu_words); a placeholder else.
    this.noTexture = zeros(16);
    this.lightTextures = doc.lights.map((l) => (l.texture ? init(s[l.texture]) : this.noTexture));
    this.jobs = init(Uint32Array.from({ length: this.n }, (_, i) => i));
    this.results = zeros(this.n * 48);
    const none = new Uint32Array(this.n * 6).fill(NO_TREES);
    this.roots = init(none);
    this.rootsNone = init(none);
    this.nodeCap = 1 << 16;
    this.nodes = zeros(this.nodeCap * 8, S | GPUBufferUsage.COPY_SRC);
    this.lineNormals = zeros(16);
    this.shadeParams = zeros(208);
    this.rasterParams = zeros(64);
    this.resolveParams = zeros(272);
    this.presentParams = zeros(16);
    // sides.wgsl: its parameters and the per-vertex votes (zero between frames).
    this.sidesParams = zeros(32);
    this.votes = zeros(this.n * 4);
    this.image = zeros(this.width * this.height * 16);
    this.overlay = zeros(this.width * this.height * 4);
    this.visibility = device.createTexture({
      size: [this.width, this.height],
      format: 'rg16uint',
      usage: GPUTextureUsage.RENDER_ATTACHMENT | GPUTextureUsage.TEXTURE_BINDING,
    });
    this.depth = device.createTexture({
      size: [this.width, this.height],
      format: 'depth32float',
      usage: GPUTextureUsage.RENDER_ATTACHMENT,
    });
    const module = (code, label) => device.createShaderModule({ code, label });
    this.modules = {
      shade: module(sources.shade, 'shade.wgsl'),
      visibility: module(sources.visibility, 'visibility.wgsl'),
      resolve: module(sources.resolve, 'resolve.wgsl'),
      present: module(sources.present, 'present.wgsl'),
      sides: module(sources.sides, 'sides.wgsl'),
    };
    this.format = format;
  }

  /** Compiles the pipelines; rejects with the compiler's messages. */
  async compile() {
    for (const [name, m] of Object.entries(this.modules)) {
      const info = await m.getCompilationInfo();
      const errors = info.messages.filter((x) => x.type === 'error');
      if (errors.length) {
        throw new Error(`${name}.wgsl: ${errors.map((e) => `${e.lineNum}:${e.linePos} ${e.message}`).join('; ')}`);
      }
    }
    const d = this.device;
    const m = this.modules;
    [this.shadePipe, this.rasterPipe, this.resolvePipe, this.presentPipe, this.votePipe, this.markPipe] = await Promise.all([
      d.createComputePipelineAsync({ layout: 'auto', compute: { module: m.shade, entryPoint: 'main' } }),
      d.createRenderPipelineAsync({
        layout: 'auto',
        vertex: { module: m.visibility, entryPoint: 'vs' },
        fragment: { module: m.visibility, entryPoint: 'fs', targets: [{ format: 'rg16uint' }] },
        primitive: { topology: 'triangle-list' },
        // Reversed Z (near → 1, infinity → 0), as the native raster pass.
        depthStencil: { format: 'depth32float', depthWriteEnabled: true, depthCompare: 'greater' },
      }),
      d.createComputePipelineAsync({ layout: 'auto', compute: { module: m.resolve, entryPoint: 'main' } }),
      d.createRenderPipelineAsync({
        layout: 'auto',
        vertex: { module: m.present, entryPoint: 'vs' },
        fragment: { module: m.present, entryPoint: 'fs', targets: [{ format: this.format }] },
        primitive: { topology: 'triangle-list' },
      }),
      d.createComputePipelineAsync({ layout: 'auto', compute: { module: m.sides, entryPoint: 'vote' } }),
      d.createComputePipelineAsync({ layout: 'auto', compute: { module: m.sides, entryPoint: 'mark' } }),
    ]);
  }

  /** The shading passes' parameters for lamp k; `layer`: 1 adds its frame to the lamps' before it. */
  writeLampParams(k, layer) {
    const q = this.device.queue;
    const v = this.view;
    const { words: light, count } = this.lightRecord(k);
    const codec = this.codec ?? { offsets: 1, halfStep: 0 };
    // shade.wgsl `Params`: eye, light, counts (light vertices, jobs, codec offsets, LTC size),
    // codec (half step).
    const sp = new ArrayBuffer(208);
    new Float32Array(sp, 0, 4).set([...v.eye, 1]);
    new Float32Array(sp, 16, 40).set(light);
    new Uint32Array(sp, 176, 4).set([count, this.n, codec.offsets, this.doc.ltc_size]);
    new Float32Array(sp, 192, 4).set([codec.halfStep, 0, 0, 0]);
    q.writeBuffer(this.shadeParams, 0, sp);
    // resolve.wgsl `ResolveParams`.
    const rp = new ArrayBuffer(272);
    const f = new Float32Array(rp, 0, 16);
    f.set([...v.eye, v.tanHalf], 0);
    f.set([...v.forward, v.width / v.height], 4);
    f.set([...v.right, 0], 8);
    f.set([...v.up, 0], 12);
    new Float32Array(rp, 64, 40).set(light);
    new Uint32Array(rp, 224, 8).set([
      count,
      this.mode === 'pixel' ? 1 : 0,
      this.doc.ltc_size,
      this.doc.materials,
      this.width,
      this.height,
      1,
      0,
    ]);
    new Uint32Array(rp, 256, 4).set([layer, 0, 0, 0]);
    q.writeBuffer(this.resolveParams, 0, rp);
  }

  /** The parameters of the passes run once a frame: the raster's camera, present's exposure. */
  writeFrameParams() {
    const q = this.device.queue;
    q.writeBuffer(this.rasterParams, 0, viewProj(this.view, this.diagonal));
    // sides.wgsl `SidesParams`: the eye; width, height, vertices.
    const sp = new ArrayBuffer(32);
    new Float32Array(sp, 0, 4).set([...this.view.eye, 1]);
    new Uint32Array(sp, 16, 4).set([this.width, this.height, this.n, 0]);
    q.writeBuffer(this.sidesParams, 0, sp);
    const pp = new ArrayBuffer(16);
    new Uint32Array(pp).set([this.width, this.height, 0, 0]);
    new Float32Array(pp, 8, 1)[0] = this.exposure;
    q.writeBuffer(this.presentParams, 0, pp);
  }

  group(pipeline, entries) {
    return this.device.createBindGroup({
      layout: pipeline.getBindGroupLayout(0),
      entries: entries.map((r, binding) => ({
        binding,
        resource: r instanceof GPUBuffer ? { buffer: r } : r,
      })),
    });
  }

  /**
   * One frame: the visibility raster once and the side each vertex is seen from (sides.wgsl),
   * then per lamp its per-vertex shading and a resolve that adds its frame to the image, then
   * present. The lamps are submitted one after the other (their parameters share one buffer
   * each).
   */
  draw() {
    const d = this.device;
    const { records, changed } = this.vertexRecords();
    if (changed) d.queue.writeBuffer(this.verts, 0, records);
    const visView = this.visibility.createView();
    // Per lamp: the trees that shadow it (none for unshadowed LTC, and for a sun beside lamps)
    // and its texture.
    const shadeGroup = (k) =>
      this.group(this.shadePipe, [
        this.shadeParams,
        this.verts,
        this.jobs,
        this.method === 'bspvt' && this.doc.lights[k]?.shadowed !== false ? this.roots : this.rootsNone,
        this.nodes,
        this.lineNormals,
        this.ltc,
        this.results,
        this.lightTextures[k] ?? this.noTexture,
      ]);
    const resolveGroup = (k) =>
      this.group(this.resolvePipe, [
        this.resolveParams,
        this.verts,
        this.tris,
        this.materials,
        this.results,
        this.ltc,
        this.image,
        visView,
        this.lightTextures[k] ?? this.noTexture,
        this.surfaceTextures,
        this.frames,
      ]);
    this.writeFrameParams();
    const lamps = Math.max(1, this.doc.lights.length);
    for (let k = 0; k < lamps; k++) {
      this.writeLampParams(k, k === 0 ? 0 : 1);
      const enc = d.createCommandEncoder();
      if (k === 0) {
        const pass = enc.beginRenderPass({
          colorAttachments: [{ view: visView, clearValue: [0, 0, 0, 0], loadOp: 'clear', storeOp: 'store' }],
          depthStencilAttachment: {
            view: this.depth.createView(),
            depthClearValue: 0,
            depthLoadOp: 'clear',
            depthStoreOp: 'discard',
          },
        });
        pass.setPipeline(this.rasterPipe);
        pass.setBindGroup(0, this.group(this.rasterPipe, [this.rasterParams, this.verts, this.tris, this.cut]));
        pass.draw(this.doc.triangles * 3);
        pass.end();
        const sides = enc.beginComputePass();
        sides.setPipeline(this.votePipe);
        sides.setBindGroup(
          0,
          d.createBindGroup({
            layout: this.votePipe.getBindGroupLayout(0),
            entries: [this.sidesParams, this.verts, this.tris, this.votes, visView].map((r, i) => ({
              binding: i,
              resource: r instanceof GPUBuffer ? { buffer: r } : r,
            })),
          }),
        );
        sides.dispatchWorkgroups(Math.ceil(this.width / 8), Math.ceil(this.height / 8));
        sides.setPipeline(this.markPipe);
        sides.setBindGroup(
          0,
          d.createBindGroup({
            layout: this.markPipe.getBindGroupLayout(0),
            entries: [
              { binding: 0, resource: { buffer: this.sidesParams } },
              { binding: 1, resource: { buffer: this.verts } },
              { binding: 3, resource: { buffer: this.votes } },
            ],
          }),
        );
        sides.dispatchWorkgroups(Math.ceil(this.n / 64));
        sides.end();
      }
      {
        const pass = enc.beginComputePass();
        pass.setPipeline(this.shadePipe);
        pass.setBindGroup(0, shadeGroup(k));
        pass.dispatchWorkgroups(Math.ceil(this.n / 64));
        pass.end();
      }
      {
        const pass = enc.beginComputePass();
        pass.setPipeline(this.resolvePipe);
        pass.setBindGroup(0, resolveGroup(k));
        pass.dispatchWorkgroups(Math.ceil(this.width / 8), Math.ceil(this.height / 8));
        pass.end();
      }
      if (k === lamps - 1) {
        const pass = enc.beginRenderPass({
          colorAttachments: [
            { view: this.context.getCurrentTexture().createView(), clearValue: [0, 0, 0, 1], loadOp: 'clear', storeOp: 'store' },
          ],
        });
        pass.setPipeline(this.presentPipe);
        pass.setBindGroup(0, this.group(this.presentPipe, [this.presentParams, this.image, this.overlay]));
        pass.draw(3);
        pass.end();
      }
      d.queue.submit([enc.finish()]);
    }
    return d.queue.onSubmittedWorkDone();
  }

  // ---- trees

  putLineNormals(bytesIn) {
    this.lineNormals = this.device.createBuffer({
      size: Math.max(16, bytesIn.byteLength),
      usage: GPUBufferUsage.STORAGE | GPUBufferUsage.COPY_DST,
    });
    this.device.queue.writeBuffer(this.lineNormals, 0, bytesIn);
  }

  putNodes(at, words) {
    this.reserve(at + words.length / 2);
    this.device.queue.writeBuffer(this.nodes, at * 8, words);
  }

  putRoots(first, roots) {
    this.device.queue.writeBuffer(this.roots, first * 24, roots);
  }

  reserve(nodes) {
    if (nodes <= this.nodeCap) return;
    const cap = Math.max(nodes, this.nodeCap * 2);
    const bigger = this.device.createBuffer({
      size: cap * 8,
      usage: GPUBufferUsage.STORAGE | GPUBufferUsage.COPY_DST | GPUBufferUsage.COPY_SRC,
    });
    const enc = this.device.createCommandEncoder();
    if (this.nodeLen) enc.copyBufferToBuffer(this.nodes, 0, bigger, 0, this.nodeLen * 8);
    this.device.queue.submit([enc.finish()]);
    this.nodes = bigger;
    this.nodeCap = cap;
  }
}

/** The CPU path (cpu.js), for a browser without WebGPU: per vertex, onto a 2-D canvas. */
class CpuViewer extends Frames {
  constructor(context, doc, size) {
    super(doc, size);
    this.context = context;
    this.mode = 'vertex';
    const s = doc.sectionBytes;
    const f32 = (b) => new Float32Array(b.buffer, b.byteOffset, b.byteLength / 4);
    this.scene = {
      verts: f32(s.verts),
      tris: new Uint32Array(s.tris.buffer, s.tris.byteOffset, s.tris.byteLength / 4),
      triangles: doc.triangles,
      ltc: f32(s.ltc),
      ltcSize: doc.ltc_size,
    };
    this.trees = {
      roots: new Uint32Array(this.n * 6).fill(NO_TREES),
      nodes: new Uint32Array(1 << 17),
      nodeLen: 0,
      lineNormals: new Float32Array(0),
      codec: { offsets: 1, halfStep: 0 },
    };
    this.linear = new Float64Array(this.width * this.height * 3);
    this.pixels = new ImageData(this.width, this.height);
    // A textured lamp's mean colour: its pyramid's coarsest texel (LightTexture::gpu_words:
    // [0] = (levels, …), [1 + l] = (w, h, offset) of level l, as u32 bits).
    this.textureMeans = doc.lights.map((l) => {
      if (!l.texture) return null;
      const b = s[l.texture];
      const u = new Uint32Array(b.buffer, b.byteOffset, b.byteLength / 4);
      const at = u[4 * u[0] + 2];
      return Array.from(f32(b).subarray(4 * at, 4 * at + 3));
    });
  }

  /** Nothing to compile. */
  async compile() {}

  putLineNormals(bytesIn) {
    this.trees.lineNormals = new Float32Array(bytesIn.buffer, bytesIn.byteOffset, bytesIn.byteLength / 4);
    this.trees.codec = this.codec;
  }

  putNodes(at, words) {
    const need = 2 * at + words.length;
    if (need > this.trees.nodes.length) {
      const bigger = new Uint32Array(Math.max(need, 2 * this.trees.nodes.length));
      bigger.set(this.trees.nodes.subarray(0, 2 * at));
      this.trees.nodes = bigger;
    }
    this.trees.nodes.set(words, 2 * at);
    this.trees.nodeLen = at + words.length / 2;
  }

  putRoots(first, roots) {
    this.trees.roots.set(roots, first * 6);
  }

  /** One frame: every lamp at the vertices the camera sees, summed, then interpolated. */
  async draw() {
    this.scene.verts = this.vertexRecords().records;
    const colour = new Float64Array(this.n * 3);
    const vis = visibilityBuffer(this.scene, this.view);
    const { visible: seen, behind } = vertexSides(this.scene, this.view.eye, vis);
    const lamps = this.doc.lights.length;
    for (let k = 0; k < lamps; k++) {
      const { words, count } = this.lightRecord(k);
      this.textureMeans[k]?.forEach((m, a) => (words[4 + a] *= m));
      const shadowed = this.method === 'bspvt' && this.doc.lights[k].shadowed !== false;
      for (let i = 0; i < seen.length; i++) {
        const v = seen[i];
        const c = shadeVertex(this.scene, this.trees, v, words, count, this.view.eye, shadowed, behind[v] === 1);
        for (let a = 0; a < 3; a++) colour[3 * v + a] += c[a];
        // Let the page breathe (input, progress) between slices of vertices.
        if (i % 4096 === 4095) await new Promise((ok) => setTimeout(ok, 0));
      }
    }
    interpolate(this.scene, vis, colour, this.linear);
    toneMap(this.linear, this.exposure, this.pixels.data);
    this.context.putImageData(this.pixels, 0, 0);
  }
}

// ---- input

function wireInput(viewer, canvas) {
  let drag = null;
  const c = viewer.camera;
  canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  canvas.addEventListener('pointerdown', (e) => {
    canvas.setPointerCapture(e.pointerId);
    drag = { x: e.clientX, y: e.clientY, light: e.shiftKey || e.button === 2 };
  });
  canvas.addEventListener('pointerup', () => {
    drag = null;
  });
  canvas.addEventListener('pointermove', (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x;
    const dy = e.clientY - drag.y;
    drag.x = e.clientX;
    drag.y = e.clientY;
    if (drag.light) moveLight(viewer, dx, dy);
    else orbit(viewer, dx, dy);
  });
  canvas.addEventListener(
    'wheel',
    (e) => {
      e.preventDefault();
      const off = sub(c.eye, c.target);
      c.eye = add(c.target, scale(off, Math.exp(e.deltaY * 0.001)));
      viewer.setView();
    },
    { passive: false },
  );
}

function orbit(viewer, dx, dy) {
  const c = viewer.camera;
  const off = sub(c.eye, c.target);
  const dist = Math.hypot(...off);
  let yaw = Math.atan2(off[0], off[2]) - dx * 0.005;
  let pitch = Math.asin(Math.max(-1, Math.min(1, off[1] / dist))) + dy * 0.005;
  pitch = Math.max(-1.5, Math.min(1.5, pitch));
  c.eye = add(c.target, [dist * Math.cos(pitch) * Math.sin(yaw), dist * Math.sin(pitch), dist * Math.cos(pitch) * Math.cos(yaw)]);
  viewer.setView();
}

/** Moves the light in the horizontal plane, its centroid kept inside its region. */
function moveLight(viewer, dx, dy) {
  const lamp = viewer.lightIndex;
  const l = viewer.doc.lights[lamp];
  if (!l?.region) {
    say('this light has no region to move in (the scene file gives one)');
    return;
  }
  const v = viewer.view;
  const dist = Math.hypot(...sub(v.eye, viewer.camera.target));
  const k = (2 * dist * v.tanHalf) / v.height;
  const flat = (a) => normalizeOr([a[0], 0, a[2]], [0, 0, 0]);
  const delta = add(scale(flat(v.right), dx * k), scale(flat(v.forward), -dy * k));
  const centroid = scale(l.vertices.reduce(add, [0, 0, 0]), 1 / l.vertices.length);
  const o = add(viewer.lightOffsets[lamp], delta);
  for (const axis of [0, 2]) {
    const at = centroid[axis] + o[axis];
    o[axis] += Math.max(l.region.min[axis], Math.min(l.region.max[axis], at)) - at;
  }
  viewer.lightOffsets[lamp] = o;
  viewer.dirty = true;
  html.dataset.lightOffset = o.map((x) => x.toFixed(3)).join(',');
}

// ---- main

async function main() {
  $('scene-id').textContent = sceneId.slice(0, 12);
  if (!/^[0-9a-f]{32}$/.test(sceneId)) {
    fail(`"${sceneId}" is not a scene id`);
    return;
  }
  // WebGPU where the browser has an adapter; else (or with `graphics=cpu`) the CPU path.
  const forced = query.get('graphics') === 'cpu';
  let adapter = null;
  let why = 'asked for by graphics=cpu';
  if (!forced) {
    adapter = navigator.gpu ? await navigator.gpu.requestAdapter().catch(() => null) : null;
    why = navigator.gpu ? 'WebGPU offers no adapter here' : 'this browser has no WebGPU';
  }
  let device = null;
  let graphics;
  if (adapter) {
    const info = adapter.info ?? {};
    graphics = `WebGPU: ${[info.vendor, info.architecture, info.description].filter(Boolean).join(' ') || 'adapter'}`;
    device = await adapter.requestDevice({
      requiredLimits: { maxStorageBuffersPerShaderStage: Math.min(12, adapter.limits.maxStorageBuffersPerShaderStage) },
    });
    device.lost.then((l) => fail(`the GPU device was lost: ${l.message}`));
    device.addEventListener('uncapturederror', (e) => fail(`WebGPU: ${e.error.message}`));
  } else {
    graphics = `CPU (JavaScript, per vertex; ${why})`;
  }
  html.dataset.graphics = graphics;
  $('graphics').textContent = graphics;

  const t0 = performance.now();
  const [doc, ...wgsl] = await Promise.all([
    fetchScene(),
    ...(device ? ['shade.wgsl', 'visibility.wgsl', 'resolve.wgsl', 'present.wgsl', 'sides.wgsl'].map(fetchShader) : []),
  ]);
  const canvas = $('frame');
  const width = Number(query.get('width')) || 960;
  const aspect = doc.camera.aspect ?? 16 / 9;
  const height = Number(query.get('height')) || Math.round(width / aspect);
  canvas.width = width;
  canvas.height = height;
  let viewer;
  if (device) {
    const context = canvas.getContext('webgpu');
    const format = navigator.gpu.getPreferredCanvasFormat();
    context.configure({ device, format, alphaMode: 'opaque' });
    const [shade, visibility, resolve, present, sides] = wgsl;
    viewer = new GpuViewer(device, context, format, doc, { shade, visibility, resolve, present, sides }, { width, height });
  } else {
    viewer = new CpuViewer(canvas.getContext('2d'), doc, { width, height });
    // The CPU path shades per vertex only.
    $('mode').querySelector('option[value="pixel"]').disabled = true;
    say(`No WebGPU (${why}): drawn on the CPU in JavaScript, per vertex, slower than the GPU path.`);
    // A scene with alpha cut-outs has more than the one zero word of `cut`.
    if (doc.sectionBytes.cut.byteLength > 4) doc.not_shown.push('alpha cut-outs: the CPU path draws masked surfaces whole');
    if (doc.lights.some((l) => l.texture)) doc.not_shown.push("light textures: the CPU path draws a textured lamp with its texture's mean");
  }
  for (const s of doc.not_shown) $('not-shown').append(Object.assign(document.createElement('li'), { textContent: `not shown: ${s}` }));
  if (doc.lights.length > 1) {
    $('light-pick').hidden = false;
    doc.lights.forEach((l, k) => $('light').append(new Option(`#${k} ${l.kind}${l.name ? `: ${l.name}` : ''}`, String(k))));
    $('light').addEventListener('change', () => {
      viewer.lightIndex = Number($('light').value);
    });
  }
  if (doc.lights.length === 0) say('the scene has no light: it is drawn black');
  $('method').value = viewer.method;
  $('mode').value = viewer.mode;
  $('method').addEventListener('change', () => {
    viewer.method = $('method').value;
    viewer.dirty = true;
  });
  $('mode').addEventListener('change', () => {
    viewer.mode = device ? $('mode').value : 'vertex';
    viewer.dirty = true;
  });
  html.dataset.step = 'compiling';
  await viewer.compile();
  html.dataset.step = 'compiled';
  wireInput(viewer, canvas);
  html.dataset.state = 'streaming';

  let streamed = false;
  viewer
    .stream()
    .then(() => {
      streamed = true;
      viewer.dirty = true;
    })
    .catch((e) => fail(`trees: ${e.message}`));

  let first = null;
  let frames = 0;
  let since = performance.now();
  let busy = false;
  let drawn = 0;
  const tick = async () => {
    requestAnimationFrame(tick);
    if (busy) return;
    // `data-idle`: every change is drawn (a test waits for it after input).
    html.dataset.idle = String(!viewer.dirty);
    if (!viewer.dirty) return;
    busy = true;
    html.dataset.drawing = 'true';
    viewer.dirty = false;
    const complete = streamed && viewer.treesIn === viewer.n;
    const start = performance.now();
    html.dataset.step = `drawing frame ${drawn + 1}`;
    await viewer.draw();
    html.dataset.step = `drew frame ${drawn + 1}`;
    const ms = performance.now() - start;
    frames += 1;
    if (first === null) {
      first = performance.now() - t0;
      $('first').textContent = `${first.toFixed(0)} ms after the page's start`;
      html.dataset.firstFrameMs = first.toFixed(0);
    }
    const now = performance.now();
    if (now - since > 500) {
      $('fps').textContent = `${ms.toFixed(1)} ms (${((frames * 1000) / (now - since)).toFixed(1)} fps while redrawing)`;
      frames = 0;
      since = now;
    }
    html.dataset.frameMs = ms.toFixed(2);
    $('trees').textContent = `${viewer.treesIn.toLocaleString('en')} of ${viewer.n.toLocaleString('en')} vertices (${viewer.chunksIn}/${viewer.chunkCount} chunks)`;
    $('bytes').textContent = `${bytes(viewer.fetched)} (${bytes(viewer.decoded)} decoded): scene and trees`;
    html.dataset.bytes = String(viewer.fetched);
    html.dataset.decodedBytes = String(viewer.decoded);
    if (complete && html.dataset.state === 'streaming') html.dataset.state = 'complete';
    drawn += 1;
    html.dataset.frames = String(drawn);
    html.dataset.drawing = 'false';
    busy = false;
  };
  requestAnimationFrame(tick);

  // `?bench=N`: once complete, N frames back to back, each waited for (docs/service.md).
  const bench = Number(query.get('bench')) || 0;
  if (bench > 0) {
    while (html.dataset.state !== 'complete') await new Promise((ok) => setTimeout(ok, 50));
    while (busy) await new Promise((ok) => setTimeout(ok, 5));
    busy = true;
    const start = performance.now();
    for (let k = 0; k < bench; k++) await viewer.draw();
    html.dataset.benchMs = ((performance.now() - start) / bench).toFixed(2);
    busy = false;
  }
}

main().catch((e) => fail(e.message));
