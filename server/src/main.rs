//! `bspvt-server`: the bake engine's command line.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use anyhow::{Context, Result};
use bspvt_bake::stats::BakeStats;
use bspvt_bake::{Baker, CastMode};
use bspvt_proto::SplitMethod;
use bspvt_proto::scene::open_scene;
use bspvt_server::bench::{self, BenchArgs};
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

#[derive(Parser)]
#[command(name = "bspvt-server", version, about = "bspvt bake engine")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Bake a scene's visibility trees to a file.
    Bake(BakeArgs),
    /// Measure the bake on real meshes: rays and fit separately, every split method.
    Bench(BenchArgs),
    /// Run the HTTP baking service (docs/service.md).
    Serve(Box<bspvt_server::service::ServeArgs>),
    /// Bake chunks for the distributed service: leases them from its PostgreSQL database and
    /// writes them to its store (docs/service.md, "Scale-out").
    Worker(Box<bspvt_server::service::WorkerArgs>),
    /// Measure the distributed shape's coordination cost on a PostgreSQL database.
    BenchCluster(bspvt_server::service::ClusterBenchArgs),
}

#[derive(Clone, Copy, ValueEnum)]
enum CastArg {
    /// Nearby rays' blockers and a walk over the mesh answer most occluded rays.
    Adaptive,
    /// Every ray the culling leaves is answered by its candidate list or a BVH traversal.
    Full,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum BackendArg {
    /// Rays on the CPU threads (`--cast` says how).
    Cpu,
    /// Rays in a wgpu compute shader, trees fitted on the CPU threads meanwhile.
    Gpu,
}

#[derive(Clone, Copy, ValueEnum)]
enum SplitArg {
    Default,
    Exhaustive,
    NelderMead,
}

#[derive(clap::Args)]
struct BakeArgs {
    /// Scene file (JSON) or `builtin:NAME` (e.g. builtin:plate).
    scene: Option<String>,
    /// Bake a bare mesh (.glb/.gltf/.obj/.ply) with the default scene around it.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Output bake file.
    #[arg(long)]
    out: PathBuf,
    /// Cube-map face resolution, pixels a side (default: the scene's `bake.face_res`, 64).
    #[arg(long)]
    face_res: Option<u32>,
    /// Leaf tolerance ε: a node is a leaf when its squared deviation is at most ε × the face's
    /// pixel count (default: the scene's, 1e-3); smaller is closer and bigger (docs/bake.md).
    #[arg(long)]
    epsilon: Option<f32>,
    /// s × s rays per pixel, stored as fractional visibility (default: the scene's, 1). The
    /// fit's ε then lets more through: lower it with it (docs/benchmarks.md, "Two-sided
    /// surfaces per vertex").
    #[arg(long)]
    supersampling: Option<u32>,
    /// How the fit chooses split lines (default: the scene's, `default`).
    #[arg(long, value_enum)]
    split: Option<SplitArg>,
    /// How rays are cast (the same cube maps and bytes either way; docs/bake.md).
    #[arg(long, value_enum, default_value = "adaptive")]
    cast: CastArg,
    /// Where rays are cast: the CPU threads, or the GPU (docs/bake.md, "The GPU backend");
    /// `gpu` fails when no GPU adapter is found.
    #[arg(long, value_enum, default_value = "cpu")]
    backend: BackendArg,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Write bake statistics (JSON) here.
    #[arg(long)]
    stats: Option<PathBuf>,
}

#[allow(unsafe_code)]
fn main() -> std::process::ExitCode {
    // SAFETY: the first statement of `main`: no other thread exists yet.
    #[cfg(feature = "gpu")]
    unsafe {
        bspvt_raytrace::gpu::quiet_headless_vulkan()
    };
    let result = match Cli::parse().command {
        Command::Bake(a) => bake(a),
        Command::Bench(a) => bench::run(&a),

        Command::Serve(a) => bspvt_server::service::serve_command(&a),
        Command::Worker(a) => bspvt_server::service::worker_command(&a),
        Command::BenchCluster(a) => bspvt_server::service::cluster_bench_command(&a),
    };
    bspvt_proto::error::exit_code(result)
}

#[cfg(feature = "gpu")]
use bspvt_bake::gpu_cast::GpuContext;

/// The GPU context, or the "no adapter" error.
#[cfg(feature = "gpu")]
fn gpu_context() -> Result<std::sync::Arc<GpuContext>> {
    Ok(std::sync::Arc::new(GpuContext::new()?))
}

#[cfg(feature = "gpu")]
fn bake_gpu(
    pool: &rayon::ThreadPool,
    baker: &Baker,
    ctx: &std::sync::Arc<GpuContext>,
    progress: &(dyn Fn(u64, u64) + Sync),
    cancel: &AtomicBool,
) -> Result<bspvt_bake::BakeOutput> {
    let caster = baker.gpu_caster(ctx.clone())?;
    Ok(pool.install(|| baker.bake_all_gpu(&caster, progress, cancel))?)
}

/// Stands in for the GPU context in a build without the `gpu` feature.
#[cfg(not(feature = "gpu"))]
enum GpuContext {}

#[cfg(not(feature = "gpu"))]
impl GpuContext {
    fn describe(&self) -> String {
        match *self {}
    }
}

#[cfg(not(feature = "gpu"))]
fn gpu_context() -> Result<std::sync::Arc<GpuContext>> {
    anyhow::bail!("this bspvt-server was built without the `gpu` feature: use --backend cpu")
}

#[cfg(not(feature = "gpu"))]
fn bake_gpu(
    _: &rayon::ThreadPool,
    _: &Baker,
    ctx: &std::sync::Arc<GpuContext>,
    _: &(dyn Fn(u64, u64) + Sync),
    _: &AtomicBool,
) -> Result<bspvt_bake::BakeOutput> {
    match **ctx {}
}

fn bake(a: BakeArgs) -> Result<()> {
    let started = std::time::Instant::now();
    let mut scene = open_scene(a.scene.as_deref(), a.mesh.as_deref())?;
    for w in &scene.warnings {
        tracing::warn!("{w}");
    }
    let b = &mut scene.bake;
    if let Some(r) = a.face_res {
        b.face_res = r;
    }
    if let Some(e) = a.epsilon {
        b.epsilon = e;
    }
    if let Some(s) = a.supersampling {
        b.supersampling = s;
    }
    if let Some(s) = a.split {
        b.split = match s {
            SplitArg::Default => SplitMethod::Default,
            SplitArg::Exhaustive => SplitMethod::Exhaustive,
            SplitArg::NelderMead => SplitMethod::NelderMead,
        };
    }
    scene.validate()?;
    if let Some(r) = bspvt_bake::refine::refine_scene(&mut scene)? {
        eprintln!(
            "refined {} → {} vertices ({} splits{}) in {:.2} s",
            r.vertices_before,
            r.vertices_after,
            r.splits,
            if r.budget_reached {
                ", vertex budget reached"
            } else {
                ""
            },
            r.seconds
        );
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .context("cannot start the worker threads")?;
    let threads = pool.current_num_threads();
    let build_start = std::time::Instant::now();
    let mut baker = Baker::new(&scene);
    let prepared = build_start.elapsed().as_secs_f64();
    baker.set_cast(match a.cast {
        CastArg::Adaptive => CastMode::Adaptive,
        CastArg::Full => CastMode::Full,
    });
    let gpu = match a.backend {
        BackendArg::Cpu => None,
        BackendArg::Gpu => Some(gpu_context()?),
    };
    let n = baker.header().vertex_count as u64;
    eprintln!(
        "baking {n} vertices, {} triangles, {}² faces, ε = {}, {} thread(s), rays on {} (BVHs and mesh walk built in {prepared:.2} s)",
        scene.mesh.triangles.len(),
        scene.bake.face_res,
        scene.bake.epsilon,
        threads,
        gpu.as_ref().map_or("the CPU".to_string(), |g| g.describe()),
    );
    let bar = ProgressBar::new(n).with_style(
        ProgressStyle::with_template(
            "{bar:40} {pos}/{len} vertices  {per_sec}  elapsed {elapsed_precise}  ETA {eta_precise}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let cancel = AtomicBool::new(false);
    let progress = |done, _| bar.set_position(done);
    let out = match &gpu {
        None => pool.install(|| baker.bake_all(&progress, &cancel))?,
        Some(ctx) => bake_gpu(&pool, &baker, ctx, &progress, &cancel)?,
    };
    bar.finish();
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(&a.out, &out.bytes)
        .with_context(|| format!("cannot write {}", a.out.display()))?;
    let stats = BakeStats::new(&out, threads);
    eprintln!(
        "wrote {} ({} bytes, {:.1} B/vertex, {:.1} leaves/vertex) in {:.2} s ({:.3} ms/vertex/core of the whole command's wall clock); {:.3} ms/vertex/thread (rays {:.3}, fit {:.3}); mean |ΔV| {:.5}, misclassified {:.5}",
        a.out.display(),
        stats.bytes,
        stats.bytes_per_vertex,
        stats.leaves_per_vertex,
        stats.seconds,
        started.elapsed().as_secs_f64() * threads as f64 / n.max(1) as f64 * 1e3,
        stats.thread_seconds_per_vertex * 1e3,
        stats.ray_thread_seconds_per_vertex * 1e3,
        stats.fit_thread_seconds_per_vertex * 1e3,
        stats.mean_abs_visibility_error,
        stats.misclassified_pixel_fraction,
    );
    if let Some(p) = &a.stats {
        std::fs::write(p, serde_json::to_string_pretty(&stats)?)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}
