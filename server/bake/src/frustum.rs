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
//!
//! A fifth plane is the vertex's horizon: only rays with d·n > 0 are cast (the others escape,
//! `VertexRays::escapes_below_horizon`), and every point o + t d of such a ray lies above the
//! plane through o with normal n, so nothing wholly below it can block one. Its test keeps a
//! margin ([`Pyramid::below`]) far above the f32 ray test's rounding and far below the origin's
//! lift off its surface, so the vertex's own neighbourhood, which the lift puts below the
//! plane, is culled on a flat or convex surface.

use bspvt_proto::Mesh;
use bspvt_raytrace::Occluder;
use glam::{BVec4A, Vec3, Vec4};
use obvhs::{BvhBuildParams, bvh2::Bvh2, ray::Ray, triangle::Triangle};

/// A BVH2 (obvhs) over the triangles, for pyramid queries.
pub(crate) struct FrustumCuller {
    bvh: Bvh2,
    /// Per primitive (BVH order): vertices and vertex indices.
    prims: Vec<([Vec3; 3], [u32; 3])>,
    /// Per primitive (BVH order), the same triangle's primitive in the [`Occluder`].
    occ_prim: Vec<u32>,
}

/// A pyramid of directions from an apex: four inward plane normals through the apex, cut by
/// the horizon plane through it. The four side planes are held across the lanes of a `Vec4`
/// per coordinate, so one box or triangle is tested against all four at once (with the
/// arithmetic of the scalar dot products, so the same answers bit for bit).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pyramid {
    apex: Vec3,
    /// The side planes' normals, x, y and z of plane k in lane k.
    nx: Vec4,
    ny: Vec4,
    nz: Vec4,
    /// Per side plane and coordinate, whether the normal's component is ≥ 0 (a box's
    /// farthest corner along the normal takes `max` there).
    px: BVec4A,
    py: BVec4A,
    pz: BVec4A,
    /// The horizon's unit normal: every ray cast has d · `horizon` > 0.
    horizon: Vec3,
    /// A point lies below the horizon when `horizon` · (x − apex) < −`below`.
    below: f32,
}

impl Pyramid {
    pub(crate) fn new(apex: Vec3, normals: [Vec3; 4], horizon: Vec3, below: f32) -> Pyramid {
        let lane = |c: fn(Vec3) -> f32| Vec4::from(normals.map(c));
        let (nx, ny, nz) = (lane(|n| n.x), lane(|n| n.y), lane(|n| n.z));
        Pyramid {
            apex,
            nx,
            ny,
            nz,
            px: nx.cmpge(Vec4::ZERO),
            py: ny.cmpge(Vec4::ZERO),
            pz: nz.cmpge(Vec4::ZERO),
            horizon,
            below,
        }
    }

    /// Per side plane, n · d.
    #[inline]
    fn side_dots(&self, d: Vec3) -> Vec4 {
        self.nx * d.x + self.ny * d.y + self.nz * d.z
    }

    /// Whether the box [min, max] lies entirely behind one of the planes.
    #[inline]
    fn excludes_box(&self, min: Vec3, max: Vec3) -> bool {
        let far = |pos: BVec4A, hi: f32, lo: f32, o: f32| {
            Vec4::select(pos, Vec4::splat(hi), Vec4::splat(lo)) - o
        };
        let (a, fx, fy, fz) = (
            self.apex,
            far(self.px, max.x, min.x, self.apex.x),
            far(self.py, max.y, min.y, self.apex.y),
            far(self.pz, max.z, min.z, self.apex.z),
        );
        let h = self.horizon;
        (self.nx * fx + self.ny * fy + self.nz * fz)
            .cmplt(Vec4::ZERO)
            .any()
            || h.dot(Vec3::select(h.cmpge(Vec3::ZERO), max, min) - a) < -self.below
    }

    /// Whether the triangle lies entirely behind one of the planes.
    #[inline]
    fn excludes_triangle(&self, p: &[Vec3; 3]) -> bool {
        let d = p.map(|q| q - self.apex);
        let behind = |d: Vec3| self.side_dots(d).cmplt(Vec4::ZERO);
        (behind(d[0]) & behind(d[1]) & behind(d[2])).any()
            || d.iter().all(|&d| self.horizon.dot(d) < -self.below)
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
        let nodes = &self.bvh.nodes;
        let outside = |n: u32| {
            let b = nodes[n as usize].aabb();
            pyr.excludes_box(b.min.into(), b.max.into())
        };
        if nodes.is_empty() || outside(0) {
            return true;
        }
        // Nodes are tested when their parent is opened (both children's boxes read together)
        // and pushed only when inside: the same order of visits as testing them when popped.
        stack.push(0);
        while let Some(n) = stack.pop() {
            let node = &nodes[n as usize];
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
                for c in [node.first_index, node.first_index + 1] {
                    if !outside(c) {
                        stack.push(c);
                    }
                }
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

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::rt_triangle::RtTriangle;
    use proptest::prelude::*;

    proptest! {
        // Rays that graze the plane closely are often rounded below it and skipped: allow it.
        #![proptest_config(ProptestConfig { max_global_rejects: 1 << 20, ..ProptestConfig::default() })]

        /// The four side planes in `Vec4` lanes decide as the scalar dot products do, bit
        /// for bit (the claim that makes culling the same as before the lanes).
        #[test]
        fn lanes_decide_as_scalar_planes(
            apex in prop::array::uniform3(-2.0f32..2.0),
            normals in prop::array::uniform4(prop::array::uniform3(-1.0f32..1.0)),
            h in prop::array::uniform3(-1.0f32..1.0),
            pts in prop::array::uniform3(prop::array::uniform3(-3.0f32..3.0)),
            below in 0.0f32..1e-3,
        ) {
            let (apex, h) = (Vec3::from(apex), Vec3::from(h));
            let normals = normals.map(Vec3::from);
            let p = pts.map(Vec3::from);
            let pyr = Pyramid::new(apex, normals, h, below);
            let far = |n: Vec3, min: Vec3, max: Vec3| Vec3::select(n.cmpge(Vec3::ZERO), max, min) - apex;
            let (min, max) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
            let scalar_box = h.dot(far(h, min, max)) < -below
                || normals.iter().any(|&n| n.dot(far(n, min, max)) < 0.0);
            let scalar_tri = p.iter().all(|&q| h.dot(q - apex) < -below)
                || normals.iter().any(|n| p.iter().all(|&q| n.dot(q - apex) < 0.0));
            prop_assert_eq!(pyr.excludes_box(min, max), scalar_box);
            prop_assert_eq!(pyr.excludes_triangle(&p), scalar_tri);
        }

        /// The horizon plane culls only what no cast ray can hit: a triangle wholly more than
        /// the margin below the plane through the apex is missed, by the bake's own closed
        /// ray test, by every ray above the horizon — here those passing just above the
        /// triangle, grazing the plane, where rounding is worst. A scene of diagonal 2 (the
        /// margin is [`crate::RAY_HORIZON_MARGIN_SCALE`] of it, t_min
        /// [`crate::RAY_T_MIN_SCALE`]), triangles up to its size.
        #[test]
        fn what_the_horizon_culls_no_cast_ray_hits(
            o in prop::array::uniform3(-1.0f32..1.0),
            n in prop::array::uniform3(-1.0f32..1.0),
            corners in prop::array::uniform3(prop::array::uniform2(-1.0f32..1.0)),
            depths in prop::array::uniform3(1.0001f32..10.0),
            at in prop::array::uniform2(0.0f32..1.0),
            above in prop_oneof![1e-9f32..1e-6, 1e-6f32..1e-3],
        ) {
            let diagonal = 2.0;
            let margin = crate::RAY_HORIZON_MARGIN_SCALE * diagonal;
            let (o, n) = (Vec3::from(o), Vec3::from(n));
            prop_assume!(n.length() > 0.1);
            let n = n.normalize();
            let (t1, t2) = n.any_orthonormal_pair();
            let p: [Vec3; 3] = std::array::from_fn(|k| {
                o + corners[k][0] * t1 + corners[k][1] * t2 - depths[k] * margin * n
            });
            let pyr = Pyramid::new(o, [Vec3::ZERO; 4], n, margin);
            prop_assume!(pyr.excludes_triangle(&p));
            // A point of the triangle, lifted to `above` over the horizon plane.
            let (a, b) = if at[0] + at[1] > 1.0 { (1.0 - at[0], 1.0 - at[1]) } else { (at[0], at[1]) };
            let q = p[0] + a * (p[1] - p[0]) + b * (p[2] - p[0]);
            let d = (q + (n.dot(o - q) + above) * n - o).normalize_or_zero();
            prop_assume!(d.dot(n) > 0.0);
            let tri = RtTriangle::from(&Triangle { v0: p[0].into(), v1: p[1].into(), v2: p[2].into() });
            let t_min = crate::RAY_T_MIN_SCALE * diagonal;
            let ray = Ray::new(o.into(), d.into(), t_min, f32::INFINITY);
            prop_assert_eq!(bspvt_raytrace::hit(&tri, &ray), f32::INFINITY);
        }
    }
}
