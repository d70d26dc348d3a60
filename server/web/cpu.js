// The viewer's CPU path, for a browser without WebGPU (docs/service.md, "Viewer"): BSPVT per
// vertex (paper 000 §3.1 eq. 2) in JavaScript's f64, as the native client's CPU reference
// shades it (client/src/shade/bspvt.rs, ltc/polygon.rs, light.rs) and shade.wgsl mirrors in
// f32, over the same buffers the GPU path uploads (the service's scene bundle and the trees'
// GPU words); then the per-vertex colours interpolated over a ray-cast of the triangles (the
// CPU G-buffer's rule: the primary ray against each triangle's plane) and tone-mapped as
// present.wgsl does. Per vertex only: the per-pixel mode needs WebGPU.

const ABSENT = 0xffffffff;
const NO_TREES = 0xfffffffe;
const LEAF = 0x80000000;
// ggx::MIN_ALPHA and ltc::table::THETA_MAX_DEG in radians.
const MIN_ALPHA = 1e-4;
const THETA_MAX = 1.5706217;
// The kinds of light of bspvt_shaders::gpu::lights and their round polygon.
const SPHERE = 2;
const SUN = 3;
const ROUND_SIDES = 12;

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const len = (a) => Math.hypot(a[0], a[1], a[2]);
const clamp = (x, lo, hi) => Math.min(hi, Math.max(lo, x));
// A 3×3 matrix as its rows.
const apply = (m, v) => [dot(m[0], v), dot(m[1], v), dot(m[2], v)];
const mul = (a, b) => a.map((row) => [0, 1, 2].map((c) => row[0] * b[0][c] + row[1] * b[1][c] + row[2] * b[2][c]));

// (w, a, b) of each cube face, in proto/src/cubemap.rs order: +X, −X, +Y, −Y, +Z, −Z.
const FACE_W = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]];
const FACE_A = [[0, 1, 0], [0, 0, 1], [0, 0, 1], [1, 0, 0], [1, 0, 0], [0, 1, 0]];
const FACE_B = [[0, 0, 1], [0, 1, 0], [1, 0, 0], [0, 0, 1], [0, 1, 0], [1, 0, 0]];

/** ltc::table::LtcTable::lookup over the table's nodes (two vec4 each), as common.wgsl's. */
function ltcLookup(table, n, alphaIn, thetaIn) {
  const alpha = Number.isFinite(alphaIn) ? clamp(alphaIn, MIN_ALPHA, 1) : 1;
  const theta = clamp(thetaIn, 0, THETA_MAX);
  const last = n - 1;
  const sa = clamp(1 - Math.log(alpha) / Math.log(MIN_ALPHA), 0, 1) * last;
  const st = clamp(1 - Math.sqrt(1 - clamp(theta / THETA_MAX, 0, 1)), 0, 1) * last;
  const i0 = Math.min(Math.floor(sa), n - 2);
  const j0 = Math.min(Math.floor(st), n - 2);
  const fi = clamp(sa - i0, 0, 1);
  const fj = clamp(st - j0, 0, 1);
  const taps = [
    [i0 * n + j0, (1 - fi) * (1 - fj)],
    [i0 * n + j0 + 1, (1 - fi) * fj],
    [(i0 + 1) * n + j0, fi * (1 - fj)],
    [(i0 + 1) * n + j0 + 1, fi * fj],
  ];
  const q = new Float64Array(8);
  for (const [k, w] of taps) for (let c = 0; c < 8; c++) q[c] += w * table[8 * k + c];
  const rho = q[0] - theta;
  const m11 = Math.exp(q[1]);
  const m22 = Math.exp(q[2]);
  const m13 = q[3] * m11;
  const m31 = q[4];
  const det = Math.max(m11 - m13 * m31, 1e-6 * m11);
  const [s, c] = [Math.sin(rho), Math.cos(rho)];
  const x = [c, 0, -s];
  const z = [s, 0, c];
  const k = m22 / det;
  const magnitude = Math.max(q[5], 0);
  return {
    mInv: [scale(sub(x, scale(z, m13)), k), [0, 1, 0], scale(sub(scale(z, m11), scale(x, m31)), k)],
    magnitude,
    fresnel: clamp(q[6], 0, magnitude),
  };
}

/** frame::shading::ShadingFrame: rows x (the view's tangential part), y, the normal. */
function toLocal(n, wo) {
  const t0 = sub(wo, scale(n, dot(n, wo)));
  const t = sub(t0, scale(n, dot(n, t0)));
  let x;
  if (dot(t, t) > 1e-24) {
    x = scale(t, 1 / len(t));
  } else {
    // glam's any_orthonormal_vector.
    const sg = n[2] >= 0 ? 1 : -1;
    const a = -1 / (sg + n[2]);
    x = [n[0] * n[1] * a, sg + n[1] * n[1] * a, -n[1]];
  }
  return [x, cross(n, x), n];
}

/** The part of `poly` with n·d ≥ 0 (sphere::clip_into); [] when nothing lies strictly inside. */
function clip(poly, n) {
  const d = poly.map((p) => dot(n, p));
  if (!d.some((x) => x > 0) || poly.length < 3) return [];
  if (!d.some((x) => x < 0)) return poly;
  const out = [];
  for (let i = 0; i < poly.length; i++) {
    const j = (i + 1) % poly.length;
    if (d[i] >= 0) out.push(poly[i]);
    if (d[i] >= 0 !== d[j] >= 0) out.push(add(poly[i], scale(sub(poly[j], poly[i]), d[i] / (d[i] - d[j]))));
  }
  return out.length >= 3 ? out : [];
}

/**
 * ltc::polygon::integrate: ∫ over `poly` (directions; need not be unit) of the clamped cosine
 * transformed by `m` (M⁻¹ · world → local), normalised: transformed, scaled by a power of two,
 * clipped to z ≥ 0, θ (p × q)·z / |p × q| per edge with θ = atan2(|p × q|, p·q) and p × q as
 * p × (q − p) (no cancellation for short edges).
 */
function integrate(m, poly) {
  if (poly.length < 3) return 0;
  let t = poly.map((p) => apply(m, p));
  const big = Math.max(...t.map((p) => Math.max(Math.abs(p[0]), Math.abs(p[1]), Math.abs(p[2]))));
  if (!(big > 0) || !Number.isFinite(big)) return 0;
  const s = 2 ** -Math.floor(Math.log2(big));
  t = clip(
    t.map((p) => scale(p, s)),
    [0, 0, 1],
  );
  let sum = 0;
  let p = t[t.length - 1];
  for (const q of t) {
    const c = cross(p, sub(q, p));
    const sl = len(c);
    if (sl > 0 && Number.isFinite(sl)) sum += (Math.atan2(sl, dot(p, q)) * c[2]) / sl;
    p = q;
  }
  const v = Math.abs(sum) / (2 * Math.PI);
  return Number.isFinite(v) ? Math.min(v, 1) : 0;
}

/**
 * light::round_directions: the regular spherical 12-gon around unit `axis` with the solid angle
 * Ω = 4π sin²(α/2) of the cap of half-angle α; each of its N isosceles triangles (apex angle
 * C = 2π/N) has area Ω/N, tan(Ω/2N) = t² sin C / (1 + t² cos C), t = tan(β/2) (Todhunter §101).
 */
function roundDirections(axis, sinHalf) {
  const c = (2 * Math.PI) / ROUND_SIDES;
  const omega = 4 * Math.PI * sinHalf * sinHalf;
  const bigT = Math.tan((0.5 * omega) / ROUND_SIDES);
  const t2 = bigT / (Math.sin(c) - bigT * Math.cos(c));
  const al = len(axis);
  if (!(t2 > 0) || !Number.isFinite(t2) || !(al > 0) || !Number.isFinite(al)) return [];
  const beta = 2 * Math.atan(Math.sqrt(t2));
  const [sb, cb] = [Math.sin(beta), Math.cos(beta)];
  const a = scale(axis, 1 / al);
  // glam's any_orthonormal_pair (its signum: the sign bit).
  const sg = a[2] > 0 || Object.is(a[2], 0) ? 1 : -1;
  const k = -1 / (sg + a[2]);
  const b = a[0] * a[1] * k;
  const u = [1 + sg * a[0] * a[0] * k, sg * b, -sg * a[0]];
  const v = [b, sg + a[1] * a[1] * k, -a[1]];
  const out = [];
  for (let i = 0; i < ROUND_SIDES; i++) {
    const phi = -c * i;
    out.push(add(scale(a, cb), scale(add(scale(u, Math.cos(phi)), scale(v, Math.sin(phi))), sb)));
  }
  return out;
}

/**
 * shade::light_directions: what light `r` (a LightRecord's 40 words) subtends from p, as unit
 * directions clipped to the upper hemisphere of n; [] when it sends nothing there.
 */
function lightDirections(r, count, p, n) {
  const kind = r[3];
  const word = (i) => [r[8 + 4 * i], r[9 + 4 * i], r[10 + 4 * i], r[11 + 4 * i]];
  let dirs = [];
  if (kind === SPHERE || kind === SUN) {
    if (count !== ROUND_SIDES) return [];
    const w0 = word(0);
    if (kind === SUN) {
      dirs = roundDirections(w0, Math.sin(0.5 * w0[3]));
    } else {
      const to = sub(w0, p);
      const d = len(to);
      if (!(d > w0[3]) || !Number.isFinite(d)) return [];
      const sinA = w0[3] / d;
      const cosA = Math.sqrt(Math.max(1 - sinA * sinA, 0));
      dirs = roundDirections(scale(to, 1 / d), Math.min(sinA / Math.sqrt(2 * (1 + cosA)), 1));
    }
  } else {
    if (count < 3 || count > 8) return [];
    if (kind === 0 && !(dot([r[0], r[1], r[2]], sub(p, word(0))) > 0)) return [];
    for (let i = 0; i < count; i++) {
      const d = sub(word(i), p);
      const l = len(d);
      if (!(l > 0) || !Number.isFinite(l)) return [];
      dirs.push(scale(d, 1 / l));
    }
  }
  return dirs.length ? clip(dirs, n) : [];
}

/** PunctualLight::falloff of a sphere toward p (1 for the other kinds). */
function lightFalloff(r, p) {
  if (r[3] !== SPHERE) return 1;
  const to = sub(p, [r[8], r[9], r[10]]);
  const d = len(to);
  if (!(d > 0) || !Number.isFinite(d)) return 0;
  let f = 1;
  if (r[18] !== 0) {
    const cosTo = dot([r[12], r[13], r[14]], scale(to, 1 / d));
    const s = 1 / Math.max(r[16] - r[17], 0.001);
    const a = clamp(cosTo * s - r[17] * s, 0, 1);
    f *= a * a;
  }
  if (r[15] > 0) {
    const x = d / r[15];
    const w = clamp(1 - x ** 4, 0, 1);
    f *= w * w;
  }
  return Number.isFinite(f) ? f : 0;
}

/**
 * The trees' plane of a split word on face f (LineCodec::plane): N = n.x·a + n.y·b − c·w with
 * c(o) = (2o + 1 − O)·h, the codec's own f32 normal table.
 */
function linePlane(trees, word, f) {
  const angle = word >>> 16;
  const offset = word & 0xffff;
  const nx = trees.lineNormals[2 * angle];
  const ny = trees.lineNormals[2 * angle + 1];
  const c = (2 * offset + 1 - trees.codec.offsets) * trees.codec.halfStep;
  return sub(add(scale(FACE_A[f], nx), scale(FACE_B[f], ny)), scale(FACE_W[f], c));
}

/**
 * Cuts `poly` by the plane n: (n·d ≤ 0 part, n·d ≥ 0 part) (sphere::cut_into); either may be
 * empty.
 */
function cut(poly, n) {
  const neg = [];
  const pos = [];
  const d = poly.map((p) => dot(n, p));
  for (let i = 0; i < poly.length; i++) {
    const j = (i + 1) % poly.length;
    if (d[i] <= 0) neg.push(poly[i]);
    if (d[i] >= 0) pos.push(poly[i]);
    if ((d[i] < 0 && d[j] > 0) || (d[i] > 0 && d[j] < 0)) {
      const x = add(poly[i], scale(sub(poly[j], poly[i]), d[i] / (d[i] - d[j])));
      neg.push(x);
      pos.push(x);
    }
  }
  return [neg.length >= 3 ? neg : [], pos.length >= 3 ? pos : []];
}

/**
 * Eq. 2 of paper 000 at vertex v for one light: Σ over the tree leaves v̄ · the LTC integrals of
 * the light's pieces in them (the light cut by each face's pyramid, then by the tree's lines),
 * times the light's radiance (and a sphere's falloff); unshadowed where `shadowed` is false,
 * the vertex's trees have not arrived or it is seen from `behind` (its trees are for its other
 * side; its normal is turned over). Returns linear RGB.
 */
export function shadeVertex(scene, trees, v, record, count, eye, shadowed, behind = false) {
  const V = scene.verts;
  const p = [V[16 * v], V[16 * v + 1], V[16 * v + 2]];
  const n0 = [V[16 * v + 4], V[16 * v + 5], V[16 * v + 6]];
  const nl = len(n0);
  // Seen from behind (vertexSides): shaded on that side, where it has no trees.
  const n = scale(nl > 0 && Number.isFinite(nl) ? scale(n0, 1 / nl) : [0, 1, 0], behind ? -1 : 1);
  const albedo = [V[16 * v + 8], V[16 * v + 9], V[16 * v + 10]];
  const alpha = V[16 * v + 11];
  const f0 = [V[16 * v + 12], V[16 * v + 13], V[16 * v + 14]];
  let wo = sub(eye, p);
  const lo = len(wo);
  wo = lo > 0 && Number.isFinite(lo) ? scale(wo, 1 / lo) : n;
  const frame = toLocal(n, wo);
  const lt = ltcLookup(scene.ltc, scene.ltcSize, alpha, Math.atan2(len(cross(n, wo)), dot(n, wo)));
  const toLtc = mul(lt.mInv, frame);
  const spec = f0.map((f) => f * lt.magnitude + (1 - f) * lt.fresnel);
  const dirs = lightDirections(record, count, p, n);
  if (dirs.length < 3) return [0, 0, 0];
  const radiance = scale([record[4], record[5], record[6]], lightFalloff(record, p));
  const shade = (rd, rs) => [0, 1, 2].map((c) => radiance[c] * (albedo[c] * rd + spec[c] * rs));
  const root0 = trees.roots[6 * v];
  if (!shadowed || behind || root0 === NO_TREES || root0 === undefined) {
    return shade(integrate(frame, dirs), integrate(toLtc, dirs));
  }
  let sd = 0;
  let ss = 0;
  const piece = (poly, vbar) => {
    sd += vbar * integrate(frame, poly);
    ss += vbar * integrate(toLtc, poly);
  };
  for (let f = 0; f < 6; f++) {
    // tree::clip_to_face: |d·a| ≤ d·w, |d·b| ≤ d·w.
    let poly = dirs;
    for (const plane of [sub(FACE_W[f], FACE_A[f]), add(FACE_W[f], FACE_A[f]), sub(FACE_W[f], FACE_B[f]), add(FACE_W[f], FACE_B[f])]) {
      poly = clip(poly, plane);
      if (poly.length < 3) break;
    }
    if (poly.length < 3) continue;
    const root = trees.roots[6 * v + f];
    if (root === ABSENT) {
      // bspvt::ABSENT_FACE_VALUE: visible.
      piece(poly, 1);
      continue;
    }
    const pending = [[root, poly]];
    while (pending.length) {
      let [node, part] = pending.pop();
      for (let steps = 0; steps < 65536 && node < trees.nodeLen; steps++) {
        const word = trees.nodes[2 * node];
        if ((word & LEAF) >>> 0 !== 0) {
          const value = word & 0xff;
          if (value) piece(part, value / 255);
          break;
        }
        const [neg, pos] = cut(part, linePlane(trees, word, f));
        if (pos.length) pending.push([root + trees.nodes[2 * node + 1], pos]);
        if (!neg.length) break;
        part = neg;
        node += 1;
      }
    }
  }
  return shade(sd, ss);
}

/**
 * The frame's visibility: every pixel's nearest triangle along its primary ray (against the
 * triangle's plane, barycentrics inside it: gbuffer::ray_plane_barycentrics) — `tri` (−1:
 * none) and the barycentrics of its corners 1 and 2.
 */
export function visibilityBuffer(scene, view) {
  const { width: w, height: h } = view;
  const V = scene.verts;
  const T = scene.tris;
  const depth = new Float64Array(w * h).fill(Infinity);
  const tri = new Int32Array(w * h).fill(-1);
  const bary = new Float64Array(2 * w * h);
  const aspect = w / h;
  const rel = (v) => sub([V[16 * v], V[16 * v + 1], V[16 * v + 2]], view.eye);
  // Screen position of a point (pixels) and its depth along the view.
  const project = (d) => {
    const z = dot(d, view.forward);
    return [((dot(d, view.right) / (z * view.tanHalf * aspect) + 1) / 2) * w, ((1 - dot(d, view.up) / (z * view.tanHalf)) / 2) * h, z];
  };
  const near = 1e-6;
  for (let t = 0; t < scene.triangles; t++) {
    const ids = [T[4 * t], T[4 * t + 1], T[4 * t + 2]];
    const d = ids.map(rel);
    const s = d.map(project);
    if (s.some((x) => !(x[2] > near))) continue;
    const x0 = Math.max(0, Math.floor(Math.min(s[0][0], s[1][0], s[2][0])));
    const x1 = Math.min(w - 1, Math.ceil(Math.max(s[0][0], s[1][0], s[2][0])));
    const y0 = Math.max(0, Math.floor(Math.min(s[0][1], s[1][1], s[2][1])));
    const y1 = Math.min(h - 1, Math.ceil(Math.max(s[0][1], s[1][1], s[2][1])));
    if (x0 > x1 || y0 > y1) continue;
    const e1 = sub(d[1], d[0]);
    const e2 = sub(d[2], d[0]);
    const tv = scale(d[0], -1);
    const qv = cross(tv, e1);
    for (let y = y0; y <= y1; y++) {
      for (let x = x0; x <= x1; x++) {
        // frame::camera: the ray through the pixel's centre.
        const sx = ((2 * (x + 0.5)) / w - 1) * view.tanHalf * aspect;
        const sy = (1 - (2 * (y + 0.5)) / h) * view.tanHalf;
        const dir = add(view.forward, add(scale(view.right, sx), scale(view.up, sy)));
        // Möller–Trumbore against the triangle (its edges inclusive).
        const pv = cross(dir, e2);
        const det = dot(e1, pv);
        if (!(Math.abs(det) > 0)) continue;
        const inv = 1 / det;
        const u = dot(tv, pv) * inv;
        const v = dot(dir, qv) * inv;
        if (u < 0 || v < 0 || u + v > 1) continue;
        const dist = dot(e2, qv) * inv;
        const i = y * w + x;
        if (!(dist > 0) || dist >= depth[i]) continue;
        depth[i] = dist;
        tri[i] = t;
        bary[2 * i] = u;
        bary[2 * i + 1] = v;
      }
    }
  }
  return { tri, bary };
}

/**
 * The vertices the frame interpolates (corners of the triangles in `vis`) and, per vertex,
 * whether the camera sees it from behind (GBuffer::vertex_sides, sides.wgsl): every pixel of
 * `vis` votes for its triangle's corners, for the back where a corner's normal points away
 * from the face the eye sees; a vertex is behind where the back has more votes.
 */
export function vertexSides(scene, eye, vis) {
  const V = scene.verts;
  const T = scene.tris;
  const pixels = new Int32Array(scene.triangles);
  for (const t of vis.tri) if (t >= 0) pixels[t] += 1;
  const seen = new Uint8Array(V.length / 16);
  const votes = new Int32Array(V.length / 16);
  for (let t = 0; t < scene.triangles; t++) {
    if (!pixels[t]) continue;
    const ids = [T[4 * t], T[4 * t + 1], T[4 * t + 2]];
    const p = ids.map((v) => [V[16 * v], V[16 * v + 1], V[16 * v + 2]]);
    let g = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    if (dot(g, sub(eye, p[0])) < 0) g = scale(g, -1);
    for (const v of ids) {
      seen[v] = 1;
      const d = dot([V[16 * v + 4], V[16 * v + 5], V[16 * v + 6]], g);
      if (d < 0) votes[v] += pixels[t];
      else if (d > 0) votes[v] -= pixels[t];
    }
  }
  const visible = [];
  for (let v = 0; v < seen.length; v++) if (seen[v]) visible.push(v);
  return { visible, behind: Uint8Array.from(votes, (x) => (x > 0 ? 1 : 0)) };
}

/** The frame per vertex: the vertices' colours (linear RGB, 3 per vertex) interpolated at `vis`. */
export function interpolate(scene, vis, colour, out) {
  const T = scene.tris;
  out.fill(0);
  for (let i = 0; i < vis.tri.length; i++) {
    const t = vis.tri[i];
    if (t < 0) continue;
    const u = vis.bary[2 * i];
    const v = vis.bary[2 * i + 1];
    const b = [1 - u - v, u, v];
    const ids = [T[4 * t], T[4 * t + 1], T[4 * t + 2]];
    for (let c = 0; c < 3; c++) out[3 * i + c] = b[0] * colour[3 * ids[0] + c] + b[1] * colour[3 * ids[1] + c] + b[2] * colour[3 * ids[2] + c];
  }
}

/** ACES filmic (Narkowicz 2015) then the sRGB OETF, 8-bit: present.wgsl's and Image::to_srgb8's. */
export function toneMap(linear, exposure, rgba) {
  const aces = (c) => {
    const x = clamp(Number.isNaN(c) ? 0 : c, 0, 1e4);
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0, 1);
  };
  const srgb = (c) => (c <= 0.0031308 ? 12.92 * c : 1.055 * c ** (1 / 2.4) - 0.055);
  for (let i = 0; i < linear.length / 3; i++) {
    for (let c = 0; c < 3; c++) rgba[4 * i + c] = Math.floor(clamp(srgb(aces(linear[3 * i + c] * exposure)) * 255 + 0.5, 0, 255));
    rgba[4 * i + 3] = 255;
  }
}
