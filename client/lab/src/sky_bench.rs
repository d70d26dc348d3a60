//! `bspvt bench-sky`: the environment through the baked trees (`bspvt-env`) for k pieces per
//! cube-face side, against the SG + screen-space SSDF path (paper 001) and the unshadowed
//! sky, all measured against the Monte Carlo environment reference (`mc-env`) in the same
//! run. The sky is re-shaded every timed frame (the map turning by 1° a frame), so the
//! figures are the cost of a moving sky, not of the cached one. Writes `results.json` and
//! `results.md` (and the images) to `--out`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bspvt_proto::Scene;
use bspvt_proto::scene::open_scene;
use bspvt_raytrace::Occluder;
use serde::Serialize;

use bspvt_client::envmap::EnvLight;
use bspvt_client::frame::image::Image;
use bspvt_client::gpu::frame::GpuFrames;
use bspvt_client::groundtruth::render_mc_env;
use bspvt_client::method::trees::cached_sky_bake;
use bspvt_client::render::renderer::{Mode, Renderer, Trees};
use bspvt_client::render::sky_cells::CellTransfer;
use bspvt_client::sg::{self, SgOptions, SsdfMode};
use bspvt_client::sky::{DEFAULT_THRESHOLD, SkyPieces};
use bspvt_client::sky_cells::SkyCells;

use crate::bench::median_ms;
use crate::compare::metrics::{covered, covered_mean, rmse_mae};

/// `bspvt bench-sky`: speed and error of `bspvt-env` per k against SG and Monte Carlo.
#[derive(clap::Args, Clone, Debug)]
pub struct BenchSkyArgs {
    /// Scene file or builtin:NAME [default: builtin:plate]; its lamps are left out (the sky
    /// alone is measured).
    pub(crate) scene: Option<String>,
    /// A bare mesh with the default scene around it (instead of SCENE).
    #[arg(long)]
    pub(crate) mesh: Option<PathBuf>,
    /// Subdivide the mesh uniformly (longest edges first) to about this many vertices: a
    /// held-out-size mesh from a shared one.
    #[arg(long)]
    pub(crate) subdivide: Option<u32>,
    /// Environment map [default: env/royal_esplanade_1k.hdr under BSPVT_ASSETS or
    /// ../shared/assets].
    #[arg(long)]
    pub(crate) env: Option<PathBuf>,
    /// Image side.
    #[arg(long, default_value_t = 512)]
    pub(crate) size: u32,
    /// Pieces per cube-face side to measure.
    #[arg(long, value_delimiter = ',', default_values_t = vec![1u32, 2, 4, 8])]
    pub(crate) pieces: Vec<u32>,
    /// `bspvt-env` per vertex in world-fixed cells: latitude bands to measure (0: none).
    #[arg(long, value_delimiter = ',', default_values_t = vec![8u32, 12, 16])]
    pub(crate) cells: Vec<u32>,
    /// SG lobes of the comparison.
    #[arg(long, value_delimiter = ',', default_values_t = vec![16usize, 32])]
    pub(crate) lobes: Vec<usize>,
    /// Also measure the cells on the GPU (`bspvt-env --backend gpu` per vertex; each frame
    /// read back): the first frame (the terms), the map turning, the camera moving.
    #[arg(long)]
    pub(crate) gpu: bool,
    /// Timed frames per configuration (median reported).
    #[arg(long, default_value_t = 3)]
    pub(crate) frames: usize,
    /// Monte Carlo samples per pixel of the reference.
    #[arg(long, default_value_t = 1024)]
    pub(crate) spp: u32,
    /// Where the sky's bake is kept (by the sky scene's hash).
    #[arg(long, default_value = "out/cache/bakes")]
    pub(crate) cache: PathBuf,
    /// Output folder.
    #[arg(long, default_value = "bench-sky")]
    pub out: PathBuf,
}

/// One measured configuration.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// `bspvt-env`, `sg-screen`, `sg-unshadowed`, `bspvt-env-unshadowed`.
    pub method: String,
    pub(crate) mode: Option<Mode>,
    /// Pieces per face side (`bspvt-env`).
    pub(crate) k: Option<u32>,
    /// Sky pieces after splitting and leaving out.
    pub(crate) sky_pieces: Option<usize>,
    pub(crate) lobes: Option<usize>,
    /// Median frame time, ms.
    pub ms_per_frame: f64,
    pub(crate) fps: f64,
    /// Mean |error| over covered pixels and channels, relative to the reference's mean.
    pub rel_mae: f64,
    /// RMSE relative to the reference's mean.
    pub(crate) rel_rmse: f64,
    /// Tree pieces integrated per shaded vertex (`bspvt-env`).
    pub(crate) tree_pieces_per_vertex: Option<f64>,
    /// Latitude bands of the sky's cells (`bspvt-env-cells`).
    pub(crate) bands: Option<u32>,
    /// The first frame (the cells cut by every vertex's trees), ms (`bspvt-env-cells`).
    pub(crate) first_frame_ms: Option<f64>,
    /// Bytes kept between frames for the visible vertices' cells (`bspvt-env-cells`).
    pub(crate) kept_bytes: Option<usize>,
}

/// What `bspvt bench-sky` measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub(crate) scene: String,
    pub(crate) vertices: usize,
    pub(crate) vertices_shaded: usize,
    pub(crate) env: String,
    pub(crate) threads: usize,
    pub(crate) size: u32,
    pub(crate) reference_spp: u32,
    pub(crate) reference_seconds: f64,
    pub(crate) reference_mean_rel_stderr: f64,
    /// The sky's bake: seconds (when made by this run), bytes, from the cache.
    pub(crate) sky_bake_seconds: f64,
    pub(crate) sky_bake_bytes: usize,
    pub(crate) sky_bake_from_cache: bool,
    /// One row per method and setting.
    pub rows: Vec<Row>,
}

impl Row {
    /// A row of `method` taking `ms` a frame with errors `(mean |error|, RMSE)` relative to
    /// the reference's mean; the optional fields empty.
    fn new(method: &str, mode: Mode, ms: f64, (rel_mae, rel_rmse): (f64, f64)) -> Row {
        Row {
            method: method.into(),
            mode: Some(mode),
            k: None,
            sky_pieces: None,
            lobes: None,
            ms_per_frame: ms,
            fps: 1e3 / ms.max(1e-9),
            rel_mae,
            rel_rmse,
            tree_pieces_per_vertex: None,
            bands: None,
            first_frame_ms: None,
            kept_bytes: None,
        }
    }
}

/// The scene measured: the sky alone, subdivided when asked.
fn sky_scene(a: &BenchSkyArgs) -> Result<(String, Scene)> {
    let name = a.scene.clone().unwrap_or_else(|| "builtin:plate".into());
    let scene = match &a.mesh {
        Some(m) => open_scene(None, Some(m))?,
        None => open_scene(Some(&name), None)?,
    };
    if scene.is_dynamic() {
        bail!("bench-sky measures static scenes (the trees are baked at rest)");
    }
    let mut sky = scene.sky();
    let mut label = a.mesh.as_ref().map_or(name, |m| m.display().to_string());
    if let Some(n) = a.subdivide {
        let (mesh, _) = bspvt_bake::refine::refine_uniform(&sky.mesh, n)
            .context("cannot subdivide the mesh")?;
        sky.mesh = mesh;
        label += &format!(" subdivided to {} vertices", sky.mesh.vertex_count());
    }
    Ok((label, sky))
}

/// `camera` turned by `deg` about the vertical through its target.
fn orbit_camera(camera: &bspvt_proto::scene::Camera, deg: f64) -> bspvt_proto::scene::Camera {
    let target = glam::Vec3::from(camera.target).as_dvec3();
    let eye = glam::Vec3::from(camera.position).as_dvec3();
    let moved = target + glam::DMat3::from_rotation_y(deg.to_radians()) * (eye - target);
    bspvt_proto::scene::Camera {
        position: moved.as_vec3().to_array(),
        ..camera.clone()
    }
}

/// Runs `bspvt bench-sky` and writes results.json/.md and images.
pub fn run(a: &BenchSkyArgs) -> Result<Report> {
    let (label, scene) = sky_scene(a)?;
    let env_path = a
        .env
        .clone()
        .unwrap_or_else(bspvt_client::envmap::default_env_path);
    let env = EnvLight::load(&env_path)?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let frames = a.frames.max(1);

    // `scene` is already the sky's: its sky is itself.
    let (baked, bake) = cached_sky_bake(&scene, &a.cache, &|_, _| {})?;
    let trees = Trees::full(&bake.trees, bake.header.codec());
    println!(
        "{label}: {} vertices; sky bake {} bytes{}",
        scene.mesh.vertex_count(),
        baked.bytes,
        if baked.from_cache {
            " (cached)".to_string()
        } else {
            format!(" in {:.1} s", baked.seconds)
        }
    );

    let r = Renderer::new(&scene, a.size, a.size);
    let occ = Occluder::of_surfaces(&scene.mesh, &scene.materials);
    let t = Instant::now();
    let (reference, noise) = render_mc_env(&scene, &r.view, &r.gbuffer, &env, &occ, a.spp, 1);
    let reference_seconds = t.elapsed().as_secs_f64();
    println!(
        "reference: {} spp in {reference_seconds:.1} s ({noise})",
        a.spp
    );
    reference.save(&a.out.join("mc-env.png"), 1.0)?;
    // Mean |error| and RMSE over the covered pixels, relative to the reference's mean there.
    let covered = covered(&r.gbuffer);
    let mean = covered_mean(&reference, &covered).max(1e-12);
    let errors = |img: &Image| {
        let (rmse, mae) = rmse_mae(img, &reference, &covered);
        (mae / mean, rmse / mean)
    };
    let mut rows = Vec::new();
    let mut vertices_shaded = 0;
    let mut push = |row: Row, img: &Image, file: String| -> Result<()> {
        println!(
            "{} {}: {:.1} ms/frame ({:.1} fps), mean |error| {:.2} %, RMSE {:.2} % of the mean",
            row.method,
            [
                row.mode.map(|m| format!("{m:?}")),
                row.k
                    .map(|k| format!("k={k} ({} pieces)", row.sky_pieces.unwrap_or(0))),
                row.lobes.map(|l| format!("K={l}")),
                row.bands
                    .map(|b| format!("B={b} ({} cells)", row.sky_pieces.unwrap_or(0))),
                row.first_frame_ms
                    .map(|ms| format!("first frame {ms:.0} ms")),
                row.kept_bytes
                    .map(|b| format!("{:.1} MiB kept", b as f64 / f64::from(1 << 20))),
            ]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join(" "),
            row.ms_per_frame,
            row.fps,
            100.0 * row.rel_mae,
            100.0 * row.rel_rmse
        );
        img.save(&a.out.join(file), 1.0)?;
        rows.push(row);
        Ok(())
    };

    // The sky through the trees, for each k, both modes; the map turns 1° a frame (so each
    // timed frame shades the sky anew); the error is the frame at rotation 0, the reference's.
    for &k in &a.pieces {
        let sky = SkyPieces::new(&env, k, DEFAULT_THRESHOLD, 1.0)?;
        for mode in [Mode::Vertex, Mode::Pixel] {
            let (img, counts) = r.sky(&sky.posed(0.0), Some(&trees), mode);
            let mut turn = 0.0;
            let (ms, _) = median_ms(frames, || {
                turn += 1.0;
                Ok(r.sky(&sky.posed(turn), Some(&trees), mode))
            })?;
            vertices_shaded = counts.vertices_shaded;
            let row = Row {
                k: Some(k),
                sky_pieces: Some(sky.len()),
                tree_pieces_per_vertex: Some(
                    counts.pieces as f64 / counts.vertices_shaded.max(1) as f64,
                ),
                ..Row::new("bspvt-env", mode, ms, errors(&img))
            };
            push(
                row,
                &img,
                format!("bspvt-env-k{k}-{mode:?}.png").to_lowercase(),
            )?;
        }
    }
    // The sky in world-fixed cells, per vertex: the first frame cuts the cells by the trees;
    // then the map turns 1° a frame with the camera still, and again with the camera moving
    // too (two cameras 1° apart about the target, in turn: every frame re-weights the
    // specular lobe of every vertex).
    let orbit = orbit_camera(&scene.camera, 1.0);
    let r2 = Renderer::with_camera(&scene, &orbit, a.size, a.size);
    for &bands in a.cells.iter().filter(|&&b| b > 0) {
        let cells = SkyCells::new(&env, bands, 1.0)?;
        let mut keep = CellTransfer::default();
        let t = Instant::now();
        let (img, counts) = r.sky_cells(&cells, &cells.radiance(0.0), Some(&trees), &mut keep);
        let first = t.elapsed().as_secs_f64() * 1e3;
        let mut turn = 0.0;
        let (ms, _) = median_ms(frames.max(5), || {
            turn += 1.0;
            Ok(r.sky_cells(&cells, &cells.radiance(turn), Some(&trees), &mut keep))
        })?;
        let (err, name) = (errors(&img), format!("bspvt-env-cells-b{bands}.png"));
        let row = Row {
            sky_pieces: Some(cells.len()),
            tree_pieces_per_vertex: Some(
                counts.pieces as f64 / counts.vertices_shaded.max(1) as f64,
            ),
            bands: Some(bands),
            first_frame_ms: Some(first),
            kept_bytes: Some(keep.bytes()),
            ..Row::new("bspvt-env-cells", Mode::Vertex, ms, err)
        };
        push(row, &img, name)?;
        let mut i = 0;
        let (ms, _) = median_ms(frames.max(5), || {
            turn += 1.0;
            i += 1;
            let view = if i % 2 == 0 { &r } else { &r2 };
            Ok(view.sky_cells(&cells, &cells.radiance(turn), Some(&trees), &mut keep))
        })?;
        let row = Row {
            sky_pieces: Some(cells.len()),
            bands: Some(bands),
            ..Row::new("bspvt-env-cells, camera moving", Mode::Vertex, ms, err)
        };
        push(row, &img, format!("bspvt-env-cells-b{bands}-moving.png"))?;
    }
    // The same cells on the GPU: the first frame makes every visible vertex's terms (after a
    // frame of the other camera, so that compiling the pipelines and uploading the trees are
    // not in it), then the map turns with the camera still (one gather pass a frame), then the
    // camera moves too (the terms again every frame). Every frame is read back.
    if a.gpu {
        let gpu = bspvt_client::gpu::Gpu::shared()?;
        println!("GPU: {}", gpu.adapter);
        let mut on_gpu = GpuFrames::new(gpu, &scene, 1)?;
        for &bands in a.cells.iter().filter(|&&b| b > 0) {
            let cells = SkyCells::new(&env, bands, 1.0)?;
            let mut frame = |r: &Renderer, turn: f64| {
                on_gpu.sky_frame(gpu, r, &cells, &cells.radiance(turn), Some(&trees))
            };
            frame(&r2, 0.0)?;
            let t = Instant::now();
            let (img, _) = frame(&r, 0.0)?;
            let first = t.elapsed().as_secs_f64() * 1e3;
            let mut turn = 0.0;
            let (ms, _) = median_ms(frames.max(5), || {
                turn += 1.0;
                frame(&r, turn)
            })?;
            let err = errors(&img);
            let row = Row {
                sky_pieces: Some(cells.len()),
                bands: Some(bands),
                first_frame_ms: Some(first),
                ..Row::new("bspvt-env-cells GPU", Mode::Vertex, ms, err)
            };
            push(row, &img, format!("bspvt-env-cells-b{bands}-gpu.png"))?;
            let mut i = 0;
            let (ms, _) = median_ms(frames.max(5), || {
                turn += 1.0;
                i += 1;
                frame(if i % 2 == 0 { &r } else { &r2 }, turn)
            })?;
            let row = Row {
                sky_pieces: Some(cells.len()),
                bands: Some(bands),
                ..Row::new("bspvt-env-cells GPU, camera moving", Mode::Vertex, ms, err)
            };
            push(
                row,
                &img,
                format!("bspvt-env-cells-b{bands}-gpu-moving.png"),
            )?;
        }
    }
    // Without the trees: what the shadows are worth.
    let sky = SkyPieces::new(&env, 2, DEFAULT_THRESHOLD, 1.0)?;
    let (ms, (img, _)) = median_ms(1, || Ok(r.sky(&sky.posed(0.0), None, Mode::Pixel)))?;
    let row = Row {
        k: Some(2),
        sky_pieces: Some(sky.len()),
        ..Row::new("bspvt-env-unshadowed", Mode::Pixel, ms, errors(&img))
    };
    push(row, &img, "bspvt-env-unshadowed.png".into())?;
    // SG with the screen-space SSDF (paper 001) and unshadowed SG.
    sg::halfspace::warm_up();
    for &lobes in &a.lobes {
        let fit = sg::fit(&env, lobes);
        for (name, ssdf) in [
            ("sg-screen", SsdfMode::Screen),
            ("sg-unshadowed", SsdfMode::None),
        ] {
            let opts = SgOptions {
                ssdf,
                ..SgOptions::default()
            };
            let (ms, (img, _)) = median_ms(frames, || {
                sg::render(&scene, &r.view, &r.gbuffer, &fit, Some(&occ), &opts)
            })?;
            let row = Row {
                lobes: Some(lobes),
                ..Row::new(name, Mode::Pixel, ms, errors(&img))
            };
            push(row, &img, format!("{name}-k{lobes}.png"))?;
        }
    }
    let report = Report {
        scene: label,
        vertices: scene.mesh.vertex_count(),
        vertices_shaded,
        env: env_path.display().to_string(),
        threads: rayon::current_num_threads(),
        size: a.size,
        reference_spp: a.spp,
        reference_seconds,
        reference_mean_rel_stderr: noise.mean_rel_stderr,
        sky_bake_seconds: baked.seconds,
        sky_bake_bytes: baked.bytes,
        sky_bake_from_cache: baked.from_cache,
        rows,
    };
    std::fs::write(
        a.out.join("results.json"),
        serde_json::to_string_pretty(&report)?,
    )
    .with_context(|| format!("cannot write {}", a.out.display()))?;
    std::fs::write(a.out.join("results.md"), markdown(&report))
        .with_context(|| format!("cannot write {}", a.out.display()))?;
    Ok(report)
}

fn markdown(r: &Report) -> String {
    let mut s = format!(
        "# bench-sky: {} under {} ({} vertices, {} shaded; {}² on {} threads)\n\n\
         Reference: Monte Carlo, {} spp, {:.1} s, mean relative standard error {:.4}. \
         Sky bake: {} bytes{}.\n\n\
         | method | mode | k | B | pieces or cells | K | ms/frame | fps | mean abs. error | RMSE | tree pieces/vertex | first frame ms |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        r.scene,
        r.env,
        r.vertices,
        r.vertices_shaded,
        r.size,
        r.threads,
        r.reference_spp,
        r.reference_seconds,
        r.reference_mean_rel_stderr,
        r.sky_bake_bytes,
        if r.sky_bake_from_cache {
            " (cached)".to_string()
        } else {
            format!(", {:.1} s", r.sky_bake_seconds)
        }
    );
    let opt = |v: Option<String>| v.unwrap_or_default();
    for x in &r.rows {
        s += &format!(
            "| {} | {} | {} | {} | {} | {} | {:.1} | {:.1} | {:.2} % | {:.2} % | {} | {} |\n",
            x.method,
            opt(x.mode.map(|m| format!("{m:?}").to_lowercase())),
            opt(x.k.map(|k| k.to_string())),
            opt(x.bands.map(|b| b.to_string())),
            opt(x.sky_pieces.map(|k| k.to_string())),
            opt(x.lobes.map(|k| k.to_string())),
            x.ms_per_frame,
            x.fps,
            100.0 * x.rel_mae,
            100.0 * x.rel_rmse,
            opt(x.tree_pieces_per_vertex.map(|p| format!("{p:.1}"))),
            opt(x.first_frame_ms.map(|ms| format!("{ms:.0}")))
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every configuration is measured with finite figures, the trees' shadows bring the sky
    /// closer to Monte Carlo than the unshadowed sky, and the files are written.
    #[test]
    fn measures_every_configuration() {
        let dir = tempfile::tempdir().expect("temp dir");
        let a = BenchSkyArgs {
            scene: Some("builtin:plate-small".into()),
            mesh: None,
            subdivide: None,
            env: Some(bspvt_client::envmap::write_test_map(dir.path())),
            size: 48,
            pieces: vec![1, 2],
            cells: vec![4],
            lobes: vec![4],
            gpu: false,
            frames: 1,
            spp: 64,
            cache: dir.path().join("cache"),
            out: dir.path().join("out"),
        };
        let r = run(&a).expect("bench-sky runs");
        assert_eq!(r.rows.len(), 2 * 2 + 2 + 1 + 2);
        assert!(
            r.rows
                .iter()
                .all(|x| x.rel_mae.is_finite() && x.ms_per_frame > 0.0)
        );
        let row = |f: &dyn Fn(&Row) -> bool| r.rows.iter().find(|x| f(x)).expect("row");
        let shadowed =
            row(&|x| x.method == "bspvt-env" && x.k == Some(2) && x.mode == Some(Mode::Pixel));
        let open = row(&|x| x.method == "bspvt-env-unshadowed");
        assert!(shadowed.rel_mae < open.rel_mae, "{shadowed:?} vs {open:?}");
        // The cells' shadows too.
        let cells = row(&|x| x.method == "bspvt-env-cells");
        assert!(cells.rel_mae < open.rel_mae, "{cells:?} vs {open:?}");
        assert!(a.out.join("results.md").is_file());
        // A second run finds the sky's bake in the cache.
        let again = run(&a).expect("bench-sky runs again");
        assert!(again.sky_bake_from_cache);
    }
}
