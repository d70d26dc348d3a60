//! GPU frames: the mesh rasterised with MSAA into an offscreen target, per vertex (the
//! compute pass's shading interpolated) or per pixel (LTC per pixel × the interpolated
//! per-vertex shadow ratios), read back into an [`Image`] of linear radiance (tone mapping is
//! the image's, as for the CPU's frames). `frame.wgsl`; the CPU twin is
//! [`crate::render::renderer::Renderer::bspvt`].

use anyhow::{Result, bail};
use bspvt_proto::Scene;
use glam::DMat4;

use super::context::Gpu;
use super::vertex::{VertexShader, ltc_buffer, supports};
use crate::frame::image::Image;
use crate::light::Light;
use crate::render::renderer::{FrameCounts, Mode, Renderer, Trees};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct FrameParams {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    light_normal: [f32; 4],
    radiance: [f32; 4],
    light: [[f32; 4]; 8],
    counts: [u32; 4],
}

/// The render target of one size.
struct Target {
    size: (u32, u32),
    colour: wgpu::Texture,
    resolve: Option<wgpu::Texture>,
    depth: wgpu::Texture,
    readback: wgpu::Buffer,
    row_bytes: u32,
}

/// BSPVT (and unshadowed LTC) frames on the GPU for one scene.
pub struct GpuFrames {
    shader: VertexShader,
    key: Option<u64>,
    pipeline: wgpu::RenderPipeline,
    params: wgpu::Buffer,
    indices: wgpu::Buffer,
    tri_material: wgpu::Buffer,
    materials: wgpu::Buffer,
    materials_key: Option<u64>,
    ltc: wgpu::Buffer,
    triangles: u32,
    samples: u32,
    target: Option<Target>,
}

/// The colour target's format: RGBA16F resolves with MSAA everywhere; RGBA32F without it.
fn colour_format(samples: u32) -> wgpu::TextureFormat {
    if samples > 1 {
        wgpu::TextureFormat::Rgba16Float
    } else {
        wgpu::TextureFormat::Rgba32Float
    }
}

impl GpuFrames {
    /// The pipelines and the scene's buffers; `samples`: MSAA samples per pixel (1 or 4).
    /// Scenes with textured materials are drawn on the CPU (the error says so).
    pub fn new(gpu: &Gpu, scene: &Scene, samples: u32) -> Result<GpuFrames> {
        use wgpu::util::DeviceExt;
        if scene.materials.iter().any(|m| m.maps.is_some()) {
            bail!("textured materials are drawn on the CPU");
        }
        if !matches!(samples, 1 | 4) {
            bail!("MSAA samples must be 1 or 4, not {samples}");
        }
        let mesh = &scene.mesh;
        let src = [include_str!("common.wgsl"), include_str!("frame.wgsl")].concat();
        let module = gpu.checked("frame.wgsl", || {
            gpu.device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("frame.wgsl"),
                    source: wgpu::ShaderSource::Wgsl(src.into()),
                })
        })?;
        let pipeline = gpu.checked("the frame pipeline", || {
            gpu.device
                .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some("bspvt frame"),
                    layout: None,
                    vertex: wgpu::VertexState {
                        module: &module,
                        entry_point: Some("vs"),
                        compilation_options: Default::default(),
                        buffers: &[],
                    },
                    primitive: wgpu::PrimitiveState::default(),
                    depth_stencil: Some(wgpu::DepthStencilState {
                        format: wgpu::TextureFormat::Depth32Float,
                        depth_write_enabled: Some(true),
                        depth_compare: Some(wgpu::CompareFunction::Less),
                        stencil: Default::default(),
                        bias: Default::default(),
                    }),
                    multisample: wgpu::MultisampleState {
                        count: samples,
                        ..Default::default()
                    },
                    fragment: Some(wgpu::FragmentState {
                        module: &module,
                        entry_point: Some("fs"),
                        compilation_options: Default::default(),
                        targets: &[Some(colour_format(samples).into())],
                    }),
                    multiview_mask: None,
                    cache: None,
                })
        })?;
        let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
        let tri_material: Vec<u32> = (0..mesh.triangles.len())
            .map(|t| mesh.material_ids.get(t).copied().unwrap_or(0))
            .collect();
        let init = |label: &str, bytes: &[u8], usage: wgpu::BufferUsages| {
            let mut padded = bytes.to_vec();
            padded.resize(bytes.len().max(16), 0);
            gpu.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: &padded,
                    usage: usage | wgpu::BufferUsages::COPY_DST,
                })
        };
        use wgpu::BufferUsages as U;
        Ok(GpuFrames {
            shader: VertexShader::new(gpu, mesh.vertex_count())?,
            key: None,
            pipeline,
            params: init(
                "frame params",
                bytemuck::bytes_of(&<FrameParams as bytemuck::Zeroable>::zeroed()),
                U::UNIFORM,
            ),
            indices: init("indices", bytemuck::cast_slice(&indices), U::STORAGE),
            tri_material: init(
                "triangle materials",
                bytemuck::cast_slice(&tri_material),
                U::STORAGE,
            ),
            materials: init(
                "materials",
                &vec![0; 32 * scene.materials.len().max(1)],
                U::STORAGE,
            ),
            materials_key: None,
            ltc: ltc_buffer(gpu),
            triangles: mesh.triangles.len() as u32,
            samples,
            target: None,
        })
    }

    /// Vertices whose trees are on the GPU.
    pub fn trees_uploaded(&self) -> usize {
        self.shader.trees.uploaded()
    }

    fn target(&mut self, gpu: &Gpu, w: u32, h: u32) -> &Target {
        if self.target.as_ref().is_none_or(|t| t.size != (w, h)) {
            let size = wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            };
            let tex = |label: &str, format, samples, usage| {
                gpu.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size,
                    mip_level_count: 1,
                    sample_count: samples,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage,
                    view_formats: &[],
                })
            };
            use wgpu::TextureUsages as T;
            let fmt = colour_format(self.samples);
            let (colour, resolve) = if self.samples > 1 {
                (
                    tex("msaa colour", fmt, self.samples, T::RENDER_ATTACHMENT),
                    Some(tex("colour", fmt, 1, T::RENDER_ATTACHMENT | T::COPY_SRC)),
                )
            } else {
                (
                    tex("colour", fmt, 1, T::RENDER_ATTACHMENT | T::COPY_SRC),
                    None,
                )
            };
            let texel = if self.samples > 1 { 8 } else { 16 };
            let row_bytes = (w * texel).div_ceil(256) * 256;
            self.target = Some(Target {
                size: (w, h),
                colour,
                resolve,
                depth: tex(
                    "depth",
                    wgpu::TextureFormat::Depth32Float,
                    self.samples,
                    T::RENDER_ATTACHMENT,
                ),
                readback: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("frame readback"),
                    size: u64::from(row_bytes) * u64::from(h),
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
                row_bytes,
            });
        }
        match &self.target {
            Some(t) => t,
            None => unreachable!("set above"),
        }
    }

    /// The per-vertex compute pass alone (for timing), waited for.
    pub fn shade_only(
        &mut self,
        gpu: &Gpu,
        renderer: &Renderer,
        light: &Light,
        trees: Option<&Trees>,
    ) -> Result<()> {
        let _queue = gpu.exclusive();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.shader
            .shade_renderer(gpu, &mut enc, renderer, &mut self.key, light, trees)?;
        gpu.queue.submit([enc.finish()]);
        gpu.wait()
    }

    /// One frame of `renderer`'s camera: BSPVT with `trees` (`None`: unshadowed LTC) in
    /// `mode`, read back as linear radiance.
    pub fn frame(
        &mut self,
        gpu: &Gpu,
        renderer: &Renderer,
        light: &Light,
        trees: Option<&Trees>,
        mode: Mode,
    ) -> Result<(Image, FrameCounts)> {
        supports(light)?;
        let _queue = gpu.exclusive();
        let view = &renderer.view;
        let (w, h) = (view.width, view.height);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.shader
            .shade_renderer(gpu, &mut enc, renderer, &mut self.key, light, trees)?;
        let mkey = renderer.shading_key();
        if self.materials_key != Some(mkey) {
            let m: Vec<[f32; 4]> = renderer
                .materials()
                .iter()
                .flat_map(|m| {
                    [
                        [m.albedo[0], m.albedo[1], m.albedo[2], m.roughness],
                        [m.specular[0], m.specular[1], m.specular[2], 0.0],
                    ]
                })
                .collect();
            gpu.queue
                .write_buffer(&self.materials, 0, bytemuck::cast_slice(&m));
            self.materials_key = Some(mkey);
        }
        let mut params = FrameParams {
            view_proj: view_proj(renderer).to_cols_array_2d(),
            eye: view.eye.as_vec3().extend(1.0).to_array(),
            light_normal: light
                .normal
                .as_vec3()
                .extend(if light.two_sided { 1.0 } else { 0.0 })
                .to_array(),
            radiance: light.radiance.as_vec3().extend(0.0).to_array(),
            light: [[0.0; 4]; 8],
            counts: [
                light.vertices.len() as u32,
                u32::from(mode == Mode::Pixel),
                crate::ltc::table::LtcTable::builtin().size() as u32,
                renderer.materials().len() as u32,
            ],
        };
        if !light.vertices.iter().all(|v| v.is_finite()) || !light.radiance.is_finite() {
            params.counts[0] = 0;
        }
        for (k, v) in light.vertices.iter().enumerate().take(8) {
            params.light[k] = v.as_vec3().extend(1.0).to_array();
        }
        gpu.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let layout = self.pipeline.get_bind_group_layout(0);
        let buffers = [
            &self.params,
            &self.shader.verts,
            &self.indices,
            &self.tri_material,
            &self.materials,
            &self.shader.out,
            &self.ltc,
        ];
        let group = gpu.bind_buffers("bspvt frame", &layout, &buffers);
        let triangles = self.triangles;
        let pipeline = self.pipeline.clone();
        let half = self.samples > 1;
        let t = self.target(gpu, w, h);
        let colour_view = t.colour.create_view(&Default::default());
        let resolve_view = t
            .resolve
            .as_ref()
            .map(|r| r.create_view(&Default::default()));
        let depth_view = t.depth.create_view(&Default::default());
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("bspvt frame"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &colour_view,
                    depth_slice: None,
                    resolve_target: resolve_view.as_ref(),
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.draw(0..triangles * 3, 0..1);
        }
        let src = t.resolve.as_ref().unwrap_or(&t.colour);
        enc.copy_texture_to_buffer(
            src.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &t.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(t.row_bytes),
                    rows_per_image: None,
                },
            },
            src.size(),
        );
        gpu.queue.submit([enc.finish()]);
        let bytes = gpu.map_read(&t.readback)?;
        let mut img = Image::new(w, h);
        for (y, row) in bytes
            .chunks(t.row_bytes as usize)
            .take(h as usize)
            .enumerate()
        {
            for x in 0..w as usize {
                let px = &mut img.pixels[y * w as usize + x];
                *px = if half {
                    std::array::from_fn(|c| {
                        let o = x * 8 + c * 2;
                        f16_to_f32(u16::from_le_bytes([row[o], row[o + 1]]))
                    })
                } else {
                    std::array::from_fn(|c| {
                        let o = x * 16 + c * 4;
                        f32::from_le_bytes([row[o], row[o + 1], row[o + 2], row[o + 3]])
                    })
                };
            }
        }
        let counts = FrameCounts {
            vertices_shaded: renderer.visible_vertices.len(),
            pixels_shaded: if mode == Mode::Pixel {
                renderer.gbuffer.covered()
            } else {
                0
            },
            ..FrameCounts::default()
        };
        Ok((img, counts))
    }
}

/// The camera's world → clip matrix, matching [`crate::frame::camera::View`]'s rays (wgpu's
/// clip space: depth in [0, 1], y up).
fn view_proj(r: &Renderer) -> glam::Mat4 {
    let v = &r.view;
    // World → camera (x right, y up, looking down −z).
    let (r_, u_, f_) = (v.right, v.up, v.forward);
    let look = DMat4::from_cols(
        glam::DVec4::new(r_.x, u_.x, -f_.x, 0.0),
        glam::DVec4::new(r_.y, u_.y, -f_.y, 0.0),
        glam::DVec4::new(r_.z, u_.z, -f_.z, 0.0),
        glam::DVec4::new(-r_.dot(v.eye), -u_.dot(v.eye), f_.dot(v.eye), 1.0),
    );
    let aspect = f64::from(v.width) / f64::from(v.height);
    let fy = 1.0 / v.tan_half_fov;
    // Near and far from the scene's extent seen from the eye.
    let mesh = &r.scene.mesh;
    let far = mesh
        .positions
        .iter()
        .map(|p| (p.as_dvec3() - v.eye).length())
        .fold(0.0, f64::max)
        .max(1e-3)
        * 1.01;
    let near = (far * 1e-5).max(1e-6);
    // Camera → clip, depth in [0, 1].
    let proj = DMat4::from_cols(
        glam::DVec4::new(fy / aspect, 0.0, 0.0, 0.0),
        glam::DVec4::new(0.0, fy, 0.0, 0.0),
        glam::DVec4::new(0.0, 0.0, far / (near - far), -1.0),
        glam::DVec4::new(0.0, 0.0, near * far / (near - far), 0.0),
    );
    (proj * look).as_mat4()
}

/// An IEEE half (the MSAA target's texels) as f32.
fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = i32::from((h >> 10) & 0x1f);
    let frac = f32::from(h & 0x3ff);
    match exp {
        0 => sign * frac * 2f32.powi(-24),
        31 => 0.0, // Inf / NaN: not radiance (the shader writes finite values)
        e => sign * (1.0 + frac / 1024.0) * 2f32.powi(e - 15),
    }
}
