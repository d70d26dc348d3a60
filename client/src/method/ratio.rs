//! Stochastic shadows by the ratio estimator [HeitzHillMcGuire18]: unshadowed per-pixel LTC ×
//! the ratio of two Monte Carlo sums from the same samples, with and without shadow rays;
//! optionally denoised by filtering both sums before dividing (§4).

use anyhow::Result;

use super::{Frame, FrameInput, FrameMethod, MethodState, Needs, SceneData, Settings, SetupReport};
use crate::penumbra::GuideCache;
use crate::ratio::render_ratio;
use crate::render::renderer::{FrameCounts, Mode};

/// The ratio estimator, not denoised.
pub(crate) static RATIO: Ratio = Ratio {
    name: "ratio",
    label: "ratio estimator",
    description: "unshadowed LTC × ratio of MC sums with and without shadow rays (Heitz, Hill, McGuire 2018; --spp)",
    denoised: false,
};

/// The ratio estimator with both sums filtered edge-aware before dividing.
pub(crate) static RATIO_DENOISED: Ratio = Ratio {
    name: "ratio-denoised",
    label: "ratio + denoise",
    description: "the ratio estimator with both sums filtered edge-aware before dividing (--spp)",
    denoised: true,
};

/// The ratio estimator, denoised or not.
pub(crate) struct Ratio {
    name: &'static str,
    label: &'static str,
    description: &'static str,
    denoised: bool,
}

impl FrameMethod for Ratio {
    fn name(&self) -> &'static str {
        self.name
    }
    fn label(&self) -> &'static str {
        self.label
    }
    fn description(&self) -> &'static str {
        self.description
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
    fn prepare(&self, scene: &SceneData, settings: &Settings) -> Result<Box<dyn MethodState>> {
        scene.occluder();
        Ok(Box::new(State {
            spp: settings.spp,
            denoise: self.denoised.then_some(settings.denoise_radius),
            guide: GuideCache::default(),
        }))
    }
}

struct State {
    spp: u32,
    denoise: Option<f64>,
    guide: GuideCache,
}

impl MethodState for State {
    fn frame(&mut self, f: &FrameInput) -> Result<Frame> {
        let r = f.renderer;
        let guide = self.guide.get(r);
        let image = super::sum_over_lights(f.lights, |light| {
            Ok(render_ratio(
                r,
                guide,
                light,
                f.scene.occluder(),
                self.spp,
                f.index,
                self.denoise,
            ))
        })?;
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
