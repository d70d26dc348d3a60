//! Options shared by several commands: the frame (size, method, mode), the source of a
//! streamed scene, and the method argument built from the registry.

use std::path::PathBuf;

use anyhow::Result;
use bspvt_client::method::{FrameMethod, METHODS, registry};
use bspvt_client::render::renderer::Mode;
use bspvt_client::session::connect::ConnectOptions;
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
