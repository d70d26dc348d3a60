//! The light record the shading passes read (`light_normal`, `radiance` and `light` of the
//! parameters of shade.wgsl and resolve.wgsl; `light_directions` and `light_falloff` of
//! common.wgsl): ten vec4 and a vertex count, for the native client and the browser viewer.
//!
//! | kind (word 0's w) | words 2… |
//! |---|---|
//! | 0 / 1: a one- / two-sided polygon | its ≤ 8 corners (word 0: its unit normal) |
//! | [`SPHERE`]: a point or spot light's sphere | (centre, radius), (spot direction, range), (cos inner, cos outer, 1 when a spot) |
//! | [`SUN`]: a sun's disk at infinity | (unit direction toward it, half its angular diameter) |
//!
//! Word 1 is the radiance (w: 1 when a light texture modulates it). A sphere and a disk reach
//! the shaders as the regular spherical [`ROUND_SIDES`]-gon of their solid angle, as on the
//! CPU (client/src/light.rs `round_directions`).

use bspvt_proto::scene::{PunctualLight, SunLight};
use glam::Vec3;

/// Ten vec4: (normal, kind), (radiance, textured), then eight words of the light's shape.
pub type LightRecord = [[f32; 4]; 10];

/// The kind of a point or spot light's sphere.
pub const SPHERE: f32 = 2.0;
/// The kind of a sun's disk at infinity.
pub const SUN: f32 = 3.0;
/// Sides of the spherical polygon a sphere or a disk is shaded as (`ROUND_SIDES` of
/// common.wgsl).
pub const ROUND_SIDES: usize = 12;

/// The "vertex count" the shaders take for a round light.
const ROUND: u32 = ROUND_SIDES as u32;

fn record(kind: f32, radiance: Vec3, textured: bool) -> LightRecord {
    let mut r = [[0.0; 4]; 10];
    r[0][3] = kind;
    r[1] = radiance.extend(if textured { 1.0 } else { 0.0 }).to_array();
    r
}

/// Its count, or 0 (the light sends nothing) where a word is not finite.
fn checked(r: LightRecord, count: u32) -> (LightRecord, u32) {
    let finite = r.iter().flatten().all(|x| x.is_finite());
    (r, if finite { count } else { 0 })
}

/// A planar convex polygon of at most 8 corners (more: count 0; the caller shades it
/// elsewhere).
pub fn polygon(
    corners: &[Vec3],
    normal: Vec3,
    radiance: Vec3,
    two_sided: bool,
    textured: bool,
) -> (LightRecord, u32) {
    let mut r = record(if two_sided { 1.0 } else { 0.0 }, radiance, textured);
    r[0][..3].copy_from_slice(&normal.to_array());
    for (k, c) in corners.iter().enumerate().take(8) {
        r[2 + k] = c.extend(1.0).to_array();
    }
    let count = if corners.len() <= 8 {
        corners.len() as u32
    } else {
        0
    };
    checked(r, count)
}

/// A point or spot light as its sphere of [`PunctualLight::sphere_radius`] and `radiance` (its
/// [`PunctualLight::sphere_radiance`], or that scaled), with the spot's cone and the range
/// window of [`PunctualLight::falloff`].
pub fn sphere(l: &PunctualLight, radiance: Vec3) -> (LightRecord, u32) {
    let mut r = record(SPHERE, radiance, false);
    r[2] = Vec3::from(l.position).extend(l.sphere_radius()).to_array();
    let range = l.range.filter(|r| *r > 0.0).unwrap_or(0.0);
    r[3] = [0.0, 0.0, 0.0, range];
    if let Some(s) = &l.spot {
        r[3] = Vec3::from(s.direction)
            .normalize_or_zero()
            .extend(range)
            .to_array();
        r[4] = [s.inner_cone_angle.cos(), s.outer_cone_angle.cos(), 1.0, 0.0];
    }
    checked(r, ROUND)
}

/// A sun as its disk at infinity: unit `toward` it, `half_angle` half its angular diameter.
pub fn sun(toward: Vec3, half_angle: f32, radiance: Vec3) -> (LightRecord, u32) {
    let mut r = record(SUN, radiance, false);
    r[2] = toward.extend(half_angle).to_array();
    checked(r, ROUND)
}

/// A scene's sun at rest ([`sun`] of its direction, half angle and disk radiance).
pub fn scene_sun(l: &SunLight) -> (LightRecord, u32) {
    sun(
        l.toward(),
        l.half_angle(),
        glam::DVec3::from(l.disk_radiance()).as_vec3(),
    )
}

/// A scene's point or spot light at rest ([`sphere`] of its sphere radiance).
pub fn scene_sphere(l: &PunctualLight) -> (LightRecord, u32) {
    sphere(l, glam::DVec3::from(l.sphere_radiance()).as_vec3())
}
