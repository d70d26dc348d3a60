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
