//! A light placed in the world for one frame — a polygon, a point or spot light's sphere, or
//! the sun's disk at infinity — moved by a rigid transform (translate + rotate), in f64.
//!
//! Every method sees a light through what it subtends from a point ([`Light::directions`]):
//! a polygon's corners; a sphere's silhouette, the cap of half-angle α (sin α = r / d), as a
//! regular spherical [`ROUND_SIDES`]-gon of the cap's solid angle; the sun's disk likewise.
//! The LTC integral of that polygon cut by the trees [paper000 §3.1 eq. 2] shades all three.

use std::sync::Arc;

use anyhow::Result;
use bspvt_proto::Scene;
use bspvt_proto::scene::{LightMotion, PolygonLight, PunctualLight, SunLight};
use bspvt_proto::sphere::SphPoly;
use glam::{DAffine3, DVec3};

use crate::texture::{LightFrame, LightTexture};

/// Sides of the spherical polygon a round light (sphere, sun) is integrated as (the GPU's
/// shaders make the same polygon).
pub const ROUND_SIDES: usize = bspvt_shaders::gpu::lights::ROUND_SIDES;

/// What a light is, beyond its radiance.
#[derive(Clone, Debug)]
pub enum Shape {
    /// A planar convex polygon ([`Light::vertices`]).
    Polygon,
    /// A point or spot light's sphere: the scene's light (its position, spot and range posed
    /// with it), radius [`PunctualLight::sphere_radius`].
    Sphere(PunctualLight),
    /// A disk at infinity (the sun).
    Distant {
        /// Unit direction toward the disk's centre.
        toward: DVec3,
        /// Half its angular diameter (radians).
        half_angle: f64,
    },
}

/// A light as posed for one frame.
#[derive(Clone, Debug)]
pub struct Light {
    /// A polygon's corners, counter-clockwise seen from the emitting side (empty for a
    /// sphere or a sun: see [`Light::directions`]).
    pub vertices: Vec<DVec3>,
    /// Unit normal of a polygon's emitting side (zero for the others).
    pub normal: DVec3,
    /// Linear RGB radiance (a sphere's: I / (π r²); the sun's: E / (π sin² h)).
    pub radiance: DVec3,
    /// Emits from both sides.
    pub two_sided: bool,
    /// Prefiltered texture modulating the radiance (shared between frames).
    pub texture: Option<Arc<LightTexture>>,
    /// Polygon, sphere or sun.
    pub shape: Shape,
}

/// Every light of `scene` at rest, with where its bake lets it go: the polygon lights (with
/// their textures), then the point and spot lights, then the suns — the order `--light K` and
/// the viewer count in.
pub fn scene_lights(scene: &Scene) -> Result<Vec<(Light, LightMotion)>> {
    let mut out = Vec::with_capacity(light_count(scene));
    for l in &scene.lights {
        out.push((Light::load(l)?, l.motion()));
    }
    out.extend(
        scene
            .punctual
            .iter()
            .map(|l| (Light::sphere(l), l.motion())),
    );
    out.extend(scene.suns.iter().map(|l| (Light::sun(l), l.motion())));
    Ok(out)
}

/// How many lights [`scene_lights`] gives.
pub fn light_count(scene: &Scene) -> usize {
    scene.lights.len() + scene.punctual.len() + scene.suns.len()
}

/// A regular spherical polygon of [`ROUND_SIDES`] unit directions around unit `axis` with the
/// solid angle of the cap of half-angle α, given as `sin_half` = sin(α/2), counter-clockwise
/// seen from the centre of the sphere (the point looking out along `axis`).
///
/// Each of its N isosceles triangles (apex angle C = 2π/N, sides β) has area E = Ω/N with
/// tan(E/2) = t² sin C / (1 + t² cos C), t = tan(β/2) (Todhunter, "Spherical Trigonometry",
/// §101), so t² = T / (sin C − T cos C) with T = tan(E/2) and Ω = 4π sin²(α/2).
pub(crate) fn round_directions(axis: DVec3, sin_half: f64) -> Option<[DVec3; ROUND_SIDES]> {
    let n = ROUND_SIDES as f64;
    let c = std::f64::consts::TAU / n;
    let omega = 4.0 * std::f64::consts::PI * sin_half * sin_half;
    let big_t = (0.5 * omega / n).tan();
    let t2 = big_t / (c.sin() - big_t * c.cos());
    if !(t2 > 0.0) || !t2.is_finite() || !axis.is_finite() {
        return None;
    }
    let beta = 2.0 * t2.sqrt().atan();
    let (sb, cb) = beta.sin_cos();
    let a = axis.normalize();
    let (u, v) = a.any_orthonormal_pair();
    let mut out = [DVec3::ZERO; ROUND_SIDES];
    for (k, d) in out.iter_mut().enumerate() {
        // Clockwise about `a` seen from outside = counter-clockwise from the centre.
        let phi = -c * k as f64;
        *d = a * cb + (u * phi.cos() + v * phi.sin()) * sb;
    }
    Some(out)
}

impl Light {
    /// A point or spot light as its sphere (radiance I / (π r²), the same far field).
    pub fn sphere(l: &PunctualLight) -> Light {
        Light {
            vertices: Vec::new(),
            normal: DVec3::ZERO,
            radiance: DVec3::from(l.sphere_radiance()),
            two_sided: true,
            texture: None,
            shape: Shape::Sphere(l.clone()),
        }
    }

    /// A sun as its disk at infinity (radiance E / (π sin² h), h half its diameter).
    pub fn sun(l: &SunLight) -> Light {
        Light {
            vertices: Vec::new(),
            normal: DVec3::ZERO,
            radiance: DVec3::from(l.disk_radiance()),
            two_sided: true,
            texture: None,
            shape: Shape::Distant {
                toward: l.toward().as_dvec3(),
                half_angle: f64::from(l.half_angle()),
            },
        }
    }

    /// True for a polygon light.
    pub fn is_polygon(&self) -> bool {
        matches!(self.shape, Shape::Polygon)
    }

    /// What the light subtends from `p`, as unit directions (polygon: its corners' directions,
    /// in order; sphere and sun: [`round_directions`]); empty when `p` sees none of it (inside
    /// the sphere, or at a corner). No heap: this runs per vertex (or pixel) and light.
    pub fn directions(&self, p: DVec3) -> SphPoly {
        let mut out = SphPoly::new();
        match &self.shape {
            Shape::Polygon => {
                for &q in &self.vertices {
                    let d = q - p;
                    let len = d.length();
                    if !(len > 0.0) || !len.is_finite() || out.try_push(d / len).is_err() {
                        return SphPoly::new();
                    }
                }
            }
            Shape::Sphere(l) => {
                let c = glam::Vec3::from(l.position).as_dvec3();
                let r = f64::from(l.sphere_radius());
                let to = c - p;
                let d = to.length();
                if !(d > r) || !d.is_finite() {
                    return out;
                }
                // sin(α/2) from sin α = r / d, stable for tiny α.
                let sin_a = r / d;
                let cos_a = (1.0 - sin_a * sin_a).max(0.0).sqrt();
                let sin_half = (sin_a / (2.0 * (1.0 + cos_a)).sqrt()).min(1.0);
                out.extend(round_directions(to / d, sin_half).into_iter().flatten());
            }
            Shape::Distant { toward, half_angle } => {
                out.extend(
                    round_directions(*toward, (0.5 * half_angle).sin())
                        .into_iter()
                        .flatten(),
                );
            }
        }
        out
    }

    /// The radiance that reaches `p` (per unit of what [`Self::directions`] subtends): a
    /// spot's cone and a range's window scale a sphere's ([`PunctualLight::falloff`]).
    pub fn radiance_toward(&self, p: DVec3) -> DVec3 {
        match &self.shape {
            Shape::Sphere(l) => self.radiance * f64::from(l.falloff(p.as_vec3())),
            _ => self.radiance,
        }
    }

    /// The scene light at rest, without its texture (see `Light::load`).
    pub fn from_scene(l: &PolygonLight) -> Light {
        Light {
            vertices: l.points().iter().map(|p| p.as_dvec3()).collect(),
            normal: l.normal().as_dvec3(),
            radiance: glam::Vec3::from(l.radiance).as_dvec3(),
            two_sided: l.two_sided,
            texture: None,
            shape: Shape::Polygon,
        }
    }

    /// [`Self::from_scene`] with the light's texture prefiltered from its image (the file its
    /// `texture` names, or a glTF lamp's emissive texture, decoded by the scene loader).
    pub fn load(l: &PolygonLight) -> Result<Light> {
        let mut light = Light::from_scene(l);
        if let Some(image) = &l.image {
            light.texture = Some(Arc::new(LightTexture::from_texels(
                image.width as usize,
                image.height as usize,
                &image.texels,
            )?));
        } else if let Some(t) = &l.texture {
            anyhow::bail!(
                "the light's texture {t:?} was not decoded (scenes opened by the scene loader \
                 or served by a service carry it)"
            );
        }
        Ok(light)
    }

    /// This light moved by a rigid transform (a sun only turns).
    pub fn transformed(&self, m: &DAffine3) -> Light {
        let shape = match &self.shape {
            Shape::Polygon => Shape::Polygon,
            Shape::Sphere(l) => {
                let mut l = l.clone();
                let c = m.transform_point3(glam::Vec3::from(l.position).as_dvec3());
                l.position = c.as_vec3().to_array();
                if let Some(s) = &mut l.spot {
                    let d = glam::Vec3::from(s.direction).as_dvec3();
                    s.direction = m.transform_vector3(d).normalize_or(d).as_vec3().to_array();
                }
                Shape::Sphere(l)
            }
            Shape::Distant { toward, half_angle } => Shape::Distant {
                toward: m.transform_vector3(*toward).normalize_or(*toward),
                half_angle: *half_angle,
            },
        };
        Light {
            vertices: self
                .vertices
                .iter()
                .map(|&p| m.transform_point3(p))
                .collect(),
            normal: m.transform_vector3(self.normal).normalize_or(self.normal),
            radiance: self.radiance,
            two_sided: self.two_sided,
            texture: self.texture.clone(),
            shape,
        }
    }

    /// The mean of the polygon's vertices; a sphere's centre; for the sun, the origin (the
    /// pivot it turns about).
    pub fn centroid(&self) -> DVec3 {
        match &self.shape {
            Shape::Polygon => {
                self.vertices.iter().sum::<DVec3>() / self.vertices.len().max(1) as f64
            }
            Shape::Sphere(l) => glam::Vec3::from(l.position).as_dvec3(),
            Shape::Distant { .. } => DVec3::ZERO,
        }
    }

    /// True when a point at `p` receives light from the emitting side(s): a polygon's front
    /// (or either side), outside a sphere within its spot's cone and range, anywhere for
    /// the sun.
    #[inline]
    pub fn faces(&self, p: DVec3) -> bool {
        match &self.shape {
            Shape::Polygon => {
                !self.vertices.is_empty()
                    && (self.two_sided || self.normal.dot(p - self.vertices[0]) > 0.0)
            }
            Shape::Sphere(l) => {
                let c = glam::Vec3::from(l.position).as_dvec3();
                (p - c).length() > f64::from(l.sphere_radius()) && l.falloff(p.as_vec3()) > 0.0
            }
            Shape::Distant { .. } => true,
        }
    }

    /// Radiance emitted at light point `q` toward the receiver: the radiance times the
    /// texture's finest level at q's (u, v) (see [`crate::texture`]).
    #[inline]
    pub fn radiance_at(&self, q: DVec3) -> DVec3 {
        match &self.texture {
            Some(t) if self.vertices.len() >= 3 => {
                let f = LightFrame::new(&self.vertices, DVec3::ZERO);
                self.radiance * t.sample(f.uv(q - self.vertices[0]), 0.0)
            }
            _ => self.radiance,
        }
    }

    /// Where the ray from `o` along unit `d` meets the light's emitting side: (distance, the
    /// point), if it does. A one-sided light is seen from its emitting side only; a ray in
    /// its plane does not meet it. The sun is met at infinity (distance `f64::INFINITY`, the
    /// point its direction) by a ray within its disk.
    pub fn hit(&self, o: DVec3, d: DVec3) -> Option<(f64, DVec3)> {
        match &self.shape {
            Shape::Polygon => {
                if !self.two_sided && !(d.dot(self.normal) < 0.0) {
                    return None;
                }
                crate::frame::brdf::polygon_crossing(&self.vertices, self.normal, o, d)
            }
            Shape::Sphere(l) => {
                let c = glam::Vec3::from(l.position).as_dvec3();
                let t = crate::frame::brdf::sphere_entry(c, f64::from(l.sphere_radius()), o, d)?;
                Some((t, o + t * d))
            }
            Shape::Distant { toward, half_angle } => {
                (d.dot(*toward) >= half_angle.cos()).then_some((f64::INFINITY, *toward))
            }
        }
    }

    /// The light's body as a surface in the way of other lights' shadow rays (none for the
    /// sun).
    pub fn surface(&self) -> Option<crate::frame::brdf::LampSurface> {
        use crate::frame::brdf::LampSurface;
        match &self.shape {
            Shape::Polygon => Some(LampSurface::Polygon {
                vertices: self.vertices.clone(),
                normal: self.normal,
            }),
            Shape::Sphere(l) => Some(LampSurface::Sphere {
                centre: glam::Vec3::from(l.position).as_dvec3(),
                radius: f64::from(l.sphere_radius()),
            }),
            Shape::Distant { .. } => None,
        }
    }

    /// Area of the polygon.
    pub(crate) fn area(&self) -> f64 {
        let v = &self.vertices;
        let mut a = DVec3::ZERO;
        for i in 1..v.len().saturating_sub(1) {
            a += (v[i] - v[0]).cross(v[i + 1] - v[0]);
        }
        0.5 * a.length()
    }
}
