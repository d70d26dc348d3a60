//! rt-penumbra (paper 003) on the GPU: the hard shadow rays — the scene's BVH on the device
//! ([`bspvt_raytrace::GpuFirstHit`], `first_hit.wgsl`), each frame's segments up and one
//! distance per segment back — and the edge-aware blur ([`super::penumbra_blur`]).

use anyhow::{Result, anyhow};
use bspvt_raytrace::{GpuFirstHit, Occluder, Segment};

use std::sync::Mutex;

use super::context::Gpu;
use super::penumbra_blur::GpuBlur;
use crate::penumbra::rt::{RtBuffers, ShadowCaster};
use crate::penumbra::{Guide, Params};

/// The scene's occluder on `gpu`, for closest-hit shadow rays.
pub struct GpuShadowRays {
    gpu: &'static Gpu,
    rays: GpuFirstHit,
    /// The blur's pipeline and buffers (`None`: the CPU blurs).
    blur: Option<Mutex<GpuBlur>>,
}

impl GpuShadowRays {
    /// Uploads `occ`'s BVH, triangles and cut-outs to `gpu`; with `blur`, the soft shadow is
    /// blurred there too.
    pub fn new(gpu: &'static Gpu, occ: &Occluder, blur: bool) -> Result<GpuShadowRays> {
        let rays = GpuFirstHit::new(&gpu.device, occ)
            .map_err(|e| anyhow!("the shadow rays' BVH on the GPU: {e}"))?;
        let blur = if blur {
            Some(Mutex::new(GpuBlur::new(gpu)?))
        } else {
            None
        };
        Ok(GpuShadowRays { gpu, rays, blur })
    }
}

impl ShadowCaster for GpuShadowRays {
    fn first_hits(&self, segments: &[Segment]) -> Result<Vec<Option<f32>>> {
        let _queue = self.gpu.exclusive();
        self.rays
            .first_hits(&self.gpu.device, &self.gpu.queue, segments)
            .map_err(|e| anyhow!("shadow rays on the GPU: {e}"))
    }

    fn blur(
        &self,
        buffers: &RtBuffers,
        guide: &Guide,
        params: &Params,
    ) -> Option<Result<Vec<f32>>> {
        let blur = self.blur.as_ref()?;
        let mut blur = blur.lock().unwrap_or_else(|p| p.into_inner());
        Some(blur.soft(self.gpu, &buffers.hard, &buffers.radius, guide, params))
    }
}
