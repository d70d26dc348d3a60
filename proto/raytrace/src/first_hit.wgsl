// Closest hits of segments (rt-penumbra's hard shadow rays, paper 003: the occluder's distance
// from the closest hit), the GPU twin of `Occluder::first_hit` (proto/raytrace/src/lib.rs):
// obvhs's compressed wide BVH (CWBVH, Ylitie et al. 2017) traversed as obvhs's `traverse!` does,
// the segment's end shrinking to each hit found, and the closed Möller–Trumbore test of
// `bspvt_raytrace::hit` through the alpha cut-outs. Unlike the bake's `occlusion.wgsl` it keeps
// no account of this device's rounding: a shadow ray grazing an edge may answer otherwise than
// the CPU's (tests/tests/first_hit_gpu.rs counts how often).

// The CWBVH's nodes (cwbvh.wgsl, prepended).
@group(0) @binding(0) var<storage, read> nodes: array<u32>;
// RtTriangle per primitive, 16 floats: v0, e1 (= v0 - v1), e2 (= v2 - v0), ng (= e1 × e2),
// then four words this shader does not read.
@group(0) @binding(1) var<storage, read> tris: array<f32>;
// The alpha cut-outs (Cutouts::gpu_words; a single 0 word when every surface is opaque).
@group(0) @binding(2) var<storage, read> cut: array<u32>;
// Per segment two vec4: origin.xyz and its length t_max; the unit direction.xyz and 0.
@group(0) @binding(3) var<storage, read> segments: array<vec4<f32>>;
// Per segment: the closest hit's distance, or -1 when the segment is clear.
@group(0) @binding(4) var<storage, read_write> hits: array<f32>;
// Segments in this dispatch, invocations per row of the dispatch grid, and the nearest distance
// a child box is entered at (f32 bits; `Occluder::box_t_min`).
@group(0) @binding(5) var<storage, read> shape: vec4<u32>;

fn box_t_min() -> f32 {
    return bitcast<f32>(shape.z);
}

// bspvt_raytrace::EDGE_SLACK (2^-20): barycentrics down to minus this count as inside.
const EDGE_SLACK: f32 = 9.5367431640625e-7;

// obvhs's ray::safe_inverse (signum(±0) = ±1).
fn safe_inverse(x: f32) -> f32 {
    if abs(x) <= F32_EPSILON {
        let s = select(1.0, -1.0, (bitcast<u32>(x) & 0x80000000u) != 0u);
        return s / F32_EPSILON;
    }
    return 1.0 / x;
}

// CwBvhNode::intersect_ray: the hit mask of the node's children (slab test of each child's
// quantized box against [box_t_min(), t_max]).
fn intersect_node(n: u32, o: vec3<f32>, inv_d: vec3<f32>, neg: vec3<bool>, t_max: f32, oct_inv4: u32) -> u32 {
    let frame = node_frame(n, o, inv_d);
    var hit_mask = 0u;
    for (var c = 0u; c < 8u; c++) {
        let child_meta = node_byte(n, 6u, c);
        if child_meta == 0u {
            continue; // empty slot
        }
        let box = child_near_far(n, c, neg);
        let t0 = box[0] * frame[0] + frame[1];
        let t1 = box[1] * frame[0] + frame[1];
        let tmin = max(max(max(t0.x, t0.y), t0.z), box_t_min());
        let tmax = min(min(min(t1.x, t1.y), t1.z), t_max);
        if tmin <= tmax {
            hit_mask |= child_hit_bits(child_meta, oct_inv4);
        }
    }
    return hit_mask;
}

// bspvt_raytrace::intersect through the cut-out (Occluder::primitive_hit): the hit's distance
// in [0, t_max], or -1.
fn hit_distance(id: u32, o: vec3<f32>, d: vec3<f32>, t_max: f32) -> f32 {
    let b = id * 16u;
    let v0 = vec3<f32>(tris[b], tris[b + 1u], tris[b + 2u]);
    let e1 = vec3<f32>(tris[b + 3u], tris[b + 4u], tris[b + 5u]);
    let e2 = vec3<f32>(tris[b + 6u], tris[b + 7u], tris[b + 8u]);
    let ng = vec3<f32>(tris[b + 9u], tris[b + 10u], tris[b + 11u]);
    let c = v0 - o;
    let r = cross(d, c);
    let det = dot(ng, d);
    if det == 0.0 {
        return -1.0;
    }
    let inv_det = 1.0 / det;
    // u weighs v1 and v the corner v2 (obvhs's layout).
    let u = dot(r, e2) * inv_det;
    let v = dot(r, e1) * inv_det;
    let w = 1.0 - u - v;
    if u < -EDGE_SLACK || v < -EDGE_SLACK || w < -EDGE_SLACK {
        return -1.0;
    }
    let t = dot(ng, c) * inv_det;
    if !(t >= 0.0 && t <= t_max) || !covers(id, vec3<f32>(w, u, v)) {
        return -1.0;
    }
    return t;
}

// obvhs's `traverse!` for the closest hit (CwBvh::ray_traverse): every leaf the segment still
// reaches is tested, and the segment ends at each nearer hit found.
fn first_hit(o: vec3<f32>, d: vec3<f32>, t_end: f32) -> f32 {
    let inv_d = vec3<f32>(safe_inverse(d.x), safe_inverse(d.y), safe_inverse(d.z));
    let neg = d < vec3<f32>(0.0);
    let oct_inv4 = octant_inv4(neg);
    var stack: array<vec2<u32>, STACK_SIZE>;
    var sp = 0u;
    var current = vec2<u32>(0u, 0x80000000u);
    var prims = vec2<u32>(0u, 0u);
    var t_max = t_end;
    var best = -1.0;
    loop {
        while prims.y != 0u {
            let local = firstLeadingBit(prims.y);
            prims.y &= ~(1u << local);
            let t = hit_distance(prims.x + local, o, d, t_max);
            // The traversal's own acceptance (`t < ray.tmax`): a hit at the segment's very end
            // does not count.
            if t >= 0.0 && t < t_max {
                best = t;
                t_max = t;
            }
        }
        prims = vec2<u32>(0u, 0u);
        if (current.y & 0xff000000u) != 0u {
            let hits_imask = current.y;
            let offset = firstLeadingBit(hits_imask);
            current.y &= ~(1u << offset);
            // A full stack drops the node's remaining children (a CWBVH of obvhs's depth
            // does not reach it).
            if (current.y & 0xff000000u) != 0u && sp < STACK_SIZE {
                stack[sp] = current;
                sp++;
            }
            let n = child_node(vec2<u32>(current.x, hits_imask), offset, oct_inv4);
            let next = enter_node(n, intersect_node(n, o, inv_d, neg, t_max, oct_inv4));
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
    return best;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * shape.y + gid.x;
    if i >= shape.x {
        return;
    }
    let a = segments[2u * i];
    let b = segments[2u * i + 1u];
    hits[i] = first_hit(a.xyz, b.xyz, a.w);
}
