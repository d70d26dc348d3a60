//! Finding the triangle that blocks a ray by walking the mesh from a nearby ray's blocker.
//!
//! Neighbouring pixels' rays are usually blocked by the same surface, but on a finely
//! tessellated mesh by different triangles of it (the bunny's triangles span ~0.4°, a 64²
//! pixel ~1.4°). From the triangle that blocked a neighbour, step across the edge the ray
//! passes outside of (the most negative of its three edge functions, seen from the ray's
//! origin) until a triangle contains the ray: point location by walking. The walk only
//! proposes; a triangle is accepted by the occluder's own ray test
//! ([`Occluder::primitive_blocks`]), so a walk that strays (a seam, a silhouette, rounding)
//! costs a few steps and the ray falls back to a traversal, never a wrong answer.

use bspvt_proto::Mesh;
use bspvt_raytrace::Occluder;
use glam::Vec3;
use obvhs::ray::Ray;

/// No neighbour across an edge (a boundary or a triangle the occluder left out).
const NONE: u32 = u32::MAX;

/// Steps a walk may take before giving up.
const MAX_STEPS: usize = 32;

/// A shortcut hit must cross the triangle at least this far inside (smallest barycentric
/// coordinate, as seen from the ray's origin). At a hit on or near an edge the traversal can
/// disagree with the triangle test: in the project's room (floor and walls on a dyadic grid) a
/// pixel's ray crosses the floor exactly on a triangle's edge, which is also its leaf box's
/// face; the triangle test counts the hit, the box test rejects the box, and the full cast
/// sees the ray escape. Such a ray is left to the traversal, so both casts agree.
const INTERIOR: f64 = 1e-3;

/// Edge adjacency of the occluder's primitives (in its order).
pub(crate) struct SurfaceWalk {
    tris: Vec<WalkTriangle>,
}

/// What a step of the walk reads of a primitive, in one cache line (a step is a cache miss
/// on a large mesh).
#[derive(Clone, Copy)]
#[repr(align(64))]
struct WalkTriangle {
    /// Its vertices.
    v: [Vec3; 3],
    /// Its vertex indices.
    idx: [u32; 3],
    /// The primitive across the edge opposite vertex k (k = 0, 1, 2).
    across: [u32; 3],
}

impl SurfaceWalk {
    pub(crate) fn new(mesh: &Mesh, occ: &Occluder) -> SurfaceWalk {
        let prims = occ.primitive_triangles();
        let tris: Vec<([Vec3; 3], [u32; 3])> = prims
            .iter()
            .map(|&t| {
                let idx = mesh.triangles[t as usize];
                (idx.map(|v| mesh.positions[v as usize]), idx)
            })
            .collect();
        // Non-manifold edges link their first two triangles (`edges::across`).
        let idx: Vec<[u32; 3]> = tris.iter().map(|&(_, idx)| idx).collect();
        let across = crate::edges::across(&idx, NONE);
        let tris = tris
            .into_iter()
            .zip(across)
            .map(|((v, idx), across)| WalkTriangle { v, idx, across })
            .collect();
        SurfaceWalk { tris }
    }

    /// Whether the line from `o` along `d` crosses primitive `prim` at least [`INTERIOR`]
    /// inside each of its edges (in f64 from the f32 vertices: rounding far below the margin).
    pub(crate) fn interior(&self, prim: u32, o: Vec3, d: Vec3) -> bool {
        let [a, b, c] = self.tris[prim as usize].v.map(|p| (p - o).as_dvec3());
        let d = d.as_dvec3();
        let l = [d.dot(b.cross(c)), d.dot(c.cross(a)), d.dot(a.cross(b))];
        let sum = l[0] + l[1] + l[2];
        sum != 0.0 && l.iter().all(|&x| x / sum >= INTERIOR)
    }

    /// Walks from primitive `start` toward the triangle that `ray` passes through; returns it
    /// when it blocks the ray (the occluder's test), [`Self::interior`]ly, and does not use
    /// vertex `skip`.
    pub(crate) fn find(&self, occ: &Occluder, start: u32, ray: &Ray, skip: u32) -> Option<u32> {
        let o = Vec3::from(ray.origin);
        let d = Vec3::from(ray.direction);
        let mut cur = start;
        let mut facing = 0.0;
        for _ in 0..MAX_STEPS {
            let t = &self.tris[cur as usize];
            // The next step reads one of the three triangles across, and the last step the
            // occluder's copy of it: ask for their lines now, while this one's edge functions
            // are computed (a step is otherwise a cache miss or two).
            for &q in &t.across {
                bspvt_raytrace::prefetch(&self.tris, q as usize);
                occ.prefetch_primitive(q);
            }
            let [a, b, c] = t.v.map(|p| p - o);
            // Edge functions: d · (B × C) etc., signed so that all are ≥ 0 when the ray (on
            // the side t > 0) passes inside the triangle.
            let sign = a.dot(b.cross(c)).signum();
            // Stepping onto a triangle that faces the other way crosses a silhouette: the
            // ray passes beside the surface, not through it.
            if sign * facing < 0.0 {
                return None;
            }
            facing = sign;
            let l = [
                sign * d.dot(b.cross(c)),
                sign * d.dot(c.cross(a)),
                sign * d.dot(a.cross(b)),
            ];
            let (k, &m) = l
                .iter()
                .enumerate()
                .min_by(|x, y| x.1.total_cmp(y.1))
                .unwrap_or((0, &0.0));
            if m >= 0.0 {
                let blocks = !t.idx.contains(&skip)
                    && occ.primitive_blocks(cur, ray)
                    && self.interior(cur, o, d);
                return blocks.then_some(cur);
            }
            cur = t.across[k];
            if cur == NONE {
                return None;
            }
        }
        None
    }
}
