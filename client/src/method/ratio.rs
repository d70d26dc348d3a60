//! Stochastic shadows by the ratio estimator [HeitzHillMcGuire18]: unshadowed per-pixel LTC ×
//! the ratio of two Monte Carlo sums from the same samples, with and without shadow rays;
//! optionally denoised by filtering both sums before dividing (§4).

use anyhow::Result;

use super::{Frame, FrameInput, FrameMethod, MethodState, Needs, SceneData, Settings, SetupReport};
use crate::penumbra::Guide;
use crate::ratio::render_ratio;
use crate::render::renderer::{FrameCounts, Mode};

/// The ratio estimator, not denoised.
pub(crate) struct Ratio;

/// The ratio estimator with both sums filtered edge-aware before dividing.
pub(crate) struct RatioDenoised;

fn needs() -> Needs {
    Needs {
        rays: true,
        polygon_light: true,
        ..Needs::default()
    }
}

impl FrameMethod for Ratio {
    fn name(&self) -> &'static str {
        "ratio"
    }
    fn label(&self) -> &'static str {
        "ratio estimator"
    }
    fn description(&self) -> &'static str {
        "unshadowed LTC × ratio of MC sums with and without shadow rays (Heitz, Hill, McGuire 2018; --spp)"
    }
    fn needs(&self) -> Needs {
        needs()
    }
    fn fixed_mode(&self) -> Option<Mode> {
        Some(Mode::Pixel)
    }
    fn prepare(&self, scene: &SceneData, settings: &Settings) -> Result<Box<dyn MethodState>> {
        scene.occluder();
        Ok(Box::new(State {
            spp: settings.spp,
            denoise: None,
        }))
    }
}

impl FrameMethod for RatioDenoised {
    fn name(&self) -> &'static str {
        "ratio-denoised"
    }
    fn label(&self) -> &'static str {
        "ratio + denoise"
    }
    fn description(&self) -> &'static str {
        "the ratio estimator with both sums filtered edge-aware before dividing (--spp)"
    }
    fn needs(&self) -> Needs {
        needs()
    }
    fn fixed_mode(&self) -> Option<Mode> {
        Some(Mode::Pixel)
    }
    fn prepare(&self, scene: &SceneData, settings: &Settings) -> Result<Box<dyn MethodState>> {
        scene.occluder();
        Ok(Box::new(State {
            spp: settings.spp,
            denoise: Some(settings.denoise_radius),
        }))
    }
}

struct State {
    spp: u32,
    denoise: Option<f64>,
}

impl MethodState for State {
    fn frame(&mut self, f: &FrameInput) -> Result<Frame> {
        let r = f.renderer;
        let guide = Guide::new(r);
        let image = render_ratio(
            r,
            &guide,
            f.light()?,
            f.scene.occluder(),
            self.spp,
            f.index,
            self.denoise,
        );
        Ok(Frame::new(
            image,
            FrameCounts {
                pixels_shaded: r.gbuffer.covered(),
                ..FrameCounts::default()
            },
        ))
    }

    fn report(&self) -> SetupReport {
        SetupReport {
            spp: Some(self.spp),
            ..SetupReport::default()
        }
    }
}
