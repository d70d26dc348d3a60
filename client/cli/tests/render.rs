//! The headless renderer end to end: a real bake of the built-in scene, BSPVT shading in both
//! modes against LTC with exact (ray-traced) visibility, and the `bspvt render` command.

use std::path::PathBuf;
use std::process::Command;
use std::sync::atomic::AtomicBool;

use bspvt_bake::Baker;
use bspvt_client::frame::image::Image;
use bspvt_client::groundtruth::ltcvis::{builtin_lookup, render_ltc_exact_visibility};
use bspvt_client::light::Light;
use bspvt_client::render::renderer::{Mode, Renderer, Trees};
use bspvt_proto::encoding::decode_bake;
use bspvt_raytrace::{Occluder, mesh_triangles};

fn scene() -> bspvt_proto::Scene {
    let mut s = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
    s.bake.face_res = 32;
    s
}

fn bake(scene: &bspvt_proto::Scene) -> Vec<u8> {
    Baker::new(scene)
        .bake_all(&|_, _| {}, &AtomicBool::new(false))
        .expect("bake")
        .bytes
}

/// Mean over pixels of |a − b| (channel mean), and the mean of `reference`.
fn mean_abs_diff(a: &Image, b: &Image) -> f64 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(x, y)| (0..3).map(|k| f64::from((x[k] - y[k]).abs())).sum::<f64>() / 3.0)
        .sum::<f64>()
        / a.pixels.len() as f64
}

#[test]
fn bspvt_matches_exact_visibility_and_has_shadows() {
    let scene = scene();
    let bytes = bake(&scene);
    let b = decode_bake(&bytes).expect("decode");
    let trees = Trees::full(&b.trees, b.header.codec());
    let r = Renderer::new(&scene, 96, 72);
    let light = Light::from_scene(&scene.lights[0]);
    let (vertex, c) = r.bspvt(std::slice::from_ref(&light), &trees, Mode::Vertex);
    let (pixel, _) = r.bspvt(std::slice::from_ref(&light), &trees, Mode::Pixel);
    let (unshadowed, _) = r.ltc(std::slice::from_ref(&light), Mode::Pixel);
    assert!(
        c.vertices_shaded > 500 && c.pieces > 0 && c.pieces_dropped > 0,
        "{c:?}"
    );
    let occ = Occluder::new(&scene.mesh, &mesh_triangles(&scene.mesh));
    let exact = render_ltc_exact_visibility(
        &scene,
        &r.view,
        &r.gbuffer,
        &light,
        &occ,
        &builtin_lookup,
        256,
        1,
    );
    let scale = unshadowed.mean();
    let shadow = mean_abs_diff(&unshadowed, &exact) / scale;
    let err_pixel = mean_abs_diff(&pixel, &exact) / scale;
    let err_vertex = mean_abs_diff(&vertex, &exact) / scale;
    println!(
        "relative to the unshadowed mean: shadows change {shadow:.4}, BSPVT per-pixel error {err_pixel:.4}, per-vertex {err_vertex:.4}"
    );
    for img in [&vertex, &pixel, &unshadowed, &exact] {
        assert!(
            img.pixels
                .iter()
                .flatten()
                .all(|c| c.is_finite() && *c >= 0.0)
        );
    }
    // The scene has real shadows, and BSPVT gets most of them right.
    assert!(shadow > 0.05, "shadows change only {shadow}");
    assert!(
        err_pixel < 0.1 * shadow,
        "per-pixel error {err_pixel} vs shadow {shadow}"
    );
    assert!(
        err_vertex < 0.12 * shadow,
        "per-vertex error {err_vertex} vs shadow {shadow}"
    );
}

fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_bspvt"))
}

#[test]
fn render_command_writes_images_and_stats() {
    let dir = std::env::temp_dir().join(format!("bspvt-render-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let scene = scene();
    let trees = dir.join("t.bspvt");
    std::fs::write(&trees, bake(&scene)).expect("write bake");
    // As a CI job or a service account runs it: no desktop session. Mesa's Vulkan layer
    // would print a Wayland error there although nothing is wrong (issue 38).
    let out = Command::new(bin())
        .args(["render", "builtin:plate-small", "--trees"])
        .arg(&trees)
        .args([
            "--mode", "both", "--width", "40", "--height", "30", "--frames", "3",
        ])
        .arg("--out")
        .arg(dir.join("f.exr"))
        .arg("--stats")
        .arg(dir.join("stats.json"))
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .output()
        .expect("run bspvt");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        !stderr.lines().any(|l| l.starts_with("error")) && !stderr.contains("XDG_RUNTIME_DIR"),
        "a clean run prints no error: {stderr}"
    );
    for k in 0..3 {
        let img = image::open(dir.join(format!("f-{k:03}.exr"))).expect("exr frame");
        assert_eq!((img.width(), img.height()), (80, 30));
    }
    let stats: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("stats.json")).expect("stats"))
            .expect("json");
    for s in stats.as_array().expect("two modes") {
        for key in ["seconds", "ms_per_frame", "us_per_vertex", "threads"] {
            assert!(s[key].as_f64().is_some_and(|v| v >= 0.0), "{key} in {s}");
        }
        assert!(s["ms_per_frame"].as_f64().is_some_and(|v| v > 0.0));
    }
    // Trees of another scene are refused with a message that says so.
    let other = Command::new(bin())
        .args(["render", "builtin:plate", "--trees"])
        .arg(&trees)
        .arg("--out")
        .arg(dir.join("x.png"))
        .output()
        .expect("run bspvt");
    assert!(!other.status.success());
    let msg = String::from_utf8_lossy(&other.stderr);
    assert!(msg.contains("different mesh"), "{msg}");
    let _ = std::fs::remove_dir_all(&dir);
}
