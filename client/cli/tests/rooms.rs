//! Enclosed rooms given alone, as a user brings them (`--mesh`): the project's Cornell box
//! (OBJ + MTL with `Ke`) and glTF room (`assets/rooms/`). Their own lamps light them, the
//! ceiling above the lamp does not shadow the floor, and BSPVT per pixel agrees with the
//! project's Monte Carlo reference.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use bspvt_bake::Baker;
use bspvt_client::frame::image::Image;
use bspvt_client::groundtruth::render_mc;
use bspvt_client::light::Light;
use bspvt_client::render::renderer::{Mode, Renderer, Trees};
use bspvt_proto::Scene;
use bspvt_proto::encoding::decode_bake;
use bspvt_raytrace::{Occluder, mesh_triangles};

fn room(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/rooms")
        .join(name)
}

/// Mean over pixels of the channel-mean |a − b|.
fn mean_abs_diff(a: &Image, b: &Image) -> f64 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(x, y)| (0..3).map(|k| f64::from((x[k] - y[k]).abs())).sum::<f64>() / 3.0)
        .sum::<f64>()
        / a.pixels.len() as f64
}

/// BSPVT (per pixel and per vertex) and unshadowed LTC against Monte Carlo; returns the
/// errors relative to the Monte Carlo mean: (per pixel, per vertex, shadows' effect).
fn errors(scene: &Scene, size: (u32, u32), spp: u32) -> (f64, f64, f64) {
    let bytes = Baker::new(scene)
        .bake_all(&|_, _| {}, &AtomicBool::new(false))
        .expect("bake")
        .bytes;
    let b = decode_bake(&bytes).expect("decode");
    // A refined scene's bake carries the refined mesh, whose hash the header names.
    assert_eq!(
        b.mesh.as_ref(),
        Some(&scene.mesh),
        "the bake carries its mesh"
    );
    let trees = Trees::full(&b.trees, b.header.codec());
    let r = Renderer::new(scene, size.0, size.1);
    let light = Light::from_scene(&scene.lights[0]);
    let (pixel, _) = r.bspvt(&light, &trees, Mode::Pixel);
    let (vertex, _) = r.bspvt(&light, &trees, Mode::Vertex);
    let (unshadowed, _) = r.ltc(&light, Mode::Pixel);
    let occ = Occluder::new(&scene.mesh, &mesh_triangles(&scene.mesh));
    let (mc, _) = render_mc(scene, &r.view, &r.gbuffer, &light, &occ, spp, 7);
    for img in [&pixel, &vertex, &unshadowed, &mc] {
        assert!(
            img.pixels
                .iter()
                .flatten()
                .all(|c| c.is_finite() && *c >= 0.0)
        );
    }
    let mean = mc.mean();
    assert!(mean > 0.0, "the room is black");
    (
        mean_abs_diff(&pixel, &mc) / mean,
        mean_abs_diff(&vertex, &mc) / mean,
        mean_abs_diff(&unshadowed, &mc) / mean,
    )
}

#[test]
fn cornell_box_bspvt_per_pixel_matches_monte_carlo() {
    let mut s = Scene::from_mesh_path(&room("cornell-box.obj")).expect("cornell box");
    s.bake.face_res = 32;
    // A budget keeps the test quick (the default refines to ~16K vertices).
    if let Some(r) = &mut s.bake.refine {
        r.max_vertices = 4000;
    }
    let before = s.mesh.vertex_count();
    bspvt_bake::refine::refine_scene(&mut s).expect("refine");
    let (pixel, vertex, shadows) = errors(&s, (64, 64), 64);
    println!(
        "cornell box: {before} → {} vertices; vs MC: per pixel {pixel:.4}, per vertex {vertex:.4}, unshadowed {shadows:.4}",
        s.mesh.vertex_count()
    );
    assert!(pixel <= 0.05, "per-pixel error {pixel}");
}

#[test]
fn gltf_room_bspvt_per_pixel_matches_monte_carlo() {
    let mut s = Scene::from_mesh_path(&room("room.gltf")).expect("room");
    s.bake.face_res = 32;
    // A budget keeps the test quick (the default refines to ~16K vertices).
    if let Some(r) = &mut s.bake.refine {
        r.max_vertices = 4000;
    }
    let before = s.mesh.vertex_count();
    bspvt_bake::refine::refine_scene(&mut s).expect("refine");
    let (pixel, vertex, shadows) = errors(&s, (72, 48), 64);
    println!(
        "glTF room: {before} → {} vertices; vs MC: per pixel {pixel:.4}, per vertex {vertex:.4}, unshadowed {shadows:.4}",
        s.mesh.vertex_count()
    );
    assert!(pixel <= 0.05, "per-pixel error {pixel}");
}
