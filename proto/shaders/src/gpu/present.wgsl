// Presents a frame: linear radiance (the resolve pass's buffer, or a CPU frame uploaded the
// same way) tone-mapped as `Image::to_srgb8` does (exposure, ACES after Narkowicz 2015, sRGB
// OETF, 8-bit), then the overlay layer (premultiplied RGBA8: text, guides, panels) composited
// over it in 8-bit sRGB, as the CPU's canvas blends into a tone-mapped frame.

struct Params {
    // Frame width, height; exposure's bits; 1 when the target encodes sRGB itself.
    size: vec4u,
};

// Storage, not uniform: lavapipe specializes a shader on the uniform values its branches
// read and compiles it again (a minute on 2 cores) whenever they change (docs/gpu.md).
@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> radiance: array<vec4f>;
// 0xAARRGGBB, premultiplied by A.
@group(0) @binding(2) var<storage, read> overlay: array<u32>;

@vertex
fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4f {
    // One triangle over the whole target.
    let uv = vec2f(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4f(uv * 2.0 - 1.0, 0.0, 1.0);
}

// ACES filmic, Narkowicz's fit: x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14); NaN → 0, flat
// beyond 1e4 (as the CPU's `aces`).
fn aces(c: f32) -> f32 {
    var x = c;
    if !(x == x) {
        x = 0.0;
    }
    x = clamp(x, 0.0, 1e4);
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

fn encode_srgb(c: f32) -> f32 {
    if c <= 0.0031308 {
        return 12.92 * c;
    }
    return 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

fn decode_srgb(s: f32) -> f32 {
    if s <= 0.04045 {
        return s / 12.92;
    }
    return pow((s + 0.055) / 1.055, 2.4);
}

@fragment
fn fs(@builtin(position) pos: vec4f) -> @location(0) vec4f {
    let px = vec2u(pos.xy);
    let w = params.size.x;
    let h = params.size.y;
    var c = vec3f(0.0);
    if px.x < w && px.y < h {
        let i = px.y * w + px.x;
        let e = bitcast<f32>(params.size.z);
        let l = radiance[i].xyz * e;
        // The 8-bit value the CPU writes, so that the overlay blends onto the same numbers.
        let s = vec3f(encode_srgb(aces(l.x)), encode_srgb(aces(l.y)), encode_srgb(aces(l.z)));
        c = floor(clamp(s * 255.0 + 0.5, vec3f(0.0), vec3f(255.0))) / 255.0;
        let o = overlay[i];
        let a = f32(o >> 24u) / 255.0;
        let over = vec3f(f32((o >> 16u) & 255u), f32((o >> 8u) & 255u), f32(o & 255u)) / 255.0;
        c = over + (1.0 - a) * c;
    }
    if params.size.w == 1u {
        c = vec3f(decode_srgb(c.x), decode_srgb(c.y), decode_srgb(c.z));
    }
    return vec4f(c, 1.0);
}
