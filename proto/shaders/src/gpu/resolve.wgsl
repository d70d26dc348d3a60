// The shading pass of GPU frames (render::renderer's per-vertex and per-pixel modes), one
// invocation per pixel over the visibility buffer of visibility.wgsl. Each sample's surface is
// found as the CPU's G-buffer finds it (frame::gbuffer): the primary ray through the sample
// meets the plane of the triangle drawn there (Möller–Trumbore, barycentrics clamped into the
// triangle), so positions do not depend on the rasteriser's interpolation. Then:
// - per vertex (mode 0): the per-vertex shading of shade.wgsl, interpolated;
// - per pixel (mode 1): unshadowed LTC GGX [Heitz16] at the surface, times the per-vertex
//   shadow ratios (diffuse, specular) interpolated; black where the viewer is below the
//   shading hemisphere (shade::sees_viewer).
// With MSAA, a pixel inside one triangle is shaded once at its centre (as the CPU shades it);
// at an edge, each distinct triangle of the pixel is shaded once, at its first sample, and
// weighted by its share of the samples.
// Prepended: common.wgsl; appended: the visibility buffer's binding and `vis_id` (frame.rs).

struct ResolveParams {
    // xyz: the eye; w: tan(fov_y / 2).
    eye: vec4f,
    // xyz: the unit forward, right and up vectors of frame::camera::View; forward.w: aspect.
    forward: vec4f,
    right: vec4f,
    up: vec4f,
    // xyz: a polygon's emitting side's unit normal; w: the light's kind (common.wgsl).
    light_normal: vec4f,
    // w: 1 when textured (light_tex holds the texture).
    radiance: vec4f,
    // The light's shape (bspvt_shaders::gpu::lights).
    light: array<vec4f, 8>,
    // light vertices, mode (0 per vertex, 1 per pixel), LTC table size, materials.
    counts: vec4u,
    // width, height, samples per pixel, the roughness override's f32 bits (0: none).
    size: vec4u,
    // x: 1 when `image` holds the frames of the lights drawn before this one and this light's
    // frame is added to it (several lights, one pass each); 0: this frame replaces it.
    layer: vec4u,
}

struct VertexOut {
    colour: vec4f,
    ratio_d: vec3f,
    pieces: u32,
    ratio_s: vec3f,
    dropped: u32,
}

// Storage, not uniform: lavapipe specializes a shader on the uniform values its branches
// read and compiles it again (a minute on 2 cores) whenever they change (docs/gpu.md).
@group(0) @binding(0) var<storage, read> fp: ResolveParams;
// Four per vertex: position, (normal, u), (albedo, α), (F0, v) — the compute pass's records.
@group(0) @binding(1) var<storage, read> verts: array<vec4f>;
// Per triangle: its three corners and its material (gpu/records.rs `triangles`; one buffer,
// not two, so that the pass fits WebGPU's ten storage buffers per stage).
@group(0) @binding(2) var<storage, read> tris: array<vec4u>;
// Five per material (gpu/materials.rs): (albedo, α), (F0, kind), then the textured kinds'
// factors and texture indices.
@group(0) @binding(3) var<storage, read> materials: array<vec4f>;
@group(0) @binding(4) var<storage, read> shading: array<VertexOut>;
@group(0) @binding(5) var<storage, read> ltc: array<vec4f>;
// Linear radiance per pixel, row-major.
@group(0) @binding(6) var<storage, read_write> image: array<vec4f>;
// The light's texture (LightTexture::gpu_words; a placeholder when untextured).
@group(0) @binding(8) var<storage, read> light_texture: array<vec4f>;
// The textures the materials sample: a 12-word header per texture use (width, height,
// offset, wrap u | wrap v << 4, the UV transform a, b, c, d, tx, ty as f32 bits, two unused),
// then RGBA8 texels (gpu/materials.rs).
@group(0) @binding(9) var<storage, read> surface_tex: array<u32>;
// Two per vertex where a material is normal-mapped — (unbent normal, 0), (tangent, bitangent
// sign) —, a single zero vec4 otherwise (frame.rs `tangent_frames`).
@group(0) @binding(10) var<storage, read> frames: array<vec4f>;

fn light_count() -> u32 {
    return fp.counts.x;
}
fn light_word(i: u32) -> vec4f {
    return fp.light[i];
}
fn light_normal() -> vec4f {
    return fp.light_normal;
}
fn light_textured() -> bool {
    return fp.radiance.w != 0.0;
}
fn light_tex(i: u32) -> vec4f {
    return light_texture[i];
}
fn ltc_size() -> u32 {
    return fp.counts.z;
}
fn ltc_a(k: u32) -> vec4f {
    return ltc[2u * k];
}
fn ltc_b(k: u32) -> vec4f {
    return ltc[2u * k + 1u];
}

// The sample positions within a pixel: the centre, or the standard 4× pattern of Vulkan,
// Direct3D and Metal.
fn sample_offset(s: u32) -> vec2f {
    if fp.size.z == 1u {
        return vec2f(0.5, 0.5);
    }
    switch s {
        case 0u: { return vec2f(0.375, 0.125); }
        case 1u: { return vec2f(0.875, 0.375); }
        case 2u: { return vec2f(0.125, 0.625); }
        default: { return vec2f(0.625, 0.875); }
    }
}

// View::ray_dir: the unit direction of the primary ray through image point (x, y) in pixels.
fn ray_dir(x: f32, y: f32) -> vec3f {
    let w = f32(fp.size.x);
    let h = f32(fp.size.y);
    let sx = (2.0 * x / w - 1.0) * fp.eye.w * fp.forward.w;
    let sy = (1.0 - 2.0 * y / h) * fp.eye.w;
    return normalize(fp.forward.xyz + sx * fp.right.xyz + sy * fp.up.xyz);
}

// gbuffer::ray_plane_barycentrics: the barycentric weights of the ray's hit on the plane of
// (p0, p1, p2), clamped into the triangle; the centroid where the ray runs along the plane.
fn weights(d: vec3f, p0: vec3f, p1: vec3f, p2: vec3f) -> vec3f {
    let pw = plane_weights(d, p0, p1, p2);
    if pw.w < 0.0 {
        return vec3f(1.0 / 3.0);
    }
    var u = clamp(pw.y, 0.0, 1.0);
    var v = clamp(pw.z, 0.0, 1.0);
    let s = u + v;
    if s > 1.0 {
        u /= s;
        v /= s;
    }
    return vec3f(1.0 - u - v, u, v);
}

// gbuffer::plane_hit: the weights (xyz) where the ray meets the plane of (p0, p1, p2),
// unclamped; w: 1 where it meets it in front, 0 behind, −1 where it runs along the plane.
fn plane_weights(d: vec3f, p0: vec3f, p1: vec3f, p2: vec3f) -> vec4f {
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    let pv = cross(d, e2);
    let det = dot(e1, pv);
    if !(abs(det) > 0.0) || !finite(det) {
        return vec4f(0.0, 0.0, 0.0, -1.0);
    }
    let inv = 1.0 / det;
    let tv = fp.eye.xyz - p0;
    let qv = cross(tv, e1);
    let u = dot(tv, pv) * inv;
    let v = dot(d, qv) * inv;
    let front = dot(e2, qv) * inv > 0.0 && finite(u) && finite(v);
    return vec4f(1.0 - u - v, u, v, select(0.0, 1.0, front));
}

// IEC 61966-2-1 sRGB → linear (texture::srgb_table).
fn srgb_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        return c / 12.92;
    }
    return pow((c + 0.055) / 1.055, 2.4);
}

// Texel (x, y) of the level at word `offset`, `width` texels wide.
fn surface_texel(offset: u32, width: u32, x: u32, y: u32, srgb: bool) -> vec4f {
    let w = surface_tex[offset + y * width + x];
    let c = vec4f(f32(w & 255u), f32((w >> 8u) & 255u), f32((w >> 16u) & 255u),
        f32(w >> 24u)) / 255.0;
    if srgb {
        return vec4f(srgb_linear(c.x), srgb_linear(c.y), srgb_linear(c.z), c.w);
    }
    return c;
}

// Wrap::index: repeat (0), clamp to edge (1), mirrored repeat (2).
fn wrap_index(mode: u32, i: i32, n: i32) -> u32 {
    if mode == 1u {
        return u32(clamp(i, 0, n - 1));
    }
    if mode == 2u {
        let m = ((i % (2 * n)) + 2 * n) % (2 * n);
        return u32(select(2 * n - 1 - m, m, m < n));
    }
    return u32(((i % n) + n) % n);
}

// texture::bilinear on one level (size `n`, texels at word `offset`): between the four
// nearest texel centres, wrapped per axis; `uv` already in one period of its wrap modes.
fn level_bilinear(offset: u32, n: vec2u, modes: vec2u, uv: vec2f, srgb: bool) -> vec4f {
    let tap = bilinear_taps(uv, n.x, n.y);
    let ni = vec2i(i32(n.x), i32(n.y));
    let xs = vec2u(wrap_index(modes.x, tap.x0, ni.x), wrap_index(modes.x, tap.x0 + 1, ni.x));
    let ys = vec2u(wrap_index(modes.y, tap.y0, ni.y), wrap_index(modes.y, tap.y0 + 1, ni.y));
    let a = surface_texel(offset, n.x, xs.x, ys.x, srgb);
    let b = surface_texel(offset, n.x, xs.y, ys.x, srgb);
    let c = surface_texel(offset, n.x, xs.x, ys.y, srgb);
    let d = surface_texel(offset, n.x, xs.y, ys.y, srgb);
    let top = a + (b - a) * tap.f.x;
    let bottom = c + (d - c) * tap.f.x;
    return top + (bottom - top) * tap.f.y;
}

// TextureRef::sample_footprint: the texture use t at the mesh's `uv_mesh`, as a pixel whose
// UV changes by duv (columns: to the next pixel right, down) per pixel sees it — trilinear
// between the mip levels around log2 of the footprint's longer side in texels (lod 0: the
// finest level, bilinear). Colour textures are linearised before filtering. The UV is first
// brought into one period of its wrap mode (exact in f32), so a large UV keeps the texel's
// fraction.
fn surface_sample(t: u32, uv_mesh: vec2f, srgb: bool, duv: mat2x2f) -> vec4f {
    let hb = 12u * t;
    let h = vec4u(surface_tex[hb], surface_tex[hb + 1u], surface_tex[hb + 2u], surface_tex[hb + 3u]);
    if h.x == 0u || h.y == 0u {
        return vec4f(0.0);
    }
    // UvTransform::apply: (a u + b v + tx, c u + d v + ty).
    let m = array<f32, 6>(bitcast<f32>(surface_tex[hb + 4u]), bitcast<f32>(surface_tex[hb + 5u]),
        bitcast<f32>(surface_tex[hb + 6u]), bitcast<f32>(surface_tex[hb + 7u]),
        bitcast<f32>(surface_tex[hb + 8u]), bitcast<f32>(surface_tex[hb + 9u]));
    let uv_in = vec2f(m[0] * uv_mesh.x + m[1] * uv_mesh.y + m[4],
        m[2] * uv_mesh.x + m[3] * uv_mesh.y + m[5]);
    var uv = select(vec2f(0.0), uv_in, finite(uv_in.x) && finite(uv_in.y));
    let modes = vec2u(h.w & 15u, (h.w >> 4u) & 15u);
    for (var k = 0; k < 2; k++) {
        if modes[k] == 0u {
            uv[k] = uv[k] - floor(uv[k]);
        } else if modes[k] == 2u {
            uv[k] = uv[k] - 2.0 * floor(uv[k] * 0.5);
        } else {
            uv[k] = clamp(uv[k], -1.0, 2.0);
        }
    }
    // TextureRef::lod: the footprint through the transform's linear part, in texels.
    let size = vec2f(f32(h.x), f32(h.y));
    let lin = mat2x2f(vec2f(m[0], m[2]), vec2f(m[1], m[3]));
    let rho = max(length((lin * duv[0]) * size), length((lin * duv[1]) * size));
    let levels = surface_tex[hb + 10u];
    var lod = 0.0;
    if rho > 1.0 {
        lod = min(log2(rho), f32(levels));
    }
    if !(lod > 0.0) {
        return level_bilinear(h.z, h.xy, modes, uv, srgb);
    }
    // Texture::sample_lod: levels k and k + 1 blended by the fraction.
    let k = u32(floor(lod));
    let f = lod - f32(k);
    var offset = h.z;
    var n = h.xy;
    for (var j = 0u; j < k; j++) {
        offset += n.x * n.y;
        n = max(n / 2u, vec2u(1u));
    }
    let a = level_bilinear(offset, n, modes, uv, srgb);
    if f <= 0.0 || k >= levels {
        return a;
    }
    let b = level_bilinear(offset + n.x * n.y, max(n / 2u, vec2u(1u)), modes, uv, srgb);
    return a + (b - a) * f;
}

fn unit3(v: vec3f) -> vec3f {
    return select(vec3f(0.0), clamp(v, vec3f(0.0), vec3f(1.0)), vec3<bool>(finite(v.x),
        finite(v.y), finite(v.z)));
}

fn unit1(x: f32) -> f32 {
    return select(0.0, clamp(x, 0.0, 1.0), finite(x));
}

// Material m at `uv` (MaterialMaps::eval): (albedo, α) and (F0, _); the roughness override
// after the lookup, as Renderer::material_at.
struct SurfaceMaterial {
    albedo: vec4f,
    f0: vec3f,
}

fn surface_material(m: u32, uv: vec2f, duv: mat2x2f) -> SurfaceMaterial {
    var out: SurfaceMaterial;
    out.albedo = materials[5u * m];
    let r1 = materials[5u * m + 1u];
    out.f0 = r1.xyz;
    let kind = u32(r1.w);
    if kind == 1u {
        let factor = materials[5u * m + 2u];
        let r3 = materials[5u * m + 3u];
        let bt = bitcast<u32>(r3.z);
        let mt = bitcast<u32>(r3.w);
        var bc = vec4f(1.0);
        var mr = vec4f(1.0);
        if bt != 0u {
            bc = surface_sample(bt - 1u, uv, true, duv);
        }
        if mt != 0u {
            mr = surface_sample(mt - 1u, uv, false, duv);
        }
        let c = unit3(factor.xyz * bc.xyz);
        let metal = unit1(r3.x * mr.z);
        let rough = unit1(r3.y * mr.y);
        out.albedo = vec4f(c * (1.0 - metal), clamp(rough * rough, 1e-3, 1.0));
        out.f0 = vec3f(0.04) + (c - vec3f(0.04)) * metal;
    } else if kind == 2u {
        let kd = materials[5u * m + 2u];
        let t = bitcast<u32>(materials[5u * m + 3u].z);
        if t != 0u {
            let tex = surface_sample(t - 1u, uv, true, duv);
            out.albedo = vec4f(unit3(kd.xyz * tex.xyz), out.albedo.w);
        }
    }
    if kind != 0u && fp.size.w != 0u {
        out.albedo.w = bitcast<f32>(fp.size.w);
    }
    return out;
}

// NormalMap::at: the unit tangent-space normal of texel c, normalize((2c − 1) ⊙ (s, s, 1)).
fn normal_texel(c: vec4f, scale: f32) -> vec3f {
    let s = select(1.0, scale, finite(scale));
    let v = vec3f((2.0 * c.x - 1.0) * s, (2.0 * c.y - 1.0) * s, 2.0 * c.z - 1.0);
    let l = length(v);
    return select(vec3f(0.0, 0.0, 1.0), v / l, l > 0.0 && finite(l));
}

// normal_map::bend: normalize(x T + y B + z N), T made orthogonal to the unit normal n,
// B = sign · n × T; n where T or the result is degenerate.
fn bend(n: vec3f, t_in: vec3f, sign: f32, m: vec3f) -> vec3f {
    let t0 = t_in - n * dot(n, t_in);
    let tl = length(t0);
    if !(tl > 1e-12) || !finite(tl) {
        return n;
    }
    let t = t0 / tl;
    let b = sign * cross(n, t);
    let r = m.x * t + m.y * b + m.z * n;
    let rl = length(r);
    return select(n, r / rl, rl > 0.0 && finite(rl));
}

// NormalMaps::facing: a bent normal kept just this side of the silhouette.
fn keep_facing(bent: vec3f, n: vec3f, wo: vec3f) -> vec3f {
    let eps = 0.02;
    let d = dot(bent, wo);
    if d < eps && dot(n, wo) > eps {
        let r = bent + (eps - d) * wo;
        let rl = length(r);
        return select(n, r / rl, rl > 0.0 && finite(rl));
    }
    return bent;
}

// The radiance of triangle t seen along the ray through image point (x, y).
fn shade(t: u32, x: f32, y: f32) -> vec3f {
    let tri = tris[t];
    let i0 = tri.x;
    let i1 = tri.y;
    let i2 = tri.z;
    let p0 = verts[4u * i0].xyz;
    let p1 = verts[4u * i1].xyz;
    let p2 = verts[4u * i2].xyz;
    let w = weights(ray_dir(x, y), p0, p1, p2);
    if fp.counts.y == 0u {
        return w.x * shading[i0].colour.xyz + w.y * shading[i1].colour.xyz
            + w.z * shading[i2].colour.xyz;
    }
    // GBuffer::surface: the interpolated normal on the side of the geometric normal that
    // faces the eye.
    let pos = w.x * p0 + w.y * p1 + w.z * p2;
    let to_eye = fp.eye.xyz - pos;
    var g = cross(p1 - p0, p2 - p0);
    let gl = length(g);
    g = select(vec3f(0.0, 0.0, 1.0), g / gl, gl > 0.0 && finite(gl));
    if dot(g, to_eye) < 0.0 {
        g = -g;
    }
    // The vertex records hold the (per-vertex) bent normals; a normal-mapped scene's unbent
    // ones are in `frames`.
    let mapped = arrayLength(&frames) > 1u;
    var ni = w.x * verts[4u * i0 + 1u].xyz + w.y * verts[4u * i1 + 1u].xyz
        + w.z * verts[4u * i2 + 1u].xyz;
    if mapped {
        ni = w.x * frames[2u * i0].xyz + w.y * frames[2u * i1].xyz + w.z * frames[2u * i2].xyz;
    }
    let nl = length(ni);
    var n = select(g, ni / nl, nl > 0.0 && finite(nl));
    let side = select(1.0, -1.0, dot(n, g) < 0.0);
    let el = length(to_eye);
    let wo = select(n, to_eye / el, el > 0.0 && finite(el));
    let m = min(tri.w, max(fp.counts.w, 1u) - 1u);
    let uv = w.x * vec2f(verts[4u * i0 + 1u].w, verts[4u * i0 + 3u].w)
        + w.y * vec2f(verts[4u * i1 + 1u].w, verts[4u * i1 + 3u].w)
        + w.z * vec2f(verts[4u * i2 + 1u].w, verts[4u * i2 + 3u].w);
    // gbuffer::uv_footprint: the UV where the rays through the next pixel right and down meet
    // the triangle's plane, less the UV here.
    let uv_at = array<vec2f, 3>(vec2f(verts[4u * i0 + 1u].w, verts[4u * i0 + 3u].w),
        vec2f(verts[4u * i1 + 1u].w, verts[4u * i1 + 3u].w),
        vec2f(verts[4u * i2 + 1u].w, verts[4u * i2 + 3u].w));
    let w0 = plane_weights(ray_dir(x, y), p0, p1, p2);
    let wx = plane_weights(ray_dir(x + 1.0, y), p0, p1, p2);
    let wy = plane_weights(ray_dir(x, y + 1.0), p0, p1, p2);
    var duv = mat2x2f(vec2f(0.0), vec2f(0.0));
    if w0.w > 0.0 && wx.w > 0.0 && wy.w > 0.0 {
        let here = w0.x * uv_at[0] + w0.y * uv_at[1] + w0.z * uv_at[2];
        duv = mat2x2f(wx.x * uv_at[0] + wx.y * uv_at[1] + wx.z * uv_at[2] - here,
            wy.x * uv_at[0] + wy.y * uv_at[1] + wy.z * uv_at[2] - here);
    }
    let nm = materials[5u * m + 4u];
    let nt = bitcast<u32>(nm.x);
    if mapped && nt != 0u {
        let tv = w.x * frames[2u * i0 + 1u] + w.y * frames[2u * i1 + 1u]
            + w.z * frames[2u * i2 + 1u];
        let facing = side * n;
        n = side * bend(n, tv.xyz, select(1.0, -1.0, tv.w < 0.0),
            normal_texel(surface_sample(nt - 1u, uv, false, duv), nm.y));
        n = keep_facing(n, facing, wo);
    } else {
        n = side * n;
    }
    if !(dot(n, wo) > 0.0) {
        return vec3f(0.0);
    }
    let mat = surface_material(m, uv, duv);
    let albedo = mat.albedo;
    let f0 = mat.f0;
    let frame = to_local(n, wo);
    let lt = ltc_lookup(albedo.w, atan2(length(cross(n, wo)), dot(n, wo)));
    let spec = f0 * lt.magnitude + (vec3f(1.0) - f0) * lt.fresnel;
    let nd = light_directions(pos, n);
    if nd < 3u {
        return vec3f(0.0);
    }
    // light_directions leaves its polygon in ig_src, where shade_piece reads it.
    let pc = shade_piece(nd, emitter(pos, frame, lt));
    let rd = clamp(w.x * shading[i0].ratio_d + w.y * shading[i1].ratio_d
        + w.z * shading[i2].ratio_d, vec3f(0.0), vec3f(1.0));
    let rs = clamp(w.x * shading[i0].ratio_s + w.y * shading[i1].ratio_s
        + w.z * shading[i2].ratio_s, vec3f(0.0), vec3f(1.0));
    let c = fp.radiance.xyz * light_falloff(pos)
        * (albedo.xyz * pc.d.xyz * rd + spec * pc.s.xyz * rs);
    return select(vec3f(0.0), c, finite3(c));
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    if id.x >= fp.size.x || id.y >= fp.size.y {
        return;
    }
    let px = vec2i(id.xy);
    let samples = fp.size.z;
    // A pixel inside one triangle is shaded once, at its centre, as the CPU shades it.
    let first = vis_id(px, 0u);
    var uniform = true;
    for (var s = 1u; s < samples; s++) {
        uniform = uniform && vis_id(px, s) == first;
    }
    if uniform {
        var c = vec3f(0.0);
        if first != 0u {
            c = shade(first - 1u, f32(id.x) + 0.5, f32(id.y) + 0.5);
        }
        put(id.y * fp.size.x + id.x, c);
        return;
    }
    var sum = vec3f(0.0);
    // The triangles shaded so far in this pixel and their radiance.
    var seen = array<u32, 4>(0u, 0u, 0u, 0u);
    var value = array<vec3f, 4>(vec3f(0.0), vec3f(0.0), vec3f(0.0), vec3f(0.0));
    for (var s = 0u; s < samples; s++) {
        let tri = vis_id(px, s);
        if tri == 0u {
            continue;
        }
        var c = vec3f(0.0);
        var found = false;
        for (var k = 0u; k < s; k++) {
            if seen[k] == tri {
                c = value[k];
                found = true;
            }
        }
        if !found {
            let o = sample_offset(s);
            c = shade(tri - 1u, f32(id.x) + o.x, f32(id.y) + o.y);
        }
        seen[s] = tri;
        value[s] = c;
        sum += c;
    }
    put(id.y * fp.size.x + id.x, sum / f32(samples));
}

// Writes pixel i's radiance c, or adds it to the lights' before it (`ResolveParams::layer`).
fn put(i: u32, c: vec3f) {
    if fp.layer.x == 1u {
        image[i] = vec4f(image[i].xyz + c, 1.0);
    } else {
        image[i] = vec4f(c, 1.0);
    }
}
