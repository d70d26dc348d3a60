// Visibility cube maps (the bake's, one invocation per vertex and pixel) from any-hit occlusion
// rays over obvhs's compressed wide BVH (CWBVH, Ylitie et al. 2017), the GPU twin of
// `Occluder::occluded_between` (proto/raytrace/src/lib.rs): the same nodes, the same
// triangles in BVH primitive order, the same traversal order (obvhs's `traverse!` macro) and the
// same Möller–Trumbore test (obvhs's `RtTriangle::intersect`). A ray is occluded when a triangle
// not using its `skip` vertex is hit at a distance in [t_min, t_max).

// The CWBVH's nodes (cwbvh.wgsl, prepended).
@group(0) @binding(0) var<storage, read> nodes: array<u32>;
// RtTriangle per primitive, 16 floats: v0, e1 (= v0 - v1), e2 (= v2 - v0), ng (= e1 × e2),
// then |e1|, |e2|, |ng| (bounds for `judge`) and 0.
@group(0) @binding(1) var<storage, read> tris: array<f32>;
// The three mesh vertex indices of each primitive.
@group(0) @binding(2) var<storage, read> prim_verts: array<u32>;
// Per vertex of the dispatch, two vec4: origin.xyz and t_min (f32 bits); normal.xyz (f32 bits)
// and the vertex's index (triangles using it are skipped).
@group(0) @binding(3) var<storage, read> sources: array<vec4<u32>>;
// The sub-ray directions of every pixel of the cube map, face-major, then pixel (j·res + i),
// then sub-sample: xyz (unit), w unused (RayTable::sub, as the CPU casts them).
@group(0) @binding(4) var<storage, read> dirs: array<vec4<f32>>;
// Per vertex, per 32 pixels (face·res² + pixel): a bitmask of the pixels that matter, chosen on
// the CPU (VertexRays::matters) so that the sets are the CPU's exactly, and the number of
// pixels that matter before them in the dispatch (where their counts go).
@group(0) @binding(5) var<storage, read> mask: array<vec2<u32>>;
// Where rays end (cubemap::LightStop), ten vec4 per stop: a region box (min.xyz, 0),
// (max.xyz, 0); a plane (point.xyz, 1), (normal.xyz, 0); or a fixed lamp (normal.xyz, 2),
// (offset, spread, edges, two-sided), then per edge (inward in-plane normal, offset); or a
// point or spot light's sphere (centre.xyz, 3), (radius, spread, 0, 0).
@group(0) @binding(6) var<storage, read> stops: array<vec4<f32>>;
// Per pixel that matters, in order, 16 bits (two per word): escaping sub-rays | cast sub-rays
// << 8 (at most 64 each: supersampling ≤ 8).
@group(0) @binding(7) var<storage, read_write> counts: array<atomic<u32>>;
struct CubeParams {
    // vertices in this dispatch, pixels per vertex, sub-rays per pixel, stops.
    shape: vec4<u32>,
    // invocations per row of the dispatch grid, mask words per vertex, and two test hooks
    // (GpuCubeTable::skew_rounding): a skew of every reciprocal and quotient in ULP (another
    // device's rounding), 1 for plain answers (every decision as computed, none unsure).
    grid: vec4<u32>,
    // x: the nearest distance a child box is entered at (f32 bits; `Occluder::box_t_min`).
    box: vec4<u32>,
}
// Storage, not uniform: lavapipe specializes a shader on the uniform values its branches
// read and compiles it again (a minute on 2 cores) whenever they change (docs/gpu.md).
@group(0) @binding(8) var<storage, read> cp: CubeParams;
// The alpha cut-outs (Cutouts::gpu_words): a header (1, first entry word, first mask word, 0) —
// a single 0 word when every surface is opaque —, each primitive's entry (0: opaque), 8 words
// per entry (mask, has UVs, the corners' UVs), 16 per mask (width, height, first texel word,
// wrap u, wrap v, alpha, cut-off, mean alpha, the UV transform's a, b, c, d, tx, ty, 2 unused),
// the masks' alpha bytes four to a word.
@group(0) @binding(9) var<storage, read> cut: array<u32>;


fn box_t_min() -> f32 {
    return bitcast<f32>(cp.box.x);
}

// What a test decided: surely not, within rounding of the other way, or surely. In this order,
// `min` is "and" (MISS if any is, else UNSURE if any is) and 2 − x is "not".
const MISS: u32 = 0u;
const UNSURE: u32 = 1u;
const HIT: u32 = 2u;
// How far this device's value of a quantity may be from the CPU's, relative to the magnitudes
// it is made of: WGSL allows 2.5 ULP for a division and lets a compiler fuse a·b + c (the CPU
// rounds each IEEE-exactly); 2⁻¹⁶ is 128 ULP. A decision closer than that to the other way
// makes the pixel "unsure", and the CPU casts it again (Baker::gpu_cube_maps), so the two
// machines give the same cube map whatever the device's rounding.
const ROUNDING: f32 = 1.52587890625e-5; // 2^-16
// Set when a child box's test was unsure (the box is then entered: the traversal sees a superset
// of the CPU's triangles, so its sure misses hold; a hit is sure only with no unsure box).
var<private> unsure_box: bool;

// A quotient as a device that rounds division less well would give it (a test's skew, ULP;
// ×1 exactly without one).
fn skewed(x: f32) -> f32 {
    return x * (1.0 + f32(cp.grid.z) * F32_EPSILON);
}

// obvhs's ray::safe_inverse (signum(±0) = ±1).
fn safe_inverse(x: f32) -> f32 {
    if abs(x) <= F32_EPSILON {
        let s = select(1.0, -1.0, (bitcast<u32>(x) & 0x80000000u) != 0u);
        return s / F32_EPSILON;
    }
    return skewed(1.0 / x);
}

// CwBvhNode::intersect_ray (intersect_ray_basic): the hit mask of the node's children, by the
// CPU's box test (a relative slack here made the answers differ more, not less: 1,012 vs 89
// sub-rays per million on the room's dyadic grid, tests/tests/cast_gpu.rs). A child whose
// entry and exit are within rounding of each other is decided pair by pair (`box_pairs`), and
// entered when unsure (`unsure_box`). `t_err`: how far `t_max` may be from the CPU's.
fn intersect_node(n: u32, o: vec3<f32>, inv_d: vec3<f32>, neg: vec3<bool>, t_max: f32, t_err: f32, oct_inv4: u32) -> u32 {
    let frame = node_frame(n, o, inv_d);
    let adj_inv = frame[0];
    let adj_o = frame[1];
    var hit_mask = 0u;
    for (var c = 0u; c < 8u; c++) {
        let child_meta = node_byte(n, 6u, c);
        if child_meta == 0u {
            continue; // empty slot
        }
        let box = child_near_far(n, c, neg);
        let near = box[0];
        let far = box[1];
        let t0 = near * adj_inv + adj_o;
        let t1 = far * adj_inv + adj_o;
        let tmin = max(max(max(t0.x, t0.y), t0.z), box_t_min());
        let tmax = min(min(min(t1.x, t1.y), t1.z), t_max);
        var enter = tmin <= tmax;
        if cp.grid.w == 0u {
            // Each slab's t = q·a + b (q a quantized bound, 0..255) may be rounded once or
            // twice: off by ROUNDING × (q |a| + |b|). The answer is sure when it holds with
            // every entry moved its error toward the exits and every exit toward the entries
            // (entering) or away (not); else decided pair by pair.
            let e0 = ROUNDING * (near * abs(adj_inv) + abs(adj_o));
            let e1 = ROUNDING * (far * abs(adj_inv) + abs(adj_o));
            let k = select(-1.0, 1.0, enter);
            let lo = max(max(max(t0.x + k * e0.x, t0.y + k * e0.y), t0.z + k * e0.z), box_t_min());
            let hi = min(min(min(t1.x - k * e1.x, t1.y - k * e1.y), t1.z - k * e1.z), t_max - k * t_err);
            if select(lo > hi, lo < hi, enter) == false {
                let d = box_pairs(t0, e0, t1, e1, box_t_min(), t_max, t_err);
                enter = d != MISS;
                unsure_box = unsure_box || d == UNSURE;
            }
        }
        if enter {
            hit_mask |= child_hit_bits(child_meta, oct_inv4);
        }
    }
    return hit_mask;
}

// Whether a box with slab entries `t0` and exits `t1` (errors `e0`, `e1`) is entered between
// `lowest` and `t_max` (error `t_err`): every entry ≤ every exit. An entry and the exit of its
// own axis are never swapped by rounding (both round the same monotone function of near ≤ far),
// so only the other pairs can make the two machines disagree.
fn box_pairs(t0: vec3<f32>, e0: vec3<f32>, t1: vec3<f32>, e1: vec3<f32>, lowest: f32, t_max: f32, t_err: f32) -> u32 {
    let a = array<f32, 4>(t0.x, t0.y, t0.z, lowest);
    let ea = array<f32, 4>(e0.x, e0.y, e0.z, 0.0);
    let b = array<f32, 4>(t1.x, t1.y, t1.z, t_max);
    let eb = array<f32, 4>(e1.x, e1.y, e1.z, t_err);
    var sure = true;
    for (var i = 0u; i < 4u; i++) {
        for (var j = 0u; j < 4u; j++) {
            if i == j && i < 3u {
                continue;
            }
            let gap = b[j] - a[i];
            let err = ea[i] + eb[j];
            if gap < -err {
                return MISS;
            }
            sure = sure && gap > err;
        }
    }
    return select(UNSURE, HIT, sure);
}

// bspvt_raytrace::hit (closed Möller–Trumbore: barycentrics down to -EDGE_SLACK count), as a
// "blocks" test: a hit at t in [t_min, t_max) (`t_err`: how far t_max may be from the CPU's).
// UNSURE when a barycentric, t or the cut-out's alpha is within rounding of its limit: the
// bounds below are ROUNDING × the magnitudes each value is made of (|r| ≤ |d||c|), over |det|.
const EDGE_SLACK: f32 = 9.5367431640625e-7; // 2^-20
fn blocks(id: u32, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, t_err: f32) -> u32 {
    let b = id * 16u;
    let v0 = vec3<f32>(tris[b], tris[b + 1u], tris[b + 2u]);
    let e1 = vec3<f32>(tris[b + 3u], tris[b + 4u], tris[b + 5u]);
    let e2 = vec3<f32>(tris[b + 6u], tris[b + 7u], tris[b + 8u]);
    let ng = vec3<f32>(tris[b + 9u], tris[b + 10u], tris[b + 11u]);
    let c = v0 - o;
    let r = cross(d, c);
    let det = dot(ng, d);
    let inv_det = skewed(1.0 / det);
    // The numerators of u and v.
    let n = vec2<f32>(dot(r, e2), dot(r, e1));
    let u = n.x * inv_det;
    let v = n.y * inv_det;
    let w = 1.0 - u - v;
    if cp.grid.w == 1u {
        let t = dot(ng, c) * inv_det;
        let inside = inv_det != 0.0 && u >= -EDGE_SLACK && v >= -EDGE_SLACK && w >= -EDGE_SLACK;
        return select(MISS, HIT, inside && t >= t_min && t < t_max && covers(id, vec3<f32>(w, u, v)));
    }
    // A determinant that is exactly 0 is 0 on both machines (products of zeros): a miss.
    if det == 0.0 {
        return MISS;
    }
    // |d| = 1 (the table's unit directions), |c| bounded by |c|₁ (no square root: ≤ √3 ×
    // looser), the triangle's own norms stored with it.
    let norms = vec3<f32>(tris[b + 12u], tris[b + 13u], tris[b + 14u]);
    return judge(id, u, v, w, n, det, dot(ng, c) * inv_det, norm1(c), norms, t_min, t_max, t_err);
}

// The decision of `blocks` for barycentrics u, v, w (numerators `n` of u and v over det) and
// distance t, given bounds on |c| and on |e1|, |e2|, |ng| (`norms`): each quantity's error is
// ROUNDING × the magnitudes it is made of (|r| ≤ |d||c|). Compared as numerators (u·|det|
// against -EDGE_SLACK·|det|, …): no division.
fn judge(id: u32, u: f32, v: f32, w: f32, n: vec2<f32>, det: f32, t: f32, nc: f32, norms: vec3<f32>, t_min: f32, t_max: f32, t_err: f32) -> u32 {
    let ad = abs(det);
    let e_det = ROUNDING * 1.00001 * norms.z;
    let e_nu = ROUNDING * nc * norms.y;
    let e_nv = ROUNDING * nc * norms.x;
    if ad <= e_det {
        // The ray is edge-on to the plane: det's sign is unsure. The barycentrics' numerators
        // sum to det ≈ 0, so when all three are clearly non-zero two have opposite signs and
        // one barycentric is far below -EDGE_SLACK whichever det's sign: a sure miss.
        let nw = det - n.x - n.y;
        let slack = EDGE_SLACK * (ad + e_det);
        if abs(n.x) > e_nu + slack && abs(n.y) > e_nv + slack && abs(nw) > e_det + e_nu + e_nv + slack {
            return MISS;
        }
        return UNSURE;
    }
    let s = -EDGE_SLACK * ad;
    // Most tests end at the first barycentric.
    let e_u = e_nu + abs(u) * e_det;
    let bu = sure_at_least(u * ad, s, e_u);
    if bu == MISS {
        return MISS;
    }
    let e_v = e_nv + abs(v) * e_det;
    let bv = sure_at_least(v * ad, s, e_v);
    if bv == MISS {
        return MISS;
    }
    let e_w = e_u + e_v + ROUNDING * ad * (1.0 + abs(u) + abs(v));
    let bary = min(min(bu, bv), sure_at_least(w * ad, s, e_w));
    if bary == MISS {
        return MISS;
    }
    let e_t = ROUNDING * norms.z * nc + abs(t) * e_det;
    let near = sure_at_least(t * ad, t_min * ad, e_t);
    // t < t_max: not t ≥ t_max.
    let far = HIT - sure_at_least(t * ad, t_max * ad, e_t + t_err * ad);
    let hit = min(min(bary, near), far);
    if hit == MISS {
        return MISS;
    }
    let a = coverage(id, vec3<f32>(w, u, v), max(max(e_u, e_v), e_w) / ad);
    let cover = sure_at_least(a.x, 0.0, a.y);
    return min(hit, cover);
}

// |x|₁ ≥ |x|.
fn norm1(x: vec3<f32>) -> f32 {
    return abs(x.x) + abs(x.y) + abs(x.z);
}

// Whether x ≥ limit: HIT, MISS, or UNSURE when |x − limit| ≤ err.
fn sure_at_least(x: f32, limit: f32, err: f32) -> u32 {
    // Without error (values both machines compute alike) the comparison itself.
    if err == 0.0 {
        return select(MISS, HIT, x >= limit);
    }
    if x - limit > err {
        return HIT;
    }
    if limit - x > err {
        return MISS;
    }
    return UNSURE;
}

fn uses_vertex(id: u32, skip: u32) -> bool {
    let b = id * 3u;
    return prim_verts[b] == skip || prim_verts[b + 1u] == skip || prim_verts[b + 2u] == skip;
}

// obvhs's `traverse!` with `ray_traverse_miss`'s early exit: HIT, MISS, or UNSURE when this
// device's rounding may have decided it otherwise than the CPU's (`t_err`: how far `t_max` may
// be from the CPU's). A miss is sure when every triangle tested missed surely (unsure boxes were
// entered); a hit when a triangle was hit surely and no box was unsure.
fn is_occluded(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, t_err: f32, skip: u32) -> u32 {
    let inv_d = vec3<f32>(safe_inverse(d.x), safe_inverse(d.y), safe_inverse(d.z));
    let neg = d < vec3<f32>(0.0);
    let oct_inv4 = octant_inv4(neg);
    var stack: array<vec2<u32>, STACK_SIZE>;
    var sp = 0u;
    var current = vec2<u32>(0u, 0x80000000u);
    var prims = vec2<u32>(0u, 0u);
    var answer = MISS;
    unsure_box = false;
    loop {
        while prims.y != 0u {
            let local = firstLeadingBit(prims.y);
            prims.y &= ~(1u << local);
            let id = prims.x + local;
            if !uses_vertex(id, skip) {
                let hit = blocks(id, o, d, t_min, t_max, t_err);
                if hit == HIT {
                    return select(HIT, UNSURE, unsure_box);
                }
                answer = max(answer, hit);
            }
        }
        prims = vec2<u32>(0u, 0u);
        if (current.y & 0xff000000u) != 0u {
            let hits_imask = current.y;
            let offset = firstLeadingBit(hits_imask);
            current.y &= ~(1u << offset);
            if (current.y & 0xff000000u) != 0u {
                if sp < STACK_SIZE {
                    stack[sp] = current;
                    sp++;
                } else {
                    // Children left untested: a miss is no longer sure.
                    answer = max(answer, UNSURE);
                }
            }
            let n = child_node(vec2<u32>(current.x, hits_imask), offset, oct_inv4);
            let next = enter_node(n, intersect_node(n, o, inv_d, neg, t_max, t_err, oct_inv4));
            current = next[0];
            prims = next[1];
        } else {
            current = vec2<u32>(0u, 0u);
        }
        if prims.y == 0u && (current.y & 0xff000000u) == 0u {
            if sp == 0u {
                break;
            }
            sp--;
            current = stack[sp];
        }
    }
    return answer;
}

const F32_MAX: f32 = 3.40282347e38;

fn is_nan(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7fffffffu) > 0x7f800000u;
}

// f32::min and f32::max (glam's Vec3 min/max per component): a NaN operand loses.
fn fmin(a: f32, b: f32) -> f32 {
    if is_nan(a) {
        return b;
    }
    if is_nan(b) {
        return a;
    }
    return min(a, b);
}

fn fmax(a: f32, b: f32) -> f32 {
    if is_nan(a) {
        return b;
    }
    if is_nan(b) {
        return a;
    }
    return max(a, b);
}

// VertexRays::t_max: the distance at which the ray from o along unit d reaches its first stop
// (LightStop::distance: Aabb::ray_entry for a region, the plane crossing for a light moving in
// its plane, the crossing within the grown polygon for a fixed lamp, the entry into the grown
// sphere of a point or spot light); f32::MAX when it reaches none. Ten vec4 per stop
// (gpu_occluder.rs, STOP_WORDS). Returns (t, how far t may be from the CPU's); sets
// `unsure_end` when whether a stop is reached is within rounding of the other way.
var<private> unsure_end: bool;
fn ray_end(o: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    var t = F32_MAX;
    var err = 0.0;
    unsure_end = false;
    for (var k = 0u; k < cp.shape.w; k++) {
        let a = stops[10u * k];
        let b = stops[10u * k + 1u];
        var tk = F32_MAX;
        var ek = 0.0;
        if a.w == 0.0 {
            let inv = vec3<f32>(skewed(1.0 / d.x), skewed(1.0 / d.y), skewed(1.0 / d.z));
            let t0 = (a.xyz - o) * inv;
            let t1 = (b.xyz - o) * inv;
            let near = min(t0, t1);
            let far = max(t0, t1);
            let enter = fmax(fmax(fmin(t0.x, t1.x), fmin(t0.y, t1.y)), fmin(t0.z, t1.z));
            let exit = fmin(fmin(fmax(t0.x, t1.x), fmax(t0.y, t1.y)), fmax(t0.z, t1.z));
            // A slab's t is a difference times a quotient: off by ROUNDING × |t|.
            let en = ROUNDING * abs(near);
            let ef = ROUNDING * abs(far);
            let e_enter = max(max(en.x, en.y), en.z);
            if enter > 0.0 && enter <= exit {
                tk = enter;
                ek = e_enter;
            }
            // Whether the box is ahead (its entry against 0), and whether the ray meets it.
            unsure_end = unsure_end || abs(enter) <= e_enter;
            if abs(enter - exit) <= e_enter + max(max(ef.x, ef.y), ef.z) {
                unsure_end = unsure_end || box_pairs(near, en, far, ef, -F32_MAX, F32_MAX, 0.0) == UNSURE;
            }
        } else if a.w == 1.0 {
            let den = dot(d, b.xyz);
            let h = dot(a.xyz - o, b.xyz);
            let tp = skewed(h / den);
            let e_den = ROUNDING * length(d) * length(b.xyz);
            let e_h = ROUNDING * length(a.xyz - o) * length(b.xyz);
            if den != 0.0 && tp > 0.0 && tp <= F32_MAX {
                tk = tp;
                ek = (e_h + abs(tp) * e_den) / abs(den);
            }
            unsure_end = unsure_end || (den != 0.0 && (abs(den) <= e_den || abs(h) <= e_h));
        } else if a.w == 3.0 {
            // SphereStop::distance.
            let oc = a.xyz - o;
            let tc = dot(oc, d);
            let l2 = dot(oc, oc);
            let e_tc = ROUNDING * length(oc);
            unsure_end = unsure_end || abs(tc) <= e_tc;
            if !(tc > 0.0) {
                continue;
            }
            let perp2 = max(l2 - tc * tc, 0.0);
            let grown = b.x + 2.0 * tc * b.y;
            let e_perp2 = ROUNDING * 4.0 * (l2 + tc * tc);
            let e_grown2 = 2.0 * grown * (ROUNDING * grown + 2.0 * e_tc * b.y);
            unsure_end = unsure_end || abs(perp2 - grown * grown) <= e_perp2 + e_grown2;
            if !(perp2 <= grown * grown) {
                continue;
            }
            let under = max(b.x * b.x - perp2, 0.0);
            let ts = tc - sqrt(under);
            // √ of a value off by e: off by ≤ √e (by e / 2√x where that is smaller).
            let e_under = e_perp2 + ROUNDING * b.x * b.x;
            let e_ts = e_tc + min(sqrt(e_under), e_under / max(2.0 * sqrt(under), 1e-30)) + ROUNDING * abs(ts);
            unsure_end = unsure_end || abs(ts) <= e_ts;
            if ts > 0.0 && ts <= F32_MAX {
                tk = ts;
                ek = e_ts;
            }
        } else {
            // LampStop::distance.
            let height = b.x - dot(a.xyz, o);
            let e_height = ROUNDING * (abs(b.x) + length(a.xyz) * length(o));
            let den = dot(d, a.xyz);
            let e_den = ROUNDING * length(d) * length(a.xyz);
            // The side of the lamp the origin is on, and the direction's.
            unsure_end = unsure_end || abs(height) <= e_height || (den != 0.0 && abs(den) <= e_den);
            if b.w == 0.0 && !(height < 0.0) {
                continue;
            }
            let tp = skewed(height / den);
            if !(den != 0.0 && tp > 0.0 && tp <= F32_MAX) || abs(den) <= e_den {
                continue;
            }
            let e_tp = (e_height + abs(tp) * e_den) / abs(den);
            let x = o + tp * d;
            let e_x = ROUNDING * (length(o) + abs(tp)) + e_tp;
            let grow = tp * b.y / abs(den);
            let e_grow = (e_tp * b.y + abs(grow) * e_den) / abs(den) + ROUNDING * abs(grow);
            var inside = true;
            for (var e = 0u; e < u32(b.z); e++) {
                let m = stops[10u * k + 2u + e];
                let side = dot(m.xyz, x) - m.w;
                if side < -grow {
                    inside = false;
                }
                let e_side = ROUNDING * (length(m.xyz) * length(x) + abs(m.w)) + length(m.xyz) * e_x + e_grow;
                unsure_end = unsure_end || abs(side + grow) <= e_side;
            }
            if inside {
                tk = tp;
                ek = e_tp;
            }
        }
        // The nearest stop; two within their errors of each other keep the larger error.
        if tk < t {
            err = select(ek, max(err, ek), t - tk <= err + ek);
            t = tk;
        } else if tk - t <= err + ek {
            err = max(err, ek);
        }
    }
    return vec2<f32>(t, err);
}

// One pixel that matters of one vertex's cube map (VertexRays::cast_brute_force): each sub-ray
// below the vertex's horizon escapes uncast; the others are cast to their stop.
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * cp.grid.x + gid.x;
    let pixels = cp.shape.y;
    if i >= cp.shape.x * pixels {
        return;
    }
    let k = i / pixels;
    let p = i % pixels;
    let m = mask[k * cp.grid.y + p / 32u];
    let bit = 1u << (p % 32u);
    if (m.x & bit) == 0u {
        return;
    }
    let slot = m.y + countOneBits(m.x & (bit - 1u));
    let a = sources[2u * k];
    let b = sources[2u * k + 1u];
    let o = bitcast<vec3<f32>>(a.xyz);
    let t_min = bitcast<f32>(a.w);
    let n = bitcast<vec3<f32>>(b.xyz);
    let skip = b.w;
    let s = cp.shape.z;
    var escaping = 0u;
    var casts = 0u;
    var unsure = false;
    for (var j = 0u; j < s; j++) {
        let d = dirs[p * s + j].xyz;
        // Below the horizon: sure when every product is 0 (both machines get exactly 0) or the
        // dot product is clear of 0.
        let dn = d * n;
        let above = dn.x + dn.y + dn.z;
        let e_dn = ROUNDING * (abs(dn.x) + abs(dn.y) + abs(dn.z));
        unsure = unsure || abs(above) <= e_dn && e_dn > 0.0;
        if above <= 0.0 {
            escaping++;
            continue;
        }
        casts++;
        let end = ray_end(o, d);
        let hit = is_occluded(o, d, t_min, end.x, end.y, skip);
        unsure = unsure || unsure_end || hit == UNSURE;
        if hit != HIT {
            escaping++;
        }
    }
    // Escaping and cast counts are ≤ 64: bit 7 flags a pixel for the CPU to cast again.
    let flag = select(0u, 0x80u, unsure && cp.grid.w == 0u);
    atomicOr(&counts[slot / 2u], (escaping | flag | (casts << 8u)) << (16u * (slot % 2u)));
}
