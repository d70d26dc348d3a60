//! The sky's world-fixed cells per vertex on the GPU (`sky.wgsl`, issue 37 item 3; the CPU
//! twin is [`crate::render::sky_cells`]): one pass cuts every visible vertex's cells by its
//! sky trees into (D_c, ρ_c S_c) when the camera, the materials or the trees change; a frame
//! of a turning map is one more pass, two dot products per vertex with the cells' radiances.

use anyhow::{Result, bail};
use glam::DVec3;

use super::context::Gpu;
use super::trees::GpuTrees;
use super::vertex::{Params, VertexShader};
use crate::ltc::table::LtcTable;
use crate::render::renderer::{Renderer, Trees};
use crate::sky_cells::SkyCells;

/// The two pipelines of `sky.wgsl` (terms, gather).
fn pipelines(gpu: &Gpu) -> Result<(wgpu::ComputePipeline, wgpu::ComputePipeline)> {
    if let Some(p) = gpu.sky_pipelines.get() {
        return Ok(p.clone());
    }
    let made = gpu.checked("the sky's pipelines", || {
        let module = gpu
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("sky.wgsl"),
                source: wgpu::ShaderSource::Wgsl(bspvt_shaders::gpu::wgsl::sky().into()),
            });
        let entry = |name: &'static str| {
            gpu.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(name),
                    layout: None,
                    module: &module,
                    entry_point: Some(name),
                    compilation_options: Default::default(),
                    cache: None,
                })
        };
        (entry("sky_terms"), entry("sky_gather"))
    })?;
    Ok(gpu.sky_pipelines.get_or_init(|| made).clone())
}

/// Cells per invocation of `sky_terms` (the dispatch's y covers the rest): llvmpipe (lavapipe)
/// ends an invocation after 65,535 loop iterations in all, and one vertex's 288 cells cut by
/// its trees take more (measured: the terms of the last ~half of the cells came back zero).
const CELLS_PER_INVOCATION: u32 = 8;

fn storage(gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// Records a dispatch of `pipeline` over `groups` workgroups with the `(binding, buffer)`
/// pairs it reads (the entry points use some of the module's bindings each, so they are named).
fn dispatch(
    gpu: &Gpu,
    enc: &mut wgpu::CommandEncoder,
    pipeline: &wgpu::ComputePipeline,
    buffers: &[(u32, &wgpu::Buffer)],
    (x, y): (u32, u32),
) {
    let entries: Vec<wgpu::BindGroupEntry> = buffers
        .iter()
        .map(|&(binding, b)| wgpu::BindGroupEntry {
            binding,
            resource: b.as_entire_binding(),
        })
        .collect();
    let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    });
    let mut pass = enc.begin_compute_pass(&Default::default());
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, &group, &[]);
    pass.dispatch_workgroups(x, y, 1);
}

/// The sky's buffers for one scene: the cells, the sky trees, the terms kept between frames.
pub(crate) struct GpuSky {
    terms_pipeline: wgpu::ComputePipeline,
    gather_pipeline: wgpu::ComputePipeline,
    params: wgpu::Buffer,
    /// Four vec4 per cell: its corners, the first's w the count.
    cells: wgpu::Buffer,
    cell_count: u32,
    /// The bands `cells` holds (0: none yet).
    bands: usize,
    /// Per job and cell: (D_c, ρ_c S_c).
    terms: wgpu::Buffer,
    /// Per cell: this frame's radiance.
    radiance: wgpu::Buffer,
    trees: GpuTrees,
    /// What `terms` was made for.
    made_for: Option<TermsKey>,
}

/// The renderer's shading key, the trees' key, the bands.
type TermsKey = (u64, Option<(usize, usize, usize)>, usize);

impl GpuSky {
    /// Empty buffers for a mesh of `vertices` vertices (the pipelines compiled once per
    /// process).
    pub(crate) fn new(gpu: &Gpu, vertices: usize) -> Result<GpuSky> {
        let (terms_pipeline, gather_pipeline) = pipelines(gpu)?;
        Ok(GpuSky {
            terms_pipeline,
            gather_pipeline,
            params: storage(gpu, "sky params", std::mem::size_of::<Params>() as u64),
            cells: storage(gpu, "sky cells", 16),
            cell_count: 0,
            bands: 0,
            terms: storage(gpu, "sky terms", 16),
            radiance: storage(gpu, "sky radiance", 16),
            trees: GpuTrees::new(gpu, vertices),
            made_for: None,
        })
    }

    /// Records the sky's passes for `renderer`'s camera into `enc`, writing each job's
    /// radiance into `shader.out` (the vertex records and jobs already synced): the terms
    /// when what they depend on changed, then the gather with `radiance`, this frame's
    /// radiance of each of `cells` ([`SkyCells::radiance`]).
    pub(crate) fn encode(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        shader: &VertexShader,
        renderer: &Renderer,
        (cells, radiance): (&SkyCells, &[DVec3]),
        trees: Option<&Trees>,
    ) -> Result<()> {
        if self.bands != cells.bands() {
            let polys = &cells.grid().polys;
            let mut words = vec![[0f32; 4]; 4 * polys.len()];
            for (c, poly) in polys.iter().enumerate() {
                for (i, d) in poly.iter().enumerate() {
                    words[4 * c + i] = d.as_vec3().extend(0.0).to_array();
                }
                words[4 * c][3] = poly.len() as f32;
            }
            self.cells = storage(gpu, "sky cells", (words.len() * 16) as u64);
            gpu.queue
                .write_buffer(&self.cells, 0, bytemuck::cast_slice(&words));
            self.cell_count = polys.len() as u32;
            self.radiance = storage(gpu, "sky radiance", u64::from(self.cell_count) * 16);
            self.bands = cells.bands();
            self.made_for = None;
        }
        if radiance.len() != self.cell_count as usize {
            bail!(
                "{} cell radiances for {} sky cells",
                radiance.len(),
                self.cell_count
            );
        }
        let jobs = shader.jobs_len();
        let bytes = u64::from(jobs) * u64::from(self.cell_count) * 8;
        let limits = gpu.device.limits();
        let most = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if bytes > most {
            bail!(
                "the sky's cell terms need {} MiB for {jobs} vertices × {} cells, more than \
                 this GPU binds ({} MiB): lower --sky-cells or shade the sky on the CPU \
                 (--backend cpu)",
                bytes >> 20,
                self.cell_count,
                most >> 20
            );
        }
        if self.terms.size() < bytes {
            self.terms = storage(gpu, "sky terms", bytes);
            self.made_for = None;
        }
        self.trees.sync(gpu, trees);
        let params = Params {
            eye: renderer.view.eye.as_vec3().extend(1.0).to_array(),
            light: bytemuck::Zeroable::zeroed(),
            counts: [
                self.cell_count,
                jobs,
                self.trees.codec.0,
                LtcTable::builtin().size() as u32,
            ],
            codec: [self.trees.codec.1, 0.0, 0.0, 0.0],
        };
        gpu.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let l: Vec<[f32; 4]> = radiance
            .iter()
            .map(|l| l.as_vec3().extend(0.0).to_array())
            .collect();
        gpu.queue
            .write_buffer(&self.radiance, 0, bytemuck::cast_slice(&l));
        let made_for = (renderer.shading_key(), trees.map(Trees::key), self.bands);
        let groups = jobs.div_ceil(64);
        if self.made_for != Some(made_for) {
            dispatch(
                gpu,
                enc,
                &self.terms_pipeline,
                &[
                    (0, &self.params),
                    (1, &shader.verts),
                    (2, &shader.jobs),
                    (3, &self.trees.roots),
                    (4, &self.trees.nodes),
                    (5, &self.trees.line_normals),
                    (6, &shader.ltc),
                    (8, &shader.light_texture),
                    (9, &self.cells),
                    (10, &self.terms),
                ],
                (groups, self.cell_count.div_ceil(CELLS_PER_INVOCATION)),
            );
            self.made_for = Some(made_for);
        }
        dispatch(
            gpu,
            enc,
            &self.gather_pipeline,
            &[
                (0, &self.params),
                (1, &shader.verts),
                (2, &shader.jobs),
                (6, &shader.ltc),
                (7, &shader.out),
                (10, &self.terms),
                (11, &self.radiance),
            ],
            (groups, 1),
        );
        Ok(())
    }
}
