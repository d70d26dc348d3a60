//! One spherical Gaussian (SG) and the closed forms on it: evaluation, product, integral over the
//! sphere, inner product.
//!
//! G(v; p, λ, μ) = μ · exp(λ (p·v − 1)) — always with the shifted exponent, so that
//! 0 < G ≤ μ for every λ and direction and nothing overflows (Wang et al. 2009, "All-Frequency
//! Rendering of Dynamic, Spatially-Varying Reflectance", §3; the shifted form as in Tokuyoshi
//! 2022, "Accurate Diffuse Lighting from Spherical Gaussian Lights").
//!
//! - Product (Wang et al. 2009, eq. 4): G₁G₂ is an SG with axis q/‖q‖, sharpness r = ‖q‖,
//!   q = λ₁p₁ + λ₂p₂, amplitude μ₁μ₂ exp(r − λ₁ − λ₂). The exponent is written
//!   r − λ₁ − λ₂ = (r² − (λ₁+λ₂)²) / (r + λ₁ + λ₂) = −λ₁λ₂‖p₁ − p₂‖² / (r + λ₁ + λ₂), with
//!   ‖p₁ − p₂‖² computed from the difference vector: no cancellation when the axes nearly
//!   coincide or the lobes are sharp.
//! - Sphere integral: ∫ exp(λ(p·v − 1)) dv = 2π (1 − e^{−2λ}) / λ = 2π · (−expm1(−2λ)) / λ,
//!   which tends to 4π as λ → 0 (series 4π(1 − λ + …) below 1e-8).
//! - Inner product ∫ G₁G₂ = integral of the product.

#[cfg(test)]
use std::f64::consts::PI;

use glam::DVec3;

#[cfg(test)]
/// Sharpness below this is treated by its series (the closed forms are 0/0 at λ = 0).
const TINY_LAMBDA: f64 = 1e-8;

/// A spherical Gaussian μ · exp(λ (p·v − 1)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sg {
    /// Unit axis p.
    pub(crate) axis: DVec3,
    /// Sharpness λ ≥ 0.
    pub(crate) lambda: f64,
    /// Amplitude μ (the value on the axis).
    pub(crate) mu: f64,
}

impl Sg {
    /// An SG; the axis is normalised (a zero or non-finite axis becomes +z), a negative or NaN
    /// sharpness becomes 0 and a non-finite amplitude 0.
    pub(crate) fn new(axis: DVec3, lambda: f64, mu: f64) -> Sg {
        let axis = if axis.is_finite() {
            axis.normalize_or(DVec3::Z)
        } else {
            DVec3::Z
        };
        Sg {
            axis,
            lambda: if lambda > 0.0 {
                lambda.min(f64::MAX)
            } else {
                0.0
            },
            mu: if mu.is_finite() { mu } else { 0.0 },
        }
    }

    /// G(v) for a unit direction `v`.
    #[inline]
    pub(crate) fn eval(&self, v: DVec3) -> f64 {
        // p·v − 1 = −‖p − v‖²/2: exact near the axis, where the dot product would round.
        let e = -0.5 * (self.axis - v).length_squared();
        self.mu * (self.lambda * e).exp()
    }

    /// The product's axis p = (λ₁p₁ + λ₂p₂)/r, sharpness r = ‖λ₁p₁ + λ₂p₂‖ and amplitude
    /// exponent −λ₁λ₂‖p₁ − p₂‖²/(r + λ₁ + λ₂) (= λ₁(p₁·p−1)+… without cancellation).
    #[inline]
    fn product_shape(&self, o: &Sg) -> (DVec3, f64, f64) {
        let (l1, l2) = (self.lambda, o.lambda);
        let q = self.axis * l1 + o.axis * l2;
        let r = q.length();
        let axis = if r > 0.0 && q.is_finite() {
            q / r
        } else {
            self.axis
        };
        let denom = r + l1 + l2;
        let expo = if denom > 0.0 {
            -l1 * l2 * (self.axis - o.axis).length_squared() / denom
        } else {
            0.0
        };
        (axis, r, expo)
    }

    #[cfg(test)]
    /// The product G₁·G₂ as one SG (exact).
    pub(crate) fn product(&self, o: &Sg) -> Sg {
        let (axis, r, expo) = self.product_shape(o);
        Sg {
            axis,
            lambda: r,
            mu: self.mu * o.mu * expo.exp(),
        }
    }

    /// [`Sg::product`] and the product's sphere integral for the shading loops: the same
    /// formulas with the exponentials in f32 (relative error ≈ 1e-6; tested against the f64
    /// forms).
    #[inline]
    pub(crate) fn product_and_integral_f32(&self, o: &Sg) -> (Sg, f64) {
        let (axis, r, expo) = self.product_shape(o);
        let mu = self.mu * o.mu * f64::from((expo.max(-150.0) as f32).exp());
        let g = Sg {
            axis,
            lambda: r,
            mu,
        };
        (g, mu * f64::from(sphere_integral_f32(r as f32)))
    }

    #[cfg(test)]
    /// ∫ G(v) dv over the sphere.
    #[inline]
    pub(crate) fn integral(&self) -> f64 {
        self.mu * sphere_integral(self.lambda)
    }

    #[cfg(test)]
    /// ∫ G₁(v) G₂(v) dv over the sphere.
    pub(crate) fn inner_product(&self, o: &Sg) -> f64 {
        self.product(o).integral()
    }
}

#[cfg(test)]
/// ∫ exp(λ(p·v − 1)) dv over the whole sphere = 2π (−expm1(−2λ)) / λ; 4π at λ = 0.
#[inline]
pub(crate) fn sphere_integral(lambda: f64) -> f64 {
    if !(lambda > TINY_LAMBDA) {
        // 2π(1 − e^{−2λ})/λ = 4π (1 − λ + 2λ²/3 − …); NaN and negative λ read as 0.
        let l = if lambda > 0.0 { lambda } else { 0.0 };
        return 4.0 * PI * (1.0 - l);
    }
    if lambda > 40.0 {
        // e^{−80} < 1e-34: the exponential term is below f64 resolution.
        return 2.0 * PI / lambda;
    }
    2.0 * PI * (-(-2.0 * lambda).exp_m1()) / lambda
}

/// f32 version of [`sphere_integral`] for the shading loops.
#[inline]
pub(crate) fn sphere_integral_f32(lambda: f32) -> f32 {
    if !(lambda > 1e-4) {
        let l = if lambda > 0.0 { lambda } else { 0.0 };
        return 4.0 * std::f32::consts::PI * (1.0 - l);
    }
    if lambda > 9.0 {
        // e^{−18} < 2e-8: below f32 resolution.
        return 2.0 * std::f32::consts::PI / lambda;
    }
    2.0 * std::f32::consts::PI * (-(-2.0 * lambda).exp_m1()) / lambda
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sg::testutil::quad_about as sphere_quad;
    use proptest::prelude::*;

    fn dir(theta: f64, phi: f64) -> DVec3 {
        DVec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    #[test]
    fn sphere_integral_matches_quadrature_and_limits() {
        for l in [1e-6, 1e-3, 0.1, 1.0, 10.0, 1e3, 1e6] {
            let g = Sg::new(DVec3::Z, l, 1.0);
            let q = sphere_quad(DVec3::Z, &|v| g.eval(v));
            let a = g.integral();
            assert!((a - q).abs() <= 1e-9 * q, "λ {l}: {a} vs {q}");
        }
        assert!((sphere_integral(0.0) - 4.0 * PI).abs() < 1e-12);
        assert!((sphere_integral(1e-9) - sphere_integral(2e-8)).abs() < 1e-6);
        assert!(sphere_integral(f64::NAN).is_finite());
        assert!((sphere_integral_f32(1e-6) - 4.0 * std::f32::consts::PI).abs() < 1e-4);
        assert!((sphere_integral_f32(3.0) as f64 / sphere_integral(3.0) - 1.0).abs() < 1e-6);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        /// The closed-form product is the pointwise product, and the inner product is the
        /// numerical integral of the pointwise product, across 1e-6 ≤ λ ≤ 1e6.
        #[test]
        fn product_and_inner_product(
            ll1 in -6.0f64..6.0, ll2 in -6.0f64..6.0,
            t1 in 0.0f64..PI, p1 in 0.0f64..std::f64::consts::TAU, t2 in 0.0f64..PI, p2 in 0.0f64..std::f64::consts::TAU,
            tv in 0.0f64..PI, pv in 0.0f64..std::f64::consts::TAU,
            m1 in 0.1f64..10.0, m2 in 0.1f64..10.0,
        ) {
            let a = Sg::new(dir(t1, p1), 10f64.powf(ll1), m1);
            let b = Sg::new(dir(t2, p2), 10f64.powf(ll2), m2);
            let ab = a.product(&b);
            prop_assert!(ab.axis.is_finite() && ab.lambda.is_finite() && ab.mu.is_finite());
            // Pointwise, at a random direction and at the product's axis.
            for v in [dir(tv, pv), ab.axis] {
                let want = a.eval(v) * b.eval(v);
                let got = ab.eval(v);
                prop_assert!((got - want).abs() <= 1e-8 * want.max(1e-300) + 1e-300,
                    "{got} vs {want}");
            }
            // Inner product against quadrature around the product's axis.
            let ip = a.inner_product(&b);
            let q = sphere_quad(ab.axis, &|v| a.eval(v) * b.eval(v));
            prop_assert!(ip.is_finite() && ip >= 0.0);
            prop_assert!((ip - q).abs() <= 1e-7 * q + 1e-280, "{ip} vs {q}");
        }

        /// The f32 shading form agrees with the f64 kernel.
        #[test]
        fn f32_product_matches_f64(
            ll1 in -6.0f64..6.0, ll2 in -6.0f64..6.0,
            t1 in 0.0f64..PI, p1 in 0.0f64..std::f64::consts::TAU,
            t2 in 0.0f64..PI, p2 in 0.0f64..std::f64::consts::TAU,
        ) {
            let a = Sg::new(dir(t1, p1), 10f64.powf(ll1), 1.5);
            let b = Sg::new(dir(t2, p2), 10f64.powf(ll2), 0.5);
            let (g, i) = a.product_and_integral_f32(&b);
            let want = a.product(&b);
            if want.mu < 1e-30 {
                // Beyond f32's range the shading form flushes to zero.
                prop_assert!(g.mu < 2e-30 && i < 1e-25);
                return Ok(());
            }
            // The exponent is rounded to f32 before exp: relative error ≈ 6e-8 × |exponent|.
            let expo = -(want.mu / (a.mu * b.mu)).ln();
            let tol = 1e-6 + 1.2e-7 * expo.abs();
            prop_assert!((g.mu - want.mu).abs() <= tol * want.mu + 1e-40, "{} vs {}", g.mu, want.mu);
            let wi = want.integral();
            prop_assert!((i - wi).abs() <= (tol + 1e-6) * wi + 1e-40, "{i} vs {wi}");
        }

        /// Any direction and sharpness: finite, in [0, μ].
        #[test]
        fn eval_is_finite_and_bounded(ll in -8.0f64..8.0, t in 0.0f64..PI, p in 0.0f64..std::f64::consts::TAU) {
            let g = Sg::new(DVec3::new(0.3, -0.2, 0.9), 10f64.powf(ll), 2.0);
            let v = g.eval(dir(t, p));
            prop_assert!(v.is_finite() && (0.0..=2.0).contains(&v));
        }
    }

    #[test]
    fn degenerate_inputs() {
        let g = Sg::new(DVec3::ZERO, f64::NAN, f64::INFINITY);
        assert_eq!(g.axis, DVec3::Z);
        assert_eq!(g.lambda, 0.0);
        assert_eq!(g.mu, 0.0);
        // Opposite axes: the product is an SG of sharpness |λ1 − λ2| and tiny amplitude.
        let a = Sg::new(DVec3::Z, 1e6, 1.0);
        let b = Sg::new(DVec3::NEG_Z, 1e6, 1.0);
        let ab = a.product(&b);
        assert!(ab.lambda.is_finite() && ab.mu == 0.0 && ab.axis.is_finite());
        assert!(a.inner_product(&b).is_finite());
    }
}
