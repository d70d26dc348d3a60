//! Exact culling of ray blocks: when no triangle can lie inside the pyramid of directions
//! through a block of cube-map pixels, every ray of the block escapes and none is cast.
//!
//! A block `[u0, u1] × [v0, v1]` of face (w, a, b) is the pyramid with apex at the ray origin o
//! bounded by four planes through o: (a − u0 w), (u1 w − a), (b − v0 w), (v1 w − b) (each ·(x − o)
//! ≥ 0 inside). A box is outside when its vertex farthest along some plane normal is behind that
//! plane; a triangle is outside when its three vertices are behind one plane. Both tests are
//! conservative (they may keep something outside, never drop something inside), so culled
//! blocks give exactly what casting their rays would: rays pass through pixel (sub-)centres,
//! strictly inside the pyramid.

use bspvt_proto::Mesh;
use bspvt_raytrace::Occluder;
use glam::Vec3;
use obvhs::{BvhBuildParams, bvh2::Bvh2, ray::Ray, triangle::Triangle};

/// A BVH2 (obvhs) over the triangles, for pyramid queries.
pub(crate) struct FrustumCuller {
    bvh: Bvh2,
    /// Per primitive (BVH order): vertices and vertex indices.
    prims: Vec<([Vec3; 3], [u32; 3])>,
    /// Per primitive (BVH order), the same triangle's primitive in the [`Occluder`].
    occ_prim: Vec<u32>,
}

/// A pyramid of directions from an apex: four inward plane normals through the apex.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pyramid {
    pub apex: Vec3,
    pub normals: [Vec3; 4],
}

impl Pyramid {
    /// Whether the box [min, max] lies entirely behind one of the planes.
    #[inline]
    fn excludes_box(&self, min: Vec3, max: Vec3) -> bool {
        self.normals.iter().any(|n| {
            let far = Vec3::select(n.cmpge(Vec3::ZERO), max, min);
            n.dot(far - self.apex) < 0.0
        })
    }

    /// Whether the triangle lies entirely behind one of the planes.
    #[inline]
    fn excludes_triangle(&self, p: &[Vec3; 3]) -> bool {
        self.normals
            .iter()
            .any(|n| p.iter().all(|&q| n.dot(q - self.apex) < 0.0))
    }
}

impl FrustumCuller {
    /// `tris`: [`bspvt_raytrace::mesh_triangles`] of `mesh`; `occ`: the occluder built from
    /// them.
    pub(crate) fn new(mesh: &Mesh, tris: &[Triangle], occ: &Occluder) -> FrustumCuller {
        let mut params = BvhBuildParams::medium_build();
        params.pre_split = false;
        // Copies of a triangle cull nothing the first one does not.
        let (unique, built) = bspvt_raytrace::distinct_triangles(mesh, tris);
        let bvh =
            obvhs::bvh2::builder::build_bvh2_from_tris(&built, params, &mut Default::default());
        let order: Vec<usize> = bvh
            .primitive_indices
            .iter()
            .map(|&i| unique[i as usize] as usize)
            .collect();
        let prims = order
            .iter()
            .map(|&i| {
                let t = mesh.triangles[i];
                (t.map(|v| mesh.positions[v as usize]), t)
            })
            .collect();
        // Both BVHs hold the same distinct triangles (`distinct_triangles`).
        let mut of_triangle = vec![u32::MAX; mesh.triangles.len()];
        for (p, &t) in occ.primitive_triangles().iter().enumerate() {
            of_triangle[t as usize] = p as u32;
        }
        let occ_prim = order.iter().map(|&i| of_triangle[i]).collect();
        FrustumCuller {
            bvh,
            prims,
            occ_prim,
        }
    }

    /// Collects the primitives (not using vertex `skip`) that may lie inside the pyramid into
    /// `out`; returns false, with `out` incomplete, once more than `limit` are found.
    pub(crate) fn collect(
        &self,
        pyr: &Pyramid,
        skip: u32,
        limit: usize,
        out: &mut Vec<u32>,
        stack: &mut Vec<u32>,
    ) -> bool {
        out.clear();
        stack.clear();
        if self.bvh.nodes.is_empty() {
            return true;
        }
        stack.push(0);
        while let Some(n) = stack.pop() {
            let node = &self.bvh.nodes[n as usize];
            if pyr.excludes_box(node.aabb.min.into(), node.aabb.max.into()) {
                continue;
            }
            if node.is_leaf() {
                let first = node.first_index as usize;
                for p in first..first + node.prim_count as usize {
                    let (v, idx) = &self.prims[p];
                    if !idx.contains(&skip) && !pyr.excludes_triangle(v) {
                        if out.len() == limit {
                            return false;
                        }
                        out.push(p as u32);
                    }
                }
            } else {
                stack.push(node.first_index);
                stack.push(node.first_index + 1);
            }
        }
        true
    }

    /// The primitives of `from` that may lie inside the pyramid.
    pub(crate) fn filter(&self, pyr: &Pyramid, from: &[u32], out: &mut Vec<u32>) {
        out.clear();
        out.extend(
            from.iter()
                .copied()
                .filter(|&p| !pyr.excludes_triangle(&self.prims[p as usize].0)),
        );
    }

    /// Whether the ray hits any primitive of the list between `t_min` and `t_max` (by the
    /// occluder's test: through cut-outs).
    #[inline]
    pub(crate) fn ray_hits_any(
        &self,
        occ: &Occluder,
        origin: Vec3,
        dir: Vec3,
        [t_min, t_max]: [f32; 2],
        list: &[u32],
    ) -> bool {
        let ray = Ray::new(origin.into(), dir.into(), t_min, t_max);
        list.iter()
            .any(|&p| occ.primitive_hit(self.occ_prim[p as usize] as usize, &ray) < f32::INFINITY)
    }

    /// The first primitive of the list that `ray` hits between its `tmin` and `tmax` (the
    /// test of [`Self::ray_hits_any`]), as its primitive in the [`Occluder`].
    #[inline]
    pub(crate) fn ray_first_hit(&self, occ: &Occluder, ray: &Ray, list: &[u32]) -> Option<u32> {
        list.iter()
            .map(|&p| self.occ_prim[p as usize])
            .find(|&q| occ.primitive_hit(q as usize, ray) < f32::INFINITY)
    }
}
