//! The WGSL sources of the GPU path, assembled as each pipeline compiles them. Storage buffers
//! stand where uniforms would: lavapipe specializes a shader on the uniform values its
//! branches read and compiles it again whenever they change (docs/gpu.md).

/// Shared by the shading passes: LTC lookup, polygon integral, clipping, light textures.
const COMMON: &str = include_str!("common.wgsl");

/// Per-vertex BSPVT shading (paper 000 §3.1 eq. 2), a compute pass: `common` + `shade`.
pub fn shade() -> String {
    [COMMON, include_str!("shade.wgsl")].concat()
}

/// The sky's world-fixed cells per vertex (issue 37 item 3): `shade` + `sky` (entry points
/// `sky_terms`, `sky_gather`).
pub fn sky() -> String {
    [COMMON, include_str!("shade.wgsl"), include_str!("sky.wgsl")].concat()
}

/// The raster pass of frames: a visibility buffer of triangle ids, with the alpha test of
/// the scene's cut-outs (`bspvt_raytrace::CUTOUT_WGSL`, shared with the ray caster).
pub fn visibility() -> String {
    [include_str!("visibility.wgsl"), bspvt_raytrace::CUTOUT_WGSL].concat()
}

/// The per-pixel pass of frames over the visibility buffer of `samples` samples per pixel
/// (1, or more with MSAA): `common` + `resolve` + the visibility buffer's binding.
pub fn resolve(samples: u32) -> String {
    [
        COMMON,
        include_str!("resolve.wgsl"),
        visibility_binding(samples),
    ]
    .concat()
}

/// Which side of each vertex the camera sees, voted by the pixels of a one-sample visibility
/// buffer (entry points `vote`, `mark`): the browser viewer's per-vertex frames.
pub fn sides() -> String {
    [
        include_str!("sides.wgsl"),
        &visibility_binding(1).replace("@binding(7)", "@binding(4)"),
    ]
    .concat()
}

/// rt-penumbra's edge-aware blur (paper 003): edges, the widths' spread, the tent's boxes.
pub fn penumbra() -> &'static str {
    include_str!("penumbra.wgsl")
}

/// Tone mapping and the overlay, drawn to the window or canvas.
pub fn present() -> &'static str {
    include_str!("present.wgsl")
}

/// The visibility buffer's binding and reader, appended to `resolve.wgsl`.
fn visibility_binding(samples: u32) -> &'static str {
    if samples > 1 {
        "@group(0) @binding(7) var vis: texture_multisampled_2d<u32>;
fn vis_id(px: vec2i, s: u32) -> u32 {
    let v = textureLoad(vis, px, i32(s));
    return v.x | (v.y << 16u);
}
"
    } else {
        "@group(0) @binding(7) var vis: texture_2d<u32>;
fn vis_id(px: vec2i, s: u32) -> u32 {
    let v = textureLoad(vis, px, 0);
    return v.x | (v.y << 16u);
}
"
    }
}
