//! Placement and motion of a scene's meshes: the scene file's `transform` (where a mesh sits)
//! and `motion` (how it moves over one animation cycle, t ∈ [0, 1)), documented in
//! `docs/scene-format.md`.
//!
//! A moving mesh is posed at time t in three steps, each in world space:
//!
//! 1. its rest geometry (the file's mesh placed by `transform`);
//! 2. deformed ([`Deform`]: a twist about an axis, or a travelling wave), normals recomputed
//!    from the deformed triangles;
//! 3. moved rigidly by the keyframed pose ([`Key`]s interpolated linearly in t, Euler angles
//!    too, so 0° → 360° is a full turn; the cycle wraps from the last key to the first),
//!    rotating and scaling about the pivot.
//!
//! The bake and the polygon-light methods see the scene at t = 0 ([`crate::Scene::mesh`]);
//! the run-time methods (SG environment lighting) pose it every frame.

use glam::{Affine3A, EulerRot, Mat3, Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::error::SceneError;

/// Where a mesh sits: scale, then rotation (Euler X, Y, Z in degrees: R = Rz·Ry·Rx), then
/// translation, about the origin (as a glTF node).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Transform {
    /// Translation.
    #[serde(default)]
    pub translation: [f32; 3],
    /// Rotation: Euler angles X, Y, Z in degrees.
    #[serde(default)]
    pub rotation_deg: [f32; 3],
    /// Scale per axis.
    #[serde(default = "unit_scale")]
    pub scale: [f32; 3],
}

fn unit_scale() -> [f32; 3] {
    [1.0; 3]
}

impl Default for Transform {
    fn default() -> Transform {
        Transform {
            translation: [0.0; 3],
            rotation_deg: [0.0; 3],
            scale: unit_scale(),
        }
    }
}

impl Transform {
    /// The affine map, rotating and scaling about `pivot`.
    pub(crate) fn affine(&self, pivot: Vec3) -> Affine3A {
        Affine3A::from_translation(Vec3::from(self.translation) + pivot)
            * Affine3A::from_scale_rotation_translation(
                Vec3::from(self.scale),
                rotation(self.rotation_deg),
                Vec3::ZERO,
            )
            * Affine3A::from_translation(-pivot)
    }

    /// Checks the transform of mesh entry `index`.
    pub(crate) fn validate_entry(&self, index: usize) -> Result<(), SceneError> {
        self.validate(&format!("meshes[{index}].transform"))
    }

    fn validate(&self, what: &str) -> Result<(), SceneError> {
        let bad = |m: String| Err(SceneError::Invalid(format!("{what}: {m}")));
        if !finite(&self.translation) || !finite(&self.rotation_deg) {
            return bad("translation and rotation_deg must be finite numbers".into());
        }
        if self.rotation_deg.iter().any(|a| a.abs() > MAX_DEGREES) {
            return bad(format!("rotation angles must be within ±{MAX_DEGREES}°"));
        }
        if !self.scale.iter().all(|s| s.is_finite() && *s > 0.0) {
            return bad(format!(
                "scale {:?} must be three positive finite numbers",
                self.scale
            ));
        }
        Ok(())
    }
}

/// Euler angles in degrees (about X, then Y, then Z) as a rotation.
fn rotation(deg: [f32; 3]) -> Quat {
    let [x, y, z] = deg.map(f32::to_radians);
    Quat::from_euler(EulerRot::ZYX, z, y, x)
}

fn finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Largest angle a file may write (ten turns): keeps f32 angles exact enough.
const MAX_DEGREES: f32 = 3600.0;
/// Most keys one motion may have.
const MAX_KEYS: usize = 4096;

/// A pose of a moving mesh at cycle time `t` (relative to its rest placement): a
/// [`Transform`]'s fields beside `t` (serde's `flatten` cannot be combined with
/// `deny_unknown_fields`, so they are spelled out).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Key {
    /// Time in the cycle, in [0, 1].
    pub t: f32,
    /// Translation at `t`.
    #[serde(default)]
    pub translation: [f32; 3],
    /// Rotation at `t`: Euler angles X, Y, Z in degrees.
    #[serde(default)]
    pub rotation_deg: [f32; 3],
    /// Scale per axis at `t`.
    #[serde(default = "unit_scale")]
    pub scale: [f32; 3],
}

impl Key {
    fn transform(&self) -> Transform {
        Transform {
            translation: self.translation,
            rotation_deg: self.rotation_deg,
            scale: self.scale,
        }
    }
}

/// A non-rigid deformation, evaluated at cycle time t.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Deform {
    /// A twist about `axis` through the pivot: a vertex at signed height h along the axis
    /// turns by `degrees` · sin(2πt) · h / H, H the mesh's largest |h|.
    Twist {
        /// The twist axis (non-zero).
        axis: [f32; 3],
        /// Turn in degrees at the largest |h|, at the peak of the cycle.
        degrees: f32,
    },
    /// A travelling wave: p += `normal` · `amplitude` · sin(2π (p·d / `wavelength` − t)),
    /// d the unit `direction`.
    Wave {
        /// Direction of travel (non-zero).
        direction: [f32; 3],
        /// Direction of the displacement (non-zero).
        normal: [f32; 3],
        /// Largest displacement.
        amplitude: f32,
        /// Wavelength (positive).
        wavelength: f32,
    },
}

impl Deform {
    fn validate(&self, what: &str) -> Result<(), SceneError> {
        let bad = |m: &str| Err(SceneError::Invalid(format!("{what}: {m}")));
        let unit = |v: &[f32; 3]| finite(v) && Vec3::from(*v).length() > 1e-6;
        match self {
            Deform::Twist { axis, degrees } => {
                if !unit(axis) {
                    return bad("twist.axis must be a non-zero finite vector");
                }
                if !(degrees.is_finite() && degrees.abs() <= MAX_DEGREES) {
                    return bad("twist.degrees must be a finite angle within ±3600°");
                }
            }
            Deform::Wave {
                direction,
                normal,
                amplitude,
                wavelength,
            } => {
                if !unit(direction) || !unit(normal) {
                    return bad("wave.direction and wave.normal must be non-zero finite vectors");
                }
                if !amplitude.is_finite() {
                    return bad("wave.amplitude must be finite");
                }
                if !(wavelength.is_finite() && *wavelength > 0.0) {
                    return bad("wave.wavelength must be positive and finite");
                }
            }
        }
        Ok(())
    }
}

/// How one mesh of a scene file moves (the `motion` of a mesh entry).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Motion {
    /// Centre of the keys' rotation and scaling and of the twist; default: the centre of the
    /// placed mesh's bounding box.
    #[serde(default)]
    pub pivot: Option<[f32; 3]>,
    /// Poses over the cycle, in non-decreasing `t` (none or one: no rigid motion).
    #[serde(default)]
    pub keys: Vec<Key>,
    /// A non-rigid deformation on top of the keys.
    #[serde(default)]
    pub deform: Option<Deform>,
}

impl Motion {
    /// Checks the motion of mesh entry `index`.
    pub(crate) fn validate(&self, index: usize) -> Result<(), SceneError> {
        let what = format!("meshes[{index}].motion");
        if let Some(p) = &self.pivot
            && !finite(p)
        {
            return Err(SceneError::Invalid(format!("{what}.pivot must be finite")));
        }
        if self.keys.len() > MAX_KEYS {
            return Err(SceneError::Invalid(format!(
                "{what} has {} keys; at most {MAX_KEYS} are accepted",
                self.keys.len()
            )));
        }
        let mut last = 0.0f32;
        for (k, key) in self.keys.iter().enumerate() {
            let kw = format!("{what}.keys[{k}]");
            if !(0.0..=1.0).contains(&key.t) {
                return Err(SceneError::Invalid(format!(
                    "{kw}.t = {} is outside the cycle [0, 1]",
                    key.t
                )));
            }
            if key.t < last {
                return Err(SceneError::Invalid(format!(
                    "{kw}.t = {} comes before the previous key's {last}: keys must be in time order",
                    key.t
                )));
            }
            last = key.t;
            key.transform().validate(&kw)?;
        }
        if let Some(d) = &self.deform {
            d.validate(&format!("{what}.deform"))?;
        }
        Ok(())
    }

    /// The keyed pose at cycle time `t` (wrapped into [0, 1)), about `pivot`.
    fn pose(&self, t: f32, pivot: Vec3) -> Option<Affine3A> {
        let (first, last) = (self.keys.first()?, self.keys.last()?);
        let t = t.rem_euclid(1.0);
        // The segment holding t; past the last key the cycle wraps to the first (at t0 + 1).
        let (a, b, ta, tb) = match self.keys.windows(2).find(|w| w[0].t <= t && t <= w[1].t) {
            Some(w) => (&w[0], &w[1], w[0].t, w[1].t),
            None if t < first.t => (last, first, last.t - 1.0, first.t),
            None => (last, first, last.t, first.t + 1.0),
        };
        let s = if tb > ta { (t - ta) / (tb - ta) } else { 0.0 };
        let lerp = |x: [f32; 3], y: [f32; 3]| Vec3::from(x).lerp(Vec3::from(y), s).to_array();
        let key = Transform {
            translation: lerp(a.translation, b.translation),
            rotation_deg: lerp(a.rotation_deg, b.rotation_deg),
            scale: lerp(a.scale, b.scale),
        };
        Some(key.affine(pivot))
    }
}

/// A moving part of a loaded scene: a contiguous run of the mesh's vertices and triangles,
/// its rest geometry and its motion.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MovingPart {
    /// First vertex of the part in the scene's mesh.
    pub first_vertex: u32,
    /// First triangle of the part in the scene's mesh.
    pub first_triangle: u32,
    /// Triangles of the part.
    pub triangle_count: u32,
    /// Rest positions and normals (the placed mesh), one per vertex of the part.
    pub rest_positions: Vec<Vec3>,
    /// Rest normals, one per vertex of the part.
    pub rest_normals: Vec<Vec3>,
    /// Centre of rotation, scaling and twist ([`Motion::pivot`], resolved).
    pub pivot: Vec3,
    /// How the part moves.
    pub motion: Motion,
}

impl MovingPart {
    /// Checks that the part fits a mesh of `vertices` vertices and `triangles` triangles
    /// (stored scenes are read back through this).
    pub(crate) fn validate(
        &self,
        index: usize,
        vertices: usize,
        triangles: usize,
    ) -> Result<(), SceneError> {
        let n = self.rest_positions.len();
        let v_end = self.first_vertex as usize + n;
        let t_end = self.first_triangle as usize + self.triangle_count as usize;
        if n == 0 || self.rest_normals.len() != n || v_end > vertices || t_end > triangles {
            return Err(SceneError::Invalid(format!(
                "moving part {index} does not fit the mesh ({n} vertices from {}, {} triangles from {})",
                self.first_vertex, self.triangle_count, self.first_triangle
            )));
        }
        if !self.pivot.is_finite() || !self.rest_positions.iter().all(|p| p.is_finite()) {
            return Err(SceneError::Invalid(format!(
                "moving part {index} has a non-finite position"
            )));
        }
        self.motion.validate(index)
    }

    /// A part over `first_vertex..` (positions and normals as placed) and its triangles.
    pub(crate) fn new(
        first_vertex: u32,
        first_triangle: u32,
        triangle_count: u32,
        positions: &[Vec3],
        normals: &[Vec3],
        motion: Motion,
    ) -> MovingPart {
        let pivot = match motion.pivot {
            Some(p) => Vec3::from(p),
            None => crate::mesh::Aabb::from_points(positions).center(),
        };
        MovingPart {
            first_vertex,
            first_triangle,
            triangle_count,
            rest_positions: positions.to_vec(),
            rest_normals: normals.to_vec(),
            pivot,
            motion,
        }
    }

    /// Writes the part's pose at cycle time `t` into `positions`, `normals` (the whole mesh's
    /// arrays); `triangles` is the whole mesh's, for the normals of a deformed part.
    pub(crate) fn pose_into(
        &self,
        t: f32,
        positions: &mut [Vec3],
        normals: &mut [Vec3],
        triangles: &[[u32; 3]],
    ) {
        let v0 = self.first_vertex as usize;
        let n = self.rest_positions.len();
        let (Some(pos), Some(nrm)) = (positions.get_mut(v0..v0 + n), normals.get_mut(v0..v0 + n))
        else {
            return;
        };
        pos.copy_from_slice(&self.rest_positions);
        nrm.copy_from_slice(&self.rest_normals);
        if let Some(d) = &self.motion.deform {
            deform(d, t, self.pivot, pos);
            let t0 = self.first_triangle as usize;
            let tris = triangles
                .get(t0..t0 + self.triangle_count as usize)
                .unwrap_or(&[]);
            area_weighted_normals(tris, v0, pos, nrm);
        }
        if let Some(m) = self.motion.pose(t, self.pivot) {
            // Normals by the inverse transpose (non-uniform scale).
            let nm: Mat3 = Mat3::from(m.matrix3).inverse().transpose();
            for p in pos.iter_mut() {
                *p = m.transform_point3(*p);
            }
            for q in nrm.iter_mut() {
                *q = (nm * *q).try_normalize().unwrap_or(*q);
            }
        }
    }
}

/// Applies `d` at time `t` to positions (pivot: the twist's axis point).
fn deform(d: &Deform, t: f32, pivot: Vec3, pos: &mut [Vec3]) {
    let phase = std::f32::consts::TAU * t;
    match d {
        Deform::Twist { axis, degrees } => {
            let a = Vec3::from(*axis).normalize_or(Vec3::Y);
            let h_max = pos
                .iter()
                .map(|p| (*p - pivot).dot(a).abs())
                .fold(0.0f32, f32::max);
            if !(h_max > 0.0) {
                return;
            }
            let amp = degrees.to_radians() * phase.sin() / h_max;
            for p in pos.iter_mut() {
                let r = *p - pivot;
                *p = pivot + Quat::from_axis_angle(a, amp * r.dot(a)) * r;
            }
        }
        Deform::Wave {
            direction,
            normal,
            amplitude,
            wavelength,
        } => {
            let dir = Vec3::from(*direction).normalize_or(Vec3::X);
            let nrm = Vec3::from(*normal).normalize_or(Vec3::Y);
            let k = std::f32::consts::TAU / wavelength;
            for p in pos.iter_mut() {
                *p += nrm * (amplitude * (k * p.dot(dir) - phase).sin());
            }
        }
    }
}

/// Area-weighted vertex normals of `tris` (global indices, part starting at vertex `v0`).
fn area_weighted_normals(tris: &[[u32; 3]], v0: usize, pos: &[Vec3], nrm: &mut [Vec3]) {
    let mut acc = vec![Vec3::ZERO; pos.len()];
    for tri in tris {
        let Some(i) = tri
            .iter()
            .map(|&i| (i as usize).checked_sub(v0).filter(|&l| l < pos.len()))
            .collect::<Option<Vec<usize>>>()
        else {
            continue;
        };
        let f = (pos[i[1]] - pos[i[0]]).cross(pos[i[2]] - pos[i[0]]);
        if f.is_finite() {
            for &l in &i {
                acc[l] += f;
            }
        }
    }
    for (q, a) in nrm.iter_mut().zip(acc) {
        if let Some(u) = a.try_normalize() {
            *q = u;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(t: f32, x: f32, ry: f32) -> Key {
        Key {
            t,
            translation: [x, 0.0, 0.0],
            rotation_deg: [0.0, ry, 0.0],
            scale: [1.0; 3],
        }
    }

    #[test]
    fn keys_interpolate_and_wrap() {
        let m = Motion {
            pivot: Some([0.0; 3]),
            keys: vec![key(0.25, 0.0, 0.0), key(0.75, 2.0, 360.0)],
            deform: None,
        };
        let p = |t: f32| {
            m.pose(t, Vec3::ZERO)
                .expect("keys")
                .transform_point3(Vec3::Z)
        };
        // Halfway between the keys: x = 1, half a turn about Y.
        assert!(
            (p(0.5) - Vec3::new(1.0, 0.0, -1.0)).length() < 1e-5,
            "{}",
            p(0.5)
        );
        // Past the last key the cycle wraps back to the first: at t = 0 (= 1) halfway back.
        assert!((p(0.0) - p(1.0)).length() < 1e-6);
        assert!(
            (p(0.0) - Vec3::new(1.0, 0.0, -1.0)).length() < 1e-4,
            "{}",
            p(0.0)
        );
        assert!((p(0.25) - Vec3::Z).length() < 1e-5);
    }

    #[test]
    fn validation_names_the_problem() {
        let mut m = Motion {
            keys: vec![key(0.5, 0.0, 0.0), key(0.2, 0.0, 0.0)],
            ..Motion::default()
        };
        let e = m.validate(3).expect_err("out of order").to_string();
        assert!(
            e.contains("meshes[3].motion.keys[1]") && e.contains("time order"),
            "{e}"
        );
        m.keys = vec![key(1.5, 0.0, 0.0)];
        assert!(m.validate(0).is_err());
        m.keys = vec![key(0.0, f32::NAN, 0.0)];
        assert!(m.validate(0).is_err());
        m.keys = vec![Key {
            scale: [1.0, 0.0, 1.0],
            ..key(0.0, 0.0, 0.0)
        }];
        assert!(m.validate(0).is_err());
        m.keys.clear();
        m.deform = Some(Deform::Wave {
            direction: [0.0; 3],
            normal: [0.0, 1.0, 0.0],
            amplitude: 0.1,
            wavelength: 1.0,
        });
        assert!(m.validate(0).is_err());
        m.deform = Some(Deform::Twist {
            axis: [0.0, 1.0, 0.0],
            degrees: 45.0,
        });
        assert!(m.validate(0).is_ok());
    }

    /// A twisted unit bar: the ends turn by ± the amplitude, the pivot plane stays, lengths
    /// along the axis are kept, and normals stay unit.
    #[test]
    fn twist_turns_the_ends() {
        let bar =
            crate::builtin::cuboid(Vec3::ZERO, Vec3::new(0.2, 1.0, 0.2), Quat::IDENTITY, 3, 0);
        let part = MovingPart::new(
            0,
            0,
            bar.triangles.len() as u32,
            &bar.positions,
            &bar.normals,
            Motion {
                deform: Some(Deform::Twist {
                    axis: [0.0, 1.0, 0.0],
                    degrees: 90.0,
                }),
                ..Motion::default()
            },
        );
        let (mut pos, mut nrm) = (bar.positions.clone(), bar.normals.clone());
        part.pose_into(0.25, &mut pos, &mut nrm, &bar.triangles);
        for (p, q) in bar.positions.iter().zip(&pos) {
            assert!((p.y - q.y).abs() < 1e-6);
            if p.x.hypot(p.z) < 1e-3 {
                continue; // on the axis: no angle
            }
            let turned = f32::atan2(q.x, q.z) - f32::atan2(p.x, p.z);
            let want = std::f32::consts::FRAC_PI_2 * p.y;
            // The angle difference, wrapped into (−π, π].
            let d = (turned - want + std::f32::consts::PI).rem_euclid(std::f32::consts::TAU)
                - std::f32::consts::PI;
            assert!(d.abs() < 1e-3, "{p} → {q}");
        }
        assert!(nrm.iter().all(|n| (n.length() - 1.0).abs() < 1e-4));
        // t = 0: sin 0 = 0, the rest pose.
        part.pose_into(0.0, &mut pos, &mut nrm, &bar.triangles);
        assert!(
            pos.iter()
                .zip(&bar.positions)
                .all(|(a, b)| (*a - *b).length() < 1e-6)
        );
    }
}
