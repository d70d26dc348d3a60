//! `bspvt report`: error against run time for every method, on real scenes, against ground
//! truth — the table a user chooses a method by.
//!
//! Per scene ([`scene::measure`]): a converged Monte Carlo ground truth (cached), the bakes
//! (cached, with their cost), then every method at its settings — BSPVT (face resolution, ε,
//! per-vertex and per-pixel), unshadowed LTC, Monte Carlo shadow rays, the ratio estimator of
//! stochastic shadows with and without denoising, LTC with ray-traced visibility (the error
//! budget's middle point) and the point-light shadow methods — each timed in the same run and
//! measured against the ground truth ([`crate::compare::metrics`]). [`analysis`] derives the
//! equal-time comparison and the error budget; [`write`], [`plot`] and [`grid`] write
//! `report.md`, `results.csv`, the log-log plots and the image grids.

pub(crate) mod analysis;
pub(crate) mod env;
pub(crate) mod grid;
pub(crate) mod plot;
pub(crate) mod scene;
pub(crate) mod write;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use serde::Serialize;

use crate::bench::{file_stem, load_named_scene, named_scene_path};

/// `bspvt report`: error against run time of every method on real scenes.
#[derive(clap::Args, Clone, Debug)]
pub struct ReportArgs {
    /// Scenes: built-in names (plate, plate-small, room, two-lamps, punctual-room), shared meshes (teapot,
    /// bunny, dragon, or a file name in the meshes folder such as bunny_res3.ply), or paths to
    /// a mesh or scene JSON [default: plate,teapot,bunny,room,two-lamps; with --quick:
    /// plate-small,teapot,bunny_res3.ply,room]
    #[arg(long, value_delimiter = ',')]
    pub scenes: Vec<String>,
    /// The smoke-test report: smaller images, scenes and sample counts (minutes, for CI).
    #[arg(long)]
    pub quick: bool,
    /// Image width and height [default: 256; 96 with --quick].
    #[arg(long)]
    pub size: Option<u32>,
    /// Timed renders of each fast method; the median is reported [default: 5; 3 with --quick].
    #[arg(long)]
    pub frames: Option<usize>,
    /// Folder holding the meshes (default: $BSPVT_ASSETS/meshes or ../shared/assets/meshes).
    #[arg(long)]
    pub meshes_dir: Option<PathBuf>,
    /// Environment map for the spherical-Gaussian methods [default:
    /// env/royal_esplanade_1k.hdr under $BSPVT_ASSETS or ../shared/assets].
    #[arg(long)]
    pub env: Option<PathBuf>,
    /// Leave out environment lighting.
    #[arg(long)]
    pub no_env: bool,
    /// Where ground truths and bakes are cached [default: DIR/cache].
    #[arg(long)]
    pub cache: Option<PathBuf>,
    /// Output folder: report.md, results.csv, results.json, plots and image grids.
    #[arg(long)]
    pub out: PathBuf,
}

/// What a run measures, resolved from [`ReportArgs`].
#[derive(Clone, Debug, Serialize)]
pub struct Settings {
    pub(crate) quick: bool,
    pub(crate) size: u32,
    pub(crate) frames: usize,
    /// Ground truth: per-pixel relative standard error target, first and last sample counts.
    pub(crate) gt_target_rel_stderr: f64,
    pub(crate) gt_min_spp: u32,
    pub(crate) gt_max_spp: u32,
    /// LTC with ray-traced visibility: shadow rays per pixel of each of its two estimates.
    pub(crate) exact_spp: u32,
    /// Sample counts of the stochastic methods.
    pub spp: Vec<u32>,
    /// Bakes: (face resolution, ε).
    pub(crate) bakes: Vec<(u32, f32)>,
    /// Radius in pixels of the ratio estimator's edge-aware denoiser.
    pub denoise_radius: f64,
    /// Environment lighting: the map (`None`: left out), lobe counts, ground-truth spp and
    /// the Monte Carlo sample counts.
    pub(crate) env_map: Option<PathBuf>,
    pub(crate) env_lobes: Vec<usize>,
    /// `bspvt-env`: pieces per cube-face side, one entry each.
    pub(crate) env_sky_pieces: Vec<u32>,
    pub(crate) env_gt_spp: u32,
    pub(crate) env_spp: Vec<u32>,
}

impl Settings {
    pub(crate) fn from_args(a: &ReportArgs) -> Result<Settings> {
        let q = a.quick;
        let size = a.size.unwrap_or(if q { 96 } else { 256 });
        if !(8..=4096).contains(&size) {
            bail!("--size {size}: expected 8 ..= 4096");
        }
        let frames = a.frames.unwrap_or(if q { 3 } else { 5 });
        if frames == 0 {
            bail!("--frames must be at least 1");
        }
        Ok(Settings {
            quick: q,
            size,
            frames,
            gt_target_rel_stderr: if q { 0.02 } else { 0.005 },
            gt_min_spp: if q { 64 } else { 256 },
            gt_max_spp: if q { 1024 } else { 16384 },
            exact_spp: if q { 256 } else { 2048 },
            spp: if q {
                vec![1, 4, 16, 64]
            } else {
                vec![1, 4, 16, 64, 256]
            },
            bakes: if q {
                vec![(32, 1e-3), (64, 1e-3)]
            } else {
                vec![(32, 1e-3), (64, 1e-2), (64, 1e-3), (128, 1e-3)]
            },
            denoise_radius: 4.0,
            env_map: None,
            env_lobes: if q { vec![16] } else { vec![16, 32] },
            env_sky_pieces: if q { vec![1, 2, 4] } else { vec![1, 2, 4, 8] },
            env_gt_spp: if q { 256 } else { 2048 },
            env_spp: if q {
                vec![1, 4, 16]
            } else {
                vec![1, 4, 16, 64]
            },
        })
    }

    /// The default bake of the error budget: 64² at ε = 10⁻³ when measured, else the first.
    pub(crate) fn budget_bake(&self) -> (u32, f32) {
        self.bakes
            .iter()
            .copied()
            .find(|&(r, e)| r == 64 && e == 1e-3)
            .or_else(|| self.bakes.first().copied())
            .unwrap_or((64, 1e-3))
    }
}

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// The settings it ran with.
    pub settings: Settings,
    /// Worker threads.
    pub threads: usize,
    /// Every scene measured.
    pub scenes: Vec<scene::SceneReport>,
    /// Scenes skipped (missing assets), with the reason.
    pub skipped: Vec<String>,
    /// Wall time of the whole run (seconds).
    pub seconds: f64,
}

/// Runs the report and writes everything under `a.out`.
pub fn run(a: &ReportArgs) -> Result<Report> {
    let start = Instant::now();
    let mut settings = Settings::from_args(a)?;
    let mut skipped = Vec::new();
    if !a.no_env {
        let map = a
            .env
            .clone()
            .unwrap_or_else(bspvt_client::envmap::default_env_path);
        if map.is_file() {
            settings.env_map = Some(map);
        } else if a.env.is_some() {
            bail!("--env {}: no such file", map.display());
        } else {
            let msg = format!(
                "environment lighting: {} not found, left out (set --env or BSPVT_ASSETS)",
                map.display()
            );
            eprintln!("report: {msg}");
            skipped.push(msg);
        }
    }
    let meshes_dir = a
        .meshes_dir
        .clone()
        .unwrap_or_else(bspvt_proto::paths::meshes_dir);
    let cache = a.cache.clone().unwrap_or_else(|| a.out.join("cache"));
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let names: Vec<String> = if a.scenes.iter().any(|s| !s.is_empty()) {
        a.scenes.iter().filter(|s| !s.is_empty()).cloned().collect()
    } else if settings.quick {
        vec![
            "plate-small".into(),
            "teapot".into(),
            "bunny_res3.ply".into(),
            "room".into(),
        ]
    } else {
        vec![
            "plate".into(),
            "teapot".into(),
            "bunny".into(),
            "room".into(),
            "two-lamps".into(),
            "punctual-room".into(),
        ]
    };
    let mut report = Report {
        settings: settings.clone(),
        threads: rayon::current_num_threads(),
        scenes: Vec::new(),
        skipped,
        seconds: 0.0,
    };
    for name in &names {
        let Some(s) = load_named_scene(name, &meshes_dir)? else {
            let msg = format!(
                "{name}: {} not found, skipped (set --meshes-dir or BSPVT_ASSETS)",
                named_scene_path(name, &meshes_dir).display()
            );
            eprintln!("report: {msg}");
            report.skipped.push(msg);
            continue;
        };
        eprintln!("report: {name} …");
        let t = Instant::now();
        let mut sr = scene::measure(name, &s, &settings, &cache, &a.out)?;
        let stem = file_stem(name);
        match plot::plots(&sr, &a.out.join(&stem)) {
            Ok(paths) => {
                sr.plots = paths
                    .iter()
                    .filter_map(|p| p.strip_prefix(&a.out).ok())
                    .map(|p| p.to_string_lossy().into_owned())
                    .collect();
            }
            Err(e) => {
                let msg = format!("{name}: plots not drawn: {e:#}");
                eprintln!("report: {msg}");
                report.skipped.push(msg);
            }
        }
        eprintln!("report: {name} done in {:.1} s", t.elapsed().as_secs_f64());
        report.scenes.push(sr);
    }
    report.seconds = start.elapsed().as_secs_f64();
    write::write_all(&report, &a.out)?;
    Ok(report)
}
