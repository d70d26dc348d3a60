// Visibility cube maps (the bake's, one invocation per vertex and pixel) from any-hit occlusion
// rays over obvhs's compressed wide BVH (CWBVH, Ylitie et al. 2017), the GPU twin of
// `Occluder::occluded_between` (proto/raytrace/src/lib.rs): the same nodes, the same
// triangles in BVH primitive order, the same traversal order (obvhs's `traverse!` macro) and the
// same Möller–Trumbore test (obvhs's `RtTriangle::intersect`). A ray is occluded when a triangle
// not using its `skip` vertex is hit at a distance in [t_min, t_max).

// CwBvhNode (80 bytes, repr(C)) as 20 words: p.xyz, e[3] | imask << 24, child_base_idx,
// primitive_base_idx, child_meta (2 words), then child_{min,max}_{x,y,z} (2 words each).
@group(0) @binding(0) var<storage, read> nodes: array<u32>;
// RtTriangle per primitive, 12 floats: v0, e1 (= v0 - v1), e2 (= v2 - v0), ng (= e1 × e2).
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
    // invocations per row of the dispatch grid, mask words per vertex.
    grid: vec4<u32>,
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

// obvhs's cwbvh::node::EPSILON: a child box is entered no nearer than this.
const BOX_T_MIN: f32 = 0.0001;
// f32::EPSILON, for obvhs's `safe_inverse`.
const F32_EPSILON: f32 = 1.1920929e-7;
const STACK_SIZE: u32 = 32u;

// obvhs's ray::safe_inverse (signum(±0) = ±1).
fn safe_inverse(x: f32) -> f32 {
    if abs(x) <= F32_EPSILON {
        let s = select(1.0, -1.0, (bitcast<u32>(x) & 0x80000000u) != 0u);
        return s / F32_EPSILON;
    }
    return 1.0 / x;
}

fn byte_of(w: u32, i: u32) -> u32 {
    return (w >> (8u * i)) & 0xffu;
}

// Byte `c` (0..8) of the 8-byte field starting at word `w` of node `n`.
fn node_byte(n: u32, w: u32, c: u32) -> u32 {
    return byte_of(nodes[n * 20u + w + c / 4u], c % 4u);
}

// CwBvhNode::intersect_ray (intersect_ray_basic): the hit mask of the node's children, by the
// CPU's box test (a relative slack here made the answers differ more, not less: 1,012 vs 89
// sub-rays per million on the room's dyadic grid, tests/tests/cast_gpu.rs).
fn intersect_node(n: u32, o: vec3<f32>, inv_d: vec3<f32>, neg: vec3<bool>, t_max: f32, oct_inv4: u32) -> u32 {
    let b = n * 20u;
    let p = vec3<f32>(bitcast<f32>(nodes[b]), bitcast<f32>(nodes[b + 1u]), bitcast<f32>(nodes[b + 2u]));
    let ew = nodes[b + 3u];
    let extent = vec3<f32>(
        bitcast<f32>(byte_of(ew, 0u) << 23u),
        bitcast<f32>(byte_of(ew, 1u) << 23u),
        bitcast<f32>(byte_of(ew, 2u) << 23u),
    );
    let adj_inv = extent * inv_d;
    let adj_o = (p - o) * inv_d;
    var hit_mask = 0u;
    for (var c = 0u; c < 8u; c++) {
        let child_meta = node_byte(n, 6u, c);
        if child_meta == 0u {
            continue; // empty slot
        }
        let lo = vec3<f32>(f32(node_byte(n, 8u, c)), f32(node_byte(n, 12u, c)), f32(node_byte(n, 16u, c)));
        let hi = vec3<f32>(f32(node_byte(n, 10u, c)), f32(node_byte(n, 14u, c)), f32(node_byte(n, 18u, c)));
        let near = select(lo, hi, neg);
        let far = select(hi, lo, neg);
        let t0 = near * adj_inv + adj_o;
        let t1 = far * adj_inv + adj_o;
        let tmin = max(max(max(t0.x, t0.y), t0.z), BOX_T_MIN);
        let tmax = min(min(min(t1.x, t1.y), t1.z), t_max);
        if tmin <= tmax {
            // CwBvhNode::get_child_and_index_bits, one byte at a time.
            let inner = ((child_meta & (child_meta << 1u)) & 0x10u) != 0u;
            let oct = select(0u, oct_inv4 & 0xffu, inner);
            let bit_index = (child_meta ^ oct) & 0x1fu;
            let child_bits = (child_meta >> 5u) & 7u;
            hit_mask |= child_bits << bit_index;
        }
    }
    return hit_mask;
}

// bspvt_raytrace::hit (closed Möller–Trumbore: barycentrics down to -EDGE_SLACK count), as a
// "blocks" test: a hit at t in [t_min, t_max).
const EDGE_SLACK: f32 = 9.5367431640625e-7; // 2^-20
fn blocks(id: u32, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    let b = id * 12u;
    let v0 = vec3<f32>(tris[b], tris[b + 1u], tris[b + 2u]);
    let e1 = vec3<f32>(tris[b + 3u], tris[b + 4u], tris[b + 5u]);
    let e2 = vec3<f32>(tris[b + 6u], tris[b + 7u], tris[b + 8u]);
    let ng = vec3<f32>(tris[b + 9u], tris[b + 10u], tris[b + 11u]);
    let c = v0 - o;
    let r = cross(d, c);
    let inv_det = 1.0 / dot(ng, d);
    let u = dot(r, e2) * inv_det;
    let v = dot(r, e1) * inv_det;
    let w = 1.0 - u - v;
    if !(inv_det != 0.0 && u >= -EDGE_SLACK && v >= -EDGE_SLACK && w >= -EDGE_SLACK) {
        return false;
    }
    let t = dot(ng, c) * inv_det;
    return t >= t_min && t < t_max && covers(id, vec3<f32>(w, u, v));
}

fn uses_vertex(id: u32, skip: u32) -> bool {
    let b = id * 3u;
    return prim_verts[b] == skip || prim_verts[b + 1u] == skip || prim_verts[b + 2u] == skip;
}

// obvhs's `traverse!` with `ray_traverse_miss`'s early exit.
fn is_occluded(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, skip: u32) -> bool {
    let inv_d = vec3<f32>(safe_inverse(d.x), safe_inverse(d.y), safe_inverse(d.z));
    let neg = d < vec3<f32>(0.0);
    let oct_inv4 = select(0x04040404u, 0u, neg.x) | select(0x02020202u, 0u, neg.y) | select(0x01010101u, 0u, neg.z);
    var stack: array<vec2<u32>, STACK_SIZE>;
    var sp = 0u;
    var current = vec2<u32>(0u, 0x80000000u);
    var prims = vec2<u32>(0u, 0u);
    loop {
        while prims.y != 0u {
            let local = firstLeadingBit(prims.y);
            prims.y &= ~(1u << local);
            let id = prims.x + local;
            if !uses_vertex(id, skip) && blocks(id, o, d, t_min, t_max) {
                return true;
            }
        }
        prims = vec2<u32>(0u, 0u);
        if (current.y & 0xff000000u) != 0u {
            let hits_imask = current.y;
            let offset = firstLeadingBit(hits_imask);
            current.y &= ~(1u << offset);
            if (current.y & 0xff000000u) != 0u && sp < STACK_SIZE {
                stack[sp] = current;
                sp++;
            }
            let slot = (offset - 24u) ^ (oct_inv4 & 0xffu);
            let relative = countOneBits(hits_imask & ~(0xffffffffu << slot));
            let n = current.x + relative;
            let hit_mask = intersect_node(n, o, inv_d, neg, t_max, oct_inv4);
            current.x = nodes[n * 20u + 4u];
            prims.x = nodes[n * 20u + 5u];
            current.y = (hit_mask & 0xff000000u) | (nodes[n * 20u + 3u] >> 24u);
            prims.y = hit_mask & 0x00ffffffu;
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
    return false;
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
// sphere of a point or spot light); f32::MAX when it reaches
// none. Ten vec4 per stop (gpu_occluder.rs, STOP_WORDS).
fn ray_end(o: vec3<f32>, d: vec3<f32>) -> f32 {
    var t = F32_MAX;
    for (var k = 0u; k < cp.shape.w; k++) {
        let a = stops[10u * k];
        let b = stops[10u * k + 1u];
        if a.w == 0.0 {
            let inv = vec3<f32>(1.0) / d;
            let t0 = (a.xyz - o) * inv;
            let t1 = (b.xyz - o) * inv;
            let enter = fmax(fmax(fmin(t0.x, t1.x), fmin(t0.y, t1.y)), fmin(t0.z, t1.z));
            let exit = fmin(fmin(fmax(t0.x, t1.x), fmax(t0.y, t1.y)), fmax(t0.z, t1.z));
            if enter > 0.0 && enter <= exit {
                t = min(t, enter);
            }
        } else if a.w == 1.0 {
            let den = dot(d, b.xyz);
            let tp = dot(a.xyz - o, b.xyz) / den;
            if den != 0.0 && tp > 0.0 && tp <= F32_MAX {
                t = min(t, tp);
            }
        } else if a.w == 3.0 {
            // SphereStop::distance.
            let oc = a.xyz - o;
            let tc = dot(oc, d);
            if !(tc > 0.0) {
                continue;
            }
            let perp2 = max(dot(oc, oc) - tc * tc, 0.0);
            let grown = b.x + 2.0 * tc * b.y;
            if !(perp2 <= grown * grown) {
                continue;
            }
            let ts = tc - sqrt(max(b.x * b.x - perp2, 0.0));
            if ts > 0.0 && ts <= F32_MAX {
                t = min(t, ts);
            }
        } else {
            // LampStop::distance.
            let height = b.x - dot(a.xyz, o);
            if b.w == 0.0 && !(height < 0.0) {
                continue;
            }
            let den = dot(d, a.xyz);
            let tp = height / den;
            if !(den != 0.0 && tp > 0.0 && tp <= F32_MAX) {
                continue;
            }
            let x = o + tp * d;
            let grow = tp * b.y / abs(den);
            var inside = true;
            for (var e = 0u; e < u32(b.z); e++) {
                let m = stops[10u * k + 2u + e];
                if dot(m.xyz, x) - m.w < -grow {
                    inside = false;
                }
            }
            if inside {
                t = min(t, tp);
            }
        }
    }
    return t;
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
    for (var j = 0u; j < s; j++) {
        let d = dirs[p * s + j].xyz;
        if dot(d, n) <= 0.0 {
            escaping++;
            continue;
        }
        casts++;
        if !is_occluded(o, d, t_min, ray_end(o, d), skip) {
            escaping++;
        }
    }
    atomicOr(&counts[slot / 2u], (escaping | (casts << 8u)) << (16u * (slot % 2u)));
}
