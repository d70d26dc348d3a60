// Which side of each vertex the camera sees, for frames shaded per vertex where the G-buffer
// is on the GPU (the browser viewer; the CPU's is GBuffer::vertex_sides, the same
// rule): every pixel of the visibility buffer votes for the three corners of its triangle, +1
// where a corner's normal points away from the triangle's face the eye sees and −1 where it
// points toward it; `mark` then sets each vertex record's position w to −1 where the votes say
// behind, else 1 (records::seen_from_behind: shade.wgsl turns its normal over and shades it
// unshadowed), and clears the votes for the next frame. Appended: the visibility buffer's
// binding and `vis_id` (wgsl::sides).

struct SidesParams {
    // The eye (w unused).
    eye: vec4f,
    // Width and height of the visibility buffer, vertices, 0.
    size: vec4u,
}

@group(0) @binding(0) var<storage, read> sp: SidesParams;
// Four per vertex: position (w: the side, written by `mark`), normal on the mesh's side, …
@group(0) @binding(1) var<storage, read_write> verts: array<vec4f>;
// Per triangle: its three corners and its material (gpu/records.rs `triangles`).
@group(0) @binding(2) var<storage, read> tris: array<vec4u>;
// Per vertex: pixels that see its back minus pixels that see its front.
@group(0) @binding(3) var<storage, read_write> votes: array<atomic<i32>>;

@compute @workgroup_size(8, 8)
fn vote(@builtin(global_invocation_id) id: vec3u) {
    if id.x >= sp.size.x || id.y >= sp.size.y {
        return;
    }
    let t = vis_id(vec2i(id.xy), 0u);
    if t == 0u {
        return;
    }
    let c = tris[t - 1u];
    let p0 = verts[4u * c.x].xyz;
    var g = cross(verts[4u * c.y].xyz - p0, verts[4u * c.z].xyz - p0);
    if dot(g, sp.eye.xyz - p0) < 0.0 {
        g = -g;
    }
    for (var k = 0u; k < 3u; k++) {
        let v = c[k];
        let d = dot(verts[4u * v + 1u].xyz, g);
        if d < 0.0 {
            atomicAdd(&votes[v], 1);
        } else if d > 0.0 {
            atomicAdd(&votes[v], -1);
        }
    }
}

@compute @workgroup_size(64)
fn mark(@builtin(global_invocation_id) id: vec3u) {
    let v = id.x;
    if v >= sp.size.z {
        return;
    }
    let c = atomicExchange(&votes[v], 0);
    verts[4u * v].w = select(1.0, -1.0, c > 0);
}
