//! Quantised split lines on a cube face.
//!
//! A line is `n(θ)·(u, v) = c` with `n(θ) = (cos θ, sin θ)`; pixels with `n·p − c ≥ 0` go to the
//! right child (the side the paper's E(P, l) predicts as visible), the rest to the left. Lines
//! are stored quantised — `angle_bits` for θ over [0, 2π), `offset_bits` for c over (−√2, √2)
//! — and the builder chooses among the quantised lines directly, so what is stored is exactly
//! what was fitted. Every side test, in the builder and in the query, goes through
//! [`LineCodec::side`], so both see the same partition to the last bit.

use glam::{DVec3, Vec2};

use crate::cubemap::FaceFrame;

/// [`LineCodec::offsets_below`], its constants taken once.
#[derive(Clone, Copy, Debug)]
pub struct OffsetBins {
    scale: f32,
    offsets: f32,
}

impl OffsetBins {
    /// Number of offsets `o` with `c(o) ≤ t`, clamped to [0, O] ([`LineCodec::offsets_below`]).
    #[inline]
    pub fn bin(&self, t: f32) -> u32 {
        let k = (t * self.scale + self.offsets - 1.0) * 0.5 + 1.0;
        // Clamped to [0, O] without a branch (`max` takes 0 over NaN), where truncation is
        // floor: k ≤ 0 (and NaN) gives 0, k ≥ O gives O.
        k.max(0.0).min(self.offsets) as u32
    }
}

/// A quantised line: indices into the codec's angle and offset tables.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct QLine {
    /// Index into the angle table: θ = 2π · angle / 2^angle_bits.
    pub angle: u16,
    /// Index into the offset table ([`LineCodec::offset`]).
    pub offset: u16,
}

/// Tables for one quantisation (fixed per bake by the face resolution).
#[derive(Clone, Debug, PartialEq)]
pub struct LineCodec {
    /// Bits of the angle index.
    pub angle_bits: u8,
    /// Bits of the offset index.
    pub offset_bits: u8,
    normals: Vec<Vec2>,
    half_step: f32,
    inv_half_step: f32,
}

/// The largest |c| a line through a face can need: half the face diagonal, √2.
pub const MAX_OFFSET: f32 = std::f32::consts::SQRT_2;

impl LineCodec {
    /// Line precision for a face resolution: about a third of a pixel in offset and a pixel
    /// across the face in angle (`log2(res) + 2` bits each, at least 6).
    pub fn for_resolution(res: u32) -> LineCodec {
        let bits = (32 - res.max(2).saturating_sub(1).leading_zeros()) as u8 + 2;
        LineCodec::new(bits.clamp(6, 14), bits.clamp(6, 14))
    }

    pub(crate) fn new(angle_bits: u8, offset_bits: u8) -> LineCodec {
        let a = 1usize << angle_bits;
        let half = a / 2;
        // The second half of the table is the exact negation of the first, so that the line
        // (θ + π, −c) is the exact mirror of (θ, c).
        let mut normals = Vec::with_capacity(a);
        for k in 0..half {
            let t = std::f64::consts::TAU * k as f64 / a as f64;
            normals.push(Vec2::new(t.cos() as f32, t.sin() as f32));
        }
        for k in 0..half {
            normals.push(-normals[k]);
        }
        LineCodec {
            angle_bits,
            offset_bits,
            normals,
            half_step: MAX_OFFSET / (1u32 << offset_bits) as f32,
            inv_half_step: (1u32 << offset_bits) as f32 / MAX_OFFSET,
        }
    }

    /// Number of quantised angles, 2^angle_bits.
    pub fn angles(&self) -> u32 {
        1 << self.angle_bits
    }

    /// Number of quantised offsets, 2^offset_bits.
    pub fn offsets(&self) -> u32 {
        1 << self.offset_bits
    }

    /// The unit normal n(θ) = (cos θ, sin θ) of angle index `angle`.
    #[inline]
    pub fn normal(&self, angle: u16) -> Vec2 {
        self.normals[angle as usize]
    }

    /// c(o) = (2o + 1 − O)·h, h = √2 / O: symmetric, so c(O − 1 − o) = −c(o) exactly.
    #[inline]
    pub fn offset(&self, offset: u16) -> f32 {
        (2 * offset as i32 + 1 - self.offsets() as i32) as f32 * self.half_step
    }

    /// Number of offsets `o` with `c(o) ≤ t`, clamped to [0, O]; the builder's histogram bin.
    /// May differ from the exact count by one when `t` sits on a line; the partition itself
    /// is always recomputed with [`Self::side`].
    #[inline]
    pub fn offsets_below(&self, t: f32) -> u32 {
        self.offset_bins().bin(t)
    }

    /// [`Self::offsets_below`] with its constants read once, for loops over many points.
    #[inline]
    pub fn offset_bins(&self) -> OffsetBins {
        OffsetBins {
            scale: self.inv_half_step,
            offsets: self.offsets() as f32,
        }
    }

    /// Signed distance (scaled by |n| = 1) of face point `p` to the line.
    #[inline]
    pub fn distance(&self, line: QLine, p: Vec2) -> f32 {
        let n = self.normal(line.angle);
        n.x * p.x + n.y * p.y - self.offset(line.offset)
    }

    /// True when `p` goes to the right child (`n·p − c ≥ 0`).
    #[inline]
    pub fn side(&self, line: QLine, p: Vec2) -> bool {
        self.distance(line, p) >= 0.0
    }

    /// The same line with the sides swapped (θ + π, −c).
    pub fn mirror(&self, line: QLine) -> QLine {
        let half = (self.angles() / 2) as u16;
        QLine {
            angle: (line.angle + half) % (2 * half),
            offset: (self.offsets() - 1) as u16 - line.offset,
        }
    }

    /// The plane through the origin that this line cuts the sphere with, for face `frame`:
    /// `N = n.x·a + n.y·b − c·w`; a direction `d` in the face's pyramid is on the right side
    /// iff `N·d ≥ 0` (because `N·d = (d·w)(n·(u, v) − c)` and `d·w > 0`).
    pub fn plane(&self, line: QLine, frame: &FaceFrame) -> DVec3 {
        let n = self.normal(line.angle).as_dvec2();
        let c = self.offset(line.offset) as f64;
        n.x * frame.a64() + n.y * frame.b64() - c * frame.w64()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirror_swaps_sides_exactly() {
        let codec = LineCodec::for_resolution(64);
        assert_eq!((codec.angle_bits, codec.offset_bits), (8, 8));
        let p = Vec2::new(0.123, -0.456);
        for a in (0..256).step_by(7) {
            for o in (0..256).step_by(5) {
                let l = QLine {
                    angle: a,
                    offset: o,
                };
                let m = codec.mirror(l);
                assert_eq!(codec.distance(l, p), -codec.distance(m, p));
                assert_eq!(codec.mirror(m), l);
            }
        }
    }

    #[test]
    fn offsets_below_counts_offsets() {
        let codec = LineCodec::new(6, 6);
        for k in 0..1000 {
            let t = -1.5 + 3.0 * k as f32 / 999.0;
            let exact = (0..codec.offsets())
                .filter(|&o| codec.offset(o as u16) <= t)
                .count() as i64;
            let got = codec.offsets_below(t) as i64;
            assert!((exact - got).abs() <= 1, "t={t} exact={exact} got={got}");
        }
    }

    /// The bin is the formula's k truncated and clamped to [0, O] (the bins the trees were
    /// always fitted with), at every f32 around the face's range and at the extremes.
    #[test]
    fn bins_are_the_clamped_truncation() {
        let codec = LineCodec::for_resolution(64);
        let bins = codec.offset_bins();
        let o = codec.offsets();
        let reference = |t: f32| {
            let k = (t * bins.scale + bins.offsets - 1.0) * 0.5 + 1.0;
            if k > 0.0 { (k as u32).min(o) } else { 0 }
        };
        let specials = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            0.0,
            -0.0,
        ];
        // Every f32 in [-2, 2] whose bits are a multiple of 64 (≈ 1.6 · 10⁷ values).
        let sweep = (0..=2.0f32.to_bits())
            .step_by(64)
            .flat_map(|b| [f32::from_bits(b), -f32::from_bits(b)]);
        for t in specials.into_iter().chain(sweep) {
            assert_eq!(bins.bin(t), reference(t), "t = {t:e}");
        }
    }
}
