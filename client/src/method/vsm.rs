//! Variance shadow map [Donnelly06]: Chebyshev's bound with light-bleeding reduction
//! [Lauritzen07], × unshadowed per-pixel LTC.

use super::point_shadow::PointShadow;
use crate::penumbra::Technique;

/// See the module doc.
pub(crate) static VSM: PointShadow = PointShadow {
    name: "vsm",
    label: "VSM",
    description: "variance shadow map (Chebyshev bound, light-bleeding reduction)",
    technique: Technique::Vsm,
};
