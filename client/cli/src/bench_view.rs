//! `bspvt bench-view`: what a viewer user waits for and gets, on a finished bake served on
//! loopback. Each trial is the viewer's start-up path without the window: connect (status,
//! scene), the session (G-buffer, camera's vertices), frames drawn continuously while the
//! trees stream in (view-first order), then the light moving along its path at full quality.
//! Cold trials start with an empty client cache, warm ones with the cache the previous trial
//! filled. Unshadowed LTC frames in the same run are the baseline.

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use crate::frame_args::ConnectArgs;
use anyhow::{Context, Result, bail};
use bspvt_proto::api::JobState;
use bspvt_server::service::Background;
use bspvt_server::service::config::Config;
use serde::Serialize;

use crate::animate::{PathOptions, render_path};
use bspvt_client::method::registry;
use bspvt_client::render::renderer::Mode;
use bspvt_client::session::connect::connect;
use bspvt_client::stream::remote::Remote;

#[derive(clap::Args, Debug)]
pub(crate) struct BenchViewArgs {
    /// Mesh to serve (default: the bunny from $BSPVT_ASSETS/meshes or ../shared/assets/meshes).
    #[arg(long)]
    pub(crate) mesh: Option<PathBuf>,
    /// Service data and client caches (a bake made before is reused).
    #[arg(long, default_value = "out/bench-view")]
    pub(crate) dir: PathBuf,
    #[arg(long, default_value_t = 512)]
    pub(crate) size: u32,
    /// Frames along the light's path per mode.
    #[arg(long, default_value_t = 64)]
    pub(crate) frames: usize,
    /// Cold (empty cache) trials; each is followed by a warm one.
    #[arg(long, default_value_t = 3)]
    pub(crate) trials: usize,
    #[arg(long)]
    pub(crate) json: Option<PathBuf>,
}

#[derive(Clone, Debug, Serialize)]
pub(crate) struct Trial {
    pub(crate) cache: &'static str,
    /// Connect: status and scene (fetched or from the cache).
    pub(crate) connect_ms: f64,
    /// The first frame drawn (with whatever trees were here).
    pub(crate) first_frame_ms: f64,
    pub(crate) first_frame_trees: f64,
    /// The first frame in which every vertex the camera sees had its trees.
    pub(crate) view_ready_ms: f64,
    /// The first frame with every tree.
    pub(crate) full_ms: f64,
    pub(crate) scene_bytes: u64,
    pub(crate) tree_bytes_at_view_ready: u64,
    pub(crate) tree_bytes_at_full: u64,
    pub(crate) frames_while_streaming: u64,
}

#[derive(Clone, Debug, Serialize)]
pub(crate) struct FrameRate {
    pub(crate) method: &'static str,
    pub(crate) mode: &'static str,
    pub(crate) ms_per_frame: f64,
    pub(crate) fps: f64,
}

#[derive(Clone, Debug, Serialize)]
pub(crate) struct Report {
    pub(crate) mesh: String,
    pub(crate) vertices: usize,
    pub(crate) visible_vertices: usize,
    pub(crate) stream_bytes: u64,
    pub(crate) size: u32,
    pub(crate) threads: usize,
    pub(crate) trials: Vec<Trial>,
    pub(crate) frame_rates: Vec<FrameRate>,
}

pub(crate) fn run(a: &BenchViewArgs) -> Result<()> {
    let mesh = a
        .mesh
        .clone()
        .unwrap_or_else(|| bspvt_proto::paths::assets_dir().join("meshes/bunny.ply"));
    if !mesh.exists() {
        bail!(
            "{} not found (give --mesh or set BSPVT_ASSETS)",
            mesh.display()
        );
    }
    let mut cfg = Config::with_data_dir(a.dir.join("service"));
    cfg.addr = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
    let service = Background::start(cfg).context("cannot start the service")?;
    let base = format!("http://{}", service.addr);
    let mut args = ConnectArgs {
        source: None,
        mesh: Some(mesh.clone()),
        server: Some(base.clone()),
        api_key: None,
        data_dir: a.dir.join("client"),
        cache_dir: a.dir.join("cache"),
        no_cache: false,
    };
    // Submit (or find) the bake and wait for it: the benchmark is about a finished bake.
    let id = connect(&args.options())?.served.id;
    let remote = Remote::new(&base, None);
    let t = Instant::now();
    let mut shown = None;
    loop {
        let s = remote.status(&id)?;
        match s.state {
            JobState::Done => break,
            JobState::Failed | JobState::Cancelled => bail!("the bake stopped: {:?}", s.reason),
            _ => {
                let pct = (s.progress * 100.0).floor() as u32;
                if shown != Some(pct) {
                    shown = Some(pct);
                    eprintln!(
                        "baking {}: {pct} % ({:.0} s)",
                        mesh.display(),
                        t.elapsed().as_secs_f64()
                    );
                }
                std::thread::sleep(Duration::from_millis(500));
            }
        }
    }
    // From here on the source is the scene's URL, as `bspvt view URL` would be given.
    args.source = Some(format!("{base}/v1/scenes/{id}"));
    args.mesh = None;

    let mut trials = Vec::new();
    let mut report = None;
    for k in 0..a.trials.max(1) {
        for warm in [false, true] {
            if !warm {
                let _ = std::fs::remove_dir_all(&args.cache_dir);
            }
            let (trial, rates, info) = trial(&args, a, warm, k + 1 == a.trials.max(1) && warm)?;
            println!(
                "{} cache: connect {:.1} ms, first frame {:.1} ms ({:.0} % trees), view ready {:.1} ms ({} B), all trees {:.1} ms ({} B), {} frames drawn while streaming",
                trial.cache,
                trial.connect_ms,
                trial.first_frame_ms,
                trial.first_frame_trees * 100.0,
                trial.view_ready_ms,
                trial.tree_bytes_at_view_ready,
                trial.full_ms,
                trial.tree_bytes_at_full,
                trial.frames_while_streaming
            );
            trials.push(trial);
            if let Some(r) = rates {
                report = Some((r, info));
            }
        }
    }
    let (frame_rates, (vertices, visible_vertices)) = report.context("no frame rates")?;
    for r in &frame_rates {
        println!(
            "{} {} at {}²: median {:.2} ms/frame ({:.0} fps) while the light moves",
            r.method, r.mode, a.size, r.ms_per_frame, r.fps
        );
    }
    let stream_bytes = remote.status(&id)?.sizes.stored_bytes;
    let out = Report {
        mesh: mesh.display().to_string(),
        vertices,
        visible_vertices,
        stream_bytes,
        size: a.size,
        threads: rayon::current_num_threads(),
        trials,
        frame_rates,
    };
    if let Some(p) = &a.json {
        std::fs::write(p, serde_json::to_vec_pretty(&out)?)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    service.stop()
}

type TrialOut = (Trial, Option<Vec<FrameRate>>, (usize, usize));

fn trial(args: &ConnectArgs, a: &BenchViewArgs, warm: bool, rates: bool) -> Result<TrialOut> {
    let started = Instant::now();
    let opts = args.options();
    let connected = connect(&opts)?;
    let connect_ms = started.elapsed().as_secs_f64() * 1e3;
    let mut s = connected.session(&opts, a.size, a.size)?;
    let visible = s.visible_vertices().to_vec();
    let counters = s.counters.clone().context("no fetcher")?;
    let bytes = || counters.tree_bytes.load(Ordering::Relaxed);
    let ms = || started.elapsed().as_secs_f64() * 1e3;
    let mut first = None;
    let mut view_ready = None;
    let mut full = None;
    let mut frames = 0u64;
    let deadline = Instant::now() + Duration::from_secs(300);
    while full.is_none() {
        if Instant::now() > deadline {
            bail!("the trees did not arrive in 300 s");
        }
        s.poll();
        // What the frame is drawn with is decided by the poll above.
        let ready = s.streamed.has_all(&visible);
        let complete = s.streamed.complete();
        let fraction = s.streamed.fraction();
        s.frame();
        frames += 1;
        let t = ms();
        first.get_or_insert((t, fraction));
        if ready && view_ready.is_none() {
            view_ready = Some((t, bytes()));
        }
        if complete {
            full = Some((t, bytes()));
        }
        if !s.streaming() && !complete {
            bail!("the stream stopped: {:?}", s.streamed.failed);
        }
    }
    let (first, view_ready, full) = (
        first.unwrap_or_default(),
        view_ready.unwrap_or_default(),
        full.unwrap_or_default(),
    );
    let trial = Trial {
        cache: if warm { "warm" } else { "cold" },
        connect_ms,
        first_frame_ms: first.0,
        first_frame_trees: first.1,
        view_ready_ms: view_ready.0,
        full_ms: full.0,
        scene_bytes: connected.scene_bytes_fetched,
        tree_bytes_at_view_ready: view_ready.1,
        tree_bytes_at_full: full.1,
        frames_while_streaming: frames,
    };
    let mut frame_rates = None;
    if rates {
        let mut out = Vec::new();
        for (method, mname) in [
            (registry::lookup("bspvt")?, "BSPVT"),
            (registry::lookup("ltc")?, "LTC unshadowed"),
        ] {
            for (mode, mode_name) in [(Mode::Vertex, "vertex"), (Mode::Pixel, "pixel")] {
                s.method = method;
                s.mode = mode;
                let times = render_path(
                    &mut s,
                    &mut PathOptions {
                        frames: a.frames,
                        exposure: 1.0,
                        frames_dir: None,
                        preview: None,
                        progressive: false,
                    },
                    |_, _| {},
                )?;
                let m = times.median();
                out.push(FrameRate {
                    method: mname,
                    mode: mode_name,
                    ms_per_frame: m,
                    fps: 1e3 / m.max(1e-9),
                });
            }
        }
        frame_rates = Some(out);
    }
    Ok((
        trial,
        frame_rates,
        (s.streamed.vertex_count(), visible.len()),
    ))
}
