//! rt-penumbra's edge-aware blur on the GPU (`penumbra.wgsl`; the CPU twin is
//! [`crate::penumbra::blur`]): the hard shadow, its half-widths and, where the light is split,
//! the sharp pixels go up (12 bytes a pixel; 8 with one ray), seven dispatches — edges, the widths spread along rows and columns, the tent's two boxes
//! along rows and two along columns — and the soft shadow comes back (4 bytes a pixel). The
//! guide (the pixels' surfaces) goes up once per camera, the buffers once per size.

use anyhow::{Context, Result};
use wgpu::util::DeviceExt;

use super::context::Gpu;
use crate::penumbra::{Guide, Params};

/// The buffers of one image size, and the guide they hold.
struct Target {
    size: (usize, usize),
    /// [`Guide::id`] of the guide uploaded (0: none yet).
    guide_id: u64,
    guide: wgpu::Buffer,
    hard: wgpu::Buffer,
    widths: wgpu::Buffer,
    /// 1 per sharp pixel ([`crate::penumbra::blur::sharp_pixels`]; all 0 with one ray).
    sharp: wgpu::Buffer,
    /// Whether `sharp` holds a mask (else all 0, as wgpu creates it): with one ray a frame
    /// uploads nothing there.
    sharp_set: bool,
    /// Buffers between the stages (the bind groups read and write them).
    _between: [wgpu::Buffer; 2],
    /// Where the soft shadow ends.
    c: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// One bind group per stage, in order.
    stages: Vec<wgpu::BindGroup>,
    /// Their parameters (rewritten when the parameters change).
    params: Vec<wgpu::Buffer>,
    groups: (u32, u32),
}

/// The blur's pipeline and its buffers.
pub(crate) struct GpuBlur {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    target: Option<Target>,
}

/// Workgroup size of `penumbra.wgsl`, and its grid's row (65,535 workgroups).
const WORKGROUP: u32 = 64;
const ROW: u32 = 65_535;

/// `penumbra.wgsl`'s parameters: width, height, stage, axis; cap, plane tolerance, normal
/// cosine, width scale.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct StageParams {
    shape: [u32; 4],
    limits: [f32; 4],
}

/// The seven stages: (stage, axis, width scale).
const STAGES: [(u32, u32, f32); 7] = [
    (0, 0, 1.0),
    (1, 0, 1.0),
    (1, 1, 1.0),
    (2, 0, std::f32::consts::FRAC_1_SQRT_2),
    (2, 0, std::f32::consts::FRAC_1_SQRT_2),
    (2, 1, std::f32::consts::FRAC_1_SQRT_2),
    (2, 1, std::f32::consts::FRAC_1_SQRT_2),
];

impl GpuBlur {
    pub(crate) fn new(gpu: &Gpu) -> Result<GpuBlur> {
        let (pipeline, layout) = gpu.checked("the penumbra blur's pipeline", || {
            bspvt_raytrace::gpu::storage_pipeline(
                &gpu.device,
                "penumbra blur",
                bspvt_shaders::gpu::wgsl::penumbra(),
                &[true, true, true, false, true, true],
            )
        })?;
        Ok(GpuBlur {
            pipeline,
            layout,
            target: None,
        })
    }

    /// The soft shadow of the hard shadow `hard` with world half-widths `radius` (per pixel of
    /// `guide`), as [`crate::penumbra::blur`]'s `edge_radius`, `spread_radius` and `blur` make
    /// it (the box kernel's tent), in f32.
    pub(crate) fn soft(
        &mut self,
        gpu: &Gpu,
        hard: &[f32],
        radius: &[f64],
        guide: &Guide,
        params: &Params,
    ) -> Result<Vec<f32>> {
        let (w, h) = (guide.width, guide.height);
        let n = w * h;
        if hard.len() != n || radius.len() != n || guide.pixels.len() != n {
            anyhow::bail!(
                "the blur's buffers: {} hard, {} widths, {} guide pixels for {w}×{h}",
                hard.len(),
                radius.len(),
                guide.pixels.len()
            );
        }
        if n == 0 {
            return Ok(Vec::new());
        }
        let t0 = std::time::Instant::now();
        let _queue = gpu.exclusive();
        if self.target.as_ref().is_none_or(|t| t.size != (w, h)) {
            self.target = Some(self.target(gpu, w, h)?);
        }
        let t = self.target.as_mut().context("the blur's buffers")?;
        if t.guide_id != guide.id {
            gpu.queue
                .write_buffer(&t.guide, 0, bytemuck::cast_slice(&guide_words(guide)));
            t.guide_id = guide.id;
        }
        let own = crate::penumbra::blur::own_widths(radius, params);
        for (buffer, &(stage, axis, scale)) in t.params.iter().zip(&STAGES) {
            // The spread within the pixels' own widths, where they have them
            // (blur::spread_radius).
            let stage = if stage == 1 && own.is_some() {
                3
            } else {
                stage
            };
            let p = StageParams {
                shape: [w as u32, h as u32, stage, axis],
                limits: [
                    params.max_radius as f32,
                    params.plane_tolerance as f32,
                    params.normal_cos as f32,
                    scale,
                ],
            };
            gpu.queue.write_buffer(buffer, 0, bytemuck::bytes_of(&p));
        }
        gpu.queue
            .write_buffer(&t.hard, 0, bytemuck::cast_slice(hard));
        match crate::penumbra::blur::sharp_pixels(hard, own, guide, params) {
            Some(m) => {
                let words: Vec<u32> = m.into_iter().map(u32::from).collect();
                gpu.queue
                    .write_buffer(&t.sharp, 0, bytemuck::cast_slice(&words));
                t.sharp_set = true;
            }
            None if t.sharp_set => {
                gpu.queue
                    .write_buffer(&t.sharp, 0, bytemuck::cast_slice(&vec![0u32; n]));
                t.sharp_set = false;
            }
            None => {}
        }
        // f64::MAX (an occluder at the light) to f32::MAX, not ∞: ∞ / ∞ would be NaN where the
        // CPU's f64::MAX / f64::MAX is 1.
        let widths: Vec<f32> = radius.iter().map(|&r| (r as f32).min(f32::MAX)).collect();
        gpu.queue
            .write_buffer(&t.widths, 0, bytemuck::cast_slice(&widths));
        // With BSPVT_GPU_TIMING each stage is submitted and waited for alone, and timed.
        let timing = std::env::var_os("BSPVT_GPU_TIMING").is_some();
        let mut stage_ms = Vec::new();
        let t_upload = t0.elapsed();
        let batches: Vec<&[wgpu::BindGroup]> = if timing {
            t.stages.chunks(1).collect()
        } else {
            vec![&t.stages[..]]
        };
        for (k, batch) in batches.iter().enumerate() {
            let t_stage = std::time::Instant::now();
            let mut enc = gpu
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("penumbra blur"),
                });
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("penumbra blur"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.pipeline);
                for group in *batch {
                    pass.set_bind_group(0, group, &[]);
                    pass.dispatch_workgroups(t.groups.0, t.groups.1, 1);
                }
            }
            if k + 1 == batches.len() {
                enc.copy_buffer_to_buffer(&t.c, 0, &t.readback, 0, (n * 4) as u64);
            }
            gpu.queue.submit([enc.finish()]);
            if timing && k + 1 < batches.len() {
                gpu.wait()?;
                stage_ms.push(t_stage.elapsed().as_secs_f64() * 1e3);
            }
        }
        let t_last = std::time::Instant::now();
        let bytes = gpu.map_read(&t.readback)?;
        if timing {
            stage_ms.push(t_last.elapsed().as_secs_f64() * 1e3);
            let stages: Vec<String> = stage_ms.iter().map(|m| format!("{m:.1}")).collect();
            eprintln!(
                "gpu penumbra blur: {w}×{h}: buffers+upload {:.2} ms; stages (edge, spread x, \
                 spread y, box x, box x, box y, box y + read-back) {} ms",
                t_upload.as_secs_f64() * 1e3,
                stages.join(", ")
            );
        }
        Ok(bytemuck::cast_slice::<u8, f32>(&bytes).to_vec())
    }

    fn target(&self, gpu: &Gpu, w: usize, h: usize) -> Result<Target> {
        let n = (w * h) as u64;
        let device = &gpu.device;
        gpu.checked("the penumbra blur's buffers", || {
            use wgpu::BufferUsages as U;
            let buffer = |label: &str, size: u64, usage: U| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage,
                    mapped_at_creation: false,
                })
            };
            let guide = buffer("blur guide", n * 48, U::STORAGE | U::COPY_DST);
            let hard = buffer("hard shadow", n * 4, U::STORAGE | U::COPY_DST);
            let widths = buffer("half-widths", n * 4, U::STORAGE | U::COPY_DST);
            let sharp = buffer("sharp pixels", n * 4, U::STORAGE | U::COPY_DST);
            let a = buffer("blur a", n * 4, U::STORAGE);
            let b = buffer("blur b", n * 4, U::STORAGE);
            let c = buffer("blur c", n * 4, U::STORAGE | U::COPY_SRC);
            let readback = buffer("soft shadow readback", n * 4, U::MAP_READ | U::COPY_DST);
            let params: Vec<wgpu::Buffer> = STAGES
                .iter()
                .map(|_| {
                    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("blur stage"),
                        contents: bytemuck::bytes_of(&StageParams {
                            shape: [0; 4],
                            limits: [0.0; 4],
                        }),
                        usage: U::STORAGE | U::COPY_DST,
                    })
                })
                .collect();
            // (values, widths, out) per stage: the edges of the hard shadow into a; a spread
            // along rows into c, along columns into a (their values: the pixels' own widths);
            // the boxes hard → b → c along rows, then c → b → c along columns.
            let io: [(&wgpu::Buffer, &wgpu::Buffer, &wgpu::Buffer); 7] = [
                (&hard, &widths, &a),
                (&widths, &a, &c),
                (&widths, &c, &a),
                (&hard, &a, &b),
                (&b, &a, &c),
                (&c, &a, &b),
                (&b, &a, &c),
            ];
            let stages = io
                .iter()
                .zip(&params)
                .map(|(&(v, wd, o), p)| {
                    gpu.bind_buffers("blur stage", &self.layout, &[&guide, v, wd, o, p, &sharp])
                })
                .collect();
            let groups = (n as u32).div_ceil(WORKGROUP);
            let groups = if groups <= ROW {
                (groups, 1)
            } else {
                (ROW, groups.div_ceil(ROW))
            };
            Target {
                size: (w, h),
                guide_id: 0,
                guide,
                hard,
                widths,
                sharp,
                sharp_set: false,
                _between: [a, b],
                c,
                readback,
                stages,
                params,
                groups,
            }
        })
    }
}

/// The guide as `penumbra.wgsl` reads it: per pixel (position, 1), (normal, depth), (step x,
/// step y, 0, 0); zeros for the background.
fn guide_words(guide: &Guide) -> Vec<[f32; 4]> {
    let big = |x: f64| (x as f32).min(f32::MAX);
    guide
        .pixels
        .iter()
        .flat_map(|p| match p {
            Some(p) => [
                p.position.as_vec3().extend(1.0).to_array(),
                p.normal.as_vec3().extend(p.depth as f32).to_array(),
                [big(p.step[0]), big(p.step[1]), 0.0, 0.0],
            ],
            None => [[0.0; 4]; 3],
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::penumbra::blur::{self, tests};

    #[test]
    fn a_contact_stays_sharp_on_the_gpu_as_on_the_cpu() {
        let Some(gpu) = Gpu::shared_or_skip() else {
            return;
        };
        let (g, p) = (tests::flat(), Params::default());
        let (hard, own) = tests::contact();
        let edge = blur::edge_radius(&hard, &own, &g, &p);
        let radius = blur::spread_radius(&edge, Some(&own), &g, &p);
        let sharp = blur::sharp_pixels(&hard, blur::own_widths(&own, &p), &g, &p);
        let cpu = blur::blur(&hard, &radius, sharp.as_deref(), &g, &p);
        let mut blur = GpuBlur::new(gpu).expect("the blur's pipeline");
        let got = blur.soft(gpu, &hard, &own, &g, &p).expect("the GPU's blur");
        assert_eq!(got.len(), cpu.len());
        for (i, (a, b)) in got.iter().zip(&cpu).enumerate() {
            assert!((a - b).abs() < 1e-5, "pixel {i}: GPU {a}, CPU {b}");
        }
        // The cut is what keeps the lit side's first column at the rays' half or above.
        assert!(got[16] >= 0.5, "{}", got[16]);
        // A one-ray frame after it, on the same buffers: the mask the split frame left is
        // cleared (it uploads none of its own), so the contact is rounded as on the CPU.
        let one_ray = Params { split: 1, ..p };
        let radius = blur::spread_radius(&edge, None, &g, &one_ray);
        let cpu = blur::blur(&hard, &radius, None, &g, &one_ray);
        let got = blur
            .soft(gpu, &hard, &own, &g, &one_ray)
            .expect("the GPU's blur");
        for (i, (a, b)) in got.iter().zip(&cpu).enumerate() {
            assert!((a - b).abs() < 1e-5, "pixel {i}: GPU {a}, CPU {b}");
        }
        assert!(got[16] < 0.45, "{}", got[16]);
    }
}
