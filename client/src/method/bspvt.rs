//! BSPVT: baked visibility × LTC GGX (paper 000 §3.2, eq. 2). Vertices without trees yet
//! (while streaming) are shaded unshadowed.

use anyhow::Result;

use super::gpu::GpuPath;
use super::{Frame, FrameInput, FrameMethod, MethodState, Needs, SceneData, Settings};

/// See the module doc.
pub(crate) struct Bspvt;

impl FrameMethod for Bspvt {
    fn name(&self) -> &'static str {
        "bspvt"
    }
    fn label(&self) -> &'static str {
        "BSPVT"
    }
    fn description(&self) -> &'static str {
        "baked BSPVT visibility × LTC GGX over the lights' pieces (paper 000)"
    }
    fn needs(&self) -> Needs {
        Needs {
            trees: true,
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
        let lights = f.lights()?;
        let cpu =
            |ls: &[crate::light::Light]| f.renderer.bspvt_lights(ls, f.trees, f.sky_trees, f.mode);
        if let Some(g) = self.gpu.as_mut()
            && let Some(frame) = g.frame(f, lights, f.trees, &cpu)?
        {
            return Ok(frame);
        }
        let (image, counts) = cpu(lights);
        Ok(Frame::new(image, counts))
    }
}
