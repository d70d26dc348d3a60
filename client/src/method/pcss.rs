//! Percentage-closer soft shadows [Fernando05]: blocker search, then PCF over the
//! similar-triangles penumbra width, × unshadowed per-pixel LTC.

use super::point_shadow::PointShadow;
use crate::penumbra::Technique;

/// See the module doc.
pub(crate) static PCSS: PointShadow = PointShadow {
    name: "pcss",
    label: "PCSS",
    description: "percentage-closer soft shadows: blocker search, then PCF of the penumbra width",
    technique: Technique::Pcss,
};
