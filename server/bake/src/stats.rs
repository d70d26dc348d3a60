//! The STATS.json of a bake.

use serde::Serialize;

use crate::{BakeOutput, Totals};

/// What `bspvt-server bake --stats` writes.
#[derive(Clone, Debug, Serialize)]
pub struct BakeStats {
    /// Vertices baked.
    pub vertices: u64,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Worker threads.
    pub threads: usize,
    /// (ray + fit) thread-seconds per vertex, measured per vertex on the worker threads.
    pub thread_seconds_per_vertex: f64,
    /// Ray-casting thread-seconds per vertex (with the GPU backend: the caster's wall-clock
    /// seconds per vertex, ray generation, upload and read-back included).
    pub ray_thread_seconds_per_vertex: f64,
    /// Fitting thread-seconds per vertex.
    pub fit_thread_seconds_per_vertex: f64,
    /// Rays tested against geometry per vertex (rays answered by culling alone not counted).
    pub rays_per_vertex: f64,
    /// Rays per vertex that traversed the BVH (the rest were answered by a candidate list or,
    /// in the adaptive cast, by a neighbour's blocker).
    pub traversals_per_vertex: f64,
    /// GPU backend: sub-rays per vertex cast again on the CPU, those of pixels where the
    /// device's rounding could have decided a ray otherwise (0 on the CPU).
    pub recast_per_vertex: f64,
    /// Rays tested per ray-casting thread-second.
    pub rays_per_thread_second: f64,
    /// How rays were cast (`adaptive` or `full`: the same cube maps).
    pub cast: crate::CastMode,
    /// Where rays were cast (`cpu` or `gpu`).
    pub backend: crate::Backend,
    /// Encoded bytes (chunk frames, after zstd).
    pub bytes: u64,
    /// Encoded bytes per vertex.
    pub bytes_per_vertex: f64,
    /// Tree leaves per vertex.
    pub leaves_per_vertex: f64,
    /// Mean |V − v̄| of the tree against the ray-cast cube map, over the pixels that matter.
    pub mean_abs_visibility_error: f64,
    /// Share of the pixels that matter whose leaf value is on the other side of ½.
    pub misclassified_pixel_fraction: f64,
    /// Pixels that matter per vertex (those fitted).
    pub pixels_that_matter_per_vertex: f64,
    /// Cube-map face resolution.
    pub face_res: u32,
    /// Leaf tolerance ε.
    pub epsilon: f32,
    /// Rays per pixel side.
    pub supersampling: u32,
    /// How split lines were chosen.
    pub split: bspvt_proto::SplitMethod,
}

impl BakeStats {
    /// The statistics of a finished bake run on `threads` threads.
    pub fn new(out: &BakeOutput, threads: usize) -> BakeStats {
        let mut s = BakeStats::from_totals(&out.totals, out.totals.bytes, threads);
        s.seconds = out.seconds;
        s.face_res = out.header.face_res;
        s.epsilon = out.header.epsilon;
        s.supersampling = out.header.supersampling;
        s.split = out.header.split;
        s.cast = out.cast;
        s.backend = out.backend;
        s
    }

    /// The statistics of `t` (per-vertex sums) with `bytes` encoded; `seconds` and the settings are
    /// left at zero (the split method at its default).
    pub fn from_totals(t: &Totals, bytes: u64, threads: usize) -> BakeStats {
        let v = t.vertices.max(1) as f64;
        let px = t.fit.pixels.max(1) as f64;
        BakeStats {
            vertices: t.vertices,
            seconds: 0.0,
            threads,
            thread_seconds_per_vertex: (t.ray_seconds + t.fit_seconds) / v,
            ray_thread_seconds_per_vertex: t.ray_seconds / v,
            fit_thread_seconds_per_vertex: t.fit_seconds / v,
            rays_per_vertex: t.rays as f64 / v,
            traversals_per_vertex: t.traversals as f64 / v,
            recast_per_vertex: t.recast as f64 / v,
            rays_per_thread_second: if t.ray_seconds > 0.0 {
                t.rays as f64 / t.ray_seconds
            } else {
                0.0
            },
            cast: Default::default(),
            backend: Default::default(),
            bytes,
            bytes_per_vertex: bytes as f64 / v,
            leaves_per_vertex: t.fit.leaves as f64 / v,
            mean_abs_visibility_error: t.fit.abs_error / px,
            misclassified_pixel_fraction: t.fit.misclassified as f64 / px,
            pixels_that_matter_per_vertex: t.fit.pixels as f64 / v,
            face_res: 0,
            epsilon: 0.0,
            supersampling: 0,
            split: Default::default(),
        }
    }
}
