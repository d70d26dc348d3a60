//! The GPU path of the methods that have one (`bspvt`, `ltc`): frames drawn by
//! [`crate::gpu::frame::GpuFrames`] when [`Settings::backend`] asks for the GPU; the lights the
//! GPU's shaders do not take (a polygon of more than 8 vertices: said once; a sun whose shadows
//! are in the sky's bake, [`bspvt_proto::Scene::suns_in_sky_bake`]) are drawn by the CPU and
//! added.

use anyhow::Result;

use super::{Frame, FrameInput, Settings};
use crate::frame::image::Image;
use crate::gpu::frame::GpuFrames;
use crate::gpu::{Backend, Gpu};
use crate::light::{Light, Shape};
use crate::render::renderer::{FrameCounts, Mode, Trees};
use crate::sky_cells::SkyCells;
use glam::DVec3;

/// MSAA samples of the GPU's frames.
pub(crate) const SAMPLES: u32 = 4;

/// A method's GPU state: the device, and the scene's frames once built.
pub(crate) struct GpuPath {
    gpu: &'static Gpu,
    frames: Option<GpuFrames>,
    /// Why the GPU does not draw this scene (said once; its frames are the CPU's).
    refused: Option<String>,
    /// Some light was left to the CPU (said once).
    said: bool,
    /// The sky's cells do not fit this GPU (said once; the CPU draws the sky).
    sky_refused: bool,
}

impl GpuPath {
    /// The GPU path `settings` ask for (`None`: the CPU draws).
    pub(crate) fn new(settings: &Settings) -> Result<Option<GpuPath>> {
        if settings.backend == Backend::Cpu {
            return Ok(None);
        }
        let (gpu, _) = settings.backend.resolve()?;
        Ok(gpu.map(|gpu| GpuPath {
            gpu,
            frames: None,
            refused: None,
            said: false,
            sky_refused: false,
        }))
    }

    /// The GPU's frame of `lights` with `trees` (`None`: unshadowed), or `None` where the
    /// CPU must draw it. Several lights are drawn one GPU frame each and summed (read back:
    /// a window is then given the sum as a CPU image); each light's per-pixel frame has its
    /// own shadow ratios, as on the CPU. The lights the GPU does not take are drawn by `cpu`
    /// and added.
    pub(crate) fn frame(
        &mut self,
        f: &FrameInput,
        lights: &[Light],
        trees: Option<&Trees>,
        cpu: &dyn Fn(&[Light]) -> (Image, FrameCounts),
    ) -> Result<Option<Frame>> {
        if !self.made(f) {
            return Ok(None);
        }
        // A sun baked with the sky is shadowed by the sky's trees, which the GPU does not hold.
        let sky_suns = trees.is_some() && f.scene.scene.suns_in_sky_bake();
        let (on_gpu, on_cpu): (Vec<Light>, Vec<Light>) = lights.iter().cloned().partition(|l| {
            crate::gpu::vertex::supports(l).is_ok()
                && !(sky_suns && matches!(l.shape, Shape::Distant { .. }))
        });
        if let Some(e) = on_cpu
            .iter()
            .find_map(|l| crate::gpu::vertex::supports(l).err())
            && !self.said
        {
            tracing::warn!("GPU backend: {e:#}");
            self.said = true;
        }
        if on_gpu.is_empty() {
            return Ok(None);
        }
        let Some(frames) = self.frames.as_mut() else {
            return Ok(None);
        };
        if !on_cpu.is_empty() {
            let (mut image, mut counts) = cpu(&on_cpu);
            for l in &on_gpu {
                let (i, c) = frames.frame(self.gpu, f.renderer, l, trees, f.mode)?;
                image.add(&i);
                counts.pieces += c.pieces;
                counts.pieces_dropped += c.pieces_dropped;
            }
            return Ok(Some(Frame::new(image, counts)));
        }
        let lights = &on_gpu[..];
        let light = match lights {
            [one] => one,
            _ => {
                let mut sum: Option<(Image, crate::render::renderer::FrameCounts)> = None;
                for l in lights {
                    let (image, c) = frames.frame(self.gpu, f.renderer, l, trees, f.mode)?;
                    match sum.as_mut() {
                        None => sum = Some((image, c)),
                        Some((s, counts)) => {
                            s.add(&image);
                            counts.pieces += c.pieces;
                            counts.pieces_dropped += c.pieces_dropped;
                        }
                    }
                }
                return Ok(sum.map(|(image, counts)| Frame::new(image, counts)));
            }
        };
        if f.on_gpu {
            let (image, counts) =
                frames.frame_on_gpu(self.gpu, f.renderer, light, trees, f.mode)?;
            let mut frame = Frame::new(Image::new(0, 0), counts);
            frame.gpu = Some(image);
            return Ok(Some(frame));
        }
        let (image, counts) = frames.frame(self.gpu, f.renderer, light, trees, f.mode)?;
        Ok(Some(Frame::new(image, counts)))
    }

    /// The unshadowed per-pixel LTC frame of one `light` (`None`: the CPU must draw it — a
    /// light the shaders do not take, or the scene refused): what the point-light shadow
    /// methods multiply by their shadow factor.
    pub(crate) fn unshadowed(&mut self, f: &FrameInput, light: &Light) -> Result<Option<Image>> {
        if crate::gpu::vertex::supports(light).is_err() || !self.made(f) {
            return Ok(None);
        }
        let Some(frames) = self.frames.as_mut() else {
            return Ok(None);
        };
        let (image, _) = frames.frame(self.gpu, f.renderer, light, None, Mode::Pixel)?;
        Ok(Some(image))
    }

    /// The GPU's per-vertex frame of the sky in `cells` with this frame's cell radiances,
    /// through the sky's `trees` (`None`: the CPU must draw it; a GPU that cannot hold the
    /// terms says why once and leaves the sky to the CPU).
    pub(crate) fn sky_cells(
        &mut self,
        f: &FrameInput,
        cells: &SkyCells,
        radiance: &[DVec3],
        trees: Option<&Trees>,
    ) -> Option<(Image, FrameCounts)> {
        if self.sky_refused || !self.made(f) {
            return None;
        }
        let frames = self.frames.as_mut()?;
        match frames.sky_frame(self.gpu, f.renderer, cells, radiance, trees) {
            Ok(frame) => Some(frame),
            Err(e) => {
                tracing::warn!("GPU backend: {e:#}; the sky is drawn on the CPU");
                self.sky_refused = true;
                None
            }
        }
    }

    /// Whether the scene's GPU frames are made (made now if not; `false`: refused).
    fn made(&mut self, f: &FrameInput) -> bool {
        if self.refused.is_some() {
            return false;
        }
        if self.frames.is_none() {
            match GpuFrames::new(self.gpu, f.scene.scene, SAMPLES) {
                Ok(fr) => self.frames = Some(fr),
                Err(e) => {
                    self.refuse(format!("{e:#}"));
                    return false;
                }
            }
        }
        true
    }

    fn refuse(&mut self, why: String) -> Option<Frame> {
        tracing::warn!("GPU backend: {why}; these frames are drawn on the CPU");
        self.refused = Some(why);
        None
    }
}
