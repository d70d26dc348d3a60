//! What every rendering method shares: the [`image::Image`] it returns, the camera
//! ([`camera::View`]), primary visibility ([`gbuffer::GBuffer`]), normal maps ([`normal_map`]), the LTC shading
//! frame
//! ([`shading::ShadingFrame`]), the material's BRDF and the shadow-ray policy ([`brdf`]),
//! image statistics ([`stats`]) and text drawn into a framebuffer ([`canvas`]).

pub mod brdf;
pub mod camera;
pub mod canvas;
pub mod gbuffer;
pub mod image;
pub(crate) mod shading;
pub(crate) use bspvt_shaders::normal_map;
pub mod stats;
