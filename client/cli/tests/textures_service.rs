//! The project's textured asset (`assets/rooms/textured-floor.gltf`: a checker base-colour
//! texture, a lamp with an emissive texture, a punctual spot) submitted to the real service
//! (`bspvt serve` on loopback) as a bare mesh: the stored scene it serves carries the UVs of
//! the refined mesh, the textures, the lamp's image and the spot, and equals the scene the
//! offline path opens (so every client renders the same textured frames).

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::Path;

use bspvt_client::light::Light;
use bspvt_client::render::renderer::{Mode, Renderer};
use bspvt_client::stream::remote::Remote;
use bspvt_tests::service::{agent, get, wait_done};
use common::*;

#[test]
fn the_service_stores_and_serves_the_textured_scene() {
    let asset =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rooms/textured-floor.gltf");
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), "127.0.0.1:0", &[]);
    let remote = Remote::new(&srv.base, None);
    let id = remote.submit(None, Some(&asset)).expect("submit");
    let a = agent();
    let status = wait_done(&a, &srv, &id);
    let warnings = status["warnings"].as_array().expect("warnings");
    assert!(
        warnings.iter().any(|w| w
            .as_str()
            .is_some_and(|w| w.contains("1 punctual lights feed the point-light methods only"))),
        "{warnings:?}"
    );
    let stored = get(&a, &srv.url(&format!("/v1/scenes/{id}/scene"))).body;
    let served = bspvt_proto::api::decode_scene(&stored).expect("the stored scene decodes");
    let mut offline = bspvt_client::scene::open(None, Some(&asset)).expect("offline scene");
    offline.warnings.clear();
    assert_eq!(
        served, offline,
        "the served scene is the offline one, textures and all"
    );
    assert!(
        served.mesh.vertex_count() > 4,
        "refined where the lamp's light varies"
    );
    assert_eq!(served.mesh.uvs.len(), served.mesh.vertex_count());
    // Every refined floor vertex keeps the floor's affine UVs: u = (x + 1) / 2, v = (z + 1) / 2.
    for (p, uv) in served.mesh.positions.iter().zip(&served.mesh.uvs) {
        assert!(
            (uv.x - (p.x + 1.0) / 2.0).abs() < 1e-6 && (uv.y - (p.z + 1.0) / 2.0).abs() < 1e-6,
            "{p} has UV {uv}"
        );
    }
    assert!(served.materials.iter().any(|m| m.maps.is_some()));
    assert!(
        served.lights[0].image.is_some(),
        "the lamp's emissive texture"
    );
    assert_eq!(served.punctual.len(), 1);
    let light = Light::load(&served.lights[0]).expect("light");
    let frame = |s: &bspvt_proto::Scene| Renderer::new(s, 48, 48).ltc(&light, Mode::Pixel).0;
    assert!(frame(&served) == frame(&offline));
    eprintln!(
        "stored scene: {} bytes ({} vertices)",
        stored.len(),
        served.mesh.vertex_count()
    );
}
