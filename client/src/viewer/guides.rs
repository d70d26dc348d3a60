//! The viewport's guides, drawn over the shaded frame: a ground grid, the world axes, the light
//! polygon with its emitting side and the box it may move in. Segments are clipped to the near
//! plane, projected, clipped to the image and hidden behind the surface (the frame's depth).

use bspvt_proto::Scene;
use glam::DVec3;

use crate::frame::camera::View;
use crate::frame::canvas::Canvas;
use crate::light::Light;

/// The light's outline where its emitting side faces the camera.
pub(crate) const LIGHT_FRONT: u32 = 0x00ff_d000;
/// The light's outline seen from behind (it emits away from the camera).
pub(crate) const LIGHT_BACK: u32 = 0x0090_6000;
const REGION: u32 = 0x0040_d0ff;
const GRID: u32 = 0x00c0_c0c0;
const AXES: [u32; 3] = [0x00ff_4040, 0x0040_ff40, 0x0050_70ff];

/// A world-space segment to draw.
struct Segment {
    a: DVec3,
    b: DVec3,
    rgb: u32,
    alpha: f32,
    /// Hidden behind the surface (false: always on top, as the light's gizmo is).
    occluded: bool,
}

/// Draws the guides of `scene` and its light `selected` (as posed now: `light`) into `canvas`:
/// the light's gizmo and, where it declares one, its region.
pub(crate) fn draw(
    canvas: &mut Canvas,
    view: &View,
    depth: &[f32],
    scene: &Scene,
    selected: usize,
    light: Option<&Light>,
) {
    let b = scene.mesh.bounds();
    let (lo, hi) = (b.min.as_dvec3(), b.max.as_dvec3());
    let size = (hi - lo).max_element().max(1e-6);
    let mut segs = Vec::new();
    grid(&mut segs, lo, hi, size);
    axes(&mut segs, lo.y, size);
    if let Some(l) = light {
        light_gizmo(&mut segs, l, view, size);
    }
    if let Some(r) = scene.lights.get(selected).and_then(|l| l.region) {
        boxed(
            &mut segs,
            DVec3::from(r.min.map(f64::from)),
            DVec3::from(r.max.map(f64::from)),
        );
    }
    let near = 1e-4 * size;
    for s in &segs {
        draw_segment(canvas, view, depth, s, near);
    }
}

/// Lines at round spacing (1, 2 or 5 × 10ⁿ, about ten cells over the scene) on the lowest
/// plane of the scene's box (y = min y: the ground, for a scene that has one).
fn grid(segs: &mut Vec<Segment>, lo: DVec3, hi: DVec3, size: f64) {
    let step = round_step(size / 10.0);
    let pad = step;
    let (x0, x1) = (
        ((lo.x - pad) / step).floor() as i64,
        ((hi.x + pad) / step).ceil() as i64,
    );
    let (z0, z1) = (
        ((lo.z - pad) / step).floor() as i64,
        ((hi.z + pad) / step).ceil() as i64,
    );
    if (x1 - x0) > 400 || (z1 - z0) > 400 {
        return;
    }
    let y = lo.y;
    let at = |x: i64, z: i64| DVec3::new(x as f64 * step, y, z as f64 * step);
    let lines = (x0..=x1)
        .map(|i| (at(i, z0), at(i, z1)))
        .chain((z0..=z1).map(|k| (at(x0, k), at(x1, k))));
    for (a, b) in lines {
        segs.push(Segment {
            a,
            b,
            rgb: GRID,
            alpha: 0.25,
            occluded: true,
        });
    }
}

/// 1, 2 or 5 × 10ⁿ, the nearest at or below `x`.
fn round_step(x: f64) -> f64 {
    let p = 10f64.powf(x.max(1e-12).log10().floor());
    let m = x / p;
    p * if m >= 5.0 {
        5.0
    } else if m >= 2.0 {
        2.0
    } else {
        1.0
    }
}

/// +x red, +y green, +z blue from the origin, on the grid's plane.
fn axes(segs: &mut Vec<Segment>, y: f64, size: f64) {
    let o = DVec3::new(0.0, y, 0.0);
    for (k, rgb) in AXES.iter().enumerate() {
        segs.push(Segment {
            a: o,
            b: o + DVec3::AXES[k] * 0.25 * size,
            rgb: *rgb,
            alpha: 0.9,
            occluded: true,
        });
    }
}

/// The outline (bright where its emitting side faces the camera), its diagonals to the
/// centroid, and an arrow along each emitting normal.
fn light_gizmo(segs: &mut Vec<Segment>, l: &Light, view: &View, size: f64) {
    let n = l.vertices.len();
    if n < 3 {
        return;
    }
    let c = l.centroid();
    let front = (view.eye - c).dot(l.normal) > 0.0 || l.two_sided;
    let rgb = if front { LIGHT_FRONT } else { LIGHT_BACK };
    for i in 0..n {
        let (a, b) = (l.vertices[i], l.vertices[(i + 1) % n]);
        segs.push(Segment {
            a,
            b,
            rgb,
            alpha: 1.0,
            occluded: false,
        });
        segs.push(Segment {
            a: c,
            b: a,
            rgb,
            alpha: 0.4,
            occluded: false,
        });
    }
    let radius = l
        .vertices
        .iter()
        .map(|v| (*v - c).length())
        .fold(0.0, f64::max);
    let len = radius.max(0.05 * size);
    let sides: &[f64] = if l.two_sided { &[1.0, -1.0] } else { &[1.0] };
    for &s in sides {
        let dir = l.normal * s;
        let tip = c + dir * len;
        segs.push(Segment {
            a: c,
            b: tip,
            rgb: LIGHT_FRONT,
            alpha: 1.0,
            occluded: false,
        });
        // Arrow head: two short strokes back from the tip.
        let side = dir.any_orthonormal_vector();
        for h in [side, -side] {
            segs.push(Segment {
                a: tip,
                b: tip - dir * 0.25 * len + h * 0.12 * len,
                rgb: LIGHT_FRONT,
                alpha: 1.0,
                occluded: false,
            });
        }
    }
}

/// The 12 edges of a box.
fn boxed(segs: &mut Vec<Segment>, lo: DVec3, hi: DVec3) {
    let corner = |i: usize| {
        DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    for i in 0..8usize {
        for bit in [1, 2, 4] {
            if i & bit == 0 {
                segs.push(Segment {
                    a: corner(i),
                    b: corner(i | bit),
                    rgb: REGION,
                    alpha: 0.7,
                    occluded: true,
                });
            }
        }
    }
}

/// Near-plane clip in camera space, projection, Liang–Barsky clip to the image; 1/z is
/// linear in screen space, so the clipped ends' depths come from it.
fn draw_segment(canvas: &mut Canvas, view: &View, depth: &[f32], s: &Segment, near: f64) {
    let (mut a, mut b) = (view.to_camera(s.a), view.to_camera(s.b));
    if a.z < near && b.z < near {
        return;
    }
    if a.z < near {
        a = a + (b - a) * ((near - a.z) / (b.z - a.z));
    } else if b.z < near {
        b = b + (a - b) * ((near - b.z) / (a.z - b.z));
    }
    let (pa, pb) = (view.to_image(a), view.to_image(b));
    let (w, h) = (canvas.width as f64, canvas.height as f64);
    let (dx, dy) = (pb.0 - pa.0, pb.1 - pa.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, pa.0 + 1.0),
        (dx, w + 1.0 - pa.0),
        (-dy, pa.1 + 1.0),
        (dy, h + 1.0 - pa.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    if t0 > t1 || !t0.is_finite() || !t1.is_finite() {
        return;
    }
    let (ia, ib) = (1.0 / a.z, 1.0 / b.z);
    let at = |t: f64| ((pa.0 + dx * t, pa.1 + dy * t), 1.0 / (ia + (ib - ia) * t));
    let ((p0, z0), (p1, z1)) = (at(t0), at(t1));
    let depth = (s.occluded && depth.len() == canvas.width * canvas.height).then_some(depth);
    canvas.line(p0, p1, z0, z1, depth, s.rgb, s.alpha);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_steps_are_round() {
        assert_eq!(round_step(0.37), 0.2);
        assert_eq!(round_step(7.0), 5.0);
        assert_eq!(round_step(1.0), 1.0);
        assert!((round_step(0.0123) - 0.01).abs() < 1e-15);
    }
}
