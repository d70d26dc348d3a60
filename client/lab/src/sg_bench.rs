//! `bspvt bench-sg`: frame time and error of the SG renderer (screen-space and exact SSDF,
//! and unshadowed) against the Monte Carlo environment-light reference, per image size and
//! lobe count. Writes `results.json` and `results.md` (and the images) to `--out`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use bspvt_proto::scene::open_scene;
use bspvt_raytrace::{Occluder, mesh_triangles};
use serde::Serialize;

use bspvt_client::envmap::EnvLight;
use bspvt_client::frame::image::Image;
use bspvt_client::groundtruth::render_mc_env;
use bspvt_client::render::posed::Posed;
use bspvt_client::render::renderer::Renderer;
use bspvt_client::sg::{self, SgEnv, SgOptions, SsdfMode, fit};

/// `bspvt bench-sg`: speed and error of SG environment lighting against its Monte Carlo reference.
#[derive(clap::Args, Clone, Debug)]
pub struct BenchSgArgs {
    /// Scene file or builtin:NAME [default: builtin:plate].
    pub(crate) scene: Option<String>,
    /// A bare mesh with the default scene around it (instead of SCENE).
    #[arg(long)]
    pub(crate) mesh: Option<PathBuf>,
    /// Environment map [default: env/royal_esplanade_1k.hdr under BSPVT_ASSETS or
    /// ../shared/assets].
    #[arg(long)]
    pub(crate) env: Option<PathBuf>,
    /// Image sides.
    #[arg(long, value_delimiter = ',', default_values_t = vec![256u32, 512])]
    pub(crate) sizes: Vec<u32>,
    /// Lobe counts.
    #[arg(long, value_delimiter = ',', default_values_t = vec![16usize, 32])]
    pub(crate) lobes: Vec<usize>,
    /// Timed frames per configuration (median reported; the exact SSDF runs once).
    #[arg(long, default_value_t = 5)]
    pub(crate) frames: usize,
    /// Monte Carlo samples per pixel of the reference.
    #[arg(long, default_value_t = 256)]
    pub(crate) spp: u32,
    /// Side of the screen-space depth maps.
    #[arg(long, default_value_t = 128)]
    pub(crate) depth_res: u32,
    /// SSDF sharing stride (1: search at every pixel, the paper's).
    #[arg(long, default_value_t = 2)]
    pub(crate) stride: u32,
    /// Neighbourhood of the screen-space search at each finer level (the paper's 6).
    #[arg(long, default_value_t = 6)]
    pub(crate) window: u32,
    /// Skip the exact SSDF above this image side (it is slow).
    #[arg(long, default_value_t = 256)]
    pub(crate) exact_max_size: u32,
    /// Output folder.
    #[arg(long, default_value = "bench-sg")]
    pub out: PathBuf,
    /// Exposure of the PNGs.
    #[arg(long, default_value_t = 1.0)]
    pub(crate) exposure: f32,
    /// Cycle time at which a moving scene is measured (its meshes frozen there). A moving
    /// scene also gets a `moving` row per size and K: screen-space frames along the cycle
    /// from this time, each re-posed and re-rasterised inside its time.
    #[arg(long, default_value_t = 0.0)]
    pub(crate) time: f32,
}

/// One measured configuration.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub(crate) size: u32,
    pub(crate) lobes: usize,
    pub(crate) ssdf: SsdfMode,
    /// Median frame time, ms.
    pub ms_per_frame: f64,
    pub(crate) fps: f64,
    pub(crate) maps_ms: f64,
    /// RMSE over covered pixels and channels against the reference, absolute and relative to
    /// the reference's mean.
    pub rmse: f64,
    pub(crate) rel_rmse: f64,
    /// RMSE against the exact-SSDF image of the same configuration (screen mode only).
    pub(crate) rmse_vs_exact: Option<f64>,
    /// Frames along a moving scene's cycle (posing, G-buffer and depth maps every frame);
    /// the error is that of the frame at `--time`.
    pub(crate) moving: bool,
    /// Posing and rasterising, median per frame (moving rows), ms.
    pub(crate) pose_ms: Option<f64>,
}

/// What `bspvt bench-sg` measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub(crate) scene: String,
    pub(crate) env: String,
    pub(crate) threads: usize,
    pub(crate) fits: Vec<FitRow>,
    pub(crate) references: Vec<RefRow>,
    /// One row per image size, lobe count and SSDF mode.
    pub rows: Vec<Row>,
}

#[derive(Clone, Debug, Serialize)]
pub(crate) struct FitRow {
    pub(crate) lobes: usize,
    pub(crate) fit_error: f64,
    pub(crate) seconds: f64,
}

#[derive(Clone, Debug, Serialize)]
pub(crate) struct RefRow {
    pub(crate) size: u32,
    pub(crate) spp: u32,
    pub(crate) seconds: f64,
    pub(crate) mean_rel_stderr: f64,
    /// RMS of the per-pixel standard error (the noise floor of the RMSE numbers).
    pub(crate) rms_stderr: f64,
}

/// RMSE over the pixels not black in both images (the background is left out).
fn rmse(a: &Image, b: &Image) -> f64 {
    bspvt_client::frame::stats::rmse(a, b, |i| a.pixels[i] != [0.0; 3] || b.pixels[i] != [0.0; 3])
}

fn median(mut v: Vec<f64>) -> f64 {
    bspvt_client::frame::stats::median(&mut v)
}

/// Runs `bspvt bench-sg` and writes results.json/.md and images.
pub fn run(a: &BenchSgArgs) -> Result<Report> {
    let scene_name = a.scene.clone().unwrap_or_else(|| "builtin:plate".into());
    let moving_scene = if a.mesh.is_some() {
        open_scene(None, a.mesh.as_deref())?
    } else {
        open_scene(Some(&scene_name), None)?
    };
    if !(a.time.is_finite() && (0.0..=1.0).contains(&a.time)) {
        anyhow::bail!("--time {} is outside the cycle [0, 1]", a.time);
    }
    // Everything but the moving rows sees the meshes frozen at --time.
    let scene = moving_scene.at(a.time);
    let env_path = a
        .env
        .clone()
        .unwrap_or_else(bspvt_client::envmap::default_env_path);
    let env = EnvLight::load(&env_path)?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let tris = mesh_triangles(&scene.mesh);
    let occ = Occluder::new(&scene.mesh, &tris)
        .cut_out(bspvt_raytrace::Cutouts::of(&scene.mesh, &scene.materials));
    sg::halfspace::warm_up();
    let mut report = Report {
        scene: a
            .mesh
            .as_ref()
            .map_or(scene_name.clone(), |m| m.display().to_string()),
        env: env_path.display().to_string(),
        threads: rayon::current_num_threads(),
        fits: Vec::new(),
        references: Vec::new(),
        rows: Vec::new(),
    };
    let mut fits = Vec::new();
    for &k in &a.lobes {
        let f = fit(&env, k);
        println!(
            "fit K={k}: relative L2 {:.4} over the sphere, {:.2} s",
            f.fit_error, f.seconds
        );
        report.fits.push(FitRow {
            lobes: k,
            fit_error: f.fit_error,
            seconds: f.seconds,
        });
        fits.push((k, f));
    }
    for &size in &a.sizes {
        let r = Renderer::new(&scene, size, size);
        let t = Instant::now();
        let (reference, noise) = render_mc_env(&scene, &r.view, &r.gbuffer, &env, &occ, a.spp, 1);
        let ref_s = t.elapsed().as_secs_f64();
        let rms_se = {
            let px = &noise.stderr.pixels;
            let s: f64 = px
                .iter()
                .flatten()
                .map(|&c| f64::from(c) * f64::from(c))
                .sum();
            (s / (3 * noise.covered.max(1)) as f64).sqrt()
        };
        println!("{size}²: reference {} spp in {ref_s:.1} s ({noise})", a.spp);
        reference.save(&a.out.join(format!("mc-env-{size}.png")), a.exposure)?;
        reference.save(&a.out.join(format!("mc-env-{size}.exr")), 1.0)?;
        report.references.push(RefRow {
            size,
            spp: a.spp,
            seconds: ref_s,
            mean_rel_stderr: noise.mean_rel_stderr,
            rms_stderr: rms_se,
        });
        let ref_mean = reference.mean().max(1e-12);
        for (k, f) in &fits {
            let mut exact_img = None;
            for ssdf in [SsdfMode::Exact, SsdfMode::Screen, SsdfMode::None] {
                if ssdf == SsdfMode::Exact && size > a.exact_max_size {
                    continue;
                }
                let opts = SgOptions {
                    ssdf,
                    depth_res: a.depth_res,
                    stride: a.stride,
                    window: a.window,
                };
                let n = if ssdf == SsdfMode::Exact {
                    1
                } else {
                    a.frames.max(1)
                };
                let (mut times, mut maps) = (Vec::new(), Vec::new());
                let mut img = None;
                for _ in 0..n {
                    let t = Instant::now();
                    let (i, tm) = sg::render(&scene, &r.view, &r.gbuffer, f, Some(&occ), &opts)?;
                    times.push(t.elapsed().as_secs_f64() * 1e3);
                    maps.push(tm.maps_ms);
                    img = Some(i);
                }
                let img = img.context("at least one frame")?;
                let ms = median(times);
                let e = rmse(&img, &reference);
                let vs_exact = match (&exact_img, ssdf) {
                    (Some(x), SsdfMode::Screen) => Some(rmse(&img, x)),
                    _ => None,
                };
                let row = Row {
                    size,
                    lobes: *k,
                    ssdf,
                    ms_per_frame: ms,
                    fps: 1e3 / ms.max(1e-9),
                    maps_ms: median(maps),
                    rmse: e,
                    rel_rmse: e / ref_mean,
                    rmse_vs_exact: vs_exact,
                    moving: false,
                    pose_ms: None,
                };
                println!(
                    "{size}² K={k} {ssdf:?}: {ms:.1} ms/frame ({:.1} fps; maps {:.1} ms), RMSE {e:.4} ({:.1} % of the mean){}",
                    row.fps,
                    row.maps_ms,
                    100.0 * row.rel_rmse,
                    vs_exact.map_or(String::new(), |v| format!(", {v:.4} vs exact"))
                );
                let name = format!("sg-{size}-k{k}-{ssdf:?}").to_lowercase();
                img.save(&a.out.join(format!("{name}.png")), a.exposure)?;
                if ssdf == SsdfMode::Exact {
                    exact_img = Some(img);
                }
                report.rows.push(row);
            }
            if moving_scene.is_dynamic() {
                let row = moving_row(a, &moving_scene, &r.view, f, *k, &reference)?;
                println!(
                    "{size}² K={k} Screen, moving: {:.1} ms/frame ({:.1} fps; posing {:.1} ms, maps {:.1} ms), RMSE {:.4} at t = {}",
                    row.ms_per_frame,
                    row.fps,
                    row.pose_ms.unwrap_or(0.0),
                    row.maps_ms,
                    row.rmse,
                    a.time
                );
                report.rows.push(row);
            }
        }
    }
    std::fs::write(
        a.out.join("results.json"),
        serde_json::to_string_pretty(&report)?,
    )
    .with_context(|| format!("cannot write {}", a.out.display()))?;
    std::fs::write(a.out.join("results.md"), markdown(&report))
        .with_context(|| format!("cannot write {}", a.out.display()))?;
    Ok(report)
}

/// Screen-space frames along a moving scene's cycle from `--time`, each posed, rasterised and
/// shaded inside its time; the error is the first frame's (at `--time`) against `reference`.
fn moving_row(
    a: &BenchSgArgs,
    scene: &bspvt_proto::Scene,
    view: &bspvt_client::frame::camera::View,
    env: &SgEnv,
    lobes: usize,
    reference: &Image,
) -> Result<Row> {
    let opts = SgOptions {
        ssdf: SsdfMode::Screen,
        depth_res: a.depth_res,
        stride: a.stride,
        window: a.window,
    };
    let n = a.frames.max(2);
    let mut posed = Posed::new(scene, a.time, view, false);
    let (mut times, mut poses, mut maps, mut first) = (Vec::new(), Vec::new(), Vec::new(), None);
    for i in 0..n {
        let t = Instant::now();
        posed.update(scene, a.time + i as f32 / n as f32, view);
        poses.push(t.elapsed().as_secs_f64() * 1e3);
        let (img, tm) = sg::render(&posed.scene, view, &posed.gbuffer, env, None, &opts)?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        maps.push(tm.maps_ms);
        first.get_or_insert(img);
    }
    let img = first.context("at least one frame")?;
    let name = format!("sg-{}-k{lobes}-moving", view.width);
    img.save(&a.out.join(format!("{name}.png")), a.exposure)?;
    let ms = median(times);
    let e = rmse(&img, reference);
    Ok(Row {
        size: view.width,
        lobes,
        ssdf: SsdfMode::Screen,
        ms_per_frame: ms,
        fps: 1e3 / ms.max(1e-9),
        maps_ms: median(maps),
        rmse: e,
        rel_rmse: e / reference.mean().max(1e-12),
        rmse_vs_exact: None,
        moving: true,
        pose_ms: Some(median(poses)),
    })
}

fn markdown(r: &Report) -> String {
    let mut s = format!(
        "# bench-sg: {} under {} ({} threads)\n\n| K | fit rel. L2 | fit s |\n|---:|---:|---:|\n",
        r.scene, r.env, r.threads
    );
    for f in &r.fits {
        s += &format!("| {} | {:.4} | {:.2} |\n", f.lobes, f.fit_error, f.seconds);
    }
    s += "\n| size | reference spp | s | mean rel. stderr | RMS stderr |\n|---:|---:|---:|---:|---:|\n";
    for x in &r.references {
        s += &format!(
            "| {} | {} | {:.1} | {:.4} | {:.5} |\n",
            x.size, x.spp, x.seconds, x.mean_rel_stderr, x.rms_stderr
        );
    }
    s += "\n| size | K | SSDF | ms/frame | fps | maps ms | RMSE | rel. RMSE | RMSE vs exact |\n|---:|---:|---|---:|---:|---:|---:|---:|---:|\n";
    for x in &r.rows {
        let ssdf = match x.pose_ms {
            Some(p) => format!("{:?}, moving (posing {p:.1} ms)", x.ssdf),
            None => format!("{:?}", x.ssdf),
        };
        s += &format!(
            "| {} | {} | {ssdf} | {:.1} | {:.1} | {:.1} | {:.4} | {:.3} | {} |\n",
            x.size,
            x.lobes,
            x.ms_per_frame,
            x.fps,
            x.maps_ms,
            x.rmse,
            x.rel_rmse,
            x.rmse_vs_exact.map_or("".into(), |v| format!("{v:.4}"))
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a moving scene every configuration is measured with finite numbers, and the moving
    /// row's error is that of the frame at `--time`: the static screen row's image.
    #[test]
    fn moving_scenes_get_a_moving_row() {
        let dir = tempfile::tempdir().expect("temp dir");
        let a = BenchSgArgs {
            scene: Some("builtin:dynamic".into()),
            mesh: None,
            env: Some(bspvt_client::envmap::write_test_map(dir.path())),
            sizes: vec![32],
            lobes: vec![4],
            frames: 2,
            spp: 4,
            depth_res: 64,
            stride: 2,
            window: 6,
            exact_max_size: 32,
            out: dir.path().join("out"),
            exposure: 1.0,
            time: 0.3,
        };
        let r = run(&a).expect("bench-sg runs");
        let screen = r
            .rows
            .iter()
            .find(|x| x.ssdf == SsdfMode::Screen && !x.moving)
            .expect("screen row");
        let moving = r.rows.iter().find(|x| x.moving).expect("moving row");
        assert_eq!(r.rows.len(), 4, "exact, screen, none, moving");
        assert!(
            r.rows
                .iter()
                .all(|x| x.rmse.is_finite() && x.ms_per_frame > 0.0)
        );
        assert_eq!(moving.rmse, screen.rmse);
        assert!(moving.pose_ms.is_some_and(|p| p >= 0.0));
        assert!(a.out.join("results.md").is_file());
        let bad = BenchSgArgs { time: 1.5, ..a };
        assert!(run(&bad).is_err());
    }
}
