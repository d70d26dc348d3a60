//! Paper 001: the environment map as K spherical Gaussians [Wang09], visibility by a
//! spherical signed distance found at run time (screen-space depth maps, or exact rays).

use anyhow::{Context, Result};

use super::env_scene::Pose;
use super::{Frame, FrameInput, FrameMethod, MethodState, Needs, SceneData, Settings, SetupReport};
use crate::render::renderer::FrameCounts;
use crate::sg::{SgCache, SgEnv, SgOptions, SsdfMode};

/// See the module doc.
pub(crate) struct SgEnvironment;

impl FrameMethod for SgEnvironment {
    fn name(&self) -> &'static str {
        "sg"
    }
    fn label(&self) -> &'static str {
        "SG environment + SSDF"
    }
    fn description(&self) -> &'static str {
        "environment map as spherical Gaussians, visibility by a run-time SSDF (paper 001; --env, --lobes, --ssdf)"
    }
    fn needs(&self) -> Needs {
        Needs {
            env_map: true,
            ..Needs::default()
        }
    }
    fn fixed_mode(&self) -> Option<crate::render::renderer::Mode> {
        Some(crate::render::renderer::Mode::Pixel)
    }
    fn prepare(&self, scene: &SceneData, settings: &Settings) -> Result<Box<dyn MethodState>> {
        let e = &settings.env;
        let env = e.load_map()?;
        // Cached in the temp folder: a second start skips the fit's seconds.
        let sg = crate::sg::fit_cached(&env, e.lobes, &std::env::temp_dir().join("bspvt-sg-fit"));
        crate::sg::halfspace::warm_up();
        let rays = e.sg.ssdf == SsdfMode::Exact;
        if rays && !scene.scene.is_dynamic() {
            scene.occluder();
        }
        Ok(Box::new(State {
            sg,
            opts: e.sg,
            rays,
            pose: Pose::default(),
            cache: SgCache::default(),
        }))
    }
}

struct State {
    sg: SgEnv,
    opts: SgOptions,
    rays: bool,
    pose: Pose,
    /// Depth maps and diffuse tables kept while the scene is still.
    cache: SgCache,
}

impl MethodState for State {
    fn frame(&mut self, f: &FrameInput) -> Result<Frame> {
        let (scene, gbuffer, occ, pose_ms) = self.pose.at(f, self.rays);
        let (image, timings) = crate::sg::render_cached(
            scene,
            &f.renderer.view,
            gbuffer,
            &self.sg,
            occ,
            &self.opts,
            &mut self.cache,
        )
        .context("SG rendering")?;
        let mut frame = Frame::new(image, FrameCounts::default());
        frame.maps_ms = Some(timings.maps_ms);
        frame.pose_ms = pose_ms;
        Ok(frame)
    }

    fn report(&self) -> SetupReport {
        SetupReport {
            sg_lobes: Some(self.sg.lobes.len()),
            sg_fit_error: Some(self.sg.fit_error),
            sg_fit_seconds: Some(self.sg.seconds),
            ssdf: Some(self.opts.ssdf),
            ..SetupReport::default()
        }
    }
}
