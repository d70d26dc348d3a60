// Shared by the compute and the raster shaders: the LTC table lookup [Heitz16], the stable
// polygon integral of client/src/ltc/polygon.rs, the light's directions and its texture, in
// f32. Each shader defines the accessors ltc_size, ltc_a, ltc_b, light_count, light_word,
// light_normal, light_textured and light_tex over its own bindings.
//
// Stability as on the CPU: θ = atan2(|p × q|, p·q), p × q computed as p × (q − p), and each
// polygon scaled by a power of two (exact) before the edge sum. Non-finite values are tested on
// their bits (a shader compiler may assume that no NaN occurs and fold `x != x` away).

const PI: f32 = 3.14159265358979;
// Vertices of one spherical polygon (a light's 8, the horizon, four face planes, cuts).
const MAXV: u32 = 24u;
// ggx::MIN_ALPHA and ltc::table::THETA_MAX_DEG in radians.
const MIN_ALPHA: f32 = 1e-4;
const THETA_MAX: f32 = 1.5706217;
// Below this angular width a polygon is integrated as a fan (integrate_poly).
const SMALL: f32 = 0.0156;

fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn finite3(v: vec3f) -> bool {
    return finite(v.x) && finite(v.y) && finite(v.z);
}

// One LTC: world → cosine space (M⁻¹ · to_local) and the BRDF integrals.
struct Ltc {
    m_inv: mat3x3f,
    // local ← cosine space up to a scale (the inverse of m_inv, formed without inverting:
    // rows (m11, 0, m13), (0, m22, 0), (m31, 0, 1) in the basis X, Y, Z), its determinant.
    m: mat3x3f,
    det: f32,
    magnitude: f32,
    fresnel: f32,
}

// ltc::table::LtcTable::lookup: bilinear over (ln α, view angle) of δ = ρ + θ, ln m11, ln m22,
// q = m13/m11, m31, magnitude, fresnel; M⁻¹ rows (m22/Δ)(X − m13 Z), Y, (m22/Δ)(m11 Z − m31 X).
fn ltc_lookup(alpha_in: f32, theta_in: f32) -> Ltc {
    // ggx::clamp_alpha (NaN → 1).
    let alpha = select(1.0, clamp(alpha_in, MIN_ALPHA, 1.0), finite(alpha_in));
    let theta = clamp(theta_in, 0.0, THETA_MAX);
    let n = ltc_size();
    let last = f32(n - 1u);
    let sa = clamp(1.0 - log(alpha) / log(MIN_ALPHA), 0.0, 1.0) * last;
    let st = clamp(1.0 - sqrt(1.0 - clamp(theta / THETA_MAX, 0.0, 1.0)), 0.0, 1.0) * last;
    let i0 = min(u32(floor(sa)), n - 2u);
    let j0 = min(u32(floor(st)), n - 2u);
    let fi = clamp(sa - f32(i0), 0.0, 1.0);
    let fj = clamp(st - f32(j0), 0.0, 1.0);
    let w = vec4f((1.0 - fi) * (1.0 - fj), (1.0 - fi) * fj, fi * (1.0 - fj), fi * fj);
    let k00 = i0 * n + j0;
    let k01 = k00 + 1u;
    let k10 = k00 + n;
    let k11 = k10 + 1u;
    let a = w.x * ltc_a(k00) + w.y * ltc_a(k01) + w.z * ltc_a(k10) + w.w * ltc_a(k11);
    let b = w.x * ltc_b(k00) + w.y * ltc_b(k01) + w.z * ltc_b(k10) + w.w * ltc_b(k11);
    let rho = a.x - theta;
    let m11 = exp(a.y);
    let m22 = exp(a.z);
    let m13 = a.w * m11;
    let m31 = b.x;
    // Δ > 0 for every interpolated shape of the shipped table (client/tests/ltc_table.rs).
    let det = max(m11 - m13 * m31, 1e-6 * m11);
    let s = sin(rho);
    let c = cos(rho);
    let x = vec3f(c, 0.0, -s);
    let z = vec3f(s, 0.0, c);
    let k = m22 / det;
    let r0 = k * (x - m13 * z);
    let r2 = k * (m11 * z - m31 * x);
    var out: Ltc;
    out.m_inv = transpose(mat3x3f(r0, vec3f(0.0, 1.0, 0.0), r2));
    let fwd = transpose(mat3x3f(vec3f(m11, 0.0, m13), vec3f(0.0, m22, 0.0),
        vec3f(m31, 0.0, 1.0)));
    out.m = mat3x3f(x, vec3f(0.0, 1.0, 0.0), z) * fwd;
    out.det = m22 * det;
    out.magnitude = max(b.y, 0.0);
    out.fresnel = clamp(b.z, 0.0, out.magnitude);
    return out;
}

// The local shading frame (frame::shading::ShadingFrame): z the normal, the view in the
// xz-plane; rows of the world → local matrix. glam's any_orthonormal_vector when wo ∥ n.
// In f32 the view's tangential part t is rounding noise below |t| ~ 1e-5 (the CPU's f64 test
// is |t|² > 1e-24); there the lobe is symmetric to that order and any tangent works. Above,
// t is orthogonalised again against n so that the frame stays orthonormal.
fn to_local(n: vec3f, wo: vec3f) -> mat3x3f {
    let t0 = wo - n * dot(n, wo);
    let t = t0 - n * dot(n, t0);
    var x: vec3f;
    if dot(t, t) > 1e-10 {
        x = normalize(t);
    } else {
        let sg = select(-1.0, 1.0, n.z >= 0.0);
        let a = -1.0 / (sg + n.z);
        let b = n.x * n.y * a;
        x = vec3f(b, sg + n.y * n.y * a, -n.y);
    }
    let y = cross(n, x);
    return transpose(mat3x3f(x, y, n));
}

// θ (p × q)·z / |p × q| for one edge, cancellation-free (ltc::polygon::edge).
fn edge(p: vec3f, q: vec3f) -> f32 {
    let c = cross(p, q - p);
    let s = length(c);
    if !(s > 0.0) || !finite(s) {
        return 0.0;
    }
    return atan2(s, dot(p, q)) * c.z / s;
}

// θ (p × q) / |p × q| for one edge: a term of the vector form factor (ltc::polygon::
// vector_form_factor).
fn edge_vec(p: vec3f, q: vec3f) -> vec3f {
    let c = cross(p, q - p);
    let s = length(c);
    if !(s > 0.0) || !finite(s) {
        return vec3f(0.0);
    }
    return c * (atan2(s, dot(p, q)) / s);
}

// Scratch polygons of the integral (private: one per invocation).
var<private> ig_t: array<vec3f, MAXV>;
var<private> ig_c: array<vec3f, MAXV>;
// For a textured light: the direction of the last integrated polygon's vector form factor in
// the lobe's space (unnormalised, z ≥ 0), where the texture is fetched [Heitz16 §5.3].
var<private> ig_dir: vec3f;

// ∫ over the polygon `poly[0..count]` of the LTC with inverse matrix `m` (normalised): the
// polygon transformed by M⁻¹, scaled by a power of two, clipped to z ≥ 0 and integrated
// against cos/π (ltc::polygon::integrate). In [0, 1], 0 for degenerate input.
fn integrate_poly(m: mat3x3f, count: u32) -> f32 {
    if count < 3u {
        return 0.0;
    }
    var big = 0.0;
    for (var i = 0u; i < count; i++) {
        let t = m * ig_src[i];
        ig_t[i] = t;
        big = max(big, max(abs(t.x), max(abs(t.y), abs(t.z))));
    }
    if !(big > 0.0) || !finite(big) {
        return 0.0;
    }
    let e = frexp(big).exp;
    let scale = ldexp(1.0, -e);
    var pos = false;
    var neg = false;
    for (var i = 0u; i < count; i++) {
        let t = ig_t[i] * scale;
        ig_t[i] = t;
        pos = pos || t.z > 0.0;
        neg = neg || t.z < 0.0;
    }
    if !pos {
        return 0.0;
    }
    var k = count;
    if neg {
        // Sutherland–Hodgman against z = 0 (sphere::clip_into).
        k = 0u;
        for (var i = 0u; i < count; i++) {
            let p = ig_t[i];
            let q = ig_t[(i + 1u) % count];
            if p.z >= 0.0 && k < MAXV {
                ig_c[k] = p;
                k++;
            }
            if (p.z >= 0.0) != (q.z >= 0.0) && k < MAXV {
                ig_c[k] = p + (q - p) * (p.z / (p.z - q.z));
                k++;
            }
        }
        if k < 3u {
            return 0.0;
        }
    } else {
        for (var i = 0u; i < count; i++) {
            ig_c[i] = ig_t[i];
        }
    }
    // A polygon narrower than SMALL: in f32, the edge terms (each ~ its width t) cancel to a
    // sum ~ t², losing eps / t² of it; ∫ z/π over a fan of triangles, each its solid angle
    // [VanOosterom83] times z of its centroid, is off by O(t²) instead. SMALL = eps^¼ balances
    // the two (both ≲ 2.4e-4 relative).
    let u0 = normalize(ig_c[0]);
    var width = 0.0;
    for (var i = 1u; i < k; i++) {
        width = max(width, length(normalize(ig_c[i]) - u0));
    }
    let want_dir = light_textured();
    var dir = vec3f(0.0);
    var v: f32;
    if width < SMALL {
        var sum = 0.0;
        var b = normalize(ig_c[1]);
        for (var i = 2u; i < k; i++) {
            let c = normalize(ig_c[i]);
            let num = dot(u0, cross(b - u0, c - u0));
            let den = 1.0 + dot(u0, b) + dot(b, c) + dot(c, u0);
            // Each triangle's solid angle times its centroid's direction: the fan's vector
            // form factor (its z is the integral).
            let omega = 2.0 * atan2(num, den) * normalize(u0 + b + c);
            sum += omega.z;
            dir += omega;
            b = c;
        }
        v = abs(sum) / PI;
    } else {
        var sum = 0.0;
        var p = ig_c[k - 1u];
        for (var i = 0u; i < k; i++) {
            let q = ig_c[i];
            if want_dir {
                // The vector form factor's term; its z is the integral's term.
                let e = edge_vec(p, q);
                sum += e.z;
                dir += e;
            } else {
                sum += edge(p, q);
            }
            p = q;
        }
        v = abs(sum) / (2.0 * PI);
    }
    ig_dir = select(dir, -dir, dir.z < 0.0);
    if !finite(v) {
        return 0.0;
    }
    return min(v, 1.0);
}

// The source polygon of integrate_poly.
var<private> ig_src: array<vec3f, MAXV>;

// Out of stack or polygon room: the result is flagged, never silently wrong.
const OVERFLOW: u32 = 1u;
var<private> flags: u32;
// The light's directions after the horizon clip, and a scratch polygon.
var<private> dirs: array<vec3f, MAXV>;
var<private> tmp: array<vec3f, MAXV>;

// Keeps the part of ig_src[0..count] with n·d ≥ 0 (sphere::clip_into); returns its size (0
// when fewer than three vertices remain or none lies strictly inside).
fn clip_src(n: vec3f, count: u32) -> u32 {
    var pos = false;
    var neg = false;
    for (var i = 0u; i < count; i++) {
        let d = dot(n, ig_src[i]);
        pos = pos || d > 0.0;
        neg = neg || d < 0.0;
    }
    if !pos || count < 3u {
        return 0u;
    }
    if !neg {
        return count;
    }
    var k = 0u;
    for (var i = 0u; i < count; i++) {
        let p = ig_src[i];
        let q = ig_src[(i + 1u) % count];
        let dp = dot(n, p);
        let dq = dot(n, q);
        if dp >= 0.0 {
            if k < MAXV { tmp[k] = p; k++; } else { flags |= OVERFLOW; }
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            if k < MAXV { tmp[k] = p + (q - p) * (dp / (dp - dq)); k++; } else { flags |= OVERFLOW; }
        }
    }
    if k < 3u {
        return 0u;
    }
    for (var i = 0u; i < k; i++) {
        ig_src[i] = tmp[i];
    }
    return k;
}

// The kinds of light (light_normal().w; bspvt_shaders::gpu::lights): a polygon (0 one-sided,
// 1 two-sided; words its corners), a point or spot light's sphere (word 0 its centre and
// radius, word 1 its spot direction and range, word 2 cos inner, cos outer, 1 when a spot),
// a sun's disk at infinity (word 0 the unit direction toward it and half its diameter).
const LIGHT_SPHERE: f32 = 2.0;
const LIGHT_SUN: f32 = 3.0;
// light::ROUND_SIDES: a sphere or a disk is shaded as this regular spherical polygon.
const ROUND_SIDES: u32 = 12u;

// sin, cos, tan and atan with a small relative error at small arguments. Vulkan lets a
// device's sin and cos be off by 2⁻¹¹ absolute and its atan by 4096 ULP; an NVIDIA H200's sin
// is off by ~2⁻²¹ absolute, which is percents of sin x at x ~ 1e-5 (a sun's half-angle is
// 4.6e-3, the 12th of its solid angle 5.6e-6), and the round polygons' solid angle goes as the
// square of such angles. Below 1/4 (atan: 1/10) their Taylor series, to the first term below
// f32's rounding (x⁹/9! < 1e-11, y¹¹/11 < 1e-12, relative).
fn sin_rel(x: f32) -> f32 {
    if abs(x) < 0.25 {
        let x2 = x * x;
        return x * (1.0 - x2 / 6.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0 * (1.0 - x2 / 72.0))));
    }
    return sin(x);
}

// cos x = 1 − 2 sin²(x/2): exact to f32's rounding of 1 near 0.
fn cos_rel(x: f32) -> f32 {
    if abs(x) < 0.5 {
        let s = sin_rel(0.5 * x);
        return 1.0 - 2.0 * s * s;
    }
    return cos(x);
}

fn tan_rel(x: f32) -> f32 {
    if abs(x) < 0.25 {
        return sin_rel(x) / cos_rel(x);
    }
    return tan(x);
}

// atan y = 2 atan(y / (1 + √(1 + y²))), at most three times from [0, 1] (below 0.1 then),
// and π/2 − atan(1/y) above 1; lavapipe's atan is off by 1.5e-5 relative near 0.1.
fn atan_rel(y: f32) -> f32 {
    let inv = abs(y) > 1.0;
    var a = select(abs(y), 1.0 / abs(y), inv);
    var k = 1.0;
    if a >= 0.1 {
        a = a / (1.0 + sqrt(1.0 + a * a));
        k = 2.0;
    }
    if a >= 0.1 {
        a = a / (1.0 + sqrt(1.0 + a * a));
        k = 4.0;
    }
    if a >= 0.1 {
        a = a / (1.0 + sqrt(1.0 + a * a));
        k = 8.0;
    }
    let a2 = a * a;
    var r = k * a * (1.0 - a2 * (1.0 / 3.0 - a2 * (1.0 / 5.0 - a2 * (1.0 / 7.0 - a2 / 9.0))));
    r = select(r, 0.5 * PI - r, inv);
    return select(r, -r, y < 0.0);
}

fn light_vertex(i: u32) -> vec3f {
    return light_word(i).xyz;
}

// light::round_directions into ig_src[0..ROUND_SIDES]: the regular spherical polygon around
// `axis` with the solid angle Ω = 4π sin²(α/2) of the cap of half-angle α (sin_half =
// sin(α/2)). Each of its N isosceles triangles (apex angle C = 2π/N, sides β) has area Ω/N
// with tan(Ω/2N) = t² sin C / (1 + t² cos C), t = tan(β/2) (Todhunter §101). false where
// the input is degenerate.
fn round_directions(axis: vec3f, sin_half: f32) -> bool {
    let c = 2.0 * PI / f32(ROUND_SIDES);
    let omega = 4.0 * PI * sin_half * sin_half;
    let big_t = tan_rel(0.5 * omega / f32(ROUND_SIDES));
    let t2 = big_t / (sin(c) - big_t * cos(c));
    let al = length(axis);
    if !(t2 > 0.0) || !finite(t2) || !(al > 0.0) || !finite(al) {
        return false;
    }
    let beta = 2.0 * atan_rel(sqrt(t2));
    let sb = sin_rel(beta);
    let cb = cos_rel(beta);
    let a = axis / al;
    // glam's any_orthonormal_pair (its signum: the sign bit), so that the polygon's corners
    // are where the CPU puts them.
    let sg = select(1.0, -1.0, (bitcast<u32>(a.z) >> 31u) != 0u);
    let k = -1.0 / (sg + a.z);
    let b = a.x * a.y * k;
    let u = vec3f(1.0 + sg * a.x * a.x * k, sg * b, -sg * a.x);
    let v = vec3f(b, sg + a.y * a.y * k, -a.y);
    for (var i = 0u; i < ROUND_SIDES; i++) {
        // Clockwise about a seen from outside = counter-clockwise from the centre.
        let phi = -c * f32(i);
        ig_src[i] = a * cb + (u * cos(phi) + v * sin(phi)) * sb;
    }
    return true;
}

// Light::directions for a sphere or a disk into ig_src; false where p sees none of it
// (inside the sphere) or the input is degenerate.
fn round_light(p: vec3f) -> bool {
    let w0 = light_word(0u);
    if light_normal().w == LIGHT_SUN {
        return round_directions(w0.xyz, sin_rel(0.5 * w0.w));
    }
    let to = w0.xyz - p;
    let d = length(to);
    let r = w0.w;
    if !(d > r) || !finite(d) {
        return false;
    }
    // sin(α/2) from sin α = r / d, stable for tiny α.
    let sin_a = r / d;
    let cos_a = sqrt(max(1.0 - sin_a * sin_a, 0.0));
    return round_directions(to / d, min(sin_a / sqrt(2.0 * (1.0 + cos_a)), 1.0));
}

// shade::light_directions: the light as unit directions from p (a polygon's corners; a
// sphere's or a disk's round polygon), clipped to the upper hemisphere of n, into `dirs`; 0
// when below the horizon or behind a one-sided light.
fn light_directions(p: vec3f, n: vec3f) -> u32 {
    let count = light_count();
    let ln = light_normal();
    if ln.w == LIGHT_SPHERE || ln.w == LIGHT_SUN {
        if count != ROUND_SIDES || !round_light(p) {
            return 0u;
        }
    } else {
        if count < 3u || count > 8u {
            return 0u;
        }
        if ln.w == 0.0 && !(dot(ln.xyz, p - light_vertex(0u)) > 0.0) {
            return 0u;
        }
        for (var i = 0u; i < count; i++) {
            let d = light_vertex(i) - p;
            let l2 = dot(d, d);
            if !(l2 > 0.0) || !finite(l2) {
                return 0u;
            }
            ig_src[i] = d * inverseSqrt(l2);
        }
    }
    let k = clip_src(n, count);
    for (var i = 0u; i < k; i++) {
        dirs[i] = ig_src[i];
    }
    return k;
}

// PunctualLight::falloff of a sphere toward p (1 for the other kinds): the spot's smooth
// cone, saturate((cos − cos outer) / (cos inner − cos outer))², and the range window,
// saturate(1 − (d / range)⁴)², as KHR_lights_punctual recommends.
fn light_falloff(p: vec3f) -> f32 {
    if light_normal().w != LIGHT_SPHERE {
        return 1.0;
    }
    let to = p - light_word(0u).xyz;
    let d = length(to);
    if !(d > 0.0) || !finite(d) {
        return 0.0;
    }
    let spot = light_word(1u);
    let cone = light_word(2u);
    var f = 1.0;
    if cone.z != 0.0 {
        let cos_to = dot(spot.xyz, to / d);
        let scale = 1.0 / max(cone.x - cone.y, 0.001);
        let a = clamp(cos_to * scale - cone.y * scale, 0.0, 1.0);
        f *= a * a;
    }
    if spot.w > 0.0 {
        let x = d / spot.w;
        let x2 = x * x;
        let w = clamp(1.0 - x2 * x2, 0.0, 1.0);
        f *= w * w;
    }
    return select(0.0, f, finite(f));
}

// Textured lights [Heitz16 §5.3] (client/src/texture.rs): the prefiltered pyramid read through
// light_tex (LightTexture::gpu_words: [0] = (levels, size), [1 + l] = (width, height, offset)
// of level l as u32 bits, then the texels). A lobe fetches it once per piece where its vector
// form factor meets the light's plane, at the level of the lobe's footprint, bounded by the
// piece's own extent (LightFrame::piece_lod).

fn tex_word(i: u32) -> vec3u {
    let w = light_tex(i);
    return vec3u(bitcast<u32>(w.x), bitcast<u32>(w.y), bitcast<u32>(w.z));
}

fn tex_texel(h: vec3u, x: i32, y: i32) -> vec3f {
    let xi = u32(clamp(x, 0, i32(h.x) - 1));
    let yi = u32(clamp(y, 0, i32(h.y) - 1));
    return light_tex(h.z + yi * h.x + xi).xyz;
}

// The bilinear footprint of `uv` on a w × h image (texel centres at half-integers, v down the
// image): the top-left tap (x₀, y₀) and the weights (fx, fy) toward the next tap on each axis.
struct Taps {
    x0: i32,
    y0: i32,
    f: vec2f,
}

fn bilinear_taps(uv: vec2f, w: u32, h: u32) -> Taps {
    let xy = uv * vec2f(f32(w), f32(h)) - 0.5;
    let c = floor(xy);
    var t: Taps;
    t.x0 = i32(c.x);
    t.y0 = i32(c.y);
    t.f = xy - c;
    return t;
}

// Level::bilinear: clamp to edge, v down the image.
fn tex_bilinear(l: u32, uv_in: vec2f) -> vec3f {
    let h = tex_word(1u + l);
    // Beyond a texture's width outside [0, 1], every tap is an edge texel: clamping there
    // keeps the conversion to integers in range and changes nothing.
    let t = bilinear_taps(clamp(uv_in, vec2f(-1.0), vec2f(2.0)), h.x, h.y);
    let top = mix(tex_texel(h, t.x0, t.y0), tex_texel(h, t.x0 + 1, t.y0), t.f.x);
    let bottom = mix(tex_texel(h, t.x0, t.y0 + 1), tex_texel(h, t.x0 + 1, t.y0 + 1), t.f.x);
    return mix(top, bottom, t.f.y);
}

// LightTexture::sample: trilinear at level `lod` (clamped; NaN and +∞ → the coarsest).
fn tex_sample(uv_in: vec2f, lod_in: f32) -> vec3f {
    let levels = tex_word(0u).x;
    let top = f32(levels - 1u);
    var lod = clamp(lod_in, 0.0, top);
    if !finite(lod_in) {
        lod = select(top, 0.0, lod_in < 0.0);
    }
    let uv = select(vec2f(0.5), uv_in, finite(uv_in.x) && finite(uv_in.y));
    let l0 = min(u32(floor(lod)), levels - 1u);
    let f = lod - f32(l0);
    let a = tex_bilinear(l0, uv);
    if f > 0.0 && l0 + 1u < levels {
        return mix(a, tex_bilinear(l0 + 1u, uv), f);
    }
    return a;
}

// The texture's mean: the coarsest level's one texel.
fn tex_average() -> vec3f {
    return light_tex(tex_word(tex_word(0u).x).z).xyz;
}

// Coordinates of q in the basis (e1, e2) of a plane (texture::uv_in).
fn plane_uv(e1: vec3f, e2: vec3f, q: vec3f) -> vec2f {
    let d11 = dot(e1, e1);
    let d12 = dot(e1, e2);
    let d22 = dot(e2, e2);
    let det = d11 * d22 - d12 * d12;
    if !(abs(det) > 0.0) || !finite(det) {
        return vec2f(0.5);
    }
    let a = dot(e1, q);
    let b = dot(e2, q);
    return vec2f((d22 * a - d12 * b) / det, (d11 * b - d12 * a) / det);
}

// The light's frame from p (LightFrame::new): p₀ − p, p₁ − p₀, pₙ₋₁ − p₀, all scaled by one
// power of two to magnitudes below 1 (exact; what is computed from them does not depend on
// their common scale, and f32 keeps its range for any scene's units).
struct LightPlane {
    o: vec3f,
    e1: vec3f,
    e2: vec3f,
    // e₁ × e₂ (twice the texture's area along the plane's normal) and its dot with o.
    ortho: vec3f,
    dist: f32,
}

fn light_plane(p: vec3f) -> LightPlane {
    let n = light_count();
    let v0 = light_vertex(0u);
    var l: LightPlane;
    l.o = v0 - p;
    l.e1 = light_vertex(1u) - v0;
    l.e2 = light_vertex(n - 1u) - v0;
    let a = max(abs(l.o), max(abs(l.e1), abs(l.e2)));
    let big = max(a.x, max(a.y, a.z));
    if big > 0.0 && finite(big) {
        let scale = ldexp(1.0, -frexp(big).exp);
        l.o *= scale;
        l.e1 *= scale;
        l.e2 *= scale;
    }
    l.ortho = cross(l.e1, l.e2);
    l.dist = dot(l.ortho, l.o);
    return l;
}

// PlaneLookup [Heitz16 §5.3], evaluated in world space: the ray along a lobe's vector form
// factor meets the light's plane at the same (u, v) in either space (a linear map keeps
// coordinates on a plane), and in f32 the world is the well-conditioned side (the cosine space
// of α = 1e-4 stretches the plane by 1/α², and (u, v) solved there loses every digit).
// `fwd`: world ← the lobe's space (up to a scale); `lod`: the footprint's level log₂(d · size),
// d = distance / √area in the lobe's space = |dist| |det A|^½ / |Aᵀ ortho|^{3/2} (A = the
// lobe's local ← cosine map; ortho and dist the plane's in the local frame).
struct Lookup {
    fwd: mat3x3f,
    lod: f32,
}

// `frame`: world → local; `a`, `det_a`: local ← the lobe's space and its determinant.
fn plane_lookup(frame: mat3x3f, a: mat3x3f, det_a: f32, l: LightPlane) -> Lookup {
    var k: Lookup;
    k.fwd = transpose(frame) * a;
    let t = transpose(a) * (frame * l.ortho);
    let tl = length(t);
    let d = abs(l.dist) * sqrt(abs(det_a)) / (tl * sqrt(tl));
    k.lod = log2(max(d * f32(tex_word(0u).y), 1.0));
    return k;
}

// PlaneLookup::fetch: the texture where the ray along f (the lobe's space) meets the plane,
// the level bounded by max_lod; the mean where the ray misses it or the plane is degenerate.
fn plane_fetch(k: Lookup, l: LightPlane, f_in: vec3f, max_lod: f32) -> vec3f {
    let fw = k.fwd * f_in;
    let fl = length(fw);
    if !(fl > 0.0) || !finite(fl) || !(length(l.ortho) > 0.0) {
        return tex_average();
    }
    let f = fw / fl;
    let denom = dot(l.ortho, f);
    if !(abs(denom) > 0.0) {
        return tex_average();
    }
    let q = f * (l.dist / denom) - l.o;
    return tex_sample(plane_uv(l.e1, l.e2, q), min(k.lod, max_lod));
}

// LightFrame::piece_lod for the piece ig_src[0..count] (unit world directions): the finest
// level that still averages over all of the piece, log₂(√(its area on the light's plane / the
// texture's area) · size); 1e30 (no bound) when a direction does not reach the plane.
fn piece_lod(l: LightPlane, count: u32) -> f32 {
    let none = 1e30;
    let ortho = l.ortho;
    let texture_area = length(ortho);
    let dist = l.dist;
    if !(texture_area > 0.0) || !(abs(dist) > 0.0) || count < 3u {
        return none;
    }
    var twice = vec3f(0.0);
    var first = vec3f(0.0);
    var prev = vec3f(0.0);
    for (var i = 0u; i < count; i++) {
        let w = ig_src[i];
        let den = dot(ortho, w);
        if !(den * dist > 0.0) {
            return none;
        }
        let q = w * (dist / den);
        if i == 0u {
            first = q;
        } else {
            twice += cross(prev, q);
        }
        prev = q;
    }
    twice += cross(prev, first);
    let ratio = 0.5 * length(twice) / texture_area;
    let lod = log2(max(sqrt(ratio) * f32(tex_word(0u).y), 1.0));
    return select(none, lod, finite(lod));
}

// Both integrals of the polygon ig_src[0..count] with the light's colour (shade::Lobes::
// shade): diffuse in d, specular in s; xyz the integral times the texture fetched where its
// vector form factor points (1 for an untextured light), w the integral.
struct Piece {
    d: vec4f,
    s: vec4f,
}

// What a shading point needs of the light beyond its polygon (shade::Emitter::for_lobes):
// the lobes' maps, and for a textured light its plane and each lobe's lookup, made once for
// the many pieces a tree cuts from the light.
struct Emitter {
    frame: mat3x3f,
    to_ltc: mat3x3f,
    plane: LightPlane,
    l0: Lookup,
    l1: Lookup,
}

// `frame`: world → the local shading frame; `lt`: the specular lobe's LTC at the point p.
fn emitter(p: vec3f, frame: mat3x3f, lt: Ltc) -> Emitter {
    var e: Emitter;
    e.frame = frame;
    e.to_ltc = lt.m_inv * frame;
    if light_textured() {
        e.plane = light_plane(p);
        let id = mat3x3f(vec3f(1.0, 0.0, 0.0), vec3f(0.0, 1.0, 0.0), vec3f(0.0, 0.0, 1.0));
        e.l0 = plane_lookup(frame, id, 1.0, e.plane);
        e.l1 = plane_lookup(frame, lt.m, lt.det, e.plane);
    }
    return e;
}

fn shade_piece(count: u32, e: Emitter) -> Piece {
    var out: Piece;
    let d = integrate_poly(e.frame, count);
    var dc = vec3f(d);
    var lod = 0.0;
    if light_textured() {
        lod = piece_lod(e.plane, count);
        if d > 0.0 {
            dc = plane_fetch(e.l0, e.plane, ig_dir, lod) * d;
        }
    }
    let s = integrate_poly(e.to_ltc, count);
    var sc = vec3f(s);
    if light_textured() && s > 0.0 {
        sc = plane_fetch(e.l1, e.plane, ig_dir, lod) * s;
    }
    out.d = vec4f(dc, d);
    out.s = vec4f(sc, s);
    return out;
}
