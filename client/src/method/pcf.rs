//! Shadow map from the light's centroid with percentage-closer filtering [Reeves87], fixed
//! kernel, × unshadowed per-pixel LTC.

use super::point_shadow::PointShadow;
use crate::penumbra::Technique;

/// See the module doc.
pub(crate) static PCF: PointShadow = PointShadow {
    name: "pcf",
    label: "PCF",
    description: "shadow map from the light centroid, percentage-closer filtering with a fixed kernel",
    technique: Technique::Pcf,
};
