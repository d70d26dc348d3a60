//! The bake's bytes are pinned: the offline bake of the built-in scene and of two shared
//! meshes hashes (FNV-1a 64 of the whole file) to the values the bake produced before the
//! crates were split (commit 581d5b0), re-pinned four times since: when the rays of a vertex on an
//! open boundary started leaving from inside its own surface (`bspvt-bake`'s `origin`, so that a
//! surface meeting that boundary shadows them) — the trees that changed are those of boundary
//! vertices only: plate-small 55 of 240, bunny_res4 9 of 406, teapot 360 of 1,369 (of 2,587,
//! 9,669 and 12,860 vertices; the teapot's spout and handle end on its body); and when the
//! default split search's angle schedule changed (issue 23, 2026-11-27: every 45° then
//! bisection around the best, instead of every 8th angle then ±4, ±2, ±1 around the two best;
//! docs/bake.md — lower error and fewer bytes on every shared mesh at 64²; at the 16² faces
//! pinned here every leaf is exact either way); and when directions that cannot reach a light's
//! plane became "don't care" (issue 23, 2026-11-27, docs/bake.md "Per vertex": the meshes'
//! default lamp has no region; plate-small's has one and is unchanged: bunny_res4 119,882 →
//! 116,794 bytes, teapot 141,082 → 128,028); and when the ray–triangle test became closed at the
//! edges (issue 35, 2026-11-27, `bspvt_raytrace::hit`: a ray through an edge two triangles share
//! slipped between them): bunny_res4 1 tree of 9,669, 116,794 → 116,798 bytes; plate-small and
//! the teapot unchanged; and when the fit's decisions became exact integers (issue 36 item 1,
//! 2026-11-29, for a GPU fit: the angle ranking by the children's squared deviation compares
//! exact ratios instead of ⌊1024·SSD⌋ buckets, `bspvt-bake`'s `fit`): plate-small 122,511 →
//! 122,514 bytes, bunny_res4 116,798 → 116,791, the teapot unchanged (the integer leaf test,
//! leaf value and deviation sums alone change no byte). A change to the bake, the fit or the encoding that
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
    assert_eq!(bake_hash(&scene), (122_514, 0x7cdf_fec5_1a36_e4b4));
}

#[test]
fn shared_mesh_bakes_are_pinned() {
    let dir = bspvt_proto::paths::meshes_dir();
    for (file, bytes, hash) in [
        ("bunny_res4.ply", 116_791, 0x0e53_16af_6ded_0e68_u64),
        ("teapot.obj", 128_028, 0xaf73_add6_d0c4_82ca),
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
