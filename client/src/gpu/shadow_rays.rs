//! rt-penumbra's hard shadow rays (paper 003) on the GPU: the scene's BVH on the device
//! ([`bspvt_raytrace::GpuFirstHit`], `first_hit.wgsl`), each frame's segments up and one
//! distance per segment back. The blur stays on the CPU ([`crate::penumbra::blur`]).

use anyhow::{Result, anyhow};
use bspvt_raytrace::{GpuFirstHit, Occluder, Segment};

use super::context::Gpu;
use crate::penumbra::rt::ShadowCaster;

/// The scene's occluder on `gpu`, for closest-hit shadow rays.
pub struct GpuShadowRays {
    gpu: &'static Gpu,
    rays: GpuFirstHit,
}

impl GpuShadowRays {
    /// Uploads `occ`'s BVH, triangles and cut-outs to `gpu`.
    pub fn new(gpu: &'static Gpu, occ: &Occluder) -> Result<GpuShadowRays> {
        let rays = GpuFirstHit::new(&gpu.device, occ)
            .map_err(|e| anyhow!("the shadow rays' BVH on the GPU: {e}"))?;
        Ok(GpuShadowRays { gpu, rays })
    }
}

impl ShadowCaster for GpuShadowRays {
    fn first_hits(&self, segments: &[Segment]) -> Result<Vec<Option<f32>>> {
        let _queue = self.gpu.exclusive();
        self.rays
            .first_hits(&self.gpu.device, &self.gpu.queue, segments)
            .map_err(|e| anyhow!("shadow rays on the GPU: {e}"))
    }
}
