//! Monte Carlo ground truth under the environment map: exact GGX, shadow rays, MIS of map and
//! BRDF sampling ([Veach95], [Pharr16] §14.2); plus the scene's lamps, as `bspvt-env` has them.

use anyhow::{Context, Result};

use super::env_scene::Pose;
use super::{Frame, FrameInput, FrameMethod, MethodState, Needs, SceneData, Settings, SetupReport};
use crate::envmap::EnvLight;
use crate::groundtruth::{render_mc, render_mc_env};
use crate::render::renderer::{FrameCounts, Mode};

/// See the module doc.
pub(crate) struct McEnv;

impl FrameMethod for McEnv {
    fn name(&self) -> &'static str {
        "mc-env"
    }
    fn label(&self) -> &'static str {
        "Monte Carlo environment"
    }
    fn description(&self) -> &'static str {
        "Monte Carlo ground truth under the environment map and the scene's lamps: exact GGX, shadow rays, MIS (--env, --spp)"
    }
    fn needs(&self) -> Needs {
        Needs {
            env_map: true,
            rays: true,
            ..Needs::default()
        }
    }
    fn fixed_mode(&self) -> Option<Mode> {
        Some(Mode::Pixel)
    }
    fn prepare(&self, scene: &SceneData, settings: &Settings) -> Result<Box<dyn MethodState>> {
        let env = settings.env.load_map()?;
        if !scene.scene.is_dynamic() {
            scene.occluder();
        }
        Ok(Box::new(State {
            env,
            spp: settings.spp,
            pose: Pose::default(),
        }))
    }
}

struct State {
    env: EnvLight,
    spp: u32,
    pose: Pose,
}

impl MethodState for State {
    fn frame(&mut self, f: &FrameInput) -> Result<Frame> {
        let (scene, gbuffer, occ, pose_ms) = self.pose.at(f, true);
        let occ = occ.context("the Monte Carlo reference needs rays")?;
        let (mut image, noise) = render_mc_env(
            scene,
            &f.renderer.view,
            gbuffer,
            &self.env,
            occ,
            self.spp,
            f.index,
        );
        // The scene's lamps too, as `bspvt-env` draws them beside the sky (issue 34).
        if !f.lights.is_empty() {
            let seed = f.index ^ 0x6c61_6d70_7300_0000;
            let lamps = render_mc(
                scene,
                &f.renderer.view,
                gbuffer,
                f.lights,
                occ,
                self.spp,
                seed,
            );
            image.add(&lamps.0);
        }
        let mut frame = Frame::new(image, FrameCounts::default());
        frame.noise = Some(noise.mean_rel_stderr);
        frame.pose_ms = pose_ms;
        Ok(frame)
    }

    fn report(&self) -> SetupReport {
        SetupReport {
            spp: Some(self.spp),
            ..SetupReport::default()
        }
    }
}
