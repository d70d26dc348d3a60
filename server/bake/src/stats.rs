//! The STATS.json of a bake.

use serde::Serialize;

use crate::{BakeOutput, Totals};

/// What `bspvt-server bake --stats` writes.
#[derive(Clone, Debug, Serialize)]
pub struct BakeStats {
    pub vertices: u64,
    pub seconds: f64,
    pub threads: usize,
    /// (ray + fit) thread-seconds per vertex, measured per vertex on the worker threads.
    pub thread_seconds_per_vertex: f64,
    pub ray_thread_seconds_per_vertex: f64,
    pub fit_thread_seconds_per_vertex: f64,
    pub rays_per_vertex: f64,
    pub bytes: u64,
    pub bytes_per_vertex: f64,
    pub leaves_per_vertex: f64,
    /// Mean |V − v̄| of the tree against the ray-cast cube map, over the pixels that matter.
    pub mean_abs_visibility_error: f64,
    /// Share of the pixels that matter whose leaf value is on the other side of ½.
    pub misclassified_pixel_fraction: f64,
    pub pixels_that_matter_per_vertex: f64,
    pub face_res: u32,
    pub epsilon: f32,
    pub supersampling: u32,
    pub split: bspvt_proto::SplitMethod,
}

impl BakeStats {
    pub fn new(out: &BakeOutput, threads: usize) -> BakeStats {
        let mut s = BakeStats::from_totals(&out.totals, out.totals.bytes, threads);
        s.seconds = out.seconds;
        s.face_res = out.header.face_res;
        s.epsilon = out.header.epsilon;
        s.supersampling = out.header.supersampling;
        s.split = out.header.split;
        s
    }

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
