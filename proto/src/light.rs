//! Planar convex polygonal lights and the regions they move in [paper000 §3].

use glam::Vec3;
use serde::{Deserialize, Serialize};

use std::sync::Arc;

use crate::error::SceneError;
use crate::mesh::Aabb;
use crate::texture::LightImage;

/// A planar convex polygonal light of uniform (or textured) radiance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolygonLight {
    /// 3 to 8 coplanar vertices of a convex polygon, counter-clockwise seen from the emitting
    /// side (the emitting normal is `(v1 - v0) × (v2 - v0)`).
    pub vertices: Vec<[f32; 3]>,
    /// Emitted radiance, linear RGB (W·sr⁻¹·m⁻²).
    pub radiance: [f32; 3],
    /// Emits from both sides.
    #[serde(default)]
    pub two_sided: bool,
    /// Optional texture (path relative to the scene file) modulating the radiance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<String>,
    /// Optional box the light stays inside while it moves. Directions from a vertex that cannot
    /// reach this box can never see the light, so the bake treats them as "don't care".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<Region>,
    /// Without a region: the light moves in its own plane (dragged, or along its path), and
    /// the bake ends rays at that plane. Neither this nor a region: the lamp is fixed where it
    /// is, and rays end at its polygon ([`PolygonLight::motion`]; docs/bake.md).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub moves_in_plane: bool,
    /// The texture's texels: the file `texture` names, decoded by the scene loader
    /// (`SceneFile::load_light_textures`), or a glTF lamp's emissive texture resampled onto the
    /// polygon's parametrisation. Not written in scene files; the stored scene carries it
    /// (`api`, version 5), so a client never reads `texture`'s path.
    #[serde(skip)]
    pub image: Option<Arc<LightImage>>,
}

/// An axis-aligned region of space, as written in scene files.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// Smallest corner.
    pub min: [f32; 3],
    /// Largest corner.
    pub max: [f32; 3],
}

impl Region {
    /// The region as a box.
    pub fn aabb(&self) -> Aabb {
        Aabb {
            min: Vec3::from(self.min),
            max: Vec3::from(self.max),
        }
    }
}

/// Where a light may be while the scene is shown: what its bake assumed (docs/bake.md, "Where
/// a ray ends").
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightMotion {
    /// Fixed where the scene put it (an asset's lamp): rays end at its polygon.
    Fixed,
    /// Anywhere in its own plane: rays end at the plane.
    Plane,
    /// Anywhere inside this box: rays end where they enter it.
    Region(Region),
    /// Turned to any direction (a sun): every direction is baked, rays run to infinity.
    Turns,
}

impl PolygonLight {
    /// Where the light may move: its region where it declares one, else its plane when it
    /// says so, else nowhere.
    pub fn motion(&self) -> LightMotion {
        match (self.region, self.moves_in_plane) {
            (Some(r), _) => LightMotion::Region(r),
            (None, true) => LightMotion::Plane,
            (None, false) => LightMotion::Fixed,
        }
    }

    /// The light's corners as vectors.
    pub fn points(&self) -> Vec<Vec3> {
        self.vertices.iter().map(|&v| Vec3::from(v)).collect()
    }

    /// Unit normal of the emitting side.
    pub fn normal(&self) -> Vec3 {
        let p = self.points();
        newell_normal(&p).normalize_or_zero()
    }

    pub(crate) fn validate(&self, index: usize) -> Result<(), SceneError> {
        let bad = |m: String| Err(SceneError::Invalid(format!("lights[{index}]: {m}")));
        let n = self.vertices.len();
        if !(3..=8).contains(&n) {
            return bad(format!("has {n} vertices; a light needs 3 to 8"));
        }
        if self.vertices.iter().flatten().any(|x| !x.is_finite()) {
            return bad("a vertex is NaN or infinite".into());
        }
        if self.radiance.iter().any(|x| !x.is_finite() || *x < 0.0) {
            return bad("radiance must be finite and ≥ 0".into());
        }
        let p = self.points();
        let normal = newell_normal(&p);
        let size = Aabb::from_points(&p).diagonal();
        let area2 = normal.length();
        if area2.is_nan() || area2 <= 1e-12 * size * size {
            return bad("polygon has zero area".into());
        }
        let nrm = normal / area2;
        // Planarity: every vertex within 1e-3 of the polygon's size from its plane.
        let d0 = nrm.dot(p[0]);
        if p.iter().any(|q| (nrm.dot(*q) - d0).abs() > 1e-3 * size) {
            return bad("vertices are not coplanar".into());
        }
        // Convexity: every turn has the same sign as the polygon normal.
        for i in 0..n {
            let (a, b, c) = (p[i], p[(i + 1) % n], p[(i + 2) % n]);
            if (b - a).cross(c - b).dot(nrm) < -1e-6 * size * size {
                return bad(format!(
                    "polygon is not convex (or not counter-clockwise) at vertex {}",
                    (i + 1) % n
                ));
            }
        }
        if self.image.as_ref().is_some_and(|i| !i.is_valid()) {
            return bad("its texture image is empty or not finite".into());
        }
        if self.region.is_some() && self.moves_in_plane {
            return bad("declares both a region and moves_in_plane: a light moves in one".into());
        }
        if let Some(r) = &self.region {
            let b = r.aabb();
            if !b.is_valid() {
                return bad("region min must be ≤ max and finite".into());
            }
            let eps = 1e-4 * size.max(b.diagonal());
            if p.iter().any(|q| {
                q.cmplt(b.min - Vec3::splat(eps)).any() || q.cmpgt(b.max + Vec3::splat(eps)).any()
            }) {
                return bad("the light starts outside its declared region".into());
            }
        }
        Ok(())
    }
}

/// Newell's polygon normal: robust for any planar polygon, length = 2 · area.
pub(crate) fn newell_normal(p: &[Vec3]) -> Vec3 {
    let mut n = Vec3::ZERO;
    for i in 0..p.len() {
        n += p[i].cross(p[(i + 1) % p.len()]);
    }
    n
}

/// A `KHR_lights_punctual` point or spot light, placed by its node (or written in a scene
/// file). The point-light methods (paper 003) shade it as a point; every other method as a
/// small sphere of [`PunctualLight::sphere_radius`] whose radiance gives the same far field
/// ([`PunctualLight::sphere_radiance`]), shadowed through the trees (docs/scene-format.md).
///
/// Units: `intensity` is the glTF colour × intensity, read as radiant intensity in the
/// renderer's linear units per steradian (the glTF candela taken as W·sr⁻¹, no 683 lm/W
/// factor, as emissive strengths are taken as radiance). Irradiance at distance d, normal
/// incidence: I / d² × the spot's and the range's attenuation ([`PunctualLight::falloff`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PunctualLight {
    /// The light's name in the file (for messages).
    pub name: String,
    /// World position (the node's origin).
    pub position: [f32; 3],
    /// Radiant intensity, linear RGB (colour × intensity).
    pub intensity: [f32; 3],
    /// glTF `range`: beyond it the light is off (`None`: infinite).
    pub range: Option<f32>,
    /// A spot's cone (`None`: a point light, emitting in every direction).
    #[serde(default)]
    pub spot: Option<Spot>,
    /// The radius of the sphere it is shaded as (`None`: the scene file's `punctual_radius`,
    /// else [`DEFAULT_SPHERE_RADIUS`]). Stored scenes are postcard: no field is skipped.
    #[serde(default)]
    pub radius: Option<f32>,
}

/// The radius a point or spot light is given when neither it nor its scene says one: a bulb
/// of 10 cm across (scene units are metres in glTF).
pub const DEFAULT_SPHERE_RADIUS: f32 = 0.05;

/// The sun's angular diameter, the default of a [`SunLight`]: 0.53°.
pub const SUN_ANGULAR_DIAMETER: f32 = 0.53 * std::f32::consts::PI / 180.0;

/// A directional light (`KHR_lights_punctual` `directional`: the sun): a disk at infinity of
/// `angular_diameter`, shadowed through the trees with every direction baked (its rays run to
/// infinity), so it may turn freely (docs/scene-format.md).
///
/// Units: `illuminance` is the glTF colour × intensity (lux, taken as W·m⁻² as `intensity`
/// is above): the irradiance on a surface facing the sun. The disk's radiance is
/// illuminance / its projected solid angle there ([`SunLight::disk_radiance`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SunLight {
    /// The light's name in the file (for messages).
    #[serde(default)]
    pub name: String,
    /// The direction the light travels (the node's −Z): from the sun toward the scene.
    pub direction: [f32; 3],
    /// Illuminance at normal incidence, linear RGB (colour × intensity).
    pub illuminance: [f32; 3],
    /// The disk's angular diameter in radians (`None`: [`SUN_ANGULAR_DIAMETER`]).
    #[serde(default)]
    pub angular_diameter: Option<f32>,
}

impl SunLight {
    /// A sun turns freely: its bake holds every direction.
    pub fn motion(&self) -> LightMotion {
        LightMotion::Turns
    }

    /// Half the disk's angular diameter.
    pub fn half_angle(&self) -> f32 {
        0.5 * self.angular_diameter.unwrap_or(SUN_ANGULAR_DIAMETER)
    }

    /// Unit direction toward the sun.
    pub fn toward(&self) -> Vec3 {
        -Vec3::from(self.direction).normalize_or_zero()
    }

    /// The disk's radiance: illuminance / (π sin² h), h the half-angle — ∫ cos dω over a cap
    /// of half-angle h around the normal is π sin² h —, so that a surface facing the sun
    /// receives exactly the illuminance.
    pub fn disk_radiance(&self) -> [f64; 3] {
        let h = f64::from(self.half_angle());
        let projected = std::f64::consts::PI * h.sin().powi(2);
        self.illuminance.map(|e| f64::from(e) / projected)
    }

    pub(crate) fn validate(&self, index: usize) -> Result<(), SceneError> {
        let bad = |m: &str| Err(SceneError::Invalid(format!("sun {index}: {m}")));
        let d = Vec3::from(self.direction);
        if !d.is_finite() || d.length_squared() < 1e-12 {
            return bad("its direction is not a direction");
        }
        if self.illuminance.iter().any(|x| !x.is_finite() || *x < 0.0) {
            return bad("its illuminance must be finite and ≥ 0");
        }
        let a = self.angular_diameter.unwrap_or(SUN_ANGULAR_DIAMETER);
        if !(a > 1e-5 && a <= 0.5) {
            return bad("its angular_diameter must be in [1e-5, 0.5] radians");
        }
        Ok(())
    }
}

/// A spot light's cone (KHR_lights_punctual `spot`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Spot {
    /// Unit direction the spot points (the node's −Z).
    pub direction: [f32; 3],
    /// Full intensity within this angle of `direction` (radians).
    pub inner_cone_angle: f32,
    /// No light beyond this angle (radians).
    pub outer_cone_angle: f32,
}

impl PunctualLight {
    /// A point or spot light stays where its scene put it: rays end at its sphere.
    pub fn motion(&self) -> LightMotion {
        LightMotion::Fixed
    }

    /// The radius of the sphere the light is shaded as.
    pub fn sphere_radius(&self) -> f32 {
        self.radius.unwrap_or(DEFAULT_SPHERE_RADIUS)
    }

    /// The sphere's radiance: I / (π r²), so that far away (d ≫ r) it gives the irradiance
    /// I / d² of a point light of intensity I (a sphere is seen as a disk of area π r²).
    pub fn sphere_radiance(&self) -> [f64; 3] {
        let r = f64::from(self.sphere_radius());
        self.intensity
            .map(|i| f64::from(i) / (std::f64::consts::PI * r * r))
    }

    /// The factor by which `intensity` is scaled toward the point `p`, without the 1/d² of
    /// distance: the spot's smooth falloff and the range window, as the KHR_lights_punctual
    /// specification recommends:
    ///
    /// ```text
    /// scale  = 1 / max(0.001, cos(inner) − cos(outer)),  offset = −cos(outer) · scale
    /// spot   = saturate(cos θ · scale + offset)²
    /// window = saturate(1 − (d / range)⁴)²   (the spec's recommended range falloff)
    /// ```
    pub fn falloff(&self, p: Vec3) -> f32 {
        let to = p - Vec3::from(self.position);
        let d = to.length();
        if !(d > 0.0) || !d.is_finite() {
            return 0.0;
        }
        let mut f = 1.0;
        if let Some(s) = &self.spot {
            let cos = Vec3::from(s.direction).normalize_or_zero().dot(to / d);
            let (ci, co) = (s.inner_cone_angle.cos(), s.outer_cone_angle.cos());
            let scale = 1.0 / (ci - co).max(0.001);
            let a = (cos * scale - co * scale).clamp(0.0, 1.0);
            f *= a * a;
        }
        if let Some(r) = self.range.filter(|r| *r > 0.0) {
            let w = (1.0 - (d / r).powi(4)).clamp(0.0, 1.0);
            f *= w * w;
        }
        if f.is_finite() { f } else { 0.0 }
    }

    pub(crate) fn validate(&self, index: usize) -> Result<(), SceneError> {
        let bad = |m: &str| Err(SceneError::Invalid(format!("punctual light {index}: {m}")));
        if self.position.iter().any(|x| !x.is_finite()) {
            return bad("its position is not finite");
        }
        if self.intensity.iter().any(|x| !x.is_finite() || *x < 0.0) {
            return bad("its intensity must be finite and ≥ 0");
        }
        if let Some(s) = &self.spot {
            let d = Vec3::from(s.direction);
            if !d.is_finite() || d.length_squared() < 1e-12 {
                return bad("its spot direction is not a direction");
            }
            if !(0.0 <= s.inner_cone_angle
                && s.inner_cone_angle < s.outer_cone_angle
                && s.outer_cone_angle <= std::f32::consts::FRAC_PI_2)
            {
                return bad("its cone angles must satisfy 0 ≤ inner < outer ≤ π/2");
            }
        }
        if self.radius.is_some_and(|r| !(r > 0.0 && r.is_finite())) {
            return bad("its radius must be finite and > 0");
        }
        Ok(())
    }
}
