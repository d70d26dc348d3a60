//! The viewer's input: every key and mouse event winit delivers, kept until the next frame so
//! none is lost at a low frame rate. A held key acts for exactly as long as it was held (press
//! to release, measured on event times), a short press acts once, mouse motion is summed.

use std::collections::HashMap;
use std::time::Instant;

use winit::event::{ElementState, MouseButton, MouseScrollDelta};
use winit::keyboard::KeyCode;

/// The key map, one line each: the `H` overlay and `bspvt view --help` print this text.
pub const KEYS_HELP: &str = "\
Left-drag      orbit
Middle-drag    pan (or Shift+left-drag)
Wheel          zoom
Right-drag     move the light
Bottom bar     drag: roughness α
W A S D  Q E   move the light (-z -x +z +x, down, up)
R F  T G       turn / tilt the light
- =            light radiance ÷ / × (held)
P   L          light along its path / back to rest
N              next light (keys and mouse move it)
Y U            turn the environment (sky methods)
1-9, 0         method, in the registry's order
M              per vertex / per pixel
[ ]  O         roughness α ×0.8 / ×1.25 / the scene's
C              camera back to the scene's
F12            screenshot (PNG)
V              save view (camera, light) to a scene file
Tab            hide/show overlay and guides
H              this help
Esc            quit";

/// Keys whose effect lasts while they are held.
pub(crate) const HELD: [KeyCode; 14] = [
    KeyCode::KeyW,
    KeyCode::KeyA,
    KeyCode::KeyS,
    KeyCode::KeyD,
    KeyCode::KeyQ,
    KeyCode::KeyE,
    KeyCode::KeyR,
    KeyCode::KeyF,
    KeyCode::KeyT,
    KeyCode::KeyG,
    KeyCode::Minus,
    KeyCode::Equal,
    KeyCode::KeyY,
    KeyCode::KeyU,
];

/// Mouse motion while a button was down, in pixels, since the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Drag {
    pub(crate) orbit: (f64, f64),
    pub(crate) pan: (f64, f64),
    pub(crate) light: (f64, f64),
}

/// Everything that happened since the last frame.
#[derive(Default)]
pub(crate) struct Input {
    /// Held keys: when their unaccounted time began.
    down: HashMap<KeyCode, Instant>,
    /// Seconds each held key was down since the last frame (released ones included).
    held_for: HashMap<KeyCode, f64>,
    /// Presses (not auto-repeats) since the last frame, in order.
    pressed: Vec<KeyCode>,
    cursor: Option<(f64, f64)>,
    left: bool,
    middle: bool,
    right: bool,
    shift: bool,
    drag: Drag,
    /// Wheel notches (positive: towards the screen).
    wheel: f64,
    /// Left clicks and drags on the roughness bar: the cursor's last x there.
    slider_x: Option<f64>,
}

/// What a frame applies.
pub(crate) struct Frame {
    pub(crate) held: Vec<(KeyCode, f64)>,
    pub(crate) pressed: Vec<KeyCode>,
    pub(crate) drag: Drag,
    pub(crate) wheel: f64,
    pub(crate) slider_x: Option<f64>,
}

impl Input {
    pub(crate) fn key(&mut self, code: KeyCode, state: ElementState, repeat: bool, at: Instant) {
        match state {
            ElementState::Pressed => {
                if !repeat {
                    self.pressed.push(code);
                }
                if HELD.contains(&code) {
                    self.down.entry(code).or_insert(at);
                }
            }
            ElementState::Released => {
                if let Some(t0) = self.down.remove(&code) {
                    *self.held_for.entry(code).or_default() +=
                        at.saturating_duration_since(t0).as_secs_f64();
                }
            }
        }
    }

    /// The window lost the keyboard: held keys end now (no release will come).
    pub(crate) fn release_all(&mut self, at: Instant) {
        for (code, t0) in self.down.drain() {
            *self.held_for.entry(code).or_default() +=
                at.saturating_duration_since(t0).as_secs_f64();
        }
        self.left = false;
        self.middle = false;
        self.right = false;
    }

    pub(crate) fn shift(&mut self, on: bool) {
        self.shift = on;
    }

    pub(crate) fn cursor_moved(&mut self, x: f64, y: f64) {
        if let Some((px, py)) = self.cursor {
            let d = (x - px, y - py);
            let add = |a: &mut (f64, f64)| {
                a.0 += d.0;
                a.1 += d.1;
            };
            if self.slider_x.is_some() && self.left {
                self.slider_x = Some(x);
            } else if self.middle || (self.left && self.shift) {
                add(&mut self.drag.pan);
            } else if self.left {
                add(&mut self.drag.orbit);
            }
            if self.right {
                add(&mut self.drag.light);
            }
        }
        self.cursor = Some((x, y));
    }

    /// `on_slider`: whether a y coordinate is on the roughness bar.
    pub(crate) fn button(
        &mut self,
        button: MouseButton,
        state: ElementState,
        on_slider: impl Fn(f64) -> bool,
    ) {
        let down = state == ElementState::Pressed;
        match button {
            MouseButton::Left => {
                self.left = down;
                if down
                    && let Some((x, y)) = self.cursor
                    && on_slider(y)
                {
                    self.slider_x = Some(x);
                }
            }
            MouseButton::Middle => self.middle = down,
            MouseButton::Right => self.right = down,
            _ => {}
        }
    }

    pub(crate) fn wheel(&mut self, delta: MouseScrollDelta) {
        self.wheel += match delta {
            MouseScrollDelta::LineDelta(_, y) => f64::from(y),
            // Touchpads: about 40 pixels a notch.
            MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
        };
    }

    /// Takes what happened since the last frame; held keys are accounted up to `now`.
    pub(crate) fn take(&mut self, now: Instant) -> Frame {
        for (code, t0) in &mut self.down {
            *self.held_for.entry(*code).or_default() +=
                now.saturating_duration_since(*t0).as_secs_f64();
            *t0 = now;
        }
        let mut held: Vec<(KeyCode, f64)> = self.held_for.drain().collect();
        held.sort_by_key(|(k, _)| HELD.iter().position(|h| h == k));
        let slider_x = self.slider_x;
        if !self.left {
            self.slider_x = None;
        }
        Frame {
            held,
            pressed: std::mem::take(&mut self.pressed),
            drag: std::mem::take(&mut self.drag),
            wheel: std::mem::take(&mut self.wheel),
            slider_x,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn the_key_map_fits_a_small_window() {
        // 8 pixels a character: 480 pixels hold 58 with the panel's margins.
        let widest = KEYS_HELP.lines().map(|l| l.chars().count()).max();
        assert!(widest <= Some(58), "{widest:?}");
    }

    #[test]
    fn the_overlay_font_draws_every_character_of_the_key_map() {
        let missing: String = KEYS_HELP
            .chars()
            .filter(|&c| c != '\n' && !crate::frame::canvas::has_glyph(c))
            .collect();
        assert!(missing.is_empty(), "no glyph for {missing:?}");
    }

    #[test]
    fn a_press_and_release_between_frames_is_not_lost() {
        let mut i = Input::default();
        let t0 = Instant::now();
        i.key(KeyCode::KeyM, ElementState::Pressed, false, t0);
        i.key(KeyCode::KeyM, ElementState::Released, false, t0);
        // A held key tapped for 30 ms between two frames moves for 30 ms.
        i.key(KeyCode::KeyD, ElementState::Pressed, false, t0);
        i.key(
            KeyCode::KeyD,
            ElementState::Released,
            false,
            t0 + Duration::from_millis(30),
        );
        let f = i.take(t0 + Duration::from_millis(500));
        assert_eq!(f.pressed, vec![KeyCode::KeyM, KeyCode::KeyD]);
        assert_eq!(f.held.len(), 1);
        assert!((f.held[0].1 - 0.030).abs() < 1e-9, "{:?}", f.held);
        let f = i.take(t0 + Duration::from_millis(900));
        assert!(f.pressed.is_empty() && f.held.is_empty());
    }

    #[test]
    fn a_key_held_across_frames_counts_its_whole_time_once() {
        let mut i = Input::default();
        let t0 = Instant::now();
        i.key(KeyCode::KeyW, ElementState::Pressed, false, t0);
        // Auto-repeats neither restart the clock nor count as presses.
        i.key(
            KeyCode::KeyW,
            ElementState::Pressed,
            true,
            t0 + Duration::from_millis(100),
        );
        let a = i.take(t0 + Duration::from_millis(200));
        i.key(
            KeyCode::KeyW,
            ElementState::Released,
            false,
            t0 + Duration::from_millis(350),
        );
        let b = i.take(t0 + Duration::from_millis(600));
        let total: f64 = a.held.iter().chain(&b.held).map(|h| h.1).sum();
        assert!((total - 0.350).abs() < 1e-9, "{total}");
        assert_eq!(a.pressed, vec![KeyCode::KeyW]);
        assert!(b.pressed.is_empty());
    }

    #[test]
    fn drags_go_to_orbit_pan_or_light_by_button() {
        let mut i = Input::default();
        let never = |_y: f64| false;
        i.cursor_moved(10.0, 10.0);
        i.button(MouseButton::Left, ElementState::Pressed, never);
        i.cursor_moved(15.0, 12.0);
        i.shift(true);
        i.cursor_moved(16.0, 12.0);
        i.shift(false);
        i.button(MouseButton::Left, ElementState::Released, never);
        i.button(MouseButton::Right, ElementState::Pressed, never);
        i.cursor_moved(16.0, 20.0);
        let f = i.take(Instant::now());
        assert_eq!(f.drag.orbit, (5.0, 2.0));
        assert_eq!(f.drag.pan, (1.0, 0.0));
        assert_eq!(f.drag.light, (0.0, 8.0));
    }
}
