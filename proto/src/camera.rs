//! The pinhole camera of a scene, and framing a mesh that brings none.

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::error::SceneError;
use crate::mesh::{Aabb, Mesh};

/// A pinhole camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Eye position.
    pub position: [f32; 3],
    /// The point looked at.
    pub target: [f32; 3],
    /// Up direction (default +Y).
    #[serde(default = "default_up")]
    pub up: [f32; 3],
    /// Vertical field of view in degrees.
    #[serde(default = "default_fov")]
    pub fov_y_deg: f32,
    /// Width / height of the image the camera was made for (a glTF camera's `aspectRatio`).
    /// Commands given no image height take it from this; the field of view stays vertical
    /// whatever the image's shape (glTF 2.0 §3.10.2: `yfov` is kept, the viewport's aspect
    /// is used).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aspect: Option<f32>,
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}
fn default_fov() -> f32 {
    40.0
}

impl Camera {
    /// A camera looking at `bounds` from the front-right and above, fitting its bounding sphere.
    pub(crate) fn framing(bounds: &Aabb) -> Camera {
        let center = bounds.center();
        let radius = (0.5 * bounds.diagonal()).max(1e-6);
        let fov_y_deg = default_fov();
        let dist = radius / (0.5 * fov_y_deg.to_radians()).sin() * 1.05;
        let dir = Vec3::new(0.55, 0.45, 1.0).normalize();
        Camera {
            position: (center + dir * dist).to_array(),
            target: center.to_array(),
            up: default_up(),
            fov_y_deg,
            aspect: None,
        }
    }

    /// A camera for a mesh that brings none. An object (most of its area faces away from the
    /// centre of its box) is framed as [`Camera::framing`] does. An enclosure (a room, a
    /// Cornell box: most area faces inward) is looked into through its most open side (the
    /// side of ±x or ±z with the least wall area): from outside, framing the box with a 40°
    /// field of view, when that side is mostly open; from just inside that wall at eye height
    /// with a 60° field of view when it is closed.
    pub(crate) fn framing_mesh(mesh: &Mesh) -> Camera {
        let b = mesh.bounds();
        let c = b.center();
        let ext = (b.max - b.min).max(Vec3::splat(1e-6));
        let Some((axis, sign, coverage)) = open_side(mesh, &b) else {
            return Camera::framing(&b);
        };
        let mut out = Vec3::ZERO;
        out[axis] = sign;
        let mut face = c;
        face[axis] = if sign < 0.0 { b.min[axis] } else { b.max[axis] };
        let (position, fov_y_deg) = if coverage < 0.5 {
            let other = if axis == 0 { ext.z } else { ext.x };
            let half = 0.5 * other.max(ext.y);
            let fov: f32 = 40.0;
            (
                face + out * (half / (0.5 * fov).to_radians().tan() * 1.05),
                fov,
            )
        } else {
            let mut eye = face - out * (0.02 * ext[axis]);
            eye.y = b.min.y + 0.55 * ext.y;
            (eye, 60.0)
        };
        Camera {
            position: position.to_array(),
            target: c.to_array(),
            up: default_up(),
            fov_y_deg,
            aspect: None,
        }
    }

    pub(crate) fn validate(&self) -> Result<(), SceneError> {
        let p = Vec3::from(self.position);
        let t = Vec3::from(self.target);
        let up = Vec3::from(self.up);
        if !(p.is_finite() && t.is_finite() && up.is_finite()) {
            return Err(SceneError::Invalid(
                "camera has a NaN or infinite value".into(),
            ));
        }
        let f = t - p;
        if f.length_squared() == 0.0 || f.cross(up).length_squared() == 0.0 {
            return Err(SceneError::Invalid(
                "camera target equals its position or looks along `up`".into(),
            ));
        }
        if !(self.fov_y_deg > 0.1 && self.fov_y_deg < 179.0) {
            return Err(SceneError::Invalid(format!(
                "camera fov_y_deg {} is outside (0.1, 179)",
                self.fov_y_deg
            )));
        }
        if let Some(a) = self.aspect
            && !(a >= Camera::ASPECT_RANGE.0 && a <= Camera::ASPECT_RANGE.1)
        {
            return Err(SceneError::Invalid(format!(
                "camera aspect {a} is outside [{}, {}]",
                Camera::ASPECT_RANGE.0,
                Camera::ASPECT_RANGE.1
            )));
        }
        Ok(())
    }

    /// The aspect ratios (width / height) a camera may declare.
    pub const ASPECT_RANGE: (f32, f32) = (0.01, 100.0);

    /// The image height for `width` pixels: `height` when given, else `width / aspect` when
    /// the camera declares an aspect, else `width` (square).
    pub fn image_height(&self, width: u32, height: Option<u32>) -> u32 {
        match (height, self.aspect) {
            (Some(h), _) => h,
            (None, Some(a)) => ((f64::from(width) / f64::from(a)).round() as u32).max(1),
            (None, None) => width,
        }
    }
}

/// The side an enclosure is looked into through, or `None` for an object
/// ([`Camera::framing_mesh`]): (axis, side sign, that side's wall area as a fraction of the
/// side) for the side of ±x or ±z with the least wall, when more of the mesh's area faces the
/// centre of its box `b` than away. One pass over the triangles, no list of them (a scan's
/// million triangles made one of 31 MB).
fn open_side(mesh: &Mesh, b: &Aabb) -> Option<(usize, f32, f32)> {
    let c = b.center();
    let ext = (b.max - b.min).max(Vec3::splat(1e-6));
    // (axis, side sign): the four sides a camera may look in through.
    const SIDES: [(usize, f32); 4] = [(2, -1.0), (2, 1.0), (0, -1.0), (0, 1.0)];
    let walls_at = SIDES.map(|(axis, sign)| {
        let plane = if sign < 0.0 { b.min[axis] } else { b.max[axis] };
        (axis, plane, 0.02 * ext[axis])
    });
    // The area facing the centre net of the area facing away, and each side's wall area.
    let mut inward = 0.0f32;
    let mut walls = [0.0f32; 4];
    for t in &mesh.triangles {
        let p = t.map(|i| mesh.positions[i as usize]);
        let n = (p[1] - p[0]).cross(p[2] - p[0]);
        let area = 0.5 * n.length();
        if !(area > 0.0 && area.is_finite()) {
            continue;
        }
        let (n, at) = (n / (2.0 * area), (p[0] + p[1] + p[2]) / 3.0);
        inward += if n.dot(c - at) > 0.0 { area } else { -area };
        for (wall, &(axis, plane, tol)) in walls.iter_mut().zip(&walls_at) {
            if (at[axis] - plane).abs() <= tol && n[axis].abs() > 0.9 {
                *wall += area;
            }
        }
    }
    if inward <= 0.0 {
        return None;
    }
    let sides: [(usize, f32, f32); 4] = std::array::from_fn(|k| {
        let (axis, sign) = SIDES[k];
        let other = if axis == 0 { ext.z } else { ext.x };
        (axis, sign, walls[k] / (other * ext.y))
    });
    Some(sides.into_iter().fold(
        sides[0],
        |best, s| if s.2 < best.2 - 1e-3 { s } else { best },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_height_follows_the_declared_aspect() {
        let mut c = Camera::framing(&Aabb {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        });
        assert_eq!(c.image_height(600, None), 600);
        c.aspect = Some(1.5);
        assert_eq!(c.image_height(600, None), 400);
        assert_eq!(c.image_height(600, Some(123)), 123);
        assert!(c.validate().is_ok());
        c.aspect = Some(0.0);
        assert!(c.validate().is_err());
        c.aspect = Some(f32::NAN);
        assert!(c.validate().is_err());
    }

    /// The one-pass side choice against its definition with a list of faces (the code before
    /// the pass): the same result, bit for bit, for an object and for rooms open on a side
    /// and closed.
    #[test]
    fn open_side_is_the_face_lists() {
        use crate::scene::builtin::{grid_plane, icosphere};
        fn by_lists(mesh: &Mesh) -> Option<(usize, f32, f32)> {
            let b = mesh.bounds();
            let c = b.center();
            let ext = (b.max - b.min).max(Vec3::splat(1e-6));
            let faces: Vec<(Vec3, Vec3, f32)> = mesh
                .triangles
                .iter()
                .filter_map(|t| {
                    let p = t.map(|i| mesh.positions[i as usize]);
                    let n = (p[1] - p[0]).cross(p[2] - p[0]);
                    let area = 0.5 * n.length();
                    (area > 0.0 && area.is_finite())
                        .then(|| (n / (2.0 * area), (p[0] + p[1] + p[2]) / 3.0, area))
                })
                .collect();
            let inward: f32 = faces
                .iter()
                .map(|(n, at, a)| if n.dot(c - *at) > 0.0 { *a } else { -*a })
                .sum();
            if inward <= 0.0 {
                return None;
            }
            let sides = [(2usize, -1.0f32), (2, 1.0), (0, -1.0), (0, 1.0)].map(|(axis, sign)| {
                let plane = if sign < 0.0 { b.min[axis] } else { b.max[axis] };
                let tol = 0.02 * ext[axis];
                let wall: f32 = faces
                    .iter()
                    .filter(|(n, at, _)| (at[axis] - plane).abs() <= tol && n[axis].abs() > 0.9)
                    .map(|(_, _, a)| a)
                    .sum();
                let other = if axis == 0 { ext.z } else { ext.x };
                (axis, sign, wall / (other * ext.y))
            });
            Some(sides.into_iter().fold(
                sides[0],
                |best, s| if s.2 < best.2 - 1e-3 { s } else { best },
            ))
        }
        // Walls of a 4 × 2.5 × 3 room centred on the origin, facing inward.
        let wall = |center: Vec3, du: Vec3, dv: Vec3| {
            let inward = du.cross(dv).dot(-center) > 0.0;
            grid_plane(
                center,
                if inward { du } else { dv },
                if inward { dv } else { du },
                3,
                0,
            )
        };
        let (x, y, z) = (Vec3::X * 2.0, Vec3::Y * 1.25, Vec3::Z * 1.5);
        let mut open = wall(-y, x, z);
        for (c, du, dv) in [(y, z, x), (-x, y, z), (x, z, y), (-z, x, y)] {
            open.append(&wall(c, du, dv), 0);
        }
        let mut closed = open.clone();
        closed.append(&wall(z, y, x), 0);
        let object = icosphere(3, 0);
        for (name, mesh, expected) in [
            ("object", object, None),
            ("open room", open, Some((2, 1.0, false))),
            ("closed room", closed, Some((2, -1.0, true))),
        ] {
            let side = open_side(&mesh, &mesh.bounds());
            assert_eq!(side, by_lists(&mesh), "{name}");
            // (axis, sign, whether the side's wall covers it)
            assert_eq!(side.map(|s| (s.0, s.1, s.2 >= 0.5)), expected, "{name}");
        }
    }
}
