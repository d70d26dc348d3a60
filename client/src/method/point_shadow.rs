//! What the point-light shadow methods (paper 003 and its shadow-map baselines) share: the
//! unshadowed per-pixel LTC × one technique's shadow factor ([`crate::penumbra::render`]).

use anyhow::Result;

use super::{Frame, FrameInput, MethodState, SceneData, Settings};
use crate::penumbra::{self, Params, Technique};
use crate::render::renderer::FrameCounts;

/// A technique and whether it traces rays.
pub(crate) struct PointShadow {
    technique: Technique,
    rays: bool,
}

impl PointShadow {
    pub(crate) fn new(technique: Technique, rays: bool) -> PointShadow {
        debug_assert_eq!(rays, technique.needs_rays());
        PointShadow { technique, rays }
    }
}

/// The prepared state: the BVH is built now when the technique traces rays.
pub(crate) fn prepare(
    p: PointShadow,
    scene: &SceneData,
    settings: &Settings,
) -> Box<dyn MethodState> {
    if p.rays {
        scene.occluder();
    }
    Box::new(State {
        p,
        params: settings.penumbra,
    })
}

struct State {
    p: PointShadow,
    params: Params,
}

impl MethodState for State {
    fn frame(&mut self, f: &FrameInput) -> Result<Frame> {
        let occ = self.p.rays.then(|| f.scene.occluder());
        let image = penumbra::render(f.renderer, f.light()?, self.p.technique, occ, &self.params)?;
        Ok(Frame::new(
            image,
            FrameCounts {
                pixels_shaded: f.renderer.gbuffer.covered(),
                ..FrameCounts::default()
            },
        ))
    }
}
