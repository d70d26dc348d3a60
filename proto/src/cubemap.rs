//! The world-aligned cube-map layout on which each vertex's visibility is sampled.
//!
//! Face `f` has a forward axis `w` and tangent axes `a` (u) and `b` (v) with `a × b = w`. A
//! direction `d` in face `f`'s pyramid has face coordinates `u = d·a / d·w`, `v = d·b / d·w`
//! in [-1, 1] (gnomonic projection): straight lines in (u, v) are great circles on the sphere.
//! Pixel `(i, j)` of a face of resolution `r` has its centre at `u = (2i + 1)/r − 1`,
//! `v = (2j + 1)/r − 1`; its index is `j · r + i`.

use glam::{DVec3, Vec2, Vec3};

/// Number of cube faces.
pub const FACES: usize = 6;

/// (w, a, b) per face: +X, −X, +Y, −Y, +Z, −Z.
const AXES: [[[f32; 3]; 3]; FACES] = [
    [[1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
    [[-1., 0., 0.], [0., 0., 1.], [0., 1., 0.]],
    [[0., 1., 0.], [0., 0., 1.], [1., 0., 0.]],
    [[0., -1., 0.], [1., 0., 0.], [0., 0., 1.]],
    [[0., 0., 1.], [1., 0., 0.], [0., 1., 0.]],
    [[0., 0., -1.], [0., 1., 0.], [1., 0., 0.]],
];

/// The three axes of a face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaceFrame {
    /// Forward axis: the face's centre direction.
    pub w: Vec3,
    /// Tangent axis of u.
    pub a: Vec3,
    /// Tangent axis of v (a × b = w).
    pub b: Vec3,
}

impl FaceFrame {
    /// The axes of face `face` (0..6: +X, −X, +Y, −Y, +Z, −Z).
    pub fn of(face: usize) -> FaceFrame {
        let [w, a, b] = AXES[face];
        FaceFrame {
            w: Vec3::from(w),
            a: Vec3::from(a),
            b: Vec3::from(b),
        }
    }

    /// The (unnormalised) direction through face coordinates (u, v).
    pub fn direction(&self, uv: Vec2) -> Vec3 {
        self.w + uv.x * self.a + uv.y * self.b
    }

    /// `w` in double precision.
    pub fn w64(&self) -> DVec3 {
        self.w.as_dvec3()
    }
    /// `a` in double precision.
    pub fn a64(&self) -> DVec3 {
        self.a.as_dvec3()
    }
    /// `b` in double precision.
    pub fn b64(&self) -> DVec3 {
        self.b.as_dvec3()
    }
}

/// The face a direction falls in (largest absolute component; ties go to the lower axis) and
/// its face coordinates. `None` for the zero or a non-finite vector.
pub fn face_uv(d: Vec3) -> Option<(usize, Vec2)> {
    if !d.is_finite() {
        return None;
    }
    let ad = d.abs();
    let (axis, m) = if ad.x >= ad.y && ad.x >= ad.z {
        (0, d.x)
    } else if ad.y >= ad.z {
        (1, d.y)
    } else {
        (2, d.z)
    };
    if m == 0.0 {
        return None;
    }
    let face = 2 * axis + usize::from(m < 0.0);
    let f = FaceFrame::of(face);
    let inv = 1.0 / d.dot(f.w);
    Some((face, Vec2::new(d.dot(f.a) * inv, d.dot(f.b) * inv)))
}

/// The pixel (`j · res + i`) of a face of resolution `res` that face coordinates `uv` fall in:
/// pixel i spans u ∈ [2i/res − 1, 2(i+1)/res − 1) (the inverse of [`pixel_centres`]), clamped to
/// the face.
pub fn pixel_index(uv: Vec2, res: u32) -> usize {
    let cell = |x: f32| (((x + 1.0) * 0.5 * res as f32) as u32).min(res.saturating_sub(1)) as usize;
    cell(uv.y) * res as usize + cell(uv.x)
}

/// Pixel-centre coordinates of a face of resolution `res`, indexed `j · res + i`.
pub fn pixel_centres(res: u32) -> Vec<Vec2> {
    let r = res as f32;
    let c = |i: u32| (2 * i + 1) as f32 / r - 1.0;
    (0..res)
        .flat_map(|j| (0..res).map(move |i| Vec2::new(c(i), c(j))))
        .collect()
}

/// Solid angle of the pixel at face coordinates `uv` with side `2/res`: dω ≈ dA / (1+u²+v²)^{3/2}.
pub fn pixel_solid_angle(uv: Vec2, res: u32) -> f32 {
    let da = (2.0 / res as f32).powi(2);
    da / (1.0 + uv.length_squared()).powf(1.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_right_handed_and_faces_round_trip() {
        for f in 0..FACES {
            let fr = FaceFrame::of(f);
            assert!((fr.a.cross(fr.b) - fr.w).length() < 1e-6, "face {f}");
            for uv in pixel_centres(8) {
                let (g, back) = face_uv(fr.direction(uv)).expect("finite");
                assert_eq!(g, f);
                assert!((back - uv).length() < 1e-6);
            }
        }
    }

    #[test]
    fn pixels_are_found_from_their_coordinates() {
        for res in [1, 7, 64] {
            let h = 1.0 / res as f32;
            for (p, uv) in pixel_centres(res).into_iter().enumerate() {
                for o in [Vec2::ZERO, Vec2::splat(0.9 * h), Vec2::splat(-0.9 * h)] {
                    assert_eq!(pixel_index(uv + o, res), p, "res {res}, {uv} + {o}");
                }
            }
            // The face's edges and beyond stay on the face.
            assert_eq!(pixel_index(Vec2::splat(1.0), res), (res * res - 1) as usize);
            assert_eq!(pixel_index(Vec2::splat(-1.5), res), 0);
            assert_eq!(pixel_index(Vec2::splat(f32::NAN), res), 0);
        }
    }

    #[test]
    fn pixel_solid_angles_sum_to_the_sphere() {
        let total: f64 = pixel_centres(64)
            .iter()
            .map(|&uv| pixel_solid_angle(uv, 64) as f64)
            .sum::<f64>()
            * 6.0;
        assert!((total - 4.0 * std::f64::consts::PI).abs() < 1e-3, "{total}");
    }
}
