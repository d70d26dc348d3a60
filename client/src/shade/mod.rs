//! Direct light from one polygonal light at one shading point, in the LTC form
//! (Heitz et al. 2016, §4; paper 000, eq. 2):
//!
//! ```text
//! L_o = L ⊙ ( albedo · D  +  (F0 · magnitude + (1 − F0) · fresnel) · S )
//! D = Σᵢ v̄ᵢ ∫_{Ωᵢ} cos θ / π dω,    S = Σᵢ v̄ᵢ ∫_{Ωᵢ} D_ltc dω
//! ```
//!
//! Ωᵢ are the pieces of the light polygon (seen from the point, above its horizon) and v̄ᵢ their
//! visibility: one piece with v̄ = 1 for unshadowed LTC ([`unshadowed`]), the BSPVT leaves for
//! the baked shadows ([`bspvt`]).

pub mod bspvt;
pub mod sky;
pub(crate) mod sky_cells;

use bspvt_proto::scene::Material;
use bspvt_proto::sphere::{self, SphPoly};
use glam::{DMat3, DVec3};

use crate::frame::shading::ShadingFrame;
use crate::ggx;
use crate::light::Light;
use crate::ltc::polygon::{integrate, vector_form_factor};
use crate::ltc::table::LtcTable;
use crate::texture::{LightFrame, PlaneLookup};

/// The two integrals of a light at a point: diffuse D = ∫ V cos/π and specular S = ∫ V D_ltc.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Integrals {
    /// ∫ V cos θ / π over the light.
    pub diffuse: f64,
    /// ∫ V D_ltc over the light [Heitz16].
    pub specular: f64,
}

impl std::ops::AddAssign for Integrals {
    fn add_assign(&mut self, o: Integrals) {
        self.diffuse += o.diffuse;
        self.specular += o.specular;
    }
}

impl std::ops::Mul<f64> for Integrals {
    type Output = Integrals;
    fn mul(self, k: f64) -> Integrals {
        Integrals {
            diffuse: self.diffuse * k,
            specular: self.specular * k,
        }
    }
}

/// Integrals with the light's colour: `diffuse_rgb` = Σ v̄ᵢ Dᵢ · texᵢ (texᵢ = 1 for untextured
/// lights), likewise `specular_rgb`. The scalar `integrals` give the shadow ratios.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Shaded {
    /// The scalar integrals (shadow ratios).
    pub integrals: Integrals,
    /// Σ v̄ᵢ Dᵢ · texᵢ per channel.
    pub diffuse_rgb: DVec3,
    /// Σ v̄ᵢ Sᵢ · texᵢ per channel.
    pub specular_rgb: DVec3,
}

impl std::ops::AddAssign for Shaded {
    fn add_assign(&mut self, o: Shaded) {
        self.integrals += o.integrals;
        self.diffuse_rgb += o.diffuse_rgb;
        self.specular_rgb += o.specular_rgb;
    }
}

impl Shaded {
    /// The coloured integrals times a light's radiance `l` (the scalar integrals unchanged):
    /// direct light is linear in the lights, so several lights sum as `Σ L_l ⊙ Shaded_l`,
    /// shaded with radiance 1.
    #[inline]
    pub(crate) fn tinted(self, l: DVec3) -> Shaded {
        Shaded {
            integrals: self.integrals,
            diffuse_rgb: self.diffuse_rgb * l,
            specular_rgb: self.specular_rgb * l,
        }
    }

    /// Adds `v` × one piece.
    #[inline]
    pub(crate) fn add_weighted(&mut self, piece: &Shaded, v: f64) {
        self.integrals += piece.integrals * v;
        self.diffuse_rgb += piece.diffuse_rgb * v;
        self.specular_rgb += piece.specular_rgb * v;
    }
}

/// Shadowed / unshadowed per lobe and channel — \[diffuse, specular\] × RGB — the per-vertex
/// factor the per-pixel mode interpolates and multiplies its own unshadowed shading by. Per
/// channel, because what a point sees of a coloured light (a textured lamp, the sky through a
/// doorway) need not have the whole light's colour.
pub type ShadowRatio = [[f32; 3]; 2];

/// The ratio of a point that nothing shadows.
pub const UNSHADOWED: ShadowRatio = [[1.0; 3]; 2];

impl Shaded {
    /// Shadowed (`self`) / `unshadowed` per lobe and channel, clamped to \[0, 1\]; 1 where the
    /// unshadowed value is zero (the ratio then multiplies nothing).
    pub fn ratio(&self, unshadowed: &Shaded) -> ShadowRatio {
        let r = |s: DVec3, u: DVec3| {
            let c = |s: f64, u: f64| {
                if u > 0.0 {
                    (s / u).clamp(0.0, 1.0) as f32
                } else {
                    1.0
                }
            };
            [c(s.x, u.x), c(s.y, u.y), c(s.z, u.z)]
        };
        [
            r(self.diffuse_rgb, unshadowed.diffuse_rgb),
            r(self.specular_rgb, unshadowed.specular_rgb),
        ]
    }
}

/// The material's lobes at one point and view: the world → LTC-space matrices of the diffuse
/// (cosine) and specular (LTC) lobes, and the specular scale per channel.
#[derive(Clone, Copy, Debug)]
pub struct Lobes {
    /// World direction → local frame (rows: tangent, bitangent, normal).
    pub to_local: DMat3,
    /// World direction → the specular LTC's cosine space: M⁻¹ · to_local.
    pub(crate) to_ltc: DMat3,
    /// Albedo (diffuse weight).
    pub(crate) albedo: DVec3,
    /// F0 · magnitude + (1 − F0) · fresnel, per channel.
    pub(crate) specular: DVec3,
}

impl Lobes {
    /// `n`: unit normal; `wo`: unit direction to the viewer.
    pub fn new(table: &LtcTable, material: &Material, n: DVec3, wo: DVec3) -> Lobes {
        let frame = ShadingFrame::new(n, wo);
        let alpha = ggx::clamp_alpha(f64::from(material.roughness));
        let ltc = table.lookup(alpha, frame.cos_view(wo));
        let to_local = DMat3::from_cols(frame.x, frame.y, frame.z).transpose();
        let f0 = glam::Vec3::from(material.specular).as_dvec3();
        Lobes {
            to_local,
            to_ltc: ltc.m_inv * to_local,
            albedo: glam::Vec3::from(material.albedo).as_dvec3(),
            specular: f0 * ltc.magnitude + (DVec3::ONE - f0) * ltc.fresnel,
        }
    }

    /// Both integrals over one spherical polygon of world directions (from the point).
    #[inline]
    pub(crate) fn integrate(&self, poly: &[DVec3]) -> Integrals {
        Integrals {
            diffuse: integrate(&self.to_local, poly),
            specular: integrate(&self.to_ltc, poly),
        }
    }

    /// Both integrals over one polygon, with the light's texture fetched per lobe where its
    /// vector form factor points (Heitz et al. 2016, §5.3).
    #[inline]
    pub(crate) fn shade(&self, poly: &[DVec3], emitter: &Emitter) -> Shaded {
        match emitter.texture {
            None => {
                let i = self.integrate(poly);
                Shaded {
                    integrals: i,
                    diffuse_rgb: DVec3::splat(i.diffuse),
                    specular_rgb: DVec3::splat(i.specular),
                }
            }
            Some(tex) => {
                let mut out = Shaded::default();
                let piece_lod = emitter.frame.piece_lod(poly, tex);
                if let Some(f) = vector_form_factor(&self.to_local, poly) {
                    out.integrals.diffuse = f.z.min(1.0);
                    out.diffuse_rgb =
                        emitter.fetch(0, &self.to_local, f, tex, piece_lod) * f.z.min(1.0);
                }
                if let Some(f) = vector_form_factor(&self.to_ltc, poly) {
                    out.integrals.specular = f.z.min(1.0);
                    out.specular_rgb =
                        emitter.fetch(1, &self.to_ltc, f, tex, piece_lod) * f.z.min(1.0);
                }
                out
            }
        }
    }

    /// Outgoing radiance for light radiance `l`.
    #[inline]
    pub fn radiance(&self, l: DVec3, s: &Shaded) -> DVec3 {
        l * (self.albedo * s.diffuse_rgb + self.specular * s.specular_rgb)
    }

    /// Outgoing radiance with separate shadow ratios [diffuse, specular] (per-pixel mode).
    #[inline]
    pub(crate) fn radiance_scaled(&self, l: DVec3, s: &Shaded, ratio: ShadowRatio) -> DVec3 {
        let [d, sp] = ratio.map(|r| glam::Vec3::from(r).as_dvec3());
        l * (self.albedo * s.diffuse_rgb * d + self.specular * s.specular_rgb * sp)
    }
}

/// What a shading point needs of the light beyond its polygon: its plane frame and texture.
pub(crate) struct Emitter<'a> {
    pub(crate) frame: LightFrame,
    pub(crate) texture: Option<&'a crate::texture::LightTexture>,
    /// A textured light's lookups for the diffuse and specular lobe, prepared once for the
    /// many pieces a tree cuts from it ([`Emitter::for_lobes`]).
    lookups: Option<[PlaneLookup; 2]>,
}

impl<'a> Emitter<'a> {
    pub(crate) fn new(light: &'a Light, p: DVec3) -> Emitter<'a> {
        // Only a polygon has a texture (and a frame to look it up in).
        let textured = light.vertices.len() >= 3;
        Emitter {
            frame: match textured {
                true => LightFrame::new(&light.vertices, p),
                false => LightFrame {
                    origin: DVec3::ZERO,
                    e1: DVec3::X,
                    e2: DVec3::Y,
                },
            },
            texture: light.texture.as_deref().filter(|_| textured),
            lookups: None,
        }
    }

    /// [`Emitter::new`] with the texture lookups of `lobes` prepared: for shading many
    /// pieces of the light with the same lobes (the same results as without).
    pub(crate) fn for_lobes(light: &'a Light, p: DVec3, lobes: &Lobes) -> Emitter<'a> {
        let mut e = Emitter::new(light, p);
        e.lookups = e.texture.map(|t| {
            [
                PlaneLookup::new(&e.frame, &lobes.to_local, t),
                PlaneLookup::new(&e.frame, &lobes.to_ltc, t),
            ]
        });
        e
    }

    /// The texture seen along `f` by lobe `lobe` (0 diffuse, 1 specular; `m` its map).
    #[inline]
    fn fetch(
        &self,
        lobe: usize,
        m: &DMat3,
        f: DVec3,
        tex: &crate::texture::LightTexture,
        max_lod: f64,
    ) -> DVec3 {
        match &self.lookups {
            Some(l) => l[lobe].fetch(f, tex, max_lod),
            None => PlaneLookup::new(&self.frame, m, tex).fetch(f, tex, max_lod),
        }
    }
}

/// True when the viewer is above the shading hemisphere (n · ωo > 0). Below it (silhouettes,
/// where the interpolated normal turns away from the viewer) the BRDF is 0 — as in the Monte
/// Carlo ground truth and Mitsuba's one-sided BSDFs — so the per-pixel shaders return black
/// there instead of clamping ωo to the horizon.
#[inline]
pub(crate) fn sees_viewer(n: DVec3, wo: DVec3) -> bool {
    n.dot(wo) > 0.0
}

/// What the light subtends from `p` ([`Light::directions`]: a polygon, a sphere's or the
/// sun's disk), clipped to the upper hemisphere of `n`; empty when the light is wholly below
/// the horizon, `p` is behind a one-sided light, outside a spot's cone or inside a sphere.
pub fn light_directions(light: &Light, p: DVec3, n: DVec3) -> SphPoly {
    if !p.is_finite() || !n.is_finite() || !light.faces(p) {
        return SphPoly::new();
    }
    let dirs = light.directions(p);
    if dirs.len() < 3 {
        return SphPoly::new();
    }
    sphere::clip(&dirs, n)
}

/// Unshadowed LTC at a point: the whole (horizon-clipped) polygon with V = 1.
pub fn unshadowed(lobes: &Lobes, light: &Light, p: DVec3, n: DVec3) -> Shaded {
    let dirs = light_directions(light, p, n);
    if dirs.len() < 3 {
        return Shaded::default();
    }
    lobes.shade(&dirs, &Emitter::new(light, p))
}

/// Unshadowed LTC of several lights at a point, each tinted by its radiance
/// ([`Shaded::tinted`]): shade with radiance 1.
pub fn unshadowed_lights(lobes: &Lobes, lights: &[Light], p: DVec3, n: DVec3) -> Shaded {
    let mut sum = Shaded::default();
    for l in lights {
        sum += unshadowed(lobes, l, p, n).tinted(l.radiance_toward(p));
    }
    sum
}
