//! Comparing a rendered image with its reference: error metrics ([`metrics`]) and error heat
//! maps ([`heatmap`]). Shared by the error-vs-time report and the benchmarks.

pub(crate) mod heatmap;
pub mod metrics;
