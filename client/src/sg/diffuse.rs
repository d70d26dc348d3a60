//! The diffuse term of one lighting lobe as a function of one number.
//!
//! The clamped-cosine SG ([`super::brdf::cosine_lobe`]) has a fixed sharpness, so the product
//! G_k · C(n) of lobe k (axis ξ, sharpness λ) with it depends on n only through c = n·ξ:
//!
//! ```text
//! q = λ ξ + λ_c n,  |q|² = λ² + λ_c² + 2 λ λ_c c,   p·n = (λ c + λ_c) / |q|,
//! ∫ G_k C = μ_c e^{−λ λ_c (2 − 2c) / (|q| + λ + λ_c)} S(|q|)
//! ```
//!
//! and so does its integral over the horizon's half-space, ∫ G_k C · S(|q|) F(|q|, asin p·n).
//! Both are tabulated over c ∈ [−1, 1] once per lobe (linear interpolation); the renderer uses
//! the table whenever the lobe's occluder boundary does not cut the product below the
//! horizon (p·m ≥ p·n: the horizon is then the nearer boundary), which is most pixels.
//!
//! Lobes sharper than [`MAX_LAMBDA`] are not tabulated: their horizon transition,
//! of width ≈ 1/√λ in c, would need a finer table than it saves.

use glam::DVec3;

use super::Sg;
use super::brdf::{COS_LAMBDA, cosine_lobe};
use super::halfspace;

/// Table entries over c ∈ [−1, 1].
const N: usize = 1024;
/// Sharpest lobe tabulated (the horizon step is then ≥ 0.03 wide in c, 16 entries).
pub(crate) const MAX_LAMBDA: f64 = 1000.0;

/// One lobe's diffuse tables.
#[derive(Clone, Debug)]
pub(crate) struct DiffuseTable {
    /// ∫ G_k C over the sphere, at c_i = −1 + 2i/N.
    full: Vec<f32>,
    /// ∫ G_k C over the horizon's half-space.
    horizon: Vec<f32>,
}

/// The two integrals for a shading normal `n` (exact path, the renderer's own formulas).
pub(crate) fn exact(g: &Sg, n: DVec3) -> (f64, f64) {
    let (p, full) = g.product_and_integral_f32(&cosine_lobe(n));
    let d = p.axis.dot(n).clamp(-1.0, 1.0).asin();
    (
        full,
        full * f64::from(halfspace::fraction(p.lambda as f32, d as f32)),
    )
}

impl DiffuseTable {
    /// The tables of `g` (`None` when it is sharper than [`MAX_LAMBDA`]).
    pub(crate) fn new(g: &Sg) -> Option<DiffuseTable> {
        if !(g.lambda <= MAX_LAMBDA) {
            return None;
        }
        let (t, _) = g.axis.any_orthonormal_pair();
        let (mut full, mut horizon) = (Vec::with_capacity(N + 1), Vec::with_capacity(N + 1));
        for i in 0..=N {
            let c = -1.0 + 2.0 * i as f64 / N as f64;
            let n = (g.axis * c + t * (1.0 - c * c).max(0.0).sqrt()).normalize_or(g.axis);
            let (f, h) = exact(g, n);
            full.push(f as f32);
            horizon.push(h as f32);
        }
        Some(DiffuseTable { full, horizon })
    }

    /// (∫ G_k C, ∫_horizon G_k C) at c = n·ξ.
    #[inline]
    pub(crate) fn lookup(&self, c: f64) -> (f64, f64) {
        let x = (c.clamp(-1.0, 1.0) + 1.0) * 0.5 * N as f64;
        let i = (x as usize).min(N - 1);
        let w = (x - i as f64) as f32;
        let lerp = |v: &[f32]| f64::from(v[i] + (v[i + 1] - v[i]) * w);
        (lerp(&self.full), lerp(&self.horizon))
    }
}

/// The product's axis p (unit) for lobe `g` and normal `n`: what the occluder test needs.
#[inline]
pub(crate) fn product_axis(g: &Sg, n: DVec3) -> DVec3 {
    (g.axis * g.lambda + n * COS_LAMBDA).normalize_or(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tables match the exact path to 1e-3 of the lobe's peak diffuse integral, for every
    /// tabulated sharpness, at points between the entries (where linear interpolation is
    /// worst) and across the horizon.
    #[test]
    fn tables_match_the_exact_path() {
        for lambda in [1e-6, 0.1, 1.0, 10.0, 100.0, 1000.0] {
            let g = Sg::new(DVec3::new(0.3, 0.9, -0.2).normalize(), lambda, 1.0);
            let table = DiffuseTable::new(&g).expect("tabulated");
            let peak = exact(&g, g.axis).0;
            let (t, _) = g.axis.any_orthonormal_pair();
            let mut worst: f64 = 0.0;
            for j in 0..4000 {
                let c = -1.0 + 2.0 * (j as f64 + 0.37) / 4000.0;
                let n = (g.axis * c + t * (1.0 - c * c).sqrt()).normalize();
                let (ef, eh) = exact(&g, n);
                let (tf, th) = table.lookup(n.dot(g.axis));
                assert!(tf.is_finite() && th.is_finite());
                worst = worst.max((ef - tf).abs().max((eh - th).abs()) / peak);
            }
            eprintln!("λ {lambda:e}: worst |table − exact| / peak = {worst:.2e}");
            assert!(worst < 1e-3, "λ {lambda}: {worst}");
        }
        let sharp = Sg::new(DVec3::Y, 2.0 * MAX_LAMBDA, 1.0);
        assert!(DiffuseTable::new(&sharp).is_none());
    }
}
