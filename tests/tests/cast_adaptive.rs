//! The adaptive cast (`CastMode::Adaptive`, the default) gives the same cube maps as the full
//! cast and as casting every ray against the BVH, bit for bit, on the shared meshes (scanned
//! bunny and dragon, the non-manifold teapot, each on the default ground under the default
//! light), at face resolutions from the smallest the bake accepts (4) to the largest (512),
//! odd and non-power-of-two ones included, with and without supersampling; and a bake is
//! byte-identical whichever cast made it and on 1 or 2 threads. Skips, saying so, when the
//! shared meshes are absent. The built-in room (edge ties) is compared at every vertex.

use std::sync::atomic::AtomicBool;

use bspvt_bake::{Baker, CastMode};
use bspvt_proto::{BakeSettings, Scene};

/// The shared mesh's default scene at `res`² × `ss`², or `None` (with a message) when the
/// file is not there.
fn mesh_baker(file: &str, res: u32, ss: u32) -> Option<Baker> {
    let dir = bspvt_proto::paths::meshes_dir();
    let path = dir.join(file);
    if !path.is_file() {
        eprintln!(
            "skipped {file}: not found in {} (set BSPVT_ASSETS)",
            dir.display()
        );
        return None;
    }
    let mut scene = Scene::from_mesh_path(&path).expect("mesh scene");
    scene.bake.face_res = res;
    scene.bake.supersampling = ss;
    Some(Baker::new(&scene))
}

/// Compares the casts on `count` vertices spread over the mesh (the reference too when
/// `reference`); returns the occluded pixels seen, so a caller can check the comparison saw
/// shadows.
fn compare(b: &Baker, label: &str, count: u32, reference: bool) -> usize {
    let n = b.mesh().vertex_count() as u32;
    let s = b.header().supersampling.pow(2) as u16;
    let mut occluded = 0;
    for k in 0..count.min(n) {
        // Spread over the mesh, the ground's vertices (appended last) included.
        let v = (k as u64 * n as u64 / count.min(n) as u64) as u32;
        let (full, fc) = b.cube_map_with(v, CastMode::Full);
        let (adaptive, ac) = b.cube_map_with(v, CastMode::Adaptive);
        assert_eq!(adaptive, full, "{label}: vertex {v}, adaptive vs full");
        assert!(
            ac.traversals <= fc.traversals,
            "{label}: vertex {v}: {} traversals adaptive, {} full",
            ac.traversals,
            fc.traversals
        );
        // Deterministic: the same vertex cast again gives the same map and the same work.
        assert_eq!(
            b.cube_map_with(v, CastMode::Adaptive),
            (adaptive.clone(), ac),
            "{label}: vertex {v}, adaptive twice"
        );
        if reference {
            assert_eq!(
                full,
                b.reference_cube_map(v),
                "{label}: vertex {v}, full vs every ray"
            );
        }
        occluded += full
            .iter()
            .flatten()
            .flat_map(|f| &f.visible)
            .filter(|&&x| x < s)
            .count();
    }
    occluded
}

const MESHES: [&str; 3] = ["bunny_res4.ply", "teapot.obj", "dragon_res4.ply"];

#[test]
fn adaptive_equals_full_and_every_ray_on_shared_meshes() {
    // The bake accepts 4..=512: the smallest, odd, non-power-of-two and power-of-two sizes
    // below the default (64). Larger ones in `adaptive_equals_full_at_large_faces`.
    for res in [4, 5, 7, 8, 12, 16, 24, 31, 50, 64] {
        for file in MESHES {
            let Some(b) = mesh_baker(file, res, 1) else {
                continue;
            };
            let occluded = compare(&b, &format!("{file} at {res}²"), 12, true);
            assert!(occluded > 0, "{file} at {res}²: no shadow seen");
        }
    }
}

#[test]
fn adaptive_equals_full_at_every_resolution_to_128() {
    // Every face resolution from the smallest the bake accepts to 128² (the quadtree walk's
    // block sizes turn odd at different depths), two vertices each: one of the teapot, one of
    // its ground.
    let Some(first) = mesh_baker("teapot.obj", 4, 1) else {
        return;
    };
    let n = first.mesh().vertex_count() as u32;
    for res in 4..=128 {
        let Some(b) = mesh_baker("teapot.obj", res, 1) else {
            return;
        };
        for v in [n / 7, n - 5] {
            assert_eq!(
                b.cube_map_with(v, CastMode::Adaptive).0,
                b.cube_map_with(v, CastMode::Full).0,
                "teapot.obj at {res}²: vertex {v}"
            );
        }
    }
}

#[test]
fn adaptive_equals_full_with_supersampling() {
    for (res, ss) in [(8, 2), (16, 3), (24, 2)] {
        for file in MESHES {
            let Some(b) = mesh_baker(file, res, ss) else {
                continue;
            };
            let occluded = compare(&b, &format!("{file} at {res}² × {ss}²"), 8, true);
            assert!(occluded > 0, "{file} at {res}² × {ss}²: no shadow seen");
        }
    }
}

#[test]
fn adaptive_equals_full_at_large_faces() {
    // Every ray at 512² is 786K rays a vertex: the reference only up to 128².
    for (res, count, reference) in [(100, 4, true), (128, 3, true), (256, 2, false)] {
        for file in MESHES {
            let Some(b) = mesh_baker(file, res, 1) else {
                continue;
            };
            compare(&b, &format!("{file} at {res}²"), count, reference);
        }
    }
    if let Some(b) = mesh_baker("bunny_res4.ply", BakeSettings::MAX_FACE_RES, 1) {
        compare(&b, "bunny_res4.ply at 512²", 1, false);
    }
}

/// The room (built in, refined as its bake is): floor and walls on a dyadic grid, so pixel
/// rays cross them exactly on triangle edges, where the BVH traversal and the triangle test
/// could disagree. The adaptive cast leaves rays that cross a triangle near an edge to the
/// traversal, so it equals the full cast at every vertex; and the full cast, whose candidate
/// lists test triangles without boxes, equals the traversal of every ray (the BVH's boxes reach
/// past their triangles: before, one ray at 16² hit a wall's edge that was its leaf box's face
/// in the lists and slipped past the box in the traversal).
#[test]
fn adaptive_equals_full_on_the_room() {
    for (res, step) in [(8, 1), (16, 3)] {
        let mut scene = bspvt_proto::builtin::scene("room").expect("built-in room");
        scene.bake.face_res = res;
        bspvt_bake::refine::refine_scene(&mut scene).expect("refinement");
        let b = Baker::new(&scene);
        let n = b.mesh().vertex_count() as u32;
        for v in (0..n).step_by(step) {
            let full = b.cube_map_with(v, CastMode::Full).0;
            assert_eq!(
                b.cube_map_with(v, CastMode::Adaptive).0,
                full,
                "room at {res}²: vertex {v}"
            );
            assert_eq!(
                b.reference_cube_map(v),
                full,
                "room at {res}²: vertex {v}, every ray"
            );
        }
    }
}

fn bake_bytes(b: &Baker, threads: usize) -> Vec<u8> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool")
        .install(|| b.bake_all(&|_, _| {}, &AtomicBool::new(false)))
        .expect("not cancelled")
        .bytes
}

#[test]
fn bake_is_the_same_whichever_cast_and_thread_count() {
    for file in ["teapot.obj", "bunny_res4.ply"] {
        let Some(mut b) = mesh_baker(file, 16, 1) else {
            continue;
        };
        assert_eq!(b.cast(), CastMode::Adaptive, "the default cast");
        let one = bake_bytes(&b, 1);
        let two = bake_bytes(&b, 2);
        assert!(one == two, "{file}: adaptive, 1 vs 2 threads");
        b.set_cast(CastMode::Full);
        let full = bake_bytes(&b, 2);
        assert!(one == full, "{file}: adaptive vs full cast");
    }
}
