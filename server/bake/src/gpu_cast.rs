//! The bake's GPU backend: each chunk's visibility cube maps are cast in a wgpu compute shader
//! over the CPU-built BVH ([`bspvt_raytrace::GpuOccluder`]) while CPU threads fit the previous
//! chunk's trees ([`Baker::bake_all_gpu`]).
//!
//! The rays are those of [`VertexRays::cast_brute_force`]: every sub-ray above the horizon of
//! every pixel that matters, to the light. Which pixels matter is decided here, on the CPU (so
//! the sets are the CPU's exactly); the sub-ray directions are uploaded once per bake and the
//! rays made on the GPU, which returns each pixel's counts. A device may round otherwise than
//! the CPU (WGSL lets it fuse a·b + c, and divide to 2.5 ULP), which decides rays through a
//! triangle's edge or a box's corner either way; so the shader flags a pixel when any decision
//! of its rays was within a bound of that rounding of the other way, and the CPU casts the
//! flagged pixels again ([`VertexRays::reference_pixel`]): the cube maps, and so the bake's
//! bytes, are the CPU's on any device (`tests/tests/cast_gpu.rs`; the test below skews the
//! shader's rounding to show it).
//!
//! [`VertexRays::cast_brute_force`]: crate::cubemap::VertexRays
//! [`VertexRays::reference_pixel`]: crate::cubemap::VertexRays
//!
//! [`VertexRays::cast_brute_force`]: crate::cubemap::VertexRays

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, mpsc};
use std::time::Instant;

use bspvt_proto::cubemap::FACES;
use bspvt_raytrace::{CubeSource, GpuCubeTable, GpuOccluder, GpuStop};
use rayon::prelude::*;

pub use bspvt_raytrace::gpu::{GpuContext, GpuError};

use crate::cubemap::{CastCounts, CubeMap, FacePixels, LightStop};
use crate::fit::FitStats;
use crate::gpu_fit::{self, FaceInput, GpuFitter};
use crate::{BakeOutput, Baker, Cancelled, Totals};

/// A baker's occluder and cube-map table uploaded to a GPU.
pub struct GpuCaster {
    ctx: Arc<GpuContext>,
    occ: GpuOccluder,
    table: GpuCubeTable,
    /// The tree fit's pipeline ([`GpuFitter`]), built on the first GPU bake that uses it;
    /// `None` where the device refused it (the trees are then fitted on the CPU).
    fit: std::sync::OnceLock<Option<GpuFitter>>,
    /// Where the trees are fitted.
    fit_on: FitOn,
    /// The GPU's and the pool's measured fit rates, for [`FitOn::Shared`].
    rates: std::sync::Mutex<FitRates>,
}

/// Where a GPU bake fits its trees; every choice writes the same bytes (the GPU fit gives the
/// CPU's trees to the bit).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FitOn {
    /// The CPU pool alone (`BSPVT_GPU_FIT=0`; the default on a software adapter such as
    /// lavapipe, whose "GPU" is the pool's own cores).
    Cpu,
    /// The GPU, the faces it leaves on the pool (`BSPVT_GPU_FIT=1`).
    Gpu,
    /// Both at once, each a share of a chunk's faces in proportion to its measured rate
    /// (`BSPVT_GPU_FIT=shared`, the default on a hardware adapter): on an NVIDIA H200 the GPU
    /// fit is about half as fast as 16 cores (docs/bake.md), so neither alone keeps both busy.
    Shared,
}

impl FitOn {
    /// `BSPVT_GPU_FIT`: `0` the CPU, `1` the GPU, `shared` both; unset (or anything else) the
    /// default for the adapter (`software`: a CPU implementation of the API).
    pub fn from_env(software: bool) -> FitOn {
        match std::env::var("BSPVT_GPU_FIT").as_deref() {
            Ok("0") => FitOn::Cpu,
            Ok("1") => FitOn::Gpu,
            Ok("shared") => FitOn::Shared,
            _ if software => FitOn::Cpu,
            _ => FitOn::Shared,
        }
    }
}

/// Faces fitted per second by the GPU and by the pool, smoothed over chunks (0: not yet).
#[derive(Clone, Copy, Debug, Default)]
struct FitRates {
    gpu: f64,
    cpu: f64,
}

impl FitRates {
    /// The GPU's least share: its rate stays measured.
    const FLOOR: f64 = 1.0 / 16.0;

    /// How many of `n` faces the GPU takes: in proportion to the rates, the floor until
    /// both are measured.
    fn gpu_faces(&self, n: usize) -> usize {
        let share = if self.gpu > 0.0 && self.cpu > 0.0 {
            (self.gpu / (self.gpu + self.cpu)).max(Self::FLOOR)
        } else {
            Self::FLOOR
        };
        ((n as f64 * share).round() as usize).min(n)
    }

    /// Adds a chunk's measurement: `faces` fitted in `seconds` on each side.
    fn update(&mut self, gpu: (usize, f64), cpu: (usize, f64)) {
        let mix = |old: f64, (faces, s): (usize, f64)| {
            if faces == 0 || s <= 0.0 {
                return old;
            }
            let rate = faces as f64 / s;
            if old > 0.0 { 0.5 * (old + rate) } else { rate }
        };
        self.gpu = mix(self.gpu, gpu);
        self.cpu = mix(self.cpu, cpu);
    }
}

impl GpuCaster {
    /// Fits the trees on `fit_on` instead of what `BSPVT_GPU_FIT` says.
    pub fn set_fit_on(&mut self, fit_on: FitOn) {
        self.fit_on = fit_on;
    }

    /// The GPU tree fit, unless the fit is on the CPU or the device refused its pipeline.
    fn fitter(&self) -> Option<&GpuFitter> {
        if self.fit_on == FitOn::Cpu {
            return None;
        }
        self.fit
            .get_or_init(|| match GpuFitter::new(self.ctx.clone()) {
                Ok(f) => Some(f),
                Err(e) => {
                    eprintln!("the GPU tree fit is unavailable ({e}): fitting on the CPU");
                    None
                }
            })
            .as_ref()
    }
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

/// The vertices of one dispatch: where their rays start, and per vertex its mask of pixels
/// that matter (the GPU's input) and, per face, those pixels in order (for the assembly).
/// Bit 7 of a pixel's GPU count: the device's answer for some ray of it was within rounding
/// of the other way (`occlusion.wgsl`); the CPU casts the pixel again.
const UNSURE: u16 = 0x80;

struct GpuBatch {
    vertices: Vec<u32>,
    sources: Vec<CubeSource>,
    masks: Vec<u32>,
    faces: Vec<FaceIndices>,
}

/// Per face of a vertex: the pixels that matter and `FacePixels::light_pixels`.
type FaceIndices = [(Vec<u32>, u32); FACES];

impl Baker {
    /// Uploads this bake's BVH, its cube map's sub-ray directions and its lights' stops to the
    /// GPU of `ctx`.
    pub fn gpu_caster(&self, ctx: Arc<GpuContext>) -> Result<GpuCaster, GpuError> {
        let occ = GpuOccluder::new(&ctx, &self.occluder)?;
        let t = &self.table;
        let dirs: Vec<glam::Vec3> = t.sub.iter().flatten().copied().collect();
        let stops: Vec<GpuStop> = self
            .stops
            .iter()
            .map(|s| match *s {
                LightStop::Region(b) => GpuStop::Region {
                    min: b.min,
                    max: b.max,
                },
                LightStop::Plane { point, normal } => GpuStop::Plane { point, normal },
                LightStop::Sphere(l) => GpuStop::Sphere {
                    centre: l.centre,
                    radius: l.radius,
                    spread: l.spread,
                },
                LightStop::Lamp(l) => GpuStop::Lamp {
                    normal: l.normal,
                    offset: l.offset,
                    edges: l.edges[..l.edge_count as usize]
                        .iter()
                        .map(|&(m, c)| m.extend(c))
                        .collect(),
                    spread: l.spread,
                    two_sided: l.two_sided,
                },
            })
            .collect();
        let pixels = (FACES as u32) * t.res * t.res;
        let table = occ.cube_table(&ctx, &dirs, pixels, t.samples, &stops)?;
        let software = ctx.adapter.get_info().device_type == wgpu::DeviceType::Cpu;
        Ok(GpuCaster {
            ctx,
            occ,
            table,
            fit: std::sync::OnceLock::new(),
            fit_on: FitOn::from_env(software),
            rates: std::sync::Mutex::new(FitRates::default()),
        })
    }

    /// The GPU's input for `vertices` (the pixels that matter found in parallel on the current
    /// rayon pool).
    fn gpu_batch(&self, vertices: &[u32]) -> GpuBatch {
        let t = &self.table;
        let res2 = (t.res * t.res) as usize;
        let words = (FACES * res2).div_ceil(32);
        let per_vertex: Vec<(CubeSource, Vec<u32>, FaceIndices)> = vertices
            .par_iter()
            .map(|&v| {
                let r = self.vertex_rays(v);
                let mut mask = vec![0u32; words];
                let mut matters = vec![false; res2];
                let faces = std::array::from_fn(|f| {
                    let mut index = Vec::new();
                    let Some(light_pixels) = r.face_mask(t, f, &mut matters) else {
                        return (index, 0);
                    };
                    for p in (0..res2).filter(|&p| matters[p]) {
                        let bit = f * res2 + p;
                        mask[bit / 32] |= 1 << (bit % 32);
                        index.push(p as u32);
                    }
                    (index, light_pixels)
                });
                (CubeSource::new(r.origin, r.t_min, r.normal, v), mask, faces)
            })
            .collect();
        let mut batch = GpuBatch {
            vertices: vertices.to_vec(),
            sources: Vec::with_capacity(vertices.len()),
            masks: Vec::with_capacity(vertices.len() * words),
            faces: Vec::with_capacity(vertices.len()),
        };
        for (source, mask, faces) in per_vertex {
            batch.sources.push(source);
            batch.masks.extend(mask);
            batch.faces.push(faces);
        }
        batch
    }

    /// Each vertex's cube map from its batch and the GPU's counts (one per pixel that
    /// matters, in the batch's order), and what casting them cost (every sub-ray cast
    /// traverses the BVH). A pixel the GPU flags as unsure (some decision of its rays was
    /// within rounding of the other way, `occlusion.wgsl`) is cast again here by the CPU's
    /// reference, so the cube maps are the CPU's whatever the device's rounding.
    fn gpu_assemble(&self, batch: GpuBatch, counts: &[u16]) -> (Vec<CubeMap>, CastCounts) {
        // Where each vertex's counts start.
        let mut start = 0;
        let starts: Vec<usize> = batch
            .faces
            .iter()
            .map(|faces| {
                let s = start;
                start += faces.iter().map(|f| f.0.len()).sum::<usize>();
                s
            })
            .collect();
        let samples = u64::from(self.table.samples);
        let per_vertex: Vec<(CubeMap, u64, u64)> = batch
            .faces
            .into_par_iter()
            .zip(starts)
            .zip(batch.vertices)
            .map(|((mut faces, s), v)| {
                let rays = self.vertex_rays(v);
                let mut next = counts.get(s..).unwrap_or_default().iter();
                let (mut cast, mut again) = (0u64, 0u64);
                let mut map = std::array::from_fn(|face| {
                    let (index, light_pixels) = std::mem::take(&mut faces[face]);
                    if index.is_empty() {
                        return None;
                    }
                    let visible = index
                        .iter()
                        .zip(next.by_ref())
                        .map(|(&p, &w)| {
                            cast += u64::from(w >> 8);
                            if w & UNSURE != 0 {
                                again += samples;
                                rays.reference_pixel(&self.occluder, &self.table, face, p as usize)
                            } else {
                                w & 0x7f
                            }
                        })
                        .collect();
                    Some(FacePixels {
                        index,
                        visible,
                        light_pixels,
                        protected: Vec::new(),
                    })
                });
                // The pixels of a point or spot light or a sun, aimed at it on the CPU as every
                // cast does.
                cast += rays.aim(&self.occluder, &self.table, &mut map);
                (map, cast, again)
            })
            .collect();
        let rays = per_vertex.iter().map(|(_, c, _)| c).sum();
        let again = per_vertex.iter().map(|(_, _, r)| r).sum();
        let maps = per_vertex.into_iter().map(|(m, _, _)| m).collect();
        (
            maps,
            CastCounts {
                rays,
                traversals: rays,
                recast: again,
            },
        )
    }

    /// The cube maps of `vertices`, cast on the GPU, and what casting them cost (every ray
    /// cast traverses the BVH).
    pub fn gpu_cube_maps(
        &self,
        gpu: &GpuCaster,
        vertices: &[u32],
    ) -> Result<(Vec<CubeMap>, CastCounts), GpuError> {
        let batch = self.gpu_batch(vertices);
        let counts = batch.cast(gpu)?;
        Ok(self.gpu_assemble(batch, &counts))
    }

    /// [`Baker::bake_chunk`] with the rays cast on the GPU and the trees fitted there where the
    /// GPU fit applies (`fit_chunk_gpu`; the service's GPU workers: several workers keep the
    /// GPU and the refit threads busy).
    pub fn bake_chunk_gpu(&self, gpu: &GpuCaster, c: u32) -> Result<(Vec<u8>, Totals), GpuError> {
        let t0 = Instant::now();
        let (maps, counts) = self.gpu_cube_maps(gpu, &self.chunk_range(c).collect::<Vec<_>>())?;
        let ray_seconds = t0.elapsed().as_secs_f64();
        let (frame, mut t) = self.fit_chunk_gpu(gpu, c, &maps)?;
        t.rays = counts.rays;
        t.traversals = counts.traversals;
        t.recast = counts.recast;
        t.ray_seconds = ray_seconds;
        Ok((frame, t))
    }

    /// [`Baker::fit_chunk`] with the trees fitted where [`GpuCaster::fit_on`] says: on the GPU
    /// ([`GpuFitter`]: the CPU's trees to the bit), on the current rayon pool, or shared
    /// between the two at once in proportion to their measured rates ([`FitRates`]). The faces
    /// the GPU leaves, and every face where the GPU fit does not apply (`gpu_fit::supported`:
    /// faces above `MAX_GPU_RES`², another split search…; a tightened tolerance or a sun's
    /// protected pixels), are fitted on the pool. `Totals::fit_seconds` is then the wall-clock
    /// seconds of the whole fit, not thread-seconds; the GPU's busy clock counts the fit's
    /// dispatches.
    fn fit_chunk_gpu(
        &self,
        gpu: &GpuCaster,
        c: u32,
        maps: &[CubeMap],
    ) -> Result<(Vec<u8>, Totals), GpuError> {
        let fitter = self.fitter(self.settings.split);
        let Some(gpu_fit) = gpu.fitter().filter(|_| gpu_fit::supported(&fitter)) else {
            return Ok(self.fit_chunk(c, maps));
        };
        let t0 = Instant::now();
        // A face whose smallest light tightens the tolerance (`Fitter::for_face`), or that holds
        // a sun's protected pixels (`FacePixels::protected`), is fitted on the CPU: the GPU fit
        // takes one threshold a dispatch and knows no protected pixels.
        let on_gpu = |p: &FacePixels| {
            p.protected.is_empty()
                && fitter.for_face(p.light_pixels).epsilon_pixels == fitter.epsilon_pixels
        };
        let faces: Vec<FaceInput> = maps
            .iter()
            .flat_map(|m| m.iter().flatten())
            .filter(|p| on_gpu(p))
            .map(|p| FaceInput {
                index: &p.index,
                visible: &p.visible,
            })
            .collect();
        // The GPU's share on a thread of its own (it waits on the device), the pool's at once.
        let k = match gpu.fit_on {
            FitOn::Shared => gpu
                .rates
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .gpu_faces(faces.len()),
            _ => faces.len(),
        };
        let (on_gpu_faces, on_cpu_faces) = faces.split_at(k);
        let (gpu_fits, gpu_s, cpu_fits, cpu_s) = std::thread::scope(|s| {
            let fitting = s.spawn(|| {
                let t = Instant::now();
                let fits = gpu_fit.fit(&fitter, on_gpu_faces);
                (fits, t.elapsed().as_secs_f64())
            });
            let t = Instant::now();
            let cpu: Vec<_> = on_cpu_faces
                .par_iter()
                .map(|f| fitter.fit(f.index, f.visible))
                .collect();
            let cpu_s = t.elapsed().as_secs_f64();
            match fitting.join() {
                Ok((fits, gpu_s)) => Ok((fits, gpu_s, cpu, cpu_s)),
                Err(_) => Err(GpuError::Failed("the GPU fit's thread panicked".into())),
            }
        })?;
        gpu.rates
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .update((k, gpu_s), (faces.len() - k, cpu_s));
        // What the GPU left, fitted on the pool.
        let gpu_fits = gpu_fits?;
        let refit = gpu_fits.iter().filter(|f| f.is_err()).count();
        let gpu_fits: Vec<_> = gpu_fits
            .into_par_iter()
            .zip(on_gpu_faces)
            .map(|(fit, face)| fit.unwrap_or_else(|_| fitter.fit(face.index, face.visible)))
            .collect();
        let mut fits = gpu_fits.into_iter().chain(cpu_fits);
        let mut totals = Totals::default();
        let mut trees = Vec::with_capacity(maps.len());
        for m in maps {
            let mut vt = bspvt_proto::bspvt::VertexTrees::default();
            let mut fit = FitStats::default();
            for (f, px) in m.iter().enumerate() {
                let Some(px) = px else {
                    continue;
                };
                let (tree, st) = if on_gpu(px) {
                    fits.next().ok_or_else(|| {
                        GpuError::Failed("the GPU fit returned too few trees".into())
                    })?
                } else {
                    fitter.for_face(px.light_pixels).fit_protected(
                        &px.index,
                        &px.visible,
                        &px.protected,
                    )
                };
                vt.faces[f] = Some(tree);
                fit += st;
            }
            totals += Totals {
                vertices: 1,
                fit,
                ..Totals::default()
            };
            trees.push(vt);
        }
        totals.fit_seconds = t0.elapsed().as_secs_f64();
        if std::env::var_os("BSPVT_GPU_TIMING").is_some() {
            eprintln!(
                "gpu chunk {c}: {k} faces fitted on the GPU in {:.2} ms, {refit} of them again on the CPU, {} on the CPU in {:.2} ms, in {:.2} ms",
                gpu_s * 1e3,
                faces.len() - k,
                cpu_s * 1e3,
                totals.fit_seconds * 1e3
            );
        }
        let frame =
            bspvt_proto::encoding::encode_chunk(self.chunk_range(c).start, &trees, &self.codec);
        totals.bytes = frame.len() as u64;
        Ok((frame, totals))
    }

    /// [`Baker::bake_all`] with the rays cast on the GPU, pipelined: while the GPU casts chunk
    /// c, the current rayon pool finds chunk c + 1's pixels that matter, then assembles and
    /// fits chunk c's trees while the GPU casts chunk c + 1. A GPU thread only uploads,
    /// dispatches and reads back; all CPU work stays on the caller's pool (so `--threads`
    /// holds). The trees are fitted on the GPU too where the GPU fit applies
    /// (`fit_chunk_gpu`), from the main thread, as the GPU thread casts the next chunk.
    /// The same chunk frames as the CPU bake where the cube maps are the same.
    /// `Totals::ray_seconds` sums the wall-clock seconds of finding the pixels, the GPU
    /// thread's upload–cast–read-back and the assembly of the cube maps (overlapping the fit),
    /// not thread-seconds.
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
                    "gpu chunk {c}: {} vertices' pixels that matter in {:.2} ms",
                    batch.sources.len(),
                    s * 1e3
                );
            }
            (batch, s)
        };
        std::thread::scope(|scope| -> Result<(), GpuBakeError> {
            type Cast = (GpuBatch, f64, Result<Vec<u16>, GpuError>);
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
                let (maps, counts) = self.gpu_assemble(batch, &occluded?);
                let seconds = seconds + t0.elapsed().as_secs_f64();
                let t1 = Instant::now();
                let (frame, mut t) = self.fit_chunk_gpu(gpu, c, &maps)?;
                if timing {
                    eprintln!(
                        "gpu chunk {c}: assembled in {:.2} ms, fitted in {:.2} ms",
                        (t1 - t0).as_secs_f64() * 1e3,
                        t1.elapsed().as_secs_f64() * 1e3
                    );
                }
                t.rays = counts.rays;
                t.traversals = counts.traversals;
                t.recast = counts.recast;
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

impl GpuBatch {
    /// One count per pixel that matters, in order (checked: the assembly relies on it).
    fn cast(&self, gpu: &GpuCaster) -> Result<Vec<u16>, GpuError> {
        let counts = gpu
            .occ
            .cube_counts(&gpu.ctx, &gpu.table, &self.sources, &self.masks)?;
        let wanted: usize = self.faces.iter().flatten().map(|f| f.0.len()).sum();
        if counts.len() != wanted {
            return Err(GpuError::Failed(format!(
                "the GPU returned {} counts for {wanted} pixels",
                counts.len()
            )));
        }
        Ok(counts)
    }
}

#[cfg(test)]
mod tests {
    /// The shared fit's split: the floor until both sides are measured, then in proportion
    /// to the rates (never under the floor); a side that fitted nothing keeps its rate.
    #[test]
    fn the_gpu_takes_faces_in_proportion_to_its_rate() {
        let mut r = super::FitRates::default();
        assert_eq!(r.gpu_faces(1600), 100);
        r.update((100, 1.0), (0, 0.0));
        assert_eq!(r.gpu_faces(1600), 100, "the pool not measured yet");
        r.update((100, 1.0), (300, 1.0));
        assert_eq!(r.gpu_faces(1600), 400);
        // A GPU 3× faster on the next chunk: the running mean of 100 and 300 faces/s.
        r.update((300, 1.0), (300, 1.0));
        assert_eq!(r.gpu_faces(1000), 400);
        // A GPU far slower than the pool (its mean halves per chunk): the floor.
        for _ in 0..6 {
            r.update((1, 10.0), (300, 1.0));
        }
        assert_eq!(r.gpu_faces(1600), 100);
        assert_eq!(r.gpu_faces(0), 0);
    }

    use super::*;

    /// Another device's rounding cannot change a cube map. With every reciprocal and quotient
    /// of the shader skewed by a few ULP (as WGSL lets a device divide), the plain answers —
    /// the shader's without the unsure flag — differ from the CPU's on the refined room, whose
    /// dyadic grid puts rays exactly on triangle edges; with the flag, the pixels it marks,
    /// cast again on the CPU, give the CPU's cube maps exactly, at any skew, for a small share
    /// of the rays cast again. The same on the punctual room (rays that end at bulbs) and the
    /// checker canopy (rays through an alpha cut-out).
    #[test]
    fn rounding_of_another_device_never_changes_a_cube_map() {
        let Some(ctx) = GpuContext::for_test() else {
            return;
        };
        let rooms = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rooms");
        let mut scenes = Vec::new();
        for (name, res, step) in [("room", 8, 3), ("punctual-room", 16, 5)] {
            let mut scene = bspvt_proto::builtin::scene(name).expect("built-in scene");
            scene.bake.face_res = res;
            if let Some(r) = scene
                .bake
                .refine
                .as_mut()
                .filter(|_| name == "punctual-room")
            {
                r.max_vertices = 2000;
            }
            scenes.push((format!("{name} at {res}²"), scene, step));
        }
        let canopy = bspvt_proto::Scene::from_mesh_path(&rooms.join("checker-canopy.gltf"))
            .expect("checker canopy");
        let mut canopy = canopy;
        canopy.bake.face_res = 16;
        if let Some(r) = &mut canopy.bake.refine {
            r.max_vertices = 1500;
        }
        scenes.push(("checker canopy at 16²".to_string(), canopy, 5));
        let mut plain_differing = 0;
        for (label, mut scene, step) in scenes {
            crate::refine::refine_scene(&mut scene).expect("refinement");
            let b = Baker::new(&scene);
            let n = b.mesh().vertex_count() as u32;
            let vertices: Vec<u32> = (0..n).step_by(step).collect();
            let cpu: Vec<CubeMap> = vertices
                .iter()
                .map(|&v| b.cube_map_with(v, crate::CastMode::Full).0)
                .collect();
            let differing = |maps: &[CubeMap]| -> u64 {
                let mut d = 0;
                for (g, c) in maps.iter().zip(&cpu) {
                    for (g, c) in g.iter().zip(c) {
                        let (Some(g), Some(c)) = (g, c) else {
                            assert_eq!(g.is_some(), c.is_some(), "pixels that matter");
                            continue;
                        };
                        assert_eq!(g.index, c.index, "pixels that matter");
                        d += g
                            .visible
                            .iter()
                            .zip(&c.visible)
                            .map(|(a, b)| u64::from(a.abs_diff(*b)))
                            .sum::<u64>();
                    }
                }
                d
            };
            let mut caster = b.gpu_caster(ctx.clone()).expect("BVH on the GPU");
            for ulps in [0, 4, 64] {
                caster.table.skew_rounding(ulps, true);
                let (plain, _) = b.gpu_cube_maps(&caster, &vertices).expect("GPU cast");
                caster.table.skew_rounding(ulps, false);
                let (maps, counts) = b.gpu_cube_maps(&caster, &vertices).expect("GPU cast");
                let (p, d) = (differing(&plain), differing(&maps));
                eprintln!(
                    "{label}, skew {ulps} ULP: {} sub-rays; plain answers: {p} differ from the \
                     CPU's; flagged: {} cast again on the CPU, {d} differ",
                    counts.rays, counts.recast
                );
                assert_eq!(d, 0, "{label}, skew {ulps} ULP: the cube maps differ");
                assert!(
                    counts.recast * 20 < counts.rays,
                    "{label}, skew {ulps} ULP: {} of {} sub-rays cast again",
                    counts.recast,
                    counts.rays
                );
                plain_differing += p;
            }
        }
        assert!(
            plain_differing > 0,
            "no skew changed a plain answer: the test would see nothing"
        );
    }
}
