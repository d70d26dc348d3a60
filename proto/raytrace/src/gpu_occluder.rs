//! [`Occluder`]'s any-hit queries in a wgpu compute shader (`occlusion.wgsl`): the CPU-built
//! CWBVH, its triangles and their vertex indices are uploaded once; batches of rays are cast and
//! answered as one occlusion flag each.

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::Occluder;
use crate::gpu::{GpuContext, GpuError};

/// Where a group of rays starts: shared by many rays (a vertex's cube map).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct RaySource {
    /// The rays' origin.
    pub origin: [f32; 3],
    /// Hits nearer than this are not counted.
    pub t_min: f32,
    /// Triangles using this vertex are skipped (`u32::MAX`: none).
    pub skip: u32,
    _pad: [u32; 3],
}

impl RaySource {
    /// Rays from `origin`, counting hits from `t_min` on, ignoring triangles that use `skip`.
    pub fn new(origin: glam::Vec3, t_min: f32, skip: u32) -> RaySource {
        RaySource {
            origin: origin.to_array(),
            t_min,
            skip,
            _pad: [0; 3],
        }
    }
}

/// One ray: a direction (unit) and the distance it ends at, from its source.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct GpuRay {
    /// Unit direction.
    pub dir: [f32; 3],
    /// Hits at this distance or beyond are not counted.
    pub t_max: f32,
}

const WORKGROUP: u32 = 64;

/// The error an error scope caught, if any.
fn scope_error(scope: wgpu::ErrorScopeGuard) -> Result<(), GpuError> {
    match crate::gpu::block_on(scope.pop()) {
        Some(e) => Err(GpuError::Failed(e.to_string())),
        None => Ok(()),
    }
}

/// An occluder on the GPU: [`Occluder::occluded_between`] for batches of rays.
pub struct GpuOccluder {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    nodes: wgpu::Buffer,
    tris: wgpu::Buffer,
    prim_verts: wgpu::Buffer,
    /// Rays per dispatch (buffer and dispatch-size limits).
    max_rays: usize,
}

impl GpuOccluder {
    /// Uploads `occ`'s BVH, triangles and vertex indices, and builds the pipeline (a device
    /// that refuses either is an error, not a panic).
    pub fn new(ctx: &GpuContext, occ: &Occluder) -> Result<GpuOccluder, GpuError> {
        let device = &ctx.device;
        let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let storage = |label: &str, contents: &[u8]| {
            // wgpu refuses empty buffers: pad to one word.
            let contents = if contents.is_empty() {
                &[0u8; 4]
            } else {
                contents
            };
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let nodes = storage("cwbvh nodes", bytemuck::cast_slice(&occ.bvh.nodes));
        let tri_words: Vec<f32> = occ
            .tris
            .iter()
            .flat_map(|t| {
                [t.v0, t.e1, t.e2, t.ng]
                    .into_iter()
                    .flat_map(|v| v.to_array())
            })
            .collect();
        let tris = storage("triangles", bytemuck::cast_slice(&tri_words));
        let prim_verts = storage("triangle vertices", bytemuck::cast_slice(&occ.indices));
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("occlusion.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("occlusion.wgsl").into()),
        });
        let entry = |binding: u32, ty: wgpu::BufferBindingType| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let read = wgpu::BufferBindingType::Storage { read_only: true };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("occlusion"),
            entries: &[
                entry(0, read),
                entry(1, read),
                entry(2, read),
                entry(3, read),
                entry(4, read),
                entry(5, read),
                entry(6, wgpu::BufferBindingType::Storage { read_only: false }),
                entry(7, wgpu::BufferBindingType::Uniform),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("occlusion"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("occlusion"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let limits = device.limits();
        let by_binding = limits.max_storage_buffer_binding_size as usize / 16;
        let by_dispatch = limits.max_compute_workgroups_per_dimension as usize
            * limits.max_compute_workgroups_per_dimension as usize
            * WORKGROUP as usize;
        let max_rays = by_binding
            .min(limits.max_buffer_size as usize / 16)
            .min(by_dispatch)
            .min(1 << 22);
        scope_error(validation)?;
        scope_error(memory)?;
        Ok(GpuOccluder {
            pipeline,
            layout,
            nodes,
            tris,
            prim_verts,
            max_rays,
        })
    }

    /// Whether each ray is occluded (1) or not (0): ray `i` leaves `sources[ray_source[i]]`.
    /// The answer of [`Occluder::occluded_between`] for the same ray, up to rays that graze a
    /// triangle's edge (the two machines may round such a hit either way).
    pub fn occluded(
        &self,
        ctx: &GpuContext,
        sources: &[RaySource],
        rays: &[GpuRay],
        ray_source: &[u32],
    ) -> Result<Vec<u32>, GpuError> {
        if rays.len() != ray_source.len() {
            return Err(GpuError::Failed(format!(
                "{} rays but {} source indices",
                rays.len(),
                ray_source.len()
            )));
        }
        if let Some(&bad) = ray_source.iter().find(|&&s| s as usize >= sources.len()) {
            return Err(GpuError::Failed(format!(
                "source {bad} of {} sources",
                sources.len()
            )));
        }
        let mut out = Vec::with_capacity(rays.len());
        for (r, s) in rays
            .chunks(self.max_rays)
            .zip(ray_source.chunks(self.max_rays))
        {
            out.extend(self.dispatch(ctx, sources, r, s)?);
        }
        Ok(out)
    }

    fn dispatch(
        &self,
        ctx: &GpuContext,
        sources: &[RaySource],
        rays: &[GpuRay],
        ray_source: &[u32],
    ) -> Result<Vec<u32>, GpuError> {
        let n = rays.len();
        if n == 0 {
            return Ok(Vec::new());
        }
        let device = &ctx.device;
        let t0 = std::time::Instant::now();
        let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let input = |label: &str, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let src = input("ray sources", bytemuck::cast_slice(sources));
        let ray_buf = input("rays", bytemuck::cast_slice(rays));
        let ray_src = input("ray source", bytemuck::cast_slice(ray_source));
        let bytes = (n * 4) as u64;
        let result = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("occluded"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("occluded readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let groups = (n as u32).div_ceil(WORKGROUP);
        let max_x = device.limits().max_compute_workgroups_per_dimension;
        let (gx, gy) = if groups <= max_x {
            (groups, 1)
        } else {
            (max_x, groups.div_ceil(max_x))
        };
        let params = [n as u32, gx * WORKGROUP, 0, 0];
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("occlusion params"),
            contents: bytemuck::cast_slice(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        fn bind(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            }
        }
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("occlusion"),
            layout: &self.layout,
            entries: &[
                bind(0, &self.nodes),
                bind(1, &self.tris),
                bind(2, &self.prim_verts),
                bind(3, &src),
                bind(4, &ray_buf),
                bind(5, &ray_src),
                bind(6, &result),
                bind(7, &uniform),
            ],
        });
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("occlusion"),
        });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("occlusion"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        enc.copy_buffer_to_buffer(&result, 0, &readback, 0, bytes);
        let t_upload = t0.elapsed();
        ctx.queue.submit([enc.finish()]);
        scope_error(validation)?;
        scope_error(memory)?;
        let (tx, rx) = std::sync::mpsc::channel();
        readback.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        ctx.wait()?;
        let t_cast = t0.elapsed();
        rx.recv()
            .map_err(|e| GpuError::Failed(e.to_string()))?
            .map_err(|e| GpuError::Failed(e.to_string()))?;
        let view = readback
            .get_mapped_range(..)
            .map_err(|e| GpuError::Failed(e.to_string()))?;
        let flags = bytemuck::cast_slice::<u8, u32>(&view).to_vec();
        drop(view);
        readback.unmap();
        if std::env::var_os("BSPVT_GPU_TIMING").is_some() {
            // Where a dispatch's wall-clock time goes (docs/benchmarks.md, the GPU bake).
            let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
            eprintln!(
                "gpu cast: {n} rays: buffers+upload {:.2} ms, submit..done {:.2} ms, read-back {:.2} ms",
                ms(t_upload),
                ms(t_cast - t_upload),
                ms(t0.elapsed() - t_cast)
            );
        }
        Ok(flags)
    }
}
