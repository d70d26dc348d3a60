//! A real bake, end to end: `builtin::scene("plate-small")` at face_res 16 baked by
//! `Baker::bake_all` on a 1-thread and a 2-thread rayon pool (each in a child process of this
//! test binary with `RAYON_NUM_THREADS`, since the global pool is fixed per process) gives
//! byte-identical files, which decode to one tree set per vertex equal to `bake_vertex`'s.
//! And an acne check: a convex mesh (icosphere) or a flat plane alone occludes none of its own
//! vertices' rays.

use std::path::PathBuf;
use std::process::Command;
use std::sync::atomic::AtomicBool;

use bspvt_bake::Baker;
use bspvt_proto::builtin::{self, grid_plane, icosphere};
use bspvt_proto::encoding::{decode_bake, decode_header, peek_chunk};
use bspvt_proto::{BakeSettings, Mesh};
use glam::Vec3;

/// Set in a child process: bake plate-small and write the file here.
const CHILD_OUT: &str = "BSPVT_TEST_BAKE_CHILD_OUT";

fn plate_small_baker() -> Baker {
    let mut scene = builtin::scene("plate-small").expect("built-in scene");
    scene.bake.face_res = 16;
    Baker::new(&scene)
}

fn bake_all(baker: &Baker) -> Vec<u8> {
    baker
        .bake_all(&|_, _| {}, &AtomicBool::new(false))
        .expect("not cancelled")
        .bytes
}

/// Not a test by itself: the body of the child processes of
/// `bake_is_byte_identical_across_thread_counts` (returns at once unless `CHILD_OUT` is set).
#[test]
fn child_process_bake() {
    let Some(out) = std::env::var_os(CHILD_OUT) else {
        return;
    };
    let t = std::time::Instant::now();
    let bytes = bake_all(&plate_small_baker());
    eprintln!(
        "child (RAYON_NUM_THREADS={}): baked {} bytes in {:.2} s",
        std::env::var("RAYON_NUM_THREADS").unwrap_or_default(),
        bytes.len(),
        t.elapsed().as_secs_f64()
    );
    std::fs::write(&out, bytes).expect("write the bake");
}

fn bake_in_child(threads: usize) -> Vec<u8> {
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "plate-small-{}-{threads}.bspvt",
        std::process::id()
    ));
    let exe = std::env::current_exe().expect("test binary path");
    let out = Command::new(exe)
        .args([
            "child_process_bake",
            "--exact",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_OUT, &path)
        .env("RAYON_NUM_THREADS", threads.to_string())
        .output()
        .expect("run the child");
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "child failed: {log}");
    for line in log.lines().filter(|l| l.starts_with("child")) {
        eprintln!("{line}");
    }
    let bytes = std::fs::read(&path).expect("the child wrote the bake");
    let _ = std::fs::remove_file(&path);
    bytes
}

#[test]
fn bake_is_byte_identical_across_thread_counts() {
    let one = bake_in_child(1);
    let two = bake_in_child(2);
    assert_eq!(
        one.len(),
        two.len(),
        "1 thread: {} bytes, 2 threads: {} bytes",
        one.len(),
        two.len()
    );
    if let Some(i) = one.iter().zip(&two).position(|(a, b)| a != b) {
        panic!("bakes differ first at byte {i} of {}", one.len());
    }

    let baker = plate_small_baker();
    let t = std::time::Instant::now();
    let here = bake_all(&baker);
    let secs = t.elapsed().as_secs_f64();
    assert!(
        here == one,
        "the in-process bake (default pool) differs from the 1-thread one"
    );

    let n = baker.mesh().vertex_count();
    // 43² grid + icosphere(3) + a cuboid of six 4 × 4 grids. (builtin.rs's doc comment says
    // "1,849 + 642 + 150": the cuboid has 96 vertices.)
    assert_eq!(n, 43 * 43 + 642 + 6 * 16);
    let bake = decode_bake(&one).expect("the bake decodes");
    assert_eq!(&bake.header, baker.header());
    assert_eq!(bake.header.vertex_count as usize, n);
    assert_eq!(bake.header.face_res, 16);
    assert_eq!(bake.trees.len(), n);

    // The frames: one header, then chunk c holds vertices c·chunk_vertices …
    let (h, mut pos) = decode_header(&one).expect("header");
    let mut c = 0;
    while pos < one.len() {
        let (ch, used) = peek_chunk(&one[pos..]).expect("chunk frame");
        assert_eq!(ch.first_vertex, c * h.chunk_vertices);
        assert_eq!(
            ch.first_vertex..ch.first_vertex + ch.vertex_count,
            baker.chunk_range(c)
        );
        pos += used;
        c += 1;
    }
    assert_eq!(c, h.chunk_count());

    // Decoded trees equal what bake_vertex returns.
    let mut checked = 0;
    let mut leaves = 0;
    for v in (0..n as u32)
        .step_by(23)
        .chain([1848, 1849, 2490, 2491, n as u32 - 1])
    {
        assert_eq!(
            bake.trees[v as usize],
            baker.bake_vertex(v).trees,
            "vertex {v}"
        );
        checked += 1;
    }
    for t in &bake.trees {
        leaves += t.leaf_count();
    }
    let sizes: Vec<usize> = bake
        .trees
        .iter()
        .map(|t| {
            let mut b = Vec::new();
            bspvt_proto::encoding::encode_vertex(t, &baker.codec().clone(), &mut b);
            b.len()
        })
        .collect();
    eprintln!(
        "plate-small @16: {n} vertices, {} chunks, {} bytes ({:.1} B/vertex after zstd, {:.1} B/vertex raw), \
         {:.1} leaves/vertex, {} one-byte vertices; in-process bake {secs:.2} s; {checked} vertices re-baked and equal",
        c,
        one.len(),
        one.len() as f64 / n as f64,
        sizes.iter().sum::<usize>() as f64 / n as f64,
        leaves as f64 / n as f64,
        sizes.iter().filter(|&&s| s == 1).count()
    );
}

/// Occluded pixels that matter, over every vertex of `mesh` baked alone.
fn self_occlusion(mesh: Mesh, face_res: u32, supersampling: u32) -> (u64, u64, u64, Vec<u32>) {
    let n = mesh.vertex_count() as u32;
    let settings = BakeSettings {
        face_res,
        supersampling,
        ..BakeSettings::default()
    };
    let baker = Baker::with_settings(mesh, settings, None);
    let s2 = (supersampling * supersampling) as u16;
    let (mut pixels, mut occluded, mut rays_lost) = (0u64, 0u64, 0u64);
    let mut bad_vertices = Vec::new();
    for v in 0..n {
        let (faces, _) = baker.cube_map(v);
        let mut bad = false;
        for px in faces.iter().flatten() {
            pixels += px.index.len() as u64;
            for &k in &px.visible {
                if k != s2 {
                    occluded += 1;
                    rays_lost += (s2 - k) as u64;
                    bad = true;
                }
            }
        }
        if bad {
            bad_vertices.push(v);
        }
    }
    (pixels, occluded, rays_lost, bad_vertices)
}

fn tilted_plane() -> Mesh {
    // A 21 × 21 plane with normal (1, 2, 3)/√14: no axis-aligned coincidences.
    let n = Vec3::new(1.0, 2.0, 3.0).normalize();
    let du = n.any_orthonormal_vector();
    let dv = n.cross(du);
    grid_plane(Vec3::new(0.3, -0.2, 0.1), du, dv, 21, 0)
}

#[test]
fn convex_and_flat_meshes_do_not_shadow_themselves() {
    for (name, mesh) in [
        ("icosphere(3)", icosphere(3, 0)),
        (
            "grid_plane 21×21",
            grid_plane(Vec3::ZERO, Vec3::X, Vec3::NEG_Z, 21, 0),
        ),
        ("tilted grid_plane 21×21", tilted_plane()),
    ] {
        for res in [16u32, 32] {
            let (pixels, occluded, _, bad) = self_occlusion(mesh.clone(), res, 1);
            eprintln!(
                "{name}, res {res}, 1 ray/pixel: {pixels} pixels that matter, {occluded} occluded ({} vertices)",
                bad.len()
            );
            assert!(pixels > 0);
            assert_eq!(
                occluded,
                0,
                "{name} @ {res}: occluded pixels at vertices {:?}",
                &bad[..bad.len().min(10)]
            );
        }
    }
}

/// With supersampling, a pixel whose centre is above the horizon may have sub-pixel rays below
/// it; for a flat or convex mesh those rays hit the mesh's own (non-adjacent) triangles. A
/// pixel that matters should still be fully visible (the sub-rays under the horizon cannot
/// carry light to the vertex).
#[test]
fn supersampled_horizon_pixels_are_not_self_shadowed() {
    let mut total = 0;
    for (name, mesh) in [
        ("icosphere(3)", icosphere(3, 0)),
        (
            "grid_plane 21×21",
            grid_plane(Vec3::ZERO, Vec3::X, Vec3::NEG_Z, 21, 0),
        ),
        ("tilted grid_plane 21×21", tilted_plane()),
    ] {
        for s in [2u32, 4] {
            let (pixels, occluded, rays, bad) = self_occlusion(mesh.clone(), 16, s);
            eprintln!(
                "{name}, res 16, {}×{} rays/pixel: {pixels} pixels that matter, {occluded} partly occluded \
                 ({rays} rays) at {} of {} vertices",
                s,
                s,
                bad.len(),
                mesh.vertex_count()
            );
            total += occluded;
        }
    }
    assert_eq!(total, 0, "supersampled horizon pixels are self-shadowed");
}
