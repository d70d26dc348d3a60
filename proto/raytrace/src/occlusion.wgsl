// Any-hit occlusion rays over obvhs's compressed wide BVH (CWBVH, Ylitie et al. 2017), the GPU
// twin of `Occluder::occluded_between` (proto/raytrace/src/lib.rs): the same nodes, the same
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
// Per ray source: origin.xyz and t_min (as f32 bits), then skip (a vertex index) and 3 unused
// words.
@group(0) @binding(3) var<storage, read> sources: array<vec4<u32>>;
// Per ray: direction.xyz, t_max.
@group(0) @binding(4) var<storage, read> rays: array<vec4<f32>>;
// Per ray: the index of its source.
@group(0) @binding(5) var<storage, read> ray_source: array<u32>;
// Per ray: 1 when occluded, else 0.
@group(0) @binding(6) var<storage, read_write> occluded: array<u32>;
// x: the number of rays; y: rays per row of the dispatch grid.
@group(0) @binding(7) var<uniform> params: vec4<u32>;

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

// RtTriangle::intersect, as a "blocks" test: a hit at t in [t_min, t_max).
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
    let signs = bitcast<u32>(u) | bitcast<u32>(v) | bitcast<u32>(w);
    if inv_det == 0.0 || (signs & 0x80000000u) != 0u {
        return false;
    }
    let t = dot(ng, c) * inv_det;
    return t >= t_min && t < t_max;
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

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * params.y + gid.x;
    if i >= params.x {
        return;
    }
    let d = rays[i];
    let s = ray_source[i];
    let src = bitcast<vec4<f32>>(sources[2u * s]);
    let skip = sources[2u * s + 1u].x;
    occluded[i] = select(0u, 1u, is_occluded(src.xyz, d.xyz, src.w, d.w, skip));
}
