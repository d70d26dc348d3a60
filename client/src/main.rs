//! `bspvt`: the client's command line.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bspvt::render::image::Image;
use bspvt::render::renderer::{Mode, Trees};
use bspvt::render::sequence::{Method, Options, render_sequence};
use bspvt_proto::encoding::{Bake, decode_bake};
use bspvt_proto::scene::open_scene;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "bspvt", version, about = "bspvt client")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Decode a bake file, check it against its scene, and report (or export) light visibility.
    Inspect(InspectArgs),
    /// The main job: an embedded service bakes the built-in scene, the client streams its trees
    /// and shades while the light moves (a window if there is a display, else frames + GIF).
    Demo(bspvt::play::demo::DemoArgs),
    /// Open a window on a scene from a service (URL or id) or a local scene (baked by an
    /// embedded service), shading while its trees stream in.
    View(bspvt::play::view::ViewArgs),
    /// Headless: stream a scene and render the light moving along its path (PNG frames, GIF,
    /// stats.json), through the viewer's own code path.
    Animate(bspvt::play::animate::AnimateArgs),
    /// Measure a viewer's start on a finished bake served on loopback: time to the first
    /// frame and to full quality, bytes fetched, fps while the light moves.
    BenchView(bspvt::play::bench::BenchViewArgs),
    /// Run the baking service (the same as `bspvt-server serve`).
    Serve(bspvt_server::service::config::ServeArgs),
    /// Render images of a scene (one frame, or a sequence while the light moves) with BSPVT
    /// shadows, unshadowed LTC, the point-light shadow methods, SG environment lighting, or
    /// the Monte Carlo references.
    Render(RenderArgs),
    /// Measure shading speed on real meshes (kernel µs/vertex and frame times).
    Bench(bspvt::bench::BenchArgs),
    /// Speed and error of rt-penumbra (paper 003) and the shadow-map baselines against Monte
    /// Carlo area-light shadows (`ltc-exact`), with the equal-RMSE speed-up and cases that
    /// break the paper's assumptions (results.csv/.md/.json and images in --out).
    BenchPenumbra(bspvt::penumbra::bench::BenchPenumbraArgs),
    /// Error against run time of every method on real scenes, against converged Monte Carlo
    /// ground truth: report.md, results.csv, log-log plots and image grids in --out.
    Report(bspvt::report::ReportArgs),
    /// Speed and error of the spherical-Gaussian environment lighting (paper 001: screen-space
    /// and exact SSDF, unshadowed) against the Monte Carlo environment reference, per image
    /// size and lobe count (results.json/.md and images in --out).
    BenchSg(bspvt::sg::bench::BenchSgArgs),
    /// Fit the LTC table of GGX (regenerates `assets/ltc/ggx.json`).
    LtcFit(bspvt::ltc::fit::FitArgs),
    /// Write a Mitsuba 3 scene that renders the same image (independent cross-check).
    ExportMitsuba(bspvt::mitsuba::ExportArgs),
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ModeArg {
    Vertex,
    Pixel,
    /// Both, side by side (vertex left, pixel right).
    Both,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// Scene file (JSON) or `builtin:NAME`.
    scene: Option<String>,
    /// A bare mesh (.glb/.gltf/.obj/.ply) with the default scene around it.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Bake file of this scene (`bspvt-server bake`); required for `--method bspvt`.
    #[arg(long)]
    trees: Option<PathBuf>,
    #[arg(long, value_enum, default_value = "bspvt")]
    method: Method,
    #[arg(long, value_enum, default_value = "vertex")]
    mode: ModeArg,
    /// Samples per pixel (mc, ltc-exact).
    #[arg(long, default_value_t = 64)]
    spp: u32,
    #[arg(long, default_value_t = 512)]
    width: u32,
    #[arg(long, default_value_t = 512)]
    height: u32,
    /// Frames along the light path; more than one writes OUT-000.png, OUT-001.png, …
    #[arg(long, default_value_t = 1)]
    frames: usize,
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
    /// Environment map (equirectangular Radiance .hdr) for `--method sg` and `mc-env`
    /// [default: env/royal_esplanade_1k.hdr under BSPVT_ASSETS or ../shared/assets].
    #[arg(long)]
    env: Option<PathBuf>,
    /// Spherical Gaussians fitted to the map (`--method sg`).
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=256))]
    lobes: u32,
    /// How `--method sg` finds the spherical signed distance (visibility).
    #[arg(long, value_enum, default_value = "screen")]
    ssdf: bspvt::sg::SsdfMode,
    /// Side of the screen-space SSDF depth maps (`--ssdf screen`).
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u32).range(8..=4096))]
    depth_res: u32,
    /// SSDF sharing: search at one pixel per STRIDE×STRIDE block, reused by the block's pixels
    /// on the same surface (1: every pixel, the paper's).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=16))]
    ssdf_stride: u32,
    /// Screen SSDF: neighbourhood searched at each finer pyramid level (the paper's 6×6).
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(2..=16))]
    ssdf_window: u32,
}

#[derive(clap::Args)]
struct InspectArgs {
    /// Bake file written by `bspvt-server bake`.
    trees: PathBuf,
    /// The scene that was baked: scene file or builtin:NAME.
    #[arg(long)]
    scene: Option<String>,
    /// …or the bare mesh that was baked.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Write the mesh with per-vertex colours = visible fraction of light 0 (binary PLY).
    #[arg(long)]
    ply: Option<PathBuf>,
}

fn main() -> std::process::ExitCode {
    let result = match Cli::parse().command {
        Command::Inspect(a) => inspect(a),
        Command::Demo(a) => bspvt::play::demo::run(&a),
        Command::View(a) => bspvt::play::view::run(&a),
        Command::Animate(a) => bspvt::play::animate::run(&a),
        Command::BenchView(a) => bspvt::play::bench::run(&a),
        Command::Serve(a) => bspvt_server::service::serve_command(&a),
        Command::Render(a) => render(a),
        Command::Bench(a) => bspvt::bench::run(&a),
        Command::BenchPenumbra(a) => bspvt::penumbra::bench::run(&a).map(|r| {
            eprintln!(
                "bench-penumbra: {} case(s) written to {}",
                r.cases.len(),
                a.out.display()
            );
        }),
        Command::Report(a) => bspvt::report::run(&a).map(|r| {
            eprintln!(
                "report: {} scene(s) in {:.0} s, written to {}",
                r.scenes.len(),
                r.seconds,
                a.out.join("report.md").display()
            );
        }),
        Command::BenchSg(a) => bspvt::sg::bench::run(&a).map(|r| {
            eprintln!(
                "bench-sg: {} configuration(s) written to {}",
                r.rows.len(),
                a.out.display()
            );
        }),
        Command::LtcFit(a) => bspvt::ltc::fit::run(&a),
        Command::ExportMitsuba(a) => bspvt::mitsuba::run(&a),
    };
    bspvt_proto::error::exit_code(result)
}

/// Reads a bake file and checks it belongs to `scene`.
fn load_trees(path: &std::path::Path, scene: &bspvt_proto::Scene) -> Result<Bake> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let bake =
        decode_bake(&bytes).with_context(|| format!("{} is not a valid bake", path.display()))?;
    if bake.header.mesh_hash != scene.mesh.content_hash()
        || bake.trees.len() != scene.mesh.vertex_count()
    {
        bail!(
            "{} was baked from a different mesh than this scene's ({} vertices in the bake, {} in the scene)",
            path.display(),
            bake.trees.len(),
            scene.mesh.vertex_count()
        );
    }
    Ok(bake)
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

fn render(a: RenderArgs) -> Result<()> {
    let scene = open_scene(a.scene.as_deref(), a.mesh.as_deref())?;
    let bake = match &a.trees {
        Some(p) => Some(load_trees(p, &scene)?),
        None => None,
    };
    let trees = bake
        .as_ref()
        .map(|b| Trees::full(&b.trees, b.header.codec()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .context("cannot start the worker threads")?;
    let modes: &[Mode] = match a.mode {
        ModeArg::Vertex => &[Mode::Vertex],
        ModeArg::Pixel => &[Mode::Pixel],
        ModeArg::Both => &[Mode::Vertex, Mode::Pixel],
    };
    let mut all_stats = Vec::new();
    let mut images: Vec<Vec<Image>> = Vec::new();
    for &mode in modes {
        let opts = Options {
            method: a.method,
            mode,
            spp: a.spp,
            width: a.width,
            height: a.height,
            frames: a.frames,
            light: 0,
            env: a
                .method
                .is_env()
                .then(|| bspvt::render::sequence::EnvOptions {
                    path: a
                        .env
                        .clone()
                        .unwrap_or_else(bspvt::sg::env::default_env_path),
                    lobes: a.lobes as usize,
                    sg: bspvt::sg::SgOptions {
                        ssdf: a.ssdf,
                        depth_res: a.depth_res,
                        stride: a.ssdf_stride,
                        window: a.ssdf_window,
                    },
                }),
        };
        let mut frames = Vec::new();
        let stats = pool.install(|| {
            render_sequence(&scene, trees.as_ref(), &opts, |k, img| {
                if modes.len() == 1 {
                    img.save(&frame_path(&a.out, k, a.frames), a.exposure)
                } else {
                    frames.push(img.clone());
                    Ok(())
                }
            })
        })?;
        println!(
            "{:?} {:?}: {} frame(s) at {}×{}, {:.2} ms/frame ({:.1} fps), {:.3} µs/vertex ({:.3} per core, {} threads), {} vertices shaded",
            stats.method,
            stats.mode,
            stats.frames,
            stats.width,
            stats.height,
            stats.ms_per_frame,
            stats.fps,
            stats.us_per_vertex,
            stats.us_per_vertex_per_core,
            stats.threads,
            stats.vertices_shaded
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

fn inspect(a: InspectArgs) -> Result<()> {
    let bytes =
        std::fs::read(&a.trees).with_context(|| format!("cannot read {}", a.trees.display()))?;
    let bake = decode_bake(&bytes)
        .with_context(|| format!("{} is not a valid bake", a.trees.display()))?;
    let h = &bake.header;
    let leaves: usize = bake.trees.iter().map(|t| t.leaf_count()).sum();
    let n = bake.trees.len().max(1) as f64;
    println!(
        "{}: {} vertices, {}² faces, ε = {}, {} bytes ({:.1} B/vertex), {:.1} leaves/vertex",
        a.trees.display(),
        h.vertex_count,
        h.face_res,
        h.epsilon,
        bytes.len(),
        bytes.len() as f64 / n,
        leaves as f64 / n
    );
    if a.scene.is_none() && a.mesh.is_none() {
        return Ok(());
    }
    let scene = open_scene(a.scene.as_deref(), a.mesh.as_deref())?;
    if scene.mesh.content_hash() != h.mesh_hash {
        bail!("the bake was made from a different mesh than this scene's");
    }
    let frac = bspvt::visibility::visible_fractions(&scene, 0, &h.codec(), &bake.trees);
    let seen: Vec<f64> = frac.iter().flatten().copied().collect();
    let shadowed = seen.iter().filter(|&&f| f < 0.999).count();
    let umbra = seen.iter().filter(|&&f| f < 0.001).count();
    println!(
        "light 0: {} vertices see it, {} in (partial) shadow, {} in umbra",
        seen.len(),
        shadowed,
        umbra
    );
    if let Some(p) = &a.ply {
        write_ply(p, &scene.mesh, &frac)?;
        println!("wrote {}", p.display());
    }
    Ok(())
}

/// Binary PLY with vertex colours: grey = visible fraction, dark blue = cannot see the light.
fn write_ply(path: &PathBuf, mesh: &bspvt_proto::Mesh, frac: &[Option<f64>]) -> Result<()> {
    let mut out = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?,
    );
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangles.len()
    )?;
    for (p, f) in mesh.positions.iter().zip(frac) {
        for c in p.to_array() {
            out.write_all(&c.to_le_bytes())?;
        }
        let rgb = match f {
            Some(f) => [(f * 255.0).round() as u8; 3],
            None => [10, 10, 60],
        };
        out.write_all(&rgb)?;
    }
    for t in &mesh.triangles {
        out.write_all(&[3])?;
        for i in t {
            out.write_all(&i.to_le_bytes())?;
        }
    }
    Ok(())
}
