//! `bspvt animate`: a moving light rendered headless through the viewer's own session — frames
//! (PNG), an animated preview (GIF) and timings (JSON).

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use serde::Serialize;

use crate::frame_args::{ConnectArgs, FrameArgs, method};
use crate::gif::Preview;
use bspvt_client::frame::stats::median;
use bspvt_client::render::renderer::Mode;
use bspvt_client::session::Session;
use bspvt_client::session::connect::{Connected, connect};

#[derive(clap::Args, Debug)]
pub(crate) struct AnimateArgs {
    #[command(flatten)]
    pub(crate) connect: ConnectArgs,
    /// Frames along the light's path (one full cycle).
    #[arg(long, default_value_t = 24)]
    pub(crate) frames: usize,
    /// Output folder: frame-NNN.png, first.png, preview.gif, stats.json.
    #[arg(long)]
    pub(crate) out: PathBuf,
    #[command(flatten)]
    pub(crate) frame: FrameArgs,
    /// GGX roughness α for every material (default: the scene's).
    #[arg(long)]
    pub(crate) roughness: Option<f32>,
    /// Draw each frame with the trees that have arrived so far instead of waiting for all.
    #[arg(long)]
    pub(crate) progressive: bool,
    /// Exposure before tone mapping.
    #[arg(long, default_value_t = 1.0)]
    pub(crate) exposure: f32,
    /// Do not write preview.gif.
    #[arg(long)]
    pub(crate) no_gif: bool,
}

/// What a headless run measured (`stats.json`).
#[derive(Clone, Debug, Default, Serialize)]
pub(crate) struct AnimateReport {
    pub(crate) scene_id: String,
    pub(crate) method: String,
    pub(crate) mode: String,
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) frames: usize,
    pub(crate) threads: usize,
    /// From the command's start to the first shaded frame (drawn with what had arrived).
    pub(crate) first_frame_ms: f64,
    /// Share of the vertices whose trees were in that first frame.
    pub(crate) first_frame_trees: f64,
    /// Where the time to the first frame went.
    pub(crate) first_frame_stages: Stages,
    /// From the command's start to every tree present (the first full-quality frame).
    pub(crate) full_trees_ms: Option<f64>,
    /// Median and mean time of one frame along the path (shading only, no file writing).
    pub(crate) ms_per_frame: f64,
    pub(crate) ms_per_frame_mean: f64,
    pub(crate) fps: f64,
    /// Scene bytes fetched (0 when it came from the cache).
    pub(crate) scene_bytes: u64,
    /// Tree-stream bytes fetched over the network, in all and before the trees were complete.
    pub(crate) tree_bytes: u64,
    pub(crate) tree_bytes_before_full: Option<u64>,
    pub(crate) chunks_fetched: u64,
    pub(crate) chunks_cached: u64,
    pub(crate) requests: u64,
    pub(crate) reconnects: u64,
    pub(crate) trees_complete: bool,
    pub(crate) stream_error: Option<String>,
}

/// The stages from the command's start to the first frame, each stage's own time (ms).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub(crate) struct Stages {
    /// Reaching the service (an embedded one started, a local scene submitted) and fetching
    /// the scene and its mesh.
    pub(crate) connect_ms: f64,
    /// The session: G-buffer, visible vertices, the tree fetcher started, cached trees read.
    pub(crate) session_ms: f64,
    /// The method and the backend set up (a GPU's device, buffers and pipelines).
    pub(crate) setup_ms: f64,
    /// The first frame drawn (after one poll of the stream).
    pub(crate) draw_ms: f64,
}

/// Marks the end of each stage of [`Stages`] as the command goes.
pub(crate) struct StageClock {
    started: Instant,
    last: Instant,
    pub(crate) stages: Stages,
}

impl StageClock {
    pub(crate) fn new(started: Instant) -> StageClock {
        StageClock {
            started,
            last: started,
            stages: Stages::default(),
        }
    }

    /// The ms since the previous mark.
    pub(crate) fn lap(&mut self) -> f64 {
        let now = Instant::now();
        let ms = (now - self.last).as_secs_f64() * 1e3;
        self.last = now;
        ms
    }
}

impl std::fmt::Display for Stages {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "connect {:.0} ms, session {:.0} ms, set-up {:.0} ms, draw {:.0} ms",
            self.connect_ms, self.session_ms, self.setup_ms, self.draw_ms
        )
    }
}

/// The frame sequence's settings.
pub(crate) struct PathOptions<'a> {
    pub(crate) frames: usize,
    pub(crate) exposure: f32,
    /// Folder for frame-NNN.png (`None`: not written).
    pub(crate) frames_dir: Option<&'a Path>,
    /// Collects a GIF preview.
    pub(crate) preview: Option<&'a mut Preview>,
    /// Keep applying stream updates between frames.
    pub(crate) progressive: bool,
}

/// Per-frame times of [`render_path`].
pub(crate) struct PathTimes {
    pub(crate) ms: Vec<f64>,
}

impl PathTimes {
    pub(crate) fn median(&self) -> f64 {
        median(&mut self.ms.clone())
    }

    pub(crate) fn mean(&self) -> f64 {
        self.ms.iter().sum::<f64>() / self.ms.len().max(1) as f64
    }
}

impl AnimateReport {
    /// A report on `session` (its method, mode and size) for `frames` frames.
    pub(crate) fn new(connected: &Connected, session: &Session, frames: usize) -> AnimateReport {
        let method = session.method;
        AnimateReport {
            scene_id: connected.served.id.clone(),
            method: method.name().to_string(),
            mode: match session.effective_mode() {
                Mode::Vertex => "vertex",
                Mode::Pixel => "pixel",
            }
            .into(),
            width: session.renderer.gbuffer.width,
            height: session.renderer.gbuffer.height,
            frames,
            threads: rayon::current_num_threads(),
            scene_bytes: connected.scene_bytes_fetched,
            ..AnimateReport::default()
        }
    }

    /// Draws the first frame at once, with whatever trees have arrived, records when (since
    /// `clock`'s start), the stages before it, and with how many trees, and saves it as `path`.
    pub(crate) fn first_frame(
        &mut self,
        session: &mut Session,
        mut clock: StageClock,
        path: &Path,
        exposure: f32,
    ) -> Result<()> {
        session.poll();
        let img = session.frame();
        clock.stages.draw_ms = clock.lap();
        self.first_frame_ms = clock.started.elapsed().as_secs_f64() * 1e3;
        self.first_frame_stages = clock.stages;
        self.first_frame_trees = session.streamed.fraction();
        img.save(path, exposure)
    }
}

/// Renders one cycle of the light's path, frame `k` at path time k / frames.
/// `on_frame` sees each frame's index and the session after it was drawn.
pub(crate) fn render_path(
    session: &mut Session,
    opts: &mut PathOptions,
    mut on_frame: impl FnMut(usize, &Session),
) -> Result<PathTimes> {
    let n = opts.frames.max(1);
    let mut ms = Vec::with_capacity(n);
    for k in 0..n {
        if opts.progressive {
            session.poll();
        }
        session.path_t = Some(k as f64 / n as f64);
        session.invalidate();
        let t = Instant::now();
        let img = session.frame();
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        on_frame(k, session);
        if let Some(dir) = opts.frames_dir {
            img.save(&dir.join(format!("frame-{k:03}.png")), opts.exposure)?;
        }
        if let Some(p) = opts.preview.as_deref_mut() {
            p.push(&img, opts.exposure);
        }
    }
    Ok(PathTimes { ms })
}

/// Fills the counters of `report` from the session's fetcher.
pub(crate) fn fill_stream_counters(report: &mut AnimateReport, session: &Session) {
    if let Some(c) = &session.counters {
        report.tree_bytes = c.tree_bytes.load(Ordering::Relaxed);
        report.chunks_fetched = c.chunks_fetched.load(Ordering::Relaxed);
        report.chunks_cached = c.chunks_cached.load(Ordering::Relaxed);
        report.requests = c.requests.load(Ordering::Relaxed);
        report.reconnects = c.reconnects.load(Ordering::Relaxed);
    }
    report.trees_complete = session.streamed.complete();
    report.stream_error = session.streamed.failed.clone();
}

pub(crate) fn run(a: &AnimateArgs) -> Result<()> {
    let started = Instant::now();
    if a.frames == 0 {
        bail!("--frames must be at least 1");
    }
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let mut clock = StageClock::new(started);
    let opts = a.connect.options();
    let connected = connect(&opts)?;
    clock.stages.connect_ms = clock.lap();
    let f = &a.frame;
    let height = connected.scene.camera.image_height(f.width, f.height);
    let mut session = connected.session(&opts, f.width, height)?;
    clock.stages.session_ms = clock.lap();
    session.method = method(&f.method)?;
    session.mode = f.mode.into();
    session.set_env(f.env.options(&connected.scene)?);
    session.set_backend(f.backend.resolve()?);
    session.set_roughness(a.roughness);
    clock.stages.setup_ms = clock.lap();
    let mut report = AnimateReport::new(&connected, &session, a.frames);
    report.first_frame(&mut session, clock, &a.out.join("first.png"), a.exposure)?;

    let full_at = |s: &Session, report: &mut AnimateReport| {
        if report.full_trees_ms.is_none() && s.streamed.complete() {
            report.full_trees_ms = Some(started.elapsed().as_secs_f64() * 1e3);
            report.tree_bytes_before_full = s
                .counters
                .as_ref()
                .map(|c| c.tree_bytes.load(Ordering::Relaxed));
        }
    };
    full_at(&session, &mut report);
    // Only BSPVT frames need the trees; the other methods do not wait for them.
    let needs = session.method.needs();
    if !a.progressive && needs.sky_trees_for(&connected.scene) {
        session.wait_sky();
        if !session.sky_ready() {
            bail!("the sky's trees could not be baked (see the warning above)");
        }
    }
    if !a.progressive && needs.lamp_trees(&connected.scene) {
        session.wait_complete();
        full_at(&session, &mut report);
        if !session.streamed.complete() {
            bail!(
                "the trees did not arrive: {} (use --progressive to render with what arrived)",
                session
                    .streamed
                    .failed
                    .as_deref()
                    .unwrap_or("the stream ended early")
            );
        }
    }
    let mut preview = Preview::default();
    let mut opts = PathOptions {
        frames: a.frames,
        exposure: a.exposure,
        frames_dir: Some(&a.out),
        preview: (!a.no_gif).then_some(&mut preview),
        progressive: a.progressive,
    };
    let times = render_path(&mut session, &mut opts, |_, s| full_at(s, &mut report))?;
    report.ms_per_frame = times.median();
    report.ms_per_frame_mean = times.mean();
    report.fps = 1e3 / report.ms_per_frame.max(1e-9);
    fill_stream_counters(&mut report, &session);
    if !preview.is_empty() {
        preview.save(&a.out.join("preview.gif"), 60)?;
    }
    let stats = a.out.join("stats.json");
    std::fs::write(&stats, serde_json::to_vec_pretty(&report)?)
        .with_context(|| format!("cannot write {}", stats.display()))?;
    print_summary(&report, &a.out, false);
    Ok(())
}

/// Prints what `r` measured; the first frame's line unless `first_frame_told` (`demo` says it
/// as it happens), the time to all trees either way.
pub(crate) fn print_summary(r: &AnimateReport, out: &Path, first_frame_told: bool) {
    let all_trees = r
        .full_trees_ms
        .map(|t| format!("all trees after {t:.0} ms"));
    if !first_frame_told {
        println!(
            "first shaded frame after {:.0} ms ({:.0} % of the trees; {}){}",
            r.first_frame_ms,
            r.first_frame_trees * 100.0,
            r.first_frame_stages,
            all_trees.map(|t| format!("; {t}")).unwrap_or_default()
        );
    } else if let Some(t) = all_trees {
        println!("{t}");
    }
    println!(
        "{} frames at {}×{} while the light moves ({} {}): median {:.2} ms/frame ({:.0} fps) on {} threads",
        r.frames, r.width, r.height, r.method, r.mode, r.ms_per_frame, r.fps, r.threads
    );
    println!(
        "fetched {} tree bytes in {} chunk(s), {} chunk(s) from the cache, {} request(s), {} reconnect(s); frames in {}",
        r.tree_bytes,
        r.chunks_fetched,
        r.chunks_cached,
        r.requests,
        r.reconnects,
        out.display()
    );
    if let Some(e) = &r.stream_error {
        eprintln!("warning: the tree stream stopped: {e}");
    }
}
