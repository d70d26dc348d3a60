//! The GPU cast (`Baker::gpu_cube_maps`, a wgpu compute shader over the CPU-built CWBVH) gives
//! the cube maps of the full CPU cast on the shared meshes (scanned bunny and dragon, the
//! non-manifold teapot, on the default ground under the default light), on the built-in
//! plate-small, at face resolutions from the smallest the bake accepts (4) to the largest (512),
//! with and without supersampling, and on the rooms, exactly: the shader flags every pixel where
//! its rounding could decide a ray otherwise than the CPU's (a ray through a triangle's edge),
//! and the CPU casts those again. The GPU cast is deterministic, and a GPU bake writes the CPU
//! bake's bytes.
//!
//! Runs on any wgpu adapter, Mesa's lavapipe (software Vulkan) included; skips, saying so,
//! when there is none, and skips the shared meshes when they are absent.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use bspvt_bake::cubemap::FacePixels;
use bspvt_bake::gpu_cast::{FitOn, GpuContext};
use bspvt_bake::{Baker, CastMode};
use bspvt_proto::{BakeSettings, Scene};

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

fn plate_baker(res: u32, ss: u32) -> Baker {
    let mut scene = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
    scene.bake.face_res = res;
    scene.bake.supersampling = ss;
    Baker::new(&scene)
}

/// What a comparison saw.
#[derive(Default)]
struct Seen {
    /// Sub-rays cast (escaping below the horizon not counted).
    rays: u64,
    /// Of those, sub-rays of pixels the GPU flagged as unsure, cast again on the CPU.
    recast: u64,
    /// Sub-rays whose answer differs (|Δ escaping| summed over pixels).
    differing: u64,
    /// Of those, sub-rays the GPU finds occluded and the CPU escaping.
    gpu_occluded: u64,
    /// Occluded pixels (some sub-ray blocked).
    occluded: u64,
    /// (differing sub-rays, vertex, face) of the faces that differ most.
    worst: Vec<(u64, u32, usize)>,
}

/// Compares the GPU cast of `count` vertices spread over the mesh (the centres of `count`
/// equal runs of its vertices) with the full CPU cast.
fn compare(ctx: &Arc<GpuContext>, b: &Baker, label: &str, count: u32) -> Seen {
    let n = b.mesh().vertex_count() as u32;
    let s = b.header().supersampling.pow(2) as u16;
    let caster = b.gpu_caster(ctx.clone()).expect("BVH on the GPU");
    let count = count.min(n);
    let vertices: Vec<u32> = (0..count)
        .map(|k| ((2 * k as u64 + 1) * n as u64 / (2 * count as u64)) as u32)
        .collect();
    let mut seen = Seen::default();
    for &v in &vertices {
        let (gpu, counts) = b.gpu_cube_maps(&caster, &[v]).expect("GPU cast");
        let (again, _) = b.gpu_cube_maps(&caster, &[v]).expect("GPU cast");
        assert!(
            gpu == again,
            "{label}: vertex {v}: GPU cast not deterministic"
        );
        let (full, _) = b.cube_map_with(v, CastMode::Full);
        let gpu = &gpu[0];
        seen.rays += counts.rays;
        seen.recast += counts.recast;
        for (f, (g, c)) in gpu.iter().zip(&full).enumerate() {
            let (g, c): (&FacePixels, &FacePixels) = match (g, c) {
                (Some(g), Some(c)) => (g, c),
                (None, None) => continue,
                _ => panic!("{label}: vertex {v} face {f}: pixels that matter differ"),
            };
            assert_eq!(
                g.index, c.index,
                "{label}: vertex {v} face {f}: pixels that matter"
            );
            let mut face_differing = 0;
            for (&a, &b) in g.visible.iter().zip(&c.visible) {
                face_differing += a.abs_diff(b) as u64;
                seen.gpu_occluded += b.saturating_sub(a) as u64;
            }
            seen.differing += face_differing;
            if face_differing > 0 {
                seen.worst.push((face_differing, v, f));
            }
            seen.occluded += c.visible.iter().filter(|&&x| x < s).count() as u64;
        }
    }
    // Batched: several vertices in one dispatch give what each gives alone.
    let lo = vertices[0];
    let hi = (lo + 4).min(n);
    let (batch, _) = b
        .gpu_cube_maps(&caster, &(lo..hi).collect::<Vec<_>>())
        .expect("GPU cast");
    for (k, v) in (lo..hi).enumerate() {
        let (one, _) = b.gpu_cube_maps(&caster, &[v]).expect("GPU cast");
        assert!(batch[k] == one[0], "{label}: vertex {v} batched vs alone");
    }
    seen.worst.sort_unstable_by(|a, b| b.cmp(a));
    let faces = seen.worst.len();
    seen.worst.truncate(8);
    let worst: Vec<String> = seen
        .worst
        .iter()
        .map(|&(d, v, f)| format!("{d} at v{v} {:?} face {f}", b.mesh().positions[v as usize]))
        .collect();
    eprintln!(
        "{label}: {} sub-rays ({} cast again on the CPU), {} differ ({} occluded on the GPU \
         only) on {faces} faces, {} occluded pixels; most: {worst:?}",
        seen.rays, seen.recast, seen.differing, seen.gpu_occluded, seen.occluded
    );
    seen
}

/// Checks that `total` saw shadows and no sub-ray that differs from the CPU cast. (Before the
/// shader flagged unsure pixels, the refined room's dyadic grid, whose pixel rays cross it
/// exactly on triangle edges, differed: lavapipe 82 per million, an NVIDIA H100 1,798.)
fn check(total: &Seen, label: &str) {
    assert!(total.occluded > 0, "{label}: no shadow seen");
    assert!(
        total.differing == 0,
        "{label}: {} of {} sub-rays differ from the CPU cast",
        total.differing,
        total.rays
    );
}

const MESHES: [&str; 3] = ["bunny_res4.ply", "teapot.obj", "dragon_res4.ply"];

#[test]
fn gpu_equals_full_cpu_cast() {
    let Some(ctx) = GpuContext::for_test() else {
        return;
    };
    let mut total = Seen::default();
    // The bake accepts 4..=512: the smallest, odd, non-power-of-two and power-of-two sizes up
    // to the default (64), with and without supersampling, then larger ones on fewer vertices.
    let sizes = [
        (4, 1, 6),
        (5, 1, 6),
        (7, 1, 6),
        (8, 2, 6),
        (12, 1, 6),
        (16, 3, 4),
        (24, 1, 4),
        (31, 1, 4),
        (50, 1, 3),
        (64, 1, 3),
        (128, 1, 1),
        (256, 1, 1),
        (BakeSettings::MAX_FACE_RES, 1, 1),
    ];
    for (res, ss, count) in sizes {
        let label = format!("plate-small at {res}² × {ss}²");
        let seen = compare(&ctx, &plate_baker(res, ss), &label, 2 * count);
        check(&seen, &label);
        total.rays += seen.rays;
        total.recast += seen.recast;
        total.differing += seen.differing;
        for file in MESHES {
            let Some(b) = mesh_baker(file, res, ss) else {
                continue;
            };
            let label = format!("{file} at {res}² × {ss}²");
            let seen = compare(&ctx, &b, &label, count);
            check(&seen, &label);
            total.rays += seen.rays;
            total.recast += seen.recast;
            total.differing += seen.differing;
        }
    }
    eprintln!(
        "all: {} sub-rays ({} cast again on the CPU), {} differ from the CPU cast",
        total.rays, total.recast, total.differing
    );
}

/// Whole GPU bakes write the CPU bake's bytes, with the trees fitted on the GPU and shared
/// between the GPU and the pool by their measured rates (`FitOn`).
#[test]
fn gpu_bake_writes_the_cpu_bytes() {
    let Some(ctx) = GpuContext::for_test() else {
        return;
    };
    let mut bakers = vec![("plate-small".to_string(), plate_baker(16, 1))];
    for file in ["teapot.obj", "bunny_res4.ply"] {
        if let Some(b) = mesh_baker(file, 8, 1) {
            bakers.push((file.to_string(), b));
        }
    }
    // The punctual room's bulbs: the faces that hold a bulb's few pixels are fitted with a
    // tighter tolerance, on the CPU (`Fitter::for_face`), the others on the GPU.
    let mut room = bspvt_proto::builtin::scene("punctual-room").expect("built-in room");
    room.bake.face_res = 16;
    bakers.push(("punctual room at 16²".to_string(), Baker::new(&room)));
    for (label, b) in bakers {
        let none = AtomicBool::new(false);
        let cpu = b.bake_all(&|_, _| {}, &none).expect("CPU bake");
        let mut caster = b.gpu_caster(ctx.clone()).expect("BVH on the GPU");
        // The trees fitted on the GPU, then shared between the GPU and the pool.
        for fit_on in [FitOn::Gpu, FitOn::Shared] {
            caster.set_fit_on(fit_on);
            let gpu = b
                .bake_all_gpu(&caster, &|_, _| {}, &none)
                .expect("GPU bake");
            assert_eq!(gpu.totals.vertices, cpu.totals.vertices, "{label}");
            assert!(
                gpu.bytes == cpu.bytes,
                "{label}, {fit_on:?}: GPU bake bytes differ"
            );
        }
    }
}

/// The room (built in, refined as its bake is): floor and walls on a dyadic grid, so pixel
/// rays cross them exactly on triangle edges: where the two machines disagree, if anywhere.
/// Every third vertex at 8², every ninth at 16².
#[test]
fn gpu_equals_full_cpu_cast_on_the_room() {
    let Some(ctx) = GpuContext::for_test() else {
        return;
    };
    for (res, step) in [(8, 3), (16, 9)] {
        let mut scene = bspvt_proto::builtin::scene("room").expect("built-in room");
        scene.bake.face_res = res;
        bspvt_bake::refine::refine_scene(&mut scene).expect("refinement");
        let b = Baker::new(&scene);
        let n = b.mesh().vertex_count() as u32;
        let label = format!("room at {res}²");
        let seen = compare(&ctx, &b, &label, n.div_ceil(step));
        check(&seen, &label);
    }
}

/// The punctual room's bulbs: rays end where they pass within two pixel cones of a sphere
/// (`SphereStop`, the WGSL `ray_end`'s sphere), the same on both (issue 34).
#[test]
fn gpu_equals_full_cpu_cast_on_the_punctual_room() {
    let Some(ctx) = GpuContext::for_test() else {
        return;
    };
    let mut scene = bspvt_proto::builtin::scene("punctual-room").expect("built-in room");
    scene.bake.face_res = 16;
    if let Some(r) = &mut scene.bake.refine {
        r.max_vertices = 2000;
    }
    bspvt_bake::refine::refine_scene(&mut scene).expect("refinement");
    let b = Baker::new(&scene);
    let n = b.mesh().vertex_count() as u32;
    let label = "punctual room at 16²".to_string();
    let seen = compare(&ctx, &b, &label, n.div_ceil(5));
    check(&seen, &label);
}

/// The GPU bake reports every chunk in order and stops between chunks when cancelled (the
/// CPU bake's contract), with the GPU thread still busy on the next chunk.
#[test]
fn gpu_bake_reports_progress_and_cancels() {
    let Some(ctx) = GpuContext::for_test() else {
        return;
    };
    let mut scene = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
    scene.bake.face_res = 8;
    scene.bake.chunk_vertices = 512;
    let b = Baker::new(&scene);
    let caster = b.gpu_caster(ctx).expect("BVH on the GPU");
    let seen = std::sync::Mutex::new(Vec::new());
    let out = b
        .bake_all_gpu(
            &caster,
            &|done, total| seen.lock().expect("lock").push((done, total)),
            &AtomicBool::new(false),
        )
        .expect("not cancelled");
    let seen = seen.into_inner().expect("lock");
    let n = b.header().vertex_count as u64;
    assert_eq!(seen.len() as u32, b.header().chunk_count());
    assert_eq!(seen.last(), Some(&(n, n)));
    assert!(seen.windows(2).all(|w| w[0].0 < w[1].0));
    assert_eq!(out.totals.vertices, n);
    assert_eq!(out.backend, bspvt_bake::Backend::Gpu);

    let cancel = AtomicBool::new(false);
    let err = b
        .bake_all_gpu(
            &caster,
            &|_, _| cancel.store(true, std::sync::atomic::Ordering::Relaxed),
            &cancel,
        )
        .err()
        .expect("cancelled");
    assert!(
        matches!(&err, bspvt_bake::gpu_cast::GpuBakeError::Cancelled(c) if c.chunks_done == 1),
        "{err}"
    );
}

/// The checker canopy's cut-out (alphaMode MASK over an 8 × 8 alpha checker): the GPU's
/// `covers` samples the mask as `Cutout::covers` does, so the floor's cube maps see the same
/// holes on both; and more than the opaque canopy's rays escape (issue 35).
#[test]
fn gpu_equals_full_cpu_cast_through_cutouts() {
    let Some(ctx) = GpuContext::for_test() else {
        return;
    };
    let rooms = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/rooms");
    let mut scene = bspvt_proto::Scene::from_mesh_path(&rooms.join("checker-canopy.gltf"))
        .expect("checker canopy");
    scene.bake.face_res = 16;
    if let Some(r) = &mut scene.bake.refine {
        r.max_vertices = 1500;
    }
    bspvt_bake::refine::refine_scene(&mut scene).expect("refinement");
    let b = Baker::new(&scene);
    let n = b.mesh().vertex_count() as u32;
    let label = "checker canopy at 16²".to_string();
    let seen = compare(&ctx, &b, &label, n.div_ceil(5));
    check(&seen, &label);
    // The same vertices with the board opaque: the cut-out lets rays through.
    let mut opaque = scene.clone();
    for m in &mut opaque.materials {
        m.cutout = None;
    }
    let o = compare(
        &ctx,
        &Baker::new(&opaque),
        "the same canopy opaque",
        n.div_ceil(5),
    );
    assert!(
        seen.occluded < o.occluded,
        "the holes let rays through: {} vs {} occluded pixels",
        seen.occluded,
        o.occluded
    );
}
