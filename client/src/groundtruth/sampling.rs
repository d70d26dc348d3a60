//! Sampling a planar convex polygon (the light) as seen from a shading point.
//!
//! - **Solid-angle sampling** (uniform over the spherical polygon, pdf 1/Ω): the polygon is
//!   cut into a fan of spherical triangles (the projection of a straight edge is a great-circle
//!   arc, so the fan tiles the spherical polygon exactly), one is chosen with probability Ωᵢ/Ω,
//!   and a direction is drawn uniformly in it by Arvo's method (J. Arvo, "Stratified Sampling of
//!   Spherical Triangles", SIGGRAPH 1995), in the numerically careful form of PBRT-v4
//!   (`SampleSphericalTriangle`). The Ωᵢ come from Van Oosterom & Strackee's formula
//!   tan(Ω/2) = |a·(b×c)| / (|a||b||c| + (a·b)|c| + (b·c)|a| + (c·a)|b|), evaluated on unnormalised
//!   offsets with the triple product taken on edge vectors, so tiny triangles keep their digits.
//! - **Area sampling** (uniform over the polygon's area, pdf_ω = d² / (A |cos θ_l|)) for
//!   polygons subtending less than [`AREA_SAMPLING_BELOW_SR`]: there Arvo's α + β + γ − π loses
//!   digits, and area sampling is already nearly uniform in solid angle (distance and cosine
//!   vary little across a light that small as seen from the point).
//!
//! The polygon can first be clipped to a half-space (the shading point's upper hemisphere):
//! Sutherland–Hodgman on the offsets; the clipped polygon is still planar and convex, and
//! directions below the horizon (where the BRDF is zero) are never drawn.
//!
//! Everything works on offsets `q − p` (light vertex minus shading point) in f64, so huge and
//! tiny scene scales only scale the numbers.

use std::f64::consts::PI;

use glam::DVec3;

/// Below this solid angle (steradians) the polygon is sampled by area.
pub(crate) const AREA_SAMPLING_BELOW_SR: f64 = 1e-4;

/// A direction drawn toward the light.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LightSample {
    /// Unit direction from the shading point.
    pub(crate) dir: DVec3,
    /// Distance to the light plane along `dir`.
    pub(crate) dist: f64,
    /// Density per unit solid angle.
    pub(crate) pdf: f64,
}

/// A light polygon seen from one shading point, ready for sampling and pdf queries.
#[derive(Clone, Debug)]
pub(crate) struct PolygonSampler {
    /// Unit normal of the light's plane and `n·x` for its points `x` (offsets); `h ≠ 0`.
    plane_n: DVec3,
    plane_h: f64,
    /// Great-circle edge normals, oriented so that directions inside have `e·w ≥ 0`.
    edges: Vec<DVec3>,
    solid_angle: f64,
    mode: Mode,
}

#[derive(Clone, Debug)]
enum Mode {
    Spherical {
        tris: Vec<SphTri>,
        cdf: Vec<f64>,
    },
    Area {
        tris: Vec<[DVec3; 3]>,
        cdf: Vec<f64>,
        area: f64,
    },
}

/// A spherical triangle with what Arvo's sampling needs precomputed.
#[derive(Clone, Copy, Debug)]
struct SphTri {
    a: DVec3,
    b: DVec3,
    /// Unit vector orthogonal to `a` in the plane of `a` and `c` (towards `c`).
    c_perp: DVec3,
    cos_alpha: f64,
    sin_alpha: f64,
    /// α + β + γ (the area plus π).
    area_pi: f64,
    cos_c: f64,
}

impl PolygonSampler {
    /// `offsets`: the polygon's vertices minus the shading point (convex, planar, any winding);
    /// `plane_n`: unit normal of its plane; `clip`: keep only the part with `clip·x ≥ 0`.
    /// `None` when nothing is left or it subtends no solid angle (the point lies in the light's
    /// plane, or the input is degenerate or not finite).
    pub(crate) fn new(
        offsets: &[DVec3],
        plane_n: DVec3,
        clip: Option<DVec3>,
    ) -> Option<PolygonSampler> {
        if offsets.len() < 3 || !offsets.iter().all(|x| x.is_finite()) || !plane_n.is_finite() {
            return None;
        }
        let scale = offsets.iter().map(|x| x.length()).fold(0.0, f64::max);
        let plane_h = offsets.iter().map(|x| plane_n.dot(*x)).sum::<f64>() / offsets.len() as f64;
        if plane_h.is_nan() || plane_h.abs() <= 1e-12 * scale {
            return None;
        }
        let verts = match clip {
            Some(n) => clip_polygon(offsets, n),
            None => offsets.to_vec(),
        };
        if verts.len() < 3 {
            return None;
        }
        let k = verts.len();
        // Edge planes, oriented by an interior direction (the normalised sum of the unit
        // vertex directions lies inside a convex spherical polygon).
        let centre: DVec3 = verts.iter().map(|x| x.normalize_or_zero()).sum();
        let mut edges: Vec<DVec3> = (0..k)
            .map(|i| {
                let (p, q) = (verts[i], verts[(i + 1) % k]);
                p.cross(q - p)
            })
            .collect();
        let orient: f64 = edges.iter().map(|e| e.dot(centre)).sum();
        if orient < 0.0 {
            edges.iter_mut().for_each(|e| *e = -*e);
        }

        // Fan triangles (x₀, xᵢ, xᵢ₊₁): solid angles.
        let x0 = verts[0];
        let l0 = x0.length();
        let mut omegas = Vec::with_capacity(k - 2);
        for i in 1..k - 1 {
            let (xi, xj) = (verts[i], verts[i + 1]);
            let triple = x0.dot((xi - x0).cross(xj - x0)).abs();
            let (li, lj) = (xi.length(), xj.length());
            let den = l0 * li * lj + x0.dot(xi) * lj + xi.dot(xj) * l0 + xj.dot(x0) * li;
            let om = 2.0 * triple.atan2(den);
            omegas.push(if om.is_finite() && om > 0.0 { om } else { 0.0 });
        }
        let solid_angle: f64 = omegas.iter().sum();
        if !(solid_angle > 0.0 && solid_angle.is_finite()) {
            return None;
        }

        let mode = if solid_angle < AREA_SAMPLING_BELOW_SR {
            let mut tris = Vec::with_capacity(k - 2);
            let mut cdf = Vec::with_capacity(k - 2);
            let mut area = 0.0;
            for i in 1..k - 1 {
                let t = [x0, verts[i], verts[i + 1]];
                area += 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
                tris.push(t);
                cdf.push(area);
            }
            if !(area > 0.0 && area.is_finite()) {
                return None;
            }
            Mode::Area { tris, cdf, area }
        } else {
            let mut tris = Vec::with_capacity(k - 2);
            let mut cdf = Vec::with_capacity(k - 2);
            let mut acc = 0.0;
            for i in 1..k - 1 {
                let Some(t) = SphTri::new(x0, verts[i], verts[i + 1]) else {
                    continue;
                };
                acc += omegas[i - 1];
                tris.push(t);
                cdf.push(acc);
            }
            if tris.is_empty() || acc.is_nan() || acc <= 0.0 {
                return None;
            }
            Mode::Spherical { tris, cdf }
        };
        Some(PolygonSampler {
            plane_n,
            plane_h,
            edges,
            solid_angle,
            mode,
        })
    }

    #[cfg(test)]
    /// Solid angle of the (clipped) polygon.
    pub(crate) fn solid_angle(&self) -> f64 {
        self.solid_angle
    }

    /// Draws a direction toward the polygon from `u` in [0, 1)². `None` on a numerically
    /// failed draw (it then contributes nothing; such draws have probability ~0).
    pub(crate) fn sample(&self, u: [f64; 2]) -> Option<LightSample> {
        match &self.mode {
            Mode::Spherical { tris, cdf } => {
                let (i, u0) = pick(cdf, u[0]);
                let dir = tris[i].sample([u0, u[1]])?;
                let dist = self.distance(dir)?;
                Some(LightSample {
                    dir,
                    dist,
                    pdf: 1.0 / self.solid_angle,
                })
            }
            Mode::Area { tris, cdf, area } => {
                let (i, u0) = pick(cdf, u[0]);
                let [a, b, c] = tris[i];
                let s = u0.sqrt();
                let x = (1.0 - s) * a + (s * (1.0 - u[1])) * b + (s * u[1]) * c;
                let dist = x.length();
                let dir = x / dist;
                let cos_l = self.plane_n.dot(dir).abs();
                let pdf = dist * dist / (area * cos_l);
                (dir.is_finite() && dist > 0.0 && pdf.is_finite() && pdf > 0.0)
                    .then_some(LightSample { dir, dist, pdf })
            }
        }
    }

    /// For a unit direction `w`: `(distance to the light, pdf of [`Self::sample`] for w)` when
    /// `w` points into the (clipped) polygon, else `None`.
    pub(crate) fn pdf(&self, w: DVec3) -> Option<(f64, f64)> {
        if self.edges.iter().any(|e| e.dot(w) < 0.0) {
            return None;
        }
        let dist = self.distance(w)?;
        let pdf = match &self.mode {
            Mode::Spherical { .. } => 1.0 / self.solid_angle,
            Mode::Area { area, .. } => {
                let cos_l = self.plane_n.dot(w).abs();
                dist * dist / (area * cos_l)
            }
        };
        (pdf.is_finite() && pdf > 0.0).then_some((dist, pdf))
    }

    /// Distance along unit `w` to the light's plane, if positive and finite.
    fn distance(&self, w: DVec3) -> Option<f64> {
        let t = self.plane_h / self.plane_n.dot(w);
        (t > 0.0 && t.is_finite()).then_some(t)
    }
}

/// Index of the cdf bin `u·total` falls in, and `u` remapped to [0, 1) within it.
fn pick(cdf: &[f64], u: f64) -> (usize, f64) {
    let total = cdf.last().copied().unwrap_or(1.0);
    let x = u * total;
    let i = cdf.partition_point(|&c| c <= x).min(cdf.len() - 1);
    let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
    let w = cdf[i] - lo;
    let r = if w > 0.0 { (x - lo) / w } else { 0.5 };
    (i, r.clamp(0.0, 1.0 - f64::EPSILON))
}

/// Sutherland–Hodgman: the part of a convex polygon with `n·x ≥ 0`.
pub(crate) fn clip_polygon(poly: &[DVec3], n: DVec3) -> Vec<DVec3> {
    let k = poly.len();
    let mut out = Vec::with_capacity(k + 1);
    for i in 0..k {
        let (a, b) = (poly[i], poly[(i + 1) % k]);
        let (da, db) = (n.dot(a), n.dot(b));
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            let t = da / (da - db);
            let x = a + (b - a) * t;
            // The cut point lies on the plane: force it there so later tests see z = 0, not
            // a rounding error below it.
            out.push(x - n * (n.dot(x) / n.length_squared()).min(0.0));
        }
    }
    out
}

/// The angle between unit vectors, accurate for nearly equal and nearly opposite ones.
fn angle_between(v1: DVec3, v2: DVec3) -> f64 {
    if v1.dot(v2) < 0.0 {
        PI - 2.0 * ((v1 + v2).length() / 2.0).min(1.0).asin()
    } else {
        2.0 * ((v2 - v1).length() / 2.0).min(1.0).asin()
    }
}

/// `v` minus its component along unit `w`.
fn gram_schmidt(v: DVec3, w: DVec3) -> DVec3 {
    v - v.dot(w) * w
}

impl SphTri {
    fn new(a: DVec3, b: DVec3, c: DVec3) -> Option<SphTri> {
        let (a, b, c) = (a.try_normalize()?, b.try_normalize()?, c.try_normalize()?);
        let n_ab = a.cross(b).try_normalize()?;
        let n_bc = b.cross(c).try_normalize()?;
        let n_ca = c.cross(a).try_normalize()?;
        let alpha = angle_between(n_ab, -n_ca);
        let beta = angle_between(n_bc, -n_ab);
        let gamma = angle_between(n_ca, -n_bc);
        let c_perp = gram_schmidt(c, a).try_normalize()?;
        let t = SphTri {
            a,
            b,
            c_perp,
            cos_alpha: alpha.cos(),
            sin_alpha: alpha.sin(),
            area_pi: alpha + beta + gamma,
            cos_c: a.dot(b),
        };
        (t.area_pi > PI && t.area_pi.is_finite()).then_some(t)
    }

    /// Arvo's uniform sample of the triangle (PBRT-v4's formulation).
    fn sample(&self, u: [f64; 2]) -> Option<DVec3> {
        // Sub-triangle of area u₀·A: its third vertex c′ on the arc from a to c.
        let ap_pi = PI + u[0] * (self.area_pi - PI);
        let (s, c) = ap_pi.sin_cos();
        let sin_phi = s * self.cos_alpha - c * self.sin_alpha;
        let cos_phi = c * self.cos_alpha + s * self.sin_alpha;
        let k1 = cos_phi + self.cos_alpha;
        let k2 = sin_phi - self.sin_alpha * self.cos_c;
        let cos_bp = (k2 + (k2 * cos_phi - k1 * sin_phi) * self.cos_alpha)
            / ((k2 * sin_phi + k1 * cos_phi) * self.sin_alpha);
        let cos_bp = if cos_bp.is_nan() {
            1.0
        } else {
            cos_bp.clamp(-1.0, 1.0)
        };
        let sin_bp = (1.0 - cos_bp * cos_bp).max(0.0).sqrt();
        let cp = cos_bp * self.a + sin_bp * self.c_perp;
        // Uniform in the sub-triangle's edge from b to c′ by the cosine of the arc.
        let cos_t = 1.0 - u[1] * (1.0 - cp.dot(self.b));
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let w = match gram_schmidt(cp, self.b).try_normalize() {
            Some(t) => cos_t * self.b + sin_t * t,
            None => self.b,
        };
        w.try_normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::groundtruth::rng::Pcg32;

    fn square(z: f64, s: f64, cx: f64) -> Vec<DVec3> {
        vec![
            DVec3::new(cx - s, -s, z),
            DVec3::new(cx + s, -s, z),
            DVec3::new(cx + s, s, z),
            DVec3::new(cx - s, s, z),
        ]
    }

    /// Uniform sampling: ∫ over the polygon of g estimated by the sampler matches a brute-force
    /// estimate over the hemisphere, for large, small and horizon-crossing polygons.
    #[test]
    fn samples_are_uniform_in_solid_angle() {
        let g = |w: DVec3| w.z.max(0.0) * (1.0 + w.x);
        for (poly, clip) in [
            (square(1.0, 0.5, 0.3), None),
            (square(1.0, 3.0, 0.0), None),
            (
                square(0.2, 1.0, 0.9),
                Some(DVec3::new(0.3, 0.0, 1.0).normalize()),
            ),
            (square(1.0, 1e-3, 0.2), None),
        ] {
            let s = PolygonSampler::new(&poly, DVec3::Z, clip).expect("sampler");
            let mut rng = Pcg32::new(1, 2);
            let n = 200_000;
            let mut est = 0.0;
            for _ in 0..n {
                if let Some(ls) = s.sample(rng.next_2d()) {
                    assert!(s.pdf(ls.dir).is_some(), "sample outside its own polygon");
                    est += g(ls.dir) / ls.pdf;
                }
            }
            est /= n as f64;
            // Brute force: uniform hemisphere directions that hit the polygon.
            let mut bf = 0.0;
            let m = 2_000_000;
            for _ in 0..m {
                let [u0, u1] = rng.next_2d();
                let z = u0;
                let r = (1.0 - z * z).sqrt();
                let w = DVec3::new(r * (2.0 * PI * u1).cos(), r * (2.0 * PI * u1).sin(), z);
                if s.pdf(w).is_some() {
                    bf += g(w) * 2.0 * PI;
                }
            }
            bf /= m as f64;
            let tol = 0.02 * bf + 2e-5;
            assert!(
                (est - bf).abs() < tol,
                "{est} vs {bf}; Ω {}",
                s.solid_angle()
            );
        }
    }

    #[test]
    fn solid_angle_of_a_square_matches_the_closed_form() {
        // Square of half-side s at height 1 centred above: Ω = 4 asin(s² / (1 + s²)).
        for s in [1e-5, 1e-3, 0.5, 10.0, 1e4] {
            let p = PolygonSampler::new(&square(1.0, s, 0.0), DVec3::Z, None).expect("sampler");
            let exact = 4.0 * (s * s / (1.0 + s * s)).asin();
            let rel = (p.solid_angle() - exact).abs() / exact;
            assert!(rel < 1e-9, "s {s}: {} vs {exact}", p.solid_angle());
        }
    }
}

/// A round light seen from one shading point — a sphere's visible cap or the sun's disk —
/// sampled uniformly in solid angle: cos θ = 1 − u k, k = 1 − cos θ_max = 2 sin²(θ_max/2)
/// (exact for tiny cones), pdf 1 / (2π k) (Pharr, Jakob & Humphreys, PBRT-v4 §A.5.4
/// `SampleUniformCone`). Directions below the horizon are drawn too (the BRDF is zero there).
#[derive(Clone, Debug)]
pub(crate) struct ConeSampler {
    axis: DVec3,
    cos_max: f64,
    /// 1 − cos θ_max.
    k: f64,
    /// The sphere's centre and radius, as an offset from the point; `None`: at infinity.
    sphere: Option<(DVec3, f64)>,
}

impl ConeSampler {
    /// The cap a sphere of `radius` at offset `centre` subtends (`None` from inside it).
    pub(crate) fn sphere(centre: DVec3, radius: f64) -> Option<ConeSampler> {
        let d = centre.length();
        if !(d > radius) || !d.is_finite() || !(radius > 0.0) {
            return None;
        }
        let sin_a = radius / d;
        let cos_a = (1.0 - sin_a * sin_a).max(0.0).sqrt();
        // 1 − cos α = sin²α / (1 + cos α).
        let k = sin_a * sin_a / (1.0 + cos_a);
        Some(ConeSampler {
            axis: centre / d,
            cos_max: cos_a,
            k,
            sphere: Some((centre, radius)),
        })
    }

    /// A disk at infinity of angular radius `half_angle` around unit `axis`.
    pub(crate) fn distant(axis: DVec3, half_angle: f64) -> Option<ConeSampler> {
        let k = 2.0 * (0.5 * half_angle).sin().powi(2);
        (k > 0.0 && axis.is_finite()).then(|| ConeSampler {
            axis: axis.normalize(),
            cos_max: half_angle.cos(),
            k,
            sphere: None,
        })
    }

    fn distance(&self, w: DVec3) -> f64 {
        match self.sphere {
            None => f64::INFINITY,
            Some((c, r)) => crate::frame::brdf::sphere_entry(c, r, DVec3::ZERO, w)
                // A direction on the rim by rounding: its closest approach.
                .unwrap_or_else(|| c.dot(w).max(0.0)),
        }
    }

    pub(crate) fn sample(&self, u: [f64; 2]) -> Option<LightSample> {
        let uk = u[0] * self.k;
        let cos = 1.0 - uk;
        let sin = (uk * (2.0 - uk)).max(0.0).sqrt();
        let phi = 2.0 * PI * u[1];
        let (a, b) = self.axis.any_orthonormal_pair();
        let dir = (self.axis * cos + (a * phi.cos() + b * phi.sin()) * sin).normalize();
        let pdf = 1.0 / (2.0 * PI * self.k);
        (dir.is_finite() && pdf.is_finite()).then(|| LightSample {
            dir,
            dist: self.distance(dir),
            pdf,
        })
    }

    pub(crate) fn pdf(&self, w: DVec3) -> Option<(f64, f64)> {
        if !(w.dot(self.axis) >= self.cos_max) {
            return None;
        }
        Some((self.distance(w), 1.0 / (2.0 * PI * self.k)))
    }
}

/// How a light is sampled from a point: a polygon, or a round light's cone.
#[derive(Clone, Debug)]
pub(crate) enum LightSampler {
    Polygon(PolygonSampler),
    Cone(ConeSampler),
}

impl LightSampler {
    pub(crate) fn sample(&self, u: [f64; 2]) -> Option<LightSample> {
        match self {
            LightSampler::Polygon(s) => s.sample(u),
            LightSampler::Cone(s) => s.sample(u),
        }
    }

    /// (distance, pdf) of direction `w`, if it reaches the light.
    pub(crate) fn pdf(&self, w: DVec3) -> Option<(f64, f64)> {
        match self {
            LightSampler::Polygon(s) => s.pdf(w),
            LightSampler::Cone(s) => s.pdf(w),
        }
    }
}
