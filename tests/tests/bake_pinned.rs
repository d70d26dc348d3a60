//! The bake's bytes are pinned: the offline bake of the built-in scene and of two shared
//! meshes hashes (FNV-1a 64 of the whole file) to the values the bake produced before the
//! crates were split (commit 581d5b0). A change to the bake, the fit or the encoding that
//! alters a single byte fails here; the service's tree stream equals the offline file
//! (server/tests/service_bake.rs), so it is pinned with it. Thread count does not matter
//! (tests/tests/bake_roundtrip.rs).

use std::sync::atomic::AtomicBool;

use bspvt_bake::Baker;
use bspvt_proto::Scene;
use bspvt_proto::hash::Fnv1a;

fn bake_hash(scene: &Scene) -> (usize, u64) {
    let out = Baker::new(scene)
        .bake_all(&|_, _| {}, &AtomicBool::new(false))
        .expect("not cancelled");
    let mut h = Fnv1a::default();
    h.write(&out.bytes);
    (out.bytes.len(), h.finish())
}

#[test]
fn builtin_scene_bake_is_pinned() {
    let scene = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
    assert_eq!(bake_hash(&scene), (125_877, 0xfeff_5238_48ce_eebc));
}

#[test]
fn shared_mesh_bakes_are_pinned() {
    let dir = bspvt_proto::paths::meshes_dir();
    for (file, bytes, hash) in [
        ("bunny_res4.ply", 119_829, 0xe8c4_9a1c_c5ed_8644_u64),
        ("teapot.obj", 140_731, 0x88bd_8123_5812_9ace),
    ] {
        let path = dir.join(file);
        if !path.is_file() {
            eprintln!(
                "skipped {file}: not found in {} (set BSPVT_ASSETS)",
                dir.display()
            );
            continue;
        }
        let mut scene = Scene::from_mesh_path(&path).expect("mesh scene");
        scene.bake.face_res = 16;
        assert_eq!(bake_hash(&scene), (bytes, hash), "{file}");
    }
}
