//! The BSP tree fit on the GPU (`fit.wgsl`): many faces at once, each fitted by one workgroup,
//! to the tree and statistics of [`Fitter::fit`] with [`SplitMethod::Default`] — the same nodes
//! to the bit — or left to the CPU ([`Refit`]), which fits it again ([`GpuFitter::fit_or_refit`]).
//!
//! **Workgroup layout.** One workgroup of 64 invocations per face, cooperating: the cells
//! (`Fitter::cells`' quadtree-merged uniform blocks) are made from the face's pixel grid level
//! by level; the tree is built depth first with an explicit stack (preorder: a split's
//! placeholder, its left subtree, its right subtree, the split's `right` patched when the right
//! child is popped — `Fitter::build`). Per node, the coarse-to-fine angle search
//! (`Fitter::coarse_to_fine`) runs in passes: the 4 coarse angles in one, then the 2 candidates
//! of each bisection step in one (both are known before either is scored). A pass does
//! `Fitter::sweep` for each of its angles at once: it histograms the node's cells over the
//! offset bins in workgroup memory (cells strided over the invocations, one histogram per
//! angle), scans the bins (each invocation a run of them, then a scan over the runs) and
//! reduces E over them; the results are then taken in the CPU's order. The partition
//! (`Fitter::partition`, exact per pixel) strides over the cells and writes the pieces to a
//! scratch area, from which they are copied back: right child first, left child above it, so
//! the cell arena is a stack (the pending right children of the path and the node on top, disjoint
//! pixel sets: at most res² cells).
//!
//! **The loop limit.** Mesa's llvmpipe (lavapipe, CI's GPU) ends an invocation after 65,535
//! loop iterations summed over all its loops (`LP_MAX_TGSI_LOOP_ITERATIONS`, docs/gpu.md). So
//! no invocation loops over all cells × angles × nodes: inner loops are strided, the wide
//! integer helpers are straight-line code, the angles of a pass share its loops, and the shader
//! counts (in every invocation alike) the iterations spent: a node that could pass the budget
//! ([`BUDGET`]) is not started, and the face is flagged for the CPU. That count is a model of
//! the limiter (a loop's failing last test counts too; a few more a pass that are not
//! understood, measured on lavapipe); so a canary loop at the end, which ends early once the
//! limiter has run out, flags the face ([`Refit::Limit`]) should the model ever fall short.
//! In the tests the count stays above the limiter's and only the budget flags faces.
//!
//! **Exactness.** The shader never evaluates the CPU's float formulas (WGSL may fuse a·b + c
//! and divides to 2.5 ULP). Every point the fit projects is X = (m/res − 1) in each axis with
//! integer m (a cell's centre: m = 2i + size; a pixel centre: m = 2i + 1; `Fitter::centre`,
//! `pixel_centres`), so the CPU's products n(a)·X[m] are uploaded ([`Tables`]) and the CPU's
//! `n.x * p.x + n.y * p.y` is the shader's single (correctly rounded) addition of two of them;
//! an angle of [π, 2π) has the exactly negated normal (`LineCodec::new`), so its projection is
//! the exact negation. The histogram bin `OffsetBins::bin` is monotone: the CPU uploads, per bin
//! b, the least f32 t with bin(t) ≥ b, and the shader's float guess is corrected against them.
//! The side test and the partition's margin test are one f32 subtraction of the CPU's offset
//! `LineCodec::offset`. Everything else is integers: moments (n, Σk, Σk²) and E in u32 at 64²,
//! the leaf test `D·2¹⁶ ≤ T_fx·n` (D = nΣk² − (Σk)², T_fx = ⌊ε_px·S²·2¹⁶⌋), the children's
//! deviation DL/nL + DR/nR compared as exact rationals (128-bit products of 32-bit limbs),
//! the leaf value by rounding 255Σk/(nS) half up, the leaf's error from integer sums. Ties keep
//! the CPU's first in its offer order: per sweep the least (E, 2·bin + mirrored) wins, across
//! sweeps the earlier sweep of the CPU's order.

use std::sync::Arc;

use bspvt_proto::SplitMethod;
use bspvt_proto::bspvt::{FaceTree, Node, QLine};
use wgpu::util::DeviceExt;

use bspvt_raytrace::gpu::scope_result;
pub use bspvt_raytrace::gpu::{GpuContext, GpuError};

use crate::fit::{FitStats, Fitter};

/// Loop iterations a face may spend, as the shader counts them (an upper bound of what
/// llvmpipe's limiter counts): a node that could pass it is not started, and the face goes to
/// the CPU. Just below llvmpipe's 65,535; should the count fall short, the shader's canary
/// loop still sees the limiter run out and flags the face.
const BUDGET: u32 = 65_000;

/// The largest face resolution fitted on the GPU (u32 moments and leaf values, 257 bins).
pub const MAX_GPU_RES: u32 = 64;

/// Header words per face in the output (`fit.wgsl`'s `HEADER`).
const HEADER: usize = 8;

/// Bit of a leaf node's first word.
const LEAF: u32 = 0x8000_0000;

/// Faces' work and output buffers per dispatch, at most (bytes): a chunk's faces (~4,400 of
/// 88 KiB at 64²) in one.
const DISPATCH_BYTES: u64 = 1 << 30;

/// Words of each face's output read back at first ([`fit_gather.wgsl`]): its header and 128
/// nodes. A face with more is read again whole.
const GATHER_WORDS: u32 = HEADER as u32 + 2 * 128;

/// Why the GPU left a face to the CPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Refit {
    /// The fit's settings or the face's pixels are outside what the shader handles (split
    /// search not `Default`, resolution above [`MAX_GPU_RES`] or not a power of two below 16,
    /// escape counts above the samples, pixel indices outside the face).
    Unsupported,
    /// The face would pass the loop budget (llvmpipe's limit).
    Budget,
    /// More nodes than the output holds.
    Nodes,
    /// The depth-first stack would overflow.
    Stack,
    /// llvmpipe's loop limiter ran out although the shader's count said it would not (the
    /// canary loop saw it): a loop may have been cut short.
    Limit,
    /// The shader's answer did not decode to a tree (a defensive check).
    Malformed,
}

/// One face to fit: its pixels that matter and their escape counts, as [`Fitter::fit`] takes
/// them.
#[derive(Clone, Copy, Debug)]
pub struct FaceInput<'a> {
    /// Pixel indices `j·res + i`.
    pub index: &'a [u32],
    /// Escape counts, one per index.
    pub visible: &'a [u16],
}

/// The GPU's tree of a face, or why the CPU must fit it.
pub type GpuFaceFit = Result<(FaceTree, FitStats), Refit>;

/// The shader's parameters (`fit.wgsl`'s `Params`).
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
struct Params {
    res: u32,
    samples: u32,
    half: u32,
    offsets: u32,
    faces: u32,
    budget: u32,
    t_fx_lo: u32,
    t_fx_hi: u32,
    work_words: u32,
    out_words: u32,
    max_nodes: u32,
    grid_words: u32,
    level_words: u32,
    wrong_ties: u32,
    canary: u32,
    pad: u32,
}

/// The CPU-computed tables that make the shader's float decisions the CPU's.
struct Tables {
    /// PX[a][m] = n(a).x · X[m], then PY[a][m] = n(a).y · X[m], a < half, m ≤ 2·res.
    proj: Vec<f32>,
    /// c(o), o < O.
    offsets: Vec<f32>,
    /// [b]: the least f32 t with `OffsetBins::bin(t) ≥ b` (b = 0 unused).
    thresholds: Vec<f32>,
}

/// f32 ordered as integers (−∞ … −0, +0 … +∞).
fn order_key(x: f32) -> u32 {
    let b = x.to_bits();
    if b >> 31 == 1 { !b } else { b | 0x8000_0000 }
}

fn from_order_key(k: u32) -> f32 {
    f32::from_bits(if k >> 31 == 1 { k & 0x7fff_ffff } else { !k })
}

impl Tables {
    /// The tables of `fitter`, or `None` where its pixel centres are not X[2i + 1] (the shader
    /// could not reproduce its projections).
    fn new(fitter: &Fitter) -> Option<Tables> {
        let res = fitter.res;
        let r = res as f32;
        // `Fitter::centre` and `pixel_centres`: m as f32 / res − 1.
        let x: Vec<f32> = (0..=2 * res).map(|m| m as f32 / r - 1.0).collect();
        let same = |a: f32, b: f32| a.to_bits() == b.to_bits();
        for j in 0..res as usize {
            for i in 0..res as usize {
                let p = fitter.uv.get(j * res as usize + i)?;
                if !same(p.x, x[2 * i + 1]) || !same(p.y, x[2 * j + 1]) {
                    return None;
                }
            }
        }
        let codec = fitter.codec;
        let half = codec.angles() / 2;
        let mut proj = Vec::with_capacity(2 * half as usize * x.len());
        for a in 0..half {
            let n = codec.normal(a as u16);
            proj.extend(x.iter().map(|&xm| n.x * xm));
        }
        for a in 0..half {
            let n = codec.normal(a as u16);
            proj.extend(x.iter().map(|&xm| n.y * xm));
        }
        let o = codec.offsets();
        let offsets = (0..o).map(|i| codec.offset(i as u16)).collect();
        let bins = codec.offset_bins();
        let (lo, hi) = (order_key(-f32::MAX), order_key(f32::MAX));
        let thresholds = (0..=o)
            .map(|b| {
                if b == 0 {
                    return -f32::MAX;
                }
                // The least key in [lo, hi] whose value bins at b or above (bin(MAX) = O).
                let (mut l, mut h) = (lo, hi);
                while l < h {
                    let mid = l + (h - l) / 2;
                    if bins.bin(from_order_key(mid)) >= b {
                        h = mid;
                    } else {
                        l = mid + 1;
                    }
                }
                from_order_key(l)
            })
            .collect();
        Some(Tables {
            proj,
            offsets,
            thresholds,
        })
    }
}

/// Whether the shader handles `fitter`'s settings (otherwise every face is
/// [`Refit::Unsupported`]; the bake then fits on the CPU without calling the GPU).
pub(crate) fn supported(fitter: &Fitter) -> bool {
    let res = fitter.res;
    let top = res.min(16);
    fitter.method == SplitMethod::Default
        && (1..=MAX_GPU_RES).contains(&res)
        && top.is_power_of_two()
        && (1..=64).contains(&fitter.samples)
        && fitter.codec.offsets() <= 256
        && fitter.codec.angles() >= 8
        && fitter.epsilon_pixels >= 0.0
}

/// The tree fit's pipeline on a GPU.
pub struct GpuFitter {
    ctx: Arc<GpuContext>,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    gather: wgpu::ComputePipeline,
    gather_layout: wgpu::BindGroupLayout,
    /// The dispatches' buffers, kept from one to the next (one dispatch at a time).
    buffers: std::sync::Mutex<Option<FitBuffers>>,
    wrong_ties: bool,
}

/// A dispatch's device buffers for up to `faces` faces of one [`Layout`], reused while they
/// fit: new allocations of hundreds of MiB a chunk, zeroed by the driver, cost more than the
/// fit.
struct FitBuffers {
    faces: usize,
    words: (u32, u32, u32),
    grid: wgpu::Buffer,
    work: wgpu::Buffer,
    result: wgpu::Buffer,
    dense: wgpu::Buffer,
    readback: wgpu::Buffer,
}

impl FitBuffers {
    fn new(device: &wgpu::Device, layout: &Layout, faces: usize) -> FitBuffers {
        use wgpu::BufferUsages as U;
        let buffer = |label: &str, words: u32, usage: U| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: faces as u64 * u64::from(words) * 4,
                usage,
                mapped_at_creation: false,
            })
        };
        FitBuffers {
            faces,
            words: (layout.grid_words, layout.work_words, layout.out_words),
            grid: buffer("fit grids", layout.grid_words, U::STORAGE | U::COPY_DST),
            work: buffer("fit work", layout.work_words, U::STORAGE | U::COPY_DST),
            result: buffer(
                "fit trees",
                layout.out_words,
                U::STORAGE | U::COPY_SRC | U::COPY_DST,
            ),
            dense: buffer("fit trees, packed", GATHER_WORDS, U::STORAGE | U::COPY_SRC),
            readback: buffer(
                "fit trees readback",
                GATHER_WORDS,
                U::MAP_READ | U::COPY_DST,
            ),
        }
    }

    fn fits(&self, layout: &Layout, faces: usize) -> bool {
        self.faces >= faces
            && self.words == (layout.grid_words, layout.work_words, layout.out_words)
    }
}

impl GpuFitter {
    /// Builds the pipeline on `ctx`'s device.
    pub fn new(ctx: Arc<GpuContext>) -> Result<GpuFitter, GpuError> {
        let device = &ctx.device;
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        // The parameters, tables and grids read; the work area and the trees written.
        let read_only = [true, true, true, true, true, false, false];
        let (pipeline, layout) = ctx.storage_pipeline("fit", include_str!("fit.wgsl"), &read_only);
        let (gather, gather_layout) = ctx.storage_pipeline(
            "fit gather",
            include_str!("fit_gather.wgsl"),
            &[true, true, false],
        );
        scope_result(validation)?;
        Ok(GpuFitter {
            ctx,
            pipeline,
            layout,
            gather,
            gather_layout,
            buffers: std::sync::Mutex::new(None),
            wrong_ties: false,
        })
    }

    /// Test hook: the shader keeps the last least E of a sweep instead of the first (a
    /// deliberately wrong shader, which the comparison with the CPU must catch).
    #[doc(hidden)]
    pub fn set_wrong_ties(&mut self, on: bool) {
        self.wrong_ties = on;
    }

    /// Each face's tree and statistics as `fitter.fit` makes them, or why the CPU must fit it.
    pub fn fit(&self, fitter: &Fitter, faces: &[FaceInput]) -> Result<Vec<GpuFaceFit>, GpuError> {
        let tables = if supported(fitter) {
            Tables::new(fitter)
        } else {
            None
        };
        let Some(tables) = tables else {
            return Ok(vec![Err(Refit::Unsupported); faces.len()]);
        };
        let res = fitter.res as usize;
        let ok = |f: &FaceInput| {
            f.index.iter().all(|&p| (p as usize) < res * res)
                && f.visible.iter().all(|&k| u32::from(k) <= fitter.samples)
        };
        let mut out: Vec<GpuFaceFit> = vec![Err(Refit::Unsupported); faces.len()];
        let todo: Vec<usize> = (0..faces.len()).filter(|&f| ok(&faces[f])).collect();
        let layout = Layout::new(fitter);
        let per_face = (layout.work_words + layout.out_words) as u64 * 4;
        let limits = self.ctx.device.limits();
        let most = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size)
            .min(DISPATCH_BYTES);
        let per_dispatch = ((most / per_face.max(1)) as usize)
            .min(limits.max_compute_workgroups_per_dimension as usize)
            .max(1);
        for batch in todo.chunks(per_dispatch) {
            let inputs: Vec<FaceInput> = batch.iter().map(|&f| faces[f]).collect();
            let fits = self.dispatch(fitter, &tables, &layout, &inputs)?;
            for (&f, fit) in batch.iter().zip(fits) {
                out[f] = fit;
            }
        }
        Ok(out)
    }

    /// [`GpuFitter::fit`], the faces the GPU left fitted on the CPU (in parallel on the current
    /// rayon pool); also how many those were.
    pub fn fit_or_refit(
        &self,
        fitter: &Fitter,
        faces: &[FaceInput],
    ) -> Result<(Vec<(FaceTree, FitStats)>, usize), GpuError> {
        use rayon::prelude::*;
        let fits = self.fit(fitter, faces)?;
        let refit = fits.iter().filter(|f| f.is_err()).count();
        let all = fits
            .into_par_iter()
            .zip(faces)
            .map(|(fit, face)| fit.unwrap_or_else(|_| fitter.fit(face.index, face.visible)))
            .collect();
        Ok((all, refit))
    }

    fn dispatch(
        &self,
        fitter: &Fitter,
        tables: &Tables,
        layout: &Layout,
        faces: &[FaceInput],
    ) -> Result<Vec<GpuFaceFit>, GpuError> {
        if faces.is_empty() {
            return Ok(Vec::new());
        }
        let ctx = &self.ctx;
        let device = &ctx.device;
        // Upload to read-back counts on the device's busy clock, as the cast does.
        let _busy = ctx.busy();
        let res = fitter.res as usize;
        let mut grid = vec![0xffu8; faces.len() * layout.grid_words as usize * 4];
        for (f, face) in faces.iter().enumerate() {
            let g = &mut grid[f * layout.grid_words as usize * 4..][..res * res];
            // `Fitter::cells`' grid: a later index of the same pixel wins.
            for (&p, &k) in face.index.iter().zip(face.visible) {
                g[p as usize] = k as u8;
            }
        }
        // The CPU's own threshold (`Fitter::within_epsilon`).
        let t_fx = fitter.leaf_threshold();
        let params = Params {
            res: fitter.res,
            samples: fitter.samples,
            half: fitter.codec.angles() / 2,
            offsets: fitter.codec.offsets(),
            faces: faces.len() as u32,
            budget: BUDGET,
            t_fx_lo: t_fx as u32,
            t_fx_hi: (t_fx >> 32) as u32,
            work_words: layout.work_words,
            out_words: layout.out_words,
            max_nodes: layout.max_nodes,
            grid_words: layout.grid_words,
            level_words: layout.level_words,
            wrong_ties: u32::from(self.wrong_ties),
            canary: 2,
            pad: 0,
        };
        let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let input = |label: &str, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let params_buf = input("fit params", bytemuck::bytes_of(&params));
        let proj = input("fit projections", bytemuck::cast_slice(&tables.proj));
        let offs = input("fit offsets", bytemuck::cast_slice(&tables.offsets));
        let thresh = input("fit thresholds", bytemuck::cast_slice(&tables.thresholds));
        let gather_params = input(
            "fit gather params",
            bytemuck::cast_slice(&[faces.len() as u32, layout.out_words, GATHER_WORDS, 0]),
        );
        let mut kept = self
            .buffers
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if !kept.as_ref().is_some_and(|b| b.fits(layout, faces.len())) {
            *kept = None;
            *kept = Some(FitBuffers::new(device, layout, faces.len()));
        }
        let Some(b) = kept.as_ref() else {
            return Err(GpuError::Failed("the fit's buffers".into()));
        };
        ctx.queue.write_buffer(&b.grid, 0, &grid);
        let words = |w: u32| faces.len() as u64 * u64::from(w) * 4;
        let buffers = [
            &params_buf,
            &proj,
            &offs,
            &thresh,
            &b.grid,
            &b.work,
            &b.result,
        ];
        let group = bspvt_raytrace::gpu::bind_buffers(device, "fit", &self.layout, &buffers);
        let gather_group = bspvt_raytrace::gpu::bind_buffers(
            device,
            "fit gather",
            &self.gather_layout,
            &[&gather_params, &b.result, &b.dense],
        );
        let mut enc =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("fit") });
        // As new buffers were: the shader's work area and output start at zero.
        enc.clear_buffer(&b.work, 0, Some(words(layout.work_words)));
        enc.clear_buffer(&b.result, 0, Some(words(layout.out_words)));
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("fit"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(faces.len() as u32, 1, 1);
            pass.set_pipeline(&self.gather);
            pass.set_bind_group(0, &gather_group, &[]);
            pass.dispatch_workgroups(faces.len() as u32, 1, 1);
        }
        enc.copy_buffer_to_buffer(&b.dense, 0, &b.readback, 0, words(GATHER_WORDS));
        let submitted = ctx.queue.submit([enc.finish()]);
        scope_result(validation)?;
        scope_result(memory)?;
        let dense = map_words(ctx, &b.readback, words(GATHER_WORDS), submitted)?;
        // Faces with more nodes than were gathered are read again whole (below).
        let cut_short = |w: &[u32]| w[0] == 0 && HEADER + 2 * w[1] as usize > w.len();
        let mut more = Vec::new();
        let mut fits: Vec<GpuFaceFit> = dense
            .chunks_exact(GATHER_WORDS as usize)
            .enumerate()
            .map(|(f, w)| {
                if cut_short(w) {
                    more.push(f);
                    Err(Refit::Malformed)
                } else {
                    decode(fitter, layout, w)
                }
            })
            .collect();
        if !more.is_empty() {
            let face_bytes = u64::from(layout.out_words) * 4;
            let whole = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("fit trees readback, whole"),
                size: more.len() as u64 * face_bytes,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let mut enc = device.create_command_encoder(&Default::default());
            for (k, &f) in more.iter().enumerate() {
                enc.copy_buffer_to_buffer(
                    &b.result,
                    f as u64 * face_bytes,
                    &whole,
                    k as u64 * face_bytes,
                    face_bytes,
                );
            }
            let submitted = ctx.queue.submit([enc.finish()]);
            let words = map_words(ctx, &whole, more.len() as u64 * face_bytes, submitted)?;
            for (&f, w) in more
                .iter()
                .zip(words.chunks_exact(layout.out_words as usize))
            {
                fits[f] = decode(fitter, layout, w);
            }
        }
        Ok(fits)
    }
}

/// The first `bytes` of a MAP_READ buffer once `submitted` is done, as words (waits for that
/// submission alone: the cast's own submissions go on).
fn map_words(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    bytes: u64,
    submitted: wgpu::SubmissionIndex,
) -> Result<Vec<u32>, GpuError> {
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, ..bytes, move |r| {
        let _ = tx.send(r);
    });
    ctx.device
        .poll(wgpu::PollType::Wait {
            submission_index: Some(submitted),
            timeout: None,
        })
        .map_err(|e| GpuError::Failed(e.to_string()))?;
    rx.recv()
        .map_err(|e| GpuError::Failed(e.to_string()))?
        .map_err(|e| GpuError::Failed(e.to_string()))?;
    let view = buffer
        .get_mapped_range(..bytes)
        .map_err(|e| GpuError::Failed(e.to_string()))?;
    let words: Vec<u32> = bytemuck::pod_collect_to_vec(&view);
    drop(view);
    buffer.unmap();
    Ok(words)
}

/// Per-face sizes in the shader's buffers.
struct Layout {
    grid_words: u32,
    level_words: u32,
    work_words: u32,
    max_nodes: u32,
    out_words: u32,
}

impl Layout {
    fn new(fitter: &Fitter) -> Layout {
        let res = fitter.res;
        let levels = res.min(16).trailing_zeros();
        let level_words: u32 = (0..=levels + 1).map(|l| (res >> l) * (res >> l)).sum();
        // A tree over res² pixels has at most 2·res² − 1 nodes.
        let max_nodes = (2 * res * res).min(4096);
        Layout {
            grid_words: (res * res).div_ceil(4),
            level_words,
            // The levels, the cell arena and the partition's scratch.
            work_words: level_words + 2 * res * res,
            max_nodes,
            out_words: HEADER as u32 + 2 * max_nodes,
        }
    }
}

/// A face's tree and statistics from the shader's words, or why the CPU must fit it.
fn decode(fitter: &Fitter, layout: &Layout, w: &[u32]) -> GpuFaceFit {
    match w[0] {
        0 => {}
        1 => return Err(Refit::Budget),
        2 => return Err(Refit::Nodes),
        3 => return Err(Refit::Stack),
        4 => return Err(Refit::Limit),
        _ => return Err(Refit::Malformed),
    }
    let count = w[1] as usize;
    if count == 0 || count > layout.max_nodes as usize {
        return Err(Refit::Malformed);
    }
    let scale = 255.0 * f64::from(fitter.samples);
    let mut abs_error = 0.0;
    let mut nodes = Vec::with_capacity(count);
    for n in w[HEADER..HEADER + 2 * count].chunks_exact(2) {
        if n[0] & LEAF != 0 {
            nodes.push(Node::Leaf {
                value: (n[0] & 0xff) as u8,
            });
            abs_error += f64::from(n[1]) / scale;
        } else {
            let line = QLine {
                angle: (n[0] & 0xffff) as u16,
                offset: (n[0] >> 16) as u16,
            };
            if u32::from(line.angle) >= fitter.codec.angles()
                || u32::from(line.offset) >= fitter.codec.offsets()
                || n[1] as usize >= count
            {
                return Err(Refit::Malformed);
            }
            nodes.push(Node::Split { line, right: n[1] });
        }
    }
    let stats = FitStats {
        pixels: u64::from(w[3]),
        abs_error,
        misclassified: u64::from(w[4]),
        leaves: u64::from(w[5]),
        cell_visits: u64::from(w[2]),
    };
    Ok((FaceTree { nodes }, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use bspvt_proto::bspvt::LineCodec;
    use bspvt_proto::cubemap::pixel_centres;
    use glam::Vec2;

    /// SplitMix64: reproducible faces without a dependency.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }
        fn unit(&mut self) -> f32 {
            (self.next() >> 40) as f32 / (1u64 << 24) as f32
        }
        fn below(&mut self, n: u32) -> u32 {
            (self.next() % u64::from(n)) as u32
        }
    }

    /// A random face: discs, half-planes or noise of escape counts, soft edges where a pixel
    /// has several rays, and pixels that do not matter (a half-plane or a disc of them, and
    /// scattered holes).
    fn random_face(res: u32, samples: u32, rng: &mut Rng) -> (Vec<u32>, Vec<u16>) {
        let uv = pixel_centres(res);
        let kind = rng.below(5);
        let s = samples as f32;
        let mut shapes = Vec::new();
        for _ in 0..1 + rng.below(3) {
            let c = Vec2::new(rng.unit() * 2.0 - 1.0, rng.unit() * 2.0 - 1.0);
            let r = 0.05 + rng.unit() * 0.8;
            let n = Vec2::from_angle(rng.unit() * std::f32::consts::TAU);
            shapes.push((c, r, n));
        }
        let soft = rng.unit() * 0.2;
        let noise = rng.unit();
        let care = rng.below(4);
        let care_n = Vec2::from_angle(rng.unit() * std::f32::consts::TAU);
        let holes = rng.unit() * 0.2;
        let (mut index, mut visible) = (Vec::new(), Vec::new());
        for (p, &x) in uv.iter().enumerate() {
            let matters = match care {
                0 => true,
                1 => care_n.dot(x) < 0.3,
                2 => (x - shapes[0].0).length() > 0.3,
                _ => rng.unit() >= holes,
            };
            if !matters {
                continue;
            }
            // Coverage in [0, 1] of the occluders at x.
            let mut v: f32 = 1.0;
            for &(c, r, n) in &shapes {
                let d = match kind {
                    0 | 3 => (x - c).length() - r,
                    1 => n.dot(x - c),
                    _ => 0.0,
                };
                let inside = if soft > 0.0 {
                    (0.5 - d / soft).clamp(0.0, 1.0)
                } else {
                    f32::from(u8::from(d < 0.0))
                };
                v = v.min(1.0 - inside);
            }
            if kind == 2 || (kind == 3 && rng.unit() < noise * 0.3) {
                v = rng.unit();
            }
            if kind == 4 {
                // Blocks of noise: uniform cells of several sizes.
                let b = 1 << rng.below(4);
                let (i, j) = (p as u32 % res / b, p as u32 / res / b);
                let h = (i.wrapping_mul(73_856_093) ^ j.wrapping_mul(19_349_663)) % 7;
                v = h as f32 / 6.0;
            }
            let k = if samples == 1 {
                u16::from(v >= 0.5)
            } else {
                (v * s).round().clamp(0.0, s) as u16
            };
            index.push(p as u32);
            visible.push(k);
        }
        (index, visible)
    }

    /// Fits `faces` on the GPU and on the CPU; returns (faces compared, faces flagged, faces
    /// that differ), printing the first differences.
    fn compare(
        gpu: &GpuFitter,
        fitter: &Fitter,
        faces: &[(Vec<u32>, Vec<u16>)],
        label: &str,
    ) -> (usize, usize, usize) {
        let inputs: Vec<FaceInput> = faces
            .iter()
            .map(|(index, visible)| FaceInput { index, visible })
            .collect();
        let t0 = std::time::Instant::now();
        let fits = gpu.fit(fitter, &inputs).expect("GPU fit");
        let gpu_s = t0.elapsed().as_secs_f64();
        let t1 = std::time::Instant::now();
        let cpu: Vec<(FaceTree, FitStats)> = faces.iter().map(|(i, v)| fitter.fit(i, v)).collect();
        let cpu_s = t1.elapsed().as_secs_f64();
        let (mut flagged, mut differ, mut past_limit) = (0, 0, 0);
        for (f, (fit, (ct, cs))) in fits.iter().zip(&cpu).enumerate() {
            let (gt, gs) = match fit {
                Ok(f) => f,
                Err(why) => {
                    flagged += 1;
                    // The shader's loop count is a model of llvmpipe's limiter: it should
                    // stop a face before the limiter does (the canary flags it otherwise).
                    if *why == Refit::Limit {
                        past_limit += 1;
                    }
                    continue;
                }
            };
            // The statistics to the bit, abs_error included (integer sums per leaf, summed in
            // the same order).
            if gt != ct || gs != cs {
                differ += 1;
                if differ <= 3 {
                    let first = gt.nodes.iter().zip(&ct.nodes).position(|(a, b)| a != b);
                    eprintln!(
                        "{label}: face {f} differs: {} GPU nodes, {} CPU nodes, first differing node {first:?}; GPU {gs:?} CPU {cs:?}",
                        gt.nodes.len(),
                        ct.nodes.len()
                    );
                }
            }
        }
        eprintln!(
            "{label}: {} faces, {flagged} flagged for the CPU ({past_limit} by the canary), {differ} differ; GPU {:.3} s, CPU {:.3} s",
            faces.len(),
            gpu_s,
            cpu_s
        );
        (faces.len(), flagged, differ)
    }

    fn fitter<'a>(
        codec: &'a LineCodec,
        uv: &'a [Vec2],
        res: u32,
        samples: u32,
        epsilon: f64,
    ) -> Fitter<'a> {
        Fitter::new(codec, uv, res, samples, epsilon, SplitMethod::Default)
    }

    /// Random faces at 4² to 64², one and 16 rays per pixel, several ε: the GPU's trees are
    /// the CPU's, node for node, with the same statistics. A resolution the shader does not
    /// take (12²: its cells' quadtree would halve to odd sides) is all left to the CPU.
    #[test]
    fn random_faces_fit_as_on_the_cpu() {
        let Some(ctx) = GpuContext::for_test() else {
            return;
        };
        let gpu = GpuFitter::new(ctx).expect("fit pipeline");
        let mut rng = Rng(7);
        let (mut total, mut flagged, mut differ) = (0, 0, 0);
        for res in [4u32, 8, 16, 24, 32, 48, 64] {
            let codec = LineCodec::for_resolution(res);
            let uv = pixel_centres(res);
            for samples in [1u32, 16] {
                for epsilon in [0.0, 1e-3] {
                    let count = if res == 64 { 24 } else { 48 };
                    let mut faces: Vec<_> = (0..count)
                        .map(|_| random_face(res, samples, &mut rng))
                        .collect();
                    // No pixel; every pixel, all visible; a pixel given twice (the later wins).
                    let all = (res * res) as usize;
                    faces.push((Vec::new(), Vec::new()));
                    faces.push(((0..res * res).collect(), vec![samples as u16; all]));
                    faces.push((vec![0, 1, 0], vec![0, samples as u16, samples as u16]));
                    let f = fitter(&codec, &uv, res, samples, epsilon);
                    let (t, fl, d) =
                        compare(&gpu, &f, &faces, &format!("{res}² S={samples} ε={epsilon}"));
                    total += t;
                    flagged += fl;
                    differ += d;
                }
            }
        }
        // 12²: unsupported, every face flagged.
        let (res, samples) = (12, 1);
        let codec = LineCodec::for_resolution(res);
        let uv = pixel_centres(res);
        let faces: Vec<_> = (0..4)
            .map(|_| random_face(res, samples, &mut rng))
            .collect();
        let inputs: Vec<FaceInput> = faces
            .iter()
            .map(|(index, visible)| FaceInput { index, visible })
            .collect();
        let fits = gpu
            .fit(&fitter(&codec, &uv, res, samples, 0.0), &inputs)
            .expect("GPU fit");
        assert!(
            fits.iter()
                .all(|r| r.as_ref().err() == Some(&Refit::Unsupported))
        );
        eprintln!("random faces: {total} compared, {flagged} flagged for the CPU, {differ} differ");
        assert_eq!(differ, 0, "faces differ");
        assert!(flagged * 2 < total, "{flagged} of {total} flagged");
    }

    /// Real faces: the cube maps of built-in scenes (plate-small, the room, the two-lamp room)
    /// at 16², 32² and 64², one and four rays per pixel.
    #[test]
    fn real_faces_fit_as_on_the_cpu() {
        let Some(ctx) = GpuContext::for_test() else {
            return;
        };
        let gpu = GpuFitter::new(ctx).expect("fit pipeline");
        let (mut total, mut flagged, mut differ) = (0, 0, 0);
        for (name, res, ss) in [
            ("plate-small", 16u32, 1u32),
            ("plate-small", 32, 1),
            ("plate-small", 64, 1),
            ("plate-small", 32, 2),
            ("plate-small", 64, 2),
            ("room", 32, 1),
            ("room", 64, 1),
            ("two-lamps", 64, 2),
        ] {
            let mut scene = bspvt_proto::builtin::scene(name).expect("built-in scene");
            scene.bake.face_res = res;
            scene.bake.supersampling = ss;
            let b = crate::Baker::new(&scene);
            let n = b.mesh().vertex_count() as u32;
            let mut faces = Vec::new();
            for v in (0..n).step_by((n / 40).max(1) as usize) {
                let (maps, _) = b.cube_map(v);
                faces.extend(maps.into_iter().flatten().map(|f| (f.index, f.visible)));
            }
            let f = Fitter::new(
                &b.codec,
                &b.table.uv,
                res,
                b.table.samples,
                f64::from(b.settings.epsilon),
                b.settings.split,
            );
            let (t, fl, d) = compare(&gpu, &f, &faces, &format!("{name} {res}² S={}", ss * ss));
            total += t;
            flagged += fl;
            differ += d;
        }
        eprintln!("real faces: {total} compared, {flagged} flagged for the CPU, {differ} differ");
        assert_eq!(differ, 0, "faces differ");
    }

    /// The comparison sees a wrong shader: ties of E broken the other way change trees.
    #[test]
    fn wrong_ties_are_caught() {
        let Some(ctx) = GpuContext::for_test() else {
            return;
        };
        let mut gpu = GpuFitter::new(ctx).expect("fit pipeline");
        gpu.set_wrong_ties(true);
        let mut rng = Rng(11);
        let res = 16;
        let codec = LineCodec::for_resolution(res);
        let uv = pixel_centres(res);
        let faces: Vec<_> = (0..48).map(|_| random_face(res, 1, &mut rng)).collect();
        let (_, _, differ) = compare(
            &gpu,
            &fitter(&codec, &uv, res, 1, 0.0),
            &faces,
            "wrong ties",
        );
        assert!(
            differ > 0,
            "a shader breaking ties the other way went unnoticed"
        );
    }
}
