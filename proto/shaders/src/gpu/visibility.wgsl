// The raster pass of GPU frames: a visibility buffer (triangle index + 1 per sample, 0 where
// nothing is drawn, split in two 16-bit halves: Rg16Uint is multisampled on every adapter,
// R32Uint is not), with a reversed-Z depth test. Everything else happens in resolve.wgsl, a
// compute pass, so that no fragment shader carries the LTC integral (on lavapipe such a
// fragment shader did not finish compiling in ten minutes; the same code compiles in a
// compute shader in well under a second). Drawn without an index buffer: vertex i is corner
// i % 3 of triangle i / 3.

struct Raster {
    view_proj: mat4x4f,
}

// Storage, not uniform: lavapipe specializes a shader on the uniform values its branches
// read and compiles it again (a minute on 2 cores) whenever they change (docs/gpu.md).
@group(0) @binding(0) var<storage, read> rp: Raster;
// Four per vertex: position, normal, (albedo, α), (F0, 0) — the compute pass's records.
@group(0) @binding(1) var<storage, read> verts: array<vec4f>;
// Per triangle: its three corners and its material (gpu/records.rs `triangles`).
@group(0) @binding(2) var<storage, read> tris: array<vec4u>;

// The scene's alpha cut-outs by mesh triangle (Cutouts::gpu_words_by_triangle; one 0 word:
// none), tested by `covers` (bspvt_raytrace::CUTOUT_WGSL, appended).
@group(0) @binding(3) var<storage, read> cut: array<u32>;

struct Varyings {
    @builtin(position) clip: vec4f,
    @location(0) @interpolate(flat) id: u32,
    // The fragment's barycentrics of its triangle's corners (perspective-correct).
    @location(1) bary: vec3f,
}

@vertex
fn vs(@builtin(vertex_index) i: u32) -> Varyings {
    var out: Varyings;
    out.clip = rp.view_proj * vec4f(verts[4u * tris[i / 3u][i % 3u]].xyz, 1.0);
    out.id = i / 3u + 1u;
    let corner = i % 3u;
    out.bary = vec3f(f32(corner == 0u), f32(corner == 1u), f32(corner == 2u));
    return out;
}

// The alpha test: a fragment where its triangle is cut out is not drawn (the CPU G-buffer's
// `rasterize_cut`).
@fragment
fn fs(in: Varyings) -> @location(0) vec2u {
    if !covers(in.id - 1u, in.bary) {
        discard;
    }
    return vec2u(in.id & 0xffffu, in.id >> 16u);
}
