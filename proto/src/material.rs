//! Surface materials: GGX microfacets over a Lambertian base [Walter07] [Karis13].

use serde::{Deserialize, Serialize};

use crate::error::SceneError;
use glam::{Vec2, Vec3};

use crate::texture::TextureRef;

/// A GGX microfacet material.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// The material's name (for messages).
    #[serde(default)]
    pub name: String,
    /// GGX roughness α (the squared perceptual roughness \[Karis13\]), in (0, 1].
    #[serde(default = "default_roughness")]
    pub roughness: f32,
    /// Diffuse (Lambertian) albedo, linear RGB in [0, 1].
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
    /// Specular colour F0 (Fresnel at normal incidence), linear RGB in [0, 1].
    #[serde(default = "default_specular")]
    pub specular: [f32; 3],
    /// Textures modulating the material through the mesh's UVs (an asset's; not written in
    /// scene files). When present, the constant fields above hold the material at the
    /// textures' means ([`MaterialMaps::at_mean`]).
    #[serde(skip)]
    pub maps: Option<MaterialMaps>,
    /// Where the surface is cut out, letting every ray through (an asset's glTF `alphaMode`
    /// MASK, or BLEND; not written in scene files). `None`: opaque everywhere.
    #[serde(skip)]
    pub cutout: Option<Cutout>,
    /// The tangent-space normal map that bends the shading normal (an asset's glTF
    /// `normalTexture`; not written in scene files).
    #[serde(skip)]
    pub normal_map: Option<NormalMap>,
}

/// A tangent-space normal map (glTF 2.0 §3.9.3 `normalTexture`): each texel is a unit normal
/// in the frame (T, B, N) of the surface — T along increasing u, B along the image's up
/// (decreasing v), N the interpolated normal —, stored as (n + 1) / 2 in linear RGB; `scale`
/// multiplies its x and y.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalMap {
    /// The image.
    pub texture: TextureRef,
    /// `scale`.
    pub scale: f32,
}

impl NormalMap {
    /// The unit tangent-space normal at `uv`: normalize((2c − 1) ⊙ (scale, scale, 1)),
    /// bilinear texels; (0, 0, 1) — no bending — where the texel is degenerate.
    pub fn at(&self, uv: Vec2) -> Vec3 {
        self.at_footprint(uv, None)
    }

    /// [`NormalMap::at`] as a pixel with UV footprint `duv` sees it (the texels mipmapped,
    /// [`TextureRef::sample_footprint`]).
    pub fn at_footprint(&self, uv: Vec2, duv: Option<[Vec2; 2]>) -> Vec3 {
        let c = self.texture.sample_footprint(uv, duv, false);
        let s = if self.scale.is_finite() {
            self.scale
        } else {
            1.0
        };
        let n = Vec3::new(
            (2.0 * c[0] - 1.0) * s,
            (2.0 * c[1] - 1.0) * s,
            2.0 * c[2] - 1.0,
        );
        n.try_normalize().unwrap_or(Vec3::Z)
    }
}

/// An alpha cut-out (glTF 2.0 §3.9.4 `alphaMode`): the surface is absent where its alpha —
/// `alpha` (`baseColorFactor`'s fourth component) × the texture's alpha at the point — is below
/// `cutoff`. Rays of every kind (the bake's, the Monte Carlo's, the penumbrae's) pass through
/// it there; nothing is absorbed where it is present.
#[derive(Clone, Debug, PartialEq)]
pub struct Cutout {
    /// The constant alpha factor, in [0, 1].
    pub alpha: f32,
    /// The cut-off: alpha below it is a hole.
    pub cutoff: f32,
    /// The base-colour texture whose alpha channel modulates `alpha` (`None`: constant).
    pub texture: Option<TextureRef>,
    /// Whether the asset asked for BLEND: partial coverage, which shadows take as the mask
    /// at [`Cutout::BLEND_CUTOFF`] (a documented choice: no partial transmission).
    pub blend: bool,
}

impl Cutout {
    /// The cut-off a BLEND material's shadows use: coverage of at least half is a blocker.
    pub const BLEND_CUTOFF: f32 = 0.5;

    /// glTF's default `alphaCutoff`.
    pub const DEFAULT_CUTOFF: f32 = 0.5;

    /// Whether it cuts nothing out (constant alpha at or above the cut-off): opaque.
    pub fn is_opaque(&self) -> bool {
        self.texture.is_none() && self.alpha >= self.cutoff
    }

    /// Whether the surface is present at `uv` (bilinear alpha, as the material's colour).
    pub fn covers(&self, uv: Option<Vec2>) -> bool {
        let a = match (&self.texture, uv) {
            (Some(t), Some(uv)) => t.sample(uv, false)[3],
            (Some(t), None) => t.texture.mean(false)[3],
            (None, _) => 1.0,
        };
        self.alpha * a >= self.cutoff
    }
}

fn default_roughness() -> f32 {
    0.3
}
fn default_albedo() -> [f32; 3] {
    [0.6, 0.6, 0.6]
}
fn default_specular() -> [f32; 3] {
    [0.04, 0.04, 0.04]
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            roughness: default_roughness(),
            albedo: default_albedo(),
            specular: default_specular(),
            maps: None,
            cutout: None,
            normal_map: None,
        }
    }
}

impl Material {
    /// Whether anything of it is read through the mesh's UVs: its maps, its normal map or its
    /// cut-out's alpha texture (a mesh keeps its UVs for such materials only).
    pub fn samples_uvs(&self) -> bool {
        self.maps.is_some()
            || self.normal_map.is_some()
            || self.cutout.as_ref().is_some_and(|c| c.texture.is_some())
    }

    pub(crate) fn validate(&self, index: usize) -> Result<(), SceneError> {
        let bad = |m: String| Err(SceneError::Invalid(format!("materials[{index}]: {m}")));
        if !(self.roughness.is_finite() && self.roughness > 0.0 && self.roughness <= 1.0) {
            return bad(format!("roughness {} must be in (0, 1]", self.roughness));
        }
        let unit = |c: &[f32; 3]| c.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x));
        if !unit(&self.albedo) {
            return bad("albedo must be in [0, 1]".into());
        }
        if !unit(&self.specular) {
            return bad("specular must be in [0, 1]".into());
        }
        if let Some(c) = &self.cutout
            && !unit(&[c.alpha, c.cutoff, 0.0])
        {
            return bad("a cut-out's alpha and cut-off must be in [0, 1]".into());
        }
        Ok(())
    }
}

/// What modulates a material over its surface, through the mesh's UVs.
#[derive(Clone, Debug, PartialEq)]
pub enum MaterialMaps {
    /// glTF 2.0 metallic-roughness (§3.9.2; BRDF of appendix B): base colour = factor ×
    /// texture (sRGB), metallic = factor × texture B, perceptual roughness = factor ×
    /// texture G; diffuse albedo = base · (1 − metallic), F0 = mix(0.04, base, metallic),
    /// GGX α = roughness².
    MetallicRoughness {
        /// `baseColorFactor` (RGB, linear).
        base_color: [f32; 3],
        /// `metallicFactor`.
        metallic: f32,
        /// `roughnessFactor` (perceptual).
        roughness: f32,
        /// `baseColorTexture`.
        base_color_texture: Option<TextureRef>,
        /// `metallicRoughnessTexture`.
        metallic_roughness_texture: Option<TextureRef>,
    },
    /// OBJ/MTL `map_Kd`: diffuse albedo = `Kd` (the material's albedo) × texture (sRGB);
    /// F0 and α are the material's.
    Diffuse {
        /// `Kd`.
        kd: [f32; 3],
        /// The `map_Kd` image.
        texture: TextureRef,
    },
}

/// Smallest GGX α a textured material gets (as the importers' [`Material`]s).
const MIN_ALPHA: f32 = 1e-3;

impl MaterialMaps {
    /// The textures it samples (for storing a scene).
    pub fn textures(&self) -> Vec<&TextureRef> {
        match self {
            MaterialMaps::MetallicRoughness {
                base_color_texture,
                metallic_roughness_texture,
                ..
            } => base_color_texture
                .iter()
                .chain(metallic_roughness_texture)
                .collect(),
            MaterialMaps::Diffuse { texture, .. } => vec![texture],
        }
    }

    /// The material at a texel value: `sample(texture, srgb)` gives each texture's value.
    fn eval(&self, base: &Material, sample: impl Fn(&TextureRef, bool) -> [f32; 4]) -> Material {
        let unit = |x: f32| {
            if x.is_finite() {
                x.clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        match self {
            MaterialMaps::MetallicRoughness {
                base_color,
                metallic,
                roughness,
                base_color_texture,
                metallic_roughness_texture,
            } => {
                let bc = base_color_texture
                    .as_ref()
                    .map_or([1.0; 4], |t| sample(t, true));
                let mr = metallic_roughness_texture
                    .as_ref()
                    .map_or([1.0; 4], |t| sample(t, false));
                let c: [f32; 3] = std::array::from_fn(|k| unit(base_color[k] * bc[k]));
                let m = unit(metallic * mr[2]);
                let r = unit(roughness * mr[1]);
                Material {
                    name: String::new(),
                    roughness: (r * r).clamp(MIN_ALPHA, 1.0),
                    albedo: c.map(|x| x * (1.0 - m)),
                    specular: c.map(|x| 0.04 + (x - 0.04) * m),
                    maps: None,
                    cutout: None,
                    normal_map: None,
                }
            }
            MaterialMaps::Diffuse { kd, texture } => {
                let t = sample(texture, true);
                Material {
                    name: String::new(),
                    roughness: base.roughness,
                    albedo: std::array::from_fn(|k| unit(kd[k] * t[k])),
                    specular: base.specular,
                    maps: None,
                    cutout: None,
                    normal_map: None,
                }
            }
        }
    }

    /// The material at `uv` (bilinear texels).
    pub fn at(&self, base: &Material, uv: Vec2) -> Material {
        self.at_footprint(base, uv, None)
    }

    /// The material at `uv` as a pixel with UV footprint `duv` sees it (the textures
    /// mipmapped, [`TextureRef::sample_footprint`]; `None`: bilinear texels).
    pub fn at_footprint(&self, base: &Material, uv: Vec2, duv: Option<[Vec2; 2]>) -> Material {
        self.eval(base, |t, srgb| t.sample_footprint(uv, duv, srgb))
    }

    /// The material at each texture's mean texel: the constant the material's own fields
    /// hold, for the paths that do not evaluate textures (the SG method, the Mitsuba export,
    /// a mesh without UVs).
    pub fn at_mean(&self, base: &Material) -> Material {
        self.eval(base, |t, srgb| t.texture.mean(srgb))
    }
}

impl Material {
    /// The material at a surface point with texture coordinates `uv` (`None`: a mesh without
    /// UVs, the material's constant fields). Untextured materials are returned as they are.
    pub fn at(&self, uv: Option<Vec2>) -> std::borrow::Cow<'_, Material> {
        self.at_footprint(uv, None)
    }

    /// [`Material::at`] as a pixel with UV footprint `duv` = [∂uv/∂x, ∂uv/∂y] sees it: the
    /// textures mipmapped ([`MaterialMaps::at_footprint`]).
    pub fn at_footprint(
        &self,
        uv: Option<Vec2>,
        duv: Option<[Vec2; 2]>,
    ) -> std::borrow::Cow<'_, Material> {
        match (&self.maps, uv) {
            (Some(m), Some(uv)) => std::borrow::Cow::Owned(m.at_footprint(self, uv, duv)),
            _ => std::borrow::Cow::Borrowed(self),
        }
    }
}
