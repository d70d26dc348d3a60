//! "LTC with exact visibility": the LTC BRDF (Heitz, Dupuy, Hill, Neubelt 2016) with the
//! light's visibility measured by many shadow rays instead of read from the BSPVT.
//!
//! Unshadowed, LTC shading is analytic: specular = L (F0·magnitude + (1 − F0)·fresnel) ∫_P D,
//! diffuse = L · albedo · ∫_P cos⁺/π ([`crate::ltc::polygon`]). With visibility V, each integral
//! becomes ∫_P g V = (∫_P g) · ⟨V⟩_g, and the g-weighted mean visibility ⟨V⟩_g is estimated by a
//! ratio estimator (self-normalised importance sampling):
//!
//! ```text
//! ⟨V⟩_g ≈ Σⱼ wⱼ Vⱼ / Σⱼ wⱼ,   wⱼ = g(ωⱼ) / q(ωⱼ),   q = n_P p_P + n_D D + n_C cos⁺/π
//! ```
//!
//! over directions drawn by three stratified strategies — uniformly on the polygon (n_P = half
//! the rays, [`super::sampling`]), from the LTC lobe D itself (n_D = a quarter: a clamped cosine
//! mapped by M), and from the cosine (n_C = a quarter) — combined with the balance heuristic
//! (Veach 1997), so narrow lobes on large lights and small lights under broad lobes are both
//! well sampled. Directions outside the polygon have weight 0. The same rays serve both
//! integrands (g = D and g = cos⁺/π). With `rays = 0`, ⟨V⟩ = 1: the unshadowed analytic LTC.
//!
//! Differences between this and BSPVT shading are the visibility representation's error alone;
//! between this and [`super::render_mc`] the BRDF fit's error alone (paper 000, figure 8).

use std::f64::consts::PI;

use bspvt_proto::Scene;
use bspvt_raytrace::Occluder;
use glam::{DMat3, DVec3};
use rayon::prelude::*;

use super::rng::Pcg32;
use super::sampling::{ConeSampler, LightSampler, PolygonSampler};
use super::{Brdf, Ctx, ShadingPoint, Shadows, cosine_hemisphere};
use crate::frame::camera::View;
use crate::frame::gbuffer::GBuffer;
use crate::frame::image::Image;
use crate::frame::shading::ShadingFrame;
use crate::light::{Light, Shape};
use crate::ltc::polygon;

/// One LTC lobe: what the LTC table's lookup gives for (α, cos θ).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LtcLobe {
    /// M⁻¹, mapping lobe directions to the clamped cosine's.
    pub m_inv: DMat3,
    /// ∫ f cos over the hemisphere with F = 1 (the lobe's norm).
    pub magnitude: f64,
    /// The Schlick weight's share: specular = F0·magnitude + (1 − F0)·fresnel.
    pub fresnel: f64,
}

impl From<crate::ltc::table::Ltc> for LtcLobe {
    fn from(l: crate::ltc::table::Ltc) -> LtcLobe {
        LtcLobe {
            m_inv: l.m_inv,
            magnitude: l.magnitude,
            fresnel: l.fresnel,
        }
    }
}

/// The lookup of the built-in LTC table, for [`render_ltc_exact_visibility`].
pub fn builtin_lookup(alpha: f64, cos_theta: f64) -> LtcLobe {
    crate::ltc::table::LtcTable::builtin()
        .lookup(alpha, cos_theta)
        .into()
}

/// The normalised LTC density at unit direction `w` (local frame):
/// D(ω) = D_o(ω_o) |det M⁻¹| / |M⁻¹ω|³ with ω_o = M⁻¹ω / |M⁻¹ω| and D_o = max(z, 0)/π.
pub(crate) fn ltc_density(m_inv: &DMat3, w: DVec3) -> f64 {
    let o = *m_inv * w;
    let l2 = o.length_squared();
    let l = l2.sqrt();
    if l.is_nan() || l <= 0.0 || o.z <= 0.0 {
        return 0.0;
    }
    let d = (o.z / l) / PI * m_inv.determinant().abs() / (l2 * l);
    if d.is_finite() { d } else { 0.0 }
}

/// Stratified points of [0, 1)²: a √n × √n jittered grid, the remainder uniform.
fn stratified(n: u32, rng: &mut Pcg32, mut f: impl FnMut([f64; 2])) {
    let m = (f64::from(n).sqrt().floor() as u32).max(1);
    let grid = if m * m <= n { m * m } else { 0 };
    for k in 0..n {
        let u = rng.next_2d();
        if k < grid {
            let (i, j) = (k % m, k / m);
            f([
                (f64::from(i) + u[0]) / f64::from(m),
                (f64::from(j) + u[1]) / f64::from(m),
            ]);
        } else {
            f(u);
        }
    }
}

/// The mean visibilities ⟨V⟩_D (specular) and ⟨V⟩_cos (diffuse) over the polygon from `rays`
/// shadow rays. `sampler`: the light seen from the shading point, in the shading frame.
fn mean_visibility(
    sp: &ShadingPoint,
    frame: &ShadingFrame,
    sampler: &LightSampler,
    m_inv: &DMat3,
    shadows: &Shadows,
    rays: u32,
    rng: &mut Pcg32,
) -> (f64, f64) {
    let m = m_inv.inverse();
    let lobe_ok = m.is_finite() && m_inv.determinant().abs() > 0.0;
    let n_d = if lobe_ok { rays / 4 } else { 0 };
    let n_c = rays / 4;
    let n_p = rays - n_d - n_c;
    let (fp, fd, fc) = (f64::from(n_p), f64::from(n_d), f64::from(n_c));
    let (mut num_s, mut den_s, mut num_d, mut den_d) = (0.0, 0.0, 0.0, 0.0);
    let mut eval = |w: DVec3, hit: Option<(f64, f64)>| {
        let Some((dist, pdf_p)) = hit else { return };
        let d = ltc_density(m_inv, w);
        let c = w.z.max(0.0) / PI;
        let q = fp * pdf_p + fd * d + fc * c;
        if q.is_nan() || q <= 0.0 || (d == 0.0 && c == 0.0) {
            return;
        }
        let v = if shadows.visible(
            sp.position,
            sp.geometric,
            frame.to_world(w).normalize(),
            dist,
        ) {
            1.0
        } else {
            0.0
        };
        let (ws, wd) = (d / q, c / q);
        if ws.is_finite() && wd.is_finite() {
            num_s += ws * v;
            den_s += ws;
            num_d += wd * v;
            den_d += wd;
        }
    };
    stratified(n_p, rng, |u| {
        if let Some(ls) = sampler.sample(u) {
            eval(ls.dir, Some((ls.dist, ls.pdf)));
        }
    });
    stratified(n_d, rng, |u| {
        if let Some(w) = (m * cosine_hemisphere(u)).try_normalize() {
            eval(w, sampler.pdf(w));
        }
    });
    stratified(n_c, rng, |u| {
        let w = cosine_hemisphere(u);
        eval(w, sampler.pdf(w));
    });
    let ratio = |n: f64, d: f64| {
        if d > 0.0 {
            (n / d).clamp(0.0, 1.0)
        } else {
            1.0
        }
    };
    (ratio(num_s, den_s), ratio(num_d, den_d))
}

/// LTC shading with visibility from `rays` shadow rays (0: unshadowed analytic LTC) at one
/// point, linear RGB. `lobe`: the LTC table's entry for (brdf.alpha, cos θ of the view in
/// the shading frame of `sp`).
pub fn shade_ltc_exact_visibility(
    sp: &ShadingPoint,
    brdf: &Brdf,
    lobe: &LtcLobe,
    light: &Light,
    shadows: &Shadows,
    rays: u32,
    rng: &mut Pcg32,
) -> DVec3 {
    let ok = |v: DVec3| v.is_finite() && v.length_squared() > 0.0;
    if !(sp.position.is_finite()
        && ok(sp.normal)
        && ok(sp.wo)
        && ok(sp.geometric)
        && light.faces(sp.position)
        && crate::shade::sees_viewer(sp.normal, sp.wo))
    {
        return DVec3::ZERO;
    }
    let frame = ShadingFrame::new(sp.normal.normalize(), sp.wo.normalize());
    // A polygon's corners; a round light's spherical 12-gon of directions (Light::directions).
    let local: Vec<DVec3> = match light.shape {
        Shape::Polygon => light
            .vertices
            .iter()
            .map(|&q| frame.to_local(q - sp.position))
            .collect(),
        _ => light
            .directions(sp.position)
            .into_iter()
            .map(|d| frame.to_local(d))
            .collect(),
    };
    if local.len() < 3 {
        return DVec3::ZERO;
    }
    let spec_int = polygon::integrate(&lobe.m_inv, &local);
    let diff_int = polygon::form_factor(&local);
    let (vis_s, vis_d) = if rays == 0 || (spec_int <= 0.0 && diff_int <= 0.0) {
        (1.0, 1.0)
    } else {
        // Shadow rays toward the light itself: its polygon, a sphere's cap, the sun's cone.
        let sampler = match &light.shape {
            Shape::Polygon => PolygonSampler::new(&local, frame.to_local(light.normal), None)
                .map(LightSampler::Polygon),
            Shape::Sphere(l) => ConeSampler::sphere(
                frame.to_local(glam::Vec3::from(l.position).as_dvec3() - sp.position),
                f64::from(l.sphere_radius()),
            )
            .map(LightSampler::Cone),
            Shape::Distant { toward, half_angle } => {
                ConeSampler::distant(frame.to_local(*toward), *half_angle).map(LightSampler::Cone)
            }
        };
        match sampler {
            Some(s) => mean_visibility(sp, &frame, &s, &lobe.m_inv, shadows, rays, rng),
            None => (1.0, 1.0),
        }
    };
    let spec_colour = brdf.f0 * lobe.magnitude + (DVec3::ONE - brdf.f0) * lobe.fresnel;
    let le = match light.shape {
        Shape::Polygon => light.radiance_at(light.centroid()),
        _ => light.radiance_toward(sp.position),
    };
    let v = le * (brdf.albedo * (diff_int * vis_d) + spec_colour * (spec_int * vis_s));
    if v.is_finite() {
        v.max(DVec3::ZERO)
    } else {
        DVec3::ZERO
    }
}

/// The LTC BRDF with visibility by `rays` shadow rays per pixel (0: unshadowed analytic
/// LTC), at the G-buffer's shading points. `lookup(α, cos θ)` is the LTC table's lookup:
/// [`builtin_lookup`] for the built-in table (or any `ltc::table::LtcTable::lookup`, `.into()`).
/// Reproducible for a `seed`.
#[allow(clippy::too_many_arguments)]
pub fn render_ltc_exact_visibility(
    scene: &Scene,
    view: &View,
    gbuffer: &GBuffer,
    light: &Light,
    occluder: &Occluder,
    lookup: &(dyn Fn(f64, f64) -> LtcLobe + Sync),
    rays: u32,
    seed: u64,
) -> Image {
    let ctx = Ctx::new(scene, Some(occluder));
    let n = gbuffer.width as usize * gbuffer.height as usize;
    let px: Vec<[f32; 3]> = (0..n)
        .into_par_iter()
        .with_min_len(16)
        .map(|i| {
            let Some(s) = gbuffer.surface(&scene.mesh, view, i) else {
                return [0.0; 3];
            };
            let sp = ShadingPoint::from_surface(&s, view.eye);
            let brdf = &ctx.brdf(&s);
            let frame = ShadingFrame::new(sp.normal, sp.wo);
            let lobe = lookup(brdf.alpha, frame.cos_view(sp.wo));
            let mut rng = Pcg32::for_key(seed, i as u64);
            shade_ltc_exact_visibility(&sp, brdf, &lobe, light, &ctx.shadows, rays, &mut rng)
                .as_vec3()
                .to_array()
        })
        .collect();
    Image {
        width: gbuffer.width,
        height: gbuffer.height,
        pixels: px,
    }
}
