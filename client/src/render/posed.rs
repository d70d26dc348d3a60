//! A moving scene posed frame by frame for the run-time methods (paper 001 needs no
//! precompute): the meshes at cycle time t ([`bspvt_proto::motion`]), the G-buffer through the
//! view, and, when rays are needed, a BVH rebuilt for the pose.

use crate::frame::normal_map::NormalMaps;
use bspvt_proto::Scene;
use bspvt_raytrace::{Cutouts, Occluder, mesh_triangles};

use crate::frame::camera::View;
use crate::frame::gbuffer::GBuffer;

/// The scene as it is in one frame.
pub struct Posed {
    /// The scene posed at `t`.
    pub scene: Scene,
    /// Its G-buffer for the view it was posed for.
    pub gbuffer: GBuffer,
    /// Ray-traced visibility of this pose (when asked for).
    pub(crate) occluder: Option<Occluder>,
    /// The cycle time of this pose.
    pub(crate) t: f32,
    /// The scene's cut-outs: posing moves vertices, not UVs or materials, so one set serves
    /// every pose.
    cut: Option<std::sync::Arc<Cutouts>>,
}

impl Posed {
    /// `base` at cycle time `t`, seen through `view`; `rays`: build the BVH too.
    pub fn new(base: &Scene, t: f32, view: &View, rays: bool) -> Posed {
        let scene = base.at(t);
        let cut = Cutouts::of(&scene.mesh, &scene.materials);
        let gbuffer = GBuffer::rasterize_cut(&scene.mesh, view, cut.as_deref())
            .with_normal_maps(NormalMaps::of(&scene.mesh, &scene.materials));
        let occluder = rays.then(|| {
            Occluder::new_fast(&scene.mesh, &mesh_triangles(&scene.mesh)).cut_out(cut.clone())
        });
        Posed {
            scene,
            gbuffer,
            occluder,
            t,
            cut,
        }
    }

    /// Moves to cycle time `t` seen through `view`: re-poses the meshes, re-rasterises, and
    /// rebuilds the BVH if there is one.
    pub fn update(&mut self, base: &Scene, t: f32, view: &View) {
        base.pose_into(t, &mut self.scene.mesh);
        if self.occluder.is_some() {
            let tris = mesh_triangles(&self.scene.mesh);
            self.occluder =
                Some(Occluder::new_fast(&self.scene.mesh, &tris).cut_out(self.cut.clone()));
        }
        // The tangent frames turn with the pose (normal-mapped scenes only).
        let normal_maps = NormalMaps::of(&self.scene.mesh, &self.scene.materials);
        self.gbuffer = GBuffer::rasterize_cut(&self.scene.mesh, view, self.cut.as_deref())
            .with_normal_maps(normal_maps);
        self.t = t;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dynamic() -> Scene {
        bspvt_proto::builtin::scene("dynamic").expect("built-in dynamic scene")
    }

    /// Updating a pose in place gives exactly a fresh pose at that time.
    #[test]
    fn update_matches_a_fresh_pose() {
        let base = dynamic();
        let view = View::new(&base.camera, 40, 30);
        let mut p = Posed::new(&base, 0.0, &view, true);
        p.update(&base, 0.4, &view);
        let q = Posed::new(&base, 0.4, &view, true);
        assert!(p.scene == q.scene && p.gbuffer.tri == q.gbuffer.tri);
        assert!(p.scene.mesh != base.mesh);
        assert!(p.occluder.is_some());
    }
}
