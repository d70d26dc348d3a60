//! Shadow map from the light's centroid with percentage-closer filtering [Reeves87], fixed
//! kernel, × unshadowed per-pixel LTC.

use super::point_shadow::{PointShadow, prepare};
use super::{FrameMethod, MethodState, Needs, SceneData, Settings};
use crate::penumbra::Technique;
use crate::render::renderer::Mode;

/// See the module doc.
pub(crate) struct Pcf;

impl FrameMethod for Pcf {
    fn name(&self) -> &'static str {
        "pcf"
    }
    fn label(&self) -> &'static str {
        "PCF"
    }
    fn description(&self) -> &'static str {
        "shadow map from the light centroid, percentage-closer filtering with a fixed kernel"
    }
    fn needs(&self) -> Needs {
        Needs {
            rays: false,
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
            PointShadow::new(Technique::Pcf, false),
            scene,
            settings,
        ))
    }
}
