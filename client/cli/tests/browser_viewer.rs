//! The browser viewer (`/view/{id}`) against `bspvt render`: a real `bspvt serve` on
//! loopback bakes the built-in `plate-small` scene; Debian's Chromium, headless, with WebGPU on
//! its SwiftShader device, opens the viewer behind a path prefix (`tests/browser/viewer.mjs`,
//! playwright-core), waits for every tree and that frame, and saves the canvas; `bspvt render`
//! draws the same scene, camera and light on the CPU. The two must agree away from edges (mean
//! difference ≤ 2 % of full scale), and a shift-drag must move the light and change the frame.
//! The proxy cuts the first two tree responses mid-body (a dropped link): the viewer must ask
//! for those chunks again, and the frame it completes is still the one compared. Chromium
//! without WebGPU gets the page's CPU path (cpu.js), compared with `bspvt render --mode vertex`.
//! The project's glTF rooms check what users' assets bring: several lamps, point and spot
//! lights, a textured lamp, a normal map. Skipped with a message where Node.js, Chromium or `tests/browser/node_modules` is missing
//! (`.ci/run` installs them).

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use bspvt_tests::service::{agent, submit_ok, wait_done};
use common::*;

/// Linear-in-8-bit RGB of a PNG, row-major.
fn rgb(path: &Path) -> (u32, u32, Vec<[f32; 3]>) {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    let px = img
        .pixels()
        .map(|p| p.0.map(|c| f32::from(c) / 255.0))
        .collect();
    (img.width(), img.height(), px)
}

/// Mean absolute difference (0–1, averaged over channels) of `a` and `b`, over the pixels of
/// `a` that are not at an edge: no 8-neighbour differs from them by more than 0.06 in mean
/// value (silhouettes, where the CPU's and the rasteriser's coverage rules differ by a pixel).
fn mean_difference_off_edges(w: u32, h: u32, a: &[[f32; 3]], b: &[[f32; 3]]) -> (f64, f64) {
    let lum = |p: &[f32; 3]| (p[0] + p[1] + p[2]) / 3.0;
    let (w, h) = (w as i64, h as i64);
    let (mut sum, mut n) = (0.0f64, 0u64);
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let l = lum(&a[i]);
            let edge = (-1..=1).any(|dy: i64| {
                (-1..=1).any(|dx: i64| {
                    let (xx, yy) = (x + dx, y + dy);
                    xx >= 0
                        && yy >= 0
                        && xx < w
                        && yy < h
                        && (lum(&a[(yy * w + xx) as usize]) - l).abs() > 0.06
                })
            });
            if !edge {
                sum += (0..3)
                    .map(|c| f64::from((a[i][c] - b[i][c]).abs()))
                    .sum::<f64>()
                    / 3.0;
                n += 1;
            }
        }
    }
    (sum / n.max(1) as f64, n as f64 / (w * h) as f64)
}

/// What one run of `tests/browser/viewer.mjs` gave: its JSON line and the frames it saved
/// (web.png, web-moved.png in `dir`).
struct Seen {
    json: serde_json::Value,
    dir: PathBuf,
}

/// Opens scene `id` of `srv` in the viewer at `w` × `h`, per pixel (per vertex with `--webgpu
/// no`: the CPU path; `--mode` in `extra` chooses), with `extra` arguments to the script;
/// panics with the script's output and the server's log when it fails.
fn view(
    chromium: &Path,
    srv: &Server,
    id: &str,
    (w, h): (u32, u32),
    dir: &Path,
    extra: &[&str],
) -> Seen {
    let run = Command::new("node")
        .current_dir(bspvt_tests::browser::scripts())
        .arg("viewer.mjs")
        .args(["--url", &srv.base, "--id", id])
        .args(if extra.contains(&"--mode") {
            &[][..]
        } else if extra.contains(&"--webgpu") {
            &["--mode", "vertex"][..]
        } else {
            &["--mode", "pixel"][..]
        })
        .args(["--width", &w.to_string(), "--height", &h.to_string()])
        .args(extra)
        .arg("--out")
        .arg(dir)
        .arg("--chromium")
        .arg(chromium)
        .output()
        .expect("run node");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "the browser script failed:\n{}\n{stdout}\nserver log:\n{}",
        String::from_utf8_lossy(&run.stderr),
        srv.log_text()
    );
    let json: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap_or(""))
        .unwrap_or_else(|e| panic!("the script's last line is not JSON ({e}): {stdout}"));
    eprintln!(
        "viewer in {}: graphics path {}, first frame {} ms after the page's start, {} ms per \
         frame, {} bytes fetched",
        json["browser"], json["graphics"], json["firstFrameMs"], json["bench_ms"], json["bytes"]
    );
    // `--webgpu no`: Chromium without WebGPU, the page on its CPU path.
    let path = if extra.contains(&"--webgpu") {
        "CPU"
    } else {
        "WebGPU"
    };
    assert!(
        json["graphics"].as_str().unwrap_or("").starts_with(path),
        "{json}"
    );
    Seen {
        json,
        dir: dir.to_path_buf(),
    }
}

/// `bspvt render SOURCE` at `w` × `h` into `out`, with `extra` (`--method bspvt` and `--mode
/// pixel` unless `extra` names others).
fn render(
    source: &[&std::ffi::OsStr],
    (w, h): (u32, u32),
    cache: &Path,
    out: &Path,
    extra: &[&str],
) {
    let st = Command::new(BIN)
        .arg("render")
        .args(source)
        .args(if extra.contains(&"--method") {
            &[][..]
        } else {
            &["--method", "bspvt"][..]
        })
        .args(if extra.contains(&"--mode") {
            &[][..]
        } else {
            &["--mode", "pixel"][..]
        })
        .args(["--width", &w.to_string(), "--height", &h.to_string()])
        .args(extra)
        .arg("--cache")
        .arg(cache)
        .arg("--out")
        .arg(out)
        .status()
        .expect("bspvt render");
    assert!(st.success());
}

/// The mean difference off edges of two PNGs of one size, and the share of pixels compared.
fn compare(a: &Path, b: &Path) -> (f64, f64) {
    let (aw, ah, a) = rgb(a);
    let (bw, bh, b) = rgb(b);
    assert_eq!((aw, ah), (bw, bh), "sizes");
    mean_difference_off_edges(aw, ah, &a, &b)
}

/// `bspvt serve` on loopback (data in `dir`/data) with `bytes` submitted as form field
/// `field` (`mesh` or `scene`) named `name`, and baked: the server and the scene's id.
fn served(dir: &Path, field: &str, name: &str, bytes: &[u8]) -> (Server, String) {
    let srv = start(&dir.join("data"), "127.0.0.1:0", &[]);
    let id = submit_ok(&agent(), &srv, &[(field, Some(name), bytes)], None);
    wait_done(&agent(), &srv, &id);
    (srv, id)
}

/// `assets/rooms/NAME` submitted as a user's mesh to a server with its data in `dir`, and
/// baked: the asset's path, the server and the scene's id.
fn served_room(dir: &Path, name: &str) -> (PathBuf, Server, String) {
    let gltf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/rooms")
        .join(name);
    let bytes = std::fs::read(&gltf).unwrap();
    let (srv, id) = served(dir, "mesh", name, &bytes);
    (gltf, srv, id)
}

#[test]
fn the_browser_viewer_matches_bspvt_render_and_moves_its_light() {
    let Some(chromium) = bspvt_tests::browser::chromium_or_skip("the viewer in Chromium") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let scene = plate_small(tmp.path(), "plate", 16, 256);
    let (srv, id) = served(
        tmp.path(),
        "scene",
        "plate.json",
        &std::fs::read(&scene).unwrap(),
    );
    let size = (192, 144);
    let reference = tmp.path().join("ref.png");
    render(
        &[scene.as_os_str()],
        size,
        &tmp.path().join("cache"),
        &reference,
        &[],
    );
    // Two tree responses cut mid-body: the viewer resumes by asking for them again.
    let seen = view(
        &chromium,
        &srv,
        &id,
        size,
        tmp.path(),
        &["--cut-trees", "2"],
    );
    assert_eq!(
        seen.json["cut_tree_responses"], 2,
        "the proxy did not cut two tree responses: {}",
        seen.json
    );

    // BSPVT_BROWSER_OUT=DIR keeps the frames (the docs' screenshots come from here).
    if let Some(dir) = std::env::var_os("BSPVT_BROWSER_OUT") {
        let dir = PathBuf::from(dir);
        std::fs::create_dir_all(&dir).unwrap();
        for f in ["ref.png", "web.png", "web-moved.png"] {
            std::fs::copy(tmp.path().join(f), dir.join(f)).unwrap();
        }
    }
    let (diff, kept) = compare(&reference, &seen.dir.join("web.png"));
    eprintln!(
        "browser vs bspvt render: mean difference {:.4} over {:.1} % of the pixels (edges left out)",
        diff,
        kept * 100.0
    );
    assert!(kept > 0.8, "edges cover too much of the frame: {kept}");
    assert!(
        diff <= 0.02,
        "the browser's frame differs from bspvt render's by {diff}"
    );

    // The light moved in its region, and the frame changed with it.
    let (change, _) = compare(&seen.dir.join("web.png"), &seen.dir.join("web-moved.png"));
    eprintln!(
        "light dragged by {}: frame changed by {change:.4}",
        seen.json["light_offset"]
    );
    assert!(
        seen.json["light_offset"]
            .as_str()
            .is_some_and(|o| o != "0.000,0.000,0.000")
    );
    assert!(change > 0.002, "the frame did not change: {change}");

    // A browser without WebGPU (Chromium started without the flags that give it an adapter):
    // the page says so, draws on its CPU path (cpu.js: BSPVT per vertex in JavaScript) and
    // matches `bspvt render --mode vertex` of the same scene; the light still moves.
    let per_vertex = tmp.path().join("ref-vertex.png");
    render(
        &[scene.as_os_str()],
        size,
        &tmp.path().join("cache"),
        &per_vertex,
        &["--mode", "vertex"],
    );
    let cpu_dir = tmp.path().join("cpu");
    std::fs::create_dir_all(&cpu_dir).unwrap();
    let seen = view(&chromium, &srv, &id, size, &cpu_dir, &["--webgpu", "no"]);
    let web = seen.dir.join("web.png");
    let (diff, kept) = compare(&per_vertex, &web);
    eprintln!(
        "CPU path ({}): vs bspvt render --mode vertex {diff:.4} over {:.1} % of the pixels",
        seen.json["graphics"],
        kept * 100.0
    );
    assert!(kept > 0.8, "edges cover too much of the frame: {kept}");
    assert!(
        diff <= 0.02,
        "the CPU path's frame differs from bspvt render's by {diff}"
    );
    let (change, _) = compare(&web, &seen.dir.join("web-moved.png"));
    assert!(
        change > 0.002,
        "the CPU path's frame did not change: {change}"
    );
}

/// The canopy (`assets/rooms/canopy.gltf`) from its own camera, which sees the board's
/// underside at the top of the frame: per vertex, on WebGPU (`sides.wgsl`) and on the CPU path
/// (cpu.js `vertexSides`), the viewer shades each vertex on the side the camera sees, as
/// `bspvt render --mode vertex` does — the underside is dark, not its lit upper side's
/// radiance. Compared over the frame and over its top quarter, where the board is.
#[test]
fn the_browser_viewer_shades_the_side_it_sees() {
    let Some(chromium) = bspvt_tests::browser::chromium_or_skip("the viewer in Chromium") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (gltf, srv, id) = served_room(tmp.path(), "canopy.gltf");
    let size = (192, 128);
    let source = [std::ffi::OsStr::new("--mesh"), gltf.as_os_str()];
    let reference = tmp.path().join("ref.png");
    render(
        &source,
        size,
        &tmp.path().join("cache"),
        &reference,
        &["--mode", "vertex"],
    );
    let (w, h, want) = rgb(&reference);
    let top = (h / 4) as usize * w as usize;
    for (path, extra) in [
        ("gpu", &["--mode", "vertex", "--drag", "no"][..]),
        ("cpu", &["--webgpu", "no", "--drag", "no"][..]),
    ] {
        let dir = tmp.path().join(path);
        std::fs::create_dir_all(&dir).unwrap();
        let seen = view(&chromium, &srv, &id, size, &dir, extra);
        let (_, _, got) = rgb(&seen.dir.join("web.png"));
        let (whole, kept) = mean_difference_off_edges(w, h, &want, &got);
        let (upper, _) = mean_difference_off_edges(w, h / 4, &want[..top], &got[..top]);
        eprintln!(
            "canopy per vertex, {} vs bspvt render: {whole:.4} over {:.1} % of the pixels, \
             {upper:.4} over the top quarter",
            seen.json["graphics"],
            kept * 100.0
        );
        assert!(kept > 0.8, "edges cover too much of the frame: {kept}");
        assert!(whole <= 0.02 && upper <= 0.01, "{path}: {whole}, {upper}");
    }
}

/// A glTF room lit by two emissive lamps (`assets/rooms/two-lamps.gltf`): the viewer draws
/// both at once, as `bspvt render` does, and not the first alone.
#[test]
fn the_browser_viewer_draws_every_lamp() {
    let Some(chromium) = bspvt_tests::browser::chromium_or_skip("the viewer in Chromium") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (gltf, srv, id) = served_room(tmp.path(), "two-lamps.gltf");
    let size = (128, 128);
    let cache = tmp.path().join("cache");
    let source = [std::ffi::OsStr::new("--mesh"), gltf.as_os_str()];
    let both = tmp.path().join("both.png");
    let first = tmp.path().join("first.png");
    render(&source, size, &cache, &both, &[]);
    render(&source, size, &cache, &first, &["--light", "0"]);
    // Lamps from a glTF have no region to be dragged in.
    let seen = view(&chromium, &srv, &id, size, tmp.path(), &["--drag", "no"]);
    let web = seen.dir.join("web.png");
    let (diff, kept) = compare(&both, &web);
    let (to_first, _) = compare(&first, &web);
    eprintln!(
        "two lamps: browser vs bspvt render {diff:.4} over {:.1} % of the pixels; vs the first \
         lamp alone {to_first:.4}",
        kept * 100.0
    );
    assert!(kept > 0.8, "edges cover too much of the frame: {kept}");
    assert!(
        diff <= 0.02,
        "the browser's two lamps differ from bspvt render's by {diff}"
    );
    assert!(
        to_first > 0.05,
        "the browser's frame is the first lamp's alone ({to_first})"
    );
}

/// A glTF room lit by a point light and a spot (`assets/rooms/punctual-room.gltf` without its
/// sun, whose shadows are the sky's bake, which the service does not stream): the viewer draws
/// each as the native client does, a sphere's round polygon cut by the trees, the spot's cone
/// and falloff, and matches `bspvt render`; the shadows are in it (it differs from the
/// unshadowed frame).
#[test]
fn the_browser_viewer_draws_point_and_spot_lights() {
    let Some(chromium) = bspvt_tests::browser::chromium_or_skip("the viewer in Chromium") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let room = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rooms/punctual-room.gltf");
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&room).unwrap()).unwrap();
    for node in doc["nodes"].as_array_mut().unwrap() {
        if node["name"] == "sun" {
            node.as_object_mut().unwrap().remove("extensions");
        }
    }
    let gltf = tmp.path().join("point-spot-room.gltf");
    std::fs::write(&gltf, serde_json::to_vec(&doc).unwrap()).unwrap();
    let bytes = std::fs::read(&gltf).unwrap();
    let (srv, id) = served(tmp.path(), "mesh", "point-spot-room.gltf", &bytes);
    let size = (160, 120);
    let cache = tmp.path().join("cache");
    let source = [std::ffi::OsStr::new("--mesh"), gltf.as_os_str()];
    let reference = tmp.path().join("ref.png");
    let unshadowed = tmp.path().join("ltc.png");
    render(&source, size, &cache, &reference, &[]);
    render(&source, size, &cache, &unshadowed, &["--method", "ltc"]);
    let seen = view(&chromium, &srv, &id, size, tmp.path(), &["--drag", "no"]);
    let web = seen.dir.join("web.png");
    if let Some(dir) = std::env::var_os("BSPVT_BROWSER_OUT") {
        let dir = PathBuf::from(dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::copy(&reference, dir.join("point-spot-ref.png")).unwrap();
        std::fs::copy(&web, dir.join("point-spot-web.png")).unwrap();
    }
    let (diff, kept) = compare(&reference, &web);
    let (shadows, _) = compare(&unshadowed, &web);
    eprintln!(
        "point and spot: browser vs bspvt render {diff:.4} over {:.1} % of the pixels; vs the \
         unshadowed frame {shadows:.4}",
        kept * 100.0
    );
    assert!(kept > 0.8, "edges cover too much of the frame: {kept}");
    assert!(
        diff <= 0.02,
        "the browser's point and spot lights differ from bspvt render's by {diff}"
    );
    assert!(
        shadows > 2.0 * diff && shadows > 0.005,
        "the browser's frame is as near the unshadowed one ({shadows}) as bspvt render's ({diff})"
    );
    // The page's CPU path (no WebGPU) draws the spheres and the spot's cone per vertex.
    let per_vertex = tmp.path().join("ref-vertex.png");
    render(&source, size, &cache, &per_vertex, &["--mode", "vertex"]);
    let cpu_dir = tmp.path().join("cpu");
    std::fs::create_dir_all(&cpu_dir).unwrap();
    let seen = view(
        &chromium,
        &srv,
        &id,
        size,
        &cpu_dir,
        &["--drag", "no", "--webgpu", "no"],
    );
    let (diff, kept) = compare(&per_vertex, &seen.dir.join("web.png"));
    eprintln!(
        "point and spot, the CPU path: vs bspvt render --mode vertex {diff:.4} over {:.1} % of the pixels",
        kept * 100.0
    );
    assert!(
        kept > 0.8 && diff <= 0.02,
        "the CPU path's point and spot lights differ from bspvt render's by {diff} ({kept})"
    );
}

/// A glTF lamp with an emissive texture over a checker floor (`assets/rooms/textured-floor.gltf`):
/// the page uploads the lamp's prefiltered texture (the service builds it with the native
/// client's code) and fetches it per piece as the native shaders do; per pixel it matches
/// `bspvt render`, and differs from the lamp drawn with its plain radiance.
#[test]
fn the_browser_viewer_draws_a_textured_lamp() {
    let Some(chromium) = bspvt_tests::browser::chromium_or_skip("the viewer in Chromium") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (gltf, srv, id) = served_room(tmp.path(), "textured-floor.gltf");
    let size = (160, 120);
    let cache = tmp.path().join("cache");
    let source = [std::ffi::OsStr::new("--mesh"), gltf.as_os_str()];
    let reference = tmp.path().join("ref.png");
    render(&source, size, &cache, &reference, &[]);
    let seen = view(&chromium, &srv, &id, size, tmp.path(), &["--drag", "no"]);
    let web = seen.dir.join("web.png");
    let (diff, kept) = compare(&reference, &web);
    eprintln!(
        "textured lamp: browser vs bspvt render {diff:.4} over {:.1} % of the pixels",
        kept * 100.0
    );
    assert!(kept > 0.8, "edges cover too much of the frame: {kept}");
    assert!(
        diff <= 0.02,
        "the browser's textured lamp differs from bspvt render's by {diff}"
    );
    // The same room with the lamp's emissive texture taken off: its plain radiance.
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&gltf).unwrap()).unwrap();
    for m in doc["materials"].as_array_mut().unwrap() {
        m.as_object_mut().unwrap().remove("emissiveTexture");
    }
    let plain_gltf = tmp.path().join("plain-lamp.gltf");
    std::fs::write(&plain_gltf, serde_json::to_vec(&doc).unwrap()).unwrap();
    let plain = tmp.path().join("plain.png");
    render(
        &[std::ffi::OsStr::new("--mesh"), plain_gltf.as_os_str()],
        size,
        &cache,
        &plain,
        &[],
    );
    let (untextured, _) = compare(&plain, &web);
    eprintln!("textured lamp: browser vs the lamp without its texture {untextured:.4}");
    assert!(
        untextured > 2.0 * diff && untextured > 0.005,
        "the texture changes nothing: {untextured} against {diff}"
    );
}

/// A normal-mapped floor (`assets/rooms/normal-floor.gltf`): the page bends the normals as the
/// native client does — per pixel in the resolve pass from the bundle's tangent frames, per
/// vertex from the service's bent vertex normals turned to the viewer's side — on WebGPU and
/// on the CPU path; each frame matches `bspvt render` and differs from the floor without its
/// normal map.
#[test]
fn the_browser_viewer_bends_normals_by_their_maps() {
    let Some(chromium) = bspvt_tests::browser::chromium_or_skip("the viewer in Chromium") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (gltf, srv, id) = served_room(tmp.path(), "normal-floor.gltf");
    let bytes = std::fs::read(&gltf).unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    for m in doc["materials"].as_array_mut().unwrap() {
        m.as_object_mut().unwrap().remove("normalTexture");
    }
    let flat_gltf = tmp.path().join("flat-floor.gltf");
    std::fs::write(&flat_gltf, serde_json::to_vec(&doc).unwrap()).unwrap();
    let size = (160, 120);
    let cache = tmp.path().join("cache");
    for (name, mode, extra) in [
        ("WebGPU per pixel", "pixel", &["--drag", "no"][..]),
        (
            "WebGPU per vertex",
            "vertex",
            &["--drag", "no", "--mode", "vertex"][..],
        ),
        (
            "the CPU path",
            "vertex",
            &["--drag", "no", "--webgpu", "no"][..],
        ),
    ] {
        let reference = tmp.path().join(format!("ref-{mode}.png"));
        let flat = tmp.path().join(format!("flat-{mode}.png"));
        render(
            &[std::ffi::OsStr::new("--mesh"), gltf.as_os_str()],
            size,
            &cache,
            &reference,
            &["--mode", mode],
        );
        render(
            &[std::ffi::OsStr::new("--mesh"), flat_gltf.as_os_str()],
            size,
            &cache,
            &flat,
            &["--mode", mode],
        );
        let dir = tmp.path().join(name.replace(' ', "-"));
        std::fs::create_dir_all(&dir).unwrap();
        let seen = view(&chromium, &srv, &id, size, &dir, extra);
        let web = seen.dir.join("web.png");
        let (diff, kept) = compare(&reference, &web);
        let (to_flat, _) = compare(&flat, &web);
        eprintln!(
            "normal map, {name}: vs bspvt render {diff:.4} over {:.1} % of the pixels; vs the \
             floor without its map {to_flat:.4}",
            kept * 100.0
        );
        assert!(
            kept > 0.5,
            "{name}: edges cover too much of the frame: {kept}"
        );
        assert!(diff <= 0.02, "{name}: differs from bspvt render by {diff}");
        assert!(
            to_flat > 2.0 * diff && to_flat > 0.005,
            "{name}: the normal map changes nothing ({to_flat} against {diff})"
        );
    }
}
