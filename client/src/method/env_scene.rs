//! What the environment methods share: the map, and a moving scene posed, rasterised and (for
//! rays) given its own BVH inside each frame's time (`render::posed`).

use std::time::Instant;

use bspvt_proto::Scene;
use bspvt_raytrace::Occluder;

use super::FrameInput;
use crate::frame::gbuffer::GBuffer;
use crate::render::posed::Posed;

/// A moving scene's current pose (`None` for a static scene: the frame's own G-buffer and
/// the scene's BVH are used).
#[derive(Default)]
pub(crate) struct Pose {
    posed: Option<Posed>,
}

impl Pose {
    /// The scene, G-buffer and BVH (when `rays`) of this frame, and the time posing took (ms;
    /// `None` for a static scene).
    pub(crate) fn at<'a>(
        &'a mut self,
        f: &'a FrameInput,
        rays: bool,
    ) -> (&'a Scene, &'a GBuffer, Option<&'a Occluder>, Option<f64>) {
        let base = f.scene.scene;
        if !base.is_dynamic() {
            let occ = rays.then(|| f.scene.occluder());
            return (base, &f.renderer.gbuffer, occ, None);
        }
        let t0 = Instant::now();
        let view = &f.renderer.view;
        let p = match self.posed.take() {
            Some(mut p) => {
                p.update(base, f.time, view);
                p
            }
            None => Posed::new(base, f.time, view, rays),
        };
        let p = self.posed.insert(p);
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        (&p.scene, &p.gbuffer, p.occluder.as_ref(), Some(ms))
    }
}
