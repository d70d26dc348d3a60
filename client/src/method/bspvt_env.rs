//! The environment through the baked trees: the map cut into textured quad lights at infinity
//! ([`crate::sky`]), each cut by the vertex's sky trees and integrated with LTC GGX
//! [paper000 §3.1 eq. 2]; the scene's lamps, where it has any, with their own trees in the
//! same frame. The map turns at run time: only the pieces move ([`FrameInput::env_rotation_deg`]).
//! Per vertex, unless the map has a sun, the sky is shaded in world-fixed cells instead
//! ([`crate::sky_cells`]): the trees cut them once per vertex, and a turning map only changes
//! their radiance. With `--backend gpu` (or `auto` on a hardware GPU), per vertex, the cells and
//! the lamps are shaded on the GPU ([`crate::gpu::sky`]; the sky's pieces stay on the CPU).

use anyhow::Result;

use super::gpu::GpuPath;
use super::{Frame, FrameInput, FrameMethod, MethodState, Needs, SceneData, Settings};
use crate::frame::image::Image;
use crate::render::renderer::{FrameCounts, Mode, Trees};
use crate::render::sky_cells::CellTransfer;
use crate::sky::SkyPieces;
use crate::sky_cells::SkyCells;

/// See the module doc.
pub(crate) struct BspvtEnv;

impl FrameMethod for BspvtEnv {
    fn name(&self) -> &'static str {
        "bspvt-env"
    }
    fn label(&self) -> &'static str {
        "BSPVT environment"
    }
    fn description(&self) -> &'static str {
        "environment map as k×k quad lights per cube face (per vertex: world-fixed cells), shadowed by baked sky trees × LTC GGX, plus the scene's lamps (--env, --env-rotation, --sky-pieces, --sky-cells)"
    }
    fn needs(&self) -> Needs {
        Needs {
            sky_trees: true,
            env_map: true,
            ..Needs::default()
        }
    }
    fn prepare(&self, _: &SceneData, settings: &Settings) -> Result<Box<dyn MethodState>> {
        let e = &settings.env;
        let env = crate::envmap::EnvLight::load(&e.path)?;
        let sky = SkyPieces::new(&env, e.pieces, e.threshold, e.strength)?;
        let cells = match e.cells {
            0 => None,
            _ if !SkyCells::suits(&sky) => {
                tracing::info!("the map has a sun: the sky is shaded in pieces, not cells");
                None
            }
            bands => Some(SkyCells::new(&env, bands, e.strength)?),
        };
        Ok(Box::new(State {
            sky,
            cells,
            transfer: CellTransfer::default(),
            rotation_deg: e.rotation_deg,
            cached: None,
            gpu: GpuPath::new(settings)?,
        }))
    }
}

struct State {
    sky: SkyPieces,
    /// The sky in cells, for per-vertex frames (`None`: the pieces).
    cells: Option<SkyCells>,
    /// The vertices' cell terms, kept between frames.
    transfer: CellTransfer,
    rotation_deg: f64,
    /// The last sky frame and what it was drawn for: while the map's rotation, the camera,
    /// the materials and the sky trees stay, the sky is reused and only the lamps are
    /// shaded (moving a lamp costs what it costs in `bspvt`).
    cached: Option<(SkyKey, Image, FrameCounts)>,
    /// The GPU's frames, where the settings ask for the GPU.
    gpu: Option<GpuPath>,
}

#[derive(Clone, Copy, PartialEq)]
struct SkyKey {
    rotation: u64,
    mode: Mode,
    shading: u64,
    trees: Option<(usize, usize, usize)>,
}

impl MethodState for State {
    fn frame(&mut self, f: &FrameInput) -> Result<Frame> {
        let rotation = self.rotation_deg + f.env_rotation_deg;
        let key = SkyKey {
            rotation: rotation.to_bits(),
            mode: f.mode,
            shading: f.renderer.shading_key(),
            trees: f.sky_trees.map(Trees::key),
        };
        let (mut image, mut counts) = match &self.cached {
            Some((k, image, counts)) if *k == key => (image.clone(), *counts),
            _ => {
                let (image, counts) = match (&self.cells, f.mode) {
                    (Some(cells), Mode::Vertex) => {
                        let radiance = cells.radiance(rotation);
                        let on_gpu = self
                            .gpu
                            .as_mut()
                            .and_then(|g| g.sky_cells(f, cells, &radiance, f.sky_trees));
                        on_gpu.unwrap_or_else(|| {
                            f.renderer
                                .sky_cells(cells, &radiance, f.sky_trees, &mut self.transfer)
                        })
                    }
                    _ => f
                        .renderer
                        .sky(&self.sky.posed(rotation), f.sky_trees, f.mode),
                };
                self.cached = Some((key, image.clone(), counts));
                (image, counts)
            }
        };
        // The lamps, shadowed by their own trees (unshadowed until those arrive).
        if !f.lights.is_empty() {
            let cpu = |lights: &[crate::light::Light]| {
                f.renderer
                    .bspvt_lights(lights, f.trees, f.sky_trees, f.mode)
            };
            // The GPU's frame is read back here (the sky is added to it).
            let read_back = FrameInput {
                on_gpu: false,
                ..*f
            };
            let on_gpu = match self.gpu.as_mut() {
                Some(g) => g.frame(&read_back, f.lights, f.trees, &cpu)?,
                None => None,
            };
            let (lamps, c) = match on_gpu {
                Some(frame) => (frame.image, frame.counts),
                None => cpu(f.lights),
            };
            image.add(&lamps);
            counts = FrameCounts {
                vertices_shaded: counts.vertices_shaded.max(c.vertices_shaded),
                pixels_shaded: counts.pixels_shaded.max(c.pixels_shaded),
                pieces: counts.pieces + c.pieces,
                pieces_dropped: counts.pieces_dropped + c.pieces_dropped,
            };
        }
        Ok(Frame::new(image, counts))
    }
}
