//! The integral of an SG over a half-space: the side of a great circle (a plane through the
//! origin) whose signed angular distance from the SG's axis is `d`.
//!
//! Wang et al. 2009 (§5.2) and Xu et al. 2013 model visibility near a lobe by the spherical
//! signed distance d of its axis to the nearest occlusion boundary (positive when the axis is
//! unoccluded) and the boundary by a great circle at that distance; the visible integral of
//! the SG is then a function of (λ, d) only. The same function gives the hemisphere
//! integral (boundary = horizon, d = asin(p·n)).
//!
//! With m the plane's unit normal on the kept side and p·m = sin d, d ∈ [−π/2, π/2]:
//!
//! ```text
//! I(λ, d) = ∫_{v·m ≥ 0} exp(λ(p·v − 1)) dv = S(λ) · F(λ, d),   S(λ) = 2π(−expm1(−2λ))/λ
//! ```
//!
//! F ∈ [0, 1] is the kept fraction; F(λ, d) + F(λ, −d) = 1 exactly (the two sides), F → ½ as
//! λ → 0 and F → Φ(d√λ) (the normal CDF) as λ → ∞.
//!
//! Exact form (the reference, [`fraction_exact`]): in polar coordinates (α, φ) about p, with
//! t = λ(1 − cos α), the SG weight is e^{−t} dt/λ and the kept set of azimuths at polar angle α
//! is {φ : cos φ ≤ k}, k = cos α sin d / (sin α cos d), of measure M(α) = 2π − 2 acos(clamp k):
//!
//! ```text
//! F(λ, d) = ∫₀^{2λ} e^{−t} M(α(t)) dt / (2π (−expm1(−2λ)))
//! ```
//!
//! M has square-root kinks where |k| = 1 (α = |d| and α = π − |d|); the integral is split there
//! and each piece integrated with the tanh-sinh rule (`quadrature` crate), which is exact to
//! rounding for endpoint singularities. The tail beyond t = 60 (e^{−60} ≈ 1e-26) is dropped.
//!
//! Fast form ([`fraction`]): a 2D table over (ln λ, w) built once from the exact form, with
//! w = tanh(κ|d|)/tanh(κπ/2), κ = 0.85√λ, which straightens F(·, d) for every λ (F ≈ ½(1 + w)
//! for sharp lobes, the logistic approximation of Φ; w = 2|d|/π for broad ones). Cubic
//! (Catmull–Rom) interpolation in ln λ and in w. λ is clamped to [1e-6, 1e6] for the row
//! (outside, F is within 1e-6 of the end rows' shapes). The measured worst error of [`fraction`]
//! against [`fraction_exact`] is stated in `docs/sg.md` and asserted by the tests here.

use std::f64::consts::{FRAC_PI_2, PI};
use std::sync::OnceLock;

/// Table rows: ln λ from ln 1e-6 to ln 1e6.
const NU: usize = 193;
/// Table columns: w from 0 to 1 (d ≥ 0; d < 0 by symmetry).
const NW: usize = 129;
const LN_MIN: f64 = -13.815_510_557_964_274; // ln 1e-6
const LN_MAX: f64 = 13.815_510_557_964_274; // ln 1e6

/// κ(λ) of the w warp.
#[inline]
fn kappa(lambda: f64) -> f64 {
    0.85 * lambda.sqrt()
}

/// w(λ, |d|) ∈ [0, 1] (f64; the table's own coordinate, tested against [`warp_f32`]).
#[cfg(test)]
#[inline]
fn warp(lambda: f64, d_abs: f64) -> f64 {
    let k = kappa(lambda);
    let kmax = k * FRAC_PI_2;
    if kmax < 1e-6 {
        return d_abs / FRAC_PI_2;
    }
    ((k * d_abs).tanh() / kmax.tanh()).min(1.0)
}

/// [`warp`] in f32 for the shading loop (tanh(κπ/2) is 1 in f32 beyond κπ/2 = 9).
#[inline]
fn warp_f32(lambda: f32, d_abs: f32) -> f32 {
    let k = 0.85 * lambda.sqrt();
    let kmax = k * std::f32::consts::FRAC_PI_2;
    if kmax < 1e-3 {
        return d_abs / std::f32::consts::FRAC_PI_2;
    }
    let num = tanh_pos(k * d_abs);
    if kmax > 9.0 {
        num.min(1.0)
    } else {
        (num / tanh_pos(kmax)).min(1.0)
    }
}

/// tanh x for x ≥ 0 in f32: the Taylor series below 0.05 (next term < 1e-10 relative), else
/// (1 − e^{−2x}) / (1 + e^{−2x}) with one `exp` (glibc's tanhf and expm1f are slower).
#[inline]
fn tanh_pos(x: f32) -> f32 {
    if x < 0.05 {
        let x2 = x * x;
        x * (1.0 - x2 * (1.0 / 3.0 - x2 * (2.0 / 15.0)))
    } else {
        let e = (-2.0 * x).exp();
        (1.0 - e) / (1.0 + e)
    }
}

/// |d| from w (inverse of [`warp`]).
fn unwarp(lambda: f64, w: f64) -> f64 {
    let k = kappa(lambda);
    let kmax = k * FRAC_PI_2;
    if kmax < 1e-6 {
        return w * FRAC_PI_2;
    }
    let x = w * kmax.tanh();
    if x >= 1.0 {
        return FRAC_PI_2;
    }
    (x.atanh() / k).min(FRAC_PI_2)
}

/// Measure of the kept azimuths at polar angle α (given as s = sin²(α/2) = t/(2λ)).
#[inline]
fn kept_azimuths(s: f64, sin_d: f64, cos_d: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    let cos_a = 1.0 - 2.0 * s;
    let sin_a = 2.0 * (s * (1.0 - s)).sqrt();
    let a = cos_a * sin_d;
    let b = sin_a * cos_d;
    if !(b > 1e-300) {
        return if a >= 0.0 { 2.0 * PI } else { 0.0 };
    }
    let k = (a / b).clamp(-1.0, 1.0);
    2.0 * PI - 2.0 * k.acos()
}

/// The kept fraction F(λ, d) by numerical integration (f64 reference; slow). `d` is clamped
/// to [−π/2, π/2]; NaN input gives 0.
pub(crate) fn fraction_exact(lambda: f64, d: f64) -> f64 {
    if lambda.is_nan() || d.is_nan() {
        return 0.0;
    }
    let lambda = lambda.max(1e-300);
    let d = d.clamp(-FRAC_PI_2, FRAC_PI_2);
    let (sin_d, cos_d) = d.sin_cos();
    let t_end = (2.0 * lambda).min(60.0);
    // Kinks: α = |d| and α = π − |d|, i.e. t = 2λ sin²(|d|/2) and 2λ cos²(|d|/2).
    let h = 0.5 * d.abs();
    let mut cuts = vec![0.0];
    for t in [
        2.0 * lambda * h.sin().powi(2),
        2.0 * lambda * h.cos().powi(2),
    ] {
        if t > 0.0 && t < t_end {
            cuts.push(t);
        }
    }
    cuts.push(t_end);
    cuts.sort_by(f64::total_cmp);
    let mut total = 0.0;
    for w in cuts.windows(2) {
        if !(w[1] > w[0]) {
            continue;
        }
        let out = quadrature::double_exponential::integrate(
            |t: f64| (-t).exp() * kept_azimuths(t / (2.0 * lambda), sin_d, cos_d),
            w[0],
            w[1],
            1e-14,
        );
        total += out.integral;
    }
    let norm = 2.0 * PI * (-(-2.0 * lambda).exp_m1());
    (total / norm).clamp(0.0, 1.0)
}

#[cfg(test)]
/// The kept integral I(λ, d) = S(λ) F(λ, d) by numerical integration (f64 reference).
pub(crate) fn integral_exact(lambda: f64, d: f64) -> f64 {
    super::lobe::sphere_integral(lambda) * fraction_exact(lambda, d)
}

/// The table of F over (ln λ, w).
struct Table {
    f: Vec<f32>,
}

impl Table {
    fn build() -> Table {
        use rayon::prelude::*;
        let mut f = vec![0.0f32; NU * NW];
        f.par_chunks_mut(NW).enumerate().for_each(|(i, row)| {
            let u = LN_MIN + (LN_MAX - LN_MIN) * i as f64 / (NU - 1) as f64;
            let lambda = u.exp();
            for (j, out) in row.iter_mut().enumerate() {
                let w = j as f64 / (NW - 1) as f64;
                // F(λ, 0) = ½ exactly (symmetry).
                *out = if j == 0 {
                    0.5
                } else {
                    fraction_exact(lambda, unwarp(lambda, w)) as f32
                };
            }
        });
        Table { f }
    }

    fn get() -> &'static Table {
        static T: OnceLock<Table> = OnceLock::new();
        T.get_or_init(Table::build)
    }

    #[inline]
    fn lookup(&self, lambda: f32, w: f32) -> f32 {
        let u = (lambda.ln() - LN_MIN as f32) / (LN_MAX - LN_MIN) as f32 * (NU - 1) as f32;
        let u = u.clamp(0.0, (NU - 1) as f32);
        let x = w.clamp(0.0, 1.0) * (NW - 1) as f32;
        let i1 = (u as usize).min(NU - 2);
        let fu = u - i1 as f32;
        let j = (x as usize).min(NW - 2);
        let fw = x - j as f32;
        // Catmull–Rom in both ln λ and w. Rows are clamped at the ends (F is flat in ln λ
        // there). The columns beyond the ends are F's mirror images: before w = 0,
        // F(λ, −w) = 1 − F(λ, w), so the slope at d = 0 is F's own (a clamped column halved
        // it: 2.1e-4 off at λ = 6.1, d = 0.002); after w = 1 (d = π/2, where F is extremal in
        // d and so in w), F(1 + h) = F(1 − h).
        let cr = |t: f32| {
            let (t2, t3) = (t * t, t * t * t);
            [
                0.5 * (-t3 + 2.0 * t2 - t),
                0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
                0.5 * (-3.0 * t3 + 4.0 * t2 + t),
                0.5 * (t3 - t2),
            ]
        };
        let (wu, ww) = (cr(fu), cr(fw));
        let mut acc = 0.0;
        for (k, wk) in wu.iter().enumerate() {
            let i = (i1 + k).saturating_sub(1).min(NU - 1);
            let row = &self.f[i * NW..(i + 1) * NW];
            let mut r = 0.0;
            for (l, wl) in ww.iter().enumerate() {
                let f = match (j + l).checked_sub(1) {
                    None => 1.0 - row[1],
                    Some(c) if c >= NW => row[NW - 2],
                    Some(c) => row[c],
                };
                r += wl * f;
            }
            acc += wk * r;
        }
        acc.clamp(0.0, 1.0)
    }
}

/// Builds the table now (it is otherwise built on first use, ≈ 0.1–0.5 s).
pub fn warm_up() {
    Table::get();
}

/// The kept fraction F(λ, d) from the table (f32, for shading). `d` is clamped to
/// [−π/2, π/2]; NaN input gives 0.
#[inline]
pub(crate) fn fraction(lambda: f32, d: f32) -> f32 {
    if lambda.is_nan() || d.is_nan() {
        return 0.0;
    }
    let lambda = lambda.clamp(1e-30, 1e30);
    let da = d.abs().min(std::f32::consts::FRAC_PI_2);
    let f = Table::get().lookup(lambda, warp_f32(lambda, da));
    if d >= 0.0 { f } else { 1.0 - f }
}

#[cfg(test)]
/// ∫ G over the half-space at signed distance `d` from G's axis (see the module docs).
#[inline]
pub(crate) fn integral(g: &super::Sg, d: f64) -> f64 {
    g.integral() * f64::from(fraction(g.lambda as f32, d as f32))
}

#[cfg(test)]
/// ∫ G over the hemisphere of unit normal `n` (v·n ≥ 0).
#[inline]
pub(crate) fn hemisphere(g: &super::Sg, n: glam::DVec3) -> f64 {
    integral(g, g.axis.dot(n).clamp(-1.0, 1.0).asin())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sg::Sg;
    use glam::DVec3;
    use proptest::prelude::*;

    /// Brute-force integral over the half-space by a fine (cos θ, φ) midpoint grid about the
    /// axis (independent of the kink-split reference).
    fn brute(lambda: f64, d: f64) -> f64 {
        let g = Sg::new(DVec3::Z, lambda, 1.0);
        let m = DVec3::new(-d.cos(), 0.0, d.sin()); // p·m = sin d
        let n = 1000;
        let mut s = 0.0;
        // Polar angle from the axis: θ ∈ [0, π], substitution-free midpoint in θ.
        for i in 0..n {
            let th = PI * (i as f64 + 0.5) / n as f64;
            let (st, ct) = th.sin_cos();
            for j in 0..n {
                let ph = 2.0 * PI * (j as f64 + 0.5) / n as f64;
                let v = DVec3::new(st * ph.cos(), st * ph.sin(), ct);
                if v.dot(m) >= 0.0 {
                    s += g.eval(v) * st;
                }
            }
        }
        s * PI / n as f64 * 2.0 * PI / n as f64
    }

    #[test]
    fn exact_form_matches_brute_force() {
        for (l, d) in [
            (0.5, 0.3),
            (3.0, -0.7),
            (10.0, 0.1),
            (1.0, 1.5),
            (2.0, -1.5),
        ] {
            let a = integral_exact(l, d);
            let b = brute(l, d);
            assert!(
                (a - b).abs() < 2e-3 * b.max(1e-3),
                "λ {l} d {d}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn exact_form_limits_and_symmetry() {
        for l in [1e-6, 1e-2, 1.0, 30.0, 1e4, 1e6] {
            assert!((fraction_exact(l, 0.0) - 0.5).abs() < 1e-9, "λ {l}");
            for d in [0.001, 0.2, 1.0, FRAC_PI_2] {
                let s = fraction_exact(l, d) + fraction_exact(l, -d);
                assert!((s - 1.0).abs() < 1e-9, "λ {l} d {d}: {s}");
            }
        }
        // d = π/2: the hemisphere about the axis, (1 − e^{−λ}) / (1 − e^{−2λ}) = 1/(1 + e^{−λ}).
        for l in [1e-3f64, 0.5, 4.0, 50.0] {
            let want = 1.0 / (1.0 + (-l).exp());
            assert!((fraction_exact(l, FRAC_PI_2) - want).abs() < 1e-10, "λ {l}");
        }
        assert_eq!(fraction_exact(f64::NAN, 0.1), 0.0);
        assert_eq!(fraction(f32::NAN, 0.1), 0.0);
        assert_eq!(fraction(1.0, f32::NAN), 0.0);
    }

    /// The worst error of the table over a dense (λ, d) grid, λ ∈ [1e-6, 1e6] (the number
    /// `docs/sg.md` states).
    #[test]
    fn table_worst_error_over_grid() {
        let mut worst = (0.0f64, 0.0, 0.0);
        for i in 0..=60 {
            let lambda = 10f64.powf(-6.0 + 12.0 * i as f64 / 60.0 + 0.0371);
            let lambda = lambda.min(1e6);
            for j in 0..=88 {
                // d dense near 0 on the scale of the lobe, across the whole range, and within
                // 10⁻⁴…10⁻¹ of the lobe's scale of 0 and of π/2 (the table's two ends).
                let scale = 6.0 / lambda.sqrt();
                let d = match j {
                    0..40 => (j as f64 / 40.0 * scale).min(FRAC_PI_2),
                    40..=80 => FRAC_PI_2 * (j - 40) as f64 / 40.0,
                    81..=84 => (scale * 10f64.powi(80 - j)).min(FRAC_PI_2),
                    _ => (FRAC_PI_2 - scale * 10f64.powi(84 - j)).max(0.0),
                };
                for d in [d, -d] {
                    let e = (f64::from(fraction(lambda as f32, d as f32))
                        - fraction_exact(lambda, d))
                    .abs();
                    if e > worst.0 {
                        worst = (e, lambda, d);
                    }
                }
            }
        }
        // Points where a clamped end column was off by more than the bound (CI's proptest
        // case, a random scan's worst).
        for (lambda, d) in [
            (6.143_334_330_533_294, 0.001_916_913_675_937_537_2),
            (270.3918, 0.00016),
        ] {
            let e =
                (f64::from(fraction(lambda as f32, d as f32)) - fraction_exact(lambda, d)).abs();
            if e > worst.0 {
                worst = (e, lambda, d);
            }
        }
        eprintln!(
            "half-space table: worst |ΔF| = {:.2e} at λ = {:.3e}, d = {:.4}",
            worst.0, worst.1, worst.2
        );
        assert!(worst.0 < 1.5e-4, "worst {worst:?}");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        /// The f32 table against the f64 quadrature at random (λ, d), λ ∈ [1e-6, 1e6], d over
        /// the whole range and near 0 (where the table's first column is).
        #[test]
        fn table_matches_quadrature(
            ll in -6.0f64..6.0,
            d in prop_oneof![-1.6f64..1.6, -0.01f64..0.01],
        ) {
            let lambda = 10f64.powf(ll);
            let got = f64::from(fraction(lambda as f32, d as f32));
            let want = fraction_exact(lambda, d);
            prop_assert!(got.is_finite() && (0.0..=1.0).contains(&got));
            prop_assert!((got - want).abs() < 1.5e-4, "λ {lambda} d {d}: {got} vs {want}");
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(12))]

        /// The hemisphere integral against the brute-force grid for moderate λ (where a grid
        /// resolves the lobe), at random axis elevations. The table's error is absolute in F,
        /// so lobes far below the horizon (tiny integrals) are only good to 2e-4 of ∫G.
        #[test]
        fn hemisphere_matches_grid(ll in -2.0f64..1.3, c in -1.0f64..1.0) {
            let lambda = 10f64.powf(ll);
            let n = DVec3::Z;
            let axis = DVec3::new((1.0 - c * c).max(0.0).sqrt(), 0.0, c);
            let g = Sg::new(axis, lambda, 2.0);
            let got = hemisphere(&g, n);
            let want = 2.0 * brute(lambda, c.asin());
            // Grid error (relative) plus the table's absolute error in F (≤ 2e-4) times ∫G.
            let tol = 3e-3 * want + 2e-4 * g.integral();
            prop_assert!((got - want).abs() < tol, "{got} vs {want}");
        }
    }

    #[test]
    fn f32_warp_matches_f64() {
        for l in [1e-6f32, 0.1, 3.0, 100.0, 1e4, 1e6] {
            for d in [0.0f32, 1e-4, 0.01, 0.3, 1.0, 1.5] {
                let a = warp_f32(l, d);
                let b = warp(f64::from(l), f64::from(d));
                assert!((f64::from(a) - b).abs() < 1e-6, "λ {l} d {d}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn extreme_inputs_are_finite() {
        for l in [0.0f32, 1e-30, 1e-6, 1.0, 1e6, 1e12, f32::INFINITY] {
            for d in [-10.0f32, -1.0, 0.0, 1e-7, 1.0, 10.0, f32::INFINITY] {
                let f = fraction(l, d);
                assert!(
                    f.is_finite() && (0.0..=1.0).contains(&f),
                    "λ {l} d {d}: {f}"
                );
            }
        }
    }
}
