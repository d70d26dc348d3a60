//! Blockers nearer to a ray's origin than obvhs's fixed box distance (`OBVHS_BOX_T_MIN`,
//! 10⁻⁴ in the scene's units) are found: a scan in metres has surfaces that close in its
//! crevices, and the traversal once entered no box whose far side was nearer than that (the
//! bake's culled casts and its every-ray reference then disagreed on 24 vertices of a
//! subdivided dragon).

use bspvt_proto::Mesh;
use bspvt_raytrace::{Occluder, hit, mesh_triangles};
use glam::{Vec3, Vec3A};
use obvhs::ray::Ray;

/// A lid of `n` × `n` quads over [−s/2, s/2]² at height `h`: small leaves, each a flat box.
fn lid(n: u32, s: f32, h: f32) -> Mesh {
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32 / n as f32 - 0.5, j as f32 / n as f32 - 0.5);
            positions.push(Vec3::new(x * s, y * s, h));
        }
    }
    let mut triangles = Vec::new();
    let at = |i: u32, j: u32| j * (n + 1) + i;
    for j in 0..n {
        for i in 0..n {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    Mesh {
        normals: vec![Vec3::Z; positions.len()],
        material_ids: vec![0; triangles.len()],
        positions,
        triangles,
        ..Mesh::default()
    }
}

#[test]
fn a_lid_nearer_than_the_box_distance_blocks() {
    for h in [2e-6f32, 2e-5, 5e-5, 9e-5, 5e-4] {
        let mesh = lid(32, 1.0, h);
        let tris = mesh_triangles(&mesh);
        let occ = Occluder::new(&mesh, &tris);
        let most = mesh.bounds().diagonal() / (1u64 << 30) as f32;
        assert!(
            occ.box_t_min() <= most,
            "h {h}: box distance {}",
            occ.box_t_min()
        );
        for o in [Vec3::new(0.01, 0.013, 0.0), Vec3::new(-0.3, 0.21, 0.0)] {
            let up = Vec3::Z;
            assert!(
                occ.occluded_between(o, up, 1e-7, f32::INFINITY, u32::MAX),
                "h {h}, {o}"
            );
            assert!(
                occ.blocker_between(o, up, 1e-7, 1.0, u32::MAX).is_some(),
                "h {h}, {o}"
            );
            assert!(occ.occluded_segment(o, up, 1.0), "h {h}, {o}");
            let t = occ.first_hit(o, up, 1.0);
            assert_eq!(t, Some(h), "h {h}, {o}: first hit");
        }
    }
}

/// Every traversal answers as testing every triangle does, for rays from just under the lid
/// in all directions above it (the hits 3 × 10⁻⁵ … 1.5 × 10⁻³ away), and under the same lid
/// scaled by 1000.
#[test]
fn traversals_answer_as_every_triangle_does() {
    for (s, h) in [(1.0f32, 3e-5f32), (1000.0, 0.03)] {
        let mesh = lid(24, s, h);
        let tris = mesh_triangles(&mesh);
        let occ = Occluder::new(&mesh, &tris);
        let rt: Vec<_> = tris
            .iter()
            .map(obvhs::rt_triangle::RtTriangle::from)
            .collect();
        let mut seen = [0usize; 2];
        for k in 0..4000u32 {
            // A quasi-random origin under the lid and direction in the upper hemisphere.
            let (a, b) = (
                (k as f32 * 0.618_034).fract(),
                (k as f32 * 0.754_877).fract(),
            );
            let (c, d) = ((k as f32 * 0.569_84).fract(), (k as f32 * 0.419_1).fract());
            let o = Vec3::new((a - 0.5) * 0.9 * s, (b - 0.5) * 0.9 * s, 0.0);
            // Down to 1° off the lid: a grazing ray once missed a hit a few 10⁻⁵ inside a
            // triangle's edge, its flat leaf box moved off the lid's plane (`grown`; (3h)/3 ≠ h
            // in f32 for this h).
            let (phi, z) = (c * std::f32::consts::TAU, 0.02 + 0.98 * d);
            let r = (1.0 - z * z).sqrt();
            let dir = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            let t_min = 1e-7 * s;
            let ray = Ray::new(Vec3A::from(o), Vec3A::from(dir), t_min, f32::INFINITY);
            let every = rt
                .iter()
                .map(|t| hit(t, &ray))
                .fold(f32::INFINITY, f32::min);
            let occluded = occ.occluded_between(o, dir, t_min, f32::INFINITY, u32::MAX);
            assert_eq!(
                occluded,
                every < f32::INFINITY,
                "lid {s}: ray {k} from {o} along {dir}"
            );
            seen[usize::from(occluded)] += 1;
            let first = occ.first_hit(o, dir, f32::MAX);
            if every < f32::INFINITY {
                assert_eq!(first, Some(every), "lid {s}: ray {k}, first hit");
            }
        }
        assert!(
            seen[1] > 1000,
            "lid {s}: too few rays hit the lid ({seen:?})"
        );
    }
}
