//! Frames presented from the GPU: a render pass (`present.wgsl`) that tone-maps a frame's
//! linear radiance as [`Image::to_srgb8`] does and composites the window's overlay over it,
//! into any colour target (a window's surface texture, or a texture read back by tests). A
//! frame the GPU drew ([`GpuImage`]) is never read back; a CPU frame (the methods without a
//! GPU path) is uploaded once.

use anyhow::{Result, bail};

use super::context::Gpu;
use super::frame::GpuImage;
use super::timing::PassClock;
use crate::frame::image::Image;

/// The frame to present.
pub enum Pixels<'a> {
    /// Drawn on the GPU.
    Gpu(&'a GpuImage),
    /// Drawn on the CPU.
    Cpu(&'a Image),
}

impl Pixels<'_> {
    /// Width and height.
    pub fn size(&self) -> (u32, u32) {
        match self {
            Pixels::Gpu(g) => (g.width, g.height),
            Pixels::Cpu(i) => (i.width, i.height),
        }
    }
}

/// `present.wgsl`'s uniform.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    size: [u32; 4],
}

/// Tone mapping and the overlay, for targets of one format.
pub struct Compositor {
    pipeline: wgpu::RenderPipeline,
    format: wgpu::TextureFormat,
    params: wgpu::Buffer,
    /// The overlay layer (premultiplied 0xAARRGGBB per pixel), grown as needed.
    overlay: wgpu::Buffer,
    /// A CPU frame's radiance, uploaded (grown as needed).
    upload: wgpu::Buffer,
    /// Timestamps around the pass, when asked for ([`Compositor::time_passes`]).
    clock: Option<PassClock>,
}

impl Compositor {
    /// The pipeline for targets of `format` (a window surface's, or `Rgba8Unorm`).
    pub fn new(gpu: &Gpu, format: wgpu::TextureFormat) -> Result<Compositor> {
        let module = gpu.checked("present.wgsl", || {
            gpu.device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("present.wgsl"),
                    source: wgpu::ShaderSource::Wgsl(bspvt_shaders::gpu::wgsl::present().into()),
                })
        })?;
        let pipeline = gpu.checked("the present pipeline", || {
            gpu.device
                .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some("bspvt present"),
                    layout: None,
                    vertex: wgpu::VertexState {
                        module: &module,
                        entry_point: Some("vs"),
                        compilation_options: Default::default(),
                        buffers: &[],
                    },
                    primitive: wgpu::PrimitiveState::default(),
                    depth_stencil: None,
                    multisample: Default::default(),
                    fragment: Some(wgpu::FragmentState {
                        module: &module,
                        entry_point: Some("fs"),
                        compilation_options: Default::default(),
                        targets: &[Some(format.into())],
                    }),
                    multiview_mask: None,
                    cache: None,
                })
        })?;
        let buffer = |label: &str, size: u64, usage: wgpu::BufferUsages| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: usage | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as U;
        Ok(Compositor {
            pipeline,
            format,
            params: buffer(
                "present params",
                std::mem::size_of::<Params>() as u64,
                U::STORAGE,
            ),
            overlay: buffer("overlay", 16, U::STORAGE),
            upload: buffer("uploaded frame", 16, U::STORAGE),
            clock: None,
        })
    }

    /// Draws `pixels` tone-mapped at `exposure` with `overlay` (premultiplied 0xAARRGGBB,
    /// one per pixel of `pixels`, or empty) over it into `target`. Pixels of the target
    /// outside the frame are black.
    pub fn draw(
        &mut self,
        gpu: &Gpu,
        pixels: Pixels,
        exposure: f32,
        overlay: &[u32],
        target: &wgpu::TextureView,
    ) -> Result<()> {
        let (w, h) = pixels.size();
        let n = u64::from(w) * u64::from(h);
        if !overlay.is_empty() && overlay.len() as u64 != n {
            bail!("overlay of {} pixels for a {w}×{h} frame", overlay.len());
        }
        let _queue = gpu.exclusive();
        grow(gpu, &mut self.overlay, "overlay", 4 * n.max(1))?;
        if overlay.is_empty() {
            // A transparent layer: nothing over the frame.
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            enc.clear_buffer(&self.overlay, 0, Some(4 * n.max(1)));
            gpu.queue.submit([enc.finish()]);
        } else {
            gpu.queue
                .write_buffer(&self.overlay, 0, bytemuck::cast_slice(overlay));
        }
        let radiance = match pixels {
            Pixels::Gpu(g) => g.buffer.clone(),
            Pixels::Cpu(img) => {
                grow(gpu, &mut self.upload, "uploaded frame", 16 * n.max(1))?;
                let texels: Vec<[f32; 4]> =
                    img.pixels.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
                gpu.queue
                    .write_buffer(&self.upload, 0, bytemuck::cast_slice(&texels));
                self.upload.clone()
            }
        };
        let params = Params {
            size: [w, h, exposure.to_bits(), u32::from(self.format.is_srgb())],
        };
        gpu.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let group = gpu.bind_buffers(
            "bspvt present",
            &self.pipeline.get_bind_group_layout(0),
            &[&self.params, &radiance, &self.overlay],
        );
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        if let Some(c) = &mut self.clock {
            c.start(&mut enc);
        }
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("bspvt present"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                ..Default::default()
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.draw(0..3, 0..1);
        }
        if let Some(c) = &mut self.clock {
            c.mark(&mut enc, "composite");
            c.resolve(&mut enc);
        }
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    /// Times the pass of the draws that follow on the GPU (`bench-gpu`): false where the
    /// device cannot write timestamps between passes.
    pub fn time_passes(&mut self, gpu: &Gpu) -> bool {
        PassClock::ensure(&mut self.clock, gpu)
    }

    /// The last draw's GPU time (`composite`), ms, after [`Compositor::time_passes`]; waits
    /// for it.
    pub fn pass_times(&self, gpu: &Gpu) -> Result<Vec<(&'static str, f64)>> {
        PassClock::read_slot(self.clock.as_ref(), gpu)
    }
}

/// Replaces `buffer` by a larger one (same usage) when it holds fewer than `bytes`.
fn grow(gpu: &Gpu, buffer: &mut wgpu::Buffer, label: &str, bytes: u64) -> Result<()> {
    if buffer.size() >= bytes {
        return Ok(());
    }
    let usage = buffer.usage();
    *buffer = gpu.checked(label, || {
        gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage,
            mapped_at_creation: false,
        })
    })?;
    Ok(())
}

/// A colour target off screen, the window's format's kind (8-bit UNORM): what a window
/// would show, for tests and benchmarks.
pub struct Offscreen {
    texture: wgpu::Texture,
    size: (u32, u32),
}

impl Offscreen {
    /// The format [`Compositor::new`] must be made for to draw here.
    pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

    /// A `w`×`h` target.
    pub fn new(gpu: &Gpu, w: u32, h: u32) -> Result<Offscreen> {
        let texture = gpu.checked("an offscreen target", || {
            gpu.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("offscreen"),
                size: wgpu::Extent3d {
                    width: w.max(1),
                    height: h.max(1),
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: Self::FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        })?;
        Ok(Offscreen {
            texture,
            size: (w.max(1), h.max(1)),
        })
    }

    /// The view to draw into.
    pub fn view(&self) -> wgpu::TextureView {
        self.texture.create_view(&Default::default())
    }

    /// Waits until what was drawn here is done.
    pub fn finish(&self, gpu: &Gpu) -> Result<()> {
        gpu.wait()
    }

    /// The pixels, 8-bit RGB.
    pub fn read(&self, gpu: &Gpu) -> Result<image::RgbImage> {
        let (w, h) = self.size;
        // Rows padded to wgpu's 256-byte copy alignment.
        let row = (4 * w).div_ceil(256) * 256;
        let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("offscreen readback"),
            size: u64::from(row) * u64::from(h),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let _queue = gpu.exclusive();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.copy_texture_to_buffer(
            self.texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(h),
                },
            },
            self.texture.size(),
        );
        gpu.queue.submit([enc.finish()]);
        let bytes = gpu.map_read(&staging)?;
        Ok(image::RgbImage::from_fn(w, h, |x, y| {
            let o = (y * row + 4 * x) as usize;
            image::Rgb([bytes[o], bytes[o + 1], bytes[o + 2]])
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The GPU's tone mapping and overlay equal the CPU's (`Image::to_srgb8`, then the
    /// canvas's `composite`) within one 8-bit step, on the stiff inputs too (NaN, ±∞,
    /// negative, 1e30), for a frame uploaded from the CPU and one already on the GPU.
    #[test]
    fn the_gpu_shows_what_the_cpu_would() {
        let Some(gpu) = Gpu::shared_or_skip() else {
            return;
        };
        let (w, h) = (37u32, 23u32);
        let stiff = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -1.0,
            1e30,
            0.0,
            1e-7,
        ];
        let mut img = Image::new(w, h);
        let mut state = 0x2545_f491_u32;
        let mut rand = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = std::array::from_fn(|c| match (i + c) % 11 {
                k if k < stiff.len() => stiff[k],
                _ => (rand() % 100_000) as f32 * 1e-4, // 0 to 10
            });
        }
        // Premultiplied overlay: alpha a, each channel at most a.
        let overlay: Vec<u32> = (0..w * h)
            .map(|i| {
                let a = if i % 3 == 0 { 0 } else { rand() % 256 };
                let c = |r: u32| if a == 0 { 0 } else { r % (a + 1) };
                (a << 24) | (c(rand()) << 16) | (c(rand()) << 8) | c(rand())
            })
            .collect();
        let mut want = img.to_0rgb(1.0);
        crate::frame::canvas::composite(&mut want, &overlay);

        let mut compositor = Compositor::new(gpu, Offscreen::FORMAT).expect("compositor");
        let target = Offscreen::new(gpu, w, h).expect("target");
        let texels: Vec<[f32; 4]> = img.pixels.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
        let on_gpu = GpuImage {
            buffer: {
                use wgpu::util::DeviceExt;
                gpu.device
                    .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("test radiance"),
                        contents: bytemuck::cast_slice(&texels),
                        usage: wgpu::BufferUsages::STORAGE,
                    })
            },
            width: w,
            height: h,
        };
        for pixels in [Pixels::Cpu(&img), Pixels::Gpu(&on_gpu)] {
            compositor
                .draw(gpu, pixels, 1.0, &overlay, &target.view())
                .expect("draw");
            let got = target.read(gpu).expect("read back");
            let mut worst = 0;
            for (g, &c) in got.pixels().zip(&want) {
                for (k, shift) in [16, 8, 0].into_iter().enumerate() {
                    worst = worst.max(g.0[k].abs_diff(((c >> shift) & 0xff) as u8));
                }
            }
            eprintln!("largest difference {worst} (8-bit)");
            assert!(worst <= 1, "largest difference {worst} (8-bit)");
        }
    }
}
