//! The GPU: one wgpu adapter and device per process, found once ([`Gpu::shared`]). Without
//! a GPU, Linux uses Mesa's lavapipe (Debian's `mesa-vulkan-drivers`) when installed; the
//! usual wgpu variables (`WGPU_BACKEND`, `WGPU_ADAPTER_NAME`, and Vulkan's
//! `VK_ICD_FILENAMES`) choose among adapters.

use std::sync::OnceLock;

use anyhow::{Result, anyhow};
use bspvt_raytrace::gpu::block_on;

/// A device and its queue, with the adapter's name.
pub struct Gpu {
    /// The instance (the viewer makes its window's surface from it).
    pub(crate) instance: wgpu::Instance,
    /// The adapter the device is on.
    pub(crate) adapter_handle: wgpu::Adapter,
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    /// The adapter, e.g. `llvmpipe (LLVM 19.1.7, 256 bits) (Vulkan, Cpu)`.
    pub adapter: String,
    /// A software rasteriser (lavapipe, WARP, SwiftShader): `auto` does not pick it.
    pub software: bool,
    /// The per-vertex shading pipeline, compiled once (`vertex.rs`).
    pub(crate) shade_pipeline: OnceLock<wgpu::ComputePipeline>,
    /// The sky's pipelines (terms, gather), compiled once (`sky.rs`).
    pub(crate) sky_pipelines: OnceLock<(wgpu::ComputePipeline, wgpu::ComputePipeline)>,
    /// The frame pipelines (raster, resolve) by MSAA samples, compiled once each (`frame.rs`:
    /// the resolve shader takes ~25 s to compile on lavapipe).
    pub(crate) frame_pipelines:
        std::sync::Mutex<Vec<(u32, wgpu::RenderPipeline, wgpu::ComputePipeline)>>,
    /// One user of the queue at a time: submissions waited for from several threads at once
    /// stall for a minute on lavapipe (measured), so each frame or batch holds this.
    busy: std::sync::Mutex<()>,
}

static SHARED: OnceLock<Result<Gpu, String>> = OnceLock::new();

impl Gpu {
    /// The process's GPU, found on first use; the error says why there is none.
    pub fn shared() -> Result<&'static Gpu> {
        SHARED
            .get_or_init(|| Gpu::new().map_err(|e| format!("{e:#}")))
            .as_ref()
            .map_err(|e| anyhow!("{e}"))
    }

    /// The shared GPU, or `None` after printing why the test that asked is skipped.
    #[cfg(test)]
    pub(crate) fn shared_or_skip() -> Option<&'static Gpu> {
        Gpu::shared()
            .map_err(|e| eprintln!("SKIPPED: no GPU adapter ({e:#})"))
            .ok()
    }

    /// The adapter and device of [`bspvt_raytrace::gpu::GpuContext`] (the one the bake's GPU
    /// ray casting uses: high performance first, the adapter's own limits, since the trees of
    /// a large mesh exceed wgpu's defaults).
    pub fn new() -> Result<Gpu> {
        let ctx = bspvt_raytrace::gpu::GpuContext::new().map_err(|e| anyhow!("{e}"))?;
        let info = &ctx.info;
        Ok(Gpu {
            adapter: format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type),
            software: info.device_type == wgpu::DeviceType::Cpu,
            instance: ctx.instance,
            adapter_handle: ctx.adapter,
            device: ctx.device,
            queue: ctx.queue,
            shade_pipeline: OnceLock::new(),
            sky_pipelines: OnceLock::new(),
            frame_pipelines: std::sync::Mutex::new(Vec::new()),
            busy: std::sync::Mutex::new(()),
        })
    }

    /// A bind group of `buffers`, bound whole at bindings 0, 1, 2, … of `layout`.
    pub(crate) fn bind_buffers(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        buffers: &[&wgpu::Buffer],
    ) -> wgpu::BindGroup {
        bspvt_raytrace::gpu::bind_buffers(&self.device, label, layout, buffers)
    }

    /// Holds the queue for one frame or batch (see `busy`).
    pub(crate) fn exclusive(&self) -> std::sync::MutexGuard<'_, ()> {
        self.busy.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Runs `f` (resource creation) with its validation and out-of-memory errors returned
    /// instead of wgpu's default handler (which panics).
    pub(crate) fn checked<T>(&self, what: &str, f: impl FnOnce() -> T) -> Result<T> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let invalid = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out = f();
        let e = block_on(invalid.pop()).or(block_on(oom.pop()));
        match e {
            None => Ok(out),
            Some(e) => Err(anyhow!("{what}: {e}")),
        }
    }

    /// Waits until the queue's work is done.
    pub(crate) fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| anyhow!("waiting for the GPU: {e}"))
    }

    /// Copies `size` bytes of `src` (a COPY_SRC buffer) back to memory.
    pub(crate) fn read_buffer(&self, src: &wgpu::Buffer, size: u64) -> Result<Vec<u8>> {
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(src, 0, &staging, 0, size);
        self.queue.submit([enc.finish()]);
        self.map_read(&staging)
    }

    /// Maps a MAP_READ buffer after the queue's work and copies it out.
    pub(crate) fn map_read(&self, staging: &wgpu::Buffer) -> Result<Vec<u8>> {
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv()
            .map_err(|_| anyhow!("the GPU dropped a read-back"))?
            .map_err(|e| anyhow!("mapping a read-back buffer: {e}"))?;
        let bytes = staging
            .get_mapped_range(..)
            .map_err(|e| anyhow!("reading a mapped buffer: {e:?}"))?
            .to_vec();
        staging.unmap();
        Ok(bytes)
    }
}

/// `buffers` bound whole at bindings 0, 1, 2, ….
pub(crate) fn buffer_entries<'a>(buffers: &[&'a wgpu::Buffer]) -> Vec<wgpu::BindGroupEntry<'a>> {
    buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect()
}
