//! GPU shading and frames with wgpu (Vulkan, Metal, DX12; Mesa's lavapipe where there is no
//! GPU): BSPVT per vertex in a compute pass ([`vertex`], eq. 2 of paper 000), and the trees
//! of all vertices in storage buffers ([`trees`]), and rt-penumbra's hard shadow rays
//! ([`shadow_rays`]). The CPU path stays the reference; the
//! bound between the two is in docs/gpu.md.

pub mod backend;
pub mod context;
pub mod frame;
pub(crate) mod penumbra_blur;
pub mod present;
pub mod shadow_rays;
pub(crate) mod sky;
pub(crate) mod timing;
pub(crate) mod trees;
pub mod vertex;

pub use backend::Backend;
pub use bspvt_raytrace::gpu::quiet_headless_vulkan;
pub use context::Gpu;
