//! The project's BRDF ([`crate::ggx`]: Lambert + Schlick-GGX, separable Smith) as spherical
//! Gaussians in ωi, for one shading point.
//!
//! - **Diffuse**: albedo/π × the clamped cosine max(n·ωi, 0) ≈ SG(n, λ = 2.133, μ = 1.170)
//!   (Wang et al. 2009, §4; Meder & Brüderlin 2018 list the same L2 fit). The half-space
//!   visibility the renderer applies includes the horizon, so the SG's tail below the surface
//!   is cut rather than counted.
//! - **Specular** (Wang et al. 2009, §4.2, "spherical warping"): the GGX NDF about the normal
//!   as an SG in the half vector, D(h) ≈ SG(h; n, 2/α², 1/(πα²)) — normalised like D
//!   (∫ D cos θh = 1) and equal to D on the axis — warped to ωi about the reflection
//!   direction r = 2(n·ωo)n − ωo: sharpness λ/(4 n·ωo) (the Jacobian dωh/dωi = 1/(4 ωi·h) at
//!   the lobe centre), same amplitude. Fresnel, masking and the cosine are taken at the lobe
//!   centre ωi = r (where ωi·h = n·ωo and n·ωi = n·ωo):
//!   f cos ≈ F(n·ωo) G₁(ωo) G₁(r) D / (4 n·ωo).
//!
//! The approximation error against numerical integration of the exact BRDF is measured by
//! the tests here (`spec_error_table`, `diffuse_error_table`) and tabulated in `docs/sg.md`.

use glam::DVec3;

use super::Sg;
use crate::ggx;

/// The clamped cosine as an SG: sharpness and amplitude.
pub(crate) const COS_LAMBDA: f64 = 2.133;
pub(crate) const COS_MU: f64 = 1.170;

/// Smallest n·ωo the specular warp uses (grazing views: the lobe is then very sharp and
/// masked to nearly nothing).
const MIN_COS_VIEW: f64 = 1e-4;

/// max(n·ωi, 0) ≈ this SG.
pub(crate) fn cosine_lobe(n: DVec3) -> Sg {
    Sg::new(n, COS_LAMBDA, COS_MU)
}

/// The specular lobe of one point: `sg` is D·G₁G₁/(4 n·ωo) warped to ωi (Fresnel excluded);
/// the Fresnel of channel c is f0_c + (1 − f0_c) · `fresnel_weight`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SpecLobe {
    pub(crate) sg: Sg,
    pub(crate) fresnel_weight: f64,
}

/// The warped GGX lobe for roughness `alpha`, unit normal `n` and unit view `wo` (world
/// space). `None` when the view is below the horizon.
pub(crate) fn ggx_lobe(alpha: f64, n: DVec3, wo: DVec3) -> Option<SpecLobe> {
    let a = ggx::clamp_alpha(alpha);
    let cos_o = n.dot(wo);
    if !(cos_o > 0.0) {
        return None;
    }
    let c = cos_o.max(MIN_COS_VIEW);
    let r = (2.0 * cos_o * n - wo).normalize_or(n);
    let a2 = a * a;
    let lambda_d = 2.0 / a2;
    let mu_d = 1.0 / (std::f64::consts::PI * a2);
    let g = ggx::g1(a, c) * ggx::g1(a, c);
    Some(SpecLobe {
        sg: Sg::new(r, lambda_d / (4.0 * c), mu_d * g / (4.0 * c)),
        fresnel_weight: ggx::schlick_weight(cos_o.min(1.0)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::shading::ShadingFrame;
    use crate::sg::testutil::quad_about;

    /// ∫ L(ωi) f cos dωi by quadrature (exact GGX, Fresnel weight f0 = 1 → F = 1) vs the SG
    /// form with the horizon cut (the renderer's formula without occluders).
    fn spec_case(alpha: f64, theta_o: f64, light: Sg) -> (f64, f64) {
        let n = DVec3::Z;
        let wo = DVec3::new(theta_o.sin(), 0.0, theta_o.cos());
        let frame = ShadingFrame::new(n, wo);
        let lo = frame.to_local(wo);
        let exact = quad_about(light.axis, &|wi| {
            light.eval(wi) * ggx::eval_spec_cos(alpha, 1.0, lo, frame.to_local(wi))
        });
        let s = ggx_lobe(alpha, n, wo).expect("view above the horizon");
        let prod = light.product(&s.sg);
        let approx = crate::sg::halfspace::hemisphere(&prod, n);
        (exact, approx)
    }

    /// The specular approximation's relative error over roughness, view angle and light
    /// sharpness, light centred on the reflection direction (where the lobe matters). The
    /// numbers go to `docs/sg.md`; the bounds catch regressions.
    #[test]
    fn spec_error_table() {
        let mut worst: f64 = 0.0;
        for alpha in [0.1, 0.3, 0.6] {
            for deg in [0.0f64, 30.0, 60.0] {
                let t = deg.to_radians();
                let r = DVec3::new(-t.sin(), 0.0, t.cos());
                let mut row = Vec::new();
                for ll in [10.0, 100.0, 1000.0] {
                    let (e, a) = spec_case(alpha, t, Sg::new(r, ll, 1.0));
                    let rel = (a - e) / e;
                    row.push(format!("λL={ll}: {:+.1}%", 100.0 * rel));
                    worst = worst.max(rel.abs());
                    assert!(a.is_finite() && e > 0.0);
                }
                eprintln!("α {alpha} θo {deg}°: {}", row.join(", "));
            }
        }
        eprintln!("spec worst |rel| {worst:.3}");
        assert!(worst < 0.6, "worst {worst}");
    }

    /// Diffuse: ∫ L max(cos, 0) by quadrature vs the SG product with the horizon cut.
    #[test]
    fn diffuse_error_table() {
        let n = DVec3::Z;
        let mut worst: f64 = 0.0;
        for ll in [1.0, 10.0, 100.0] {
            let mut row = Vec::new();
            for deg in [0.0f64, 45.0, 80.0] {
                let t = deg.to_radians();
                let light = Sg::new(DVec3::new(t.sin(), 0.0, t.cos()), ll, 1.0);
                let exact = quad_about(light.axis, &|wi| light.eval(wi) * wi.z.max(0.0));
                let approx = crate::sg::halfspace::hemisphere(&light.product(&cosine_lobe(n)), n);
                let rel = (approx - exact) / exact;
                worst = worst.max(rel.abs());
                row.push(format!("θ {deg}°: {:+.1}%", 100.0 * rel));
            }
            eprintln!("diffuse λL={ll}: {}", row.join(", "));
        }
        eprintln!("diffuse worst |rel| {worst:.3}");
        assert!(worst < 0.25, "worst {worst}");
    }

    #[test]
    fn lobes_are_finite_for_extreme_inputs() {
        for a in [0.0, 1e-6, 1e-4, 0.5, 1.0, f64::NAN] {
            for c in [1e-12f64, 1e-5, 0.3, 1.0] {
                let wo = DVec3::new((1.0 - c * c).sqrt(), 0.0, c);
                let s = ggx_lobe(a, DVec3::Z, wo).expect("above");
                assert!(s.sg.axis.is_finite() && s.sg.lambda.is_finite() && s.sg.mu.is_finite());
                assert!(s.fresnel_weight.is_finite());
            }
        }
        assert!(ggx_lobe(0.5, DVec3::Z, DVec3::NEG_Z).is_none());
    }
}
