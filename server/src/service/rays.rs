//! Where the service's bake workers cast rays (`--bake-backend`): on the shared thread pool,
//! or on the GPU with the fit on the pool (several workers keep both busy: one worker's chunk
//! is on the GPU while another's trees are fitted). The GPU holds one uploaded BVH per scene
//! being baked, dropped with the scene's baker.

use std::sync::Arc;
#[cfg(feature = "gpu")]
use std::sync::{Mutex, Weak};

use anyhow::Result;
use bspvt_bake::{Backend, Baker, Totals};

/// The workers' ray backend.
pub(crate) struct Rays {
    #[cfg(feature = "gpu")]
    gpu: Option<Gpu>,
}

#[cfg(feature = "gpu")]
struct Gpu {
    ctx: Arc<bspvt_bake::gpu_cast::GpuContext>,
    /// Per scene baker: its BVH on the GPU.
    casters: Mutex<Vec<(Weak<Baker>, Arc<bspvt_bake::gpu_cast::GpuCaster>)>>,
}

impl Rays {
    /// The backend `backend` names; the GPU's fails without an adapter.
    pub(crate) fn open(backend: Backend) -> Result<Rays> {
        match backend {
            Backend::Cpu => Ok(Rays {
                #[cfg(feature = "gpu")]
                gpu: None,
            }),
            #[cfg(feature = "gpu")]
            Backend::Gpu => {
                let ctx = bspvt_bake::gpu_cast::GpuContext::new()?;
                tracing::info!(gpu = %ctx.describe(), "bake rays on the GPU");
                Ok(Rays {
                    gpu: Some(Gpu {
                        ctx: Arc::new(ctx),
                        casters: Mutex::new(Vec::new()),
                    }),
                })
            }
            #[cfg(not(feature = "gpu"))]
            Backend::Gpu => anyhow::bail!(
                "bake_backend = gpu, but this bspvt-server was built without the `gpu` feature"
            ),
        }
    }

    /// Seconds this process's GPU has had a bake dispatch in flight (`None` on the CPU).
    pub(crate) fn gpu_busy_seconds(&self) -> Option<f64> {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &self.gpu {
            return Some(gpu.ctx.busy_seconds());
        }
        None
    }

    /// Bakes chunk `c` of `baker`'s scene (the same frame whichever backend: docs/bake.md,
    /// "The GPU backend").
    pub(crate) fn bake_chunk(
        &self,
        pool: &rayon::ThreadPool,
        baker: &Arc<Baker>,
        c: u32,
    ) -> Result<(Vec<u8>, Totals), String> {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &self.gpu {
            let caster = gpu
                .caster(baker)
                .map_err(|e| format!("GPU error preparing the scene: {e}"))?;
            return pool
                .install(|| baker.bake_chunk_gpu(&caster, c))
                .map_err(|e| format!("GPU error baking chunk {c}: {e}"));
        }
        Ok(pool.install(|| baker.bake_chunk(c)))
    }
}

#[cfg(feature = "gpu")]
impl Gpu {
    /// `baker`'s BVH on the GPU, uploaded on first use; forgets those of dropped bakers.
    fn caster(
        &self,
        baker: &Arc<Baker>,
    ) -> Result<Arc<bspvt_bake::gpu_cast::GpuCaster>, bspvt_bake::gpu_cast::GpuError> {
        let mut casters = self.casters.lock().unwrap_or_else(|p| p.into_inner());
        casters.retain(|(b, _)| b.strong_count() > 0);
        if let Some((_, c)) = casters
            .iter()
            .find(|(b, _)| std::ptr::eq(b.as_ptr(), Arc::as_ptr(baker)))
        {
            return Ok(c.clone());
        }
        let c = Arc::new(baker.gpu_caster(self.ctx.clone())?);
        casters.push((Arc::downgrade(baker), c.clone()));
        Ok(c)
    }
}
