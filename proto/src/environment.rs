//! The environment light of a scene: an equirectangular radiance map at infinity (the sky),
//! turned about the up axis and scaled.

use serde::{Deserialize, Serialize};

use crate::error::SceneError;

/// An environment map lighting the scene from infinity.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Environment {
    /// Equirectangular map (Radiance `.hdr` or `.exr`), relative to the scene file.
    pub path: String,
    /// Rotation about +y (up), degrees, counter-clockwise seen from above: the map's
    /// direction d appears at R_y(rotation) · d.
    #[serde(default)]
    pub rotation_deg: f32,
    /// Multiplies the map's radiance.
    #[serde(default = "one")]
    pub strength: f32,
}

fn one() -> f32 {
    1.0
}

impl Environment {
    pub(crate) fn validate(&self) -> Result<(), SceneError> {
        let bad = |m: String| Err(SceneError::Invalid(format!("environment: {m}")));
        if self.path.is_empty() {
            return bad("path is empty".into());
        }
        if !self.rotation_deg.is_finite() {
            return bad(format!("rotation_deg {} is not finite", self.rotation_deg));
        }
        if !(self.strength.is_finite() && self.strength >= 0.0) {
            return bad(format!("strength {} must be finite and ≥ 0", self.strength));
        }
        Ok(())
    }
}
