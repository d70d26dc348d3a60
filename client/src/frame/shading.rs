//! The local shading frame of the LTC convention: z is the normal and the view direction lies
//! in the xz-plane with x ≥ 0 (Heitz et al. 2016, §3: isotropic lobes are then fitted for
//! views (sin θ, 0, cos θ) only).

use glam::DVec3;

#[derive(Clone, Copy, Debug)]
pub(crate) struct ShadingFrame {
    pub(crate) x: DVec3,
    pub(crate) y: DVec3,
    pub(crate) z: DVec3,
}

impl ShadingFrame {
    /// The frame of unit normal `n` and unit view direction `wo` (pointing away from the
    /// surface). When the view is along the normal (or NaN-free but degenerate), any tangent
    /// works: the lobe is then rotationally symmetric.
    pub(crate) fn new(n: DVec3, wo: DVec3) -> ShadingFrame {
        let t = wo - n * n.dot(wo);
        let x = if t.length_squared() > 1e-24 {
            t.normalize()
        } else {
            n.any_orthonormal_vector()
        };
        ShadingFrame {
            x,
            y: n.cross(x),
            z: n,
        }
    }

    /// World → local.
    #[inline]
    pub(crate) fn to_local(self, w: DVec3) -> DVec3 {
        DVec3::new(w.dot(self.x), w.dot(self.y), w.dot(self.z))
    }

    /// Local → world.
    #[inline]
    pub(crate) fn to_world(self, l: DVec3) -> DVec3 {
        l.x * self.x + l.y * self.y + l.z * self.z
    }

    /// cos θ of the view in this frame, clamped to [0, 1].
    #[inline]
    pub(crate) fn cos_view(&self, wo: DVec3) -> f64 {
        wo.dot(self.z).clamp(0.0, 1.0)
    }
}
