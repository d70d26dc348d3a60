//! A pinhole camera: primary rays and projection to the image plane.

use bspvt_proto::scene::Camera;
use glam::{DVec3, Vec3};

/// A camera resolved for an image of `width` × `height` pixels. Pixel (0, 0) is the top left;
/// pixel centres are at half-integers.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub(crate) eye: DVec3,
    /// Unit viewing direction.
    pub(crate) forward: DVec3,
    /// Unit right and up vectors of the image plane.
    pub(crate) right: DVec3,
    pub(crate) up: DVec3,
    /// tan(fov_y / 2).
    pub(crate) tan_half_fov: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl View {
    /// `camera` is validated by the scene loader (distinct eye and target, up not parallel).
    pub fn new(camera: &Camera, width: u32, height: u32) -> View {
        let eye = Vec3::from(camera.position).as_dvec3();
        let target = Vec3::from(camera.target).as_dvec3();
        let forward = (target - eye).normalize_or(DVec3::NEG_Z);
        let right = forward
            .cross(Vec3::from(camera.up).as_dvec3())
            .normalize_or(DVec3::X);
        let up = right.cross(forward);
        View {
            eye,
            forward,
            right,
            up,
            tan_half_fov: (0.5 * f64::from(camera.fov_y_deg).to_radians()).tan(),
            width: width.max(1),
            height: height.max(1),
        }
    }

    fn aspect(&self) -> f64 {
        f64::from(self.width) / f64::from(self.height)
    }

    /// Unit direction of the primary ray through image point (x, y) in pixels.
    pub(crate) fn ray_dir(&self, x: f64, y: f64) -> DVec3 {
        let sx = (2.0 * x / f64::from(self.width) - 1.0) * self.tan_half_fov * self.aspect();
        let sy = (1.0 - 2.0 * y / f64::from(self.height)) * self.tan_half_fov;
        (self.forward + sx * self.right + sy * self.up).normalize()
    }

    /// Camera-space coordinates (right, up, depth along `forward`) of a world point.
    pub fn to_camera(&self, p: DVec3) -> DVec3 {
        let d = p - self.eye;
        DVec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }

    /// Image position (pixels) of a camera-space point with depth > 0.
    pub fn to_image(&self, c: DVec3) -> (f64, f64) {
        let sx = c.x / (c.z * self.tan_half_fov * self.aspect());
        let sy = c.y / (c.z * self.tan_half_fov);
        (
            (sx + 1.0) * 0.5 * f64::from(self.width),
            (1.0 - sy) * 0.5 * f64::from(self.height),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_inverts_rays() {
        let cam = Camera {
            position: [1.0, 2.0, 5.0],
            target: [0.0, 0.5, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 40.0,
            aspect: None,
        };
        let v = View::new(&cam, 320, 200);
        for (x, y) in [(0.5, 0.5), (160.0, 100.0), (319.5, 3.25)] {
            let p = v.eye + 7.0 * v.ray_dir(x, y);
            let (px, py) = v.to_image(v.to_camera(p));
            assert!(
                (px - x).abs() < 1e-9 && (py - y).abs() < 1e-9,
                "{x},{y} → {px},{py}"
            );
        }
    }
}
