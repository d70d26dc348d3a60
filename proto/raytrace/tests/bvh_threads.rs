//! The BVHs are built on rayon's threads (obvhs's `parallel` feature): the tree must not
//! depend on how many there are, so a bake, a reference and a frame are the same on a 2-core
//! CI machine and a 16-core GPU host.

use bspvt_proto::scene::builtin::{cuboid, icosphere};
use bspvt_raytrace::{Occluder, mesh_triangles};
use glam::{Quat, Vec3};

#[test]
fn the_bvh_is_the_same_on_any_number_of_threads() {
    // 20,480 + 4,056 triangles: above the sizes below which obvhs's PLOC stays on one thread.
    let mut mesh = icosphere(5, 0);
    mesh.append(
        &cuboid(
            Vec3::new(0.4, -1.3, 0.2),
            Vec3::new(2.0, 0.2, 1.5),
            Quat::from_rotation_y(0.3),
            14,
            0,
        ),
        0,
    );
    assert!(mesh.triangles.len() > 20_000);
    let tris = mesh_triangles(&mesh);
    // Per build: the primitives' order, and the primitive each of a fan of rays from outside
    // meets first in the traversal (any-hit: which one depends on the tree's shape).
    let build = |threads: usize, fast: bool| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        pool.install(|| {
            let occ = if fast {
                Occluder::new_fast(&mesh, &tris)
            } else {
                Occluder::new(&mesh, &tris)
            };
            let hits: Vec<Option<u32>> = (0..400)
                .map(|k| {
                    let (a, b) = (k as f32 * 0.157, (k % 20) as f32 * 0.15 - 1.4);
                    let origin = Vec3::new(4.0 * a.cos(), 0.7 * b, 4.0 * a.sin());
                    let toward = Vec3::new(0.3 * b, -0.2 * b, 0.1 * a.sin());
                    let dir = (toward - origin).normalize();
                    occ.blocker_between(origin, dir, 0.0, 100.0, u32::MAX)
                })
                .collect();
            (occ.primitive_triangles().to_vec(), hits)
        })
    };
    for fast in [false, true] {
        let one = build(1, fast);
        assert!(
            one.1.iter().filter(|h| h.is_some()).count() > 100,
            "the rays meet the mesh"
        );
        for threads in [2, 3, 8] {
            assert!(
                build(threads, fast) == one,
                "{threads} threads, fast build {fast}"
            );
        }
    }
}
