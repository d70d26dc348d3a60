//! `bspvt bench-refine`: what adaptive refinement (`bake.refine`, docs/bake.md "Refinement")
//! buys on scenes made of large flat polygons, against uniform subdivision at the same vertex
//! count and against the mesh as given, in one run.
//!
//! Per scene (by default the project's own rooms: `assets/rooms/room.gltf` and
//! `assets/rooms/cornell-box.obj`, given alone as a user would, with their own lamp):
//! - reference: Monte Carlo with the exact BRDF on the mesh as given, twice with independent
//!   seeds at `spp`; the reference is their mean, and MAE(A, B) / 2 estimates its own mean
//!   absolute error (independent noise: E|A − B| = √2 E|A − truth| and the mean of two has
//!   1/√2 of one's);
//! - variants: the mesh as given; adaptive refinement at each vertex budget (the default
//!   settings otherwise; "∞" is the default budget); uniform subdivision
//!   ([`bspvt_bake::refine::refine_uniform`]: longest edges first everywhere) to the vertex
//!   count that adaptive refinement reached. Each is baked (seconds, bytes) and rendered by
//!   BSPVT per pixel and per vertex;
//! - error: mean |BSPVT − reference| over covered pixels and channels, divided by the
//!   reference's mean radiance (the measure of issue 19's ≤ 5 % criterion), and RMSE.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bspvt_bake::Baker;
use bspvt_bake::refine::{RefineSettings, refine_uniform, try_refine};
use bspvt_client::frame::image::Image;
use bspvt_client::groundtruth::render_mc;
use bspvt_client::light::Light;
use bspvt_client::render::renderer::{Mode, Renderer, Trees};
use bspvt_proto::encoding::decode_bake;
use bspvt_proto::{Mesh, Scene};
use bspvt_raytrace::Occluder;
use serde::Serialize;

use crate::compare::metrics::{covered, rmse_mae};

/// `bspvt bench-refine`: adaptive refinement against uniform subdivision at equal vertex
/// count, on rooms given alone.
#[derive(clap::Args, Clone, Debug)]
pub struct BenchRefineArgs {
    /// Meshes or scene files (default: the project's rooms, assets/rooms/room.gltf and
    /// assets/rooms/cornell-box.obj, from the working directory).
    #[arg(long, value_delimiter = ',')]
    pub scenes: Vec<PathBuf>,
    /// Vertex budgets of the adaptive refinement (0: the default budget).
    #[arg(long, value_delimiter = ',', default_value = "1000,2000,4000,0")]
    pub budgets: Vec<u32>,
    /// Image width (the height follows the scene camera's aspect ratio, else square).
    #[arg(long, default_value_t = 192)]
    pub width: u32,
    /// Monte Carlo samples per pixel of each of the two reference renders.
    #[arg(long, default_value_t = 512)]
    pub spp: u32,
    /// Cube-map face resolution of the bakes (default: the scene's).
    #[arg(long)]
    pub face_res: Option<u32>,
    /// Output folder: results.md and results.json.
    #[arg(long, default_value = "out/bench-refine")]
    pub out: PathBuf,
}

/// One baked and rendered variant of a scene.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// The scene's file name.
    pub scene: String,
    /// "as given", "adaptive" or "uniform".
    pub mesh: String,
    /// The adaptive budget asked for (0: the default), for the adaptive and uniform rows.
    pub budget: u32,
    /// Vertices of the mesh baked.
    pub vertices: usize,
    /// Seconds spent refining (0 as given).
    pub refine_s: f64,
    /// Seconds of the bake.
    pub bake_s: f64,
    /// Bytes of the bake.
    pub bake_bytes: usize,
    /// mean |error| / mean radiance, BSPVT per pixel.
    pub pixel_rel_mae: f64,
    /// mean |error| / mean radiance, BSPVT per vertex.
    pub vertex_rel_mae: f64,
    /// RMSE, BSPVT per pixel.
    pub pixel_rmse: f64,
    /// RMSE, BSPVT per vertex.
    pub vertex_rmse: f64,
}

/// One scene's reference and rows.
#[derive(Clone, Debug, Serialize)]
pub struct SceneResult {
    /// The scene's file name.
    pub scene: String,
    /// The reference's mean radiance.
    pub reference_mean: f64,
    /// The reference's own estimated mean |error| / mean radiance.
    pub reference_rel_mae: f64,
    /// Unshadowed LTC per pixel's mean |error| / mean radiance (what shadows change).
    pub unshadowed_rel_mae: f64,
    /// The variants.
    pub rows: Vec<Row>,
}

fn default_scenes() -> Result<Vec<PathBuf>> {
    let rooms = Path::new("assets/rooms");
    if !rooms.is_dir() {
        bail!(
            "assets/rooms was not found (run from the project's root) — name the scenes with --scenes"
        );
    }
    Ok(vec![rooms.join("room.gltf"), rooms.join("cornell-box.obj")])
}

/// Runs the benchmark, prints and writes its tables.
pub fn run(a: &BenchRefineArgs) -> Result<Vec<SceneResult>> {
    if a.width < 8 || a.width > 4096 {
        bail!("--width {} must be in 8..=4096", a.width);
    }
    if a.spp == 0 {
        bail!("--spp must be at least 1");
    }
    let scenes = if a.scenes.is_empty() {
        default_scenes()?
    } else {
        a.scenes.clone()
    };
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut results = Vec::new();
    for path in &scenes {
        let r = bench_scene(path, a).with_context(|| format!("scene {}", path.display()))?;
        println!("{}", table(std::slice::from_ref(&r)));
        results.push(r);
    }
    let md = table(&results);
    std::fs::write(a.out.join("results.md"), &md)?;
    std::fs::write(
        a.out.join("results.json"),
        serde_json::to_string_pretty(&results)?,
    )?;
    Ok(results)
}

fn load(path: &Path) -> Result<Scene> {
    let is_json = path.extension().is_some_and(|e| e == "json");
    Ok(if is_json {
        Scene::load(path)?
    } else {
        Scene::from_mesh_path(path)?
    })
}

/// Mean |a − b| over covered pixels and channels.
fn mae(a: &Image, b: &Image, covered: &[bool]) -> f64 {
    rmse_mae(a, b, covered).1
}

fn bench_scene(path: &Path, a: &BenchRefineArgs) -> Result<SceneResult> {
    let mut given = load(path)?;
    if let Some(r) = a.face_res {
        given.bake.face_res = r;
    }
    given.bake.refine = None;
    given.validate()?;
    if given.lights.is_empty() {
        bail!("the scene has no polygon light");
    }
    // Every light of the scene, summed, in the reference and the frames.
    let lights: Vec<Light> = given.lights.iter().map(Light::from_scene).collect();
    let name = path
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let (w, h) = (a.width, given.camera.image_height(a.width, None));

    let r = Renderer::new(&given, w, h);
    let cov = covered(&r.gbuffer);
    let occ = Occluder::of_surfaces(&given.mesh, &given.materials);
    let t = Instant::now();
    let (ref_a, _) = render_mc(&given, &r.view, &r.gbuffer, &lights, &occ, a.spp, 1);
    let (ref_b, _) = render_mc(&given, &r.view, &r.gbuffer, &lights, &occ, a.spp, 2);
    let mut reference = ref_a.clone();
    for (p, q) in reference.pixels.iter_mut().zip(&ref_b.pixels) {
        *p = std::array::from_fn(|k| 0.5 * (p[k] + q[k]));
    }
    let mean = {
        let (s, n) = reference.pixels.iter().zip(&cov).filter(|(_, c)| **c).fold(
            (0.0f64, 0usize),
            |(s, n), (p, _)| {
                (
                    s + p.iter().map(|&x| f64::from(x)).sum::<f64>() / 3.0,
                    n + 1,
                )
            },
        );
        s / n.max(1) as f64
    };
    if !(mean > 0.0) {
        bail!("the reference is black: the light lights nothing the camera sees");
    }
    eprintln!(
        "{name}: reference {} spp × 2 in {:.1} s",
        a.spp,
        t.elapsed().as_secs_f64()
    );
    let (unshadowed, _) = r.ltc(&lights, Mode::Pixel);

    let measure = |scene: &Scene, kind: &str, budget: u32, refine_s: f64| -> Result<Row> {
        let t = Instant::now();
        let bytes = Baker::new(scene)
            .bake_all(&|_, _| {}, &AtomicBool::new(false))?
            .bytes;
        let bake_s = t.elapsed().as_secs_f64();
        let b = decode_bake(&bytes)?;
        let trees = Trees::full(&b.trees, b.header.codec());
        let rr = Renderer::new(scene, w, h);
        let (pixel, _) = rr.bspvt(&lights, &trees, Mode::Pixel);
        let (vertex, _) = rr.bspvt(&lights, &trees, Mode::Vertex);
        let (prmse, pmae) = rmse_mae(&pixel, &reference, &cov);
        let (vrmse, vmae) = rmse_mae(&vertex, &reference, &cov);
        let row = Row {
            scene: name.clone(),
            mesh: kind.into(),
            budget,
            vertices: scene.mesh.vertex_count(),
            refine_s,
            bake_s,
            bake_bytes: bytes.len(),
            pixel_rel_mae: pmae / mean,
            vertex_rel_mae: vmae / mean,
            pixel_rmse: prmse,
            vertex_rmse: vrmse,
        };
        eprintln!(
            "{name}: {kind} {} vertices, bake {:.1} s, per pixel {:.4}, per vertex {:.4}",
            row.vertices, row.bake_s, row.pixel_rel_mae, row.vertex_rel_mae
        );
        Ok(row)
    };
    let with_mesh = |mesh: Mesh| Scene {
        mesh,
        ..given.clone()
    };

    let mut rows = vec![measure(&given, "as given", 0, 0.0)?];
    for &budget in &a.budgets {
        let settings = RefineSettings {
            max_vertices: if budget == 0 {
                RefineSettings::default().max_vertices
            } else {
                budget
            },
            ..RefineSettings::default()
        };
        let (adaptive, st) = try_refine(&given.mesh, &given.lights, &settings)?;
        let n = adaptive.vertex_count() as u32;
        rows.push(measure(
            &with_mesh(adaptive),
            "adaptive",
            budget,
            st.seconds,
        )?);
        let t = Instant::now();
        let (uniform, _) = refine_uniform(&given.mesh, n)?;
        let s = t.elapsed().as_secs_f64();
        rows.push(measure(&with_mesh(uniform), "uniform", budget, s)?);
    }
    Ok(SceneResult {
        scene: name,
        reference_mean: mean,
        reference_rel_mae: 0.5 * mae(&ref_a, &ref_b, &cov) / mean,
        unshadowed_rel_mae: mae(&unshadowed, &reference, &cov) / mean,
        rows,
    })
}

/// The results as Markdown tables.
fn table(results: &[SceneResult]) -> String {
    let mut s = String::new();
    for r in results {
        let _ = writeln!(
            s,
            "\n### {}\n\nreference: mean radiance {:.4}, its own mean |error| {:.2} % of it; \
             unshadowed LTC per pixel {:.2} %\n\n\
             | mesh | budget | vertices | refine s | bake s | bake bytes | per pixel | per vertex | RMSE pixel | RMSE vertex |\n\
             |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
            r.scene,
            r.reference_mean,
            100.0 * r.reference_rel_mae,
            100.0 * r.unshadowed_rel_mae
        );
        for row in &r.rows {
            let budget = match (row.mesh.as_str(), row.budget) {
                ("as given", _) => "—".to_string(),
                (_, 0) => "default".to_string(),
                (_, b) => b.to_string(),
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.2} | {:.2} | {} | {:.2} % | {:.2} % | {:.4} | {:.4} |",
                row.mesh,
                budget,
                row.vertices,
                row.refine_s,
                row.bake_s,
                row.bake_bytes,
                100.0 * row.pixel_rel_mae,
                100.0 * row.vertex_rel_mae,
                row.pixel_rmse,
                row.vertex_rmse
            );
        }
    }
    s
}
