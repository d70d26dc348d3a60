//! The lamps are seen (issue 34): a frame of every method shows a lamp in view with its
//! radiance, as the Monte Carlo's camera ray finds it, and a lamp behind a surface stays hidden.

use bspvt_client::frame::image::Image;
use bspvt_client::method::sequence::{Options, render_sequence};
use bspvt_client::method::{Settings, registry};
use bspvt_client::render::renderer::Mode;
use bspvt_proto::Scene;
use bspvt_proto::scene::Camera;

/// The built-in plate seen from under its lamp (a 1 m square at y = 3 facing down, radiance
/// (12, 11, 10)), looking up past it.
fn looking_at_the_lamp() -> Scene {
    let mut s = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
    s.camera = Camera {
        position: [2.0, 1.2, 0.0],
        target: [0.0, 3.0, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 50.0,
        aspect: None,
    };
    s
}

fn frame(scene: &Scene, method: &str) -> Image {
    let opts = Options {
        method: registry::lookup(method).expect("method"),
        width: 48,
        height: 48,
        frames: 1,
        light: None,
        env_spin_deg: 0.0,
        settings: Settings {
            mode: Mode::Pixel,
            spp: 4,
            ..Settings::default()
        },
    };
    let mut out = None;
    render_sequence(scene, None, None, &opts, |_, img| {
        out = Some(img.clone());
        Ok(())
    })
    .expect("render");
    out.expect("one frame")
}

#[test]
fn a_lamp_in_view_shows_its_radiance_in_every_frame() {
    let scene = looking_at_the_lamp();
    for method in ["ltc", "mc"] {
        let img = frame(&scene, method);
        // The image centre looks at the lamp's centre from below (its emitting side).
        let c = img.pixels[(24 * 48 + 24) as usize];
        assert_eq!(c, [12.0, 11.0, 10.0], "{method}: centre pixel {c:?}");
        let lit = img
            .pixels
            .iter()
            .filter(|p| **p == [12.0, 11.0, 10.0])
            .count();
        assert!(lit > 20 && lit < 48 * 48 / 2, "{method}: {lit} lamp pixels");
    }
}

#[test]
fn a_lamp_seen_from_behind_or_hidden_is_not_drawn() {
    // From above the lamp (its back: it faces down) nothing of it is drawn.
    let mut scene = looking_at_the_lamp();
    scene.camera.position = [2.0, 4.5, 0.0];
    scene.camera.target = [0.0, 3.0, 0.0];
    let img = frame(&scene, "ltc");
    assert!(!img.pixels.contains(&[12.0, 11.0, 10.0]));
    // Made two-sided, it is.
    scene.lights[0].two_sided = true;
    let img = frame(&scene, "ltc");
    assert!(img.pixels.contains(&[12.0, 11.0, 10.0]));
}
