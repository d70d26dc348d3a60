// Shared by the compute and the raster shaders: the LTC table lookup [Heitz16], the stable
// polygon integral of client/src/ltc/polygon.rs and the light's directions, in f32. Each
// shader defines the accessors ltc_size, ltc_a, ltc_b, light_count, light_vertex and
// light_normal over its own bindings.
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

// Scratch polygons of the integral (private: one per invocation).
var<private> ig_t: array<vec3f, MAXV>;
var<private> ig_c: array<vec3f, MAXV>;

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
    var v: f32;
    if width < SMALL {
        var sum = 0.0;
        var b = normalize(ig_c[1]);
        for (var i = 2u; i < k; i++) {
            let c = normalize(ig_c[i]);
            let num = dot(u0, cross(b - u0, c - u0));
            let den = 1.0 + dot(u0, b) + dot(b, c) + dot(c, u0);
            sum += 2.0 * atan2(num, den) * normalize(u0 + b + c).z;
            b = c;
        }
        v = abs(sum) / PI;
    } else {
        var sum = 0.0;
        var p = ig_c[k - 1u];
        for (var i = 0u; i < k; i++) {
            let q = ig_c[i];
            sum += edge(p, q);
            p = q;
        }
        v = abs(sum) / (2.0 * PI);
    }
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

// shade::light_directions: the light polygon as unit directions from p, clipped to the upper
// hemisphere of n, into `dirs`; 0 when below the horizon or behind a one-sided light.
fn light_directions(p: vec3f, n: vec3f) -> u32 {
    let count = light_count();
    let ln = light_normal();
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
    let k = clip_src(n, count);
    for (var i = 0u; i < k; i++) {
        dirs[i] = ig_src[i];
    }
    return k;
}

