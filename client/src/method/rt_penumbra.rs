//! Paper 003: one hard shadow ray per pixel to the light's centroid, blurred by the
//! similar-triangles penumbra width [paper003], × unshadowed per-pixel LTC; where that blur
//! reaches, and past it while the parts' shadow is not yet the one ray's, 2 × 2 rays toward
//! the light's parts ([`crate::penumbra::rt::split_light`]; ours).

use super::point_shadow::PointShadow;
use crate::penumbra::Technique;

/// See the module doc.
pub(crate) static RT_PENUMBRA: PointShadow = PointShadow {
    name: "rt-penumbra",
    label: "RT penumbra (point light)",
    description: "one hard shadow ray to the light centroid, blurred by the similar-triangles penumbra width (paper 003); 2 × 2 rays to the light's parts where the shadow is soft",
    technique: Technique::RtPenumbra,
};
