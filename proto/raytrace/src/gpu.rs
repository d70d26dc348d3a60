//! The GPU context: one wgpu adapter, device and queue, chosen once and shared by whatever runs
//! compute or render work on it (the bake's GPU ray casting, the client's renderer).
//!
//! The adapter is the highest-performance one wgpu finds on the backends `WGPU_BACKEND` names
//! (all by default); `WGPU_ADAPTER_NAME` picks one by name (wgpu's own variables). A software
//! Vulkan driver (Mesa's lavapipe) is an adapter like any other: CI runs the GPU tests on it.

use std::sync::Arc;
use std::task::{Context, Poll, Wake, Waker};

/// Why no GPU context could be made.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GpuError {
    /// No adapter: no GPU, or no driver wgpu can use (on Linux, a Vulkan ICD such as Mesa's
    /// lavapipe: `apt-get install mesa-vulkan-drivers`).
    NoAdapter(String),
    /// The adapter refused a device.
    Device(String),
    /// A GPU operation failed after the device was made.
    Failed(String),
}

impl std::fmt::Display for GpuError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            GpuError::NoAdapter(why) => write!(
                f,
                "no GPU adapter found ({why}); install a GPU driver, or Mesa's software Vulkan \
                 driver (apt-get install mesa-vulkan-drivers), or use the CPU backend"
            ),
            GpuError::Device(why) => write!(f, "the GPU adapter refused a device: {why}"),
            GpuError::Failed(why) => write!(f, "GPU operation failed: {why}"),
        }
    }
}

impl std::error::Error for GpuError {}

/// Keeps Mesa's Vulkan device-selection layer (`VK_LAYER_MESA_device_select`, an implicit
/// layer installed with `mesa-vulkan-drivers`) from looking for a Wayland session where there
/// is none: with `XDG_RUNTIME_DIR` unset or not a folder it prints "error: XDG_RUNTIME_DIR is
/// invalid or not set in the environment." on every Vulkan instance, although nothing is
/// wrong. The layer only reorders adapters for a display's default GPU, which does not matter
/// here ([`GpuContext::new`] chooses by power preference), so this sets its own off switch,
/// `NODEVICE_SELECT=1`, in that case — unless the user set it either way.
///
/// # Safety
///
/// It changes the process environment: call it first thing in `main`, before any thread is
/// started (`std::env::set_var`'s contract).
#[allow(unsafe_code)]
pub unsafe fn quiet_headless_vulkan() {
    let session = std::env::var_os("XDG_RUNTIME_DIR")
        .is_some_and(|d| !d.is_empty() && std::path::Path::new(&d).is_dir());
    if !session && std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: the caller runs this before any other thread exists.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

/// A wgpu device and queue on the chosen adapter.
pub struct GpuContext {
    /// The instance the adapter came from (a window's surface is made from it).
    pub instance: wgpu::Instance,
    /// The adapter (a surface's capabilities are asked of it).
    pub adapter: wgpu::Adapter,
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter's name, driver and type (for logs and benchmark records).
    pub info: wgpu::AdapterInfo,
    /// How long the bake's work has kept this device busy ([`GpuContext::busy_seconds`]).
    busy: BusyClock,
}

/// Wall-clock time during which at least one piece of work was in flight: a union of
/// intervals, so work overlapping from several threads counts once.
#[derive(Default)]
struct BusyClock {
    state: std::sync::Mutex<Spells>,
}

#[derive(Default)]
struct Spells {
    /// Pieces of work in flight.
    in_flight: u32,
    /// When the current busy spell began (`None` while idle).
    since: Option<std::time::Instant>,
    /// Seconds of the finished spells.
    done: f64,
}

/// Holds the device's busy clock ([`GpuContext::busy_seconds`]) busy until dropped.
pub struct Busy<'a>(&'a BusyClock);

impl BusyClock {
    fn lock(&self) -> std::sync::MutexGuard<'_, Spells> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn enter(&self) -> Busy<'_> {
        let mut s = self.lock();
        if s.in_flight == 0 {
            s.since = Some(std::time::Instant::now());
        }
        s.in_flight += 1;
        Busy(self)
    }

    fn seconds(&self) -> f64 {
        let s = self.lock();
        s.done + s.since.map_or(0.0, |t| t.elapsed().as_secs_f64())
    }
}

impl Drop for Busy<'_> {
    fn drop(&mut self) {
        let mut s = self.0.lock();
        s.in_flight = s.in_flight.saturating_sub(1);
        if s.in_flight == 0
            && let Some(t) = s.since.take()
        {
            s.done += t.elapsed().as_secs_f64();
        }
    }
}

impl GpuContext {
    /// The highest-performance adapter with its own limits (large storage buffers), or
    /// [`GpuError::NoAdapter`].
    pub fn new() -> Result<GpuContext, GpuError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        // Vulkan, Metal or DX12 (the project's backends; lavapipe is Vulkan). wgpu's GL
        // backend would also probe EGL and, on a machine without a display or GL driver, log
        // an error on every run of every command. `WGPU_BACKEND` still chooses.
        if std::env::var_os("WGPU_BACKEND").is_none() {
            desc.backends = wgpu::Backends::PRIMARY;
        }
        let instance = wgpu::Instance::new(desc);
        let adapter = block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        // Timestamps between passes where the adapter has them (benchmarks' per-pass times;
        // nothing writes one unless asked).
        let timestamps =
            wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
        let (device, queue) = block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("bspvt"),
            required_features: adapter.features() & timestamps,
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(GpuContext {
            instance,
            adapter,
            device,
            queue,
            info,
            busy: BusyClock::default(),
        })
    }

    /// Seconds during which this device had at least one of the bake's dispatches in flight
    /// (upload to read-back: [`crate::GpuOccluder::cube_counts`], the bake's tree fit) since it
    /// was made: its rate is the GPU's utilisation by the bake (the service's
    /// `bspvt_gpu_busy_seconds_total`).
    pub fn busy_seconds(&self) -> f64 {
        self.busy.seconds()
    }

    /// Marks the device busy until the guard is dropped.
    pub fn busy(&self) -> Busy<'_> {
        self.busy.enter()
    }

    /// "name (backend, device type, driver)", for logs.
    pub fn describe(&self) -> String {
        let i = &self.info;
        format!(
            "{} ({:?}, {:?}, {} {})",
            i.name, i.backend, i.device_type, i.driver, i.driver_info
        )
    }

    /// Waits for all submitted work (and its map callbacks).
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Failed(e.to_string()))
    }

    /// A compute pipeline of `wgsl`'s `main` over one bind group of storage buffers, binding i
    /// read-only where `read_only[i]`, and that group's layout. Errors surface in the caller's
    /// error scope ([`scope_result`]).
    pub fn storage_pipeline(
        &self,
        label: &str,
        wgsl: &str,
        read_only: &[bool],
    ) -> (wgpu::ComputePipeline, wgpu::BindGroupLayout) {
        storage_pipeline(&self.device, label, wgsl, read_only)
    }

    /// This machine's GPU for a test, or `None` after saying why the test is skipped (no
    /// adapter: no driver, e.g. Mesa's lavapipe not installed).
    pub fn for_test() -> Option<Arc<GpuContext>> {
        match GpuContext::new() {
            Ok(ctx) => {
                eprintln!("GPU: {}", ctx.describe());
                Some(Arc::new(ctx))
            }
            Err(e) => {
                eprintln!("skipped: {e}");
                None
            }
        }
    }
}

/// `buffers` bound whole at bindings 0, 1, 2, … of `layout`.
pub fn bind_buffers(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    buffers: &[&wgpu::Buffer],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}

/// The most items of `bytes_per_item` one dispatch of `workgroup`-wide groups takes: what the
/// adapter binds in one storage buffer and dispatches in a grid (capped at 2²⁴).
pub fn max_items(device: &wgpu::Device, bytes_per_item: usize, workgroup: u32) -> usize {
    let limits = device.limits();
    let by_dispatch = limits.max_compute_workgroups_per_dimension as usize
        * limits.max_compute_workgroups_per_dimension as usize
        * workgroup as usize;
    (limits.max_storage_buffer_binding_size as usize / bytes_per_item)
        .min(limits.max_buffer_size as usize / bytes_per_item)
        .min(by_dispatch)
        .min(1 << 24)
}

/// The dispatch grid of `items` invocations in `workgroup`-wide groups: rows of the adapter's
/// most workgroups per dimension. The shader's index is `gid.y × x × workgroup + gid.x`.
pub fn dispatch_grid(device: &wgpu::Device, items: u32, workgroup: u32) -> (u32, u32) {
    let groups = items.div_ceil(workgroup);
    let max_x = device.limits().max_compute_workgroups_per_dimension;
    if groups <= max_x {
        (groups, 1)
    } else {
        (max_x, groups.div_ceil(max_x))
    }
}

/// A compute pipeline of `wgsl`'s `main` over one bind group of storage buffers, binding i
/// read-only where `read_only[i]`, and that group's layout, on `device` (errors surface in the
/// caller's error scope, [`scope_result`]).
pub fn storage_pipeline(
    device: &wgpu::Device,
    label: &str,
    wgsl: &str,
    read_only: &[bool],
) -> (wgpu::ComputePipeline, wgpu::BindGroupLayout) {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(wgsl.into()),
    });
    let entries: Vec<wgpu::BindGroupLayoutEntry> = read_only
        .iter()
        .enumerate()
        .map(|(binding, &read_only)| wgpu::BindGroupLayoutEntry {
            binding: binding as u32,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        })
        .collect();
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &entries,
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    (pipeline, layout)
}

/// The error an error scope caught, if any, as a [`GpuError::Failed`].
pub fn scope_result(scope: wgpu::ErrorScopeGuard) -> Result<(), GpuError> {
    match block_on(scope.pop()) {
        Some(e) => Err(GpuError::Failed(e.to_string())),
        None => Ok(()),
    }
}

/// Runs a future to completion on this thread (wgpu's native futures are ready or wake once).
pub fn block_on<F: std::future::Future>(fut: F) -> F::Output {
    struct Unpark(std::thread::Thread);
    impl Wake for Unpark {
        fn wake(self: Arc<Self>) {
            self.0.unpark();
        }
    }
    let waker = Waker::from(Arc::new(Unpark(std::thread::current())));
    let mut cx = Context::from_waker(&waker);
    let mut fut = std::pin::pin!(fut);
    loop {
        match fut.as_mut().poll(&mut cx) {
            Poll::Ready(v) => return v,
            Poll::Pending => std::thread::park(),
        }
    }
}
