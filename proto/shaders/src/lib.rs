//! # bspvt-shaders
//!
//! The shading that the native client and the service's browser viewer share, so that each
//! concept has one implementation:
//!
//! - [`ggx`]: the GGX microfacet BRDF (Walter et al. 2007; Heitz 2014, 2018);
//! - [`ltc_table`]: the project's LTC GGX table (Heitz et al. 2016, fitted by `bspvt ltc-fit`)
//!   and its lookup;
//! - [`light_texture`]: a textured light's prefiltered pyramid (Heitz et al. 2016, §5.3);
//! - [`normal_map`]: tangent-space normal maps in MikkTSpace frames (glTF 2.0 §3.9.3);
//! - [`gpu`]: the GPU path's WGSL shaders and the records they read (vertices, materials,
//!   trees, the LTC table), built here once for wgpu (client/src/gpu) and for WebGPU in the
//!   browser (the service's `/view/{id}`).
//!
//! Math kernels: no I/O. Builds on `bspvt-proto` (and `bspvt-raytrace` for the alpha cut-out
//! shader it shares); must not depend on the service, the client, wgpu or HTTP.

#![warn(unreachable_pub, missing_docs)]

pub mod ggx;
pub mod gpu;
pub mod light_texture;
pub mod ltc_table;
pub mod normal_map;
