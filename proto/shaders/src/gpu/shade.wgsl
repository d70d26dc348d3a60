// BSPVT shading per vertex on the GPU (paper 000 §3.1 eq. 2; client/src/shade/bspvt.rs): the
// light polygon seen from the vertex, clipped to its horizon, clipped to each cube face's
// pyramid, cut by the face tree's lines (great circles: planes through the origin, the same
// side test as LineCodec) while walking the tree; every piece in a leaf with v̄ > 0 is
// integrated with LTC GGX [Heitz16] and weighted by v̄. One invocation per visible vertex.
// Prepended: common.wgsl.

const STACK_DEPTH: u32 = 48u;
const STACK_VERTS: u32 = 384u;
// A face without a tree (visible) and a vertex whose trees have not arrived (gpu/trees.rs).
const ABSENT: u32 = 0xffffffffu;
const NO_TREES: u32 = 0xfffffffeu;
const LEAF: u32 = 0x80000000u;

struct Params {
    eye: vec4f,
    // xyz: a polygon's emitting side's unit normal; w: the light's kind (common.wgsl).
    light_normal: vec4f,
    // w: 1 when textured (light_tex holds the texture).
    radiance: vec4f,
    // The light's shape (bspvt_shaders::gpu::lights).
    light: array<vec4f, 8>,
    // light vertices, jobs (visible vertices), codec offsets O, LTC table size.
    counts: vec4u,
    // x: the codec's half step √2 / O.
    codec: vec4f,
}

struct VertexOut {
    // rgb: radiance; w: flags (OVERFLOW).
    colour: vec4f,
    // shadowed / unshadowed per channel, diffuse and specular (1 where nothing is unshadowed).
    ratio_d: vec3f,
    pieces: u32,
    ratio_s: vec3f,
    dropped: u32,
}

// Storage, not uniform: lavapipe specializes a shader on the uniform values its branches
// read and compiles it again (a minute on 2 cores) whenever they change (docs/gpu.md).
@group(0) @binding(0) var<storage, read> params: Params;
// Four per vertex: position, normal, (albedo, α), (F0, 0).
@group(0) @binding(1) var<storage, read> verts: array<vec4f>;
@group(0) @binding(2) var<storage, read> jobs: array<u32>;
// Six per vertex: the node index of each face tree's root, ABSENT, or NO_TREES (face 0).
@group(0) @binding(3) var<storage, read> roots: array<u32>;
// x: LEAF | v̄ (0..255), or angle << 16 | offset; y: the right child, relative to the root.
@group(0) @binding(4) var<storage, read> nodes: array<vec2u>;
// LineCodec's normal table n(θ), f32 as on the CPU.
@group(0) @binding(5) var<storage, read> line_normals: array<vec2f>;
// Two per table node: (δ, ln m11, ln m22, q), (m31, magnitude, fresnel, 0).
@group(0) @binding(6) var<storage, read> ltc: array<vec4f>;
@group(0) @binding(7) var<storage, read_write> results: array<VertexOut>;
// The light's texture (LightTexture::gpu_words; a placeholder when untextured).
@group(0) @binding(8) var<storage, read> light_texture: array<vec4f>;

fn light_count() -> u32 {
    return params.counts.x;
}
fn light_word(i: u32) -> vec4f {
    return params.light[i];
}
fn light_normal() -> vec4f {
    return params.light_normal;
}
fn ltc_size() -> u32 {
    return params.counts.w;
}
fn light_textured() -> bool {
    return params.radiance.w != 0.0;
}
fn light_tex(i: u32) -> vec4f {
    return light_texture[i];
}
fn ltc_a(k: u32) -> vec4f {
    return ltc[2u * k];
}
fn ltc_b(k: u32) -> vec4f {
    return ltc[2u * k + 1u];
}

// (w, a, b) of each cube face, in proto/src/cubemap.rs order: +X, −X, +Y, −Y, +Z, −Z.
const FACE_W = array<vec3f, 6>(
    vec3f(1.0, 0.0, 0.0), vec3f(-1.0, 0.0, 0.0), vec3f(0.0, 1.0, 0.0),
    vec3f(0.0, -1.0, 0.0), vec3f(0.0, 0.0, 1.0), vec3f(0.0, 0.0, -1.0));
const FACE_A = array<vec3f, 6>(
    vec3f(0.0, 1.0, 0.0), vec3f(0.0, 0.0, 1.0), vec3f(0.0, 0.0, 1.0),
    vec3f(1.0, 0.0, 0.0), vec3f(1.0, 0.0, 0.0), vec3f(0.0, 1.0, 0.0));
const FACE_B = array<vec3f, 6>(
    vec3f(0.0, 0.0, 1.0), vec3f(0.0, 1.0, 0.0), vec3f(1.0, 0.0, 0.0),
    vec3f(0.0, 0.0, 1.0), vec3f(0.0, 1.0, 0.0), vec3f(1.0, 0.0, 0.0));

// The walk's stack.
var<private> stk_v: array<vec3f, STACK_VERTS>;
var<private> stk_node: array<u32, STACK_DEPTH>;
var<private> stk_n: array<u32, STACK_DEPTH>;

// LineCodec::plane: N = n.x·a + n.y·b − c·w with c(o) = (2o + 1 − O)·h. a, b, w are axes, so
// N is exactly the CPU's (f32 table values, f32 offset) — the side test differs only in the
// rounding of N·d.
fn line_plane(word: u32, f: u32) -> vec3f {
    let angle = word >> 16u;
    let offset = word & 0xffffu;
    let nrm = line_normals[angle];
    let c = f32(i32(2u * offset + 1u) - i32(params.counts.z)) * params.codec.x;
    return nrm.x * FACE_A[f] + nrm.y * FACE_B[f] - c * FACE_W[f];
}

// Pops the next pending piece into ig_src; returns (node, vertices) or node = ABSENT when the
// stack is empty.
var<private> sp: u32;
var<private> sv: u32;

fn pop() -> vec2u {
    if sp == 0u {
        return vec2u(ABSENT, 0u);
    }
    sp -= 1u;
    let count = stk_n[sp];
    sv -= count;
    for (var i = 0u; i < count; i++) {
        ig_src[i] = stk_v[sv + i];
    }
    return vec2u(stk_node[sp], count);
}

// Shaded::ratio: shadowed / unshadowed per channel in [0, 1]; 1 where nothing is unshadowed.
fn ratio3(s: vec3f, u: vec3f) -> vec3f {
    return select(vec3f(1.0), clamp(s / u, vec3f(0.0), vec3f(1.0)), u > vec3f(0.0));
}

// A vertex's surface and lobes (shade::Lobes::new): where, the unit normal, the material,
// the view's frame and the specular LTC.
struct Surface {
    p: vec3f,
    // Seen from behind (records::seen_from_behind): its trees are for its other side.
    behind: bool,
    n: vec3f,
    albedo: vec3f,
    spec: vec3f,
    frame: mat3x3f,
    lt: Ltc,
}

fn surface(v: u32) -> Surface {
    var s: Surface;
    s.p = verts[4u * v].xyz;
    s.behind = verts[4u * v].w < 0.0;
    // The renderer's normals are unit in f64 (render::renderer::vertex_surface); in f32
    // they are normalised again.
    let n0 = verts[4u * v + 1u].xyz;
    let nl = length(n0);
    s.n = select(vec3f(0.0, 1.0, 0.0), n0 / nl, nl > 0.0 && finite(nl));
    // The record holds the normal on the mesh's side (resolve.wgsl interpolates it per
    // pixel); a vertex seen from behind is shaded with it turned over.
    s.n = select(s.n, -s.n, s.behind);
    let albedo = verts[4u * v + 2u];
    let f0 = verts[4u * v + 3u].xyz;
    s.albedo = albedo.xyz;
    // The view, the frame, the LTC of (α, θ_view).
    var wo = params.eye.xyz - s.p;
    let lo = length(wo);
    wo = select(s.n, wo / lo, lo > 0.0 && finite(lo));
    s.frame = to_local(s.n, wo);
    let theta = atan2(length(cross(s.n, wo)), dot(s.n, wo));
    s.lt = ltc_lookup(albedo.w, theta);
    s.spec = f0 * s.lt.magnitude + (vec3f(1.0) - f0) * s.lt.fresnel;
    return s;
}

// Σ v̄ᵢ × each piece's integrals (with the light's colour) over the pieces vertex v's trees
// cut from dirs[0..nd]; `specular`: false for the diffuse integral alone (ss stays 0).
struct Walk {
    sd: vec3f,
    ss: vec3f,
    pieces: u32,
    dropped: u32,
}

fn walk(v: u32, nd: u32, em: Emitter, specular: bool) -> Walk {
    var out: Walk;
    out.sd = vec3f(0.0);
    out.ss = vec3f(0.0);
    out.pieces = 0u;
    out.dropped = 0u;
    let node_count = arrayLength(&nodes);
    for (var f = 0u; f < 6u; f++) {
        // tree::clip_to_face: |d·a| ≤ d·w, |d·b| ≤ d·w.
        for (var i = 0u; i < nd; i++) {
            ig_src[i] = dirs[i];
        }
        var count = nd;
        let w = FACE_W[f];
        count = clip_src(w - FACE_A[f], count);
        count = clip_src(w + FACE_A[f], count);
        count = clip_src(w - FACE_B[f], count);
        count = clip_src(w + FACE_B[f], count);
        if count < 3u {
            continue;
        }
        let root = roots[6u * v + f];
        if root == ABSENT {
            // bspvt::ABSENT_FACE_VALUE: visible.
            out.pieces += 1u;
            add_piece(&out, count, em, specular, 1.0);
            continue;
        }
        sp = 0u;
        sv = 0u;
        var node = root;
        // Every step moves down a valid tree (the decoder checks it); the cap only guards
        // against a corrupt buffer.
        for (var iter = 0u; iter < 65536u; iter++) {
            var next_piece = false;
            if node >= node_count {
                flags |= OVERFLOW;
                break;
            }
            let word = nodes[node];
            if (word.x & LEAF) != 0u {
                let value = word.x & 0xffu;
                if value == 0u {
                    out.dropped += 1u;
                } else {
                    out.pieces += 1u;
                    add_piece(&out, count, em, specular, f32(value) / 255.0);
                }
                next_piece = true;
            } else {
                let plane = line_plane(word.x, f);
                var pos = false;
                var neg = false;
                for (var i = 0u; i < count; i++) {
                    let d = dot(plane, ig_src[i]);
                    pos = pos || d > 0.0;
                    neg = neg || d < 0.0;
                }
                if !pos && !neg {
                    next_piece = true;
                } else if !pos {
                    node += 1u;
                } else if !neg {
                    node = root + word.y;
                } else {
                    // sphere::cut_into: n·d ≤ 0 into tmp (walked on), n·d ≥ 0 onto the stack.
                    var kn = 0u;
                    var kp = 0u;
                    let room = min(MAXV, STACK_VERTS - sv);
                    for (var i = 0u; i < count; i++) {
                        let a = ig_src[i];
                        let b = ig_src[(i + 1u) % count];
                        let da = dot(plane, a);
                        let db = dot(plane, b);
                        if da <= 0.0 {
                            if kn < MAXV { tmp[kn] = a; kn++; } else { flags |= OVERFLOW; }
                        }
                        if da >= 0.0 {
                            if kp < room { stk_v[sv + kp] = a; kp++; } else { flags |= OVERFLOW; }
                        }
                        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
                            let x = a + (b - a) * (da / (da - db));
                            if kn < MAXV { tmp[kn] = x; kn++; } else { flags |= OVERFLOW; }
                            if kp < room { stk_v[sv + kp] = x; kp++; } else { flags |= OVERFLOW; }
                        }
                    }
                    if kp >= 3u {
                        if sp < STACK_DEPTH {
                            stk_node[sp] = root + word.y;
                            stk_n[sp] = kp;
                            sp += 1u;
                            sv += kp;
                        } else {
                            flags |= OVERFLOW;
                        }
                    }
                    if kn >= 3u {
                        for (var i = 0u; i < kn; i++) {
                            ig_src[i] = tmp[i];
                        }
                        count = kn;
                        node += 1u;
                    } else {
                        next_piece = true;
                    }
                }
            }
            if next_piece {
                let top = pop();
                if top.x == ABSENT {
                    break;
                }
                node = top.x;
                count = top.y;
            }
        }
    }
    return out;
}

// Adds the piece ig_src[0..count] weighted by v̄ to `out`.
fn add_piece(out: ptr<function, Walk>, count: u32, em: Emitter, specular: bool, vbar: f32) {
    if specular {
        let pc = shade_piece(count, em);
        (*out).sd += vbar * pc.d.xyz;
        (*out).ss += vbar * pc.s.xyz;
    } else {
        (*out).sd += vec3f(vbar * integrate_poly(em.frame, count));
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3u) {
    if gid.x >= params.counts.y {
        return;
    }
    let v = jobs[gid.x];
    let s = surface(v);
    flags = 0u;
    // Light::radiance_toward: a spot's cone and a range's window scale a sphere's.
    let radiance = params.radiance.xyz * light_falloff(s.p);

    var res: VertexOut;
    res.colour = vec4f(0.0);
    res.ratio_d = vec3f(1.0);
    res.ratio_s = vec3f(1.0);
    res.pieces = 0u;
    res.dropped = 0u;

    let nd = light_directions(s.p, s.n);
    if nd < 3u {
        results[v] = res;
        return;
    }
    let em = emitter(s.p, s.frame, s.lt);
    let un = shade_piece(nd, em);
    let ud = un.d.w;
    let us = un.s.w;
    let root0 = roots[6u * v];
    if root0 == NO_TREES || s.behind {
        // Trees not streamed in yet, or seen from behind: unshadowed
        // (render::renderer::Renderer::vertex_trees).
        res.colour = vec4f(radiance * (s.albedo * un.d.xyz + s.spec * un.s.xyz), 0.0);
        results[v] = res;
        return;
    }
    if !(ud > 0.0) && !(us > 0.0) {
        results[v] = res;
        return;
    }

    let cut = walk(v, nd, em, true);
    res.pieces = cut.pieces;
    res.dropped = cut.dropped;
    var c = radiance * (s.albedo * cut.sd + s.spec * cut.ss);
    if !finite3(c) {
        c = vec3f(0.0);
        flags |= OVERFLOW;
    }
    res.colour = vec4f(c, f32(flags));
    res.ratio_d = ratio3(cut.sd, un.d.xyz);
    res.ratio_s = ratio3(cut.ss, un.s.xyz);
    results[v] = res;
}
