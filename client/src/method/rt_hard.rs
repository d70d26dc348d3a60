//! The hard shadow ray of paper 003 to the light's centroid, unblurred, × unshadowed
//! per-pixel LTC (the baseline the blur improves on).

use super::point_shadow::PointShadow;
use crate::penumbra::Technique;

/// See the module doc.
pub(crate) static RT_HARD: PointShadow = PointShadow {
    name: "rt-hard",
    label: "RT hard shadow",
    description: "the same hard shadow ray to the light centroid, unblurred, × unshadowed per-pixel LTC",
    technique: Technique::RtHard,
};
