// obvhs's compressed wide BVH (CWBVH, Ylitie et al. 2017) as the ray shaders read it
// (occlusion.wgsl, first_hit.wgsl; prepended to each): the node layout, a child's quantized box
// and its bits in the hit mask, and the traversal's step into a child. The including shader
// declares `nodes: array<u32>`, CwBvhNode (80 bytes, repr(C)) as 20 words: p.xyz,
// e[3] | imask << 24, child_base_idx, primitive_base_idx, child_meta (2 words), then
// child_{min,max}_{x,y,z} (2 words each).

// A child box is entered no nearer than `box_t_min()` (each including shader declares it):
// obvhs's cwbvh::node::EPSILON as the CPU's traversals scale it, `Occluder::box_t_min`.
// f32::EPSILON, for obvhs's `safe_inverse`.
const F32_EPSILON: f32 = 1.1920929e-7;
const STACK_SIZE: u32 = 32u;

fn byte_of(w: u32, i: u32) -> u32 {
    return (w >> (8u * i)) & 0xffu;
}

// Byte `c` (0..8) of the 8-byte field starting at word `w` of node `n`.
fn node_byte(n: u32, w: u32, c: u32) -> u32 {
    return byte_of(nodes[n * 20u + w + c / 4u], c % 4u);
}

// The ray (origin `o`, reciprocal direction `inv_d`) in node n's quantized frame: a slab's t
// is q · [0] + [1] for a quantized bound q (CwBvhNode::intersect_ray's adjusted_ray_dir_inv
// and adjusted_ray_origin).
fn node_frame(n: u32, o: vec3<f32>, inv_d: vec3<f32>) -> array<vec3<f32>, 2> {
    let b = n * 20u;
    let p = vec3<f32>(bitcast<f32>(nodes[b]), bitcast<f32>(nodes[b + 1u]), bitcast<f32>(nodes[b + 2u]));
    let ew = nodes[b + 3u];
    let extent = vec3<f32>(
        bitcast<f32>(byte_of(ew, 0u) << 23u),
        bitcast<f32>(byte_of(ew, 1u) << 23u),
        bitcast<f32>(byte_of(ew, 2u) << 23u),
    );
    return array<vec3<f32>, 2>(extent * inv_d, (p - o) * inv_d);
}

// Child c's quantized box bounds nearest to and farthest from the ray's origin per axis
// (`neg`: the direction's negative axes).
fn child_near_far(n: u32, c: u32, neg: vec3<bool>) -> array<vec3<f32>, 2> {
    let lo = vec3<f32>(f32(node_byte(n, 8u, c)), f32(node_byte(n, 12u, c)), f32(node_byte(n, 16u, c)));
    let hi = vec3<f32>(f32(node_byte(n, 10u, c)), f32(node_byte(n, 14u, c)), f32(node_byte(n, 18u, c)));
    return array<vec3<f32>, 2>(select(lo, hi, neg), select(hi, lo, neg));
}

// CwBvhNode::get_child_and_index_bits, one byte at a time: an entered child's bits of the hit
// mask.
fn child_hit_bits(child_meta: u32, oct_inv4: u32) -> u32 {
    let inner = ((child_meta & (child_meta << 1u)) & 0x10u) != 0u;
    let oct = select(0u, oct_inv4 & 0xffu, inner);
    let bit_index = (child_meta ^ oct) & 0x1fu;
    let child_bits = (child_meta >> 5u) & 7u;
    return child_bits << bit_index;
}

// The ray's octant as obvhs's traversal keeps it (oct_inv4).
fn octant_inv4(neg: vec3<bool>) -> u32 {
    return select(0x04040404u, 0u, neg.x) | select(0x02020202u, 0u, neg.y) | select(0x01010101u, 0u, neg.z);
}

// The node of the node group `group` (child base, hit bits) at the hit mask's bit `offset`.
fn child_node(group: vec2<u32>, offset: u32, oct_inv4: u32) -> u32 {
    let slot = (offset - 24u) ^ (oct_inv4 & 0xffu);
    return group.x + countOneBits(group.y & ~(0xffffffffu << slot));
}

// Entering node n with its children's hit mask: its node group (child base, inner children's
// bits | imask) and its primitive group (primitive base, leaf bits).
fn enter_node(n: u32, hit_mask: u32) -> array<vec2<u32>, 2> {
    let current = vec2<u32>(nodes[n * 20u + 4u], (hit_mask & 0xff000000u) | (nodes[n * 20u + 3u] >> 24u));
    let prims = vec2<u32>(nodes[n * 20u + 5u], hit_mask & 0x00ffffffu);
    return array<vec2<u32>, 2>(current, prims);
}
