//! The viewer in a real X window under Xvfb: the window must show the shaded scene (the same
//! pixels the headless session draws), not a blank or error frame. Skipped, with a message,
//! where Xvfb is not installed (`.ci/run` installs it).

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use bspvt_client::session::connect::connect;
use common::*;
use x11rb::connection::Connection;
use x11rb::protocol::xproto::{ConnectionExt, ImageFormat};

const W: u32 = 320;
const H: u32 = 320;

struct Kill(Child);
impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts Xvfb on a free display; `None` when it is not installed.
fn xvfb() -> Option<(Kill, String)> {
    let mut child = Command::new("Xvfb")
        .args([
            "-displayfd",
            "1",
            "-screen",
            "0",
            "640x480x24",
            "-nolisten",
            "tcp",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .ok()?;
    let mut line = String::new();
    BufReader::new(child.stdout.take().expect("stdout"))
        .read_line(&mut line)
        .expect("Xvfb display number");
    Some((Kill(child), format!(":{}", line.trim())))
}

/// The viewer window's pixels (RGB), found among the root's children by its size.
fn grab(display: &str) -> Option<Vec<[u8; 3]>> {
    let (conn, screen) = x11rb::connect(Some(display)).ok()?;
    let root = conn.setup().roots[screen].root;
    let tree = conn.query_tree(root).ok()?.reply().ok()?;
    for w in tree.children {
        let Ok(g) = conn.get_geometry(w).ok()?.reply() else {
            continue;
        };
        if u32::from(g.width) != W || u32::from(g.height) != H {
            continue;
        }
        let at = conn
            .translate_coordinates(w, root, 0, 0)
            .ok()?
            .reply()
            .ok()?;
        let img = conn
            .get_image(
                ImageFormat::Z_PIXMAP,
                root,
                at.dst_x,
                at.dst_y,
                g.width,
                g.height,
                !0,
            )
            .ok()?
            .reply()
            .ok()?;
        // Depth 24 in 32-bit little-endian pixels: B, G, R, unused.
        return Some(
            img.data
                .chunks_exact(4)
                .map(|p| [p[2], p[1], p[0]])
                .collect(),
        );
    }
    None
}

#[test]
fn the_viewer_window_shows_the_shaded_scene() {
    let Some((_xvfb, display)) = xvfb() else {
        eprintln!("SKIPPED: Xvfb is not installed (apt-get install xvfb)");
        return;
    };
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), "127.0.0.1:0", &[]);
    let scene_path = plate_small(tmp.path(), "plate", 32, 256);
    let args = connect_args(&scene_path, &srv, tmp.path());

    // What the window should show: the session's frame with every tree, drawn headless.
    let c = connect(&args).expect("connect");
    let mut s = c.session(&args, W, H).expect("session");
    s.wait_complete();
    assert!(s.streamed.complete());
    let expected = s.frame().to_srgb8(1.0);

    let mut viewer = Kill(
        Command::new(BIN)
            .arg("view")
            .arg(&scene_path)
            .args(["--server", &srv.base])
            .arg("--data-dir")
            .arg(tmp.path().join("client"))
            .arg("--cache-dir")
            .arg(tmp.path().join("cache"))
            .args(["--width", &W.to_string(), "--height", &H.to_string()])
            .env("DISPLAY", &display)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start bspvt view"),
    );
    // The window must draw frames: wait for its first one.
    let mut first = String::new();
    BufReader::new(viewer.0.stdout.take().expect("stdout"))
        .read_line(&mut first)
        .expect("viewer output");
    assert!(
        first.starts_with("first frame on screen"),
        "viewer said {first:?}"
    );

    // Compare below the overlay panel and above the roughness slider.
    let rows = 110..(H as usize - 24);
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut last = String::new();
    loop {
        if let Some(px) = grab(&display) {
            let (mut diff, mut n, mut lit) = (0u64, 0u64, 0u64);
            for y in rows.clone() {
                for x in 0..W as usize {
                    let got = px[y * W as usize + x];
                    let want = expected.get_pixel(x as u32, y as u32).0;
                    diff += (0..3)
                        .map(|k| u64::from(got[k].abs_diff(want[k])))
                        .sum::<u64>();
                    lit += u64::from(got.iter().any(|&c| c > 40));
                    n += 1;
                }
            }
            let mean_diff = diff as f64 / (3 * n) as f64;
            let lit_share = lit as f64 / n as f64;
            last = format!("mean |Δ| = {mean_diff:.2} (8-bit), lit share {lit_share:.2}");
            // The shaded scene: mostly lit pixels (the floor fills the view), and the same
            // pixels as the headless frame once every tree is in.
            if lit_share > 0.5 && mean_diff < 0.5 {
                // BSPVT_SCREENSHOT=PATH keeps the window's pixels for a human to look at.
                if let Some(path) = std::env::var_os("BSPVT_SCREENSHOT") {
                    let img =
                        image::RgbImage::from_fn(W, H, |x, y| image::Rgb(px[(y * W + x) as usize]));
                    img.save(path).expect("write screenshot");
                }
                break;
            }
        }
        assert!(
            Instant::now() < deadline,
            "the window never showed the shaded scene: {last}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(
        matches!(viewer.0.try_wait(), Ok(None)),
        "the viewer exited early"
    );
}
