//! A polygonal light placed in the world for one frame: the scene's light moved by a rigid
//! transform (translate + rotate), in f64.

use std::sync::Arc;

use anyhow::Result;
use bspvt_proto::scene::PolygonLight;
use glam::{DAffine3, DVec3};

use crate::texture::{LightFrame, LightTexture};

/// A polygonal light as posed for one frame.
#[derive(Clone, Debug)]
pub struct Light {
    /// Convex polygon, counter-clockwise seen from the emitting side.
    pub vertices: Vec<DVec3>,
    /// Unit normal of the emitting side.
    pub normal: DVec3,
    /// Linear RGB radiance.
    pub radiance: DVec3,
    /// Emits from both sides.
    pub two_sided: bool,
    /// Prefiltered texture modulating the radiance (shared between frames).
    pub texture: Option<Arc<LightTexture>>,
}

impl Light {
    /// The scene light at rest, without its texture (see `Light::load`).
    pub fn from_scene(l: &PolygonLight) -> Light {
        Light {
            vertices: l.points().iter().map(|p| p.as_dvec3()).collect(),
            normal: l.normal().as_dvec3(),
            radiance: glam::Vec3::from(l.radiance).as_dvec3(),
            two_sided: l.two_sided,
            texture: None,
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

    /// This light moved by a rigid transform.
    pub fn transformed(&self, m: &DAffine3) -> Light {
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
        }
    }

    /// The mean of the polygon's vertices.
    pub fn centroid(&self) -> DVec3 {
        self.vertices.iter().sum::<DVec3>() / self.vertices.len().max(1) as f64
    }

    /// True when a point at `p` receives light from the emitting side(s).
    #[inline]
    pub fn faces(&self, p: DVec3) -> bool {
        self.two_sided || self.normal.dot(p - self.vertices[0]) > 0.0
    }

    /// Radiance emitted at light point `q` toward the receiver: the radiance times the
    /// texture's finest level at q's (u, v) (see [`crate::texture`]).
    #[inline]
    pub fn radiance_at(&self, q: DVec3) -> DVec3 {
        match &self.texture {
            None => self.radiance,
            Some(t) => {
                let f = LightFrame::new(&self.vertices, DVec3::ZERO);
                self.radiance * t.sample(f.uv(q - self.vertices[0]), 0.0)
            }
        }
    }

    /// Where the ray from `o` along unit `d` meets the light's emitting side: (distance, the
    /// point), if it does. A one-sided light is seen from its emitting side only; a ray in
    /// its plane does not meet it.
    pub fn hit(&self, o: DVec3, d: DVec3) -> Option<(f64, DVec3)> {
        if !self.two_sided && !(d.dot(self.normal) < 0.0) {
            return None;
        }
        crate::frame::brdf::polygon_crossing(&self.vertices, self.normal, o, d)
    }

    /// The light's polygon as a surface in the way of other lights' shadow rays.
    pub fn surface(&self) -> crate::frame::brdf::LampSurface {
        crate::frame::brdf::LampSurface {
            vertices: self.vertices.clone(),
            normal: self.normal,
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
