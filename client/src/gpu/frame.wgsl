// GPU frames (render::renderer's per-vertex and per-pixel modes): the mesh rasterised, drawn
// without an index buffer (vertex i is corner i % 3 of triangle i / 3, read from storage).
// - Per vertex (mode 0): the per-vertex shading of shade.wgsl, interpolated.
// - Per pixel (mode 1): unshadowed LTC GGX [Heitz16] per pixel, times the per-vertex shadow
//   ratios (diffuse, specular) interpolated; black where the viewer is below the shading
//   hemisphere (shade::sees_viewer).
// Prepended: common.wgsl.

struct FrameParams {
    view_proj: mat4x4f,
    eye: vec4f,
    light_normal: vec4f,
    radiance: vec4f,
    light: array<vec4f, 8>,
    // light vertices, mode, LTC table size, materials.
    counts: vec4u,
}

struct VertexOut {
    colour: vec4f,
    ratio: vec2f,
    pieces: u32,
    dropped: u32,
}

@group(0) @binding(0) var<uniform> fp: FrameParams;
// Four per vertex: position, normal, (albedo, α), (F0, 0) — the compute pass's records.
@group(0) @binding(1) var<storage, read> verts: array<vec4f>;
// Three per triangle.
@group(0) @binding(2) var<storage, read> indices: array<u32>;
// The material of each triangle.
@group(0) @binding(3) var<storage, read> tri_material: array<u32>;
// Two per material: (albedo, α), (F0, 0).
@group(0) @binding(4) var<storage, read> materials: array<vec4f>;
@group(0) @binding(5) var<storage, read> shading: array<VertexOut>;
@group(0) @binding(6) var<storage, read> ltc: array<vec4f>;

fn light_count() -> u32 {
    return fp.counts.x;
}
fn light_vertex(i: u32) -> vec3f {
    return fp.light[i].xyz;
}
fn light_normal() -> vec4f {
    return fp.light_normal;
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

struct Varyings {
    @builtin(position) clip: vec4f,
    @location(0) world: vec3f,
    @location(1) normal: vec3f,
    @location(2) colour: vec3f,
    @location(3) ratio: vec2f,
    @location(4) @interpolate(flat) geometric: vec3f,
    @location(5) @interpolate(flat) material: u32,
}

@vertex
fn vs(@builtin(vertex_index) i: u32) -> Varyings {
    let t = i / 3u;
    let v = indices[i];
    let p = verts[4u * v].xyz;
    let p0 = verts[4u * indices[3u * t]].xyz;
    let p1 = verts[4u * indices[3u * t + 1u]].xyz;
    let p2 = verts[4u * indices[3u * t + 2u]].xyz;
    var out: Varyings;
    out.clip = fp.view_proj * vec4f(p, 1.0);
    out.world = p;
    out.normal = verts[4u * v + 1u].xyz;
    let s = shading[v];
    out.colour = s.colour.xyz;
    out.ratio = s.ratio;
    out.geometric = cross(p1 - p0, p2 - p0);
    out.material = min(tri_material[t], max(fp.counts.w, 1u) - 1u);
    return out;
}

@fragment
fn fs(in: Varyings) -> @location(0) vec4f {
    if fp.counts.y == 0u {
        return vec4f(in.colour, 1.0);
    }
    // frame::gbuffer's surface: the interpolated normal on the side of the geometric normal
    // that faces the eye.
    let to_eye = fp.eye.xyz - in.world;
    var g = in.geometric;
    let gl = length(g);
    g = select(vec3f(0.0, 0.0, 1.0), g / gl, gl > 0.0 && finite(gl));
    if dot(g, to_eye) < 0.0 {
        g = -g;
    }
    let nl = length(in.normal);
    var n = select(g, in.normal / nl, nl > 0.0 && finite(nl));
    if dot(n, g) < 0.0 {
        n = -n;
    }
    let el = length(to_eye);
    let wo = select(n, to_eye / el, el > 0.0 && finite(el));
    if !(dot(n, wo) > 0.0) {
        return vec4f(0.0, 0.0, 0.0, 1.0);
    }
    let albedo = materials[2u * in.material];
    let f0 = materials[2u * in.material + 1u].xyz;
    let frame = to_local(n, wo);
    let lt = ltc_lookup(albedo.w, atan2(length(cross(n, wo)), dot(n, wo)));
    let spec = f0 * lt.magnitude + (vec3f(1.0) - f0) * lt.fresnel;
    let nd = light_directions(in.world, n);
    if nd < 3u {
        return vec4f(0.0, 0.0, 0.0, 1.0);
    }
    for (var i = 0u; i < nd; i++) {
        ig_src[i] = dirs[i];
    }
    let d = integrate_poly(frame, nd);
    for (var i = 0u; i < nd; i++) {
        ig_src[i] = dirs[i];
    }
    let s = integrate_poly(lt.m_inv * frame, nd);
    let r = clamp(in.ratio, vec2f(0.0), vec2f(1.0));
    var c = fp.radiance.xyz * (albedo.xyz * d * r.x + spec * s * r.y);
    if !finite3(c) {
        c = vec3f(0.0);
    }
    return vec4f(c, 1.0);
}
