//! Surface materials: GGX microfacets over a Lambertian base [Walter07] [Karis13].

use serde::{Deserialize, Serialize};

use crate::error::SceneError;
use crate::texture::MaterialMaps;

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
        }
    }
}

impl Material {
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
        Ok(())
    }
}
