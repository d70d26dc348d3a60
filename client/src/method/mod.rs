//! Rendering methods behind one interface ([`FrameMethod`]) and one [`registry`].
//!
//! A method says what it needs (baked trees, rays, an environment map), prepares its
//! per-scene state once ([`FrameMethod::prepare`], timed as setup) and then draws frames
//! ([`MethodState::frame`]) for a camera (the [`Renderer`]'s view and G-buffer) and a light.
//! `bspvt render`, `view`, `animate`, `demo`, the report and the benchmarks all go through
//! it; adding a method is one file here plus one line in [`registry::METHODS`].

pub mod registry;
pub mod sequence;
pub mod trees;

mod bspvt;
mod bspvt_env;
mod env_scene;
mod gpu;
mod ltc;
mod ltc_exact;
mod mc;
mod mc_env;
mod pcf;
mod pcss;
mod point_shadow;
mod ratio;
mod rt_hard;
mod rt_penumbra;
mod sg;
mod vsm;

use std::path::PathBuf;
use std::sync::OnceLock;

use anyhow::Result;
use bspvt_proto::Scene;
use bspvt_raytrace::Occluder;
use serde::Serialize;

use crate::frame::image::Image;
use crate::light::Light;
use crate::render::renderer::{FrameCounts, Mode, Renderer, Trees};

pub use registry::{METHODS, find, names};

/// What a method needs before it can draw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Needs {
    /// The scene's baked BSPVT trees (baked and cached when not given).
    pub trees: bool,
    /// The trees of the sky: the bake of [`bspvt_proto::Scene::sky`] (every direction above
    /// the horizon, rays to infinity); the scene's own trees also, for its lamps, when it has
    /// any.
    pub sky_trees: bool,
    /// A BVH of the scene for rays (built in setup).
    pub rays: bool,
    /// An environment map (`--env`).
    pub env_map: bool,
    /// A light of the scene: a polygon, a point or spot light's sphere, or a sun.
    pub polygon_light: bool,
    /// The scene's punctual lights (glTF `KHR_lights_punctual`) stand in for the polygonal
    /// light when it has them: a scene whose only lights are punctual is enough.
    pub punctual: bool,
}

impl Needs {
    /// Whether the scene's own (lamp) trees are needed: for the method itself, or for the
    /// lamps a sky method draws beside the sky.
    pub fn lamp_trees(&self, scene: &Scene) -> bool {
        self.trees || (self.sky_trees && crate::light::light_count(scene) > 0)
    }

    /// Whether the sky's trees are needed for `scene`: for the method itself, or for the suns
    /// of a method that needs trees where the scene bakes its suns apart
    /// ([`Scene::suns_in_sky_bake`]).
    pub fn sky_trees_for(&self, scene: &Scene) -> bool {
        self.sky_trees || (self.trees && scene.suns_in_sky_bake())
    }

    /// The needs in words, e.g. `trees, polygon light`.
    pub fn describe(&self) -> String {
        let mut v = Vec::new();
        if self.trees {
            v.push("trees");
        }
        if self.sky_trees {
            v.push("sky trees (+ trees for the lamps)");
        }
        if self.rays {
            v.push("rays (BVH)");
        }
        if self.env_map {
            v.push("environment map");
        }
        if self.polygon_light {
            v.push("a light");
        }
        if v.is_empty() {
            "nothing".into()
        } else {
            v.join(", ")
        }
    }
}

/// The environment light of the environment methods.
#[derive(Clone, Debug, Serialize)]
pub struct EnvOptions {
    /// Equirectangular map (Radiance `.hdr`).
    pub path: PathBuf,
    /// SG lobes fitted to the map.
    pub lobes: usize,
    /// How the SG method finds its visibility.
    pub sg: crate::sg::SgOptions,
    /// Rotation of the map about +y, degrees ([`bspvt_proto::scene::Environment`]).
    pub rotation_deg: f64,
    /// Multiplies the map's radiance.
    pub strength: f64,
    /// `bspvt-env`: pieces per cube-face side (6·k² pieces).
    pub pieces: u32,
    /// `bspvt-env`: pieces carrying less than this fraction of the map's power are left out.
    pub threshold: f64,
    /// `bspvt-env` per vertex: the sky in world-fixed cells of this many latitude bands
    /// ([`crate::sky_cells`]); 0, or a map with a sun: the pieces.
    pub cells: u32,
}

impl EnvOptions {
    /// The scene's environment where it has one (path, rotation, strength), else these.
    pub fn for_scene(mut self, scene: &Scene) -> EnvOptions {
        if let Some(e) = &scene.environment {
            self.path = PathBuf::from(&e.path);
            self.rotation_deg = f64::from(e.rotation_deg);
            self.strength = f64::from(e.strength);
        }
        self
    }

    /// The map as loaded for the methods: turned by `rotation_deg` and scaled by `strength`
    /// (the run-time methods that cannot turn it per frame: SG and its references).
    pub fn load_map(&self) -> Result<crate::envmap::EnvLight> {
        let env = crate::envmap::EnvLight::load(&self.path)?;
        Ok(env.rotated_y(self.rotation_deg).scaled(self.strength))
    }
}

impl Default for EnvOptions {
    fn default() -> EnvOptions {
        EnvOptions {
            path: crate::envmap::default_env_path(),
            lobes: 16,
            sg: crate::sg::SgOptions::default(),
            rotation_deg: 0.0,
            strength: 1.0,
            pieces: crate::sky::DEFAULT_K,
            threshold: crate::sky::DEFAULT_THRESHOLD,
            cells: crate::sky_cells::DEFAULT_BANDS,
        }
    }
}

/// What a user may set; each method reads what applies to it.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Per-vertex or per-pixel shading (methods that offer both): what a sequence asks of
    /// every frame.
    pub mode: Mode,
    /// Samples (or shadow rays) per pixel of the stochastic methods.
    pub spp: u32,
    /// The environment light (environment methods).
    pub env: EnvOptions,
    /// The point-light shadow methods' parameters.
    pub penumbra: crate::penumbra::Params,
    /// Stochastic methods accumulate frames until [`MethodState::invalidate`] (the viewer's
    /// progressive Monte Carlo) instead of drawing `spp` fresh samples a frame.
    pub progressive: bool,
    /// The denoised ratio estimator's filter radius, in pixels.
    pub denoise_radius: f64,
    /// Who draws the methods that have a GPU path ([`FrameMethod::gpu`]); the others always
    /// draw on the CPU.
    pub backend: crate::gpu::Backend,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            mode: Mode::Vertex,
            spp: 64,
            env: EnvOptions::default(),
            penumbra: crate::penumbra::Params::default(),
            progressive: false,
            denoise_radius: 4.0,
            backend: crate::gpu::Backend::Cpu,
        }
    }
}

/// The scene a method draws, with what several methods share built once, on first use.
pub struct SceneData<'a> {
    /// The scene (at t = 0 for moving scenes).
    pub scene: &'a Scene,
    occluder: OnceLock<Occluder>,
}

impl<'a> SceneData<'a> {
    /// Wraps `scene`; nothing is built yet.
    pub fn new(scene: &'a Scene) -> SceneData<'a> {
        SceneData {
            scene,
            occluder: OnceLock::new(),
        }
    }

    /// The scene's BVH for rays (built on first use: the highest-quality build).
    pub fn occluder(&self) -> &Occluder {
        self.occluder
            .get_or_init(|| Occluder::of_surfaces(&self.scene.mesh, &self.scene.materials))
    }
}

/// One frame's inputs.
pub struct FrameInput<'a> {
    /// The scene and its shared BVH.
    pub scene: &'a SceneData<'a>,
    /// The camera: view, G-buffer, visible vertices, roughness override.
    pub renderer: &'a Renderer<'a>,
    /// The scene's polygonal lights as posed for this frame (those `--light` keeps; empty:
    /// none). Every method shades their sum.
    pub lights: &'a [Light],
    /// Baked trees (all or those streamed so far); `None`: none yet.
    pub trees: Option<&'a Trees<'a>>,
    /// Baked sky trees ([`Needs::sky_trees`]); `None`: none yet.
    pub sky_trees: Option<&'a Trees<'a>>,
    /// Run-time rotation of the environment about +y, degrees, on top of the map's own.
    pub env_rotation_deg: f64,
    /// The frame's number (seeds the stochastic methods).
    pub index: u64,
    /// Cycle time of a moving scene in [0, 1) (the run-time methods pose the meshes at it).
    pub time: f32,
    /// Per-vertex or per-pixel (methods that offer both).
    pub mode: Mode,
    /// A window presents the frame from the GPU: a method drawing there may leave it there
    /// ([`Frame::gpu`]) instead of reading it back.
    pub on_gpu: bool,
}

impl FrameInput<'_> {
    /// The lights, or an error saying the method needs one.
    pub fn lights(&self) -> Result<&[Light]> {
        if self.lights.is_empty() {
            anyhow::bail!("this method needs a polygonal light; the scene has none");
        }
        Ok(self.lights)
    }
}

/// A single-light technique's image of several lights: the sum of its image of each (direct
/// light is linear in the lights).
pub(crate) fn sum_over_lights(
    lights: &[Light],
    mut one: impl FnMut(&Light) -> Result<Image>,
) -> Result<Image> {
    let mut sum: Option<Image> = None;
    for l in lights {
        let image = one(l)?;
        match sum.as_mut() {
            None => sum = Some(image),
            Some(s) => s.add(&image),
        }
    }
    sum.ok_or_else(|| anyhow::anyhow!("this method needs a light the scene does not have"))
}

/// A drawn frame and what it cost.
pub struct Frame {
    /// Linear radiance.
    pub image: Image,
    /// Vertices, pixels and pieces shaded.
    pub counts: FrameCounts,
    /// Monte Carlo: the mean relative standard error per covered pixel.
    pub noise: Option<f64>,
    /// SG: the depth maps' time (screen SSDF), ms.
    pub maps_ms: Option<f64>,
    /// A moving scene: the time to pose it, ms (inside the frame).
    pub pose_ms: Option<f64>,
    /// The frame left on the GPU (only where [`FrameInput::on_gpu`] asked; `image` is then
    /// empty).
    pub gpu: Option<crate::gpu::frame::GpuImage>,
}

impl Frame {
    /// A frame with its counts and nothing else to report.
    pub fn new(image: Image, counts: FrameCounts) -> Frame {
        Frame {
            image,
            counts,
            noise: None,
            maps_ms: None,
            pose_ms: None,
            gpu: None,
        }
    }
}

/// Figures a prepared method reports once (STATS.json).
#[derive(Clone, Debug, Default)]
pub struct SetupReport {
    /// Samples per pixel, for the stochastic methods.
    pub spp: Option<u32>,
    /// SG: lobes, the fit's relative L2 error over the sphere and its time.
    pub sg_lobes: Option<usize>,
    /// See `sg_lobes`.
    pub sg_fit_error: Option<f64>,
    /// See `sg_lobes`.
    pub sg_fit_seconds: Option<f64>,
    /// SG: how visibility is found.
    pub ssdf: Option<crate::sg::SsdfMode>,
}

/// A rendering method: what the registry lists.
pub trait FrameMethod: Sync {
    /// The name users type (`--method NAME`), kebab-case.
    fn name(&self) -> &'static str;
    /// A short label for overlays and plots.
    fn label(&self) -> &'static str;
    /// One line: what it computes (and the paper or reference it follows).
    fn description(&self) -> &'static str;
    /// What it needs before it can draw.
    fn needs(&self) -> Needs;
    /// Whether it can draw on the GPU ([`Settings::backend`]); the others draw on the CPU
    /// whatever the backend.
    fn gpu(&self) -> bool {
        false
    }
    /// The mode it shades in whatever was asked (`None`: the one asked for).
    fn fixed_mode(&self) -> Option<Mode> {
        None
    }
    /// Builds its per-scene state (BVH, fitted lobes, …): the setup a timing excludes from
    /// frames.
    fn prepare(&self, scene: &SceneData, settings: &Settings) -> Result<Box<dyn MethodState>>;
}

/// A method prepared for one scene.
pub trait MethodState: Send {
    /// Draws one frame.
    fn frame(&mut self, input: &FrameInput) -> Result<Frame>;
    /// Something the image depends on changed (camera, light, trees): progressive methods
    /// start again.
    fn invalidate(&mut self) {}
    /// Progressive methods: the passes in the current image.
    fn passes(&self) -> u32 {
        0
    }
    /// What it reports once.
    fn report(&self) -> SetupReport {
        SetupReport::default()
    }
}

impl std::fmt::Debug for dyn FrameMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Serialises a method as its name.
pub fn serialize_name<S: serde::Serializer>(
    m: &&'static dyn FrameMethod,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.serialize_str(m.name())
}
