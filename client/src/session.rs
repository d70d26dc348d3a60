//! One interactive shading session: a scene, its trees as they stream in, a camera, a light the
//! user moves, the method and mode. The viewer, `bspvt animate` and `bspvt demo` all draw their
//! frames through [`Session::frame`], so a headless sequence is what the window shows.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, TryRecvError};

use bspvt_proto::Scene;
use bspvt_proto::scene::Camera;
use bspvt_server::bake::raycast::{Occluder, mesh_triangles};
use glam::{DAffine3, DQuat, DVec3};

use crate::groundtruth;
use crate::light::Light;
use crate::penumbra;
use crate::render::image::Image;
use crate::render::path::LightPath;
use crate::render::posed::Posed;
use crate::render::renderer::{Mode, Renderer};
use crate::stream::fetch::{Counters, Update};
use crate::stream::trees::StreamedTrees;

/// What the session draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ViewMethod {
    /// BSPVT visibility × LTC GGX (streamed trees; unshadowed where none arrived yet).
    Bspvt,
    /// Unshadowed LTC GGX.
    Ltc,
    /// Progressive Monte Carlo ground truth (exact GGX, shadow rays): refines while nothing moves.
    Mc,
    /// Paper 003: a hard shadow ray to the light's centroid, blurred by the penumbra width.
    RtPenumbra,
    /// Shadow map: percentage-closer soft shadows.
    Pcss,
    /// Shadow map: percentage-closer filtering (fixed kernel).
    Pcf,
    /// Variance shadow map.
    Vsm,
    /// Paper 001: the environment map (not the polygonal light) as spherical Gaussians, with
    /// screen-space SSDF visibility; the map is loaded and fitted on first use.
    Sg,
}

impl ViewMethod {
    pub const ALL: [ViewMethod; 8] = [
        ViewMethod::Bspvt,
        ViewMethod::Ltc,
        ViewMethod::Mc,
        ViewMethod::RtPenumbra,
        ViewMethod::Pcss,
        ViewMethod::Pcf,
        ViewMethod::Vsm,
        ViewMethod::Sg,
    ];

    pub fn name(self) -> &'static str {
        match self {
            ViewMethod::Bspvt => "BSPVT",
            ViewMethod::Ltc => "LTC (no shadows)",
            ViewMethod::Mc => "Monte Carlo",
            ViewMethod::RtPenumbra => "RT penumbra (point light)",
            ViewMethod::Pcss => "PCSS",
            ViewMethod::Pcf => "PCF",
            ViewMethod::Vsm => "VSM",
            ViewMethod::Sg => "SG environment + SSDF",
        }
    }

    /// The point-light shadow technique of this method, if it is one (always per pixel).
    pub fn penumbra(self) -> Option<penumbra::Technique> {
        match self {
            ViewMethod::RtPenumbra => Some(penumbra::Technique::RtPenumbra),
            ViewMethod::Pcss => Some(penumbra::Technique::Pcss),
            ViewMethod::Pcf => Some(penumbra::Technique::Pcf),
            ViewMethod::Vsm => Some(penumbra::Technique::Vsm),
            _ => None,
        }
    }
}

/// An orbit camera around a target.
#[derive(Clone, Copy, Debug)]
pub struct Orbit {
    pub target: DVec3,
    pub yaw: f64,
    pub pitch: f64,
    pub distance: f64,
    pub fov_y_deg: f32,
}

impl Orbit {
    pub fn from_camera(c: &Camera) -> Orbit {
        let target = DVec3::from(c.target.map(f64::from));
        let d = DVec3::from(c.position.map(f64::from)) - target;
        let distance = d.length().max(1e-6);
        Orbit {
            target,
            yaw: d.x.atan2(d.z),
            pitch: (d.y / distance).clamp(-1.0, 1.0).asin(),
            distance,
            fov_y_deg: c.fov_y_deg,
        }
    }

    pub fn camera(&self) -> Camera {
        let pitch = self.pitch.clamp(-1.5, 1.5);
        let d = DVec3::new(
            pitch.cos() * self.yaw.sin(),
            pitch.sin(),
            pitch.cos() * self.yaw.cos(),
        ) * self.distance;
        let p = self.target + d;
        Camera {
            position: p.as_vec3().to_array(),
            target: self.target.as_vec3().to_array(),
            up: [0.0, 1.0, 0.0],
            fov_y_deg: self.fov_y_deg,
        }
    }
}

/// The user's pose of the light relative to its rest pose: a translation and a rotation about
/// its centroid, and a radiance scale.
#[derive(Clone, Copy, Debug)]
pub struct LightPose {
    pub offset: DVec3,
    pub yaw: f64,
    pub tilt: f64,
    pub radiance_scale: f64,
}

impl Default for LightPose {
    fn default() -> LightPose {
        LightPose {
            offset: DVec3::ZERO,
            yaw: 0.0,
            tilt: 0.0,
            radiance_scale: 1.0,
        }
    }
}

pub struct Session<'a> {
    pub scene: &'a Scene,
    pub renderer: Renderer<'a>,
    pub streamed: StreamedTrees,
    updates: Option<Receiver<Update>>,
    pub counters: Option<Arc<Counters>>,
    pub method: ViewMethod,
    pub mode: Mode,
    pub orbit: Orbit,
    rest: Light,
    path: LightPath,
    pub pose: LightPose,
    /// Position on the light's default path in [0, 1) (`None`: the user's pose alone).
    pub path_t: Option<f64>,
    pub roughness: Option<f32>,
    occluder: Option<Occluder>,
    /// Progressive Monte Carlo: running sum and passes, reset by any change.
    mc: Option<(Vec<[f32; 3]>, u32)>,
    /// [`ViewMethod::Sg`]: the environment map (default: the test map) and lobe count; the fit
    /// happens on the first SG frame, cached in the temp folder (`Err`: loading failed, SG
    /// frames fall back to LTC).
    pub env_path: Option<std::path::PathBuf>,
    pub sg_lobes: usize,
    sg: Option<Result<crate::sg::SgEnv, String>>,
    /// [`ViewMethod::Sg`] on a moving scene: the meshes posed at `path_t` (cycle time).
    posed: Option<Posed>,
}

impl<'a> Session<'a> {
    pub fn new(
        scene: &'a Scene,
        width: u32,
        height: u32,
        streamed: StreamedTrees,
        updates: Option<Receiver<Update>>,
        counters: Option<Arc<Counters>>,
    ) -> anyhow::Result<Session<'a>> {
        let light = scene
            .lights
            .first()
            .ok_or_else(|| anyhow::anyhow!("the scene has no light"))?;
        let rest = Light::load(light)?;
        let path = LightPath::new(light, rest.clone());
        Ok(Session {
            scene,
            renderer: Renderer::new(scene, width, height),
            streamed,
            updates,
            counters,
            method: ViewMethod::Bspvt,
            mode: Mode::Vertex,
            orbit: Orbit::from_camera(&scene.camera),
            rest,
            path,
            pose: LightPose::default(),
            path_t: None,
            roughness: None,
            occluder: None,
            mc: None,
            env_path: None,
            sg_lobes: 16,
            sg: None,
            posed: None,
        })
    }

    /// The fitted environment of [`ViewMethod::Sg`], loading and fitting it on first use.
    fn sg_env(&mut self) -> Result<&crate::sg::SgEnv, &str> {
        let path = self
            .env_path
            .clone()
            .unwrap_or_else(crate::sg::env::default_env_path);
        let k = self.sg_lobes;
        self.sg
            .get_or_insert_with(|| {
                // Cached in the temp folder: the viewer starts without the fit's seconds.
                let cache = std::env::temp_dir().join("bspvt-sg-fit");
                crate::sg::EnvLight::load(&path)
                    .map(|env| crate::sg::fit_cached(&env, k, &cache))
                    .map_err(|e| format!("{e:#}"))
            })
            .as_ref()
            .map_err(String::as_str)
    }

    /// Applies the updates that arrived; returns whether the trees changed.
    pub fn poll(&mut self) -> bool {
        let mut changed = false;
        let Some(rx) = &self.updates else {
            return false;
        };
        loop {
            match rx.try_recv() {
                Ok(u) => changed |= self.streamed.apply(u),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    self.updates = None;
                    break;
                }
            }
        }
        if changed {
            self.mc = None;
        }
        changed
    }

    /// Blocks until the fetcher has delivered everything (or given up).
    pub fn wait_complete(&mut self) {
        while self.streaming() {
            match self.updates.as_ref().map(Receiver::recv) {
                Some(Ok(u)) => {
                    if self.streamed.apply(u) {
                        self.mc = None;
                    }
                }
                _ => self.updates = None,
            }
        }
    }

    /// Something the image depends on changed: restart progressive rendering.
    pub fn invalidate(&mut self) {
        self.mc = None;
    }

    pub fn set_camera(&mut self, orbit: Orbit) {
        self.orbit = orbit;
        self.renderer.set_camera(&orbit.camera());
        self.invalidate();
    }

    pub fn set_roughness(&mut self, alpha: Option<f32>) {
        self.roughness = alpha.map(|a| a.clamp(1e-3, 1.0));
        self.renderer.set_roughness(self.roughness);
        self.invalidate();
    }

    /// The light for the current frame.
    pub fn light(&self) -> Light {
        let base = match self.path_t {
            Some(t) => self.path.at(t),
            None => self.rest.clone(),
        };
        let c = base.centroid();
        let m = DAffine3::from_translation(c + self.pose.offset)
            * DAffine3::from_quat(
                DQuat::from_rotation_y(self.pose.yaw) * DQuat::from_rotation_x(self.pose.tilt),
            )
            * DAffine3::from_translation(-c);
        let mut l = base.transformed(&m);
        l.radiance *= self.pose.radiance_scale;
        l
    }

    /// Vertices the camera sees (what the fetcher should bring first).
    pub fn visible_vertices(&self) -> &[u32] {
        &self.renderer.visible_vertices
    }

    /// Draws one frame.
    pub fn frame(&mut self) -> Image {
        let light = self.light();
        if self.method == ViewMethod::Sg {
            let failed = match self.sg_env() {
                Ok(env) => {
                    let env = env.clone();
                    // A moving scene is posed at the path's time (the run-time method needs
                    // no precompute; the trees of the other methods stay at t = 0).
                    let (scene, gbuffer) = if self.scene.is_dynamic() {
                        let t = self.path_t.unwrap_or(0.0) as f32;
                        let view = &self.renderer.view;
                        let p = match self.posed.take() {
                            Some(mut p) => {
                                p.update(self.scene, t, view);
                                p
                            }
                            None => Posed::new(self.scene, t, view, false),
                        };
                        let p = self.posed.insert(p);
                        (&p.scene, &p.gbuffer)
                    } else {
                        (self.scene, &self.renderer.gbuffer)
                    };
                    match crate::sg::render(
                        scene,
                        &self.renderer.view,
                        gbuffer,
                        &env,
                        None,
                        &crate::sg::SgOptions::default(),
                    ) {
                        Ok((img, _)) => return img,
                        Err(e) => format!("{e:#}"),
                    }
                }
                Err(e) => e.to_string(),
            };
            tracing::warn!("SG: {failed}; drawing unshadowed LTC");
            return self.renderer.ltc(&light, Mode::Pixel).0;
        }
        match (self.method, self.method.penumbra()) {
            (ViewMethod::Bspvt, _) => match self.streamed.view() {
                Some(trees) => self.renderer.bspvt(&light, &trees, self.mode).0,
                None => self.renderer.ltc(&light, self.mode).0,
            },
            (ViewMethod::Ltc, _) => self.renderer.ltc(&light, self.mode).0,
            (_, Some(technique)) => {
                let occ = technique.needs_rays().then(|| {
                    &*self.occluder.get_or_insert_with(|| {
                        Occluder::new(&self.scene.mesh, &mesh_triangles(&self.scene.mesh))
                    })
                });
                match penumbra::render(
                    &self.renderer,
                    &light,
                    technique,
                    occ,
                    &penumbra::Params::default(),
                ) {
                    Ok(img) => img,
                    Err(e) => {
                        tracing::warn!("{technique:?}: {e:#}");
                        self.renderer.ltc(&light, Mode::Pixel).0
                    }
                }
            }
            _ => {
                let occ = self.occluder.get_or_insert_with(|| {
                    Occluder::new(&self.scene.mesh, &mesh_triangles(&self.scene.mesh))
                });
                let (sum, passes) = self.mc.get_or_insert_with(|| {
                    let n = self.renderer.gbuffer.width * self.renderer.gbuffer.height;
                    (vec![[0.0; 3]; n as usize], 0)
                });
                let (img, _) = groundtruth::render_mc(
                    self.scene,
                    &self.renderer.view,
                    &self.renderer.gbuffer,
                    &light,
                    occ,
                    1,
                    u64::from(*passes),
                );
                *passes += 1;
                for (s, p) in sum.iter_mut().zip(&img.pixels) {
                    for k in 0..3 {
                        s[k] += p[k];
                    }
                }
                let mut out = Image::new(img.width, img.height);
                let inv = 1.0 / *passes as f32;
                for (o, s) in out.pixels.iter_mut().zip(sum.iter()) {
                    *o = s.map(|x| x * inv);
                }
                out
            }
        }
    }

    /// Monte Carlo passes accumulated in the current image.
    pub fn mc_passes(&self) -> u32 {
        self.mc.as_ref().map_or(0, |m| m.1)
    }
}

impl Session<'_> {
    /// Connects a fetcher's updates (after [`Session::new`], so the fetcher can be told which
    /// vertices the camera sees first).
    pub fn attach(&mut self, updates: Receiver<Update>, counters: Arc<Counters>) {
        self.updates = Some(updates);
        self.counters = Some(counters);
    }

    /// Whether a fetcher is still delivering.
    pub fn streaming(&self) -> bool {
        self.updates.is_some() && !self.streamed.done && self.streamed.failed.is_none()
    }
}
