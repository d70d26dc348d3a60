//! The GPU path's shaders and the records they read, one definition for the native client
//! (wgpu: client/src/gpu) and the service's browser viewer (WebGPU):
//!
//! - [`wgsl`]: the shader sources as each pipeline compiles them (per-vertex BSPVT shading,
//!   the visibility raster, the per-pixel resolve, the presentation);
//! - [`records`]: the vertex records every pass reads;
//! - [`lights`]: the light record (polygon, point or spot light's sphere, sun's disk);
//! - [`materials`]: the material records and texture words of the resolve pass;
//! - [`trees`]: the node words and root indices of the trees.

pub mod lights;
pub mod materials;
pub mod records;
pub mod trees;
pub mod wgsl;
