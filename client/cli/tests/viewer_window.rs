//! The viewer in a real X window under Xvfb: the window must show the shaded scene (the same
//! pixels the headless session draws), not a blank or error frame; synthetic key and mouse
//! events (XTest), short and long, must all be applied, the window must resize, and its
//! screenshot must show the scene and the light's gizmo. Skipped, with a message, where Xvfb
//! is not installed (`.ci/run` installs it).

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
    grab_sized(display, W, H)
}

/// Mean |Δ| (8-bit) between a screenshot and a window's pixels below the overlay's text
/// (rows 120 and down: fps and messages change from frame to frame).
fn below_overlay_diff(img: &image::RgbImage, window: &[[u8; 3]], w: u32, h: u32) -> f64 {
    let (mut diff, mut n) = (0u64, 0u64);
    for y in 120..h {
        for x in 0..w {
            let (a, b) = (img.get_pixel(x, y).0, window[(y * w + x) as usize]);
            diff += (0..3).map(|k| u64::from(a[k].abs_diff(b[k]))).sum::<u64>();
            n += 3;
        }
    }
    diff as f64 / n.max(1) as f64
}

fn grab_sized(display: &str, width: u32, height: u32) -> Option<Vec<[u8; 3]>> {
    let (conn, screen) = x11rb::connect(Some(display)).ok()?;
    let root = conn.setup().roots[screen].root;
    let tree = conn.query_tree(root).ok()?.reply().ok()?;
    for w in tree.children {
        let Ok(g) = conn.get_geometry(w).ok()?.reply() else {
            continue;
        };
        if u32::from(g.width) != width || u32::from(g.height) != height {
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
    window_shows_the_headless_frame("cpu");
}

/// The same window with its frames drawn by the GPU (lavapipe in CI): the GPU's frames equal
/// the CPU's within docs/gpu.md's bound, far below the 8-bit tolerance here.
#[test]
fn the_viewer_window_on_the_gpu_backend_shows_the_same_scene() {
    if !gpu_adapter() {
        return;
    }
    window_shows_the_headless_frame("gpu");
}

/// Whether a GPU adapter exists (named), or a message saying the test is skipped.
fn gpu_adapter() -> bool {
    match bspvt_client::gpu::Gpu::shared() {
        Ok(g) => {
            eprintln!("adapter: {}", g.adapter);
            true
        }
        Err(e) => {
            eprintln!(
                "SKIPPED: no GPU adapter ({e:#}); CI installs lavapipe (mesa-vulkan-drivers)"
            );
            false
        }
    }
}

/// `bspvt view --backend BACKEND` in Xvfb against the headless CPU session's frame.
fn window_shows_the_headless_frame(backend: &str) {
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
            // The guides (grid, axes, light) are drawn over the frame: compare without them.
            .arg("--no-guides")
            .args(["--backend", backend])
            .env("DISPLAY", &display)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit()) // never read: a pipe could fill and block the viewer
            .spawn()
            .expect("start bspvt view"),
    );
    // The window must draw frames: wait for its first one.
    let mut out = BufReader::new(viewer.0.stdout.take().expect("stdout"));
    let said = first_frame(&mut out);
    presents_as(&said, backend);

    // Compare below the overlay panel and above the roughness slider.
    let rows = 110..(H as usize - 24);
    let deadline = Instant::now() + Duration::from_secs(120);
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

/// Reads the viewer's output up to its first frame; the lines before it.
fn first_frame(out: &mut impl BufRead) -> Vec<String> {
    let mut said = Vec::new();
    loop {
        let mut line = String::new();
        let n = out.read_line(&mut line).expect("viewer output");
        assert!(n > 0, "the viewer ended before its first frame: {said:?}");
        if line.starts_with("first frame on screen") {
            return said;
        }
        said.push(line);
    }
}

/// Reads the viewer's output until it says every tree is drawn.
fn every_tree_on_screen(out: &mut impl BufRead) {
    loop {
        let mut line = String::new();
        let n = out.read_line(&mut line).expect("viewer output");
        assert!(n > 0, "the viewer ended before drawing every tree");
        if line.starts_with("every tree on screen") {
            return;
        }
    }
}

/// The viewer presents through a wgpu surface with the GPU backend, softbuffer with the CPU.
fn presents_as(said: &[String], backend: &str) {
    let line = said
        .iter()
        .find(|l| l.starts_with("presenting: "))
        .unwrap_or_else(|| panic!("no presenting line: {said:?}"));
    let want = match backend {
        "gpu" => "presenting: wgpu surface",
        _ => "presenting: CPU pixels",
    };
    assert!(line.starts_with(want), "{line:?}, want {want:?}");
}

/// The viewer's top-level window (the root's child of `w`×`h`).
fn find_window(conn: &impl Connection, root: u32, w: u32, h: u32) -> Option<u32> {
    let tree = conn.query_tree(root).ok()?.reply().ok()?;
    tree.children.into_iter().find(|&win| {
        conn.get_geometry(win)
            .ok()
            .and_then(|c| c.reply().ok())
            .is_some_and(|g| u32::from(g.width) == w && u32::from(g.height) == h)
    })
}

/// The keycode that types `keysym` on the X server's keyboard map.
fn keycode(conn: &impl Connection, keysym: u32) -> u8 {
    let setup = conn.setup();
    let (min, max) = (setup.min_keycode, setup.max_keycode);
    let map = conn
        .get_keyboard_mapping(min, max - min + 1)
        .expect("keyboard mapping")
        .reply()
        .expect("keyboard mapping");
    let per = usize::from(map.keysyms_per_keycode);
    let i = map
        .keysyms
        .chunks(per)
        .position(|syms| syms.contains(&keysym))
        .unwrap_or_else(|| panic!("no keycode for keysym {keysym:#x}"));
    min + i as u8
}

#[test]
fn the_viewport_applies_every_event_resizes_and_draws_the_light() {
    viewport(None);
}

/// The same on a wgpu surface (lavapipe in CI): frames presented from the GPU, the overlay
/// composited there, and the screenshot (read back and composited on the CPU) the same
/// pixels as the window.
#[test]
fn the_viewport_on_a_gpu_surface_applies_every_event_resizes_and_draws_the_light() {
    if !gpu_adapter() {
        return;
    }
    viewport(Some("gpu"));
}

/// `bspvt view` driven by XTest; `backend`: `--backend` (`None`: the default).
fn viewport(backend: Option<&str>) {
    use x11rb::protocol::xproto::{BUTTON_PRESS_EVENT, BUTTON_RELEASE_EVENT, KEY_PRESS_EVENT};
    use x11rb::protocol::xproto::{ConfigureWindowAux, InputFocus};
    use x11rb::protocol::xproto::{KEY_RELEASE_EVENT, MOTION_NOTIFY_EVENT};
    use x11rb::protocol::xtest::ConnectionExt as _;
    use x11rb::wrapper::ConnectionExt as _;

    let Some((_xvfb, display)) = xvfb() else {
        eprintln!("SKIPPED: Xvfb is not installed (apt-get install xvfb)");
        return;
    };
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), "127.0.0.1:0", &[]);
    let scene_path = plate_small(tmp.path(), "plate", 32, 256);
    let scene = bspvt_proto::scene::Scene::load(&scene_path).expect("scene");
    let shots = tmp.path().join("shots");
    let view_file = tmp.path().join("saved.view.json");
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
            .arg("--screenshot-dir")
            .arg(&shots)
            .arg("--save-view")
            .arg(&view_file)
            .arg("--print-state")
            .args(backend.map(|b| ["--backend", b]).into_iter().flatten())
            .env("DISPLAY", &display)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start bspvt view"),
    );
    let mut out = BufReader::new(viewer.0.stdout.take().expect("stdout"));
    let said = first_frame(&mut out);
    if let Some(b) = backend {
        presents_as(&said, b);
    }
    // Every tree drawn before any input: the held keys below are timed by the viewer's
    // frames, and on lavapipe a pipeline's first use compiles it (a minute on a cold cache).
    every_tree_on_screen(&mut out);

    let (conn, screen) = x11rb::connect(Some(&display)).expect("X connection");
    let root = conn.setup().roots[screen].root;
    let win = find_window(&conn, root, W, H).expect("the viewer's window");
    let at = conn
        .translate_coordinates(win, root, 0, 0)
        .unwrap()
        .reply()
        .unwrap();
    // Pointer into the window's middle, keyboard focus on it (Xvfb runs no window manager).
    let (cx, cy) = (at.dst_x + W as i16 / 2, at.dst_y + H as i16 / 2);
    conn.xtest_fake_input(MOTION_NOTIFY_EVENT, 0, 0, root, cx, cy, 0)
        .unwrap();
    conn.set_input_focus(InputFocus::POINTER_ROOT, win, 0u32)
        .unwrap();
    conn.sync().unwrap();
    std::thread::sleep(Duration::from_millis(300));

    let key = |sym: u32, kind: u8| {
        let code = keycode(&conn, sym);
        conn.xtest_fake_input(kind, code, 0, root, 0, 0, 0).unwrap();
    };
    // Short presses, press and release back to back (shorter than any frame): each must act.
    let taps = [
        0x32u32, /* 2 */
        0x6d,    /* m */
        0x5d, 0x5d, 0x5d, /* ] ×3 */
    ];
    for sym in taps {
        key(sym, KEY_PRESS_EVENT);
        key(sym, KEY_RELEASE_EVENT);
    }
    conn.sync().unwrap();
    // A long press: D held for 0.8 s moves the light +x by 1.5 × a quarter of the scene's
    // diagonal per second (1.76 here; its region lets it go 2).
    key(0x64 /* d */, KEY_PRESS_EVENT);
    conn.sync().unwrap();
    let held = Instant::now();
    std::thread::sleep(Duration::from_millis(800));
    key(0x64, KEY_RELEASE_EVENT);
    conn.sync().unwrap();
    let held_s = held.elapsed().as_secs_f64();
    // Q held for 1.5 s would take the light 3.3 down, out of its region (y ≥ 2): it stops
    // at the region's floor, 1 below where it started.
    key(0x71 /* q */, KEY_PRESS_EVENT);
    conn.sync().unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    key(0x71, KEY_RELEASE_EVENT);
    conn.sync().unwrap();
    // Two wheel notches away from the screen (X button 5): zoom out by 1/0.9², which
    // brings the light (above the camera) into the view.
    for _ in 0..2 {
        conn.xtest_fake_input(BUTTON_PRESS_EVENT, 5, 0, root, 0, 0, 0)
            .unwrap();
        conn.xtest_fake_input(BUTTON_RELEASE_EVENT, 5, 0, root, 0, 0, 0)
            .unwrap();
    }
    // Resize the window.
    let (w2, h2) = (400u32, 300u32);
    conn.configure_window(win, &ConfigureWindowAux::new().width(w2).height(h2))
        .unwrap();
    conn.sync().unwrap();
    std::thread::sleep(Duration::from_millis(800));
    // Screenshot, save view, quit.
    key(0xffc9 /* F12 */, KEY_PRESS_EVENT);
    key(0xffc9, KEY_RELEASE_EVENT);
    key(0x76 /* v */, KEY_PRESS_EVENT);
    key(0x76, KEY_RELEASE_EVENT);
    conn.sync().unwrap();
    // The window as it shows the screenshot's frame: polled until it matches (below the
    // overlay's text), since on a loaded 2-core machine with a software GPU the frame after
    // the screenshot may take longer than any fixed wait to reach the screen.
    let deadline = Instant::now() + Duration::from_secs(30);
    let png = loop {
        let found = std::fs::read_dir(&shots).ok().and_then(|d| {
            d.filter_map(Result::ok)
                .map(|e| e.path())
                .find(|p| p.extension().is_some_and(|x| x == "png"))
        });
        if let Some(p) = found.filter(|p| image::open(p).is_ok()) {
            break image::open(&p).expect("screenshot PNG").to_rgb8();
        }
        if Instant::now() >= deadline {
            // What the viewer said (its error, if it printed one) with the failure.
            let _ = viewer.0.kill();
            let mut rest = String::new();
            let _ = std::io::Read::read_to_string(&mut out, &mut rest);
            panic!("no screenshot was written; the viewer printed:\n{rest}");
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let window = loop {
        std::thread::sleep(Duration::from_millis(200));
        let grab = grab_sized(&display, w2, h2).expect("the resized window's pixels");
        if png.dimensions() != (w2, h2) || below_overlay_diff(&png, &grab, w2, h2) < 0.5 {
            break grab;
        }
        if Instant::now() >= deadline {
            break grab;
        }
    };
    key(0xff1b /* Escape */, KEY_PRESS_EVENT);
    key(0xff1b, KEY_RELEASE_EVENT);
    conn.sync().unwrap();

    let deadline = Instant::now() + Duration::from_secs(60);
    while matches!(viewer.0.try_wait(), Ok(None)) {
        assert!(Instant::now() < deadline, "the viewer did not quit on Esc");
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut out, &mut rest).expect("viewer output");
    let state_line = rest
        .lines()
        .find_map(|l| l.strip_prefix("state: "))
        .unwrap_or_else(|| panic!("no state printed: {rest}"));
    let st: serde_json::Value = serde_json::from_str(state_line).expect("state JSON");
    eprintln!("viewer state: {st}");

    // Every press applied: 5 taps, D, Q, F12, V.
    assert_eq!(st["key_presses"], 9, "{st}");
    assert_eq!(
        st["method"],
        bspvt_client::method::METHODS[1].name(),
        "2 picks the second method"
    );
    assert_eq!(st["mode"], "pixel");
    let alpha = st["roughness"].as_f64().expect("roughness set");
    assert!((alpha - 0.3 * 1.25f64.powi(3)).abs() < 1e-4, "α = {alpha}");
    // The held key: the light moved for as long as D was down. The viewer times the press
    // and the release when its event loop takes them, between frames: up to a frame late
    // each (0.2 s allowed, for a loaded machine, or two mean frames where frames are slower:
    // lavapipe's GPU frames).
    let b = scene.mesh.bounds();
    let quarter_diag = (b.max - b.min).length() as f64 * 0.25;
    let want = 1.5 * quarter_diag * held_s;
    let off: Vec<f64> = st["light_offset"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let frame_s = st["mean_frame_ms"].as_f64().expect("mean frame time") / 1e3;
    let late_s = 0.2f64.max(2.0 * frame_s);
    assert!(
        (off[0] - want).abs() < 1.5 * quarter_diag * late_s && off[2] == 0.0,
        "light offset {off:?}, want x = {want:.3} (±{late_s:.2} s of holding)"
    );
    assert!(
        (off[1] + 1.0).abs() < 1e-6,
        "light offset {off:?}: y should stop at the region's floor (-1)"
    );
    // The wheel: two notches of 1/0.9 each. An XTest button 5 reaches winit twice on Xvfb
    // (the button itself, and the scroll valuator the server emulates from it, which winit
    // also reads; a real wheel sends the valuator and an emulated button winit drops), so
    // each notch zooms by 1/0.9 once or twice: 0.9⁻² or 0.9⁻⁴, nothing else.
    let cam = &scene.camera;
    let d0 = (glam::Vec3::from(cam.position) - glam::Vec3::from(cam.target)).length() as f64;
    let d = st["camera_distance"].as_f64().unwrap();
    assert!(
        [0.81, 0.6561]
            .iter()
            .any(|k| (d * k - d0).abs() < 1e-3 * d0),
        "distance {d}: {:.4} of the scene's, want 1/0.81 or 1/0.6561",
        d / d0
    );
    assert_eq!(st["window"], serde_json::json!([w2, h2]));

    // The screenshot: the window as resized, the lit scene and the light's outline in its
    // gizmo colour (its emitting side faces down, away from this camera above it: the
    // "back" colour, or the front colour of the arrow).
    let shot = std::fs::read_dir(&shots)
        .expect("screenshot folder")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "png"))
        .expect("a screenshot");
    if let Some(path) = std::env::var_os("BSPVT_SCREENSHOT") {
        std::fs::copy(&shot, path).expect("copy screenshot");
    }
    let img = image::open(&shot).expect("screenshot PNG").to_rgb8();
    assert_eq!(img.dimensions(), (w2, h2));
    let near = |p: &image::Rgb<u8>, c: u32| {
        (0..3).all(|k| p.0[k].abs_diff((c >> (16 - 8 * k)) as u8) <= 8)
    };
    let gizmo = img
        .pixels()
        .filter(|p| near(p, 0x00ff_d000) || near(p, 0x0090_6000))
        .count();
    let lit = img.pixels().filter(|p| p.0.iter().any(|&c| c > 40)).count();
    assert!(gizmo >= 40, "{gizmo} gizmo pixels in {}", shot.display());
    assert!(
        lit as f64 > 0.15 * f64::from(w2 * h2),
        "{lit} lit pixels in {}",
        shot.display()
    );
    // The screenshot is what the window shows (below the overlay's text, which changes
    // from frame to frame: fps, messages).
    let mean = below_overlay_diff(&img, &window, w2, h2);
    assert!(
        mean < 0.5,
        "screenshot against the window: mean |Δ| = {mean:.3} (8-bit)"
    );

    // The saved view: a scene file with the moved light and the zoomed camera, that loads.
    let saved = bspvt_proto::scene::Scene::load(&view_file).expect("saved view loads");
    let moved = saved.lights[0].vertices[0][0] - scene.lights[0].vertices[0][0];
    assert!(
        (f64::from(moved) - off[0]).abs() < 1e-4,
        "moved {moved}, offset {}",
        off[0]
    );
    let c = &saved.camera;
    let ds = (glam::Vec3::from(c.position) - glam::Vec3::from(c.target)).length() as f64;
    assert!((ds - d).abs() < 1e-4 * d, "saved distance {ds}, viewer {d}");
    assert_eq!(saved.mesh, scene.mesh, "same geometry");
}
