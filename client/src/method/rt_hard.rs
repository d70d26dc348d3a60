//! The hard shadow ray of paper 003 to the light's centroid, unblurred, × unshadowed
//! per-pixel LTC (the baseline the blur improves on).

use super::point_shadow::{PointShadow, prepare};
use super::{FrameMethod, MethodState, Needs, SceneData, Settings};
use crate::penumbra::Technique;
use crate::render::renderer::Mode;

/// See the module doc.
pub(crate) struct RtHard;

impl FrameMethod for RtHard {
    fn name(&self) -> &'static str {
        "rt-hard"
    }
    fn label(&self) -> &'static str {
        "RT hard shadow"
    }
    fn description(&self) -> &'static str {
        "the same hard shadow ray to the light centroid, unblurred, × unshadowed per-pixel LTC"
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
            PointShadow::new(Technique::RtHard, true),
            scene,
            settings,
        ))
    }
}
