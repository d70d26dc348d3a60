//! The interactive viewer: a resizable winit window showing a [`Session`]'s frames while its
//! trees stream in, with the light drawn over them (its outline, emitting side and region),
//! a ground grid and axes, and an overlay.
//!
//! Every key and mouse event is taken from winit's event loop as it comes and applied at the
//! next frame ([`input`]): a short press is never lost and a held key acts for as long as it
//! was held, at any frame rate. The key map is [`KEYS_HELP`] (the `H` overlay, `bspvt view
//! --help`). Frames are drawn on this thread by the session's backend (CPU or GPU) and
//! presented ([`present`]): with the GPU backend through a wgpu surface, the frame never
//! leaving the GPU and the overlay drawn on the CPU into a transparent layer put over it
//! there; otherwise through softbuffer. The trees arrive on the fetcher's thread.

mod guides;
mod input;
mod present;
mod save;

pub use input::KEYS_HELP;
pub use save::SceneSource;

use std::borrow::Cow;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use glam::DVec3;
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::platform::x11::EventLoopBuilderExtX11;
use winit::window::{Window, WindowId};

use crate::frame::canvas::{Canvas, composite};
use crate::frame::image::Image;
use crate::gpu::present::Pixels;
use crate::method::METHODS;
use crate::render::renderer::Mode;
use crate::session::{Session, Shown};
use input::Input;
use present::Output;

/// How the window runs.
pub struct ViewerOptions {
    /// Window title.
    pub title: String,
    /// Close after this many frames (scripted runs, tests).
    pub max_frames: Option<u64>,
    /// Bake still running on an embedded service, etc.: shown in the overlay.
    pub note: Option<String>,
    /// Draw the grid, the axes and the light's gizmo (Tab toggles them with the overlay).
    pub guides: bool,
    /// Where F12 writes screenshots.
    pub screenshot_dir: PathBuf,
    /// Where the scene came from (V writes it back with the current camera and light).
    pub source: SceneSource,
    /// Where V writes the view [default: beside the scene file, see [`save`]].
    pub save_view: Option<PathBuf>,
}

/// What a viewer run measured.
pub struct ViewerReport {
    /// Frames drawn.
    pub frames: u64,
    /// From the session's creation to the first frame on screen.
    pub(crate) first_frame: Option<Duration>,
    /// From the session's creation to the first frame with every tree present.
    pub first_full_frame: Option<Duration>,
    /// Mean frames per second over the run.
    pub mean_fps: f64,
    /// Key presses applied (auto-repeats not counted).
    pub key_presses: u64,
    /// The screenshots written.
    pub screenshots: Vec<PathBuf>,
    /// The view files written.
    pub views: Vec<PathBuf>,
    /// Where things stood at the end (method, mode, roughness, light pose, camera, window
    /// size), as JSON.
    pub state: serde_json::Value,
}

/// Height of the roughness bar at the bottom of the window.
const SLIDER_H: usize = 18;
/// Light path speed: cycles per second.
const PATH_SPEED: f64 = 0.05;
/// How long a message (a screenshot written, an error) stays on screen.
const MESSAGE_FOR: Duration = Duration::from_secs(4);

/// Runs the window until it is closed (or `max_frames`). `started`: when the user started
/// the viewer (for the time to the first frame).
pub fn run(session: &mut Session, opts: &ViewerOptions, started: Instant) -> Result<ViewerReport> {
    let event_loop = EventLoop::builder()
        .with_any_thread(true)
        .build()
        .context("cannot open a window (is DISPLAY set? use the headless commands otherwise)")?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let size = (
        session.renderer.gbuffer.width,
        session.renderer.gbuffer.height,
    );
    let mut app = App {
        session,
        opts,
        started,
        window: None,
        output: None,
        input: Input::default(),
        buf: Vec::new(),
        depth: None,
        size,
        pending_size: None,
        show_overlay: true,
        show_help: false,
        fps: 0.0,
        t_last: Instant::now(),
        t_loop: Instant::now(),
        message: None,
        want_screenshot: false,
        report: ViewerReport {
            frames: 0,
            first_frame: None,
            first_full_frame: None,
            mean_fps: 0.0,
            key_presses: 0,
            screenshots: Vec::new(),
            views: Vec::new(),
            state: serde_json::Value::Null,
        },
        error: None,
    };
    event_loop
        .run_app(&mut app)
        .context("the window's event loop failed")?;
    if let Some(e) = app.error.take() {
        return Err(e);
    }
    app.report.mean_fps = app.report.frames as f64 / app.t_loop.elapsed().as_secs_f64().max(1e-9);
    app.report.state = app.state();
    Ok(app.report)
}

struct App<'s, 'a> {
    session: &'s mut Session<'a>,
    opts: &'s ViewerOptions,
    started: Instant,
    window: Option<Arc<Window>>,
    output: Option<Output>,
    input: Input,
    /// The window's pixels, 0RGB; on a GPU surface, the overlay layer (premultiplied
    /// 0xAARRGGBB, transparent where nothing is drawn).
    buf: Vec<u32>,
    /// The frame's depth for the guides (`None`: the camera or the size changed).
    depth: Option<Vec<f32>>,
    size: (u32, u32),
    pending_size: Option<(u32, u32)>,
    show_overlay: bool,
    show_help: bool,
    fps: f64,
    t_last: Instant,
    t_loop: Instant,
    message: Option<(String, Instant)>,
    want_screenshot: bool,
    report: ViewerReport,
    error: Option<anyhow::Error>,
}

impl ApplicationHandler for App<'_, '_> {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        if let Err(e) = self.open(event_loop) {
            self.error = Some(e);
            event_loop.exit();
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let now = Instant::now();
        let h = self.size.1 as f64;
        let on_slider = move |y: f64| y >= h - SLIDER_H as f64;
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(s) => self.pending_size = Some((s.width, s.height)),
            // winit makes up presses for the keys down when the window gains focus (read
            // when it handles the focus, so a key pressed just after counted twice, and its
            // hold began early): a key acts from its own press; releases on focus loss are
            // `release_all`'s.
            WindowEvent::KeyboardInput {
                is_synthetic: true, ..
            } => {}
            WindowEvent::KeyboardInput { event, .. } => {
                if let PhysicalKey::Code(code) = event.physical_key {
                    if code == KeyCode::Escape {
                        if event.state == ElementState::Pressed {
                            event_loop.exit();
                        }
                        return;
                    }
                    self.input.key(code, event.state, event.repeat, now);
                }
            }
            WindowEvent::ModifiersChanged(m) => self.input.shift(m.state().shift_key()),
            WindowEvent::CursorMoved { position, .. } => {
                self.input.cursor_moved(position.x, position.y);
            }
            WindowEvent::MouseInput { state, button, .. } => {
                self.input.button(button, state, on_slider);
            }
            WindowEvent::MouseWheel { delta, .. } => self.input.wheel(delta),
            WindowEvent::Focused(false) => self.input.release_all(now),
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.frame() {
                    self.error = Some(e);
                    event_loop.exit();
                } else if self
                    .opts
                    .max_frames
                    .is_some_and(|m| self.report.frames >= m)
                {
                    event_loop.exit();
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(w) = &self.window {
            w.request_redraw();
        }
    }
}

impl App<'_, '_> {
    fn open(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let attrs = Window::default_attributes()
            .with_title(self.opts.title.clone())
            .with_inner_size(PhysicalSize::new(self.size.0, self.size.1))
            .with_min_inner_size(PhysicalSize::new(64, 64));
        let window = Arc::new(
            event_loop
                .create_window(attrs)
                .context("cannot open a window")?,
        );
        let (gpu, _) = self.session.backend().resolve()?;
        let (output, line) = Output::open(&window, gpu)?;
        println!("{line}");
        self.window = Some(window);
        self.output = Some(output);
        Ok(())
    }

    /// One frame: apply the input, shade, draw the guides and the overlay, present.
    fn frame(&mut self) -> Result<()> {
        let now = Instant::now();
        let dt = now.saturating_duration_since(self.t_last).as_secs_f64();
        self.t_last = now;
        self.session.poll();
        if let Some((w, h)) = self.pending_size.take() {
            let (w, h) = (w.max(16), h.max(16));
            if (w, h) != self.size {
                self.size = (w, h);
                self.session.resize(w, h);
                self.depth = None;
            }
        }
        let f = self.input.take(now);
        self.apply(f, dt);

        let (w, h) = (self.size.0 as usize, self.size.1 as usize);
        let on_gpu = matches!(self.output, Some(Output::Gpu(_)));
        let shown = self.session.frame_to_show(on_gpu);
        // The window's pixels, or (on a GPU surface) a transparent overlay layer.
        self.buf = if on_gpu {
            vec![0; w * h]
        } else {
            read(&shown)?.to_0rgb(1.0)
        };
        self.buf.resize(w * h, 0);
        // A frame left on the GPU gets the lamps in its overlay layer (a CPU frame has them).
        if matches!(shown, Shown::Gpu(_)) {
            self.session.lamp_layer(&mut self.buf);
        }
        // Frames per second on screen: from one frame's start to the next (drawing,
        // presenting and the events between), not the time to submit this one (a GPU
        // frame's work is still queued here).
        let frame_dt = dt.max(1e-6);
        self.fps = if self.fps == 0.0 {
            1.0 / frame_dt
        } else {
            0.9 * self.fps + 0.1 / frame_dt
        };
        if self.show_overlay {
            self.draw_overlay(w, h, on_gpu);
        }
        if std::mem::take(&mut self.want_screenshot) {
            self.screenshot(&shown, on_gpu, w, h);
        }
        match self.output.as_mut() {
            Some(Output::Soft(surface)) => Output::present_soft(surface, &self.buf, w, h)?,
            Some(Output::Gpu(surface)) => {
                let pixels = match &shown {
                    Shown::Gpu(g) => Pixels::Gpu(g),
                    Shown::Cpu(i) => Pixels::Cpu(i),
                };
                let overlay: &[u32] = if pixels.size() == (w as u32, h as u32) {
                    &self.buf
                } else {
                    &[]
                };
                surface.present(pixels, overlay, w as u32, h as u32)?;
            }
            None => {}
        }
        self.report.frames += 1;
        let gpu_frame = on_gpu || matches!(shown, Shown::Gpu(_));
        if self.report.first_frame.is_none() {
            let t = self.on_screen(gpu_frame)?;
            self.report.first_frame = Some(t);
            println!(
                "first frame on screen after {:.0} ms ({:.0} % of the trees)",
                t.as_secs_f64() * 1e3,
                self.session.streamed.fraction() * 100.0
            );
        }
        if self.report.first_full_frame.is_none() && self.session.streamed.complete() {
            let t = self.on_screen(gpu_frame)?;
            self.report.first_full_frame = Some(t);
            println!("every tree on screen after {:.0} ms", t.as_secs_f64() * 1e3);
        }
        Ok(())
    }

    /// F12: the window's pixels as shown (on a GPU surface: the frame read back, tone-mapped
    /// and the overlay layer put over it as the GPU does) into a PNG.
    fn screenshot(&mut self, shown: &Shown, on_gpu: bool, w: usize, h: usize) {
        let pixels = if on_gpu {
            read(shown).map(|img| {
                let mut px = img.to_0rgb(1.0);
                px.resize(w * h, 0);
                composite(&mut px, &self.buf);
                px
            })
        } else {
            Ok(self.buf.clone())
        };
        let n = self.report.screenshots.len() as u64;
        match pixels.and_then(|px| save::screenshot(&self.opts.screenshot_dir, &px, w, h, n)) {
            Ok(p) => {
                println!("screenshot: {}", p.display());
                self.say(format!("screenshot: {}", p.display()));
                self.report.screenshots.push(p);
            }
            Err(e) => {
                eprintln!("screenshot failed: {e:#}");
                self.say(format!("screenshot failed: {e:#}"));
            }
        }
    }

    /// The time since the start at which the frame just presented is on screen. On screen
    /// means drawn: a GPU frame waits for its queue (on a software Vulkan, lavapipe, that is
    /// where a pipeline's shaders compile at their first use: a minute or more on 2 cores
    /// when Mesa's shader cache is cold), so the times printed are the times a user waited.
    fn on_screen(&self, gpu_frame: bool) -> Result<Duration> {
        if gpu_frame {
            crate::gpu::Gpu::shared()?.wait()?;
        }
        Ok(self.started.elapsed())
    }

    fn say(&mut self, m: String) {
        self.message = Some((m, Instant::now()));
    }

    /// Applies one frame's input to the session.
    fn apply(&mut self, f: input::Frame, dt: f64) {
        let scale = scene_scale(self.session);
        let mut moved_light = false;
        let s = &mut *self.session;
        for (key, secs) in f.held {
            let step = 1.5 * secs * scale;
            let pose = &mut s.pose;
            match key {
                KeyCode::KeyA => pose.offset.x -= step,
                KeyCode::KeyD => pose.offset.x += step,
                KeyCode::KeyW => pose.offset.z -= step,
                KeyCode::KeyS => pose.offset.z += step,
                KeyCode::KeyQ => pose.offset.y -= step,
                KeyCode::KeyE => pose.offset.y += step,
                KeyCode::KeyR => pose.yaw += secs,
                KeyCode::KeyF => pose.yaw -= secs,
                KeyCode::KeyT => pose.tilt = (pose.tilt + secs).clamp(-1.4, 1.4),
                KeyCode::KeyG => pose.tilt = (pose.tilt - secs).clamp(-1.4, 1.4),
                KeyCode::Minus => {
                    pose.radiance_scale = (pose.radiance_scale * (-secs).exp()).max(1e-3)
                }
                KeyCode::Equal => pose.radiance_scale = (pose.radiance_scale * secs.exp()).min(1e3),
                // The environment turns about +y (bspvt-env: the trees stay, the sky's pieces
                // move).
                KeyCode::KeyY => s.env_rotation_deg = (s.env_rotation_deg - 45.0 * secs) % 360.0,
                KeyCode::KeyU => s.env_rotation_deg = (s.env_rotation_deg + 45.0 * secs) % 360.0,
                _ => continue,
            }
            moved_light = true;
        }
        if let Some(t) = &mut s.path_t {
            *t = (*t + dt * PATH_SPEED).fract();
            moved_light = true;
        }
        let mut roughness = s.roughness;
        for key in f.pressed {
            self.report.key_presses += 1;
            let s = &mut *self.session;
            match key {
                KeyCode::Digit1
                | KeyCode::Digit2
                | KeyCode::Digit3
                | KeyCode::Digit4
                | KeyCode::Digit5
                | KeyCode::Digit6
                | KeyCode::Digit7
                | KeyCode::Digit8
                | KeyCode::Digit9
                | KeyCode::Digit0 => {
                    let i = match key {
                        KeyCode::Digit0 => 9,
                        _ => key as usize - KeyCode::Digit1 as usize,
                    };
                    if let Some(m) = METHODS.get(i) {
                        s.method = *m;
                    }
                }
                KeyCode::KeyM => {
                    s.mode = match s.mode {
                        Mode::Vertex => Mode::Pixel,
                        Mode::Pixel => Mode::Vertex,
                    }
                }
                KeyCode::KeyP => {
                    s.path_t = match s.path_t {
                        Some(_) => None,
                        None => Some(0.0),
                    }
                }
                KeyCode::KeyL => s.reset_light(),
                KeyCode::KeyN => {
                    let n = s.light_count().max(1);
                    s.select_light((s.selected_light() + 1) % n);
                    let k = s.selected_light();
                    self.say(format!("the keys and mouse move light {k}"));
                }
                KeyCode::KeyC => {
                    s.reset_camera();
                    self.depth = None;
                }
                KeyCode::KeyH => self.show_help = !self.show_help,
                KeyCode::Tab => self.show_overlay = !self.show_overlay,
                KeyCode::KeyO => roughness = None,
                KeyCode::BracketLeft => roughness = Some(roughness.unwrap_or(0.3) * 0.8),
                KeyCode::BracketRight => roughness = Some(roughness.unwrap_or(0.3) * 1.25),
                KeyCode::F12 | KeyCode::PrintScreen => self.want_screenshot = true,
                KeyCode::KeyV => self.save_view(),
                _ => continue,
            }
            self.session.invalidate();
        }
        let s = &mut *self.session;
        let (w, h) = (f64::from(self.size.0), f64::from(self.size.1));
        if let Some(x) = f.slider_x {
            // Roughness on a log scale from 1e-3 to 1.
            let t = (x / w).clamp(0.0, 1.0);
            roughness = Some(10f64.powf(-3.0 + 3.0 * t) as f32);
        }
        let mut orbit = s.orbit;
        let (ox, oy) = f.drag.orbit;
        if (ox, oy) != (0.0, 0.0) {
            orbit.yaw -= ox * 0.01;
            orbit.pitch = (orbit.pitch + oy * 0.01).clamp(-1.5, 1.5);
        }
        let (px, py) = f.drag.pan;
        if (px, py) != (0.0, 0.0) {
            // The target follows the cursor: world units per pixel at the target's depth.
            let per_px =
                2.0 * orbit.distance * (0.5 * f64::from(orbit.fov_y_deg)).to_radians().tan() / h;
            let v = &s.renderer.view;
            orbit.target += (-px * v.right + py * v.up) * per_px;
        }
        if f.wheel != 0.0 {
            orbit.distance = (orbit.distance * 0.9f64.powf(f.wheel)).max(1e-6 * scale);
        }
        if (ox, oy, px, py, f.wheel) != (0.0, 0.0, 0.0, 0.0, 0.0) {
            s.set_camera(orbit);
            self.depth = None;
        }
        let (lx, ly) = f.drag.light;
        if (lx, ly) != (0.0, 0.0) {
            let k = s.orbit.distance * 0.002;
            let (sy, cy) = s.orbit.yaw.sin_cos();
            // Screen right and screen "forward", projected on the ground.
            let right = DVec3::new(cy, 0.0, -sy);
            let fwd = DVec3::new(-sy, 0.0, -cy);
            s.pose.offset += right * lx * k - fwd * ly * k;
            moved_light = true;
        }
        if roughness != s.roughness {
            s.set_roughness(roughness);
        }
        if moved_light {
            let held = s.keep_light_baked();
            s.invalidate();
            if let Some(m) = held {
                self.say(m);
            }
        }
    }

    /// V: the current camera and light into a scene file.
    fn save_view(&mut self) {
        let s = &*self.session;
        let added_ground = save::added_ground(&self.opts.source);
        let r = save::view_file(
            &self.opts.source,
            self.opts.save_view.as_deref(),
            &s.scene().lights,
            added_ground,
            s.camera(),
            s.light().as_ref().map(|l| (s.selected_light(), l)),
        )
        .and_then(|(file, out)| save::write_view(&file, &out).map(|()| out));
        match r {
            Ok(p) => {
                println!("view saved: {}", p.display());
                self.say(format!("view saved: {}", p.display()));
                self.report.views.push(p);
            }
            Err(e) => {
                eprintln!("save view: {e:#}");
                self.say(format!("save view: {e:#}"));
            }
        }
    }

    /// The guides, panels and slider, into the frame or (`layer`) into a transparent layer.
    fn draw_overlay(&mut self, w: usize, h: usize, layer: bool) {
        if self.opts.guides {
            if self.depth.as_ref().is_none_or(|d| d.len() != w * h) {
                self.depth = Some(self.session.depth());
            }
            let light = self.session.light();
            let mut c = Canvas {
                buf: &mut self.buf,
                width: w,
                height: h,
                layer,
            };
            guides::draw(
                &mut c,
                &self.session.renderer.view,
                self.depth.as_deref().unwrap_or(&[]),
                self.session.scene(),
                self.session.selected_light(),
                light.as_ref(),
            );
        }
        let mut lines = overlay_lines(self.session, self.fps, self.opts);
        if let Some((m, at)) = &self.message {
            if at.elapsed() < MESSAGE_FOR {
                lines.push(m.chars().take(w / 8).collect());
            } else {
                self.message = None;
            }
        }
        let s = &*self.session;
        let a = f64::from(s.roughness.unwrap_or(0.3));
        let t = (a.log10() + 3.0) / 3.0;
        let label = match s.roughness {
            Some(a) => format!("roughness α = {a:.3} (drag; [ ] keys; O = scene's)"),
            None => "roughness α: the scene's (drag here or [ ] to override)".to_string(),
        };
        let mut c = Canvas {
            buf: &mut self.buf,
            width: w,
            height: h,
            layer,
        };
        c.panel(4, 4, &lines);
        if self.show_help {
            let help: Vec<String> = KEYS_HELP.lines().map(str::to_string).collect();
            let y = (4 + lines.len() * 10 + 12).min(h.saturating_sub(help.len() * 10 + 8));
            c.panel(4, y, &help);
        }
        c.slider(0, h.saturating_sub(SLIDER_H - 2), w, t, &label);
    }

    /// Where things stand, for the report.
    fn state(&self) -> serde_json::Value {
        let s = &*self.session;
        let mode = match s.effective_mode() {
            Mode::Vertex => "vertex",
            Mode::Pixel => "pixel",
        };
        serde_json::json!({
            "method": s.method.name(),
            "mode": mode,
            "roughness": s.roughness,
            "light_offset": s.pose.offset.to_array(),
            "light_yaw": s.pose.yaw,
            "light_tilt": s.pose.tilt,
            "radiance_scale": s.pose.radiance_scale,
            "path": s.path_t.is_some(),
            "camera_distance": s.orbit.distance,
            "camera_yaw": s.orbit.yaw,
            "camera_pitch": s.orbit.pitch,
            "camera_target": s.orbit.target.to_array(),
            "window": [self.size.0, self.size.1],
            "frames": self.report.frames,
            "key_presses": self.report.key_presses,
            "mean_frame_ms": self.t_loop.elapsed().as_secs_f64() * 1e3
                / self.report.frames.max(1) as f64,
            "overlay": self.show_overlay,
            "help": self.show_help,
        })
    }
}

/// The frame's linear radiance on the CPU (a GPU frame read back, a CPU frame borrowed).
fn read(shown: &Shown) -> Result<Cow<'_, Image>> {
    Ok(match shown {
        Shown::Cpu(img) => Cow::Borrowed(img),
        Shown::Gpu(g) => Cow::Owned(g.read(crate::gpu::Gpu::shared()?)?),
    })
}

/// A quarter of the scene's diagonal: how far the light moves per second of a held key.
fn scene_scale(s: &Session) -> f64 {
    let b = s.scene.mesh.bounds();
    (b.max.as_dvec3() - b.min.as_dvec3()).length().max(1e-6) * 0.25
}

fn overlay_lines(s: &Session, fps: f64, opts: &ViewerOptions) -> Vec<String> {
    let mode = match s.effective_mode() {
        Mode::Vertex => "per vertex",
        Mode::Pixel => "per pixel",
    };
    let mut lines = vec![format!(
        "{:.1} fps   {} - {mode}   {}×{}",
        fps,
        s.method.label(),
        s.renderer.gbuffer.width,
        s.renderer.gbuffer.height
    )];
    lines.extend(bake_lines(&s.streamed));
    if s.passes() > 0 {
        lines.push(format!("{} samples per pixel", s.passes()));
    }
    if let Some(n) = &opts.note {
        lines.push(n.clone());
    }
    let lights = s.light_count();
    if lights > 1 {
        let k = s.selected_light();
        let how = match s.light_motion(k) {
            Some(bspvt_proto::scene::LightMotion::Fixed) | None => "fixed",
            Some(bspvt_proto::scene::LightMotion::Plane) => "moves in its plane",
            Some(bspvt_proto::scene::LightMotion::Region(_)) => "moves in its region",
            Some(bspvt_proto::scene::LightMotion::Turns) => "a sun: turns",
        };
        lines.push(format!(
            "{lights} lights; keys move light {k} ({how}; N next)"
        ));
    }
    if s.method.needs().sky_trees {
        lines.push(format!(
            "sky: {} ({:.0}°, Y/U turn)",
            if s.sky_ready() {
                "through its trees"
            } else if s.sky_baking() {
                "baking its trees, unshadowed"
            } else {
                "unshadowed"
            },
            s.env_rotation_deg
        ));
    }
    lines.push("H keys  1-9,0 method  M mode  F12 shot  V save view".into());
    lines
}

/// The trees here and the service's bake, in words that cannot disagree: once every tree is
/// here the bake is done, whatever the last status said (the status relay stops when the
/// fetcher finishes, and its last report can be older than the last chunk); before that, the
/// service's count of durable vertices and this client's count are both shown, named.
pub(crate) fn bake_lines(t: &crate::stream::trees::StreamedTrees) -> Vec<String> {
    let n = t.vertex_count();
    if t.complete() {
        return vec![format!("trees: all {n} vertices here (bake done)")];
    }
    let mut lines = vec![format!(
        "trees here: {} of {n} vertices ({:.1} %){}",
        t.vertices_present,
        t.fraction() * 100.0,
        if t.failed.is_none() {
            ", streaming"
        } else {
            ""
        }
    )];
    if let Some(st) = &t.status {
        let eta = st
            .eta_s
            .map(|e| format!(", eta {e:.0} s"))
            .unwrap_or_default();
        lines.push(format!(
            "service: {:?}, {} of {} vertices baked ({:.1} %){eta}",
            st.state,
            st.vertices_done,
            st.vertices_total,
            st.progress * 100.0
        ));
    }
    if let Some(e) = &t.failed {
        lines.push(format!(
            "stream: {}",
            e.chars().take(60).collect::<String>()
        ));
    }
    lines
}
