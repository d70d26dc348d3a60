//! [`Occluder`]'s any-hit queries in a wgpu compute shader (`occlusion.wgsl`), shaped as the
//! bake needs them: visibility cube maps. The CPU-built CWBVH, its triangles and their vertex
//! indices are uploaded once ([`GpuOccluder::new`]), then the cube map's sub-ray directions and
//! the rays' stops once per bake ([`GpuCubeTable`]); per batch of vertices only each vertex's
//! origin and its mask of pixels that matter go up, and each pixel's counts (escaping and cast
//! sub-rays) come back ([`GpuOccluder::cube_counts`]). The rays are made on the GPU: the CPU
//! made and uploaded 24 bytes per ray before, which took most of a GPU bake's time
//! (docs/benchmarks.md).

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::Occluder;
use crate::gpu::{GpuContext, GpuError, bind_buffers, dispatch_grid, max_items, scope_result};

/// One vertex of a cube-map batch: where its rays start, the nearest hit that counts, its
/// normal (sub-rays below its horizon escape uncast) and its index (its own triangles are
/// skipped).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct CubeSource {
    origin: [f32; 3],
    t_min: f32,
    normal: [f32; 3],
    skip: u32,
}

impl CubeSource {
    /// A vertex's rays from `origin`, hits nearer than `t_min` ignored, horizon `normal`,
    /// triangles using vertex `skip` ignored.
    pub fn new(origin: glam::Vec3, t_min: f32, normal: glam::Vec3, skip: u32) -> CubeSource {
        CubeSource {
            origin: origin.to_array(),
            t_min,
            normal: normal.to_array(),
            skip,
        }
    }
}

/// Where a ray ends (the bake's light stops), for [`GpuOccluder::cube_table`].
#[derive(Clone, Debug, PartialEq)]
pub enum GpuStop {
    /// Where the ray enters the box (`Aabb::ray_entry`; a ray starting inside is unbounded).
    Region {
        /// The box's low corner.
        min: glam::Vec3,
        /// The box's high corner.
        max: glam::Vec3,
    },
    /// Where the ray crosses the plane (forward, finite).
    Plane {
        /// A point of the plane.
        point: glam::Vec3,
        /// The plane's unit normal.
        normal: glam::Vec3,
    },
    /// Where the ray crosses the plane `normal · x = offset` within `t · spread / |cos|` of the
    /// convex polygon `m · x ≥ c` (`edges`: (m, c), at most 8); from the side `normal` points
    /// to only, unless `two_sided` (bspvt-bake's `LampStop`).
    Lamp {
        /// The plane's unit normal.
        normal: glam::Vec3,
        /// The plane's offset.
        offset: f32,
        /// The polygon's edges as in-plane half-planes.
        edges: Vec<glam::Vec4>,
        /// How much the polygon grows per unit of distance.
        spread: f32,
        /// Reached from both sides.
        two_sided: bool,
    },
    /// Where the ray enters the sphere, or passes closest to its centre when it passes
    /// within `radius + 2 t · spread` of it without entering (bspvt-bake's `SphereStop`).
    Sphere {
        /// The sphere's centre.
        centre: glam::Vec3,
        /// Its radius.
        radius: f32,
        /// How much the sphere grows per unit of distance.
        spread: f32,
    },
}

/// vec4 words per stop in the shader's table: a header of two, then up to eight edges.
const STOP_WORDS: usize = 10;

/// A cube map's sub-ray directions and the rays' stops, on the GPU for a whole bake.
pub struct GpuCubeTable {
    dirs: wgpu::Buffer,
    stops: wgpu::Buffer,
    stop_count: u32,
    pixels: u32,
    samples: u32,
    /// ULP every reciprocal and quotient of the shader is scaled by (0: none).
    skew: u32,
    /// Every test answered as computed, none unsure.
    plain: bool,
}

impl GpuCubeTable {
    /// Test hook: the shader scales every reciprocal and quotient by (1 + `ulps` · 2⁻²³), as
    /// a device whose division rounds less well (WGSL allows 2.5 ULP) would; with `plain`, it
    /// answers every test as computed and flags nothing unsure (the shader before the flag).
    /// So a test on any adapter can show what another device's rounding changes, and that
    /// the flag catches it.
    #[doc(hidden)]
    pub fn skew_rounding(&mut self, ulps: u32, plain: bool) {
        self.skew = ulps;
        self.plain = plain;
    }

    /// Pixels per cube map (6 · res²).
    pub fn pixels(&self) -> u32 {
        self.pixels
    }
}

/// An occluder's CWBVH, triangles, triangles' vertex indices and cut-outs in storage buffers:
/// what every ray shader of this crate reads (`occlusion.wgsl`, `first_hit.wgsl`).
pub(crate) struct MeshBuffers {
    pub(crate) nodes: wgpu::Buffer,
    pub(crate) tris: wgpu::Buffer,
    pub(crate) prim_verts: wgpu::Buffer,
    /// The cut-outs ([`crate::Cutouts::gpu_words`]; one zero word: none).
    pub(crate) cut: wgpu::Buffer,
    /// [`Occluder::box_t_min`], which the shaders' traversals read.
    pub(crate) box_t_min: f32,
}

impl MeshBuffers {
    /// Uploads `occ`'s BVH, triangles, vertex indices and cut-outs.
    pub(crate) fn new(device: &wgpu::Device, occ: &Occluder) -> MeshBuffers {
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
        // Per triangle 16 floats: v0, e1, e2, ng, then |e1|, |e2|, |ng| (rounded up a hair:
        // bounds of the shader's rounding, `occlusion.wgsl`) and 0.
        let tri_words: Vec<f32> = occ
            .tris
            .iter()
            .flat_map(|t| {
                let norms = [t.e1, t.e2, t.ng].map(|v| v.length() * (1.0 + 1e-6));
                [t.v0, t.e1, t.e2, t.ng]
                    .into_iter()
                    .flat_map(|v| v.to_array())
                    .chain(norms)
                    .chain([0.0])
            })
            .collect();
        let tris = storage("triangles", bytemuck::cast_slice(&tri_words));
        let prim_verts = storage("triangle vertices", bytemuck::cast_slice(&occ.indices));
        let cut_words = match &occ.cut {
            Some((c, slots)) => c.gpu_words(slots),
            None => vec![0u32],
        };
        let cut = storage("cut-outs", bytemuck::cast_slice(&cut_words));
        MeshBuffers {
            nodes,
            tris,
            prim_verts,
            cut,
            box_t_min: occ.box_t_min(),
        }
    }
}

const WORKGROUP: u32 = 64;

/// An occluder on the GPU: visibility cube maps of batches of vertices.
pub struct GpuOccluder {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    mesh: MeshBuffers,
    /// Invocations (vertex × pixel) per dispatch: buffer and dispatch-size limits.
    max_items: usize,
}

impl GpuOccluder {
    /// Uploads `occ`'s BVH, triangles and vertex indices, and builds the pipeline (a device
    /// that refuses either is an error, not a panic).
    pub fn new(ctx: &GpuContext, occ: &Occluder) -> Result<GpuOccluder, GpuError> {
        let device = &ctx.device;
        let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mesh = MeshBuffers::new(device, occ);
        let wgsl = [
            include_str!("cwbvh.wgsl"),
            include_str!("occlusion.wgsl"),
            crate::CUTOUT_WGSL,
        ]
        .concat();
        // The BVH, triangles, … read; binding 7 (the counts) written.
        let read_only = [true, true, true, true, true, true, true, false, true, true];
        let (pipeline, layout) = ctx.storage_pipeline("occlusion", &wgsl, &read_only);
        let max_items = max_items(device, 4, WORKGROUP);
        scope_result(validation)?;
        scope_result(memory)?;
        Ok(GpuOccluder {
            pipeline,
            layout,
            mesh,
            max_items,
        })
    }

    /// Uploads a cube map's sub-ray directions (`dirs`, face-major, then pixel, then
    /// sub-sample: `pixels` × `samples` unit vectors) and the rays' `stops`, for a whole bake.
    /// A table larger than the adapter binds is an error that says so.
    pub fn cube_table(
        &self,
        ctx: &GpuContext,
        dirs: &[glam::Vec3],
        pixels: u32,
        samples: u32,
        stops: &[GpuStop],
    ) -> Result<GpuCubeTable, GpuError> {
        // Counts travel in 8 bits each (`cube_counts`).
        if dirs.len() != pixels as usize * samples as usize || samples == 0 || samples > 0xff {
            return Err(GpuError::Failed(format!(
                "{} directions for {pixels} pixels of {samples} sub-rays",
                dirs.len()
            )));
        }
        let limits = ctx.device.limits();
        let bytes = dirs.len() as u64 * 16;
        let most = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if bytes > most {
            return Err(GpuError::Failed(format!(
                "the cube map's {} sub-ray directions take {bytes} bytes, more than this \
                 adapter binds ({most}): lower the face resolution or the supersampling, or \
                 bake on the CPU",
                dirs.len()
            )));
        }
        let device = &ctx.device;
        let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let dir_words: Vec<[f32; 4]> = dirs.iter().map(|d| d.extend(0.0).to_array()).collect();
        let mut stop_words: Vec<[f32; 4]> = Vec::with_capacity(stops.len() * STOP_WORDS);
        for s in stops {
            let mut words = [glam::Vec4::ZERO; STOP_WORDS];
            match s {
                GpuStop::Region { min, max } => {
                    words[0] = min.extend(0.0);
                    words[1] = max.extend(0.0);
                }
                GpuStop::Plane { point, normal } => {
                    words[0] = point.extend(1.0);
                    words[1] = normal.extend(0.0);
                }
                GpuStop::Lamp {
                    normal,
                    offset,
                    edges,
                    spread,
                    two_sided,
                } => {
                    let n = edges.len().min(STOP_WORDS - 2);
                    words[0] = normal.extend(2.0);
                    words[1] = glam::Vec4::new(
                        *offset,
                        *spread,
                        n as f32,
                        if *two_sided { 1.0 } else { 0.0 },
                    );
                    words[2..2 + n].copy_from_slice(&edges[..n]);
                }
                GpuStop::Sphere {
                    centre,
                    radius,
                    spread,
                } => {
                    words[0] = centre.extend(3.0);
                    words[1] = glam::Vec4::new(*radius, *spread, 0.0, 0.0);
                }
            }
            stop_words.extend(words.iter().map(|v| v.to_array()));
        }
        // wgpu refuses empty buffers.
        if stop_words.is_empty() {
            stop_words.push([0.0; 4]);
        }
        let storage = |label: &str, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let table = GpuCubeTable {
            dirs: storage("cube map directions", bytemuck::cast_slice(&dir_words)),
            stops: storage("ray stops", bytemuck::cast_slice(&stop_words)),
            stop_count: stops.len() as u32,
            pixels,
            samples,
            skew: 0,
            plain: false,
        };
        scope_result(validation)?;
        scope_result(memory)?;
        Ok(table)
    }

    /// For each of `sources` and each of `table`'s pixels whose bit is set in the source's
    /// mask (`masks`: ⌈pixels / 32⌉ words per source, bit p of word p / 32), in that order
    /// (source, then pixel): its escaping sub-rays | 0x80 when unsure | its cast sub-rays << 8.
    /// A sub-ray below the source's horizon escapes uncast; the others are cast from its origin
    /// to their first stop, and escape when no triangle (but the source's own) is hit in
    /// [t_min, stop): the answer of [`Occluder::occluded_between`] for the same ray, except in
    /// a pixel flagged unsure (0x80), where some decision (a barycentric, t, a box, a stop, the
    /// horizon, a cut-out's alpha) was within this device's possible rounding (2⁻¹⁶ of the
    /// magnitudes it is made of) of the other way: the caller casts those again. Only the
    /// pixels that matter come back, 2 bytes each.
    pub fn cube_counts(
        &self,
        ctx: &GpuContext,
        table: &GpuCubeTable,
        sources: &[CubeSource],
        masks: &[u32],
    ) -> Result<Vec<u16>, GpuError> {
        let pixels = table.pixels as usize;
        let words = pixels.div_ceil(32);
        if masks.len() != sources.len() * words {
            return Err(GpuError::Failed(format!(
                "{} mask words for {} sources of {words}",
                masks.len(),
                sources.len()
            )));
        }
        let per_dispatch = (self.max_items / pixels.max(1)).max(1);
        let mut out = Vec::new();
        for (s, m) in sources
            .chunks(per_dispatch)
            .zip(masks.chunks(per_dispatch * words))
        {
            out.extend(self.dispatch(ctx, table, s, m)?);
        }
        Ok(out)
    }

    fn dispatch(
        &self,
        ctx: &GpuContext,
        table: &GpuCubeTable,
        sources: &[CubeSource],
        masks: &[u32],
    ) -> Result<Vec<u16>, GpuError> {
        let n = sources.len() * table.pixels as usize;
        if n == 0 {
            return Ok(Vec::new());
        }
        // Each mask word with the number of pixels that matter before it: where its pixels'
        // counts go.
        let mut slots = 0u32;
        let mask_words: Vec<[u32; 2]> = masks
            .iter()
            .map(|&m| {
                let w = [m, slots];
                slots += m.count_ones();
                w
            })
            .collect();
        let wanted = slots as usize;
        if wanted == 0 {
            return Ok(Vec::new());
        }
        let device = &ctx.device;
        let t0 = std::time::Instant::now();
        let _busy = ctx.busy();
        let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let input = |label: &str, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let src = input("cube sources", bytemuck::cast_slice(sources));
        let mask = input("cube masks", bytemuck::cast_slice(&mask_words));
        // Two 16-bit counts per word.
        let bytes = (wanted.div_ceil(2) * 4) as u64;
        let result = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("cube counts"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("cube counts readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let (gx, gy) = dispatch_grid(device, n as u32, WORKGROUP);
        let params = [
            sources.len() as u32,
            table.pixels,
            table.samples,
            table.stop_count,
            gx * WORKGROUP,
            table.pixels.div_ceil(32),
            table.skew,
            u32::from(table.plain),
            self.mesh.box_t_min.to_bits(),
            0,
            0,
            0,
        ];
        let params_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("cube params"),
            contents: bytemuck::cast_slice(&params),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let buffers = [
            &self.mesh.nodes,
            &self.mesh.tris,
            &self.mesh.prim_verts,
            &src,
            &table.dirs,
            &mask,
            &table.stops,
            &result,
            &params_buffer,
            &self.mesh.cut,
        ];
        let group = bind_buffers(device, "occlusion", &self.layout, &buffers);
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("occlusion"),
        });
        // The counts are OR-ed into it, two per word.
        enc.clear_buffer(&result, 0, None);
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
        scope_result(validation)?;
        scope_result(memory)?;
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
        // Slot 2i in the low half of word i, slot 2i + 1 in the high half.
        let mut counts: Vec<u16> = view
            .chunks_exact(4)
            .flat_map(|w| {
                let w = u32::from_le_bytes([w[0], w[1], w[2], w[3]]);
                [w as u16, (w >> 16) as u16]
            })
            .collect();
        drop(view);
        counts.truncate(wanted);
        readback.unmap();
        if std::env::var_os("BSPVT_GPU_TIMING").is_some() {
            // Where a dispatch's wall-clock time goes (docs/benchmarks.md, the GPU bake).
            let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
            eprintln!(
                "gpu cast: {} vertices × {} pixels ({wanted} matter): buffers+upload {:.2} ms, submit..done {:.2} ms, read-back {:.2} ms",
                sources.len(),
                table.pixels,
                ms(t_upload),
                ms(t_cast - t_upload),
                ms(t0.elapsed() - t_cast)
            );
        }
        Ok(counts)
    }
}
