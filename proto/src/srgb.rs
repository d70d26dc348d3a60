//! The sRGB transfer function for 8-bit codes (IEC 61966-2-1): decoding by a 256-entry table,
//! encoding linear values to the nearest code.
//!
//! Encoding is on every frame's path (PNG frames, a window's framebuffer: three channels per
//! pixel), so it does not call `powf` per value. The encoding is monotone, so the code of `c`
//! is the number of codes k ≥ 1 whose first value — the least f32 the exact rule
//! ([`encode_by_rule`]) sends to k or above — is ≤ c. Those 255 thresholds are found once by
//! bisection over the f32s of [0, 1] with the rule itself, and a value's code is read from a
//! bucket table (a lower bound) and stepped up past the thresholds it reaches: the rule's code
//! exactly (`encode_equals_the_rule`), at a table lookup and a step or two.

use std::sync::OnceLock;

/// Buckets of the encoder's first guess over [0, 1]; near 0 the curve climbs 12.92 · 255 ≈ 3,295
/// codes per unit, under one code per bucket.
const BUCKETS: usize = 4096;

/// The exact rule: c clamped to [0, 1] (NaN and ±∞ → 0; the same for the table's input), the
/// sRGB curve, ×255, rounded.
fn encode_by_rule(c: f32) -> u8 {
    let c = clamp_unit(c);
    let e = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (e * 255.0).round().clamp(0.0, 255.0) as u8
}

#[inline]
fn clamp_unit(c: f32) -> f32 {
    if c.is_finite() {
        c.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

struct Encoder {
    /// first[k]: the least c in [0, 1] with code ≥ k (first[0] = 0).
    first: [f32; 256],
    /// start[i]: the code of the lowest value a bucket-`i` input can have (a lower bound).
    start: [u8; BUCKETS + 1],
}

fn encoder() -> &'static Encoder {
    static ENCODER: OnceLock<Encoder> = OnceLock::new();
    ENCODER.get_or_init(|| {
        let mut first = [0.0f32; 256];
        for (k, f) in first.iter_mut().enumerate().skip(1) {
            // Non-negative f32s are ordered as their bits: bisect on the bits of [0, 1].
            let (mut lo, mut hi) = (0u32, 1.0f32.to_bits());
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if usize::from(encode_by_rule(f32::from_bits(mid))) >= k {
                    hi = mid;
                } else {
                    lo = mid + 1;
                }
            }
            *f = f32::from_bits(lo);
        }
        // Bucket i = ⌊c · BUCKETS⌋ holds c ≥ i / BUCKETS (a power of two: both exact).
        let start = std::array::from_fn(|i| {
            let least = i as f32 / BUCKETS as f32;
            first.iter().skip(1).filter(|&&f| f <= least).count() as u8
        });
        Encoder { first, start }
    })
}

/// The 8-bit sRGB code nearest linear `c` (clamped to [0, 1]; NaN → 0): the inverse of
/// [`decode`] for the codes, what colour textures' mip levels and PNG frames are written with.
#[inline]
pub fn linear_to_srgb8(c: f32) -> u8 {
    let c = clamp_unit(c);
    let e = encoder();
    let mut k = e.start[(c * BUCKETS as f32) as usize];
    while k < 255 && c >= e.first[usize::from(k) + 1] {
        k += 1;
    }
    k
}

/// The linear value of 8-bit sRGB code `v`.
#[inline]
pub fn decode(v: u8) -> f32 {
    decode_table()[usize::from(v)]
}

fn decode_table() -> &'static [f32; 256] {
    static TABLE: OnceLock<[f32; 256]> = OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|i| {
            let c = i as f32 / 255.0;
            if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            }
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table's code is the rule's: at every f32 within 2¹² steps of each threshold (where
    /// a non-monotone rounding of the rule would show), on a stride through all of [0, 1],
    /// and outside it.
    #[test]
    fn encode_equals_the_rule() {
        let check = |c: f32| assert_eq!(linear_to_srgb8(c), encode_by_rule(c), "c = {c:e}");
        for &f in &encoder().first[1..] {
            let b = f.to_bits();
            for bits in b.saturating_sub(1 << 12)..=(b + (1 << 12)).min(1.0f32.to_bits()) {
                check(f32::from_bits(bits));
            }
        }
        for bits in (0..=1.0f32.to_bits()).step_by(997) {
            check(f32::from_bits(bits));
        }
        for c in [
            -0.0,
            -1e-30,
            -1.0,
            1.0,
            1.000_001,
            2.0,
            1e30,
            f32::NAN,
            f32::INFINITY,
        ] {
            check(c);
            check(-c);
        }
        assert_eq!(linear_to_srgb8(f32::NAN), 0);
        assert_eq!(linear_to_srgb8(0.5), 188);
    }

    /// Every f32 of [0, 1] (about 10⁹; `cargo test --release -p bspvt-proto srgb -- --ignored`).
    #[test]
    #[ignore = "exhaustive: about a minute"]
    fn encode_equals_the_rule_everywhere() {
        for bits in 0..=1.0f32.to_bits() {
            let c = f32::from_bits(bits);
            assert_eq!(linear_to_srgb8(c), encode_by_rule(c), "c = {c:e}");
        }
    }

    /// Decoding then encoding gives every code back.
    #[test]
    fn codes_round_trip() {
        for v in 0..=255u8 {
            assert_eq!(linear_to_srgb8(decode(v)), v);
        }
    }
}
