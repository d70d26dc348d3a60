//! Closest-hit primary rays for box-filtered (jittered) pixels: the surface seen along any
//! camera ray, not only through pixel centres (the G-buffer's job). Used by
//! [`super::render_mc_box`], whose pixels integrate over their whole footprint like an
//! independent renderer's box reconstruction filter.

use std::time::Duration;

use bspvt_proto::Mesh;
use std::sync::Arc;

use bspvt_raytrace::{Cutouts, mesh_triangles};
use glam::{DVec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    cwbvh::CwBvh,
    ray::{Ray, RayHit},
    rt_triangle::RtTriangle,
};

use crate::frame::gbuffer::Surface;

/// A mesh prepared for closest-hit queries.
pub struct Tracer {
    bvh: CwBvh,
    /// Triangles in BVH primitive order.
    tris: Vec<RtTriangle>,
    /// Mesh triangle index of each BVH primitive.
    ids: Vec<u32>,
    /// The scene's alpha cut-outs: the camera sees through their holes.
    cut: Option<Arc<Cutouts>>,
    /// The scene's normal maps, which bend the surfaces' shading normals.
    normal_maps: Option<Arc<crate::frame::normal_map::NormalMaps>>,
}

impl Tracer {
    /// Builds the BVH of `mesh` for primary rays.
    pub fn new(mesh: &Mesh) -> Tracer {
        let tris = mesh_triangles(mesh);
        let bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(
            &tris,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        let ids = bvh.primitive_indices.clone();
        let rt = ids
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        Tracer {
            bvh,
            tris: rt,
            ids,
            cut: None,
            normal_maps: None,
        }
    }

    /// The tracer of `scene`'s surfaces as every method sees them: through its cut-outs, with
    /// its normal maps.
    pub fn of_scene(scene: &bspvt_proto::Scene) -> Tracer {
        let mut t = Tracer::new(&scene.mesh).cut_out(Cutouts::of(&scene.mesh, &scene.materials));
        t.normal_maps = crate::frame::normal_map::NormalMaps::of(&scene.mesh, &scene.materials);
        t
    }

    /// This tracer seeing through the scene's cut-outs ([`Cutouts::of`]).
    pub fn cut_out(mut self, cutouts: Option<Arc<Cutouts>>) -> Tracer {
        self.cut = cutouts;
        self
    }

    /// The surface hit first by the ray from `eye` along unit `dir`, shaded like
    /// [`crate::frame::gbuffer::GBuffer::surface`] (interpolated normal facing the viewer).
    pub(crate) fn surface(&self, mesh: &Mesh, eye: DVec3, dir: DVec3) -> Option<Surface> {
        let ray = Ray::new(
            Vec3A::from(eye.as_vec3()),
            Vec3A::from(dir.as_vec3()),
            0.0,
            f32::INFINITY,
        );
        let mut hit = RayHit::none();
        if !self
            .bvh
            .ray_traverse(ray, &mut hit, |r, id| match &self.cut {
                None => bspvt_raytrace::hit(&self.tris[id], r),
                Some(c) => match bspvt_raytrace::intersect(&self.tris[id], r) {
                    Some((t, w)) if c.covers_triangle(self.ids[id], w) => t,
                    _ => f32::INFINITY,
                },
            })
        {
            return None;
        }
        let t = *self.ids.get(hit.primitive_id as usize)?;
        let idx = *mesh.triangles.get(t as usize)?;
        let p = idx.map(|v| mesh.positions[v as usize].as_dvec3());
        let (b1, b2) = crate::frame::gbuffer::ray_plane_barycentrics(eye, dir, p);
        let weights = [1.0 - b1 - b2, b1, b2];
        let position = weights[0] * p[0] + weights[1] * p[1] + weights[2] * p[2];
        let mut geometric = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or(DVec3::Z);
        if geometric.dot(eye - position) < 0.0 {
            geometric = -geometric;
        }
        let normal = crate::frame::gbuffer::shading_normal(
            mesh,
            t,
            weights,
            geometric,
            (eye - position).normalize_or(geometric),
            None,
            self.normal_maps.as_deref(),
        );
        Some(Surface {
            tri: t,
            weights,
            position,
            normal,
            geometric,
            // A camera ray is a point sample: the Monte Carlo's pixel filter averages the
            // texels itself, at the finest level.
            duv: None,
        })
    }
}
