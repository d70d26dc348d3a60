//! The trees of all vertices on the GPU: one flat node array and six root indices per vertex
//! (as decoded on the CPU). Trees that arrive while streaming are appended: the node buffer
//! grows by doubling (a GPU-side copy), and only the new vertices' roots are written.

use bspvt_proto::bspvt::{LineCodec, VertexTrees};
use bspvt_proto::cubemap::FACES;
use bspvt_shaders::gpu::trees::{NO_TREES, codec_params, encode_vertex, line_normals};

use super::context::Gpu;
use crate::render::renderer::Trees;

/// The trees on the GPU and which vertices' trees are there.
pub(crate) struct GpuTrees {
    /// (trees slice address, length) of what was uploaded: another slice starts over.
    source: (usize, usize),
    uploaded: Vec<bool>,
    /// How many of `uploaded` are set.
    uploaded_count: usize,
    roots_cpu: Vec<u32>,
    pub(crate) roots: wgpu::Buffer,
    pub(crate) nodes: wgpu::Buffer,
    node_len: u64,
    node_cap: u64,
    /// LineCodec's normal table, and (offsets O, √2 / O) of the codec it came from.
    pub(crate) line_normals: wgpu::Buffer,
    pub(crate) codec: (u32, f32),
}

fn storage(gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

impl GpuTrees {
    /// Room for `vertices` vertices, none with trees.
    pub(crate) fn new(gpu: &Gpu, vertices: usize) -> GpuTrees {
        let roots_cpu = vec![NO_TREES; vertices * FACES];
        let roots = storage(gpu, "tree roots", (roots_cpu.len() * 4) as u64);
        gpu.queue
            .write_buffer(&roots, 0, bytemuck::cast_slice(&roots_cpu));
        GpuTrees {
            source: (0, 0),
            uploaded: vec![false; vertices],
            uploaded_count: 0,
            roots_cpu,
            roots,
            nodes: storage(gpu, "tree nodes", 1 << 16),
            node_len: 0,
            node_cap: (1 << 16) / 8,
            line_normals: storage(gpu, "line normals", 16),
            codec: (1, 0.0),
        }
    }

    /// Vertices whose trees are on the GPU.
    pub(crate) fn uploaded(&self) -> usize {
        self.uploaded_count
    }

    /// Uploads the trees of the vertices that have them and were not uploaded yet (all of
    /// them when `trees` is another set than last time); `None`: no trees, all unshadowed.
    pub(crate) fn sync(&mut self, gpu: &Gpu, trees: Option<&Trees>) {
        let Some(t) = trees else {
            if self.source != (0, 0) {
                self.reset(gpu, (0, 0));
            }
            return;
        };
        let source = (t.trees.as_ptr() as usize, t.trees.len());
        if source != self.source {
            self.reset(gpu, source);
            self.set_codec(gpu, &t.codec);
        }
        let n = self.uploaded.len().min(t.trees.len());
        // Every tree there: nothing to look for (a frame does no work per vertex).
        if self.uploaded_count == n {
            return;
        }
        let new: Vec<u32> = (0..n as u32)
            .filter(|&v| !self.uploaded[v as usize] && t.has(v))
            .collect();
        self.upload(gpu, &new, t.trees);
    }

    /// Uploads the trees of vertices `new` (indices into `trees`).
    pub(crate) fn upload(&mut self, gpu: &Gpu, new: &[u32], trees: &[VertexTrees]) {
        let (Some(&first), Some(&last)) = (new.first(), new.last()) else {
            return;
        };
        let mut words = Vec::new();
        for &v in new {
            let roots = encode_vertex(&trees[v as usize], self.node_len, &mut words);
            self.roots_cpu[v as usize * FACES..][..FACES].copy_from_slice(&roots);
            self.uploaded_count += usize::from(!self.uploaded[v as usize]);
            self.uploaded[v as usize] = true;
        }
        self.reserve(gpu, self.node_len + words.len() as u64);
        gpu.queue
            .write_buffer(&self.nodes, self.node_len * 8, bytemuck::cast_slice(&words));
        self.node_len += words.len() as u64;
        let (a, b) = (first as usize * FACES, (last as usize + 1) * FACES);
        gpu.queue.write_buffer(
            &self.roots,
            (a * 4) as u64,
            bytemuck::cast_slice(&self.roots_cpu[a..b]),
        );
    }

    /// Uses `codec`'s lines.
    pub(crate) fn set_codec(&mut self, gpu: &Gpu, codec: &LineCodec) {
        let normals = line_normals(codec);
        self.line_normals = storage(gpu, "line normals", (normals.len() * 8) as u64);
        gpu.queue
            .write_buffer(&self.line_normals, 0, bytemuck::cast_slice(&normals));
        self.codec = codec_params(codec);
    }

    fn reset(&mut self, gpu: &Gpu, source: (usize, usize)) {
        self.source = source;
        self.uploaded.iter_mut().for_each(|b| *b = false);
        self.uploaded_count = 0;
        self.roots_cpu.iter_mut().for_each(|r| *r = NO_TREES);
        gpu.queue
            .write_buffer(&self.roots, 0, bytemuck::cast_slice(&self.roots_cpu));
        self.node_len = 0;
    }

    /// Grows the node buffer (doubling, contents copied on the GPU) to hold `nodes`.
    fn reserve(&mut self, gpu: &Gpu, nodes: u64) {
        if nodes <= self.node_cap {
            return;
        }
        let cap = nodes.max(self.node_cap * 2);
        let bigger = storage(gpu, "tree nodes", cap * 8);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&self.nodes, 0, &bigger, 0, self.node_len * 8);
        gpu.queue.submit([enc.finish()]);
        self.nodes = bigger;
        self.node_cap = cap;
    }
}
