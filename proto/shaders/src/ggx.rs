//! The GGX microfacet BRDF (Walter et al. 2007) with separable Smith masking–shadowing,
//! Schlick's Fresnel, and sampling of the visible normals (Heitz 2018).
//!
//! Local shading frame: z is the normal; directions are unit vectors pointing away from the
//! surface. Everything is f64: these are the reference kernels the LTC fit and the Monte
//! Carlo ground truth are built on.
//!
//! Masking–shadowing is the separable form G₂ = G₁(ωo) G₁(ωi) — the form Mitsuba 3 uses, so
//! the independent cross-check renders exactly the same BRDF.

use std::f64::consts::PI;

use glam::DVec3;

/// Smallest α the kernels accept: below it D overflows nothing but the LTC table stops
/// resolving the lobe; inputs are clamped up to it.
pub const MIN_ALPHA: f64 = 1e-4;

/// Clamps a roughness to the range the kernels are defined for: [`MIN_ALPHA`]..=1
/// (NaN becomes 1, the safest lobe).
#[inline]
pub fn clamp_alpha(alpha: f64) -> f64 {
    if alpha.is_nan() {
        1.0
    } else {
        alpha.clamp(MIN_ALPHA, 1.0)
    }
}

/// The GGX normal distribution D(h) for a half vector with cos θh = `cos_h`.
/// D = α² / (π ((α² − 1) cos²θh + 1)²), written as α² / (π (α² cos² + sin²)²) so that no
/// cancellation happens near cos θh = 1 at small α.
#[inline]
pub fn d(alpha: f64, cos_h: f64) -> f64 {
    if cos_h <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let c2 = cos_h * cos_h;
    let s2 = (1.0 - c2).max(0.0);
    let k = a2 * c2 + s2;
    a2 / (PI * k * k)
}

/// Smith's Λ(ω) for GGX: (√(1 + α² tan²θ) − 1) / 2, in the cancellation-free form
/// α² tan²θ / (2 (√(1 + α² tan²θ) + 1)).
#[inline]
pub fn lambda(alpha: f64, cos_theta: f64) -> f64 {
    if cos_theta <= 0.0 {
        return f64::INFINITY;
    }
    let c2 = cos_theta * cos_theta;
    let t2 = (1.0 - c2).max(0.0) / c2;
    let x = alpha * alpha * t2;
    if !x.is_finite() {
        return f64::INFINITY;
    }
    x / (2.0 * ((1.0 + x).sqrt() + 1.0))
}

/// Smith's masking G₁(ω) = 1 / (1 + Λ(ω)).
#[inline]
pub fn g1(alpha: f64, cos_theta: f64) -> f64 {
    let l = lambda(alpha, cos_theta);
    if l.is_finite() { 1.0 / (1.0 + l) } else { 0.0 }
}

/// Schlick's Fresnel weight (1 − cos θd)⁵, so that F = F0 + (1 − F0) · w.
#[inline]
pub fn schlick_weight(cos_d: f64) -> f64 {
    let m = (1.0 - cos_d).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// The cosine-weighted GGX BRDF without Fresnel, f(ωo, ωi) cos θi = D G₂ / (4 cos θo),
/// and the half-vector cosine with ωi (for Fresnel). Zero below either horizon.
#[inline]
pub fn eval_cos(alpha: f64, wo: DVec3, wi: DVec3) -> (f64, f64) {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return (0.0, 0.0);
    }
    let h = wo + wi;
    let len = h.length();
    if !(len > 0.0) {
        return (0.0, 0.0);
    }
    let h = h / len;
    let v = d(alpha, h.z) * g1(alpha, wo.z) * g1(alpha, wi.z) / (4.0 * wo.z);
    (v, wi.dot(h).clamp(0.0, 1.0))
}

/// The specular part with Schlick Fresnel, f cos θi with F = F0 + (1 − F0)(1 − ωi·h)⁵.
#[inline]
pub fn eval_spec_cos(alpha: f64, f0: f64, wo: DVec3, wi: DVec3) -> f64 {
    let (v, cos_d) = eval_cos(alpha, wo, wi);
    v * (f0 + (1.0 - f0) * schlick_weight(cos_d))
}

/// Samples ωi by reflecting ωo about a visible normal drawn from D_ωo (Heitz 2018, "Sampling
/// the GGX Distribution of Visible Normals"). `u` in [0, 1)². May return a direction below
/// the horizon (weight zero).
pub fn sample_vndf(alpha: f64, wo: DVec3, u: [f64; 2]) -> DVec3 {
    let vh = DVec3::new(alpha * wo.x, alpha * wo.y, wo.z).normalize();
    let lensq = vh.x * vh.x + vh.y * vh.y;
    let t1 = if lensq > 0.0 {
        DVec3::new(-vh.y, vh.x, 0.0) / lensq.sqrt()
    } else {
        DVec3::X
    };
    let t2 = vh.cross(t1);
    let r = u[0].sqrt();
    let phi = 2.0 * PI * u[1];
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
    let ne = DVec3::new(alpha * nh.x, alpha * nh.y, nh.z.max(0.0)).normalize();
    2.0 * wo.dot(ne) * ne - wo
}

/// Density (per solid angle) of [`sample_vndf`] producing `wi`: G₁(ωo) D(h) / (4 cos θo).
#[inline]
pub fn pdf_vndf(alpha: f64, wo: DVec3, wi: DVec3) -> f64 {
    if wo.z <= 0.0 {
        return 0.0;
    }
    let h = wo + wi;
    let len = h.length();
    if !(len > 0.0) {
        return 0.0;
    }
    let h = h / len;
    if wo.dot(h) <= 0.0 {
        return 0.0;
    }
    g1(alpha, wo.z) * d(alpha, h.z) / (4.0 * wo.z)
}

/// The view direction at elevation cos θ in the LTC convention: (sin θ, 0, cos θ).
#[inline]
pub fn view_dir(cos_theta: f64) -> DVec3 {
    let c = cos_theta.clamp(0.0, 1.0);
    DVec3::new((1.0 - c * c).max(0.0).sqrt(), 0.0, c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Midpoint rule over the hemisphere in (cos θ, φ), `n` cells per axis.
    fn hemisphere(n: usize, f: impl Fn(DVec3) -> f64) -> f64 {
        let mut s = 0.0;
        for i in 0..n {
            let c = (i as f64 + 0.5) / n as f64;
            let st = (1.0 - c * c).sqrt();
            for j in 0..n {
                let p = 2.0 * PI * (j as f64 + 0.5) / n as f64;
                s += f(DVec3::new(st * p.cos(), st * p.sin(), c));
            }
        }
        s * 2.0 * PI / (n * n) as f64
    }

    #[test]
    fn distribution_projects_to_one() {
        // ∫ D(h) cos θh dh = 1 (Walter et al. 2007, eq. 4).
        for alpha in [0.1, 0.3, 0.7, 1.0] {
            let v = hemisphere(3000, |h| d(alpha, h.z) * h.z);
            assert!((v - 1.0).abs() < 2e-3, "α {alpha}: {v}");
        }
    }

    #[test]
    fn visible_normals_sample_their_pdf() {
        // The histogram of sampled directions matches pdf_vndf; and ∫ pdf = ∫ over directions
        // whose reflection stays above the horizon (≤ 1).
        let mut rng = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        for (alpha, ct) in [(0.2, 0.9), (0.5, 0.3), (0.9, 0.05)] {
            let wo = view_dir(ct);
            let n = 200_000;
            // Estimate ∫ f cos with importance sampling and compare with quadrature.
            let mut est = 0.0;
            for _ in 0..n {
                let wi = sample_vndf(alpha, wo, [next(), next()]);
                if wi.z > 0.0 {
                    est += eval_cos(alpha, wo, wi).0 / pdf_vndf(alpha, wo, wi);
                }
            }
            est /= n as f64;
            let quad = hemisphere(1000, |wi| eval_cos(alpha, wo, wi).0);
            assert!(
                (est - quad).abs() < 0.01 * quad,
                "α {alpha} cos {ct}: sampled {est} vs quadrature {quad}"
            );
        }
    }

    #[test]
    fn extreme_inputs_are_finite() {
        for alpha in [MIN_ALPHA, 1e-3, 0.5, 1.0] {
            for ct in [1e-12, 1e-4, 0.5, 1.0] {
                let wo = view_dir(ct);
                for wi in [DVec3::Z, wo, DVec3::new(-wo.x, 0.0, wo.z), view_dir(1e-9)] {
                    let (v, c) = eval_cos(alpha, wo, wi);
                    assert!(v.is_finite() && c.is_finite(), "α {alpha} {wo} {wi}");
                    assert!(pdf_vndf(alpha, wo, wi).is_finite());
                }
                let s = sample_vndf(alpha, wo, [0.3, 0.7]);
                assert!(s.is_finite());
            }
        }
    }
}
