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
use obvhs::{
    BvhBuildParams,
    bvh2::{Bvh2, node::Bvh2Node},
    ray::Ray,
    triangle::Triangle,
};

/// A BVH2 (obvhs) over the triangles, for pyramid queries, laid out as sibling pairs.
pub(crate) struct FrustumCuller {
    /// The root's box and link; `None` for a mesh without triangles.
    root: Option<(Vec3, Vec3, Link)>,
    /// Every inner node's two children ([`Siblings`]).
    pairs: Vec<Siblings>,
    /// Per primitive (BVH order): vertices and vertex indices.
    prims: Vec<([Vec3; 3], [u32; 3])>,
    /// Per primitive (BVH order), the same triangle's primitive in the [`Occluder`].
    occ_prim: Vec<u32>,
}

/// A node as its parent's pair names it: `[first, count]`, a leaf's first primitive and its
/// primitive count, or an inner node's children (`first` indexes the pairs) and 0.
type Link = [u32; 2];

/// Two sibling nodes in one cache line: opening a node reads its children's boxes from one
/// line (obvhs's `Bvh2Node` is 48 bytes, so siblings span two or three). The boxes are the
/// BVH's own, so every culling decision is the one the BVH2 makes.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(64))]
struct Siblings {
    min: [Vec3; 2],
    max: [Vec3; 2],
    link: [Link; 2],
}

/// [`FrustumCuller`]'s layout of obvhs's `bvh` (children of node n at `first_index` and
/// `first_index + 1`): the root's box and link, and the sibling pairs, numbered depth first.
fn sibling_pairs(bvh: &Bvh2) -> (Option<(Vec3, Vec3, Link)>, Vec<Siblings>) {
    let Some(root) = bvh.nodes.first() else {
        return (None, Vec::new());
    };
    let mut pairs = Vec::with_capacity(bvh.nodes.len() / 2);
    // (an inner node's first child in `bvh.nodes`, the pair that will hold its children)
    let mut todo = Vec::new();
    fn link(n: &Bvh2Node, pairs: &mut Vec<Siblings>, todo: &mut Vec<(usize, usize)>) -> Link {
        if n.is_leaf() {
            return [n.first_index, n.prim_count];
        }
        todo.push((n.first_index as usize, pairs.len()));
        pairs.push(Siblings::default());
        [(pairs.len() - 1) as u32, 0]
    }
    let root = (
        root.aabb().min.into(),
        root.aabb().max.into(),
        link(root, &mut pairs, &mut todo),
    );
    while let Some((c, slot)) = todo.pop() {
        for s in 0..2 {
            let n = &bvh.nodes[c + s];
            let l = link(n, &mut pairs, &mut todo);
            let pair = &mut pairs[slot];
            (pair.min[s], pair.max[s]) = (n.aabb().min.into(), n.aabb().max.into());
            pair.link[s] = l;
        }
    }
    (Some(root), pairs)
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
        let (root, pairs) = sibling_pairs(&bvh);
        FrustumCuller {
            root,
            pairs,
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
        stack: &mut Vec<Link>,
    ) -> bool {
        out.clear();
        stack.clear();
        let Some((min, max, root)) = self.root else {
            return true;
        };
        if pyr.excludes_box(min, max) {
            return true;
        }
        // A node's children are tested when it is opened (one line: [`Siblings`]) and pushed
        // only when inside, sibling 0 first: nodes are visited as when testing each on its
        // own, depth first, sibling 1 first.
        stack.push(root);
        while let Some([first, count]) = stack.pop() {
            if count > 0 {
                let first = first as usize;
                for p in first..first + count as usize {
                    let (v, idx) = &self.prims[p];
                    if !idx.contains(&skip) && !pyr.excludes_triangle(v) {
                        if out.len() == limit {
                            return false;
                        }
                        out.push(p as u32);
                    }
                }
            } else {
                let pair = &self.pairs[first as usize];
                for s in 0..2 {
                    if !pyr.excludes_box(pair.min[s], pair.max[s]) {
                        // Its line is on its way while the other sibling's subtree is walked.
                        let [at, count] = pair.link[s];
                        if count > 0 {
                            bspvt_raytrace::prefetch(&self.prims, at as usize);
                        } else {
                            bspvt_raytrace::prefetch(&self.pairs, at as usize);
                        }
                        stack.push(pair.link[s]);
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

        /// The walk over sibling pairs finds exactly the primitives (not using `skip`) that no
        /// plane excludes — a box is excluded only where everything it holds is, the f32
        /// tests being monotone — and says "more than `limit`" exactly when there are.
        #[test]
        fn collect_finds_every_primitive_the_planes_keep(
            pts in prop::collection::vec(prop::array::uniform3(-1.0f32..1.0), 3..150),
            apex in prop::array::uniform3(-1.5f32..1.5),
            face in 0usize..6,
            (i0, j0, size) in (0u32..8, 0u32..8, 1u32..5),
            h in prop::array::uniform3(-1.0f32..1.0),
            skip in 0u32..150,
            limit in 0usize..40,
        ) {
            let n = pts.len() / 3 * 3;
            let mesh = Mesh {
                positions: pts[..n].iter().map(|&p| Vec3::from(p)).collect(),
                normals: vec![Vec3::Y; n],
                triangles: (0..n as u32 / 3).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect(),
                material_ids: vec![0; n / 3],
                ..Mesh::default()
            };
            let tris = bspvt_raytrace::mesh_triangles(&mesh);
            let occ = Occluder::new(&mesh, &tris);
            let culler = FrustumCuller::new(&mesh, &tris, &occ);
            let h = Vec3::from(h);
            prop_assume!(h.length() > 0.1);
            // Block (i0, j0, size) of an 8² face, as the cast's quadtree walk builds it.
            let fr = bspvt_proto::cubemap::FaceFrame::of(face);
            let e = |i: u32| 2.0 * (i.min(8)) as f32 / 8.0 - 1.0;
            let (u0, u1, v0, v1) = (e(i0), e(i0 + size), e(j0), e(j0 + size));
            let normals = [fr.a - u0 * fr.w, u1 * fr.w - fr.a, fr.b - v0 * fr.w, v1 * fr.w - fr.b];
            let pyr = Pyramid::new(Vec3::from(apex), normals, h.normalize(), 1e-4);
            let inside: std::collections::BTreeSet<u32> = (0..culler.prims.len() as u32)
                .filter(|&p| {
                    let (v, idx) = &culler.prims[p as usize];
                    !idx.contains(&skip) && !pyr.excludes_triangle(v)
                })
                .collect();
            let (mut out, mut stack) = (Vec::new(), Vec::new());
            prop_assert!(culler.collect(&pyr, skip, usize::MAX, &mut out, &mut stack));
            prop_assert_eq!(out.len(), inside.len(), "a primitive collected twice");
            prop_assert_eq!(out.iter().copied().collect::<std::collections::BTreeSet<u32>>(), inside.clone());
            let fits = culler.collect(&pyr, skip, limit, &mut out, &mut stack);
            prop_assert_eq!(fits, inside.len() <= limit);
        }

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
