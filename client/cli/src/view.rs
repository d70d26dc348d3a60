//! `bspvt view`: the interactive window on a streamed scene.

use std::time::Instant;

use anyhow::Result;

use crate::frame_args::{ConnectArgs, FrameArgs, method};
use bspvt_client::session::connect::connect;
use bspvt_client::viewer::{self, ViewerOptions};

#[derive(clap::Args, Debug)]
#[command(after_help = format!("Keys and mouse in the window (H shows them there too):\n{}", viewer::KEYS_HELP))]
pub(crate) struct ViewArgs {
    #[command(flatten)]
    pub(crate) connect: ConnectArgs,
    #[command(flatten)]
    pub(crate) frame: FrameArgs,
    /// Start with the light moving along its path (P toggles).
    #[arg(long)]
    pub(crate) moving: bool,
    /// Close the window after this many frames (scripted runs).
    #[arg(long)]
    pub(crate) max_frames: Option<u64>,
    /// Start without the grid, the axes and the light's gizmo (Tab toggles them).
    #[arg(long)]
    pub(crate) no_guides: bool,
    /// Where F12 writes screenshots (PNG).
    #[arg(long, default_value = "out/screenshots")]
    pub(crate) screenshot_dir: std::path::PathBuf,
    /// Where V writes the view (the scene file with the current camera and light)
    /// [default: SCENE.view.json beside a scene file, out/views/NAME.view.json otherwise].
    #[arg(long)]
    pub(crate) save_view: Option<std::path::PathBuf>,
    /// Print where things stood when the window closed (method, mode, roughness, light pose,
    /// camera, window size, key presses) as one JSON line.
    #[arg(long)]
    pub(crate) print_state: bool,
}

pub(crate) fn run(a: &ViewArgs) -> Result<()> {
    let started = Instant::now();
    let opts = a.connect.options();
    let connected = connect(&opts)?;
    let f = &a.frame;
    let height = connected.scene.camera.image_height(f.width, f.height);
    let mut session = connected.session(&opts, f.width, height)?;
    session.method = method(&f.method)?;
    session.mode = f.mode.into();
    session.set_env(f.env.options(&connected.scene)?);
    session.set_backend(f.backend.resolve()?);
    if a.moving {
        session.path_t = Some(0.0);
    }
    let report = viewer::run(
        &mut session,
        &ViewerOptions {
            title: format!("bspvt — {}", connected.served.id),
            max_frames: a.max_frames,
            note: connected
                .served
                .embedded
                .as_ref()
                .map(|b| format!("embedded service on {}", b.addr)),
            guides: !a.no_guides,
            screenshot_dir: a.screenshot_dir.clone(),
            source: viewer::SceneSource {
                scene: a.connect.source.clone(),
                mesh: a.connect.mesh.clone(),
            },
            save_view: a.save_view.clone(),
        },
        started,
    )?;
    println!(
        "{} frames, {:.1} fps{}",
        report.frames,
        report.mean_fps,
        report
            .first_full_frame
            .map(|t| format!(
                "; first full-quality frame after {:.0} ms",
                t.as_secs_f64() * 1e3
            ))
            .unwrap_or_default()
    );
    if a.print_state {
        println!("state: {}", report.state);
    }
    Ok(())
}
