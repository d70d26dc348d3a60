//! Textured polygonal lights (Heitz et al. 2016, §5.3): the texture is prefiltered into a
//! pyramid whose level k is blurred over 2ᵏ texels, and a lobe fetches it once per polygon
//! (here: once per BSPVT piece) at the point where its vector form factor pierces the light's
//! plane, at the level of the lobe's footprint.
//!
//! Light parameterisation: (u, v) are coordinates in the basis (p₁ − p₀, pₙ₋₁ − p₀) of the
//! light's plane, so a quad's texture covers it exactly; other polygons use the parallelogram
//! spanned by their first and last edges. Outside [0, 1]² the texture is clamped to its edge.
//! The pyramid itself ([`LightTexture`]) is bspvt-shaders', shared with the service, which
//! uploads it for the browser viewer.

use glam::{DMat3, DVec2, DVec3};

pub use bspvt_shaders::light_texture::LightTexture;

/// How much the texture varies at its coarsest useful scale: (max − min) / mean of the
/// luminances of its four quadrants' means (finest level); 0 for a texture too small to
/// have quadrants or with a zero mean.
pub(crate) fn quadrant_variation(texture: &LightTexture) -> f64 {
    let (w, h, texels) = texture.finest();
    if w < 2 || h < 2 {
        return 0.0;
    }
    let mut sums = [0.0f64; 4];
    let mut counts = [0usize; 4];
    for y in 0..h {
        for x in 0..w {
            let q = usize::from(2 * x >= w) + 2 * usize::from(2 * y >= h);
            let t = texels[y * w + x];
            sums[q] += crate::frame::stats::luminance(t.x, t.y, t.z);
            counts[q] += 1;
        }
    }
    let means: Vec<f64> = sums
        .iter()
        .zip(counts)
        .map(|(s, c)| s / c.max(1) as f64)
        .collect();
    let mean = means.iter().sum::<f64>() / 4.0;
    let (lo, hi) = means
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &m| {
            (a.min(m), b.max(m))
        });
    if mean > 0.0 && (hi - lo).is_finite() {
        (hi - lo) / mean
    } else {
        0.0
    }
}

/// The light's plane frame relative to a shading point: p₀ − p, e₁ = p₁ − p₀, e₂ = pₙ₋₁ − p₀.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LightFrame {
    pub(crate) origin: DVec3,
    pub(crate) e1: DVec3,
    pub(crate) e2: DVec3,
}

impl LightFrame {
    pub(crate) fn new(vertices: &[DVec3], p: DVec3) -> LightFrame {
        let n = vertices.len();
        LightFrame {
            origin: vertices[0] - p,
            e1: vertices[1 % n] - vertices[0],
            e2: vertices[n - 1] - vertices[0],
        }
    }

    /// (u, v) of a point on the light's plane, `q` relative to the light's p₀.
    pub(crate) fn uv(&self, q: DVec3) -> DVec2 {
        uv_in(self.e1, self.e2, q)
    }

    /// Heitz et al. 2016, §5.3 (`FetchFilteredTexture`): in the lobe's cosine space (the
    /// linear map `m`), the ray along the vector form factor `f` meets the light's plane at
    /// (u, v); the footprint d = distance / √area sets the level, log₂(d · size).
    #[cfg(test)]
    pub(crate) fn lookup(&self, m: &DMat3, f: DVec3, tex: &LightTexture) -> DVec3 {
        PlaneLookup::new(self, m, tex).fetch(f, tex, f64::INFINITY)
    }

    /// The finest level that still averages over all of `poly`, a part of the light (as
    /// directions from the shading point) — log₂ of its extent in texels, √(its area on the
    /// light's plane / the texture's area) · size. The lobe's footprint [Heitz16 §5.3] is the
    /// filter for a whole light; a piece that a tree or the horizon cuts from it can be much
    /// smaller, and the lobe is then nearly constant over it, so its integral is the texture's
    /// mean over the piece, not over the lobe's footprint around it: a sliver of dim horizon
    /// seen through a doorway must not fetch the bright sky above it. Area ratios on a plane
    /// are the same in every linear space, so this does not depend on the lobe. +∞ (no limit)
    /// when the piece cannot be projected (a direction parallel to or away from the plane).
    pub(crate) fn piece_lod(&self, poly: &[DVec3], tex: &LightTexture) -> f64 {
        let ortho = self.e1.cross(self.e2);
        let texture_area = ortho.length();
        let dist = ortho.dot(self.origin);
        if !(texture_area > 0.0) || !(dist.abs() > 0.0) {
            return f64::INFINITY;
        }
        let mut twice_area = DVec3::ZERO;
        let mut first = None;
        let mut prev = DVec3::ZERO;
        for &w in poly {
            let den = ortho.dot(w);
            if !(den * dist > 0.0) {
                return f64::INFINITY;
            }
            let q = w * (dist / den);
            match first {
                None => first = Some(q),
                Some(_) => twice_area += prev.cross(q),
            }
            prev = q;
        }
        if let Some(q0) = first {
            twice_area += prev.cross(q0);
        }
        let ratio = 0.5 * twice_area.length() / texture_area;
        let lod = ((ratio.sqrt()) * tex.size() as f64).max(1.0).log2();
        if lod.is_finite() { lod } else { f64::INFINITY }
    }
}

/// [`LightFrame::lookup`] for one lobe, with what does not depend on the direction `f` (the
/// plane in the lobe's space, the level) computed once: the pieces a tree cuts from one light
/// share it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PlaneLookup {
    o: DVec3,
    e1: DVec3,
    e2: DVec3,
    ortho: DVec3,
    area: f64,
    dist_area: f64,
    lod: f64,
}

impl PlaneLookup {
    pub(crate) fn new(frame: &LightFrame, m: &DMat3, tex: &LightTexture) -> PlaneLookup {
        let (o, e1, e2) = (*m * frame.origin, *m * frame.e1, *m * frame.e2);
        let ortho = e1.cross(e2);
        let area = ortho.length();
        let dist_area = ortho.dot(o);
        // Not used when the area is 0 (`fetch` returns the average).
        let d = dist_area.abs() / (area * area.sqrt());
        let lod = (d * tex.size() as f64).max(1.0).log2();
        PlaneLookup {
            o,
            e1,
            e2,
            ortho,
            area,
            dist_area,
            lod,
        }
    }

    /// The filtered texture where the ray along `f` meets the plane; `max_lod` bounds the level: [`LightFrame::piece_lod`] for a piece of the light.
    pub(crate) fn fetch(&self, f: DVec3, tex: &LightTexture, max_lod: f64) -> DVec3 {
        let denom = self.ortho.dot(f);
        if !(self.area > 0.0) || !(denom.abs() > 0.0) {
            return tex.average();
        }
        let q = f * (self.dist_area / denom) - self.o;
        tex.sample(uv_in(self.e1, self.e2, q), self.lod.min(max_lod))
    }
}

/// Coordinates of `q` in the (non-orthogonal) basis (e₁, e₂) of a plane.
fn uv_in(e1: DVec3, e2: DVec3, q: DVec3) -> DVec2 {
    let d11 = e1.dot(e1);
    let d12 = e1.dot(e2);
    let d22 = e2.dot(e2);
    let det = d11 * d22 - d12 * d12;
    if !(det.abs() > 0.0) {
        return DVec2::splat(0.5);
    }
    let (a, b) = (e1.dot(q), e2.dot(q));
    DVec2::new((d22 * a - d12 * b) / det, (d11 * b - d12 * a) / det)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker(n: usize) -> LightTexture {
        let t: Vec<[f32; 3]> = (0..n * n)
            .map(|i| {
                let (x, y) = (i % n, i / n);
                if (x / 4 + y / 4) % 2 == 0 {
                    [1.0; 3]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        LightTexture::from_texels(n, n, &t).expect("texture")
    }

    #[test]
    fn uv_inverts_the_light_basis() {
        let v = [
            DVec3::new(0.0, 3.0, 0.0),
            DVec3::new(2.0, 3.0, 0.0),
            DVec3::new(2.5, 3.0, 1.0),
            DVec3::new(0.5, 3.0, 1.0),
        ];
        let f = LightFrame::new(&v, DVec3::ZERO);
        let q = 0.25 * f.e1 + 0.75 * f.e2;
        let uv = f.uv(q);
        assert!((uv - DVec2::new(0.25, 0.75)).length() < 1e-12);
        // Looking straight at the point (identity lobe) fetches it at a sharp level.
        let dir = f.origin + q;
        let t = checker(64);
        let got = f.lookup(&DMat3::IDENTITY, dir, &t);
        assert!(got.is_finite());
    }

    /// A piece's level is log₂ of its extent in texels: the whole light → log₂ size, a
    /// quarter of it → log₂ size − 1, whatever the distance; a piece that cannot be projected
    /// (behind the plane) sets no bound. A half-dark texture fetched over a small bright
    /// corner piece reads bright, not the half-grey of the lobe's footprint.
    #[test]
    fn a_piece_is_filtered_over_itself() {
        let size = 64;
        let half: Vec<[f32; 3]> = (0..size * size)
            .map(|i| {
                if i % size < size / 2 {
                    [1.0; 3]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        let tex = LightTexture::from_texels(size, size, &half).expect("texture");
        // A 2 × 2 light at height 1 above the point, facing down; p₀ = (−1, 1, −1).
        let light = [
            DVec3::new(-1.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(-1.0, 1.0, 1.0),
        ];
        let frame = LightFrame::new(&light, DVec3::ZERO);
        assert!((frame.piece_lod(&light, &tex) - 6.0).abs() < 1e-9);
        let quarter = [
            DVec3::new(-1.0, 1.0, -1.0),
            DVec3::new(0.0, 1.0, -1.0),
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(-1.0, 1.0, 0.0),
        ];
        assert!((frame.piece_lod(&quarter, &tex) - 5.0).abs() < 1e-9);
        let far = quarter.map(|d| d * 7.0);
        assert!((frame.piece_lod(&far, &tex) - 5.0).abs() < 1e-9);
        let behind = [DVec3::NEG_Y, DVec3::X, DVec3::Z];
        assert_eq!(frame.piece_lod(&behind, &tex), f64::INFINITY);

        // A small piece in the bright half (u < ¼), seen straight on by the cosine lobe.
        let sliver = [
            DVec3::new(-0.9, 1.0, -0.1),
            DVec3::new(-0.7, 1.0, -0.1),
            DVec3::new(-0.7, 1.0, 0.1),
            DVec3::new(-0.9, 1.0, 0.1),
        ];
        let f = DVec3::new(-0.8, 1.0, 0.0).normalize();
        let m = DMat3::IDENTITY;
        let lookup = PlaneLookup::new(&frame, &m, &tex);
        let lobe_wide = lookup.fetch(f, &tex, f64::INFINITY).x;
        let own = lookup.fetch(f, &tex, frame.piece_lod(&sliver, &tex)).x;
        assert!(own > 0.95, "filtered over itself: {own}");
        assert!(
            lobe_wide < 0.9,
            "the lobe's footprint reaches the dark half: {lobe_wide}"
        );
    }
}
