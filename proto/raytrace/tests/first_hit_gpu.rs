//! The GPU's closest hits (`GpuFirstHit`, `first_hit.wgsl`) against the CPU's
//! (`Occluder::first_hit`): shadow segments from the built-in plate's surfaces to its light, and
//! segments through the checker canopy's alpha cut-out, must give the same hit or miss and the
//! same distance, up to the device's rounding on rays that graze an edge. Runs on any wgpu
//! adapter, Mesa's lavapipe included; skips, saying so, when there is none.
#![cfg(feature = "gpu")]

use bspvt_proto::Scene;
use bspvt_raytrace::gpu::GpuContext;
use bspvt_raytrace::{GpuFirstHit, Occluder, Segment};
use glam::Vec3;

/// A small deterministic generator (SplitMix64) for the segments' endpoints.
struct Mix(u64);

impl Mix {
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Segments from points on the mesh's triangles (lifted 10⁻⁴ along the face normal to the
/// target's side) to random points of `target`'s box, as rt-penumbra's hard shadow casts them.
fn shadow_segments(scene: &Scene, target: (Vec3, Vec3), n: usize, seed: u64) -> Vec<Segment> {
    let m = &scene.mesh;
    let mut rng = Mix(seed);
    let tris = m.triangles.len();
    (0..n)
        .filter_map(|_| {
            let k = ((rng.unit() * tris as f32) as usize).min(tris - 1);
            let [a, b, c] = [0, 1, 2].map(|j| m.positions[m.triangles[k][j] as usize]);
            let (mut u, mut v) = (rng.unit(), rng.unit());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let p = a + (b - a) * u + (c - a) * v;
            let goal =
                target.0 + (target.1 - target.0) * Vec3::new(rng.unit(), rng.unit(), rng.unit());
            let ng = (b - a).cross(c - a).normalize_or_zero();
            let side = if ng.dot(goal - p) >= 0.0 { 1.0 } else { -1.0 };
            let o = p + ng * (1e-4 * side);
            let seg = goal - o;
            let len = seg.length();
            (len > 1e-3).then(|| Segment::new(o, seg / len, len - 1e-4))
        })
        .collect()
}

/// The bounds of the scene's first light polygon.
fn light_box(scene: &Scene) -> (Vec3, Vec3) {
    scene.lights[0].vertices.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), v| (lo.min(Vec3::from(*v)), hi.max(Vec3::from(*v))),
    )
}

/// What a comparison saw.
struct Seen {
    n: usize,
    hits: usize,
    /// One hits where the other misses.
    disagree: usize,
    /// Both hit, distances further apart than 10⁻⁴ of the segment.
    far: usize,
    /// The largest |Δt| / max(t, 1) where both hit.
    worst: f32,
}

fn compare(ctx: &GpuContext, occ: &Occluder, segs: &[Segment], label: &str) -> Seen {
    let gpu = GpuFirstHit::new(&ctx.device, occ).expect("GPU occluder");
    let got = gpu
        .first_hits(&ctx.device, &ctx.queue, segs)
        .expect("GPU first hits");
    assert_eq!(got.len(), segs.len(), "{label}: one answer per segment");
    // Twice through the same buffers: the same answers.
    let again = gpu
        .first_hits(&ctx.device, &ctx.queue, segs)
        .expect("GPU first hits, again");
    assert_eq!(got, again, "{label}: the GPU's answers are deterministic");
    // Smaller batches reuse the buffers of the first (a frame casts all pixels, then the
    // light's parts on a few): each answers its own segments, none of the last batch's.
    let n = segs.len();
    for range in [n / 3..n / 2, 0..7, 1..n] {
        let answers = gpu
            .first_hits(&ctx.device, &ctx.queue, &segs[range.clone()])
            .expect("GPU first hits, another batch");
        assert_eq!(
            answers,
            got[range.clone()],
            "{label}: segments {range:?} through kept buffers"
        );
    }
    let mut seen = Seen {
        n: segs.len(),
        hits: 0,
        disagree: 0,
        far: 0,
        worst: 0.0,
    };
    for (s, g) in segs.iter().zip(&got) {
        let c = s.first_hit(occ);
        match (c, g) {
            (Some(c), Some(g)) => {
                seen.hits += 1;
                let rel = (c - g).abs() / c.max(1.0);
                seen.worst = seen.worst.max(rel);
                if rel > 1e-4 {
                    seen.far += 1;
                }
            }
            (None, None) => {}
            _ => seen.disagree += 1,
        }
    }
    eprintln!(
        "{label}: {} segments, {} hit on both, {} answered otherwise, {} at other distances \
         (largest |Δt| / max(t, 1): {:.2e})",
        seen.n, seen.hits, seen.disagree, seen.far, seen.worst
    );
    // Grazing rays may go either way on another device's rounding: at most 1 in 1,000.
    assert!(
        seen.disagree * 1000 <= seen.n && seen.far * 1000 <= seen.n,
        "{label}: the GPU's closest hits differ from the CPU's"
    );
    seen
}

#[test]
fn gpu_first_hits_match_the_cpu_on_the_plate() {
    let Some(ctx) = GpuContext::for_test() else {
        return;
    };
    let scene = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
    let occ = Occluder::of_surfaces(&scene.mesh, &scene.materials);
    let segs = shadow_segments(&scene, light_box(&scene), 40_000, 1);
    let seen = compare(&ctx, &occ, &segs, "plate-small, shadow segments");
    // Both answers occur often enough for the comparison to mean something.
    assert!(
        seen.hits * 20 > seen.n && (seen.n - seen.hits) * 20 > seen.n,
        "{} hits of {}",
        seen.hits,
        seen.n
    );
}

#[test]
fn gpu_first_hits_see_the_cutouts() {
    let Some(ctx) = GpuContext::for_test() else {
        return;
    };
    let rooms = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rooms");
    let scene = Scene::from_mesh_path(&rooms.join("checker-canopy.gltf")).expect("checker canopy");
    let occ = Occluder::of_surfaces(&scene.mesh, &scene.materials);
    assert!(occ.has_cutouts(), "the canopy is alpha-masked");
    // From the floor under the canopy to the lamp, many segments cross the board.
    let segs = shadow_segments(&scene, light_box(&scene), 40_000, 2);
    let seen = compare(&ctx, &occ, &segs, "checker canopy, through the cut-out");
    let mut opaque = scene.clone();
    for m in &mut opaque.materials {
        m.cutout = None;
    }
    let solid = Occluder::of_surfaces(&opaque.mesh, &opaque.materials);
    let o = compare(&ctx, &solid, &segs, "the same canopy opaque");
    assert!(
        seen.hits < o.hits,
        "the holes let segments through: {} vs {} hits",
        seen.hits,
        o.hits
    );
}
