//! `bspvt-server bench`: the bake measured on real meshes.
//!
//! For each mesh (its default `--mesh` scene: the mesh, a ground plane, a quad light; an
//! asset with lamps: its lamps, and again with them moving in their planes), an
//! evenly spaced sample of vertices is ray-cast once per cast mode (`--casts`); each cast's
//! cube maps are compared with the first cast's (the visibility error: pixels that differ,
//! mean |ΔV|) and fitted with every split method, so casts and methods are compared in the
//! same run on the same data. Rays and fit are timed separately per vertex on the worker
//! threads.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use bspvt_proto::encoding::encode_chunk;
use bspvt_proto::scene::LightMotion;
use bspvt_proto::{BakeSettings, Scene, SplitMethod};
use rayon::prelude::*;
use serde::Serialize;

use bspvt_bake::cubemap::FacePixels;
use bspvt_bake::stats::BakeStats;
use bspvt_bake::{Baker, CastCounts, CastMode, Totals};

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
    /// Cast modes to compare (the first is the reference of the visibility error); `gpu`:
    /// the GPU backend's cast (every ray that matters, in a wgpu compute shader).
    #[arg(long, value_delimiter = ',', default_value = "full,adaptive")]
    pub casts: Vec<String>,
    /// Passes of each cast (interleaved) and of each fit; the fastest of each is reported (for
    /// a shared machine).
    #[arg(long, default_value_t = 1)]
    pub repeat: usize,
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
    /// `full`, `adaptive` or `gpu`.
    pub cast: String,
    pub stats: BakeStats,
    /// This cast's cube maps against the first cast's: pixels that differ, as a share of the
    /// pixels that matter, and mean |ΔV| over them.
    pub cast_pixels_differing: f64,
    pub cast_mean_abs_dv: f64,
    /// This cast's ray time over the first cast's, same run (the GPU cast's: wall-clock
    /// seconds, against the CPU casts' thread-seconds).
    pub ray_time_vs_first_cast: f64,
    /// This method's fit time over the Nelder–Mead baseline's, same run.
    pub fit_time_vs_nelder_mead: Option<f64>,
}

/// A cast the bench compares: on the CPU threads, or on the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum BenchCast {
    Cpu(CastMode),
    Gpu,
}

impl BenchCast {
    fn name(self) -> &'static str {
        match self {
            BenchCast::Cpu(CastMode::Full) => "full",
            BenchCast::Cpu(CastMode::Adaptive) => "adaptive",
            BenchCast::Gpu => "gpu",
        }
    }
}

fn parse_cast(s: &str) -> Result<BenchCast> {
    match s {
        "full" => Ok(BenchCast::Cpu(CastMode::Full)),
        "adaptive" => Ok(BenchCast::Cpu(CastMode::Adaptive)),
        "gpu" => Ok(BenchCast::Gpu),
        _ => anyhow::bail!("unknown cast mode {s:?} (full, adaptive, gpu)"),
    }
}

/// Vertices per GPU dispatch in the bench's GPU cast (a chunk's worth).
#[cfg(feature = "gpu")]
const GPU_BATCH: usize = 256;

/// The GPU cast of `sample`, in batches of [`GPU_BATCH`] vertices on the current rayon pool
/// (ray generation) and the GPU; each vertex is given its batch's wall-clock seconds / size.
#[cfg(feature = "gpu")]
fn gpu_pass(
    baker: &Baker,
    caster: &bspvt_bake::gpu_cast::GpuCaster,
    sample: &[u32],
) -> Result<Vec<(CubeMap, CastCounts, f64)>> {
    let mut out = Vec::with_capacity(sample.len());
    for batch in sample.chunks(GPU_BATCH) {
        let t = Instant::now();
        let (maps, counts) = baker.gpu_cube_maps(caster, batch)?;
        let per_vertex = t.elapsed().as_secs_f64() / batch.len() as f64;
        let n = batch.len() as u64;
        for (i, m) in maps.into_iter().enumerate() {
            // Rays are counted per batch: spread over its vertices, the sum kept (the
            // per-vertex figures are means).
            let spread = |x: u64| x / n + u64::from((i as u64) < x % n);
            let r = spread(counts.rays);
            let c = CastCounts {
                rays: r,
                traversals: r,
                recast: spread(counts.recast),
            };
            out.push((m, c, per_vertex));
        }
    }
    Ok(out)
}

/// The GPU context of the bench, when a cast asks for it.
#[cfg(feature = "gpu")]
type Gpu = bspvt_bake::gpu_cast::GpuContext;
#[cfg(not(feature = "gpu"))]
enum Gpu {}

#[cfg(feature = "gpu")]
fn gpu_context() -> Result<std::sync::Arc<Gpu>> {
    let ctx = Gpu::new()?;
    eprintln!("GPU: {}", ctx.describe());
    Ok(std::sync::Arc::new(ctx))
}

#[cfg(not(feature = "gpu"))]
fn gpu_context() -> Result<std::sync::Arc<Gpu>> {
    anyhow::bail!("this bspvt-server was built without the `gpu` feature: no `gpu` cast")
}

type CubeMap = [Option<FacePixels>; 6];

/// Pixels that differ between two casts of the same vertices, the pixels compared, and
/// Σ |ΔV| over them.
fn cast_difference(a: &[CubeMap], b: &[CubeMap], samples: u32) -> (u64, u64, f64) {
    let (mut differ, mut pixels, mut dv) = (0u64, 0u64, 0.0f64);
    for (fa, fb) in a.iter().flatten().zip(b.iter().flatten()) {
        match (fa, fb) {
            (Some(pa), Some(pb)) if pa.index == pb.index => {
                pixels += pa.index.len() as u64;
                for (&ka, &kb) in pa.visible.iter().zip(&pb.visible) {
                    if ka != kb {
                        differ += 1;
                        dv += (ka as f64 - kb as f64).abs() / samples as f64;
                    }
                }
            }
            (None, None) => {}
            // The pixels that matter do not depend on the cast; count a mismatch as all wrong.
            (x, y) => {
                let n = x.as_ref().or(y.as_ref()).map_or(0, |p| p.index.len()) as u64;
                pixels += n;
                differ += n;
                dv += n as f64;
            }
        }
    }
    (differ, pixels, dv)
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
    let casts: Vec<BenchCast> = a
        .casts
        .iter()
        .map(|c| parse_cast(c))
        .collect::<Result<_>>()?;
    anyhow::ensure!(!casts.is_empty(), "--casts names no cast mode");
    let gpu = match casts.contains(&BenchCast::Gpu) {
        true => Some(gpu_context()?),
        false => None,
    };
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
        // A path that exists as given (e.g. assets/rooms/room.gltf), else a file in the folder.
        let p = match std::path::Path::new(m).is_file() {
            true => PathBuf::from(m),
            false => dir.join(m),
        };
        if !p.exists() {
            eprintln!(
                "skipped: {} not found (set --meshes-dir or BSPVT_ASSETS)",
                p.display()
            );
            continue;
        }
        let mut scene = Scene::from_mesh_path(&p)?;
        // The mesh a bake of it bakes: refined where the scene asks (an asset with its own
        // lamps), once, so that both light rules below bake the same vertices.
        bspvt_bake::refine::refine_scene(&mut scene)?;
        // An asset's own lamps are fixed: rays end at their polygons. The same scene with its
        // lamps moving in their planes (rays end at the planes: the rule before issue 34) is
        // the baseline of what fixed lamps leave out.
        let fixed = scene
            .lights
            .iter()
            .any(|l| l.motion() == LightMotion::Fixed);
        if fixed {
            let mut planes = scene.clone();
            for l in planes.lights.iter_mut().filter(|l| l.region.is_none()) {
                l.moves_in_plane = true;
            }
            scenes.push((m.clone(), scene));
            scenes.push((format!("{m}, lamps moving in their planes"), planes));
        } else {
            scenes.push((m.clone(), scene));
        }
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
        // Each cast `--repeat` times, the casts interleaved; the fastest pass of each is kept
        // (the cube maps are the same every pass), so load from other processes on a shared
        // machine weighs on both casts alike.
        #[cfg(feature = "gpu")]
        let caster = match &gpu {
            Some(g) => Some(baker.gpu_caster(g.clone())?),
            None => None,
        };
        #[cfg(not(feature = "gpu"))]
        let caster: Option<()> = gpu.as_ref().map(|g| match **g {});
        let cast_pass = |cast: BenchCast| -> Result<Vec<(CubeMap, CastCounts, f64)>> {
            match cast {
                BenchCast::Cpu(cast) => Ok(pool.install(|| {
                    sample
                        .par_iter()
                        .map(|&v| {
                            let t = Instant::now();
                            let (faces, counts) = baker.cube_map_with(v, cast);
                            (faces, counts, t.elapsed().as_secs_f64())
                        })
                        .collect()
                })),
                #[cfg(feature = "gpu")]
                BenchCast::Gpu => {
                    let caster = caster.as_ref().context("no GPU context")?;
                    let out = pool.install(|| gpu_pass(&baker, caster, &sample))?;
                    let (rays, again) = out
                        .iter()
                        .fold((0, 0), |(r, a), (_, c, _)| (r + c.rays, a + c.recast));
                    eprintln!(
                        "{name}: GPU cast: {again} of {rays} sub-rays cast again on the CPU \
                         (pixels the device's rounding could have decided otherwise)"
                    );
                    Ok(out)
                }
                #[cfg(not(feature = "gpu"))]
                BenchCast::Gpu => {
                    let _ = &caster;
                    anyhow::bail!("built without the `gpu` feature")
                }
            }
        };
        let mut passes: Vec<Option<Vec<(CubeMap, CastCounts, f64)>>> = vec![None; casts.len()];
        for _ in 0..a.repeat.max(1) {
            for (slot, &cast) in passes.iter_mut().zip(&casts) {
                let m = cast_pass(cast)?;
                if slot
                    .as_ref()
                    .is_none_or(|best| pass_seconds(&m) < pass_seconds(best))
                {
                    *slot = Some(m);
                }
            }
        }
        let mut first: Option<(Vec<CubeMap>, f64)> = None;
        for (maps, &cast) in passes.into_iter().flatten().zip(&casts) {
            let faces: Vec<CubeMap> = maps.iter().map(|m| m.0.clone()).collect();
            let ray_s: f64 = maps.iter().map(|m| m.2).sum();
            let (differ, pixels, dv) = match &first {
                Some((f, _)) => cast_difference(f, &faces, scene.bake.supersampling.pow(2)),
                None => (0, 1, 0.0),
            };
            let ray_vs_first = first.as_ref().map_or(1.0, |f| ray_s / f.1);
            let mut nm_fit = None;
            for &method in &methods {
                // Fitted `--repeat` times too, the fastest pass kept (the trees are the same).
                let fit_pass = || -> Vec<_> {
                    pool.install(|| {
                        maps.par_iter()
                            .map(|(faces, _, _)| {
                                let t = Instant::now();
                                let (trees, st) = baker.fit_faces(faces, method);
                                (trees, st, t.elapsed().as_secs_f64())
                            })
                            .collect()
                    })
                };
                let mut fits = fit_pass();
                for _ in 1..a.repeat.max(1) {
                    let again = fit_pass();
                    if pass_seconds(&again) < pass_seconds(&fits) {
                        fits = again;
                    }
                }
                let mut totals = Totals::default();
                let mut trees = Vec::with_capacity(fits.len());
                for ((_, counts, rs), (tr, st, fs)) in maps.iter().zip(fits) {
                    totals += Totals {
                        vertices: 1,
                        rays: counts.rays,
                        traversals: counts.traversals,
                        recast: counts.recast,
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
                if let BenchCast::Cpu(c) = cast {
                    stats.cast = c;
                } else {
                    stats.backend = bspvt_bake::Backend::Gpu;
                }
                if method == SplitMethod::NelderMead {
                    nm_fit = Some(stats.fit_thread_seconds_per_vertex);
                }
                rows.push(BenchRow {
                    scene: name.clone(),
                    scene_vertices: n,
                    sampled: k,
                    method,
                    cast: cast.name().to_string(),
                    fit_time_vs_nelder_mead: nm_fit
                        .map(|b| stats.fit_thread_seconds_per_vertex / b),
                    stats,
                    cast_pixels_differing: differ as f64 / pixels.max(1) as f64,
                    cast_mean_abs_dv: dv / pixels.max(1) as f64,
                    ray_time_vs_first_cast: ray_vs_first,
                });
            }
            if first.is_none() {
                first = Some((faces, ray_s));
            }
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
        "| scene | vertices | cast | split | rays/vtx | BVH traversals/vtx | Mrays/s/thread | rays ms/vtx/thread | rays vs first cast | fit ms/vtx/thread | total ms/vtx/thread | fit vs NM | leaves/vtx | bytes/vtx | cast ΔV pixels | cast mean abs ΔV | mean abs ΔV (fit) | misclassified |"
    );
    println!(
        "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    let name = |v: serde_json::Result<serde_json::Value>| {
        v.ok()
            .and_then(|v| v.as_str().map(String::from))
            .unwrap_or_default()
    };
    for r in rows {
        let s = &r.stats;
        println!(
            "| {} | {} | {} | {} | {:.0} | {:.0} | {:.2} | {:.3} | {:.3}× | {:.3} | {:.3} | {} | {:.1} | {:.1} | {:.2e} | {:.2e} | {:.5} | {:.5} |",
            r.scene,
            r.scene_vertices,
            r.cast,
            name(serde_json::to_value(r.method)),
            s.rays_per_vertex,
            s.traversals_per_vertex,
            s.rays_per_thread_second * 1e-6,
            s.ray_thread_seconds_per_vertex * 1e3,
            r.ray_time_vs_first_cast,
            s.fit_thread_seconds_per_vertex * 1e3,
            s.thread_seconds_per_vertex * 1e3,
            r.fit_time_vs_nelder_mead
                .map(|x| format!("{x:.3}×"))
                .unwrap_or_else(|| "–".into()),
            s.leaves_per_vertex,
            s.bytes_per_vertex,
            r.cast_pixels_differing,
            r.cast_mean_abs_dv,
            s.mean_abs_visibility_error,
            s.misclassified_pixel_fraction,
        );
    }
    if rows.iter().any(|r| r.cast == "gpu") {
        println!(
            "\ngpu rows: rays are timed in wall-clock seconds of the GPU cast (ray generation on the \
             threads, upload, cast, read-back), not thread-seconds; \"Mrays/s/thread\" is rays per \
             wall-clock second, \"rays vs first cast\" compares those seconds with the first \
             cast's thread-seconds."
        );
    }
}

/// Seconds of a timed pass: the sum of its items' times (the last field).
fn pass_seconds<A, B>(pass: &[(A, B, f64)]) -> f64 {
    pass.iter().map(|x| x.2).sum()
}
