//! [`Occluder::first_hit`] for batches of segments in a wgpu compute shader (`first_hit.wgsl`):
//! the hard shadow rays of rt-penumbra (paper 003) on the GPU. The occluder's BVH, triangles and
//! cut-outs go up once ([`GpuFirstHit::new`]); per batch the segments go up (32 bytes each) and
//! one distance per segment comes back. The buffers of the last batch size are kept, so frames
//! of one size allocate nothing.

use std::sync::Mutex;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::Occluder;
use crate::gpu::{
    GpuError, bind_buffers, dispatch_grid, max_items, scope_result, storage_pipeline,
};
use crate::gpu_occluder::MeshBuffers;

/// A segment from `origin` along the unit `dir` up to `t_max` (as [`Occluder::first_hit`]
/// takes it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct Segment {
    origin: [f32; 3],
    t_max: f32,
    dir: [f32; 3],
    _pad: f32,
}

impl Segment {
    /// The segment from `origin` along unit `dir` up to distance `t_max`.
    pub fn new(origin: Vec3, dir: Vec3, t_max: f32) -> Segment {
        Segment {
            origin: origin.to_array(),
            t_max,
            dir: dir.to_array(),
            _pad: 0.0,
        }
    }

    /// Its closest hit on the CPU ([`Occluder::first_hit`]).
    pub fn first_hit(&self, occ: &Occluder) -> Option<f32> {
        occ.first_hit(self.origin.into(), self.dir.into(), self.t_max)
    }
}

const WORKGROUP: u32 = 64;

/// The buffers of batches of up to `capacity` segments, kept across calls (a frame's passes
/// cast batches of different sizes: all pixels, then the light's parts on a few of them).
struct Batch {
    capacity: usize,
    segments: wgpu::Buffer,
    hits: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// The batch's count and dispatch width (`first_hit.wgsl`'s shape), written per dispatch.
    shape: wgpu::Buffer,
    group: wgpu::BindGroup,
}

/// An occluder on the GPU for closest-hit queries.
pub struct GpuFirstHit {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    mesh: MeshBuffers,
    /// Segments per dispatch: the adapter's buffer and dispatch-size limits.
    max_segments: usize,
    batch: Mutex<Option<Batch>>,
}

impl GpuFirstHit {
    /// Uploads `occ`'s BVH, triangles and cut-outs and builds the pipeline (a device that
    /// refuses either is an error, not a panic).
    pub fn new(device: &wgpu::Device, occ: &Occluder) -> Result<GpuFirstHit, GpuError> {
        let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mesh = MeshBuffers::new(device, occ);
        let wgsl = [
            include_str!("cwbvh.wgsl"),
            include_str!("first_hit.wgsl"),
            crate::CUTOUT_WGSL,
        ]
        .concat();
        // Nodes, triangles, cut-outs, segments read; the hits written; the shape read.
        let read_only = [true, true, true, true, false, true];
        let (pipeline, layout) = storage_pipeline(device, "first hit", &wgsl, &read_only);
        let max_segments = max_items(device, 32, WORKGROUP);
        scope_result(validation)?;
        scope_result(memory)?;
        Ok(GpuFirstHit {
            pipeline,
            layout,
            mesh,
            max_segments,
            batch: Mutex::new(None),
        })
    }

    /// The closest hit of each segment (`None`: clear), as [`Occluder::first_hit`] answers it
    /// up to this device's rounding: a segment grazing an edge, or ending on a surface, may be
    /// answered otherwise. Waits for the queue.
    pub fn first_hits(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        segments: &[Segment],
    ) -> Result<Vec<Option<f32>>, GpuError> {
        let mut out = Vec::with_capacity(segments.len());
        for chunk in segments.chunks(self.max_segments.max(1)) {
            self.dispatch(device, queue, chunk, &mut out)?;
        }
        Ok(out)
    }

    fn dispatch(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        segments: &[Segment],
        out: &mut Vec<Option<f32>>,
    ) -> Result<(), GpuError> {
        let n = segments.len();
        if n == 0 {
            return Ok(());
        }
        let t0 = std::time::Instant::now();
        let mut batch = self.batch.lock().unwrap_or_else(|p| p.into_inner());
        let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        if batch.as_ref().is_none_or(|b| b.capacity < n) {
            // Room for a quarter more: growing batches do not reallocate every call.
            let capacity = (n + n / 4).min(self.max_segments.max(n));
            *batch = Some(self.batch(device, capacity));
        }
        let Some(b) = batch.as_ref() else {
            return Err(GpuError::Failed("no batch buffers".into()));
        };
        let groups = dispatch_grid(device, n as u32, WORKGROUP);
        queue.write_buffer(
            &b.shape,
            0,
            bytemuck::cast_slice(&[
                n as u32,
                groups.0 * WORKGROUP,
                self.mesh.box_t_min.to_bits(),
                0,
            ]),
        );
        queue.write_buffer(&b.segments, 0, bytemuck::cast_slice(segments));
        let bytes = (n * 4) as u64;
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("first hit"),
        });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("first hit"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &b.group, &[]);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        enc.copy_buffer_to_buffer(&b.hits, 0, &b.readback, 0, bytes);
        let t_upload = t0.elapsed();
        queue.submit([enc.finish()]);
        scope_result(validation)?;
        scope_result(memory)?;
        let (tx, rx) = std::sync::mpsc::channel();
        b.readback
            .map_async(wgpu::MapMode::Read, ..bytes, move |r| {
                let _ = tx.send(r);
            });
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Failed(e.to_string()))?;
        let t_cast = t0.elapsed();
        rx.recv()
            .map_err(|e| GpuError::Failed(e.to_string()))?
            .map_err(|e| GpuError::Failed(e.to_string()))?;
        {
            let view = b
                .readback
                .get_mapped_range(..bytes)
                .map_err(|e| GpuError::Failed(e.to_string()))?;
            out.extend(view.chunks_exact(4).map(|w| {
                let t = f32::from_le_bytes([w[0], w[1], w[2], w[3]]);
                (t >= 0.0).then_some(t)
            }));
        }
        b.readback.unmap();
        if std::env::var_os("BSPVT_GPU_TIMING").is_some() {
            // Where a batch's wall-clock time goes (docs/benchmarks.md, rt-penumbra on the GPU).
            let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
            eprintln!(
                "gpu first hits: {n} segments: buffers+upload {:.2} ms, submit..done {:.2} ms, read-back {:.2} ms",
                ms(t_upload),
                ms(t_cast - t_upload),
                ms(t0.elapsed() - t_cast)
            );
        }
        Ok(())
    }

    /// Buffers and bind group for batches of up to `n` segments.
    fn batch(&self, device: &wgpu::Device, n: usize) -> Batch {
        let buffer = |label: &str, size: u64, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as U;
        let segments = buffer("segments", (n * 32) as u64, U::STORAGE | U::COPY_DST);
        let hits = buffer("hits", (n * 4) as u64, U::STORAGE | U::COPY_SRC);
        let readback = buffer("hits readback", (n * 4) as u64, U::MAP_READ | U::COPY_DST);
        let shape = buffer("first hit shape", 16, U::STORAGE | U::COPY_DST);
        let group = bind_buffers(
            device,
            "first hit",
            &self.layout,
            &[
                &self.mesh.nodes,
                &self.mesh.tris,
                &self.mesh.cut,
                &segments,
                &hits,
                &shape,
            ],
        );
        Batch {
            capacity: n,
            segments,
            hits,
            readback,
            shape,
            group,
        }
    }
}
