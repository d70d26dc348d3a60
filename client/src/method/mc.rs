//! Monte Carlo ground truth: exact GGX, shadow rays, MIS of light and BRDF sampling
//! ([Veach95], [Arvo95], [Heitz18vndf]). Progressive (the viewer's): one sample a pass,
//! accumulated until something changes.

use anyhow::Result;

use super::{Frame, FrameInput, FrameMethod, MethodState, Needs, SceneData, Settings, SetupReport};
use crate::frame::image::Image;
use crate::groundtruth;
use crate::render::renderer::FrameCounts;

/// See the module doc.
pub(crate) struct Mc;

impl FrameMethod for Mc {
    fn name(&self) -> &'static str {
        "mc"
    }
    fn label(&self) -> &'static str {
        "Monte Carlo"
    }
    fn description(&self) -> &'static str {
        "Monte Carlo ground truth: exact GGX, shadow rays, MIS (--spp samples a pixel)"
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
        Ok(Box::new(State {
            spp: settings.spp,
            progressive: settings.progressive.then(|| (Vec::new(), 0)),
        }))
    }
}

struct State {
    spp: u32,
    /// Progressive: the running sum and its passes.
    progressive: Option<(Vec<[f32; 3]>, u32)>,
}

impl MethodState for State {
    fn frame(&mut self, f: &FrameInput) -> Result<Frame> {
        let (r, lights) = (f.renderer, f.lights()?);
        let occ = f.scene.occluder();
        let Some((sum, passes)) = self.progressive.as_mut() else {
            let (image, noise) = groundtruth::render_mc(
                f.scene.scene,
                &r.view,
                &r.gbuffer,
                lights,
                occ,
                self.spp,
                f.index,
            );
            let mut frame = Frame::new(image, FrameCounts::default());
            frame.noise = Some(noise.mean_rel_stderr);
            return Ok(frame);
        };
        let (img, _) = groundtruth::render_mc(
            f.scene.scene,
            &r.view,
            &r.gbuffer,
            lights,
            occ,
            1,
            u64::from(*passes),
        );
        if sum.len() != img.pixels.len() {
            *sum = vec![[0.0; 3]; img.pixels.len()];
            *passes = 0;
        }
        *passes += 1;
        for (s, p) in sum.iter_mut().zip(&img.pixels) {
            for k in 0..3 {
                s[k] += p[k];
            }
        }
        let mut out = Image::new(img.width, img.height);
        let inv = 1.0 / *passes as f32;
        for (o, s) in out.pixels.iter_mut().zip(sum.iter()) {
            *o = s.map(|x| x * inv);
        }
        Ok(Frame::new(out, FrameCounts::default()))
    }

    fn invalidate(&mut self) {
        if let Some(p) = self.progressive.as_mut() {
            *p = (Vec::new(), 0);
        }
    }

    fn passes(&self) -> u32 {
        self.progressive.as_ref().map_or(0, |p| p.1)
    }

    fn report(&self) -> SetupReport {
        SetupReport {
            spp: Some(self.spp),
            ..SetupReport::default()
        }
    }
}
