//! Planar convex polygonal lights and the regions they move in [paper000 §3].

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::error::SceneError;
use crate::mesh::Aabb;

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

impl PolygonLight {
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
