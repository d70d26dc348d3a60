//! `bspvt`: the command line of the bspvt client. One file per command; clap lives here (and
//! in the lab's argument structs), never in the client library.

mod animate;
#[cfg(feature = "service")]
mod bench_view;
mod demo;
mod embedded;
mod frame_args;
mod gif;
mod inspect;
mod methods;
mod progress;
mod render;
mod view;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "bspvt", version, about = "bspvt client")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List every rendering method: its name, what it does and what it needs.
    Methods,
    /// Decode a bake file, check it against its scene, and report (or export) light visibility.
    Inspect(inspect::InspectArgs),
    /// The main job: an embedded service bakes the built-in scene, the client streams its trees
    /// and shades while the light moves (a window if there is a display, else frames + GIF).
    Demo(demo::DemoArgs),
    /// Open a window on a scene from a service (URL or id) or a local scene (baked by an
    /// embedded service), shading while its trees stream in.
    View(view::ViewArgs),
    /// Headless: stream a scene and render the light moving along its path (PNG frames, GIF,
    /// stats.json), through the viewer's own code path.
    Animate(animate::AnimateArgs),
    /// Measure a viewer's start on a finished bake served on loopback: time to the first
    /// frame and to full quality, bytes fetched, fps while the light moves.
    #[cfg(feature = "service")]
    BenchView(bench_view::BenchViewArgs),
    /// Run the baking service (the same as `bspvt-server serve`).
    #[cfg(feature = "service")]
    Serve(Box<bspvt_server::service::config::ServeArgs>),
    /// Render images of a scene with any method (`bspvt methods`): one frame, or a sequence
    /// while the light moves.
    Render(render::RenderArgs),
    /// Measure shading speed on real meshes (kernel µs/vertex and frame times).
    Bench(bspvt_lab::bench::BenchArgs),
    /// Every method's frame time on one scene, as a ratio to a calibration workload run
    /// alongside, against a committed baseline (`--baseline`): a slowdown shows whatever the
    /// machine's speed.
    BenchMethods(bspvt_lab::method_bench::BenchMethodsArgs),
    /// Speed and error of rt-penumbra (paper 003) and the shadow-map baselines against Monte
    /// Carlo area-light shadows (`ltc-exact`), with the equal-RMSE speed-up and cases that
    /// break the paper's assumptions (results.csv/.md/.json and images in --out).
    BenchPenumbra(bspvt_lab::penumbra_bench::BenchPenumbraArgs),
    /// Error against run time of every method on real scenes, against converged Monte Carlo
    /// ground truth: report.md, results.csv, log-log plots and image grids in --out.
    Report(bspvt_lab::report::ReportArgs),
    /// Speed and error of the spherical-Gaussian environment lighting (paper 001: screen-space
    /// and exact SSDF, unshadowed) against the Monte Carlo environment reference, per image
    /// size and lobe count (results.json/.md and images in --out).
    BenchSg(bspvt_lab::sg_bench::BenchSgArgs),
    /// BSPVT per vertex and frames on the GPU against the CPU, same run (adapter, µs, ms).
    BenchGpu(bspvt_lab::gpu_bench::BenchGpuArgs),
    /// Speed and error of the environment through the baked trees (`bspvt-env`) for k pieces
    /// per cube face, against SG with the screen-space SSDF and the unshadowed sky, all
    /// against the Monte Carlo environment reference (results.json/.md and images in --out).
    BenchSky(bspvt_lab::sky_bench::BenchSkyArgs),
    /// What adaptive refinement (`bake.refine`) buys on rooms of large flat polygons: error
    /// against Monte Carlo, vertices, bake seconds and bytes, against uniform subdivision at
    /// the same vertex count (results.md/.json in --out).
    BenchRefine(bspvt_lab::refine_bench::BenchRefineArgs),
    /// Fit the LTC table of GGX (regenerates `assets/ltc/ggx.json`).
    LtcFit(bspvt_lab::ltc_fit::FitArgs),
    /// Write a Mitsuba 3 scene that renders the same image (independent cross-check).
    ExportMitsuba(bspvt_lab::mitsuba::ExportArgs),
}

#[allow(unsafe_code)]
fn main() -> std::process::ExitCode {
    // SAFETY: the first statement of `main`: no other thread exists yet.
    unsafe { bspvt_client::gpu::quiet_headless_vulkan() };
    let command = Cli::parse().command;
    #[cfg(feature = "service")]
    let serving = matches!(command, Command::Serve(_));
    #[cfg(not(feature = "service"))]
    let serving = false;
    if !serving {
        // The library's warnings (a moving scene rendered at t = 0, a method that fell back
        // to LTC, …) go to stderr; RUST_LOG overrides the level. `serve` sets up the
        // service's own logging.
        let _ = tracing_subscriber::fmt()
            .with_env_filter(
                tracing_subscriber::EnvFilter::try_from_default_env()
                    .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
            )
            .with_writer(std::io::stderr)
            .log_internal_errors(false)
            .without_time()
            .with_target(false)
            .try_init();
    }
    let result = match command {
        Command::Methods => {
            methods::run();
            Ok(())
        }
        Command::Inspect(a) => inspect::run(a),
        Command::Demo(a) => demo::run(&a),
        Command::View(a) => view::run(&a),
        Command::Animate(a) => animate::run(&a),
        #[cfg(feature = "service")]
        Command::BenchView(a) => bench_view::run(&a),
        #[cfg(feature = "service")]
        Command::Serve(a) => bspvt_server::service::serve_command(&a),
        Command::Render(a) => render::run(a),
        Command::Bench(a) => bspvt_lab::bench::run(&a),
        Command::BenchMethods(a) => bspvt_lab::method_bench::run(&a),
        Command::BenchPenumbra(a) => bspvt_lab::penumbra_bench::run(&a).map(|r| {
            eprintln!(
                "bench-penumbra: {} case(s) written to {}",
                r.cases.len(),
                a.out.display()
            );
        }),
        Command::Report(a) => bspvt_lab::report::run(&a).map(|r| {
            eprintln!(
                "report: {} scene(s) in {:.0} s, written to {}",
                r.scenes.len(),
                r.seconds,
                a.out.join("report.md").display()
            );
        }),
        Command::BenchGpu(a) => bspvt_lab::gpu_bench::run(&a).map(|r| {
            eprintln!("bench-gpu: {} row(s) on {}", r.rows.len(), r.adapter);
        }),
        Command::BenchSg(a) => bspvt_lab::sg_bench::run(&a).map(|r| {
            eprintln!(
                "bench-sg: {} configuration(s) written to {}",
                r.rows.len(),
                a.out.display()
            );
        }),
        Command::BenchSky(a) => bspvt_lab::sky_bench::run(&a).map(|r| {
            eprintln!(
                "bench-sky: {} configuration(s) written to {}",
                r.rows.len(),
                a.out.display()
            );
        }),
        Command::BenchRefine(a) => bspvt_lab::refine_bench::run(&a).map(|r| {
            eprintln!(
                "bench-refine: {} scene(s) written to {}",
                r.len(),
                a.out.join("results.md").display()
            );
        }),
        Command::LtcFit(a) => bspvt_lab::ltc_fit::run(&a),
        Command::ExportMitsuba(a) => bspvt_lab::mitsuba::run(&a),
    };
    bspvt_proto::error::exit_code(result)
}
