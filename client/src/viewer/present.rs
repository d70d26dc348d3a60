//! Where the window's frames go. With the GPU backend, a wgpu surface: the frame the GPU drew
//! is tone-mapped and the overlay composited over it on the GPU ([`Compositor`]), with no
//! read-back (at 1920×1080 the read-back alone was 25–31 ms a frame on an H100,
//! docs/benchmarks.md). Otherwise, or where the adapter cannot present to the window,
//! softbuffer shows the CPU's pixels.

use std::num::NonZeroU32;
use std::sync::Arc;

use anyhow::{Result, anyhow};
use winit::window::Window;

use crate::gpu::Gpu;
use crate::gpu::present::{Compositor, Pixels};

/// The window's output.
pub(super) enum Output {
    /// 0RGB pixels drawn on the CPU.
    Soft(softbuffer::Surface<Arc<Window>, Arc<Window>>),
    /// A wgpu surface.
    Gpu(Box<GpuSurface>),
}

/// A window's wgpu surface and the pass that draws into it.
pub(super) struct GpuSurface {
    gpu: &'static Gpu,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    compositor: Compositor,
}

impl Output {
    /// A wgpu surface on `gpu` where given and the adapter presents to `window`, else
    /// softbuffer; with a line saying which (and why not the surface).
    pub(super) fn open(
        window: &Arc<Window>,
        gpu: Option<&'static Gpu>,
    ) -> Result<(Output, String)> {
        let mut why = None;
        if let Some(gpu) = gpu {
            match GpuSurface::new(gpu, window.clone()) {
                Ok(s) => {
                    let line = format!(
                        "presenting: wgpu surface ({:?}, {:?}) on {}",
                        s.config.format, s.config.present_mode, gpu.adapter
                    );
                    return Ok((Output::Gpu(Box::new(s)), line));
                }
                Err(e) => why = Some(format!("{e:#}")),
            }
        }
        let context = softbuffer::Context::new(window.clone())
            .map_err(|e| anyhow!("cannot draw into the window: {e}"))?;
        let surface = softbuffer::Surface::new(&context, window.clone())
            .map_err(|e| anyhow!("cannot draw into the window: {e}"))?;
        let line = match why {
            Some(why) => format!("presenting: CPU pixels (softbuffer); no GPU surface: {why}"),
            None => "presenting: CPU pixels (softbuffer)".to_string(),
        };
        Ok((Output::Soft(surface), line))
    }

    /// Shows `buf` (0RGB, `w`×`h`) through softbuffer.
    pub(super) fn present_soft(
        surface: &mut softbuffer::Surface<Arc<Window>, Arc<Window>>,
        buf: &[u32],
        w: usize,
        h: usize,
    ) -> Result<()> {
        let (Some(nw), Some(nh)) = (NonZeroU32::new(w as u32), NonZeroU32::new(h as u32)) else {
            return Ok(());
        };
        let err = |e: softbuffer::SoftBufferError| anyhow!("cannot draw into the window: {e}");
        surface.resize(nw, nh).map_err(err)?;
        let mut out = surface.buffer_mut().map_err(err)?;
        out.copy_from_slice(buf);
        out.present().map_err(err)
    }
}

impl GpuSurface {
    fn new(gpu: &'static Gpu, window: Arc<Window>) -> Result<GpuSurface> {
        let size = window.inner_size();
        let surface = gpu
            .instance
            .create_surface(window)
            .map_err(|e| anyhow!("cannot make a surface for the window: {e}"))?;
        let caps = surface.get_capabilities(&gpu.adapter_handle);
        // 8-bit UNORM first: the pass writes the 8-bit sRGB values the CPU would. An sRGB
        // format gets them decoded to linear for the hardware to encode again.
        use wgpu::TextureFormat as F;
        let format = [
            F::Bgra8Unorm,
            F::Rgba8Unorm,
            F::Bgra8UnormSrgb,
            F::Rgba8UnormSrgb,
        ]
        .into_iter()
        .find(|f| caps.formats.contains(f))
        .or_else(|| caps.formats.first().copied())
        .ok_or_else(|| anyhow!("the adapter cannot present to this window"))?;
        // Mailbox: never tears, never waits for the display's refresh; else FIFO (vsync).
        let present_mode = if caps.present_modes.contains(&wgpu::PresentMode::Mailbox) {
            wgpu::PresentMode::Mailbox
        } else {
            wgpu::PresentMode::Fifo
        };
        let alpha_mode = if caps.alpha_modes.contains(&wgpu::CompositeAlphaMode::Opaque) {
            wgpu::CompositeAlphaMode::Opaque
        } else {
            caps.alpha_modes
                .first()
                .copied()
                .unwrap_or(wgpu::CompositeAlphaMode::Auto)
        };
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            color_space: wgpu::SurfaceColorSpace::Auto,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode,
            desired_maximum_frame_latency: 2,
            alpha_mode,
            view_formats: vec![],
        };
        gpu.checked("configuring the window's surface", || {
            surface.configure(&gpu.device, &config)
        })?;
        let compositor = Compositor::new(gpu, format)?;
        Ok(GpuSurface {
            gpu,
            surface,
            config,
            compositor,
        })
    }

    /// Presents `pixels` with `overlay` (premultiplied 0xAARRGGBB per pixel) over it, in a
    /// `w`×`h` window.
    pub(super) fn present(
        &mut self,
        pixels: Pixels,
        overlay: &[u32],
        w: u32,
        h: u32,
    ) -> Result<()> {
        if (w, h) != (self.config.width, self.config.height) && w > 0 && h > 0 {
            self.config.width = w;
            self.config.height = h;
            self.configure()?;
        }
        let texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) => t,
            wgpu::CurrentSurfaceTexture::Suboptimal(t) => {
                // Drawn this time; configured again for the next frame.
                self.config.width = 0;
                t
            }
            // Skipped: the next frame tries again.
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Outdated => {
                self.configure()?;
                return Ok(());
            }
            other => return Err(anyhow!("the window's surface failed: {other:?}")),
        };
        let view = texture.texture.create_view(&Default::default());
        self.compositor
            .draw(self.gpu, pixels, 1.0, overlay, &view)?;
        self.gpu.queue.present(texture);
        Ok(())
    }

    fn configure(&mut self) -> Result<()> {
        let (gpu, surface, config) = (self.gpu, &self.surface, &self.config);
        gpu.checked("configuring the window's surface", || {
            surface.configure(&gpu.device, config)
        })
    }
}
