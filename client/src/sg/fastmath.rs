//! f32 elementary functions for the shading loop, inlined and branch-light (glibc's `expf`,
//! `logf` and `asinf` are out-of-line calls with wrappers; `floor` is a call too on the baseline
//! x86-64 target). Polynomials from Cephes (S. Moshier, `expf.c`, `logf.c`, `asinf.c`), whose
//! stated peak relative errors are ≈ 1e-7 on the reduced ranges; the tests here check every
//! function against the f64 library over its whole range.

use std::f32::consts::{FRAC_PI_2, LN_2, LOG2_E};

/// e^x. Returns 0 below x = −87.3 (where e^x leaves the normal f32 range; glibc would return
/// a subnormal < 1.2e-38), +∞ above 88.7 and NaN for NaN.
#[inline]
pub fn exp(x: f32) -> f32 {
    if !(x > -87.3) {
        return if x.is_nan() { x } else { 0.0 };
    }
    if x > 88.7 {
        return f32::INFINITY;
    }
    // x = n ln 2 + r, |r| ≤ ln 2 / 2 (n rounded to nearest; ln 2 split in two for exactness).
    let t = x * LOG2_E;
    let n = (t + if t < 0.0 { -0.5 } else { 0.5 }) as i32;
    let nf = n as f32;
    let r = x - nf * 0.693_359_4 + nf * 2.121_944_4e-4;
    let z = r * r;
    let p = ((((1.987_569_1e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r
        + 1.666_666_5e-1)
        * r
        + 0.5;
    let e = p * z + r + 1.0;
    // × 2^n in two steps so that n = −126…−127 and 128 stay normal/finite in between.
    let h = n / 2;
    e * f32::from_bits(((h + 127) as u32) << 23) * f32::from_bits(((n - h + 127) as u32) << 23)
}

/// ln x for positive normal x (callers clamp; other inputs give garbage but never panic).
#[inline]
pub fn ln(x: f32) -> f32 {
    // x = m 2^e with m ∈ [√½, √2): ln x = e ln 2 + ln m, ln m = 2 atanh(f), f = (m−1)/(m+1),
    // |f| ≤ 0.172: the odd series to f⁹ has relative error < 3e-8.
    let bits = x.to_bits();
    let mut e = ((bits >> 23) & 0xff) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    if m > std::f32::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let f = (m - 1.0) / (m + 1.0);
    let f2 = f * f;
    let s = f * (2.0 + f2 * (2.0 / 3.0 + f2 * (2.0 / 5.0 + f2 * (2.0 / 7.0 + f2 * (2.0 / 9.0)))));
    e as f32 * LN_2 + s
}

/// asin x for x ∈ [−1, 1] (callers clamp; |x| > 1 gives NaN).
#[inline]
pub fn asin(x: f32) -> f32 {
    let a = x.abs();
    // |x| > ½: asin a = π/2 − 2 asin √((1 − a)/2).
    let (z, s, big) = if a > 0.5 {
        let z = 0.5 * (1.0 - a);
        (z, z.sqrt(), true)
    } else {
        (a * a, a, false)
    };
    let p = ((((4.216_32e-2 * z + 2.418_131e-2) * z + 4.547_002_6e-2) * z + 7.495_300_3e-2) * z
        + 1.666_675_2e-1)
        * z
        * s
        + s;
    let r = if big { FRAC_PI_2 - 2.0 * p } else { p };
    if x < 0.0 { -r } else { r }
}

/// tanh x for x ≥ 0: m / (2 − m) with m = 1 − e^{−2x} from [`one_minus_exp_neg`] (no
/// cancellation for small x).
#[inline]
pub fn tanh_pos(x: f32) -> f32 {
    let m = one_minus_exp_neg(2.0 * x);
    m / (2.0 - m)
}

/// 1 − e^{−x} (= −expm1(−x)) for x ≥ 0, relative error < 4e-7: the Taylor series below ¼,
/// else 1 − [`exp`]`(−x)` (e^{−x} < 0.78 there, so the subtraction costs < 2 bits).
#[inline]
pub fn one_minus_exp_neg(x: f32) -> f32 {
    if x < 0.25 {
        // 1 − e^{−x} = x (1 − x/2 + x²/6 − x³/24 + x⁴/120 − x⁵/720 + x⁶/5040): the next
        // term is < 0.25⁷/40320 ≈ 1.5e-9 relative.
        x * (1.0
            - x * (0.5
                - x * (1.0 / 6.0
                    - x * (1.0 / 24.0 - x * (1.0 / 120.0 - x * (1.0 / 720.0 - x / 5040.0))))))
    } else {
        1.0 - exp(-x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel(a: f32, b: f64) -> f64 {
        (f64::from(a) - b).abs() / b.abs().max(1e-300)
    }

    #[test]
    fn exp_matches_f64() {
        let mut worst = 0.0f64;
        let mut x = -87.0f32;
        while x < 88.0 {
            let e = rel(exp(x), f64::from(x).exp());
            worst = worst.max(e);
            x += 0.0137;
        }
        for x in [-1e-7f32, 0.0, 1e-7, 0.3465, -0.3466, -87.2, 88.6] {
            worst = worst.max(rel(exp(x), f64::from(x).exp()));
        }
        eprintln!("exp worst relative error {worst:.2e}");
        assert!(worst < 3e-7, "{worst}");
        assert_eq!(exp(-100.0), 0.0);
        assert_eq!(exp(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp(100.0), f32::INFINITY);
        assert!(exp(f32::NAN).is_nan());
    }

    #[test]
    fn ln_matches_f64() {
        let mut worst = 0.0f64;
        let mut x = 1e-37f32;
        while x < 1e37 {
            // Absolute error (the table row coordinate is absolute in ln λ).
            worst = worst.max((f64::from(ln(x)) - f64::from(x).ln()).abs());
            x *= 1.0173;
        }
        for x in [
            1.0f32,
            0.999_999_9,
            1.000_000_1,
            std::f32::consts::SQRT_2,
            1.414_213_7,
            2.0,
        ] {
            worst = worst.max((f64::from(ln(x)) - f64::from(x).ln()).abs());
        }
        eprintln!("ln worst absolute error {worst:.2e}");
        assert!(worst < 1e-5, "{worst}");
    }

    #[test]
    fn asin_matches_f64() {
        let mut worst = 0.0f64;
        for i in -100_000..=100_000 {
            let x = i as f32 / 100_000.0;
            worst = worst.max((f64::from(asin(x)) - f64::from(x).asin()).abs());
        }
        for x in [1e-30f32, 1e-7, 0.5, 0.500_000_06, 0.999_999_94] {
            let e = rel(asin(x), f64::from(x).asin());
            assert!(e < 5e-7, "x {x}: {e}");
        }
        eprintln!("asin worst absolute error {worst:.2e}");
        assert!(worst < 5e-7, "{worst}");
        assert!(asin(1.5).is_nan());
    }

    #[test]
    fn tanh_and_expm1_match_f64() {
        let mut x = 0.0f32;
        while x < 30.0 {
            let t = f64::from(x).tanh();
            assert!(rel(tanh_pos(x), t) < 3e-7 || x == 0.0, "tanh {x}");
            let m = -(-f64::from(x)).exp_m1();
            assert!(
                rel(one_minus_exp_neg(x), m) < 4e-7 || x == 0.0,
                "1 − e^−x {x}"
            );
            x = if x < 1e-3 { x + 1e-5 } else { x * 1.01 };
        }
    }
}
