//! The bake's GPU backend: each chunk's visibility rays are cast in a wgpu compute shader over
//! the CPU-built BVH ([`bspvt_raytrace::GpuOccluder`]) while CPU threads fit the previous
//! chunk's trees ([`Baker::bake_all_gpu`]).
//!
//! The rays are those of [`VertexRays::cast_brute_force`]: every sub-ray above the horizon of
//! every pixel that matters, to the light; so the cube maps equal the CPU casts' up to rays
//! that graze a triangle's edge, where the two machines may round a hit either way (counted by
//! `tests/tests/cast_gpu.rs`).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, mpsc};
use std::time::Instant;

use bspvt_proto::cubemap::FACES;
use bspvt_raytrace::{GpuOccluder, GpuRay, RaySource};
use rayon::prelude::*;

pub use bspvt_raytrace::gpu::{GpuContext, GpuError};

use crate::cubemap::{CastCounts, CubeMap, FacePixels};
use crate::{BakeOutput, Baker, Cancelled, Totals};

/// A baker's occluder uploaded to a GPU.
pub struct GpuCaster {
    ctx: Arc<GpuContext>,
    occ: GpuOccluder,
}

/// Why a GPU bake stopped.
#[derive(Debug, thiserror::Error)]
pub enum GpuBakeError {
    /// The cancellation flag was set.
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
    /// The GPU failed.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// One vertex's pixels that matter on one face, in the order their rays are cast.
#[derive(Default)]
struct FaceRays {
    index: Vec<u32>,
    /// Sub-rays below the horizon (escaping without a cast).
    below: Vec<u16>,
    /// Sub-rays cast.
    cast: Vec<u16>,
}

/// A vertex's rays and where their answers go.
struct VertexBatch {
    source: RaySource,
    rays: Vec<GpuRay>,
    faces: [Option<FaceRays>; FACES],
}

impl Baker {
    /// Uploads this bake's BVH to the GPU of `ctx`.
    pub fn gpu_caster(&self, ctx: Arc<GpuContext>) -> Result<GpuCaster, GpuError> {
        Ok(GpuCaster {
            occ: GpuOccluder::new(&ctx, &self.occluder)?,
            ctx,
        })
    }

    /// Vertex `v`'s rays: [`crate::cubemap::VertexRays::cast_brute_force`]'s, not cast.
    fn vertex_batch(&self, v: u32) -> VertexBatch {
        let r = self.vertex_rays(v);
        let table = &self.table;
        let s = table.samples as usize;
        let mut rays = Vec::new();
        let faces = std::array::from_fn(|f| {
            let mut fr = FaceRays::default();
            for (p, &d) in table.centre[f].iter().enumerate() {
                if !r.matters(r.origin, d) {
                    continue;
                }
                let (mut below, mut cast) = (0u16, 0u16);
                for &d in &table.sub[f][p * s..(p + 1) * s] {
                    if r.escapes_below_horizon(d) {
                        below += 1;
                    } else {
                        cast += 1;
                        // f32::MAX for "no light reached": the same hits as ∞ (t < t_max).
                        let t_max = r.t_max(r.origin, d).min(f32::MAX);
                        rays.push(GpuRay {
                            dir: d.to_array(),
                            t_max,
                        });
                    }
                }
                fr.index.push(p as u32);
                fr.below.push(below);
                fr.cast.push(cast);
            }
            (!fr.index.is_empty()).then_some(fr)
        });
        VertexBatch {
            source: RaySource::new(r.origin, r.t_min, v),
            rays,
            faces,
        }
    }

    /// The rays of `vertices` (generated in parallel on the current rayon pool), flattened
    /// for one dispatch.
    fn gpu_batch(&self, vertices: &[u32]) -> GpuBatch {
        let mut per_vertex: Vec<VertexBatch> =
            vertices.par_iter().map(|&v| self.vertex_batch(v)).collect();
        let n: usize = per_vertex.iter().map(|b| b.rays.len()).sum();
        let mut rays = Vec::with_capacity(n);
        let mut ray_source = Vec::with_capacity(n);
        let sources = per_vertex.iter().map(|b| b.source).collect();
        for (i, b) in per_vertex.iter_mut().enumerate() {
            ray_source.extend(std::iter::repeat_n(i as u32, b.rays.len()));
            rays.append(&mut b.rays);
        }
        GpuBatch {
            sources,
            rays,
            ray_source,
            vertices: per_vertex,
        }
    }

    /// Each vertex's cube map from its batch and the GPU's answers (in the batch's ray order).
    fn gpu_assemble(batch: GpuBatch, occluded: &[u32]) -> Vec<CubeMap> {
        let mut next = occluded.iter();
        batch
            .vertices
            .into_iter()
            .map(|b| {
                b.faces.map(|f| {
                    f.map(|fr| {
                        let visible = fr
                            .below
                            .iter()
                            .zip(&fr.cast)
                            .map(|(&below, &cast)| {
                                let hit = next.by_ref().take(cast as usize).filter(|&&o| o != 0);
                                below + cast - hit.count() as u16
                            })
                            .collect();
                        FacePixels {
                            index: fr.index,
                            visible,
                        }
                    })
                })
            })
            .collect()
    }

    /// The cube maps of `vertices`, cast on the GPU, and what casting them cost (every ray
    /// cast traverses the BVH).
    pub fn gpu_cube_maps(
        &self,
        gpu: &GpuCaster,
        vertices: &[u32],
    ) -> Result<(Vec<CubeMap>, CastCounts), GpuError> {
        let batch = self.gpu_batch(vertices);
        let counts = batch.counts();
        let occluded = batch.cast(gpu)?;
        Ok((Self::gpu_assemble(batch, &occluded), counts))
    }

    /// [`Baker::bake_chunk`] with the rays cast on the GPU (the service's GPU workers: several
    /// workers keep the GPU and the fit threads busy).
    pub fn bake_chunk_gpu(&self, gpu: &GpuCaster, c: u32) -> Result<(Vec<u8>, Totals), GpuError> {
        let t0 = Instant::now();
        let (maps, counts) = self.gpu_cube_maps(gpu, &self.chunk_range(c).collect::<Vec<_>>())?;
        let ray_seconds = t0.elapsed().as_secs_f64();
        let (frame, mut t) = self.fit_chunk(c, &maps);
        t.rays = counts.rays;
        t.traversals = counts.traversals;
        t.ray_seconds = ray_seconds;
        Ok((frame, t))
    }

    /// [`Baker::bake_all`] with the rays cast on the GPU, pipelined: while the GPU casts chunk
    /// c, the current rayon pool generates chunk c + 1's rays, then fits chunk c's trees while
    /// the GPU casts chunk c + 1. A GPU thread only uploads, dispatches and reads back; all CPU
    /// work stays on the caller's pool (so `--threads` holds). The same chunk frames as the
    /// CPU bake where the cube maps are the same. `Totals::ray_seconds` sums the wall-clock
    /// seconds of ray generation, the GPU thread's upload–cast–read-back and the assembly of
    /// the cube maps (overlapping the fit), not thread-seconds.
    pub fn bake_all_gpu(
        &self,
        gpu: &GpuCaster,
        progress: &(dyn Fn(u64, u64) + Sync),
        cancel: &AtomicBool,
    ) -> Result<BakeOutput, GpuBakeError> {
        let start = Instant::now();
        let chunks = self.header.chunk_count();
        let (mut bytes, mut totals) = self.output_start();
        let total = self.header.vertex_count as u64;
        let timing = std::env::var_os("BSPVT_GPU_TIMING").is_some();
        let generate = |c: u32| {
            let t0 = Instant::now();
            let batch = self.gpu_batch(&self.chunk_range(c).collect::<Vec<_>>());
            let s = t0.elapsed().as_secs_f64();
            if timing {
                eprintln!(
                    "gpu chunk {c}: {} rays generated in {:.2} ms",
                    batch.rays.len(),
                    s * 1e3
                );
            }
            (batch, s)
        };
        std::thread::scope(|scope| -> Result<(), GpuBakeError> {
            type Cast = (GpuBatch, f64, Result<Vec<u32>, GpuError>);
            let (to_gpu, gpu_in) = mpsc::sync_channel::<(GpuBatch, f64)>(1);
            let (gpu_out, from_gpu) = mpsc::sync_channel::<Cast>(1);
            scope.spawn(move || {
                for (batch, gen_s) in gpu_in {
                    let t0 = Instant::now();
                    let r = batch.cast(gpu);
                    let s = gen_s + t0.elapsed().as_secs_f64();
                    if gpu_out.send((batch, s, r)).is_err() {
                        return;
                    }
                }
            });
            let mut to_gpu = Some(to_gpu);
            let mut send = |c: u32| {
                if let Some(tx) = &to_gpu
                    && tx.send(generate(c)).is_err()
                {
                    to_gpu = None;
                }
            };
            if chunks > 0 {
                send(0);
            }
            for c in 0..chunks {
                if cancel.load(Ordering::Relaxed) {
                    return Err(Cancelled { chunks_done: c }.into());
                }
                if c + 1 < chunks {
                    send(c + 1);
                }
                let Ok((batch, seconds, occluded)) = from_gpu.recv() else {
                    return Err(GpuError::Failed("the GPU thread stopped".into()).into());
                };
                let t0 = Instant::now();
                let counts = batch.counts();
                let maps = Self::gpu_assemble(batch, &occluded?);
                let seconds = seconds + t0.elapsed().as_secs_f64();
                let t1 = Instant::now();
                let (frame, mut t) = self.fit_chunk(c, &maps);
                if timing {
                    eprintln!(
                        "gpu chunk {c}: assembled in {:.2} ms, fitted in {:.2} ms",
                        (t1 - t0).as_secs_f64() * 1e3,
                        t1.elapsed().as_secs_f64() * 1e3
                    );
                }
                t.rays = counts.rays;
                t.traversals = counts.traversals;
                t.ray_seconds = seconds;
                bytes.extend_from_slice(&frame);
                totals += t;
                progress(totals.vertices, total);
            }
            Ok(())
        })?;
        Ok(BakeOutput {
            backend: crate::Backend::Gpu,
            ..self.output_finish(bytes, totals, start)
        })
    }
}

/// Rays of many vertices, flattened for one dispatch.
struct GpuBatch {
    sources: Vec<RaySource>,
    rays: Vec<GpuRay>,
    ray_source: Vec<u32>,
    /// Per vertex, where its answers go (its `rays` moved into the flat list).
    vertices: Vec<VertexBatch>,
}

impl GpuBatch {
    fn cast(&self, gpu: &GpuCaster) -> Result<Vec<u32>, GpuError> {
        gpu.occ
            .occluded(&gpu.ctx, &self.sources, &self.rays, &self.ray_source)
    }

    fn counts(&self) -> CastCounts {
        CastCounts {
            rays: self.rays.len() as u64,
            traversals: self.rays.len() as u64,
        }
    }
}
