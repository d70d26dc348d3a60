//! The project's BRDF for one material (Lambert + Schlick-GGX with separable Smith masking,
//! [Walter07], [Schlick94]) with its sampling mixture, and the shadow-ray policy every
//! ray-traced method shares.

use std::f64::consts::PI;

use bspvt_proto::Scene;
use bspvt_proto::scene::Material;
use bspvt_raytrace::Occluder;
use glam::DVec3;

use crate::ggx;

/// The project's BRDF for one material: Lambert + Schlick-GGX, per RGB channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Brdf {
    /// GGX α, clamped to [`ggx::MIN_ALPHA`]..=1.
    pub(crate) alpha: f64,
    pub(crate) albedo: DVec3,
    /// F0 (specular colour at normal incidence).
    pub(crate) f0: DVec3,
}

impl Brdf {
    /// The BRDF of GGX `alpha`, diffuse `albedo` and F0 `f0`; non-finite or negative colours become 0, α is clamped.
    pub fn new(alpha: f64, albedo: DVec3, f0: DVec3) -> Brdf {
        let clean = |c: DVec3| {
            DVec3::new(
                finite_or_zero(c.x).max(0.0),
                finite_or_zero(c.y).max(0.0),
                finite_or_zero(c.z).max(0.0),
            )
        };
        Brdf {
            alpha: ggx::clamp_alpha(alpha),
            albedo: clean(albedo),
            f0: clean(f0),
        }
    }

    pub(crate) fn from_material(m: &Material) -> Brdf {
        Brdf::new(
            f64::from(m.roughness),
            glam::Vec3::from(m.albedo).as_dvec3(),
            glam::Vec3::from(m.specular).as_dvec3(),
        )
    }

    /// f(ωo, ωi) cos θi per channel, in the local frame (z = normal). Zero below either horizon.
    #[inline]
    pub fn eval_cos(&self, wo: DVec3, wi: DVec3) -> DVec3 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return DVec3::ZERO;
        }
        let (spec, cos_d) = ggx::eval_cos(self.alpha, wo, wi);
        let s = ggx::schlick_weight(cos_d);
        let fresnel = self.f0 + (DVec3::ONE - self.f0) * s;
        self.albedo * (wi.z / PI) + fresnel * spec
    }

    /// Probability of drawing a BRDF sample from the specular lobe (else the cosine lobe):
    /// the lobes' rough weights — mean F at the view angle vs mean albedo — with at least 10 %
    /// for the specular lobe (Schlick's term never vanishes at grazing angles).
    fn spec_prob(&self, wo: DVec3) -> f64 {
        let diff = (self.albedo.x + self.albedo.y + self.albedo.z) / 3.0;
        if diff.is_nan() || diff <= 0.0 {
            return 1.0;
        }
        let s = ggx::schlick_weight(wo.z.clamp(0.0, 1.0));
        let f = self.f0 + (DVec3::ONE - self.f0) * s;
        let spec = (f.x + f.y + f.z) / 3.0;
        (spec / (spec + diff)).clamp(0.1, 1.0)
    }

    /// Draws ωi from the BRDF sampling mixture. May be below the horizon (weight 0).
    pub(crate) fn sample(&self, wo: DVec3, u_lobe: f64, u: [f64; 2]) -> DVec3 {
        if u_lobe < self.spec_prob(wo) {
            ggx::sample_vndf(self.alpha, wo, u)
        } else {
            cosine_hemisphere(u)
        }
    }

    /// Density per solid angle of [`Brdf::sample`].
    pub(crate) fn pdf(&self, wo: DVec3, wi: DVec3) -> f64 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let ps = self.spec_prob(wo);
        let spec = if ps > 0.0 {
            ps * ggx::pdf_vndf(self.alpha, wo, wi)
        } else {
            0.0
        };
        spec + (1.0 - ps) * wi.z / PI
    }
}

fn finite_or_zero(x: f64) -> f64 {
    if x.is_finite() { x } else { 0.0 }
}

/// Cosine-weighted direction on the upper hemisphere.
#[inline]
pub(crate) fn cosine_hemisphere(u: [f64; 2]) -> DVec3 {
    let r = u[0].sqrt();
    let (s, c) = (2.0 * PI * u[1]).sin_cos();
    DVec3::new(r * c, r * s, (1.0 - u[0]).max(0.0).sqrt())
}

/// Shadow rays: an occluder (none = nothing casts shadows) and the offset ε that keeps rays
/// off their own surface. Origins move by ε along the geometric normal (toward the ray's side)
/// and segments stop ε short of the light.
#[derive(Clone)]
pub struct Shadows<'a> {
    /// The scene's BVH (`None`: nothing casts shadows).
    pub occluder: Option<&'a Occluder>,
    /// Offset along the geometric normal and short of the light.
    pub epsilon: f64,
    /// The scene's lamps as posed: each is a surface in the way of the others (a pendant
    /// lamp under a ceiling lamp shadows it, as in Mitsuba, where emitters are shapes). A ray
    /// to a point of a lamp ends short of that lamp, so it never blocks its own light.
    pub lamps: Vec<LampSurface>,
}

/// A lamp's polygon as a surface shadow rays cross (either side).
#[derive(Clone, Debug)]
pub enum LampSurface {
    /// A polygon lamp.
    Polygon {
        /// Convex polygon, counter-clockwise about `normal`.
        vertices: Vec<DVec3>,
        /// Unit normal.
        normal: DVec3,
    },
    /// A point or spot light's sphere.
    Sphere {
        /// Its centre.
        centre: DVec3,
        /// Its radius.
        radius: f64,
    },
}

impl LampSurface {
    /// Where the ray from `o` along unit `d` first meets it.
    fn distance(&self, o: DVec3, d: DVec3) -> Option<f64> {
        match self {
            LampSurface::Polygon { vertices, normal } => {
                polygon_crossing(vertices, *normal, o, d).map(|x| x.0)
            }
            LampSurface::Sphere { centre, radius } => sphere_entry(*centre, *radius, o, d),
        }
    }
}

/// Where the ray from `o` along unit `d` enters the sphere (`None`: it misses, the sphere is
/// behind, or `o` is inside). The near root as c/q (Press et al., "Numerical Recipes" §5.6):
/// no cancellation for a far, small sphere.
pub fn sphere_entry(centre: DVec3, radius: f64, o: DVec3, d: DVec3) -> Option<f64> {
    let oc = o - centre;
    let b = oc.dot(d);
    let c = oc.length_squared() - radius * radius;
    if !(c > 0.0) || !(b < 0.0) {
        return None;
    }
    let disc = b * b - c;
    if !(disc >= 0.0) {
        return None;
    }
    let q = -b + disc.sqrt();
    let t = c / q;
    (t > 0.0 && t.is_finite()).then_some(t)
}

/// Where the ray from `o` along unit `d` crosses the convex polygon `v` (counter-clockwise
/// about unit `n`), from either side: (distance, the point). A ray in the polygon's plane
/// does not cross it.
pub fn polygon_crossing(v: &[DVec3], n: DVec3, o: DVec3, d: DVec3) -> Option<(f64, DVec3)> {
    if v.len() < 3 {
        return None;
    }
    let t = (v[0] - o).dot(n) / d.dot(n);
    if !(t > 0.0) || !t.is_finite() {
        return None;
    }
    let q = o + t * d;
    // Inside when left of every edge.
    let inside = (0..v.len()).all(|i| {
        let (a, b) = (v[i], v[(i + 1) % v.len()]);
        (b - a).cross(q - a).dot(n) >= 0.0
    });
    inside.then_some((t, q))
}

impl<'a> Shadows<'a> {
    /// ε = 1e-4 × the mesh's bounding-box diagonal.
    pub(crate) fn for_scene(scene: &Scene, occluder: Option<&'a Occluder>) -> Shadows<'a> {
        let diag = f64::from(scene.mesh.bounds().diagonal());
        Shadows {
            occluder,
            lamps: Vec::new(),
            epsilon: 1e-4
                * if diag.is_finite() && diag > 0.0 {
                    diag
                } else {
                    1.0
                },
        }
    }

    /// True when nothing blocks the segment from `p` along unit `w` to distance `dist`.
    pub(crate) fn visible(&self, p: DVec3, ng: DVec3, w: DVec3, dist: f64) -> bool {
        let Some(occ) = self.occluder else {
            return true;
        };
        let short = dist - self.epsilon;
        if self
            .lamps
            .iter()
            .any(|l| l.distance(p, w).is_some_and(|t| t < short))
        {
            return false;
        }
        let side = if ng.dot(w) >= 0.0 { 1.0 } else { -1.0 };
        let origin = p + ng * (self.epsilon * side);
        // A light at infinity (the sun): the ray runs to infinity.
        if dist == f64::INFINITY {
            return !origin.is_finite()
                || !occ.occluded_segment(origin.as_vec3(), w.as_vec3(), f32::INFINITY);
        }
        let d = (p + w * dist) - origin;
        let len = d.length();
        let t_max = len - self.epsilon;
        if t_max.is_nan() || t_max <= 0.0 || !origin.is_finite() {
            return true;
        }
        !occ.occluded_segment(origin.as_vec3(), (d / len).as_vec3(), t_max as f32)
    }
}
