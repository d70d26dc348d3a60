//! One interactive shading session: a scene, its trees as they stream in, a camera, a light the
//! user moves, the method and mode. The viewer, `bspvt animate` and `bspvt demo` all draw their
//! frames through [`Session::frame`], so a headless sequence is what the window shows.

pub mod connect;

use std::sync::Arc;
use std::sync::mpsc::{Receiver, TryRecvError};

use std::collections::HashMap;

use bspvt_proto::Scene;
use bspvt_proto::scene::{Camera, LightMotion};
use glam::{DAffine3, DQuat, DVec3};

use crate::frame::image::Image;
use crate::gpu::frame::GpuImage;
use crate::light::Light;
use crate::method::{FrameInput, FrameMethod, MethodState, SceneData, Settings, registry};
use crate::render::path::LightPath;
use crate::render::renderer::{Mode, Renderer, Trees};
use crate::stream::fetch::{Counters, Update};
use crate::stream::trees::StreamedTrees;

/// Where the sky's trees are.
enum SkyBake {
    NotStarted,
    Baking(Receiver<Result<bspvt_proto::encoding::Bake, String>>),
    Ready(Box<bspvt_proto::encoding::Bake>),
    Failed,
}

/// An orbit camera around a target.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Orbit {
    pub(crate) target: DVec3,
    pub(crate) yaw: f64,
    pub(crate) pitch: f64,
    pub(crate) distance: f64,
    pub(crate) fov_y_deg: f32,
}

impl Orbit {
    pub(crate) fn from_camera(c: &Camera) -> Orbit {
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

    pub(crate) fn camera(&self) -> Camera {
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
            aspect: None,
        }
    }
}

/// The user's pose of the light relative to its rest pose: a translation and a rotation about
/// its centroid, and a radiance scale.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LightPose {
    pub(crate) offset: DVec3,
    pub(crate) yaw: f64,
    pub(crate) tilt: f64,
    pub(crate) radiance_scale: f64,
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

/// A frame to show: linear radiance on the CPU, or left on the GPU by a method that draws
/// there ([`Session::frame_to_show`]).
pub enum Shown {
    /// On the CPU.
    Cpu(Image),
    /// On the GPU.
    Gpu(GpuImage),
}

/// A scene being viewed: what the window, `animate` and `demo` draw through.
pub struct Session<'a> {
    /// The scene (at t = 0 for moving scenes).
    pub(crate) scene: &'a Scene,
    /// The camera's G-buffer and the shading of polygon lights.
    pub renderer: Renderer<'a>,
    /// The trees that have arrived.
    pub streamed: StreamedTrees,
    updates: Option<Receiver<Update>>,
    /// The fetcher's byte and chunk counters.
    pub counters: Option<Arc<Counters>>,
    /// What it draws (from [`crate::method::registry`]).
    pub method: &'static dyn FrameMethod,
    /// Per vertex or per pixel.
    pub mode: Mode,
    /// The camera.
    pub(crate) orbit: Orbit,
    /// Every light at rest, its default path and where its bake lets it go (empty: a scene
    /// lit by its environment alone).
    rest: Vec<(Light, LightPath, LightMotion)>,
    /// The light the mouse and keys move (an index into the scene's lights).
    selected: usize,
    /// The user's pose of the selected light.
    pub(crate) pose: LightPose,
    /// The poses of the others (the selected one's is `pose`).
    poses: Vec<LightPose>,
    /// Position on the light's default path in [0, 1) (`None`: the user's pose alone); also
    /// the cycle time of a moving scene for the run-time methods.
    pub path_t: Option<f64>,
    /// The roughness override (`None`: the materials').
    pub(crate) roughness: Option<f32>,
    data: SceneData<'a>,
    /// What the methods read; the environment map defaults to the scene's, else the shared
    /// test map.
    settings: Settings,
    /// Run-time rotation of the environment about +y, degrees (the sky methods that turn it
    /// per frame: `bspvt-env`).
    pub env_rotation_deg: f64,
    /// The sky's trees (`bspvt-env`), baked in the background on first use.
    sky: SkyBake,
    /// Where sky bakes are kept (by the sky scene's hash), shared with `bspvt render --cache`.
    pub sky_cache: std::path::PathBuf,
    /// Each method's state, prepared on first use (`Err`: preparing failed; its frames fall
    /// back to unshadowed LTC with a warning).
    states: HashMap<&'static str, Result<Box<dyn MethodState>, String>>,
}

/// A session that ends stops its fetcher: the service may go away next (an embedded one
/// stops with the process), and a fetcher told to stop ends without calling the broken stream
/// an interruption to retry.
impl Drop for Session<'_> {
    fn drop(&mut self) {
        if let Some(c) = &self.counters {
            c.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    }
}

impl<'a> Session<'a> {
    /// A session on `scene` at `width`×`height`, drawing BSPVT per vertex.
    pub(crate) fn new(
        scene: &'a Scene,
        width: u32,
        height: u32,
        streamed: StreamedTrees,
        updates: Option<Receiver<Update>>,
        counters: Option<Arc<Counters>>,
    ) -> anyhow::Result<Session<'a>> {
        for w in &scene.warnings {
            tracing::warn!("{w}");
        }
        for k in scene.lights_facing_away() {
            tracing::warn!(
                "light {k} faces away from every vertex of the scene: it lights nothing (wind \
                 its vertices the other way round, or make it two_sided)"
            );
        }
        let rest: Vec<(Light, LightPath, LightMotion)> = crate::light::scene_lights(scene)?
            .into_iter()
            .map(|(r, motion)| (r.clone(), LightPath::new(motion, r), motion))
            .collect();
        // A scene lit by its environment alone opens on the sky through the trees.
        let method = if rest.is_empty() {
            "bspvt-env"
        } else {
            "bspvt"
        };
        let poses = vec![LightPose::default(); rest.len()];
        Ok(Session {
            scene,
            renderer: Renderer::new(scene, width, height),
            streamed,
            updates,
            counters,
            method: registry::lookup(method)?,
            mode: Mode::Vertex,
            orbit: Orbit::from_camera(&scene.camera),
            rest,
            selected: 0,
            pose: LightPose::default(),
            poses,
            path_t: None,
            roughness: None,
            data: SceneData::new(scene),
            // Interactive: progressive Monte Carlo, one sample a pixel a frame elsewhere.
            settings: Settings {
                progressive: true,
                spp: 1,
                env: crate::method::EnvOptions::default().for_scene(scene),
                ..Settings::default()
            },
            states: HashMap::new(),
            env_rotation_deg: 0.0,
            sky: SkyBake::NotStarted,
            sky_cache: std::path::PathBuf::from("out/cache/bakes"),
        })
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
            self.invalidate();
        }
        changed
    }

    /// Blocks until the fetcher has delivered everything (or given up).
    pub fn wait_complete(&mut self) {
        while self.streaming() {
            match self.updates.as_ref().map(Receiver::recv) {
                Some(Ok(u)) => {
                    if self.streamed.apply(u) {
                        self.invalidate();
                    }
                }
                _ => self.updates = None,
            }
        }
    }

    /// Something the image depends on changed: restart progressive rendering.
    pub fn invalidate(&mut self) {
        for s in self.states.values_mut().flatten() {
            s.invalidate();
        }
    }

    pub(crate) fn set_camera(&mut self, orbit: Orbit) {
        self.orbit = orbit;
        self.renderer.set_camera(&orbit.camera());
        self.invalidate();
    }

    /// Draws at `width`×`height` from now on (a resized window): the G-buffer is drawn again
    /// and the methods' states, sized to the old image, are prepared again on the next frame.
    pub fn resize(&mut self, width: u32, height: u32) {
        let (width, height) = (width.max(1), height.max(1));
        if (width, height) == (self.renderer.gbuffer.width, self.renderer.gbuffer.height) {
            return;
        }
        self.renderer = Renderer::with_camera(self.scene, &self.orbit.camera(), width, height);
        self.renderer.set_roughness(self.roughness);
        self.states.clear();
    }

    /// The camera back to the scene's.
    pub fn reset_camera(&mut self) {
        self.set_camera(Orbit::from_camera(&self.scene.camera));
    }

    /// The light back to its rest pose (off its path, radiance as in the scene).
    pub fn reset_light(&mut self) {
        self.pose = LightPose::default();
        self.path_t = None;
        self.invalidate();
    }

    /// The light the mouse and keys move.
    pub fn selected_light(&self) -> usize {
        self.selected
    }

    /// How many lights the scene has (polygons, points and spots, suns).
    pub fn light_count(&self) -> usize {
        self.rest.len()
    }

    /// Where light `k`'s bake lets it go.
    pub fn light_motion(&self, k: usize) -> Option<LightMotion> {
        self.rest.get(k).map(|r| r.2)
    }

    /// Makes light `k` the one the mouse and keys move (each light keeps its own pose).
    pub fn select_light(&mut self, k: usize) {
        if k >= self.rest.len() || k == self.selected {
            return;
        }
        if let Some(p) = self.poses.get_mut(self.selected) {
            *p = self.pose;
        }
        self.selected = k;
        self.pose = self.poses[k];
    }

    /// Keeps the selected light where its bake holds (docs/bake.md, "Where a ray ends"), and
    /// says what it held back, if anything: a fixed lamp does not move (its radiance still
    /// scales); a light that moves in its plane keeps its offset in that plane; a light with
    /// a region is shifted back inside it.
    pub fn keep_light_baked(&mut self) -> Option<String> {
        let (rest, _, motion) = self.rest.get(self.selected)?;
        match *motion {
            LightMotion::Fixed => {
                let moved = self.pose.offset != DVec3::ZERO
                    || self.pose.yaw != 0.0
                    || self.pose.tilt != 0.0;
                if !moved {
                    return None;
                }
                self.pose = LightPose {
                    radiance_scale: self.pose.radiance_scale,
                    ..LightPose::default()
                };
                self.invalidate();
                Some(format!(
                    "light {} is fixed: its shadows were baked where it is (give it a region \
                     or moves_in_plane in the scene file to move it)",
                    self.selected
                ))
            }
            LightMotion::Plane => {
                let n = rest.normal;
                let off = self.pose.offset.dot(n);
                if off == 0.0 || !off.is_finite() {
                    return None;
                }
                self.pose.offset -= off * n;
                self.invalidate();
                Some(format!(
                    "light {} moves in its plane (as baked): kept in it",
                    self.selected
                ))
            }
            LightMotion::Region(region) => self
                .keep_light_in_region(region)
                .then(|| format!("light {} kept inside its region (as baked)", self.selected)),
            // A sun only turns (every direction is baked): moving it does nothing.
            LightMotion::Turns => {
                if self.pose.offset == DVec3::ZERO {
                    return None;
                }
                self.pose.offset = DVec3::ZERO;
                self.invalidate();
                Some(format!(
                    "light {} is a sun: it turns (every direction is baked), it does not move",
                    self.selected
                ))
            }
        }
    }

    /// Moves the selected light back inside `region` (the bake treats directions that cannot
    /// reach the region as "don't care": a light outside it would be shadowed wrongly); returns
    /// whether it moved. The light's box is shifted, axis by axis, the least that puts it
    /// inside; a light wider than the region is centred on it.
    fn keep_light_in_region(&mut self, region: bspvt_proto::scene::Region) -> bool {
        let Some(light) = self.light() else {
            return false;
        };
        let (rmin, rmax) = (
            DVec3::from(region.min.map(f64::from)),
            DVec3::from(region.max.map(f64::from)),
        );
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for v in &light.vertices {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
        let mut shift = DVec3::ZERO;
        for k in 0..3 {
            shift[k] = if hi[k] - lo[k] > rmax[k] - rmin[k] {
                0.5 * ((rmin[k] + rmax[k]) - (lo[k] + hi[k]))
            } else if lo[k] < rmin[k] {
                rmin[k] - lo[k]
            } else if hi[k] > rmax[k] {
                rmax[k] - hi[k]
            } else {
                0.0
            };
        }
        if shift != DVec3::ZERO && shift.is_finite() {
            self.pose.offset += shift;
            self.invalidate();
            return true;
        }
        false
    }

    /// The camera the frames are drawn from.
    pub fn camera(&self) -> Camera {
        self.orbit.camera()
    }

    /// The scene being viewed.
    pub fn scene(&self) -> &Scene {
        self.scene
    }

    /// Camera depth (along the view direction) of the surface seen through each pixel,
    /// `f32::INFINITY` where the ray hits nothing: what the viewer's guides are hidden behind.
    pub fn depth(&self) -> Vec<f32> {
        use rayon::prelude::*;
        let (g, view, mesh) = (
            &self.renderer.gbuffer,
            &self.renderer.view,
            &self.scene.mesh,
        );
        (0..g.tri.len())
            .into_par_iter()
            .map(|i| match g.surface(mesh, view, i) {
                Some(s) => view.to_camera(s.position).z as f32,
                None => f32::INFINITY,
            })
            .collect()
    }

    /// Overrides every material's GGX α (`None`: the materials' own).
    pub fn set_roughness(&mut self, alpha: Option<f32>) {
        self.roughness = alpha.map(|a| a.clamp(1e-3, 1.0));
        self.renderer.set_roughness(self.roughness);
        self.invalidate();
    }

    /// Who draws the methods that have a GPU path.
    pub fn backend(&self) -> crate::gpu::Backend {
        self.settings.backend
    }

    /// Who draws the methods that have a GPU path (resolve `auto` first:
    /// [`crate::gpu::Backend::resolve`]); their states are prepared again.
    pub fn set_backend(&mut self, backend: crate::gpu::Backend) {
        self.settings.backend = backend;
        self.states
            .retain(|name, _| !registry::find(name).is_some_and(|m| m.gpu()));
    }

    /// The environment light the methods use (before the first frame of a method that reads
    /// it; a method already prepared keeps the map it loaded).
    pub fn set_env(&mut self, env: crate::method::EnvOptions) {
        self.settings.env = env;
        self.states
            .retain(|name, _| !registry::find(name).is_some_and(|m| m.needs().env_map));
    }

    /// Light `k` for the current frame: on its path (`path_t`), then in its pose.
    fn posed(&self, k: usize) -> Option<Light> {
        let (rest, path, _) = self.rest.get(k)?;
        let pose = if k == self.selected {
            &self.pose
        } else {
            self.poses.get(k)?
        };
        let base = match self.path_t {
            Some(t) => path.at(t),
            None => rest.clone(),
        };
        let c = base.centroid();
        let m = DAffine3::from_translation(c + pose.offset)
            * DAffine3::from_quat(
                DQuat::from_rotation_y(pose.yaw) * DQuat::from_rotation_x(pose.tilt),
            )
            * DAffine3::from_translation(-c);
        let mut l = base.transformed(&m);
        l.radiance *= pose.radiance_scale;
        Some(l)
    }

    /// The selected light for the current frame (`None`: the scene has none).
    pub fn light(&self) -> Option<Light> {
        self.posed(self.selected)
    }

    /// Every light for the current frame.
    pub fn lights(&self) -> Vec<Light> {
        (0..self.rest.len()).filter_map(|k| self.posed(k)).collect()
    }

    /// The sky's trees so far: starts their bake on first call (in the background, cached in
    /// [`Self::sky_cache`]), then picks the result up when it is ready.
    fn sky_trees(&mut self) -> Option<&bspvt_proto::encoding::Bake> {
        if matches!(self.sky, SkyBake::NotStarted) {
            let (tx, rx) = std::sync::mpsc::channel();
            let scene = self.scene.clone();
            let cache = self.sky_cache.clone();
            std::thread::spawn(move || {
                let r = crate::method::trees::cached_sky_bake(&scene, &cache, &|_, _| {})
                    .map(|(_, bake)| bake)
                    .map_err(|e| format!("{e:#}"));
                let _ = tx.send(r);
            });
            self.sky = SkyBake::Baking(rx);
        }
        if let SkyBake::Baking(rx) = &self.sky {
            match rx.try_recv() {
                Ok(Ok(b)) => {
                    self.sky = SkyBake::Ready(Box::new(b));
                    self.invalidate();
                }
                Ok(Err(e)) => {
                    tracing::warn!("the sky's bake failed: {e}; the sky stays unshadowed");
                    self.sky = SkyBake::Failed;
                }
                Err(TryRecvError::Empty) => {}
                Err(TryRecvError::Disconnected) => self.sky = SkyBake::Failed,
            }
        }
        match &self.sky {
            SkyBake::Ready(b) => Some(b),
            _ => None,
        }
    }

    /// Blocks until the sky's trees are baked (or their bake failed); starts it if needed.
    pub fn wait_sky(&mut self) {
        self.sky_trees();
        while let SkyBake::Baking(rx) = &self.sky {
            let next = match rx.recv() {
                Ok(Ok(b)) => SkyBake::Ready(Box::new(b)),
                Ok(Err(e)) => {
                    tracing::warn!("the sky's bake failed: {e}; the sky stays unshadowed");
                    SkyBake::Failed
                }
                Err(_) => SkyBake::Failed,
            };
            self.sky = next;
            self.invalidate();
        }
    }

    /// True once the sky's trees are here.
    pub fn sky_ready(&self) -> bool {
        matches!(self.sky, SkyBake::Ready(_))
    }

    /// True while the sky's trees are being baked.
    pub fn sky_baking(&self) -> bool {
        matches!(self.sky, SkyBake::Baking(_))
    }

    /// Vertices the camera sees (what the fetcher should bring first).
    pub fn visible_vertices(&self) -> &[u32] {
        &self.renderer.visible_vertices
    }

    /// Draws one frame with the current method; a method that cannot draw (its preparation
    /// or frame failed) is replaced by unshadowed LTC, with a warning.
    pub fn frame(&mut self) -> Image {
        match self.frame_to_show(false) {
            Shown::Cpu(image) => image,
            // Not asked for; read back all the same.
            Shown::Gpu(image) => crate::gpu::Gpu::shared()
                .and_then(|gpu| image.read(gpu))
                .unwrap_or_else(|e| {
                    tracing::warn!("reading the GPU's frame back: {e:#}");
                    Image::new(self.renderer.gbuffer.width, self.renderer.gbuffer.height)
                }),
        }
    }

    /// [`Session::frame`] for a window that presents from the GPU (`on_gpu`): a method that
    /// draws on the GPU leaves its frame there.
    pub fn frame_to_show(&mut self, on_gpu: bool) -> Shown {
        let lights = self.lights();
        let m = self.method;
        if m.needs().sky_trees_for(self.scene) {
            self.sky_trees();
        }
        let state = self.states.entry(m.name()).or_insert_with(|| {
            m.prepare(&self.data, &self.settings)
                .map_err(|e| format!("{e:#}"))
        });
        let trees = self.streamed.view();
        let sky = match &self.sky {
            SkyBake::Ready(b) => Some(Trees::full(&b.trees, b.header.codec())),
            _ => None,
        };
        let result = match state {
            Ok(s) => s
                .frame(&FrameInput {
                    scene: &self.data,
                    renderer: &self.renderer,
                    lights: &lights,
                    trees: trees.as_ref(),
                    sky_trees: sky.as_ref(),
                    env_rotation_deg: self.env_rotation_deg,
                    index: 0,
                    time: self.path_t.unwrap_or(0.0) as f32,
                    mode: self.mode,
                    on_gpu,
                })
                .map_err(|e| format!("{e:#}")),
            Err(e) => Err(e.clone()),
        };
        let mut image = match result {
            Ok(f) => match f.gpu {
                // The window draws the lamps into its overlay layer ([`Session::lamp_layer`]).
                Some(g) => return Shown::Gpu(g),
                None => f.image,
            },
            Err(e) if !lights.is_empty() => {
                tracing::warn!("{}: {e}; drawing unshadowed LTC", m.name());
                self.renderer.ltc(&lights, Mode::Pixel).0
            }
            Err(e) => {
                tracing::warn!("{}: {e}", m.name());
                Image::new(self.renderer.gbuffer.width, self.renderer.gbuffer.height)
            }
        };
        self.renderer.draw_emitters(&mut image, &lights);
        Shown::Cpu(image)
    }

    /// The lamps as the camera sees them, into a window's overlay layer over a frame left on
    /// the GPU (premultiplied 0xAARRGGBB, opaque where a lamp is, tone-mapped as the frame is
    /// at exposure 1: [`Image::to_0rgb`]); the pixels without a lamp are left as they are.
    pub fn lamp_layer(&self, layer: &mut [u32]) {
        let lights = self.lights();
        if lights.is_empty() {
            return;
        }
        let e = self.renderer.emitters(&lights);
        if layer.len() != e.len() || e.iter().all(Option::is_none) {
            return;
        }
        let (w, h) = (self.renderer.gbuffer.width, self.renderer.gbuffer.height);
        let mut img = Image::new(w, h);
        for (p, c) in img.pixels.iter_mut().zip(&e) {
            *p = c.unwrap_or_default();
        }
        for ((l, c), x) in layer.iter_mut().zip(&e).zip(img.to_0rgb(1.0)) {
            if c.is_some() {
                *l = 0xff00_0000 | x;
            }
        }
    }

    /// Passes accumulated in the current image by a progressive method (Monte Carlo).
    pub(crate) fn passes(&self) -> u32 {
        match self.states.get(self.method.name()) {
            Some(Ok(s)) => s.passes(),
            _ => 0,
        }
    }

    /// The mode the current method shades in.
    pub fn effective_mode(&self) -> Mode {
        self.method.fixed_mode().unwrap_or(self.mode)
    }
}

impl Session<'_> {
    /// Connects a fetcher's updates (after [`Session::new`], so the fetcher can be told which
    /// vertices the camera sees first).
    pub(crate) fn attach(&mut self, updates: Receiver<Update>, counters: Arc<Counters>) {
        self.updates = Some(updates);
        self.counters = Some(counters);
    }

    /// Whether a fetcher is still delivering.
    pub fn streaming(&self) -> bool {
        self.updates.is_some() && !self.streamed.done && self.streamed.failed.is_none()
    }
}
