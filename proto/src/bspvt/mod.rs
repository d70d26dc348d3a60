//! Binary Space Partitioning Visibility Trees (paper 000).
//!
//! One tree per cube face of a vertex's visibility cube map. Internal nodes hold a quantised
//! line ([`line`](mod@line)); leaves hold the mean visibility v̄ of their pixels, quantised to
//! 8 bits (0 = occluded, 255 = visible). The tree answers point queries and splits a spherical
//! polygon into pieces that each lie in one leaf ([`tree`]).

pub mod line;
pub mod tree;

pub use line::{LineCodec, QLine};
pub use tree::{FaceTree, Node, Piece, VertexTrees};

/// Deepest tree level the builder makes and the decoder accepts.
pub const MAX_DEPTH: usize = 40;

/// Leaf value of a direction in a face that has no tree (no pixel of it matters for the
/// scene: below every horizon or unable to reach the light's region): treated as visible.
pub const ABSENT_FACE_VALUE: u8 = 255;

/// Leaf value in [0, 1].
#[inline]
pub fn unquantise(v: u8) -> f32 {
    v as f32 * (1.0 / 255.0)
}

/// Quantises a leaf's mean visibility v̄ in [0, 1] [paper000 §3.2] to 8 bits (round to nearest;
/// error ≤ 1/510).
#[inline]
pub fn quantise(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// [`quantise`] of an exact ratio `num / den` (a leaf's Σk / (n S)), in integers: round half
/// up of 255 num / den, so the CPU and the GPU fit (`bspvt-bake`) give the same value.
/// Returns 255 for `den = 0` and clamps `num > den` to 255.
#[inline]
pub fn quantise_ratio(num: u64, den: u64) -> u8 {
    if den == 0 || num >= den {
        return 255;
    }
    ((510 * u128::from(num) + u128::from(den)) / (2 * u128::from(den))) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The integer rule is round-to-nearest of 255 num / den (half up) and agrees with the f64
    /// rule wherever the f64 product is not within rounding of a half.
    #[test]
    fn quantise_ratio_rounds_to_nearest() {
        let mut ties = 0;
        for den in 1..=600u64 {
            for num in 0..=den {
                let q = quantise_ratio(num, den);
                // 2·den·q − 510·num ∈ (−den, den] ⇔ |q − 255 num/den| ≤ ½, a half rounding up.
                let twice = 2 * i128::from(den) * i128::from(q) - 510 * i128::from(num);
                assert!(
                    twice > -i128::from(den) && twice <= i128::from(den),
                    "{num}/{den} → {q}"
                );
                let x = 255.0 * num as f64 / den as f64;
                if (x - x.floor() - 0.5).abs() > 1e-9 {
                    assert_eq!(q, quantise(num as f64 / den as f64), "{num}/{den}");
                } else {
                    ties += 1;
                }
            }
        }
        assert!(ties > 0, "the halves were tried");
        assert_eq!(quantise_ratio(3, 0), 255);
        assert_eq!(quantise_ratio(7, 5), 255);
    }
}
