//! The interactive viewer: a real window (X11, software framebuffer via `minifb`) showing a
//! [`Session`]'s frames while its trees stream in.
//!
//! Mouse: left-drag orbits, wheel zooms, right-drag moves the light; dragging on the bottom bar
//! sets the roughness. Keys: W/A/S/D and Q/E move the light, R/F turn it, T/G tilt it, P runs it
//! along its path, -/= change its radiance, 1–9 pick the first nine methods of the registry
//! (BSPVT, LTC, Monte Carlo, RT penumbra, PCSS, PCF, VSM, SG, MC environment), M switches
//! per-vertex / per-pixel, [ and ] change the roughness (O: the scene's), H hides the overlay,
//! Esc quits. Frames are drawn on this thread; the trees arrive on the fetcher's thread, so the
//! window stays responsive while data streams.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use glam::DVec3;
use minifb::{Key, KeyRepeat, MouseButton, MouseMode, Window, WindowOptions};

use crate::frame::canvas::Canvas;
use crate::method::METHODS;
use crate::render::renderer::Mode;
use crate::session::Session;

/// How the window runs.
pub struct ViewerOptions {
    /// Window title.
    pub title: String,
    /// Close after this many frames (scripted runs, tests).
    pub max_frames: Option<u64>,
    /// Bake still running on an embedded service, etc.: shown in the overlay.
    pub note: Option<String>,
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
}

const SLIDER_H: usize = 18;

/// Runs the window until it is closed (or `max_frames`). `started`: when the user started
/// the viewer (for the time to the first frame).
pub fn run(session: &mut Session, opts: &ViewerOptions, started: Instant) -> Result<ViewerReport> {
    let (w, h) = (
        session.renderer.gbuffer.width as usize,
        session.renderer.gbuffer.height as usize,
    );
    let mut window = Window::new(&opts.title, w, h, WindowOptions::default())
        .context("cannot open a window (is DISPLAY set? use the headless commands otherwise)")?;
    window.set_target_fps(0);
    let mut buf = vec![0u32; w * h];
    let mut report = ViewerReport {
        frames: 0,
        first_frame: None,
        first_full_frame: None,
        mean_fps: 0.0,
    };
    let mut last_mouse: Option<(f32, f32)> = None;
    let mut show_overlay = true;
    let mut fps = 0.0f64;
    let mut t_last = Instant::now();
    let t_loop = Instant::now();
    let path_speed = 0.05; // path cycles per second
    while window.is_open() && !window.is_key_down(Key::Escape) {
        session.poll();
        let dt = t_last.elapsed().as_secs_f64();
        t_last = Instant::now();
        // --- input ---
        let mut moved_light = false;
        let step = 1.5 * dt * scene_scale(session);
        let pose = &mut session.pose;
        for (k, d) in [
            (Key::A, DVec3::NEG_X),
            (Key::D, DVec3::X),
            (Key::W, DVec3::NEG_Z),
            (Key::S, DVec3::Z),
            (Key::Q, DVec3::NEG_Y),
            (Key::E, DVec3::Y),
        ] {
            if window.is_key_down(k) {
                pose.offset += d * step;
                moved_light = true;
            }
        }
        for (k, which, s) in [
            (Key::R, 0, 1.0),
            (Key::F, 0, -1.0),
            (Key::T, 1, 1.0),
            (Key::G, 1, -1.0),
        ] {
            if window.is_key_down(k) {
                if which == 0 {
                    pose.yaw += s * dt;
                } else {
                    pose.tilt = (pose.tilt + s * dt).clamp(-1.4, 1.4);
                }
                moved_light = true;
            }
        }
        if window.is_key_down(Key::Minus) {
            pose.radiance_scale = (pose.radiance_scale * (1.0 - dt)).max(1e-3);
            moved_light = true;
        }
        if window.is_key_down(Key::Equal) {
            pose.radiance_scale = (pose.radiance_scale * (1.0 + dt)).min(1e3);
            moved_light = true;
        }
        // The environment turns about +y (bspvt-env: the trees stay, the sky's pieces move).
        for (k, s) in [(Key::Y, -1.0), (Key::U, 1.0)] {
            if window.is_key_down(k) {
                session.env_rotation_deg = (session.env_rotation_deg + s * 45.0 * dt) % 360.0;
                moved_light = true;
            }
        }
        if let Some(t) = &mut session.path_t {
            *t = (*t + dt * path_speed).fract();
            moved_light = true;
        }
        let mut roughness = session.roughness;
        for key in window.get_keys_pressed(KeyRepeat::No) {
            match key {
                Key::Key1
                | Key::Key2
                | Key::Key3
                | Key::Key4
                | Key::Key5
                | Key::Key6
                | Key::Key7
                | Key::Key8
                | Key::Key9
                | Key::Key0 => {
                    // 1–9 pick the first nine methods, 0 the tenth.
                    let i = match key {
                        Key::Key0 => 9,
                        _ => key as usize - Key::Key1 as usize,
                    };
                    if let Some(m) = METHODS.get(i) {
                        session.method = *m;
                    }
                }
                Key::M => {
                    session.mode = match session.mode {
                        Mode::Vertex => Mode::Pixel,
                        Mode::Pixel => Mode::Vertex,
                    }
                }
                Key::P => {
                    session.path_t = match session.path_t {
                        Some(_) => None,
                        None => Some(0.0),
                    }
                }
                Key::H => show_overlay = !show_overlay,
                Key::O => roughness = None,
                Key::LeftBracket => roughness = Some(roughness.unwrap_or(0.3) * 0.8),
                Key::RightBracket => roughness = Some(roughness.unwrap_or(0.3) * 1.25),
                _ => {}
            }
            session.invalidate();
        }
        let mouse = window.get_mouse_pos(MouseMode::Clamp);
        let left = window.get_mouse_down(MouseButton::Left);
        let right = window.get_mouse_down(MouseButton::Right);
        if let Some((mx, my)) = mouse {
            let on_slider = my as usize >= h - SLIDER_H;
            if left && on_slider {
                // Roughness on a log scale from 1e-3 to 1.
                let t = f64::from(mx) / w as f64;
                roughness = Some(10f64.powf(-3.0 + 3.0 * t.clamp(0.0, 1.0)) as f32);
            } else if let Some((px, py)) = last_mouse {
                let (dx, dy) = (f64::from(mx - px), f64::from(my - py));
                if left && (dx != 0.0 || dy != 0.0) {
                    let mut o = session.orbit;
                    o.yaw -= dx * 0.01;
                    o.pitch = (o.pitch + dy * 0.01).clamp(-1.5, 1.5);
                    session.set_camera(o);
                }
                if right && (dx != 0.0 || dy != 0.0) {
                    let s = session.orbit.distance * 0.002;
                    let (sy, cy) = session.orbit.yaw.sin_cos();
                    // Screen right and screen "forward" projected on the ground.
                    let right_v = DVec3::new(cy, 0.0, -sy);
                    let fwd = DVec3::new(-sy, 0.0, -cy);
                    session.pose.offset += right_v * dx * s - fwd * dy * s;
                    moved_light = true;
                }
            }
            last_mouse = (left || right).then_some((mx, my));
        }
        if let Some((_, sy)) = window.get_scroll_wheel()
            && sy != 0.0
        {
            let mut o = session.orbit;
            o.distance *= 0.9f64.powf(f64::from(sy));
            session.set_camera(o);
        }
        if roughness != session.roughness {
            session.set_roughness(roughness);
        }
        if moved_light {
            session.invalidate();
        }
        // --- draw ---
        let img = session.frame();
        let rgb = img.to_srgb8(1.0);
        for (o, p) in buf.iter_mut().zip(rgb.pixels()) {
            *o = (u32::from(p.0[0]) << 16) | (u32::from(p.0[1]) << 8) | u32::from(p.0[2]);
        }
        let frame_dt = t_last.elapsed().as_secs_f64().max(1e-6);
        fps = if fps == 0.0 {
            1.0 / frame_dt
        } else {
            0.9 * fps + 0.1 / frame_dt
        };
        if show_overlay {
            let mut c = Canvas {
                buf: &mut buf,
                width: w,
                height: h,
            };
            c.panel(4, 4, &overlay_lines(session, fps, opts));
            let a = f64::from(session.roughness.unwrap_or(0.3));
            let t = (a.log10() + 3.0) / 3.0;
            let label = match session.roughness {
                Some(a) => format!("roughness a = {a:.3} (drag; [ ] keys; O = scene's)"),
                None => "roughness: the scene's (drag here or [ ] to override)".to_string(),
            };
            c.slider(0, h - SLIDER_H + 2, w, t, &label);
        }
        window
            .update_with_buffer(&buf, w, h)
            .context("cannot draw into the window")?;
        report.frames += 1;
        if report.first_frame.is_none() {
            report.first_frame = Some(started.elapsed());
            println!(
                "first frame on screen after {:.0} ms ({:.0} % of the trees)",
                started.elapsed().as_secs_f64() * 1e3,
                session.streamed.fraction() * 100.0
            );
        }
        if report.first_full_frame.is_none() && session.streamed.complete() {
            report.first_full_frame = Some(started.elapsed());
        }
        if opts.max_frames.is_some_and(|m| report.frames >= m) {
            break;
        }
    }
    report.mean_fps = report.frames as f64 / t_loop.elapsed().as_secs_f64().max(1e-9);
    Ok(report)
}

fn scene_scale(s: &Session) -> f64 {
    let b = s.scene.mesh.bounds();
    (b.max.as_dvec3() - b.min.as_dvec3()).length().max(1e-6) * 0.25
}

fn overlay_lines(s: &Session, fps: f64, opts: &ViewerOptions) -> Vec<String> {
    let mode = match s.effective_mode() {
        Mode::Vertex => "per vertex",
        Mode::Pixel => "per pixel",
    };
    let mut lines = vec![
        format!("{:.1} fps   {} - {mode}", fps, s.method.label()),
        format!(
            "trees: {:.1} % of {} vertices{}",
            s.streamed.fraction() * 100.0,
            s.streamed.vertex_count(),
            if s.streamed.complete() {
                ""
            } else {
                " (streaming)"
            }
        ),
    ];
    if let Some(st) = &s.streamed.status {
        let eta = st
            .eta_s
            .map(|e| format!(", eta {e:.0} s"))
            .unwrap_or_default();
        lines.push(format!(
            "bake: {:?} {:.1} %{eta}",
            st.state,
            st.progress * 100.0
        ));
    }
    if let Some(e) = &s.streamed.failed {
        lines.push(format!(
            "stream: {}",
            e.chars().take(60).collect::<String>()
        ));
    }
    if s.passes() > 0 {
        lines.push(format!("{} samples per pixel", s.passes()));
    }
    if let Some(n) = &opts.note {
        lines.push(n.clone());
    }
    if s.method.needs().sky_trees {
        lines.push(format!(
            "sky: {} ({:.0} deg, Y/U turn)",
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
    lines.push("1-9,0 method  M mode  WASDQE RF TG light  Y/U sky  P path  H hide".into());
    lines
}
