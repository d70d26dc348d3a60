//! The streaming front ends: `bspvt view` (a window), `bspvt animate` (headless frames) and
//! `bspvt demo` (the README's main command). All three connect through
//! [`crate::stream::connect`] and draw through [`crate::session::Session::frame`], so what a
//! script writes is what the window shows.

pub mod animate;
pub mod bench;
pub mod demo;
pub mod gif;
pub mod view;

use crate::render::renderer::Mode;
use crate::session::ViewMethod;

/// Frame size, method and mode: what `view` and `animate` share.
#[derive(clap::Args, Clone, Debug)]
pub struct FrameArgs {
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    #[arg(long, default_value_t = 512)]
    pub height: u32,
    #[arg(long, value_enum, default_value = "bspvt")]
    pub method: ViewMethod,
    #[arg(long, value_enum, default_value = "vertex")]
    pub mode: ModeArg,
}

/// `--mode` of the streaming commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
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
