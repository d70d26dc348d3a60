//! The compute pass of BSPVT per-vertex shading (`shade.wgsl`: eq. 2 of paper 000 per vertex,
//! LTC GGX [Heitz16] per piece): buffers, pipeline, dispatch, read-back.

use anyhow::{Result, bail};
use bspvt_proto::bspvt::{LineCodec, VertexTrees};
use bspvt_proto::scene::Material;
use bspvt_shaders::gpu::{lights, records};
use glam::{DVec3, Vec3};

use super::context::Gpu;
use super::trees::GpuTrees;
use crate::light::{Light, Shape};
use crate::ltc::table::LtcTable;
use crate::render::renderer::Trees;

/// The per-vertex result, as the shader writes it (48 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuVertex {
    /// Shadowed radiance L ⊙ (albedo·D + spec·S).
    pub colour: [f32; 3],
    /// Non-zero when the walk ran out of room (the result is then incomplete).
    pub flags: f32,
    /// Shadowed / unshadowed per channel, diffuse (1 where the unshadowed value is 0).
    pub ratio_diffuse: [f32; 3],
    /// Pieces integrated (v̄ > 0).
    pub pieces: u32,
    /// Shadowed / unshadowed per channel, specular.
    pub ratio_specular: [f32; 3],
    /// Pieces dropped (v̄ = 0).
    pub dropped: u32,
}

impl GpuVertex {
    /// The shadow ratios as the CPU's [`crate::shade::ShadowRatio`].
    pub fn ratio(&self) -> crate::shade::ShadowRatio {
        [self.ratio_diffuse, self.ratio_specular]
    }
}

/// Bytes of one [`GpuVertex`].
const OUT_BYTES: u64 = std::mem::size_of::<GpuVertex>() as u64;

/// One point to shade: where, its unit normal and its material (textures already looked up).
#[derive(Clone, Debug)]
pub struct ShadePoint {
    /// Position.
    pub p: Vec3,
    /// Unit normal.
    pub n: Vec3,
    /// The material at the point.
    pub material: Material,
    /// Seen from behind (`Renderer::seen_from_behind`): shaded unshadowed, its trees being
    /// for its other side.
    pub behind: bool,
}

/// The vertex record of the shader (`bspvt_shaders::gpu::records`), without a UV.
pub(crate) fn vertex_record(p: &ShadePoint) -> [[f32; 4]; 4] {
    records::seen_from_behind(
        records::vertex_record(p.p, p.n, &p.material, None),
        p.behind,
    )
}

/// The light as the shaders read it (`bspvt_shaders::gpu::lights`).
pub(crate) type LightRecord = lights::LightRecord;

/// `light`'s record and its vertex count for the shaders (a round light: its polygon's
/// sides): 0 for a light that is not finite, which then sends nothing
/// (common.wgsl `light_directions`).
pub(crate) fn light_record(light: &Light) -> (LightRecord, u32) {
    let radiance = light.radiance.as_vec3();
    match &light.shape {
        Shape::Polygon => {
            let corners: Vec<Vec3> = light.vertices.iter().map(|v| v.as_vec3()).collect();
            lights::polygon(
                &corners,
                light.normal.as_vec3(),
                radiance,
                light.two_sided,
                light.texture.is_some(),
            )
        }
        Shape::Sphere(l) => lights::sphere(l, radiance),
        Shape::Distant { toward, half_angle } => {
            lights::sun(toward.as_vec3(), *half_angle as f32, radiance)
        }
    }
}

/// `shade.wgsl`'s parameters (also the sky's, `sky.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Params {
    pub(crate) eye: [f32; 4],
    pub(crate) light: LightRecord,
    /// Light vertices (the sky: cells), jobs, the codec's offsets, the LTC table's size.
    pub(crate) counts: [u32; 4],
    /// x: the codec's half step.
    pub(crate) codec: [f32; 4],
}

/// Whether the GPU shades this light: a polygon of at most 8 vertices, a point or spot
/// light's sphere, a sun's disk.
pub(crate) fn supports(light: &Light) -> Result<()> {
    if light.is_polygon() && light.vertices.len() > 8 {
        bail!("lights of more than 8 vertices are shaded on the CPU");
    }
    Ok(())
}

/// The LTC table as the shaders read it: two vec4 per node (ltc::table::LtcTable::gpu_nodes).
pub(crate) fn ltc_buffer(gpu: &Gpu) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    let nodes = LtcTable::builtin().gpu_nodes();
    gpu.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ltc table"),
            contents: bytemuck::cast_slice(&nodes),
            usage: wgpu::BufferUsages::STORAGE,
        })
}

/// The compute pipeline and its buffers for a mesh of `vertices` vertices.
pub struct VertexShader {
    pipeline: wgpu::ComputePipeline,
    params: wgpu::Buffer,
    pub(crate) ltc: wgpu::Buffer,
    pub(crate) verts: wgpu::Buffer,
    pub(crate) jobs: wgpu::Buffer,
    jobs_len: u32,
    /// The results, indexed by vertex (also the raster pass's per-vertex attributes).
    pub(crate) out: wgpu::Buffer,
    pub(crate) trees: GpuTrees,
    /// The light's texture as `common.wgsl` reads it, and which texture it holds (the
    /// address of the light's shared pyramid; `None`: the placeholder of untextured lights).
    pub(crate) light_texture: wgpu::Buffer,
    light_texture_of: Option<usize>,
    vertices: usize,
}

/// The compute pipeline of `shade.wgsl`.
fn pipeline(gpu: &Gpu) -> wgpu::ComputePipeline {
    let src = bspvt_shaders::gpu::wgsl::shade();
    let module = gpu
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shade.wgsl"),
            source: wgpu::ShaderSource::Wgsl(src.into()),
        });
    gpu.device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("bspvt per vertex"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        })
}

fn buffer(gpu: &Gpu, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage: usage | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

impl VertexShader {
    /// The pipeline (the shader compiled) and empty buffers for `vertices` vertices.
    pub fn new(gpu: &Gpu, vertices: usize) -> Result<VertexShader> {
        let pipeline = match gpu.shade_pipeline.get() {
            Some(p) => p.clone(),
            None => {
                let p = gpu.checked("the per-vertex shading pipeline", || pipeline(gpu))?;
                gpu.shade_pipeline.get_or_init(|| p).clone()
            }
        };
        let n = vertices as u64;
        use wgpu::BufferUsages as U;
        Ok(VertexShader {
            pipeline,
            params: buffer(
                gpu,
                "params",
                std::mem::size_of::<Params>() as u64,
                U::STORAGE,
            ),
            ltc: ltc_buffer(gpu),
            verts: buffer(gpu, "vertices", n * 64, U::STORAGE),
            jobs: buffer(gpu, "jobs", n * 4, U::STORAGE),
            jobs_len: 0,
            out: buffer(
                gpu,
                "per-vertex shading",
                n * OUT_BYTES,
                U::STORAGE | U::COPY_SRC,
            ),
            trees: GpuTrees::new(gpu, vertices),
            light_texture: buffer(gpu, "light texture", 16, U::STORAGE),
            light_texture_of: None,
            vertices,
        })
    }

    /// Sets the vertex records (positions, normals, materials).
    pub(crate) fn set_vertices(&mut self, gpu: &Gpu, records: &[[[f32; 4]; 4]]) {
        let n = records.len().min(self.vertices);
        gpu.queue
            .write_buffer(&self.verts, 0, bytemuck::cast_slice(&records[..n]));
    }

    /// Sets the vertices to shade (the visible ones).
    pub(crate) fn set_jobs(&mut self, gpu: &Gpu, jobs: &[u32]) {
        let jobs: Vec<u32> = jobs
            .iter()
            .copied()
            .filter(|&v| (v as usize) < self.vertices)
            .collect();
        gpu.queue
            .write_buffer(&self.jobs, 0, bytemuck::cast_slice(&jobs));
        self.jobs_len = jobs.len() as u32;
    }

    /// The vertices to shade (the jobs' count).
    pub(crate) fn jobs_len(&self) -> u32 {
        self.jobs_len
    }

    /// Uploads the trees that arrived since the last call ([`GpuTrees::sync`]).
    pub(crate) fn sync_trees(&mut self, gpu: &Gpu, trees: Option<&Trees>) {
        self.trees.sync(gpu, trees);
    }

    /// Uploads `light`'s texture unless it is the one already there (the same shared
    /// pyramid: a moving light keeps its texture).
    pub(crate) fn sync_light_texture(&mut self, gpu: &Gpu, light: &Light) {
        let Some(t) = &light.texture else {
            return;
        };
        let id = std::sync::Arc::as_ptr(t) as usize;
        if self.light_texture_of == Some(id) {
            return;
        }
        use wgpu::util::DeviceExt;
        self.light_texture = gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("light texture"),
                contents: bytemuck::cast_slice(&t.gpu_words()),
                usage: wgpu::BufferUsages::STORAGE,
            });
        self.light_texture_of = Some(id);
    }

    /// Records the pass for `light` seen from `eye` into `enc`.
    pub(crate) fn encode(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        light: &Light,
        eye: DVec3,
    ) -> Result<()> {
        supports(light)?;
        self.sync_light_texture(gpu, light);
        let (record, count) = light_record(light);
        let params = Params {
            eye: eye.as_vec3().extend(1.0).to_array(),
            light: record,
            counts: [
                count,
                self.jobs_len,
                self.trees.codec.0,
                LtcTable::builtin().size() as u32,
            ],
            codec: [self.trees.codec.1, 0.0, 0.0, 0.0],
        };
        gpu.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let layout = self.pipeline.get_bind_group_layout(0);
        let entries = [
            &self.params,
            &self.verts,
            &self.jobs,
            &self.trees.roots,
            &self.trees.nodes,
            &self.trees.line_normals,
            &self.ltc,
            &self.out,
            &self.light_texture,
        ];
        let group = gpu.bind_buffers("bspvt per vertex", &layout, &entries);
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(self.jobs_len.div_ceil(64), 1, 1);
        Ok(())
    }

    /// Shades the jobs and waits.
    pub(crate) fn run(&mut self, gpu: &Gpu, light: &Light, eye: DVec3) -> Result<()> {
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.encode(gpu, &mut enc, light, eye)?;
        gpu.queue.submit([enc.finish()]);
        gpu.wait()
    }

    /// The results of every vertex (those not shaded: what was there before).
    pub fn read(&self, gpu: &Gpu) -> Result<Vec<GpuVertex>> {
        let bytes = gpu.read_buffer(&self.out, self.vertices.max(1) as u64 * OUT_BYTES)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }
}

/// Shades `points` with `light` seen from `eye`, point i with `trees[i]` (the GPU side of
/// the CPU's [`crate::shade::bspvt::shade_vertex`], for tests and benchmarks).
pub fn shade_points(
    gpu: &Gpu,
    light: &Light,
    eye: DVec3,
    points: &[ShadePoint],
    trees: &[VertexTrees],
    codec: &LineCodec,
) -> Result<Vec<GpuVertex>> {
    let _queue = gpu.exclusive();
    let mut s = VertexShader::new(gpu, points.len())?;
    let records: Vec<_> = points.iter().map(vertex_record).collect();
    s.set_vertices(gpu, &records);
    let jobs: Vec<u32> = (0..points.len() as u32).collect();
    s.set_jobs(gpu, &jobs);
    s.sync_trees(gpu, Some(&Trees::full(trees, codec.clone())));
    s.run(gpu, light, eye)?;
    let mut out = s.read(gpu)?;
    out.truncate(points.len());
    Ok(out)
}

impl VertexShader {
    /// Shades the vertices `renderer` sees with `light` and `trees` (uploading the vertex
    /// records when the camera or the materials changed — `key`, the renderer's shading key
    /// of the last upload — and the trees that arrived since the last call).
    pub(crate) fn shade_renderer(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        renderer: &crate::render::renderer::Renderer,
        key: &mut Option<u64>,
        light: &Light,
        trees: Option<&Trees>,
    ) -> Result<()> {
        self.sync_renderer(gpu, renderer, key);
        self.sync_trees(gpu, trees);
        self.encode(gpu, enc, light, renderer.view.eye)
    }

    /// Uploads the vertex records and the jobs when the camera or the materials changed
    /// (`key`: the renderer's shading key of the last upload).
    pub(crate) fn sync_renderer(
        &mut self,
        gpu: &Gpu,
        renderer: &crate::render::renderer::Renderer,
        key: &mut Option<u64>,
    ) {
        let k = renderer.shading_key();
        if *key != Some(k) {
            let records: Vec<_> = (0..self.vertices as u32)
                .map(|v| {
                    let (p, n, m) = renderer.vertex_surface(v);
                    let uv = renderer.scene.mesh.uvs.get(v as usize).copied();
                    let r = records::vertex_record(p.as_vec3(), n.as_vec3(), &m, uv);
                    records::seen_from_behind(r, renderer.seen_from_behind(v))
                })
                .collect();
            self.set_vertices(gpu, &records);
            self.set_jobs(gpu, &renderer.gpu_shaded_vertices());
            *key = Some(k);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bspvt_shaders::gpu::wgsl;
    use wgpu::util::DeviceExt;

    use crate::frame::gbuffer::NONE;
    use crate::render::renderer::Renderer;

    /// `sides.wgsl`'s vote (the browser viewer's, on a visibility buffer) over the CPU
    /// G-buffer's triangle ids: which vertices of `r`'s frame are seen from behind.
    fn gpu_sides(gpu: &Gpu, r: &Renderer) -> Result<Vec<bool>> {
        let d = &gpu.device;
        let mesh = &r.scene.mesh;
        let n = mesh.vertex_count();
        let (w, h) = (r.gbuffer.width, r.gbuffer.height);
        let ids: Vec<u16> = r
            .gbuffer
            .tri
            .iter()
            .flat_map(|&t| {
                let id = if t == NONE { 0 } else { t + 1 };
                [(id & 0xffff) as u16, (id >> 16) as u16]
            })
            .collect();
        let vis = d.create_texture_with_data(
            &gpu.queue,
            &wgpu::TextureDescriptor {
                label: Some("visibility"),
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rg16Uint,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(&ids),
        );
        let storage = |label: &str, bytes: &[u8]| {
            d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            })
        };
        let eye = r.view.eye.as_vec3();
        let mut params = [0u32; 8];
        params[..3].copy_from_slice(&eye.to_array().map(f32::to_bits));
        params[4..7].copy_from_slice(&[w, h, n as u32]);
        let params = storage("sides params", bytemuck::cast_slice(&params));
        let records: Vec<[[f32; 4]; 4]> = (0..n)
            .map(|v| {
                let p = mesh.positions[v];
                records::vertex_record(p, mesh.normals[v], &Material::default(), None)
            })
            .collect();
        let verts = storage("verts", bytemuck::cast_slice(&records));
        let tris = storage(
            "tris",
            bytemuck::cast_slice(&bspvt_shaders::gpu::records::triangles(mesh)),
        );
        let votes = storage("votes", &vec![0u8; 4 * n.max(4)]);
        let module = d.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("sides.wgsl"),
            source: wgpu::ShaderSource::Wgsl(wgsl::sides().into()),
        });
        let view = vis.create_view(&Default::default());
        let mut enc = d.create_command_encoder(&Default::default());
        for (entry, groups) in [
            ("vote", (w.div_ceil(8), h.div_ceil(8))),
            ("mark", ((n as u32).div_ceil(64), 1)),
        ] {
            let pipe = gpu.checked(entry, || {
                d.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: None,
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
            })?;
            // vote: the parameters, records, triangles, votes and the visibility buffer at 4;
            // mark: no triangles nor visibility buffer.
            let bufs: &[(u32, &wgpu::Buffer)] = if entry == "vote" {
                &[(0, &params), (1, &verts), (2, &tris), (3, &votes)]
            } else {
                &[(0, &params), (1, &verts), (3, &votes)]
            };
            let mut entries: Vec<_> = bufs
                .iter()
                .map(|&(binding, b)| wgpu::BindGroupEntry {
                    binding,
                    resource: b.as_entire_binding(),
                })
                .collect();
            if entry == "vote" {
                entries.push(wgpu::BindGroupEntry {
                    binding: 4,
                    resource: wgpu::BindingResource::TextureView(&view),
                });
            }
            let group = d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(entry),
                layout: &pipe.get_bind_group_layout(0),
                entries: &entries,
            });
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipe);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        gpu.queue.submit([enc.finish()]);
        let out: Vec<[[f32; 4]; 4]> =
            bytemuck::pod_collect_to_vec(&gpu.read_buffer(&verts, (n * 64) as u64)?);
        Ok(out.iter().map(|r| r[0][3] < 0.0).collect())
    }

    /// The browser's vote (`sides.wgsl`) marks the vertices the CPU's rule
    /// (`GBuffer::vertex_sides`) does, on the canopy's own camera (its board seen
    /// from below: some vertices behind) and from above (none).
    #[test]
    fn the_gpu_vote_marks_the_cpus_vertices() {
        let Some(gpu) = Gpu::shared_or_skip() else {
            return;
        };
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/rooms/canopy.gltf");
        let scene = bspvt_proto::Scene::from_mesh_path(&path).expect("canopy");
        let above = bspvt_proto::scene::Camera {
            position: [0.4, 2.5, 1.5],
            target: [0.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 45.0,
            aspect: None,
        };
        let mut behind = Vec::new();
        for camera in [scene.camera.clone(), above] {
            let r = Renderer::with_camera(&scene, &camera, 96, 64);
            let cpu: Vec<bool> = (0..scene.mesh.vertex_count() as u32)
                .map(|v| r.seen_from_behind(v))
                .collect();
            let got = gpu_sides(gpu, &r).expect("sides.wgsl");
            assert_eq!(got, cpu, "the GPU's vote against the CPU's");
            behind.push(cpu.iter().filter(|&&b| b).count());
        }
        eprintln!(
            "vertices seen from behind: from below {}, from above {}",
            behind[0], behind[1]
        );
        assert!(behind[0] > 0 && behind[1] == 0, "{behind:?}");
    }

    /// `common.wgsl`'s sin, cos, tan and atan for small angles (the round lights' polygons,
    /// whose solid angle goes as their square) against f64: a few ULP relative, from 1e-9 to
    /// past the series' ranges. (The builtins they replace were off by percents at 1e-5 on
    /// an NVIDIA H200, where Vulkan allows 2⁻¹¹ absolute, and lavapipe's atan by 1.5e-5 near
    /// 0.1; the H200's frames check the rest: docs/gpu.md.)
    #[test]
    fn small_angles_keep_their_relative_precision() {
        let Some(gpu) = Gpu::shared_or_skip() else {
            return;
        };
        let d = &gpu.device;
        let source = wgsl::shade()
            + "
@group(0) @binding(15) var<storage, read_write> small_io: array<vec4f>;
@compute @workgroup_size(64)
fn small_angles(@builtin(global_invocation_id) id: vec3u) {
    if id.x < arrayLength(&small_io) {
        let x = small_io[id.x].x;
        small_io[id.x] = vec4f(sin_rel(x), cos_rel(x), tan_rel(x), atan_rel(x));
    }
}
";
        let xs: Vec<f32> = (0..=100)
            .map(|k| 10f64.powf(-9.0 + k as f64 / 10.0) as f32)
            .flat_map(|x| [x, -x])
            .collect();
        let io: Vec<[f32; 4]> = xs.iter().map(|&x| [x, 0.0, 0.0, 0.0]).collect();
        let buffer = d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("small angles"),
            contents: bytemuck::cast_slice(&io),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        });
        let module = d.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("small angles"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipe = gpu
            .checked("small angles", || {
                d.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some("small angles"),
                    layout: None,
                    module: &module,
                    entry_point: Some("small_angles"),
                    compilation_options: Default::default(),
                    cache: None,
                })
            })
            .expect("the test shader compiles");
        let group = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("small angles"),
            layout: &pipe.get_bind_group_layout(0),
            entries: &[wgpu::BindGroupEntry {
                binding: 15,
                resource: buffer.as_entire_binding(),
            }],
        });
        let _queue = gpu.exclusive();
        let mut enc = d.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipe);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups((xs.len() as u32).div_ceil(64), 1, 1);
        }
        gpu.queue.submit([enc.finish()]);
        let out: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(
            &gpu.read_buffer(&buffer, (xs.len() * 16) as u64)
                .expect("read back"),
        );
        let mut worst = [0f64; 4];
        for (&x, o) in xs.iter().zip(&out) {
            let x = f64::from(x);
            let want = [x.sin(), x.cos(), x.tan(), x.atan()];
            for (k, (&got, w)) in o.iter().zip(want).enumerate() {
                let rel = (f64::from(got) - w).abs() / w.abs();
                worst[k] = worst[k].max(rel);
            }
        }
        eprintln!(
            "small angles, worst relative error: sin {:.2e}, cos {:.2e}, tan {:.2e}, atan {:.2e}",
            worst[0], worst[1], worst[2], worst[3]
        );
        // f32's ULP is 1.2e-7 relative: a few of them.
        assert!(worst.iter().all(|&e| e < 5e-7), "{worst:?}");
    }
}
