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
    assert!(status["warnings"].is_array(), "{status}");
    let stored = get(&a, &srv.url(&format!("/v1/scenes/{id}/scene"))).body;
    let served = bspvt_proto::api::decode_scene(&stored).expect("the stored scene decodes");
    assert_eq!(
        served.punctual.len(),
        1,
        "the asset's point light is stored"
    );
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
    let frame = |s: &bspvt_proto::Scene| {
        Renderer::new(s, 48, 48)
            .ltc(std::slice::from_ref(&light), Mode::Pixel)
            .0
    };
    assert!(frame(&served) == frame(&offline));
    eprintln!(
        "stored scene: {} bytes ({} vertices)",
        stored.len(),
        served.mesh.vertex_count()
    );
}

/// A mesh whose materials and lamp live in other files (the Cornell box: OBJ + MTL with `Ke`)
/// submitted as the viewer submits `--mesh`: the client uploads the material library with it,
/// and the service stores the scene the offline path opens (the room lit by its own lamp, not
/// the default quad light above a closed ceiling, which once left every streamed frame black).
/// The same for a `.gltf` whose buffer and texture are files beside it.
#[test]
fn a_mesh_is_submitted_with_the_files_it_reads() {
    let cornell = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rooms/cornell-box.obj");
    let tmp = tempfile::tempdir().expect("temp dir");
    // The room glTF split into a .gltf, an external .bin and a PNG texture in a subfolder.
    let split = tmp.path().join("split");
    std::fs::create_dir_all(split.join("tex")).expect("dirs");
    let room = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rooms/room.gltf");
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&room).expect("room")).expect("json");
    let uri = doc["buffers"][0]["uri"].as_str().expect("uri").to_string();
    let b64 = uri.split_once(",").expect("data uri").1;
    use base64::Engine as _;
    let bin = base64::engine::general_purpose::STANDARD
        .decode(b64)
        .expect("base64");
    std::fs::write(split.join("room data.bin"), bin).expect("bin");
    doc["buffers"][0]["uri"] = "room%20data.bin".into();
    let mut png = Vec::new();
    image::RgbImage::from_fn(4, 4, |x, y| {
        image::Rgb([(x * 60) as u8, (y * 60) as u8, 90])
    })
    .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
    .expect("png");
    std::fs::write(split.join("tex/wall.png"), &png).expect("png");
    doc["images"] = serde_json::json!([{"uri": "tex/wall.png"}]);
    doc["textures"] = serde_json::json!([{"source": 0}]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] =
        serde_json::json!({"index": 0});
    let gltf = split.join("room.gltf");
    std::fs::write(&gltf, serde_json::to_vec(&doc).expect("json")).expect("gltf");

    let srv = start(&tmp.path().join("data"), "127.0.0.1:0", &[]);
    let remote = Remote::new(&srv.base, None);
    let a = agent();
    for (asset, files) in [
        (cornell.as_path(), vec!["cornell-box.mtl"]),
        (gltf.as_path(), vec!["room data.bin", "tex/wall.png"]),
    ] {
        let local = bspvt_proto::import::load_asset(asset).expect("loads");
        assert_eq!(local.files, files, "the files {} reads", asset.display());
        let id = remote.submit(None, Some(asset)).expect("submit");
        let stored = get(&a, &srv.url(&format!("/v1/scenes/{id}/scene")));
        assert_eq!(stored.status, 200, "{}", stored.text());
        let served = bspvt_proto::api::decode_scene(&stored.body).expect("decodes");
        let mut offline = bspvt_client::scene::open(None, Some(asset)).expect("offline");
        offline.warnings.clear();
        let name = asset.display();
        assert_eq!(served.lights, offline.lights, "{name}: its own lamps");
        assert_eq!(served.materials, offline.materials, "{name}: its materials");
        assert_eq!(
            served.mesh.vertex_count(),
            offline.mesh.vertex_count(),
            "{name}: refined alike"
        );
        // The whole scene (printed only in part: a refined mesh is long).
        assert!(served == offline, "{name}: the served scene differs");
        // Only the bake's cost is saved here: the scene is what this test is about.
        bspvt_tests::service::delete(&a, &srv.url(&format!("/v1/scenes/{id}")), None);
    }
    // A bare mesh without lamps, opened as `view --mesh` opens it: the session is told what
    // the service's importer added (the stored scene carries no warnings; the status does).
    let tri = tmp.path().join("tri.obj");
    std::fs::write(&tri, "v 0 0 0\nv 1 0 0\nv 0 1 1\nf 1 2 3\n").expect("obj");
    let connected =
        bspvt_client::session::connect::connect(&bspvt_client::session::connect::ConnectOptions {
            source: None,
            mesh: Some(tri),
            server: Some(srv.base.clone()),
            api_key: None,
            data_dir: tmp.path().join("client"),
            cache_dir: None,
            embedded: None,
        })
        .expect("connect");
    assert!(
        connected
            .scene
            .warnings
            .iter()
            .any(|w| w.contains("a quad light above it and a ground plane under it were added")),
        "{:?}",
        connected.scene.warnings
    );

    let textured = bspvt_client::scene::open(None, Some(&gltf)).expect("offline");
    assert!(textured.materials.iter().any(|m| m.maps.is_some()));

    // A scene file whose light names a texture file in a subfolder: the loader decodes it
    // (sRGB → linear), the form uploads it by file name, and the served scene carries it.
    let mut grey = Vec::new();
    image::RgbImage::from_fn(2, 1, |x, _| image::Rgb([if x == 0 { 128 } else { 255 }; 3]))
        .write_to(
            &mut std::io::Cursor::new(&mut grey),
            image::ImageFormat::Png,
        )
        .expect("png");
    std::fs::write(split.join("tex/light.png"), &grey).expect("png");
    let mut file: serde_json::Value =
        serde_json::from_str(bspvt_proto::builtin::DYNAMIC_JSON).expect("a built-in scene file");
    file["lights"][0]["texture"] = "tex/light.png".into();
    let scene_path = split.join("lit.json");
    std::fs::write(&scene_path, serde_json::to_vec(&file).expect("json")).expect("scene");
    let scene_arg = scene_path.to_string_lossy().into_owned();
    let id = remote.submit(Some(&scene_arg), None).expect("submit");
    let stored = get(&a, &srv.url(&format!("/v1/scenes/{id}/scene")));
    let served = bspvt_proto::api::decode_scene(&stored.body).expect("decodes");
    let offline = bspvt_client::scene::open(Some(&scene_arg), None).expect("offline");
    let image = offline.lights[0]
        .image
        .as_ref()
        .expect("the texture, decoded");
    // IEC 61966-2-1: 128/255 → 0.2158605.
    assert!(
        (image.texels[0][0] - 0.215_860_5).abs() < 1e-6,
        "{:?}",
        image.texels
    );
    assert_eq!(image.texels[1], [1.0; 3]);
    assert_eq!(
        served.lights, offline.lights,
        "the served light carries its texture"
    );
    Light::load(&served.lights[0]).expect("the served light loads anywhere");
    bspvt_tests::service::delete(&a, &srv.url(&format!("/v1/scenes/{id}")), None);
}
