//! # bspvt-raytrace
//!
//! Occlusion rays against a mesh: one CWBVH (obvhs) per mesh, any-hit and closest-hit queries.
//! The one ray caster of the project: the bake's visibility cube maps, the Monte Carlo
//! references, the point-light penumbrae and the exact SSDF all ask it. With the `gpu`
//! feature, the bake's cube maps (`GpuOccluder`) and the penumbrae's closest hits
//! (`GpuFirstHit`) run in wgpu compute shaders over the same BVH.
//!
//! Must not depend on: anything but `bspvt-proto`'s mesh, glam and obvhs (no I/O).

#![warn(unreachable_pub, missing_docs)]

mod cutout;
#[cfg(feature = "gpu")]
pub mod gpu;
#[cfg(feature = "gpu")]
mod gpu_first_hit;
#[cfg(feature = "gpu")]
mod gpu_occluder;
mod prefetch;
#[cfg(feature = "gpu")]
pub use gpu_first_hit::{GpuFirstHit, Segment};
#[cfg(feature = "gpu")]
pub use gpu_occluder::{CubeSource, GpuCubeTable, GpuOccluder, GpuStop};

use std::sync::Arc;
use std::time::Duration;

pub use cutout::Cutouts;
pub use prefetch::prefetch;

/// `covers`, the cut-out test of [`Cutouts::gpu_words`] in WGSL, for shaders that declare the
/// `cut` buffer (`occlusion.wgsl`; the raster pass of `bspvt_shaders::gpu::wgsl`). Text only:
/// it needs no GPU feature.
pub const CUTOUT_WGSL: &str = include_str!("cutout.wgsl");

use bspvt_proto::Mesh;
use glam::{Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    cwbvh::CwBvh,
    ray::{Ray, RayHit},
    rt_triangle::RtTriangle,
    triangle::Triangle,
};

/// How far outside a triangle, in barycentric units, [`hit`] still counts a hit.
pub const EDGE_SLACK: f32 = 1.0 / 1_048_576.0; // 2⁻²⁰

/// The ray–triangle test of every query: Möller–Trumbore (Möller & Trumbore 1997, "Fast,
/// Minimum Storage Ray/Triangle Intersection") as obvhs's `RtTriangle::intersect`, but closed:
/// barycentrics down to −[`EDGE_SLACK`] count. obvhs's test is open at the edges (a
/// barycentric of −0.0 misses), so a ray through an edge that two triangles share could miss
/// both by rounding — and the cube maps' dyadic pixel directions meet the shared edges of
/// axis-aligned, bisected meshes exactly: light leaked through the diagonal of a canopy made
/// of one quad into its umbra (issue 35). Returns the distance, or infinity for no hit in
/// \[`ray.tmin`, `ray.tmax`\]. `occlusion.wgsl`'s `blocks` is the same test.
#[inline]
pub fn hit(tri: &RtTriangle, ray: &Ray) -> f32 {
    intersect(tri, ray).map_or(f32::INFINITY, |(t, _)| t)
}

/// [`hit`] with the hit's barycentric weights of the triangle's corners (v0, v1, v2), or
/// `None` for no hit.
#[inline]
pub fn intersect(tri: &RtTriangle, ray: &Ray) -> Option<(f32, [f32; 3])> {
    let (det, [w, u, v], t) = line_crossing(tri, ray);
    if det != 0.0 && u >= -EDGE_SLACK && v >= -EDGE_SLACK && w >= -EDGE_SLACK {
        let t = t();
        if t >= ray.tmin && t <= ray.tmax {
            return Some((t, [w, u, v]));
        }
    }
    None
}

/// Where the ray's line crosses the triangle's plane (Möller–Trumbore): the determinant (0:
/// parallel), the barycentric weights of the corners (v0, v1, v2) and, on demand, the distance.
#[inline(always)]
fn line_crossing(tri: &RtTriangle, ray: &Ray) -> (f32, [f32; 3], impl Fn() -> f32) {
    let c = tri.v0 - ray.origin;
    let r = ray.direction.cross(c);
    let det = tri.ng.dot(ray.direction);
    let inv_det = 1.0 / det;
    // With e1 = v0 − v1 and e2 = v2 − v0 (obvhs's layout, after madmann91's bvh), u weighs v1
    // and v the corner v2.
    let u = r.dot(tri.e2) * inv_det;
    let v = r.dot(tri.e1) * inv_det;
    let ng = tri.ng;
    (det, [1.0 - u - v, u, v], move || ng.dot(c) * inv_det)
}

/// A mesh prepared for occlusion queries: a CWBVH over its triangles [obvhs].
pub struct Occluder {
    bvh: CwBvh,
    /// Triangles in BVH primitive order.
    tris: Vec<RtTriangle>,
    /// Vertex indices of each triangle, in BVH primitive order.
    indices: Vec<[u32; 3]>,
    /// Mesh triangle index of each triangle, in BVH primitive order.
    order: Vec<u32>,
    /// The scene's cut-outs and, per primitive, its entry there (0: opaque); `None` when
    /// every surface is opaque.
    cut: Option<(Arc<Cutouts>, Vec<u32>)>,
    /// The power of two the traversals scale their rays' distances by ([`traversal_scale`]).
    t_scale: f32,
}

/// obvhs's CWBVH traversal enters no child box nearer than this distance along the ray
/// (`cwbvh::node::EPSILON`, whatever the ray's `tmin`): a fixed 10⁻⁴ in the scene's units.
const OBVHS_BOX_T_MIN: f32 = 0.0001;

/// The power of two by which every traversal scales its ray's distances ([`Occluder`]'s
/// `traversal_ray`), so that obvhs's fixed [`OBVHS_BOX_T_MIN`] is at most 2⁻³⁰ of the scene's
/// diagonal: far below any ray's `tmin` (the bake's is 10⁻⁶ of it). Unscaled, a scan in
/// metres (a dragon 0.2 across) lost every blocker nearer than 0.1 mm to a ray's origin, deep
/// in its crevices: 24 of dragon ×2's 93,607 vertices saw light through their own folds.
/// Dividing the direction by 2^k and multiplying the reciprocal direction and the distances by
/// it changes no other bit of a traversal or a triangle test (powers of two scale exactly), so
/// every other answer is what it was. 1 for an empty or non-finite mesh.
fn traversal_scale(diagonal: f32) -> f32 {
    if !(diagonal.is_finite() && diagonal > 0.0) {
        return 1.0;
    }
    let want = OBVHS_BOX_T_MIN * (1u64 << 30) as f32 / diagonal;
    let k = want.log2().ceil().clamp(0.0, 40.0);
    2f32.powi(k as i32)
}

/// The mesh's triangles as obvhs primitives, in mesh order.
pub fn mesh_triangles(mesh: &Mesh) -> Vec<Triangle> {
    mesh.triangles
        .iter()
        .map(|t| {
            let p = t.map(|i| Vec3A::from(mesh.positions[i as usize]));
            Triangle {
                v0: p[0],
                v1: p[1],
                v2: p[2],
            }
        })
        .collect()
}

/// What a BVH over `mesh` is built from: the first of each set of copies of a triangle
/// ([`Mesh::unique_triangles`]: copies answer every ray as the first one does), as their mesh
/// indices and their primitives. `tris`: [`mesh_triangles`] of `mesh`.
pub fn distinct_triangles(mesh: &Mesh, tris: &[Triangle]) -> (Vec<u32>, Vec<Triangle>) {
    let unique = mesh.unique_triangles();
    let built = unique.iter().map(|&i| tris[i as usize]).collect();
    (unique, built)
}

/// How far, relative to the scene's diagonal, the BVH's boxes reach past their triangles
/// (2⁻¹⁸). The box test's slabs are t = (p − o)/d for a box corner p and a ray origin o in the
/// scene: their rounding is a few ULP of |p − o| ≤ the diagonal, so 2⁻¹⁸ of it is ≥ 32 ULP.
const BOX_MARGIN: f32 = 1.0 / 262_144.0;

/// `t` grown along each axis away from its centroid by `margin`, or 4 ULP of a coordinate
/// where that is more (far from the origin), but not along an axis it is flat in (its three
/// vertices equal there: a floor's box stays flat, and a flat slab's entry and exit are one
/// value). Only the BVH's boxes are built from it. Without the margin a ray that hits a
/// triangle on its edge where that edge is its leaf box's face (a dyadic floor's triangles,
/// crossed by a pixel's ray exactly on an edge) could be refused by the box test — its entry
/// in one axis rounded a hair past its exit in another — and the traversal miss a hit the
/// triangle test (and the bake's candidate lists) count.
fn grown(t: &Triangle, margin: f32) -> Triangle {
    let c = (t.v0 + t.v1 + t.v2) / 3.0;
    // Flat where the three vertices are equal, not where the centroid rounds to them: in f32
    // (3h)/3 ≠ h for 13 % of coordinates, and every vertex then stepped the same way, moving a
    // flat box a margin off its plane (a grazing ray met it beside its triangle).
    let flat = t.v0.cmpeq(t.v1) & t.v1.cmpeq(t.v2);
    let out = |v: Vec3A| {
        let away = v - c;
        let still = away.cmpeq(Vec3A::ZERO) | flat;
        let step = Vec3A::select(still, Vec3A::ZERO, away.signum());
        v + step * Vec3A::splat(margin).max(v.abs() * (4.0 * f32::EPSILON))
    };
    Triangle {
        v0: out(t.v0),
        v1: out(t.v1),
        v2: out(t.v2),
    }
}

/// What the occluder's BVH over `tris` (triangles of `mesh`) is built from: each grown by
/// [`BOX_MARGIN`] of the mesh's diagonal ([`grown`]), so that no box face that a triangle's
/// edge lies on shuts out a point of it by rounding.
fn box_triangles(mesh: &Mesh, tris: &[Triangle]) -> Vec<Triangle> {
    let diagonal = mesh.bounds().diagonal();
    let margin = if diagonal.is_finite() {
        BOX_MARGIN * diagonal
    } else {
        0.0
    };
    tris.iter().map(|t| grown(t, margin)).collect()
}

impl Occluder {
    /// `tris`: [`mesh_triangles`] of `mesh`. The highest-quality BVH (for bakes and
    /// references, where rays outnumber builds by far).
    pub fn new(mesh: &Mesh, tris: &[Triangle]) -> Occluder {
        Occluder::with_params(mesh, tris, BvhBuildParams::very_slow_build())
    }

    /// A BVH built in a fraction of [`Occluder::new`]'s time, for geometry that moves every
    /// frame.
    pub fn new_fast(mesh: &Mesh, tris: &[Triangle]) -> Occluder {
        Occluder::with_params(mesh, tris, BvhBuildParams::fast_build())
    }

    fn with_params(mesh: &Mesh, tris: &[Triangle], params: BvhBuildParams) -> Occluder {
        let (unique, built) = distinct_triangles(mesh, tris);
        // The boxes are built around the triangles grown by a margin; the hits are tested on
        // the triangles themselves.
        let bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(
            &box_triangles(mesh, &built),
            params,
            &mut Duration::default(),
        );
        let order: Vec<usize> = bvh
            .primitive_indices
            .iter()
            .map(|&i| unique[i as usize] as usize)
            .collect();
        let rt = order.iter().map(|&i| RtTriangle::from(&tris[i])).collect();
        let indices = order.iter().map(|&i| mesh.triangles[i]).collect();
        Occluder {
            bvh,
            tris: rt,
            indices,
            order: order.iter().map(|&i| i as u32).collect(),
            cut: None,
            t_scale: traversal_scale(mesh.bounds().diagonal()),
        }
    }

    /// This occluder with the scene's alpha cut-outs ([`Cutouts::of`]): a cut-out triangle
    /// blocks a ray only where its alpha at the hit reaches the cut-off.
    pub fn cut_out(mut self, cutouts: Option<Arc<Cutouts>>) -> Occluder {
        self.cut = cutouts.map(|c| {
            let slots = self.order.iter().map(|&t| c.slot(t)).collect();
            (c, slots)
        });
        self
    }

    /// The occluder of a scene's surfaces: [`Occluder::new`] with its cut-outs.
    pub fn of_surfaces(mesh: &Mesh, materials: &[bspvt_proto::scene::Material]) -> Occluder {
        Occluder::new(mesh, &mesh_triangles(mesh)).cut_out(Cutouts::of(mesh, materials))
    }

    /// `ray` as the traversals cast it: distances (and the reciprocal direction) times the
    /// occluder's power of two, the direction divided by it ([`traversal_scale`]). A hit's
    /// distance in it is the unscaled one times the same power.
    #[inline]
    fn traversal_ray(&self, ray: Ray) -> Ray {
        let s = self.t_scale;
        Ray {
            origin: ray.origin,
            direction: ray.direction / s,
            inv_direction: ray.inv_direction * s,
            tmin: ray.tmin * s,
            tmax: ray.tmax * s,
        }
    }

    /// The distance along a ray below which a traversal enters no box, in the scene's units:
    /// obvhs's [`OBVHS_BOX_T_MIN`] over the traversals' scale. What the GPU's traversals
    /// (`occlusion.wgsl`, `first_hit.wgsl`) use, so that they enter the CPU's boxes.
    pub fn box_t_min(&self) -> f32 {
        OBVHS_BOX_T_MIN / self.t_scale
    }

    /// Whether any surface is cut out.
    pub fn has_cutouts(&self) -> bool {
        self.cut.is_some()
    }

    /// [`hit`] against primitive `id`, through its cut-out: infinity where the ray meets a
    /// hole. The one triangle test of every query.
    #[inline]
    pub fn primitive_hit(&self, id: usize, ray: &Ray) -> f32 {
        match &self.cut {
            None => hit(&self.tris[id], ray),
            Some((c, slots)) => match slots[id] {
                0 => hit(&self.tris[id], ray),
                s => match intersect(&self.tris[id], ray) {
                    Some((t, w)) if c.covers(s, w) => t,
                    _ => f32::INFINITY,
                },
            },
        }
    }

    /// True when the ray from `origin` along `dir` hits any triangle that does not use vertex
    /// `skip` (the vertex the ray starts from: its own triangles cannot shadow it).
    #[inline]
    pub fn occluded(&self, origin: Vec3, dir: Vec3, skip: u32) -> bool {
        self.occluded_until(origin, dir, f32::INFINITY, skip)
    }

    /// Whether a triangle not touching vertex `skip` blocks the ray from `origin` along `dir`
    /// before distance `t_max` (in units of `dir`).
    pub fn occluded_until(&self, origin: Vec3, dir: Vec3, t_max: f32, skip: u32) -> bool {
        self.occluded_between(origin, dir, 0.0, t_max, skip)
    }

    /// [`Occluder::occluded_until`], counting only hits at distances in \[`t_min`, `t_max`\]:
    /// a surface point's rays ignore surfaces that pass through their origin (the wall beside a
    /// floor vertex of a room, whose plane contains the vertex: a hit at t ≈ 0 ± rounding).
    pub fn occluded_between(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_min: f32,
        t_max: f32,
        skip: u32,
    ) -> bool {
        let ray = self.traversal_ray(Ray::new(origin.into(), dir.into(), t_min, t_max));
        // The triangle first: most tests miss, and then its vertex indices (another cache
        // line) are not read.
        !self.bvh.ray_traverse_miss(ray, |ray, id| {
            let t = self.primitive_hit(id, ray);
            if t < f32::INFINITY && self.indices[id].contains(&skip) {
                f32::INFINITY
            } else {
                t
            }
        })
    }

    /// [`Occluder::occluded_between`], naming the primitive (in this occluder's order) whose
    /// hit ended the any-hit traversal, or `None` when nothing blocks the ray.
    pub fn blocker_between(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_min: f32,
        t_max: f32,
        skip: u32,
    ) -> Option<u32> {
        self.blocker(Ray::new(origin.into(), dir.into(), t_min, t_max), skip)
    }

    /// [`Occluder::blocker_between`] for a ray already made (`Ray::new` divides thrice).
    pub fn blocker(&self, ray: Ray, skip: u32) -> Option<u32> {
        let mut found = None;
        self.bvh
            .ray_traverse_miss(self.traversal_ray(ray), |ray, id| {
                let t = self.primitive_hit(id, ray);
                if t < f32::INFINITY && self.indices[id].contains(&skip) {
                    return f32::INFINITY;
                }
                // The traversal's own acceptance test (`t < ray.tmax`), so the primitive named
                // is the one that ended it.
                if t < ray.tmax {
                    found = Some(id as u32);
                }
                t
            });
        found
    }

    /// Whether primitive `prim` (as named by [`Occluder::blocker_between`]) blocks `ray` by the
    /// test the traversal applies to it: a hit at a distance in \[`ray.tmin`, `ray.tmax`).
    /// A ray it blocks is occluded for [`Occluder::occluded_between`] too wherever the
    /// traversal reaches the primitive's leaf — not always at a hit exactly on an edge that is
    /// also a leaf-box face (see docs/bake.md, "The adaptive cast").
    #[inline]
    pub fn primitive_blocks(&self, prim: u32, ray: &Ray) -> bool {
        self.primitive_hit(prim as usize, ray) < ray.tmax
    }

    /// [`Occluder::primitive_blocks`], and how near the ray's line passes to the triangle: the
    /// smallest of its barycentric coordinates there (Möller–Trumbore's u, v, 1 − u − v;
    /// negative outside, −∞ parallel), for choosing the closest of several triangles.
    #[inline]
    pub fn primitive_blocks_near(&self, prim: u32, ray: &Ray) -> (bool, f32) {
        let (det, [w, u, v], _) = line_crossing(&self.tris[prim as usize], ray);
        let near = w.min(u).min(v);
        let near = if det != 0.0 && !near.is_nan() {
            near
        } else {
            f32::NEG_INFINITY
        };
        (
            near >= -EDGE_SLACK && self.primitive_blocks(prim, ray),
            near,
        )
    }

    /// Asks for primitive `prim`'s triangle ahead of a [`Occluder::primitive_blocks`] on it
    /// ([`prefetch`]).
    #[inline(always)]
    pub fn prefetch_primitive(&self, prim: u32) {
        prefetch(&self.tris, prim as usize);
    }

    /// The mesh triangle index of each primitive, in this occluder's order.
    pub fn primitive_triangles(&self) -> &[u32] {
        &self.order
    }

    /// True when the segment from `origin` along unit `dir` up to distance `t_max` hits any
    /// triangle (shadow rays from surface points; the caller offsets `origin`).
    #[inline]
    pub fn occluded_segment(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        let ray = self.traversal_ray(Ray::new(origin.into(), dir.into(), 0.0, t_max));
        !self
            .bvh
            .ray_traverse_miss(ray, |ray, id| self.primitive_hit(id, ray))
    }

    /// Distance to the closest triangle hit by the segment from `origin` along unit `dir` up to
    /// `t_max`, or `None` when the segment is clear (closest-hit traversal: the ray's `tmax`
    /// shrinks to each hit found).
    #[inline]
    pub fn first_hit(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<f32> {
        if !(t_max > 0.0) || !origin.is_finite() || !dir.is_finite() {
            return None;
        }
        let ray = self.traversal_ray(Ray::new(origin.into(), dir.into(), 0.0, t_max));
        let mut hit = RayHit::none();
        self.bvh
            .ray_traverse(ray, &mut hit, |ray, id| self.primitive_hit(id, ray))
            .then_some(hit.t / self.t_scale)
            .filter(|t| t.is_finite())
    }
}
