//! The point-light shadow methods (paper 003 and its shadow-map baselines) as one
//! [`FrameMethod`]: the unshadowed per-pixel LTC × one technique's shadow factor
//! ([`crate::penumbra::render`]). Each technique is one static in its own file.

use anyhow::Result;

use super::gpu::GpuPath;
use super::{Frame, FrameInput, FrameMethod, MethodState, Needs, SceneData, Settings};
use crate::gpu::shadow_rays::GpuShadowRays;
use crate::penumbra::rt::ShadowCaster;
use crate::penumbra::{self, GuideCache, Params, Technique};
use crate::render::renderer::{FrameCounts, Mode};

/// A point-light shadow technique, registered under its name.
pub(crate) struct PointShadow {
    pub(crate) name: &'static str,
    pub(crate) label: &'static str,
    pub(crate) description: &'static str,
    pub(crate) technique: Technique,
}

impl FrameMethod for PointShadow {
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
            rays: self.technique.needs_rays(),
            polygon_light: true,
            punctual: true,
            ..Needs::default()
        }
    }
    /// The ray-traced techniques cast their hard shadow rays, blur them and shade the
    /// polygon lights unshadowed per pixel on the GPU.
    fn gpu(&self) -> bool {
        self.technique.needs_rays()
    }
    fn fixed_mode(&self) -> Option<Mode> {
        Some(Mode::Pixel)
    }
    /// The BVH is built now when the technique traces rays, and uploaded when the backend
    /// is a GPU.
    fn prepare(&self, scene: &SceneData, settings: &Settings) -> Result<Box<dyn MethodState>> {
        let (mut gpu, mut frames) = (None, None);
        if self.technique.needs_rays() {
            let occ = scene.occluder();
            if let (Some(device), _) = settings.backend.resolve()? {
                // rt-hard does not blur: no blur pipeline for it.
                let blur = self.technique == Technique::RtPenumbra;
                gpu = Some(GpuShadowRays::new(device, occ, blur)?);
                frames = GpuPath::new(settings)?;
            }
        }
        Ok(Box::new(State {
            technique: self.technique,
            params: settings.penumbra,
            guide: GuideCache::default(),
            gpu,
            frames,
        }))
    }
}

struct State {
    technique: Technique,
    params: Params,
    guide: GuideCache,
    /// The hard shadow rays and the blur on the GPU (`None`: on the CPU).
    gpu: Option<GpuShadowRays>,
    /// The unshadowed per-pixel frames on the GPU (`None`: on the CPU).
    frames: Option<GpuPath>,
}

impl MethodState for State {
    fn frame(&mut self, f: &FrameInput) -> Result<Frame> {
        let occ: Option<&dyn ShadowCaster> = match &self.gpu {
            Some(g) => Some(g),
            None => self
                .technique
                .needs_rays()
                .then(|| f.scene.occluder() as &dyn ShadowCaster),
        };
        let guide = self.guide.get(f.renderer);
        let image = if f.renderer.scene.punctual.is_empty() {
            // Each polygon light as a point light at its centroid, summed (a sun has no
            // point to cast from: it is left to the other methods).
            let polygons: Vec<_> = f
                .lights
                .iter()
                .filter(|l| l.is_polygon())
                .cloned()
                .collect();
            super::sum_over_lights(&polygons, |light| {
                let on_gpu = match self.frames.as_mut() {
                    Some(g) => g.unshadowed(f, light)?,
                    None => None,
                };
                let unshadowed = match on_gpu {
                    Some(image) => image,
                    None => f.renderer.shade_pixels(std::slice::from_ref(light), None),
                };
                penumbra::render_over(
                    f.renderer,
                    guide,
                    light,
                    self.technique,
                    occ,
                    &self.params,
                    &unshadowed,
                )
            })?
        } else {
            penumbra::render_punctual(f.renderer, guide, self.technique, occ, &self.params)?
        };
        Ok(Frame::new(
            image,
            FrameCounts {
                pixels_shaded: f.renderer.gbuffer.covered(),
                ..FrameCounts::default()
            },
        ))
    }
}
