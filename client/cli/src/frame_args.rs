//! Options shared by several commands: the frame (size, method, mode), the source of a
//! streamed scene, and the method argument built from the registry.

use std::path::PathBuf;

use anyhow::Result;
use bspvt_client::method::{EnvOptions, FrameMethod, METHODS, registry};
use bspvt_client::render::renderer::Mode;
use bspvt_client::session::connect::ConnectOptions;
use bspvt_client::sg::{SgOptions, SsdfMode};
use bspvt_proto::Scene;
use clap::builder::{PossibleValue, PossibleValuesParser};

/// `--method`'s accepted values, each with its description: read from the registry.
pub(crate) fn method_values() -> PossibleValuesParser {
    PossibleValuesParser::new(
        METHODS
            .iter()
            .map(|m| PossibleValue::new(m.name()).help(m.description())),
    )
}

/// The registered method called `name` (the parser already checked it).
pub(crate) fn method(name: &str) -> Result<&'static dyn FrameMethod> {
    registry::lookup(name)
}

/// Frame size, method and mode: what `view` and `animate` share.
#[derive(clap::Args, Clone, Debug)]
pub(crate) struct FrameArgs {
    #[arg(long, default_value_t = 512)]
    pub(crate) width: u32,
    /// Image height [default: the width over the scene camera's aspect ratio (a glTF camera's
    /// `aspectRatio`), else the width].
    #[arg(long)]
    pub(crate) height: Option<u32>,
    /// Rendering method (`bspvt methods` lists them with what they need).
    #[arg(long, default_value = "bspvt", value_parser = method_values())]
    pub(crate) method: String,
    #[arg(long, value_enum, default_value = "vertex")]
    pub(crate) mode: ModeArg,
    #[command(flatten)]
    pub(crate) env: EnvArgs,
    #[command(flatten)]
    pub(crate) backend: BackendArgs,
}

/// Who draws `bspvt` and `ltc` frames: `render`, `animate`, `demo`, `view`.
#[derive(clap::Args, Clone, Debug)]
pub(crate) struct BackendArgs {
    /// `auto`: a hardware GPU when there is one (its name is printed), else the CPU; `cpu` (the
    /// reference); `gpu` (wgpu: Vulkan, Metal, DX12; lavapipe on Linux without a GPU). The GPU's
    /// frames equal the CPU's within docs/gpu.md's tolerance. Methods other than bspvt and ltc
    /// draw on the CPU whatever this says.
    #[arg(long, default_value = "auto", value_parser = ["auto", "gpu", "cpu"])]
    pub(crate) backend: String,
}

impl BackendArgs {
    /// The backend to hand the methods (`auto` resolved), with a line saying which it is.
    pub(crate) fn resolve(&self) -> Result<bspvt_client::gpu::Backend> {
        let b: bspvt_client::gpu::Backend = self.backend.parse()?;
        let (gpu, line) = b.resolve()?;
        eprintln!("{line}");
        Ok(if gpu.is_some() {
            bspvt_client::gpu::Backend::Gpu
        } else {
            bspvt_client::gpu::Backend::Cpu
        })
    }
}

/// The environment light of the environment methods (`sg`, `mc-env`, `bspvt-env`).
#[derive(clap::Args, Clone, Debug)]
pub(crate) struct EnvArgs {
    /// Environment map (equirectangular Radiance .hdr or .exr) [default: the scene's
    /// `environment`, else env/royal_esplanade_1k.hdr under BSPVT_ASSETS or ../shared/assets].
    #[arg(long)]
    pub(crate) env: Option<PathBuf>,
    /// Rotation of the map about +y, degrees [default: the scene's, else 0].
    #[arg(long, allow_hyphen_values = true)]
    pub(crate) env_rotation: Option<f64>,
    /// Multiplies the map's radiance [default: the scene's, else 1].
    #[arg(long)]
    pub(crate) env_strength: Option<f64>,
    /// `--method bspvt-env`: pieces per cube-face side (6·k² textured quad lights).
    #[arg(long, default_value_t = bspvt_client::sky::DEFAULT_K,
          value_parser = clap::value_parser!(u32).range(1..=i64::from(bspvt_client::sky::MAX_K)))]
    pub(crate) sky_pieces: u32,
    /// `--method bspvt-env --mode vertex`: the sky in world-fixed cells of B latitude bands ×
    /// 2B sectors, cut by the trees once per vertex, so that a turning map costs two dot
    /// products per vertex a frame; 0: the pieces every frame (as per pixel, and for a map
    /// with a sun).
    #[arg(long, default_value_t = bspvt_client::sky_cells::DEFAULT_BANDS,
          value_parser = clap::value_parser!(u32).range(0..=i64::from(bspvt_client::sky_cells::MAX_BANDS)))]
    pub(crate) sky_cells: u32,
    /// Spherical Gaussians fitted to the map (`--method sg`).
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub(crate) lobes: u32,
    /// How `--method sg` finds the spherical signed distance (visibility).
    #[arg(long, value_enum, default_value = "screen")]
    pub(crate) ssdf: SsdfArg,
    /// Side of the screen-space SSDF depth maps (`--ssdf screen`).
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u32).range(8..=4096))]
    pub(crate) depth_res: u32,
    /// SSDF sharing: search at one pixel per STRIDE×STRIDE block, reused by the block's pixels
    /// on the same surface (1: every pixel, the paper's).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub(crate) ssdf_stride: u32,
    /// Screen SSDF: neighbourhood searched at each finer pyramid level (the paper's 6×6).
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(2..=16))]
    pub(crate) ssdf_window: u32,
}

impl EnvArgs {
    /// The options for `scene`: flags over the scene's `environment` over the defaults.
    pub(crate) fn options(&self, scene: &Scene) -> Result<EnvOptions> {
        let mut o = EnvOptions {
            lobes: self.lobes as usize,
            pieces: self.sky_pieces,
            cells: self.sky_cells,
            sg: SgOptions {
                ssdf: self.ssdf.into(),
                depth_res: self.depth_res,
                stride: self.ssdf_stride,
                window: self.ssdf_window,
            },
            ..EnvOptions::default()
        }
        .for_scene(scene);
        if let Some(p) = &self.env {
            o.path = p.clone();
        }
        if let Some(r) = self.env_rotation {
            anyhow::ensure!(r.is_finite(), "--env-rotation must be finite");
            o.rotation_deg = r;
        }
        if let Some(k) = self.env_strength {
            anyhow::ensure!(
                k.is_finite() && k >= 0.0,
                "--env-strength must be finite and ≥ 0"
            );
            o.strength = k;
        }
        Ok(o)
    }
}

/// `--ssdf`: how `--method sg` finds its visibility.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum SsdfArg {
    /// The paper's: a depth map per lighting lobe with a MIN/MAX pyramid, coarse-to-fine.
    Screen,
    /// Ray-cast search around each lobe axis with the BVH (reference; slow).
    Exact,
    /// No occluders (horizon only): unshadowed SG shading.
    None,
}

impl From<SsdfArg> for SsdfMode {
    fn from(s: SsdfArg) -> SsdfMode {
        match s {
            SsdfArg::Screen => SsdfMode::Screen,
            SsdfArg::Exact => SsdfMode::Exact,
            SsdfArg::None => SsdfMode::None,
        }
    }
}

/// `--mode` of the streaming commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ModeArg {
    /// Per-vertex shading interpolated over triangles (the paper's).
    Vertex,
    /// Unshadowed LTC per pixel × the interpolated per-vertex shadow ratio.
    Pixel,
}

impl From<ModeArg> for Mode {
    fn from(m: ModeArg) -> Mode {
        match m {
            ModeArg::Vertex => Mode::Vertex,
            ModeArg::Pixel => Mode::Pixel,
        }
    }
}

/// Where to find the scene and where to keep things.
#[derive(clap::Args, Clone, Debug)]
pub(crate) struct ConnectArgs {
    /// `http://HOST:PORT/v1/scenes/ID`, a scene id (with --server), a scene file or builtin:NAME.
    pub(crate) source: Option<String>,
    /// A bare mesh (.glb/.gltf/.obj/.ply) with the default scene around it.
    #[arg(long)]
    pub(crate) mesh: Option<PathBuf>,
    /// Service for scene ids and local scenes (default for local scenes: an embedded service).
    #[arg(long, env = "BSPVT_SERVER")]
    pub(crate) server: Option<String>,
    #[arg(long, env = "BSPVT_API_KEY")]
    pub(crate) api_key: Option<String>,
    /// Data folder of the embedded service.
    #[arg(long, default_value = "out/service")]
    pub(crate) data_dir: PathBuf,
    /// Where received trees are cached (by scene id).
    #[arg(long, default_value = "out/cache")]
    pub(crate) cache_dir: PathBuf,
    /// Do not use or fill the cache.
    #[arg(long)]
    pub(crate) no_cache: bool,
}

impl ConnectArgs {
    /// The library's options, with this build's embedded service.
    pub(crate) fn options(&self) -> ConnectOptions {
        ConnectOptions {
            source: self.source.clone(),
            mesh: self.mesh.clone(),
            server: self.server.clone(),
            api_key: self.api_key.clone(),
            data_dir: self.data_dir.clone(),
            cache_dir: (!self.no_cache).then(|| self.cache_dir.clone()),
            embedded: crate::embedded::EMBEDDED,
        }
    }
}
