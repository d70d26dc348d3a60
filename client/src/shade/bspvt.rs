//! BSPVT shading of one vertex (paper 000, §3.3, eq. 2): the light polygon, clipped to the
//! vertex's upper hemisphere, is clipped to each cube face's pyramid (four planes through the
//! origin), cut by the face tree's lines while walking the tree, and every piece in a leaf with
//! v̄ > 0 is integrated with LTC and weighted by v̄. Pieces in v̄ = 0 leaves are dropped.

use bspvt_proto::bspvt::{LineCodec, VertexTrees};
use glam::DVec3;

use super::{Emitter, Lobes, Shaded, light_directions};
use crate::light::Light;

/// Shadowed and unshadowed integrals of `light` at a vertex with baked `trees`.
pub struct VertexLight {
    /// With the trees' visibility: Σ v̄ᵢ ∫ over the pieces [paper000 §3.1 eq. 2].
    pub shadowed: Shaded,
    /// Without visibility (the whole light above the horizon).
    pub unshadowed: Shaded,
    /// Pieces integrated (v̄ > 0).
    pub pieces: u32,
    /// Pieces dropped (v̄ = 0).
    pub dropped: u32,
}

/// Eq. 2: Σᵢ v̄ᵢ ∫_{Ωᵢ} (cos/π, D_ltc), and the unshadowed integrals of the same polygon.
pub fn shade_vertex(
    lobes: &Lobes,
    light: &Light,
    p: DVec3,
    n: DVec3,
    trees: &VertexTrees,
    codec: &LineCodec,
) -> VertexLight {
    let mut out = VertexLight {
        shadowed: Shaded::default(),
        unshadowed: Shaded::default(),
        pieces: 0,
        dropped: 0,
    };
    let dirs = light_directions(light, p, n);
    if dirs.len() < 3 {
        return out;
    }
    let emitter = Emitter::for_lobes(light, p, lobes);
    out.unshadowed = lobes.shade(&dirs, &emitter);
    let u = out.unshadowed.integrals;
    if u.diffuse <= 0.0 && u.specular <= 0.0 {
        return out;
    }
    trees.split_polygon(codec, &dirs, &mut |piece, value, _face| {
        if value == 0 {
            out.dropped += 1;
            return;
        }
        out.pieces += 1;
        // v̄ = value / 255 in f64 (the f32 `unquantise` would lose 6e-8 of the tiling).
        let v = f64::from(value) / 255.0;
        out.shadowed.add_weighted(&lobes.shade(piece, &emitter), v);
    });
    out
}
