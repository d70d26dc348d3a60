//! Paper 003: one hard shadow ray per pixel to the light's centroid, blurred by the
//! similar-triangles penumbra width, × unshadowed per-pixel LTC.

use super::point_shadow::{PointShadow, prepare};
use super::{FrameMethod, MethodState, Needs, SceneData, Settings};
use crate::penumbra::Technique;
use crate::render::renderer::Mode;

/// See the module doc.
pub(crate) struct RtPenumbra;

impl FrameMethod for RtPenumbra {
    fn name(&self) -> &'static str {
        "rt-penumbra"
    }
    fn label(&self) -> &'static str {
        "RT penumbra (point light)"
    }
    fn description(&self) -> &'static str {
        "one hard shadow ray to the light centroid, blurred by the similar-triangles penumbra width (paper 003)"
    }
    fn needs(&self) -> Needs {
        Needs {
            rays: true,
            polygon_light: true,
            ..Needs::default()
        }
    }
    fn fixed_mode(&self) -> Option<Mode> {
        Some(Mode::Pixel)
    }
    fn prepare(
        &self,
        scene: &SceneData,
        settings: &Settings,
    ) -> anyhow::Result<Box<dyn MethodState>> {
        Ok(prepare(
            PointShadow::new(Technique::RtPenumbra, true),
            scene,
            settings,
        ))
    }
}
