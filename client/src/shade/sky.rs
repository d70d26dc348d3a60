//! Environment light through the baked trees: eq. 2 of paper 000 summed over the pieces of
//! the map ([`crate::sky`]), each a textured quad light at infinity. A piece's directions do
//! not depend on the shading point, so it is shaded from the origin; the trees cut it as they
//! cut a lamp, and every piece in a leaf with v̄ > 0 is integrated with LTC and weighted by v̄.

use bspvt_proto::bspvt::{LineCodec, VertexTrees};
use glam::DVec3;

use super::{Emitter, Lobes, Shaded, ShadowRatio, light_directions};
use crate::light::Light;

/// Σ over the pieces, with each piece's radiance folded into the colours.
#[derive(Clone, Copy, Debug, Default)]
pub struct SkyVertex {
    /// With the trees' visibility.
    pub shadowed: Shaded,
    /// Without visibility (the whole sky above the horizon).
    pub unshadowed: Shaded,
    /// Tree pieces integrated (v̄ > 0), over all sky pieces.
    pub pieces: u32,
    /// Tree pieces dropped (v̄ = 0).
    pub dropped: u32,
}

impl SkyVertex {
    /// Shadowed / unshadowed per lobe and channel, of the radiance-weighted integrals (what
    /// the per-pixel mode interpolates).
    pub fn ratio(&self) -> ShadowRatio {
        self.shadowed.ratio(&self.unshadowed)
    }
}

/// Adds piece `s` of radiance `l` (per channel) to `acc`.
#[inline]
fn add(acc: &mut Shaded, s: &Shaded, l: DVec3) {
    acc.integrals += s.integrals;
    acc.diffuse_rgb += s.diffuse_rgb * l;
    acc.specular_rgb += s.specular_rgb * l;
}

/// Eq. 2 over every piece of the sky at a vertex with normal `n` and baked sky `trees`;
/// the unshadowed integrals (for the shadow ratios of the per-pixel mode) only when asked:
/// they cost a quarter of the vertex.
pub fn shade_vertex_sky(
    lobes: &Lobes,
    pieces: &[Light],
    n: DVec3,
    trees: &VertexTrees,
    codec: &LineCodec,
    unshadowed: bool,
) -> SkyVertex {
    let mut out = SkyVertex::default();
    for piece in pieces {
        let dirs = light_directions(piece, DVec3::ZERO, n);
        if dirs.len() < 3 {
            continue;
        }
        let emitter = Emitter::for_lobes(piece, DVec3::ZERO, lobes);
        if unshadowed {
            add(
                &mut out.unshadowed,
                &lobes.shade(&dirs, &emitter),
                piece.radiance,
            );
        }
        let mut shadowed = Shaded::default();
        trees.split_polygon(codec, &dirs, &mut |poly, value, _face| {
            if value == 0 {
                out.dropped += 1;
                return;
            }
            out.pieces += 1;
            // v̄ = value / 255 in f64, as for a lamp (shade::bspvt).
            let v = f64::from(value) / 255.0;
            shadowed.add_weighted(&lobes.shade(poly, &emitter), v);
        });
        add(&mut out.shadowed, &shadowed, piece.radiance);
    }
    out
}

/// The unshadowed sky at a point with normal `n` (per-pixel mode, and vertices whose trees
/// have not arrived).
pub fn unshadowed_sky(lobes: &Lobes, pieces: &[Light], n: DVec3) -> Shaded {
    let mut out = Shaded::default();
    for piece in pieces {
        let dirs = light_directions(piece, DVec3::ZERO, n);
        if dirs.len() < 3 {
            continue;
        }
        let s = lobes.shade(&dirs, &Emitter::new(piece, DVec3::ZERO));
        add(&mut out, &s, piece.radiance);
    }
    out
}
