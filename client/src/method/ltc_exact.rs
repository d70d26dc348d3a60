//! LTC with ray-traced visibility: the LTC BRDF [Heitz16] with many shadow rays instead of
//! the trees, so that its error against the ground truth is the BRDF fit's alone and the BSPVT
//! against it shows the visibility error alone (the split of paper 000's figure 8).

use anyhow::Result;

use super::{Frame, FrameInput, FrameMethod, MethodState, Needs, SceneData, Settings, SetupReport};
use crate::groundtruth::ltcvis::{builtin_lookup, render_ltc_exact_visibility};
use crate::render::renderer::FrameCounts;

/// See the module doc.
pub(crate) struct LtcExact;

impl FrameMethod for LtcExact {
    fn name(&self) -> &'static str {
        "ltc-exact"
    }
    fn label(&self) -> &'static str {
        "LTC × ray-traced visibility"
    }
    fn description(&self) -> &'static str {
        "LTC BRDF with visibility by --spp shadow rays (separates LTC-fit and visibility error)"
    }
    fn needs(&self) -> Needs {
        Needs {
            rays: true,
            polygon_light: true,
            ..Needs::default()
        }
    }
    fn prepare(&self, scene: &SceneData, settings: &Settings) -> Result<Box<dyn MethodState>> {
        scene.occluder();
        Ok(Box::new(State { rays: settings.spp }))
    }
}

struct State {
    rays: u32,
}

impl MethodState for State {
    fn frame(&mut self, f: &FrameInput) -> Result<Frame> {
        let r = f.renderer;
        let image = super::sum_over_lights(f.lights, |light| {
            Ok(render_ltc_exact_visibility(
                f.scene.scene,
                &r.view,
                &r.gbuffer,
                light,
                f.scene.occluder(),
                &builtin_lookup,
                self.rays,
                f.index,
            ))
        })?;
        Ok(Frame::new(image, FrameCounts::default()))
    }

    fn report(&self) -> SetupReport {
        SetupReport {
            spp: Some(self.rays),
            ..SetupReport::default()
        }
    }
}
