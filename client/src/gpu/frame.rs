//! GPU frames, deferred: the mesh rasterised (MSAA or not) into a visibility buffer of
//! triangle indices (`visibility.wgsl`), then a compute pass per pixel (`resolve.wgsl`) finds
//! each sample's surface as the CPU's G-buffer does (the primary ray against the triangle's
//! plane) and shades it per vertex (the compute pass's shading interpolated) or per pixel (LTC
//! per pixel × the interpolated per-vertex shadow ratios), into a buffer of linear radiance
//! read back as an [`Image`] (tone mapping is the image's, as for the CPU's frames). No
//! fragment shader carries the LTC integral: on lavapipe one did not finish compiling in ten
//! minutes, while the compute pass compiles in well under a second. The CPU twin is
//! [`crate::render::renderer::Renderer::bspvt`].

use anyhow::{Result, bail};
use bspvt_proto::Scene;
use glam::DMat4;

use bspvt_shaders::gpu::{materials, wgsl};

use super::context::{Gpu, buffer_entries};
use super::sky::GpuSky;
use super::timing::PassClock;
use super::vertex::{LightRecord, VertexShader, light_record, ltc_buffer, supports};
use crate::frame::image::Image;
use crate::light::Light;
use crate::render::renderer::{FrameCounts, Mode, Renderer, Trees};
use crate::sky_cells::SkyCells;

/// `visibility.wgsl`'s uniform.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct RasterParams {
    view_proj: [[f32; 4]; 4],
}

/// `resolve.wgsl`'s uniform.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ResolveParams {
    eye: [f32; 4],
    forward: [f32; 4],
    right: [f32; 4],
    up: [f32; 4],
    light: LightRecord,
    counts: [u32; 4],
    size: [u32; 4],
    /// x: 1 to add this light's frame to the image (the browser's several lights); here each
    /// light is a frame of its own, summed on the CPU.
    layer: [u32; 4],
}

/// The visibility buffer's format: triangle index + 1 in two 16-bit halves (Rg16Uint is
/// multisampled on every adapter; R32Uint is not).
const VISIBILITY: wgpu::TextureFormat = wgpu::TextureFormat::Rg16Uint;

/// The targets of one size.
struct Target {
    size: (u32, u32),
    visibility: wgpu::Texture,
    depth: wgpu::Texture,
    image: wgpu::Buffer,
    readback: wgpu::Buffer,
}

/// BSPVT (and unshadowed LTC) frames on the GPU for one scene.
pub struct GpuFrames {
    shader: VertexShader,
    key: Option<u64>,
    raster: wgpu::RenderPipeline,
    resolve: wgpu::ComputePipeline,
    raster_params: wgpu::Buffer,
    resolve_params: wgpu::Buffer,
    /// Per triangle: corners and material (`records::triangles`).
    tris: wgpu::Buffer,
    /// The scene's cut-outs by triangle, for the raster pass's alpha test.
    cut: wgpu::Buffer,
    materials: wgpu::Buffer,
    /// The textures the materials sample (`materials::tables`).
    surface_textures: wgpu::Buffer,
    /// Per vertex, where a material is normal-mapped: the unbent normal and the tangent
    /// (`records::tangent_frames`); one zero vec4 otherwise.
    frames: wgpu::Buffer,
    materials_key: Option<u64>,
    ltc: wgpu::Buffer,
    triangles: u32,
    samples: u32,
    target: Option<Target>,
    /// The sky's cells and terms (made on the first sky frame).
    sky: Option<GpuSky>,
    /// Timestamps between the passes, when asked for ([`GpuFrames::time_passes`]).
    clock: Option<PassClock>,
}

/// The raster and resolve pipelines for `samples` per pixel, compiled once per process.
fn pipelines(gpu: &Gpu, samples: u32) -> Result<(wgpu::RenderPipeline, wgpu::ComputePipeline)> {
    let mut cache = gpu
        .frame_pipelines
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some((_, r, c)) = cache.iter().find(|(s, _, _)| *s == samples) {
        return Ok((r.clone(), c.clone()));
    }
    let module = |label: &'static str, src: String| {
        gpu.checked(label, || {
            gpu.device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some(label),
                    source: wgpu::ShaderSource::Wgsl(src.into()),
                })
        })
    };
    let raster_module = module("visibility.wgsl", wgsl::visibility())?;
    let resolve_module = module("resolve.wgsl", wgsl::resolve(samples))?;
    let raster = gpu.checked("the visibility pipeline", || {
        gpu.device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("bspvt visibility"),
                layout: None,
                vertex: wgpu::VertexState {
                    module: &raster_module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                // Reversed Z (near → 1, infinity → 0): f32 depth keeps its precision
                // far from the eye.
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: wgpu::TextureFormat::Depth32Float,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Greater),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: wgpu::MultisampleState {
                    count: samples,
                    ..Default::default()
                },
                fragment: Some(wgpu::FragmentState {
                    module: &raster_module,
                    entry_point: Some("fs"),
                    compilation_options: Default::default(),
                    targets: &[Some(VISIBILITY.into())],
                }),
                multiview_mask: None,
                cache: None,
            })
    })?;
    let resolve = gpu.checked("the resolve pipeline", || {
        gpu.device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("bspvt resolve"),
                layout: None,
                module: &resolve_module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            })
    })?;
    cache.push((samples, raster.clone(), resolve.clone()));
    Ok((raster, resolve))
}

impl GpuFrames {
    /// The pipelines and the scene's buffers; `samples`: MSAA samples per pixel (1 or 4).
    pub fn new(gpu: &Gpu, scene: &Scene, samples: u32) -> Result<GpuFrames> {
        use wgpu::util::DeviceExt;
        if !matches!(samples, 1 | 4) {
            bail!("MSAA samples must be 1 or 4, not {samples}");
        }
        let mesh = &scene.mesh;
        let uvs = mesh.uvs.len() == mesh.vertex_count();
        let (raster, resolve) = pipelines(gpu, samples)?;
        let tris = bspvt_shaders::gpu::records::triangles(mesh);
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
            raster,
            resolve,
            raster_params: init(
                "raster params",
                bytemuck::bytes_of(&<RasterParams as bytemuck::Zeroable>::zeroed()),
                U::STORAGE,
            ),
            resolve_params: init(
                "resolve params",
                bytemuck::bytes_of(&<ResolveParams as bytemuck::Zeroable>::zeroed()),
                U::STORAGE,
            ),
            tris: init("triangles", bytemuck::cast_slice(&tris), U::STORAGE),
            cut: init(
                "cut-outs",
                bytemuck::cast_slice(
                    &bspvt_raytrace::Cutouts::of(mesh, &scene.materials)
                        .map_or(vec![0u32], |c| c.gpu_words_by_triangle()),
                ),
                U::STORAGE,
            ),
            materials: init(
                "materials",
                &vec![0; 16 * materials::RECORDS * scene.materials.len().max(1)],
                U::STORAGE,
            ),
            frames: init(
                "tangent frames",
                bytemuck::cast_slice(&bspvt_shaders::gpu::records::tangent_frames(
                    mesh,
                    crate::frame::normal_map::NormalMaps::of(mesh, &scene.materials).as_deref(),
                )),
                U::STORAGE,
            ),
            surface_textures: init(
                "surface textures",
                bytemuck::cast_slice(&materials::tables(&scene.materials, uvs, true).1),
                U::STORAGE,
            ),
            materials_key: None,
            ltc: ltc_buffer(gpu),
            triangles: mesh.triangles.len() as u32,
            samples,
            target: None,
            sky: None,
            clock: None,
        })
    }

    /// Times each pass of the frames that follow on the GPU (`bench-gpu`): false where the
    /// device cannot write timestamps between passes.
    pub fn time_passes(&mut self, gpu: &Gpu) -> bool {
        PassClock::ensure(&mut self.clock, gpu)
    }

    /// The last frame's GPU time per pass (`shade`, `raster`, `resolve`; `sky` for the sky's),
    /// ms, after [`GpuFrames::time_passes`]; waits for the frame.
    pub fn pass_times(&self, gpu: &Gpu) -> Result<Vec<(&'static str, f64)>> {
        PassClock::read_slot(self.clock.as_ref(), gpu)
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
            let tex = |label: &str, format, usage| {
                gpu.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size,
                    mip_level_count: 1,
                    sample_count: self.samples,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage,
                    view_formats: &[],
                })
            };
            use wgpu::TextureUsages as T;
            let bytes = u64::from(w) * u64::from(h) * 16;
            let buffer = |label: &str, usage| {
                gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes,
                    usage,
                    mapped_at_creation: false,
                })
            };
            use wgpu::BufferUsages as U;
            self.target = Some(Target {
                size: (w, h),
                visibility: tex(
                    "visibility",
                    VISIBILITY,
                    T::RENDER_ATTACHMENT | T::TEXTURE_BINDING,
                ),
                depth: tex(
                    "depth",
                    wgpu::TextureFormat::Depth32Float,
                    T::RENDER_ATTACHMENT,
                ),
                image: buffer("frame", U::STORAGE | U::COPY_SRC),
                readback: buffer("frame readback", U::MAP_READ | U::COPY_DST),
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
        let _queue = gpu.exclusive();
        let (mut enc, counts) = self.encode(gpu, renderer, light, trees, mode)?;
        let t = self.made_target()?;
        enc.copy_buffer_to_buffer(&t.image, 0, &t.readback, 0, t.image.size());
        if let Some(c) = &self.clock {
            c.resolve(&mut enc);
        }
        gpu.queue.submit([enc.finish()]);
        let bytes = gpu.map_read(&t.readback)?;
        Ok((image_from_bytes(t.size, &bytes), counts))
    }

    /// The same frame left on the GPU (submitted, not waited for): what a window presents
    /// without reading 16 bytes per pixel back ([`super::present`]).
    pub fn frame_on_gpu(
        &mut self,
        gpu: &Gpu,
        renderer: &Renderer,
        light: &Light,
        trees: Option<&Trees>,
        mode: Mode,
    ) -> Result<(GpuImage, FrameCounts)> {
        let _queue = gpu.exclusive();
        let (mut enc, counts) = self.encode(gpu, renderer, light, trees, mode)?;
        if let Some(c) = &self.clock {
            c.resolve(&mut enc);
        }
        gpu.queue.submit([enc.finish()]);
        let t = self.made_target()?;
        Ok((
            GpuImage {
                buffer: t.image.clone(),
                width: t.size.0,
                height: t.size.1,
            },
            counts,
        ))
    }

    /// The target [`GpuFrames::encode`] drew into.
    fn made_target(&self) -> Result<&Target> {
        match &self.target {
            Some(t) => Ok(t),
            None => bail!("the frame's target was not made"),
        }
    }

    /// Records a frame's passes (per-vertex shading, visibility raster, resolve) into the
    /// target's radiance buffer; the caller holds the queue.
    fn encode(
        &mut self,
        gpu: &Gpu,
        renderer: &Renderer,
        light: &Light,
        trees: Option<&Trees>,
        mode: Mode,
    ) -> Result<(wgpu::CommandEncoder, FrameCounts)> {
        supports(light)?;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        if let Some(c) = &mut self.clock {
            c.start(&mut enc);
        }
        self.shader
            .shade_renderer(gpu, &mut enc, renderer, &mut self.key, light, trees)?;
        if let Some(c) = &mut self.clock {
            c.mark(&mut enc, "shade");
        }
        let counts = self.draw(gpu, &mut enc, renderer, light_record(light), mode);
        Ok((enc, counts))
    }

    /// One per-vertex frame of the sky in `cells` with this frame's cell radiances
    /// `radiance` ([`SkyCells::radiance`]) through the sky's `trees` (vertices without theirs
    /// unshadowed), read back as linear radiance; the terms are kept while the camera, the
    /// materials and the trees stay ([`crate::render::sky_cells`] is the CPU's).
    pub fn sky_frame(
        &mut self,
        gpu: &Gpu,
        renderer: &Renderer,
        cells: &SkyCells,
        radiance: &[glam::DVec3],
        trees: Option<&Trees>,
    ) -> Result<(Image, FrameCounts)> {
        let _queue = gpu.exclusive();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        if let Some(c) = &mut self.clock {
            c.start(&mut enc);
        }
        self.shader.sync_renderer(gpu, renderer, &mut self.key);
        let sky = match &mut self.sky {
            Some(s) => s,
            None => self
                .sky
                .insert(GpuSky::new(gpu, renderer.scene.mesh.vertex_count())?),
        };
        sky.encode(
            gpu,
            &mut enc,
            &self.shader,
            renderer,
            (cells, radiance),
            trees,
        )?;
        if let Some(c) = &mut self.clock {
            c.mark(&mut enc, "sky");
        }
        let none = (bytemuck::Zeroable::zeroed(), 0);
        let counts = self.draw(gpu, &mut enc, renderer, none, Mode::Vertex);
        let t = self.made_target()?;
        enc.copy_buffer_to_buffer(&t.image, 0, &t.readback, 0, t.image.size());
        if let Some(c) = &self.clock {
            c.resolve(&mut enc);
        }
        gpu.queue.submit([enc.finish()]);
        let bytes = gpu.map_read(&t.readback)?;
        Ok((image_from_bytes(t.size, &bytes), counts))
    }

    /// Records the raster and resolve passes over the per-vertex results into the target's
    /// radiance buffer, with the light `(record, count)` for per-pixel shading.
    fn draw(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        renderer: &Renderer,
        (record, count): (LightRecord, u32),
        mode: Mode,
    ) -> FrameCounts {
        let view = &renderer.view;
        let (w, h) = (view.width, view.height);
        let mkey = renderer.shading_key();
        if self.materials_key != Some(mkey) {
            let mesh = &renderer.scene.mesh;
            let uvs = mesh.uvs.len() == mesh.vertex_count();
            let (m, _) = materials::tables(renderer.materials(), uvs, false);
            gpu.queue
                .write_buffer(&self.materials, 0, bytemuck::cast_slice(&m));
            self.materials_key = Some(mkey);
        }
        let raster = RasterParams {
            view_proj: view_proj(renderer).to_cols_array_2d(),
        };
        gpu.queue
            .write_buffer(&self.raster_params, 0, bytemuck::bytes_of(&raster));
        let v3 = |v: glam::DVec3, w: f64| v.as_vec3().extend(w as f32).to_array();
        let resolve = ResolveParams {
            eye: v3(view.eye, view.tan_half_fov),
            forward: v3(view.forward, f64::from(w) / f64::from(h)),
            right: v3(view.right, 0.0),
            up: v3(view.up, 0.0),
            light: record,
            counts: [
                count,
                u32::from(mode == Mode::Pixel),
                crate::ltc::table::LtcTable::builtin().size() as u32,
                renderer.materials().len() as u32,
            ],
            // The roughness override's bits (0: none), applied after a texture lookup.
            size: [
                w,
                h,
                self.samples,
                renderer.roughness_override().map_or(0, f32::to_bits),
            ],
            layer: [0; 4],
        };
        gpu.queue
            .write_buffer(&self.resolve_params, 0, bytemuck::bytes_of(&resolve));
        let raster_group = gpu.bind_buffers(
            "bspvt visibility",
            &self.raster.get_bind_group_layout(0),
            &[
                &self.raster_params,
                &self.shader.verts,
                &self.tris,
                &self.cut,
            ],
        );
        let triangles = self.triangles;
        // Out while the target is borrowed; back after the last pass.
        let mut clock = self.clock.take();
        let (raster, resolve) = (self.raster.clone(), self.resolve.clone());
        let buffers = [
            &self.resolve_params,
            &self.shader.verts,
            &self.tris,
            &self.materials,
            &self.shader.out,
            &self.ltc,
        ]
        .map(|b| b.clone());
        let light_texture = self.shader.light_texture.clone();
        let surface_textures = self.surface_textures.clone();
        let frames = self.frames.clone();
        let t = self.target(gpu, w, h);
        let vis_view = t.visibility.create_view(&Default::default());
        let depth_view = t.depth.create_view(&Default::default());
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("bspvt visibility"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &vis_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            pass.set_pipeline(&raster);
            pass.set_bind_group(0, &raster_group, &[]);
            pass.draw(0..triangles * 3, 0..1);
        }
        if let Some(c) = &mut clock {
            c.mark(enc, "raster");
        }
        let layout = resolve.get_bind_group_layout(0);
        let buffers: Vec<&wgpu::Buffer> = buffers.iter().chain([&t.image]).collect();
        let mut entries = buffer_entries(&buffers);
        entries.push(wgpu::BindGroupEntry {
            binding: 7,
            resource: wgpu::BindingResource::TextureView(&vis_view),
        });
        entries.push(wgpu::BindGroupEntry {
            binding: 8,
            resource: light_texture.as_entire_binding(),
        });
        entries.push(wgpu::BindGroupEntry {
            binding: 9,
            resource: surface_textures.as_entire_binding(),
        });
        entries.push(wgpu::BindGroupEntry {
            binding: 10,
            resource: frames.as_entire_binding(),
        });
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("bspvt resolve"),
            layout: &layout,
            entries: &entries,
        });
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&resolve);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        }
        if let Some(c) = &mut clock {
            c.mark(enc, "resolve");
        }
        self.clock = clock;
        FrameCounts {
            vertices_shaded: renderer.visible_vertices.len(),
            pixels_shaded: if mode == Mode::Pixel {
                renderer.gbuffer.covered()
            } else {
                0
            },
            ..FrameCounts::default()
        }
    }
}

/// A frame left on the GPU: linear radiance, one `vec4<f32>` per pixel, row by row (the
/// resolve pass's output; valid until the next frame of the same [`GpuFrames`]).
#[derive(Clone, Debug)]
pub struct GpuImage {
    pub(crate) buffer: wgpu::Buffer,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

impl GpuImage {
    /// Reads it back (screenshots; a frame shown in a window is not read back).
    pub fn read(&self, gpu: &Gpu) -> Result<Image> {
        let _queue = gpu.exclusive();
        let bytes = u64::from(self.width) * u64::from(self.height) * 16;
        let data = gpu.read_buffer(&self.buffer, bytes)?;
        Ok(image_from_bytes((self.width, self.height), &data))
    }
}

/// An image from the resolve pass's little-endian `vec4<f32>` texels.
fn image_from_bytes((w, h): (u32, u32), bytes: &[u8]) -> Image {
    let mut img = Image::new(w, h);
    for (px, texel) in img.pixels.iter_mut().zip(bytes.chunks_exact(16)) {
        *px = std::array::from_fn(|c| {
            let o = c * 4;
            f32::from_le_bytes([texel[o], texel[o + 1], texel[o + 2], texel[o + 3]])
        });
    }
    img
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
    // The near plane as the CPU's G-buffer clips (frame::gbuffer): 1e-4 of the mesh's
    // diagonal.
    let near = 1e-4 * f64::from(r.scene.mesh.bounds().diagonal()).max(1e-12);
    // Camera → clip with reversed, infinite Z: depth = near / distance, in (0, 1].
    let proj = DMat4::from_cols(
        glam::DVec4::new(fy / aspect, 0.0, 0.0, 0.0),
        glam::DVec4::new(0.0, fy, 0.0, 0.0),
        glam::DVec4::new(0.0, 0.0, 0.0, -1.0),
        glam::DVec4::new(0.0, 0.0, near, 0.0),
    );
    (proj * look).as_mat4()
}
