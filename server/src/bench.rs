//! `bspvt-server bench`: the bake measured on real meshes.
//!
//! For each mesh (its default `--mesh` scene: the mesh, a ground plane, a quad light), an
//! evenly spaced sample of vertices is ray-cast once; the same cube maps are then fitted with
//! every split method, so the methods are compared in the same run on the same data. Rays and
//! fit are timed separately per vertex on the worker threads.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use bspvt_proto::encoding::encode_chunk;
use bspvt_proto::{BakeSettings, Scene, SplitMethod};
use rayon::prelude::*;
use serde::Serialize;

use bspvt_bake::stats::BakeStats;
use bspvt_bake::{Baker, Totals};

/// `bspvt-server bench` flags.
#[derive(clap::Args, Clone, Debug)]
pub struct BenchArgs {
    /// Folder holding the meshes (default: $BSPVT_ASSETS/meshes or ../shared/assets/meshes).
    #[arg(long)]
    pub meshes_dir: Option<PathBuf>,
    /// Mesh files (in the folder) to measure.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "teapot.obj,bunny.ply,dragon_res4.ply"
    )]
    pub meshes: Vec<String>,
    /// Also measure the built-in scene.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub builtin: bool,
    /// Vertices sampled (evenly spaced) per mesh.
    #[arg(long, default_value_t = 2000)]
    pub vertices: usize,
    // Cube-map face resolution of the bake.
    #[arg(long, default_value_t = 64)]
    #[allow(
        missing_docs,
        reason = "a doc comment here would become new `--help` text"
    )]
    pub face_res: u32,
    // Leaf tolerance ε (default: the scenes' own).
    #[arg(long)]
    #[allow(
        missing_docs,
        reason = "a doc comment here would become new `--help` text"
    )]
    pub epsilon: Option<f32>,
    /// Split methods to compare.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "nelder-mead,default,exhaustive"
    )]
    pub methods: Vec<String>,
    // Worker threads (default: rayon's, one per core).
    #[arg(long)]
    #[allow(
        missing_docs,
        reason = "a doc comment here would become new `--help` text"
    )]
    pub threads: Option<usize>,
    /// Write the rows as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

#[derive(Clone, Debug, Serialize)]
pub(crate) struct BenchRow {
    pub scene: String,
    pub scene_vertices: usize,
    pub sampled: usize,
    pub method: SplitMethod,
    pub stats: BakeStats,
    /// This method's fit time over the Nelder–Mead baseline's, same run.
    pub fit_time_vs_nelder_mead: Option<f64>,
}

fn parse_method(s: &str) -> Result<SplitMethod> {
    serde_json::from_value(serde_json::Value::String(s.into()))
        .with_context(|| format!("unknown split method {s:?} (nelder-mead, default, exhaustive)"))
}

/// Runs the benchmark: a Markdown table on stdout, one row per mesh and split method, and the
/// rows as JSON when `--json` is given.
pub fn run(a: &BenchArgs) -> Result<()> {
    let methods: Vec<SplitMethod> = a
        .methods
        .iter()
        .map(|m| parse_method(m))
        .collect::<Result<_>>()?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()?;
    let threads = pool.current_num_threads();
    let dir = a
        .meshes_dir
        .clone()
        .unwrap_or_else(bspvt_proto::paths::meshes_dir);
    let mut scenes: Vec<(String, Scene)> = Vec::new();
    if let Some(s) = bspvt_proto::builtin::scene("plate").filter(|_| a.builtin) {
        // The same scene without its declared light region: what "don't care" saves.
        let mut free = s.clone();
        free.lights.iter_mut().for_each(|l| l.region = None);
        scenes.push(("builtin:plate".into(), s));
        scenes.push(("builtin:plate, no light region".into(), free));
    }
    for m in &a.meshes {
        let p = dir.join(m);
        if !p.exists() {
            eprintln!(
                "skipped: {} not found (set --meshes-dir or BSPVT_ASSETS)",
                p.display()
            );
            continue;
        }
        scenes.push((m.clone(), Scene::from_mesh_path(&p)?));
    }
    let mut rows = Vec::new();
    for (name, mut scene) in scenes {
        scene.bake = BakeSettings {
            face_res: a.face_res,
            epsilon: a.epsilon.unwrap_or(scene.bake.epsilon),
            ..scene.bake.clone()
        };
        let t = Instant::now();
        let baker = Baker::new(&scene);
        let bvh_s = t.elapsed().as_secs_f64();
        let n = scene.mesh.vertex_count();
        let k = a.vertices.min(n).max(1);
        let sample: Vec<u32> = (0..k).map(|i| (i * n / k) as u32).collect();
        eprintln!("{name}: {n} vertices, BVH {bvh_s:.2} s, casting {k} vertices …");
        let maps: Vec<_> = pool.install(|| {
            sample
                .par_iter()
                .map(|&v| {
                    let t = Instant::now();
                    let (faces, rays) = baker.cube_map(v);
                    (faces, rays, t.elapsed().as_secs_f64())
                })
                .collect()
        });
        let mut nm_fit = None;
        for &method in &methods {
            let fits: Vec<_> = pool.install(|| {
                maps.par_iter()
                    .map(|(faces, _, _)| {
                        let t = Instant::now();
                        let (trees, st) = baker.fit_faces(faces, method);
                        (trees, st, t.elapsed().as_secs_f64())
                    })
                    .collect()
            });
            let mut totals = Totals::default();
            let mut trees = Vec::with_capacity(fits.len());
            for ((_, rays, rs), (tr, st, fs)) in maps.iter().zip(fits) {
                totals += Totals {
                    vertices: 1,
                    rays: *rays,
                    ray_seconds: *rs,
                    fit_seconds: fs,
                    fit: st,
                    bytes: 0,
                };
                trees.push(tr);
            }
            let bytes: u64 = trees
                .chunks(scene.bake.chunk_vertices as usize)
                .map(|c| encode_chunk(0, c, baker.codec()).len() as u64)
                .sum();
            let mut stats = BakeStats::from_totals(&totals, bytes, threads);
            stats.face_res = scene.bake.face_res;
            stats.epsilon = scene.bake.epsilon;
            stats.supersampling = scene.bake.supersampling;
            stats.split = method;
            if method == SplitMethod::NelderMead {
                nm_fit = Some(stats.fit_thread_seconds_per_vertex);
            }
            rows.push(BenchRow {
                scene: name.clone(),
                scene_vertices: n,
                sampled: k,
                method,
                fit_time_vs_nelder_mead: nm_fit.map(|b| stats.fit_thread_seconds_per_vertex / b),
                stats,
            });
        }
    }
    print_table(&rows, a, threads);
    if let Some(p) = &a.json {
        std::fs::write(p, serde_json::to_string_pretty(&rows)?)?;
    }
    Ok(())
}

fn print_table(rows: &[BenchRow], a: &BenchArgs, threads: usize) {
    println!(
        "\nbake bench: {}² faces, {} thread(s), {} sampled vertices per scene\n",
        a.face_res, threads, a.vertices
    );
    println!(
        "| scene | vertices | split | rays ms/vtx/thread | fit ms/vtx/thread | total ms/vtx/thread | fit vs NM | leaves/vtx | bytes/vtx | mean abs ΔV | misclassified |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        let s = &r.stats;
        println!(
            "| {} | {} | {} | {:.3} | {:.3} | {:.3} | {} | {:.1} | {:.1} | {:.5} | {:.5} |",
            r.scene,
            r.scene_vertices,
            serde_json::to_value(r.method)
                .ok()
                .and_then(|v| v.as_str().map(String::from))
                .unwrap_or_default(),
            s.ray_thread_seconds_per_vertex * 1e3,
            s.fit_thread_seconds_per_vertex * 1e3,
            s.thread_seconds_per_vertex * 1e3,
            r.fit_time_vs_nelder_mead
                .map(|x| format!("{x:.3}×"))
                .unwrap_or_else(|| "–".into()),
            s.leaves_per_vertex,
            s.bytes_per_vertex,
            s.mean_abs_visibility_error,
            s.misclassified_pixel_fraction,
        );
    }
}
