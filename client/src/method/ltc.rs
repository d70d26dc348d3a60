//! Unshadowed LTC GGX [Heitz16]: the polygon light with no visibility.

use anyhow::Result;

use super::gpu::GpuPath;
use super::{Frame, FrameInput, FrameMethod, MethodState, Needs, SceneData, Settings};

/// See the module doc.
pub(crate) struct Ltc;

impl FrameMethod for Ltc {
    fn name(&self) -> &'static str {
        "ltc"
    }
    fn label(&self) -> &'static str {
        "LTC (no shadows)"
    }
    fn description(&self) -> &'static str {
        "unshadowed LTC GGX of the lights (Heitz et al. 2016), no visibility"
    }
    fn needs(&self) -> Needs {
        Needs {
            polygon_light: true,
            ..Needs::default()
        }
    }
    fn gpu(&self) -> bool {
        true
    }
    fn prepare(&self, _: &SceneData, settings: &Settings) -> Result<Box<dyn MethodState>> {
        Ok(Box::new(State {
            gpu: GpuPath::new(settings)?,
        }))
    }
}

struct State {
    gpu: Option<GpuPath>,
}

impl MethodState for State {
    fn frame(&mut self, f: &FrameInput) -> Result<Frame> {
        let cpu = |ls: &[crate::light::Light]| f.renderer.ltc(ls, f.mode);
        if let Some(g) = self.gpu.as_mut()
            && let Some(frame) = g.frame(f, f.lights()?, None, &cpu)?
        {
            return Ok(frame);
        }
        let (image, counts) = f.renderer.ltc(f.lights()?, f.mode);
        Ok(Frame::new(image, counts))
    }
}
