//! Variance shadow map [Donnelly06]: Chebyshev's bound with light-bleeding reduction
//! [Lauritzen07], × unshadowed per-pixel LTC.

use super::point_shadow::{PointShadow, prepare};
use super::{FrameMethod, MethodState, Needs, SceneData, Settings};
use crate::penumbra::Technique;
use crate::render::renderer::Mode;

/// See the module doc.
pub(crate) struct Vsm;

impl FrameMethod for Vsm {
    fn name(&self) -> &'static str {
        "vsm"
    }
    fn label(&self) -> &'static str {
        "VSM"
    }
    fn description(&self) -> &'static str {
        "variance shadow map (Chebyshev bound, light-bleeding reduction)"
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
            PointShadow::new(Technique::Vsm, false),
            scene,
            settings,
        ))
    }
}
