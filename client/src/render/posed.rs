//! A moving scene posed frame by frame for the run-time methods (paper 001 needs no
//! precompute): the meshes at cycle time t ([`bspvt_proto::motion`]), the G-buffer through the
//! view, and, when rays are needed, a BVH rebuilt for the pose.

use bspvt_proto::Scene;
use bspvt_server::bake::raycast::{Occluder, mesh_triangles};

use super::camera::View;
use super::gbuffer::GBuffer;

/// The scene as it is in one frame.
pub struct Posed {
    pub scene: Scene,
    pub gbuffer: GBuffer,
    /// Ray-traced visibility of this pose (when asked for).
    pub occluder: Option<Occluder>,
    /// The cycle time of this pose.
    pub t: f32,
}

impl Posed {
    /// `base` at cycle time `t`, seen through `view`; `rays`: build the BVH too.
    pub fn new(base: &Scene, t: f32, view: &View, rays: bool) -> Posed {
        let scene = base.at(t);
        let gbuffer = GBuffer::rasterize(&scene.mesh, view);
        let occluder = rays.then(|| Occluder::new_fast(&scene.mesh, &mesh_triangles(&scene.mesh)));
        Posed {
            scene,
            gbuffer,
            occluder,
            t,
        }
    }

    /// Moves to cycle time `t` seen through `view`: re-poses the meshes, re-rasterises, and
    /// rebuilds the BVH if there is one.
    pub fn update(&mut self, base: &Scene, t: f32, view: &View) {
        base.pose_into(t, &mut self.scene.mesh);
        if self.occluder.is_some() {
            let tris = mesh_triangles(&self.scene.mesh);
            self.occluder = Some(Occluder::new_fast(&self.scene.mesh, &tris));
        }
        self.gbuffer = GBuffer::rasterize(&self.scene.mesh, view);
        self.t = t;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::image::Image;
    use crate::render::renderer::Mode;
    use crate::render::sequence::{EnvOptions, Method, Options, render_sequence};

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

    /// SG and its Monte Carlo reference on a moving scene: every frame is posed (the frame at
    /// t = ½ is the static render of the scene posed at ½), the frames differ, and the pose's
    /// time is reported.
    #[test]
    fn env_methods_render_the_scene_as_it_moves() {
        let dir = tempfile::tempdir().expect("temp dir");
        let base = dynamic();
        let mut opts = Options {
            method: Method::Sg,
            mode: Mode::Pixel,
            spp: 4,
            width: 48,
            height: 40,
            frames: 2,
            light: 0,
            env: Some(EnvOptions {
                path: crate::sg::env::write_test_map(dir.path()),
                lobes: 4,
                sg: crate::sg::SgOptions::default(),
            }),
        };
        let mut frames: Vec<Image> = Vec::new();
        let stats = render_sequence(&base, None, &opts, |_, img| {
            frames.push(img.clone());
            Ok(())
        })
        .expect("sg sequence");
        assert_eq!(frames.len(), 2);
        assert!(stats.pose_ms.is_some_and(|ms| ms >= 0.0));
        assert!(frames[0].pixels != frames[1].pixels, "the scene moved");
        let mut still: Vec<Image> = Vec::new();
        opts.frames = 1;
        render_sequence(&base.at(0.5), None, &opts, |_, img| {
            still.push(img.clone());
            Ok(())
        })
        .expect("static sequence");
        assert!(
            still[0].pixels == frames[1].pixels,
            "the frame at t = ½ differs from the scene frozen at ½"
        );
        opts.method = Method::McEnv;
        opts.frames = 2;
        let mut mc: Vec<Image> = Vec::new();
        let stats = render_sequence(&base, None, &opts, |_, img| {
            mc.push(img.clone());
            Ok(())
        })
        .expect("mc-env sequence");
        assert!(stats.pose_ms.is_some());
        assert!(
            mc.iter()
                .all(|i| i.pixels.iter().flatten().all(|c| c.is_finite()))
        );
        assert!(mc[1].mean() > 0.0);
    }
}
