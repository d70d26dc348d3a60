//! `bspvt demo`, the README's main command: an embedded service on loopback with its data in a
//! local folder, the built-in scene submitted to it, a progress bar while it bakes, the trees
//! streamed in (and cached), and the scene shaded while the light moves — in a window when a
//! display is available, otherwise headless (frames, an animated preview, timings).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use bspvt_proto::api::JobState;

use crate::animate::{self, AnimateReport, PathOptions, StageClock, render_path};
use crate::frame_args::{ConnectArgs, EnvArgs, method, method_values};
use crate::gif::Preview;
use bspvt_client::session::connect::connect;
use bspvt_client::viewer::{self, ViewerOptions};

#[derive(clap::Args, Debug)]
pub(crate) struct DemoArgs {
    /// Output folder (service data, client cache, frames).
    #[arg(long, default_value = "out/demo")]
    pub(crate) out: PathBuf,
    /// Scene to bake and show (scene file or builtin:NAME).
    #[arg(long, default_value = "builtin:plate")]
    pub(crate) scene: String,
    /// Frames of the light's path (headless).
    #[arg(long, default_value_t = 48)]
    pub(crate) frames: usize,
    /// Frame width in pixels (the height from the scene camera's aspect ratio, else square).
    #[arg(long, default_value_t = 512)]
    pub(crate) size: u32,
    /// Never open a window, even when a display is available.
    #[arg(long)]
    pub(crate) headless: bool,
    /// Rendering method (`bspvt methods`): e.g. `bspvt-env` for the scene's sky and lamps.
    #[arg(long, default_value = "bspvt", value_parser = method_values())]
    pub(crate) method: String,
    #[command(flatten)]
    pub(crate) env: EnvArgs,
    #[command(flatten)]
    pub(crate) backend: crate::frame_args::BackendArgs,
}

/// Whether a window can be opened (an X display; the viewer is X11).
fn display_available() -> bool {
    std::env::var_os("DISPLAY").is_some_and(|d| !d.is_empty())
}

pub(crate) fn run(a: &DemoArgs) -> Result<()> {
    let started = Instant::now();
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let args = ConnectArgs {
        source: Some(a.scene.clone()),
        mesh: None,
        server: None,
        api_key: None,
        data_dir: a.out.join("service"),
        cache_dir: a.out.join("cache"),
        no_cache: false,
    };
    let mut clock = StageClock::new(started);
    let opts = args.options();
    let connected = connect(&opts)?;
    clock.stages.connect_ms = clock.lap();
    let served = &connected.served;
    println!(
        "{} on the embedded service {} (data in {}): scene {}{}",
        a.scene,
        served.remote.base(),
        args.data_dir.display(),
        served.id,
        if served.submitted {
            ", submitted"
        } else {
            ", baked before: reusing it"
        }
    );
    // The service's browser pages (bake progress, submissions; the WebGPU viewer), up while
    // this runs.
    let base = served.remote.base().trim_end_matches('/');
    println!("dashboard: {base}/  viewer: {base}/view/{}", served.id);
    let height = connected.scene.camera.image_height(a.size, None);
    let mut session = connected.session(&opts, a.size, height)?;
    clock.stages.session_ms = clock.lap();
    session.method = method(&a.method)?;
    session.set_env(a.env.options(&connected.scene)?);
    session.set_backend(a.backend.resolve()?);
    clock.stages.setup_ms = clock.lap();
    let mut report = AnimateReport::new(&connected, &session, a.frames);
    // The first frame right away, with whatever trees are here (unshadowed where none are).
    report.first_frame(&mut session, clock, &a.out.join("first.png"), 1.0)?;
    println!(
        "first shaded frame after {:.0} ms ({:.0} % of the trees; {})",
        report.first_frame_ms,
        report.first_frame_trees * 100.0,
        report.first_frame_stages
    );

    // Bake progress, from the service's status as the fetcher relays it.
    let status = served.remote.status(&served.id)?;
    if status.state != JobState::Done {
        let bar = indicatif::ProgressBar::new(u64::from(status.vertices_total)).with_style(
            indicatif::ProgressStyle::with_template(
                "baking {bar:40} {pos}/{len} vertices  {per_sec}  ETA {eta}  {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        // Without a terminal the bar is hidden: print a line every 10 % instead.
        let mut printed = 0;
        loop {
            session.poll();
            if let Some(s) = &session.streamed.status {
                bar.set_position(s.vertices_done);
                let tenth = (s.progress * 10.0).floor() as u32;
                if bar.is_hidden() && tenth > printed {
                    printed = tenth;
                    println!(
                        "baking: {:.0} % ({} of {} vertices{})",
                        s.progress * 100.0,
                        s.vertices_done,
                        s.vertices_total,
                        s.eta_s
                            .map(|e| format!(", ETA {e:.0} s"))
                            .unwrap_or_default()
                    );
                }
                if matches!(
                    s.state,
                    JobState::Done | JobState::Failed | JobState::Cancelled
                ) {
                    break;
                }
            }
            bar.set_message(format!(
                "trees here: {:.0} %",
                session.streamed.fraction() * 100.0
            ));
            if !session.streaming() {
                break;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        bar.finish();
    }
    session.wait_complete();
    if !session.streamed.complete() {
        anyhow::bail!(
            "the trees did not arrive: {}",
            session
                .streamed
                .failed
                .as_deref()
                .unwrap_or("the stream ended early")
        );
    }
    if session.method.needs().sky_trees_for(session.scene()) {
        println!("baking the sky's trees (every direction above each vertex, once, cached)…");
        let t = Instant::now();
        session.wait_sky();
        if !session.sky_ready() {
            anyhow::bail!("the sky's trees could not be baked (see the warning above)");
        }
        println!("sky trees ready after {:.1} s", t.elapsed().as_secs_f64());
    }
    report.full_trees_ms = Some(started.elapsed().as_secs_f64() * 1e3);
    animate::fill_stream_counters(&mut report, &session);
    report.tree_bytes_before_full = Some(report.tree_bytes);
    if let Some(s) = &session.streamed.status {
        println!(
            "baked: {} vertices, {} bytes of trees ({:.1} B/vertex)",
            s.vertices_total,
            s.sizes.stored_bytes,
            s.sizes.stored_bytes as f64 / f64::from(s.vertices_total.max(1))
        );
    }

    if display_available() && !a.headless {
        session.path_t = Some(0.0);
        let r = viewer::run(
            &mut session,
            &ViewerOptions {
                title: format!("bspvt demo — {}", a.scene),
                max_frames: None,
                note: None,
                guides: true,
                screenshot_dir: a.out.join("screenshots"),
                source: viewer::SceneSource {
                    scene: Some(a.scene.clone()),
                    mesh: None,
                },
                save_view: None,
            },
            started,
        )?;
        println!("{} frames in the window, {:.1} fps", r.frames, r.mean_fps);
        return Ok(());
    }

    let frames_dir = a.out.join("frames");
    std::fs::create_dir_all(&frames_dir)
        .with_context(|| format!("cannot create {}", frames_dir.display()))?;
    let mut preview = Preview::default();
    let times = render_path(
        &mut session,
        &mut PathOptions {
            frames: a.frames,
            exposure: 1.0,
            frames_dir: Some(&frames_dir),
            preview: Some(&mut preview),
            progressive: false,
        },
        |_, _| {},
    )?;
    report.ms_per_frame = times.median();
    report.ms_per_frame_mean = times.mean();
    report.fps = 1e3 / report.ms_per_frame.max(1e-9);
    let gif = a.out.join("preview.gif");
    preview.save(&gif, 60)?;
    std::fs::write(
        a.out.join("stats.json"),
        serde_json::to_vec_pretty(&report)?,
    )?;
    animate::print_summary(&report, &frames_dir, true);
    println!(
        "no display: wrote {} frames and {} (set DISPLAY for the window)",
        a.frames,
        gif.display()
    );
    Ok(())
}
