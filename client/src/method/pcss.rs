//! Percentage-closer soft shadows [Fernando05]: blocker search, then PCF over the
//! similar-triangles penumbra width, × unshadowed per-pixel LTC.

use super::point_shadow::{PointShadow, prepare};
use super::{FrameMethod, MethodState, Needs, SceneData, Settings};
use crate::penumbra::Technique;
use crate::render::renderer::Mode;

/// See the module doc.
pub(crate) struct Pcss;

impl FrameMethod for Pcss {
    fn name(&self) -> &'static str {
        "pcss"
    }
    fn label(&self) -> &'static str {
        "PCSS"
    }
    fn description(&self) -> &'static str {
        "percentage-closer soft shadows: blocker search, then PCF of the penumbra width"
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
            PointShadow::new(Technique::Pcss, false),
            scene,
            settings,
        ))
    }
}
