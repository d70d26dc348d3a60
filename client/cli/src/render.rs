//! `bspvt render`: images of a scene with any registered method, one frame or a sequence
//! while the light moves; bakes the trees first (cached) when the method needs them.

use std::path::PathBuf;

use anyhow::{Context, Result};
use bspvt_client::frame::image::Image;
use bspvt_client::method::Settings;
use bspvt_client::method::sequence::{Options, render_sequence};
use bspvt_client::method::trees::bakes_for;
use bspvt_client::render::renderer::{Mode, Trees};

use crate::frame_args::{EnvArgs, method, method_values};
use crate::progress::progress_bar;

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum RenderMode {
    Vertex,
    Pixel,
    /// Both, side by side (vertex left, pixel right).
    Both,
}

#[derive(clap::Args)]
pub(crate) struct RenderArgs {
    /// Scene file (JSON) or `builtin:NAME`.
    scene: Option<String>,
    /// A bare mesh (.glb/.gltf/.obj/.ply) with the default scene around it.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Bake file of this scene (`bspvt-server bake`). A method that needs trees and is given
    /// none bakes them once, cached in --cache by the scene's hash.
    #[arg(long)]
    trees: Option<PathBuf>,
    /// Where bakes made for methods that need trees are kept (by the scene's hash).
    #[arg(long, default_value = "out/cache/bakes")]
    cache: PathBuf,
    /// Rendering method (`bspvt methods` lists them with what they need).
    #[arg(long, default_value = "bspvt", value_parser = method_values())]
    method: String,
    #[arg(long, value_enum, default_value = "vertex")]
    mode: RenderMode,
    #[command(flatten)]
    backend: crate::frame_args::BackendArgs,
    /// Samples per pixel (mc, ltc-exact).
    #[arg(long, default_value_t = 64)]
    spp: u32,
    /// `--method rt-penumbra`: where the blur of the one ray per pixel reaches, cast N × N rays
    /// toward the light's parts (docs/penumbra.md, "The light split"); 1: paper 003 as
    /// published, one ray toward the light's centroid everywhere.
    #[arg(long, default_value_t = bspvt_client::penumbra::DEFAULT_SPLIT as u32,
          value_parser = clap::value_parser!(u32).range(1..=8))]
    penumbra_split: u32,
    /// `--method rt-penumbra`: how many pixels the split region may grow past the one ray's
    /// blur, where the split fractions at its edge still differ from the one ray's (docs/
    /// penumbra.md, "The light split"); 0: the one ray's blur's reach only.
    #[arg(long, default_value_t = bspvt_client::penumbra::Params::default().grow as u32,
          value_parser = clap::value_parser!(u32).range(0..=4096))]
    penumbra_grow: u32,
    /// `--method rt-penumbra`: where the penumbra is wide (the one ray's blur reaches 8 pixels
    /// or more, and where the split region grows), cast N × N rays toward the light's parts on
    /// every `--penumbra-sparse-step`-th pixel and interpolate between (docs/penumbra.md, "The
    /// wide split"); N ≤ `--penumbra-split`: the split everywhere, every pixel cast.
    #[arg(long, default_value_t = bspvt_client::penumbra::DEFAULT_WIDE_SPLIT as u32,
          value_parser = clap::value_parser!(u32).range(1..=8))]
    penumbra_wide_split: u32,
    /// `--method rt-penumbra`: the wide split's grid spacing in pixels (1: every pixel casts).
    #[arg(long, default_value_t = bspvt_client::penumbra::DEFAULT_SPARSE_STEP as u32,
          value_parser = clap::value_parser!(u32).range(1..=16))]
    penumbra_sparse_step: u32,
    #[arg(long, default_value_t = 512)]
    width: u32,
    /// Image height [default: the width over the scene camera's aspect ratio (a glTF camera's
    /// `aspectRatio`), else the width].
    #[arg(long)]
    height: Option<u32>,
    /// Frames along the light path; more than one writes OUT-000.png, OUT-001.png, …
    #[arg(long, default_value_t = 1)]
    frames: usize,
    /// Shade only this scene light (0-based) [default: every light, summed].
    #[arg(long)]
    light: Option<usize>,
    /// Output image: .png (tone-mapped) or .exr (linear).
    #[arg(long)]
    out: PathBuf,
    /// Exposure applied before tone mapping (PNG only).
    #[arg(long, default_value_t = 1.0)]
    exposure: f32,
    /// Write timings as JSON here.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    #[command(flatten)]
    env: EnvArgs,
    /// Turns the environment by this many degrees per frame (`--method bspvt-env`, with
    /// --frames): the sky rotating while the light moves.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    env_spin: f64,
}

/// `OUT` for one frame, `OUT-NNN.ext` for a sequence.
fn frame_path(out: &std::path::Path, k: usize, frames: usize) -> PathBuf {
    if frames <= 1 {
        return out.to_path_buf();
    }
    let stem = out.file_stem().and_then(|s| s.to_str()).unwrap_or("frame");
    let ext = out.extension().and_then(|s| s.to_str()).unwrap_or("png");
    out.with_file_name(format!("{stem}-{k:03}.{ext}"))
}

pub(crate) fn run(a: RenderArgs) -> Result<()> {
    anyhow::ensure!(a.env_spin.is_finite(), "--env-spin must be finite");
    let scene = bspvt_client::scene::open(a.scene.as_deref(), a.mesh.as_deref())?;
    let method = method(&a.method)?;
    let backend = a.backend.resolve()?;
    let label = a
        .scene
        .as_deref()
        .or(a.mesh.as_deref().and_then(|m| m.to_str()))
        .unwrap_or("scene");
    let bar = progress_bar();
    let (bake, sky_bake) = bakes_for(
        method,
        label,
        &scene,
        a.trees.as_deref(),
        &a.cache,
        &|done, total| {
            bar.set_length(total);
            bar.set_position(done);
        },
    )?;
    bar.finish_and_clear();
    let trees = bake
        .as_ref()
        .map(|b| Trees::full(&b.trees, b.header.codec()));
    let sky_trees = sky_bake
        .as_ref()
        .map(|b| Trees::full(&b.trees, b.header.codec()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .context("cannot start the worker threads")?;
    let modes: &[Mode] = match a.mode {
        RenderMode::Vertex => &[Mode::Vertex],
        RenderMode::Pixel => &[Mode::Pixel],
        RenderMode::Both => &[Mode::Vertex, Mode::Pixel],
    };
    let mut all_stats = Vec::new();
    let mut images: Vec<Vec<Image>> = Vec::new();
    for &mode in modes {
        let opts = Options {
            method,
            width: a.width,
            height: scene.camera.image_height(a.width, a.height),
            frames: a.frames,
            light: a.light,
            env_spin_deg: a.env_spin,
            settings: Settings {
                mode,
                spp: a.spp,
                env: a.env.options(&scene)?,
                backend,
                penumbra: bspvt_client::penumbra::Params {
                    split: a.penumbra_split as usize,
                    grow: f64::from(a.penumbra_grow),
                    wide_split: a.penumbra_wide_split as usize,
                    sparse_step: a.penumbra_sparse_step as usize,
                    ..Default::default()
                },
                ..Settings::default()
            },
        };
        let mut frames = Vec::new();
        let stats = pool.install(|| {
            render_sequence(
                &scene,
                trees.as_ref(),
                sky_trees.as_ref(),
                &opts,
                |k, img| {
                    if modes.len() == 1 {
                        img.save(&frame_path(&a.out, k, a.frames), a.exposure)
                    } else {
                        frames.push(img.clone());
                        Ok(())
                    }
                },
            )
        })?;
        // Per-vertex figures only where vertices were shaded (a per-pixel method shades none).
        let per_vertex = if stats.vertices_shaded > 0 {
            format!(
                "{:.3} µs/vertex ({:.3} per core, {} threads), {} vertices shaded",
                stats.us_per_vertex,
                stats.us_per_vertex_per_core,
                stats.threads,
                stats.vertices_shaded
            )
        } else {
            format!("{} threads", stats.threads)
        };
        println!(
            "{} {:?}: {} frame(s) at {}×{}, {:.2} ms/frame ({:.1} fps), {per_vertex}",
            stats.method.name(),
            stats.mode,
            stats.frames,
            stats.width,
            stats.height,
            stats.ms_per_frame,
            stats.fps,
        );
        all_stats.push(stats);
        images.push(frames);
    }
    if modes.len() == 2 {
        for (k, (v, p)) in images[0].iter().zip(&images[1]).enumerate() {
            side_by_side(v, p).save(&frame_path(&a.out, k, a.frames), a.exposure)?;
        }
    }
    println!("wrote {}", frame_path(&a.out, 0, a.frames).display());
    if let Some(p) = &a.stats {
        let json = if all_stats.len() == 1 {
            serde_json::to_string_pretty(&all_stats[0])?
        } else {
            serde_json::to_string_pretty(&all_stats)?
        };
        std::fs::write(p, json).with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}

fn side_by_side(a: &Image, b: &Image) -> Image {
    let mut out = Image::new(a.width + b.width, a.height.max(b.height));
    for y in 0..out.height as usize {
        for (img, x0) in [(a, 0usize), (b, a.width as usize)] {
            if y < img.height as usize {
                let w = img.width as usize;
                let row = &img.pixels[y * w..(y + 1) * w];
                let o = y * out.width as usize + x0;
                out.pixels[o..o + w].copy_from_slice(row);
            }
        }
    }
    out
}
