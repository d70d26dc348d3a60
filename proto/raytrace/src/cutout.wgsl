// Alpha cut-outs on the GPU (bspvt_raytrace::CUTOUT_WGSL), appended to the shaders that test
// them: the bake's occlusion rays (occlusion.wgsl) and the client's raster pass
// (visibility.wgsl). The including shader declares `cut: array<u32>`, Cutouts::gpu_words: a
// header (1, first entry word, first mask word, 0) — a single 0 word when every surface is
// opaque —, each primitive's entry (0: opaque), 8 words per entry (mask, has UVs, the corners'
// UVs), 16 per mask (width, height, first texel word, wrap u, wrap v, alpha, cut-off, mean
// alpha, the UV transform's a, b, c, d, tx, ty, 2 unused), the masks' alpha bytes four to a word.

// Wrap::index: texel `i` of `n` under wrap mode `m` (0 repeat, 1 clamp, 2 mirror).
fn wrap_index(m: u32, i: i32, n: i32) -> u32 {
    if m == 1u {
        return u32(clamp(i, 0, n - 1));
    }
    if m == 2u {
        let k = ((i % (2 * n)) + 2 * n) % (2 * n);
        return u32(select(2 * n - 1 - k, k, k < n));
    }
    return u32(((i % n) + n) % n);
}

fn alpha_texel(base: u32, width: u32, x: u32, y: u32) -> f32 {
    let i = y * width + x;
    return f32((cut[base + i / 4u] >> (8u * (i % 4u))) & 0xffu) / 255.0;
}

// Cutout::covers at barycentric weights `bw` of primitive `id`'s corners: the alpha factor ×
// the texture's bilinear alpha (Texture::sample) at the interpolated UV reaches the cut-off.
fn covers(id: u32, bw: vec3<f32>) -> bool {
    return coverage(id, bw, 0.0).x >= 0.0;
}

// `covers` as a margin: (the alpha reached − the cut-off, how far that may be off when each
// weight of `bw` is off by up to `e_bw`, plus the sampling's own rounding; 0 where every device
// computes the same value: opaque, or no texture).
fn coverage(id: u32, bw: vec3<f32>, e_bw: f32) -> vec2<f32> {
    if cut[0] == 0u {
        return vec2<f32>(1.0, 0.0);
    }
    let slot = cut[4u + id];
    if slot == 0u {
        return vec2<f32>(1.0, 0.0);
    }
    let e = cut[1] + 8u * (slot - 1u);
    let m = cut[2] + 16u * cut[e];
    let alpha = bitcast<f32>(cut[m + 5u]);
    let cutoff = bitcast<f32>(cut[m + 6u]);
    let width = cut[m];
    let height = cut[m + 1u];
    if width == 0u || height == 0u {
        return vec2<f32>(alpha - cutoff, 0.0);
    }
    if cut[e + 1u] == 0u {
        // A compiler may fuse the product into the difference.
        let covered = alpha * bitcast<f32>(cut[m + 7u]);
        return vec2<f32>(covered - cutoff, 1.52587890625e-5 * (abs(covered) + abs(cutoff)));
    }
    let uv0 = vec2<f32>(bitcast<f32>(cut[e + 2u]), bitcast<f32>(cut[e + 3u]));
    let uv1 = vec2<f32>(bitcast<f32>(cut[e + 4u]), bitcast<f32>(cut[e + 5u]));
    let uv2 = vec2<f32>(bitcast<f32>(cut[e + 6u]), bitcast<f32>(cut[e + 7u]));
    let uv_mesh = uv0 * bw.x + uv1 * bw.y + uv2 * bw.z;
    // UvTransform::apply.
    let ta = bitcast<f32>(cut[m + 8u]);
    let tb = bitcast<f32>(cut[m + 9u]);
    let tc = bitcast<f32>(cut[m + 10u]);
    let td = bitcast<f32>(cut[m + 11u]);
    var uv = vec2<f32>(ta * uv_mesh.x + tb * uv_mesh.y + bitcast<f32>(cut[m + 12u]),
        tc * uv_mesh.x + td * uv_mesh.y + bitcast<f32>(cut[m + 13u]));
    if !(abs(uv.x) < 1e30 && abs(uv.y) < 1e30) {
        uv = vec2<f32>(0.0);
    }
    let x = uv.x * f32(width) - 0.5;
    let y = uv.y * f32(height) - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let wi = i32(width);
    let hi = i32(height);
    let xs = vec2<u32>(wrap_index(cut[m + 3u], i32(x0), wi), wrap_index(cut[m + 3u], i32(x0) + 1, wi));
    let ys = vec2<u32>(wrap_index(cut[m + 4u], i32(y0), hi), wrap_index(cut[m + 4u], i32(y0) + 1, hi));
    let base = cut[m + 2u];
    let a = alpha_texel(base, width, xs.x, ys.x);
    let b = alpha_texel(base, width, xs.y, ys.x);
    let c = alpha_texel(base, width, xs.x, ys.y);
    let d = alpha_texel(base, width, xs.y, ys.y);
    let top = a + (b - a) * fx;
    let bottom = c + (d - c) * fx;
    // The bilinear alpha changes by at most one texel step (≤ 1) per texel: a UV off by
    // (δu, δv) moves it by ≤ width·δu + height·δv; the texel coordinates (|x|, |y|) carry
    // their own rounding.
    let span = abs(uv0) + abs(uv1) + abs(uv2);
    let e_mesh = span * (e_bw + 1.52587890625e-5);
    let e_uv = vec2<f32>((abs(ta) + abs(tb)) * max(e_mesh.x, e_mesh.y), (abs(tc) + abs(td)) * max(e_mesh.x, e_mesh.y))
        + 1.52587890625e-5 * (abs(uv) + 1.0);
    let e_alpha = abs(alpha) * (f32(width) * e_uv.x + f32(height) * e_uv.y + 1.52587890625e-5 * (abs(x) + abs(y) + 4.0));
    return vec2<f32>(alpha * (top + (bottom - top) * fy) - cutoff, e_alpha);
}
