//! # bspvt-bake
//!
//! The visibility bake [paper000 §3.1–3.2]: per vertex, a ray-cast visibility cube map, then one
//! BSPVT per face, encoded in chunks ([`bspvt_proto::encoding`]). Used by the baking service,
//! the offline `bspvt-server bake` and the client's own bakes (methods that need trees).
//!
//! Owns: [`Baker`], the cube-map casting, the frustum culler, the tree fitter, [`stats`],
//! the visibility-driven mesh refinement done before a bake ([`refine`]).
//! Must not depend on: the HTTP service, a database or a file format beyond `bspvt-proto`.
//!
//! [`Baker`] holds what every vertex shares (the BVH, the ray directions, the line codec);
//! [`Baker::bake_vertex`] is pure and deterministic, so chunks can be baked in any order, on
//! any number of threads, and give byte-identical output.

#![warn(unreachable_pub, missing_docs)]

pub mod cubemap;
mod edges;
pub mod fit;
mod frustum;
#[cfg(feature = "gpu")]
pub mod gpu_cast;
#[cfg(feature = "gpu")]
pub mod gpu_fit;
mod origin;
pub mod refine;
pub mod stats;
mod walk;

use std::ops::Range;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use bspvt_proto::bspvt::{LineCodec, VertexTrees};
use bspvt_proto::encoding::{BakeHeader, encode_chunk, encode_header};
use bspvt_proto::{Aabb, BakeSettings, Mesh, Scene, SplitMethod};
use glam::Vec3;
use rayon::prelude::*;

use bspvt_raytrace::{Cutouts, Occluder};
pub use cubemap::{CastCounts, CastMode, LampStop, LightStop, SphereStop, SunDisk};
use cubemap::{RayTable, VertexRays};
use fit::{FitStats, Fitter};

/// Bumped whenever the same scene and settings bake to other bytes (the pinned bakes of
/// `tests/tests/bake_pinned.rs` change): caches of finished bakes key on it, so that an
/// upgrade does not serve trees baked by the old rule. 2: rays of open-boundary vertices leave
/// from inside their own surface ([`origin`]). 3: the fit's coarse-to-fine angle schedule, and
/// directions that cannot reach a light's plane are "don't care" (docs/bake.md). 4: a fixed
/// lamp (no region, not moving in its plane) stops rays at its polygon, not its plane, and only
/// the directions that reach it matter. 5: a point or spot light stops rays at its sphere (before,
/// they were not lights for the bake). 6: the ray–triangle test is closed at the edges
/// (`bspvt_raytrace::hit`): a ray through an edge two triangles share no longer slips between
/// them. 7: nor past the BVH's box test, when that edge is a leaf box's face (the occluder's
/// boxes reach a margin past their triangles: `bspvt_raytrace::Occluder`; the room's bake
/// changed, the pinned ones did not). 8: the pixels a point or spot light's sphere covers are
/// cast toward the sphere itself (`VertexRays::aim`; bakes with such lights change,
/// the pinned ones did not). 9: the sky's bake of a scene with suns casts the pixels each sun's
/// disk at rest covers toward it, and the fit keeps those pixels in pure leaves
/// (`VertexRays::aim`, `FacePixels::protected`; bakes without suns did not change). 10: BVH
/// traversals find blockers nearer to a ray's origin than obvhs's fixed box distance of 10⁻⁴
/// scene units (`bspvt_raytrace::Occluder::box_t_min`: the occluder scales its rays' distances);
/// before, a scan in metres lost them deep in its crevices.
pub const ALGORITHM_VERSION: u32 = 10;

/// Ray origins are offset along the normal by this fraction of the scene's diagonal.
pub(crate) const RAY_OFFSET_SCALE: f32 = 1e-4;

/// Hits nearer than this fraction of the scene's diagonal are not counted: a surface that
/// passes through a vertex (a wall meeting a floor in a room, as separate parts whose corners
/// coincide, or whose edge runs through a refined vertex) is hit at t ≈ 0 ± rounding by rays
/// that leave it, and must not shadow them. 1 % of the normal offset.
pub(crate) const RAY_T_MIN_SCALE: f32 = 1e-6;

/// Geometry this fraction of the scene's diagonal below a vertex's horizon plane (through its
/// ray origin) cannot block its rays and is culled (`frustum::Pyramid`): ten times
/// [`RAY_T_MIN_SCALE`], a tenth of [`RAY_OFFSET_SCALE`] (the lift that puts the vertex's own
/// flat or convex neighbourhood below the plane).
pub(crate) const RAY_HORIZON_MARGIN_SCALE: f32 = 1e-5;

/// A chunk's vertices are handed to the threads in runs of at most this many: a vertex costs
/// from microseconds (all culled) to milliseconds (in a crevice), and rayon splits a range
/// only until each thread has a run of its own, which a thread then works through alone while
/// the others, done with theirs, wait for it.
const VERTICES_PER_TASK: usize = 4;

/// Everything a bake shares across vertices.
pub struct Baker {
    mesh: Mesh,
    settings: BakeSettings,
    /// Where the rays end: at the lights (see [`LightStop`]).
    stops: Vec<LightStop>,
    /// The suns at rest the rays are aimed at: a scene's suns where nothing stops the rays (the
    /// sky's bake, or a scene lit by suns alone), else none ([`SunDisk`]).
    suns: Vec<SunDisk>,
    occluder: Occluder,
    culler: frustum::FrustumCuller,
    /// Mesh adjacency for the adaptive cast's walks.
    walk: walk::SurfaceWalk,
    table: RayTable,
    /// How rays are cast (the same cube maps either way).
    cast: CastMode,
    codec: LineCodec,
    /// Per vertex: where its rays start ([`origin`]).
    origins: Vec<Vec3>,
    /// See [`RAY_T_MIN_SCALE`].
    t_min: f32,
    /// See [`RAY_HORIZON_MARGIN_SCALE`].
    horizon_margin: f32,
    header: BakeHeader,
}

/// One vertex's trees and what it cost.
pub struct VertexResult {
    /// The six face trees.
    pub trees: VertexTrees,
    /// How well the trees fit the cube map.
    pub fit: FitStats,
    /// Rays cast.
    pub rays: u64,
    /// Rays that traversed the BVH.
    pub traversals: u64,
    /// Seconds spent casting rays.
    pub ray_seconds: f64,
    /// Seconds spent fitting trees.
    pub fit_seconds: f64,
}

/// Sums over many vertices.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Totals {
    /// Vertices baked.
    pub vertices: u64,
    /// Rays cast.
    pub rays: u64,
    /// Rays that traversed the BVH.
    pub traversals: u64,
    /// GPU backend: sub-rays cast again on the CPU ([`CastCounts::recast`]).
    pub recast: u64,
    /// Thread-seconds spent casting rays.
    pub ray_seconds: f64,
    /// Thread-seconds spent fitting trees.
    pub fit_seconds: f64,
    /// Fit statistics, summed.
    pub fit: FitStats,
    /// Encoded bytes (chunk frames, after zstd).
    pub bytes: u64,
}

impl std::ops::AddAssign for Totals {
    fn add_assign(&mut self, o: Totals) {
        self.vertices += o.vertices;
        self.rays += o.rays;
        self.traversals += o.traversals;
        self.recast += o.recast;
        self.ray_seconds += o.ray_seconds;
        self.fit_seconds += o.fit_seconds;
        self.fit += o.fit;
        self.bytes += o.bytes;
    }
}

/// The bake was cancelled through its cancellation flag.
#[derive(Debug, thiserror::Error)]
#[error("bake cancelled after {chunks_done} chunks")]
pub struct Cancelled {
    /// Chunks finished before the flag was seen.
    pub chunks_done: u32,
}

/// A finished bake.
pub struct BakeOutput {
    /// The bake's header.
    pub header: BakeHeader,
    /// Header frame followed by every chunk frame in order: the bake file's bytes.
    pub bytes: Vec<u8>,
    /// Sums over every vertex.
    pub totals: Totals,
    /// Wall-clock seconds of the bake.
    pub seconds: f64,
    /// How rays were cast.
    pub cast: CastMode,
    /// Where rays were cast.
    pub backend: Backend,
}

/// Where a bake's rays are cast.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Backend {
    /// On the CPU threads, as [`CastMode`] says, each vertex's fit right after its rays.
    #[default]
    Cpu,
    /// In a wgpu compute shader (feature `gpu`, [`gpu_cast`]), every ray of every pixel that
    /// matters; the trees are fitted on the CPU threads meanwhile.
    Gpu,
}

impl Baker {
    /// Prepares a scene's bake (builds the BVH).
    /// Where no light stops the rays (the sky's bake, `Scene::sky`, which keeps the suns, or a
    /// scene lit by suns alone), the pixels of each sun's disk at rest are cast toward it and
    /// kept in pure leaves ([`SunDisk`]).
    pub fn new(scene: &Scene) -> Baker {
        let stops = LightStop::of_scene(scene);
        let suns = if stops.is_empty() {
            SunDisk::of_scene(scene)
        } else {
            Vec::new()
        };
        let mut b = Baker::build(
            scene.mesh.clone(),
            scene.bake.clone(),
            stops,
            Cutouts::of(&scene.mesh, &scene.materials),
        );
        b.suns = suns;
        b
    }

    /// Prepares the bake of `mesh` with `settings`; `regions`: the boxes the lights may occupy
    /// (`None`: anywhere), which decide the pixels that matter; rays end where they enter one.
    /// Every surface is opaque (no materials: no cut-outs).
    pub fn with_settings(mesh: Mesh, settings: BakeSettings, regions: Option<Vec<Aabb>>) -> Baker {
        let stops = regions
            .iter()
            .flatten()
            .map(|&r| LightStop::Region(r))
            .collect();
        Baker::build(mesh, settings, stops, None)
    }

    fn build(
        mesh: Mesh,
        settings: BakeSettings,
        stops: Vec<LightStop>,
        cutouts: Option<Arc<Cutouts>>,
    ) -> Baker {
        let tris = bspvt_raytrace::mesh_triangles(&mesh);
        let occluder = Occluder::new(&mesh, &tris).cut_out(cutouts);
        let culler = frustum::FrustumCuller::new(&mesh, &tris, &occluder);
        let walk = walk::SurfaceWalk::new(&mesh, &occluder);
        let table = RayTable::new(settings.face_res, settings.supersampling);
        let codec = LineCodec::for_resolution(settings.face_res);
        let diagonal = mesh.bounds().diagonal();
        let origins = origin::ray_origins(&mesh, RAY_OFFSET_SCALE * diagonal);
        let t_min = RAY_T_MIN_SCALE * diagonal;
        let horizon_margin = RAY_HORIZON_MARGIN_SCALE * diagonal;
        let header = BakeHeader::new(&settings, mesh.vertex_count() as u32, mesh.content_hash());
        Baker {
            mesh,
            settings,
            stops,
            suns: Vec::new(),
            occluder,
            culler,
            walk,
            table,
            cast: CastMode::default(),
            codec,
            origins,
            t_min,
            horizon_margin,
            header,
        }
    }

    /// Casts rays the given way from now on (the cube maps, and so the bytes, do not change).
    pub fn set_cast(&mut self, mode: CastMode) {
        self.cast = mode;
    }

    /// How rays are cast.
    pub fn cast(&self) -> CastMode {
        self.cast
    }

    /// The header every chunk of this bake is decoded with.
    pub fn header(&self) -> &BakeHeader {
        &self.header
    }

    /// The quantisation of the split lines.
    pub fn codec(&self) -> &LineCodec {
        &self.codec
    }

    /// The mesh baked (vertex order = tree order).
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The vertex range of chunk `c`.
    pub fn chunk_range(&self, c: u32) -> Range<u32> {
        let cv = self.settings.chunk_vertices;
        let start = c * cv;
        start..(start + cv).min(self.header.vertex_count)
    }

    /// Where vertex `v`'s rays start and which directions can matter.
    fn vertex_rays(&self, v: u32) -> VertexRays<'_> {
        VertexRays {
            origin: self.origins[v as usize],
            normal: self.mesh.normals[v as usize],
            vertex: v,
            t_min: self.t_min,
            horizon_margin: self.horizon_margin,
            stops: &self.stops,
            suns: &self.suns,
        }
    }

    /// The visibility cube map of vertex `v` (pixels that matter and their escape counts) and
    /// what casting it cost, cast this bake's way ([`Baker::set_cast`]).
    pub fn cube_map(&self, v: u32) -> ([Option<cubemap::FacePixels>; 6], CastCounts) {
        self.cube_map_with(v, self.cast)
    }

    /// [`Baker::cube_map`] cast the given way.
    pub fn cube_map_with(
        &self,
        v: u32,
        mode: CastMode,
    ) -> ([Option<cubemap::FacePixels>; 6], CastCounts) {
        self.vertex_rays(v)
            .cast(&self.occluder, &self.culler, &self.walk, &self.table, mode)
    }

    /// The cube map of vertex `v` by casting every ray of every pixel that matters against the
    /// BVH, with no culling: the reference both casts must equal (slow; for tests).
    pub fn reference_cube_map(&self, v: u32) -> [Option<cubemap::FacePixels>; 6] {
        self.vertex_rays(v)
            .cast_brute_force(&self.occluder, &self.table)
    }

    /// Bakes one vertex: rays, then one tree per face that has pixels that matter.
    pub fn bake_vertex(&self, v: u32) -> VertexResult {
        let t0 = Instant::now();
        let (faces, counts) = self.cube_map(v);
        let t1 = Instant::now();
        let (trees, fit) = self.fit_faces(&faces, self.settings.split);
        VertexResult {
            trees,
            fit,
            rays: counts.rays,
            traversals: counts.traversals,
            ray_seconds: (t1 - t0).as_secs_f64(),
            fit_seconds: t1.elapsed().as_secs_f64(),
        }
    }

    /// This bake's tree builder with the given split search.
    pub(crate) fn fitter(&self, method: SplitMethod) -> Fitter<'_> {
        Fitter::new(
            &self.codec,
            &self.table.uv,
            self.settings.face_res,
            self.table.samples,
            f64::from(self.settings.epsilon),
            method,
        )
    }

    /// Fits one tree per face of a cube map with the given split search.
    pub fn fit_faces(
        &self,
        faces: &[Option<cubemap::FacePixels>; 6],
        method: SplitMethod,
    ) -> (VertexTrees, FitStats) {
        let fitter = self.fitter(method);
        let mut trees = VertexTrees::default();
        let mut fit = FitStats::default();
        for (f, px) in faces.iter().enumerate() {
            if let Some(px) = px {
                let (tree, st) = fitter.for_face(px.light_pixels).fit_protected(
                    &px.index,
                    &px.visible,
                    &px.protected,
                );
                trees.faces[f] = Some(tree);
                fit += st;
            }
        }
        (trees, fit)
    }

    /// Bakes chunk `c` (vertices in parallel on the current rayon pool) into one chunk frame.
    pub fn bake_chunk(&self, c: u32) -> (Vec<u8>, Totals) {
        let range = self.chunk_range(c);
        let results: Vec<VertexResult> = range
            .clone()
            .into_par_iter()
            .with_max_len(VERTICES_PER_TASK)
            .map(|v| self.bake_vertex(v))
            .collect();
        let mut totals = Totals::default();
        let trees: Vec<VertexTrees> = results
            .into_iter()
            .map(|r| {
                totals += Totals {
                    vertices: 1,
                    rays: r.rays,
                    traversals: r.traversals,
                    recast: 0,
                    ray_seconds: r.ray_seconds,
                    fit_seconds: r.fit_seconds,
                    fit: r.fit,
                    bytes: 0,
                };
                r.trees
            })
            .collect();
        let frame = encode_chunk(range.start, &trees, &self.codec);
        totals.bytes = frame.len() as u64;
        (frame, totals)
    }

    /// Fits the trees of chunk `c` from its vertices' cube maps (in parallel on the current
    /// rayon pool) and encodes its frame; the totals count no rays (the GPU backend's fit).
    #[cfg(feature = "gpu")]
    pub(crate) fn fit_chunk(
        &self,
        c: u32,
        maps: &[[Option<cubemap::FacePixels>; 6]],
    ) -> (Vec<u8>, Totals) {
        let results: Vec<(VertexTrees, FitStats, f64)> = maps
            .par_iter()
            .with_max_len(VERTICES_PER_TASK)
            .map(|faces| {
                let t0 = Instant::now();
                let (trees, fit) = self.fit_faces(faces, self.settings.split);
                (trees, fit, t0.elapsed().as_secs_f64())
            })
            .collect();
        let mut totals = Totals::default();
        let trees: Vec<VertexTrees> = results
            .into_iter()
            .map(|(trees, fit, seconds)| {
                totals += Totals {
                    vertices: 1,
                    fit_seconds: seconds,
                    fit,
                    ..Totals::default()
                };
                trees
            })
            .collect();
        let frame = encode_chunk(self.chunk_range(c).start, &trees, &self.codec);
        totals.bytes = frame.len() as u64;
        (frame, totals)
    }

    /// A bake file's first bytes (the header frame) and their totals.
    fn output_start(&self) -> (Vec<u8>, Totals) {
        let bytes = encode_header(&self.header);
        let totals = Totals {
            bytes: bytes.len() as u64,
            ..Totals::default()
        };
        (bytes, totals)
    }

    /// The finished bake from its header and chunk frames: a refined scene's file carries its
    /// mesh (the scene file alone names the coarse one).
    fn output_finish(&self, mut bytes: Vec<u8>, mut totals: Totals, start: Instant) -> BakeOutput {
        if self.settings.refine.is_some() {
            let frame = bspvt_proto::encoding::encode_mesh(&self.mesh);
            totals.bytes += frame.len() as u64;
            bytes.extend_from_slice(&frame);
        }
        BakeOutput {
            header: self.header.clone(),
            bytes,
            totals,
            seconds: start.elapsed().as_secs_f64(),
            cast: self.cast,
            backend: Backend::Cpu,
        }
    }

    /// Bakes every chunk in order, calling `progress(vertices_done, vertices_total)` after
    /// each; stops between chunks when `cancel` is set.
    pub fn bake_all(
        &self,
        progress: &(dyn Fn(u64, u64) + Sync),
        cancel: &AtomicBool,
    ) -> Result<BakeOutput, Cancelled> {
        let start = Instant::now();
        let (mut bytes, mut totals) = self.output_start();
        let total = self.header.vertex_count as u64;
        for c in 0..self.header.chunk_count() {
            if cancel.load(Ordering::Relaxed) {
                return Err(Cancelled { chunks_done: c });
            }
            let (frame, t) = self.bake_chunk(c);
            bytes.extend_from_slice(&frame);
            totals += t;
            progress(totals.vertices, total);
        }
        Ok(self.output_finish(bytes, totals, start))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    fn small_baker(res: u32, supersampling: u32) -> Baker {
        let mut scene = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
        scene.bake.face_res = res;
        scene.bake.supersampling = supersampling;
        scene.bake.chunk_vertices = 512;
        Baker::new(&scene)
    }

    /// The culled quadtree walk gives exactly what casting every ray of every pixel that
    /// matters gives (the "exact culling" invariant), with and without supersampling.
    #[test]
    fn culling_is_exact() {
        // 50: a block size that turns odd above the collect size (50 → 25).
        for (res, ss) in [(32, 1), (16, 2), (24, 1), (50, 1)] {
            let b = small_baker(res, ss);
            let n = b.mesh().vertex_count() as u32;
            let mut checked = 0;
            let mut occluded_pixels = 0;
            for v in (0..n).step_by(37) {
                let rays_brute = b.reference_cube_map(v);
                let (adaptive, _) = b.cube_map_with(v, CastMode::Adaptive);
                assert_eq!(
                    adaptive, rays_brute,
                    "adaptive, vertex {v} at {res}² × {ss}²"
                );
                let (walk, counts) = b.cube_map_with(v, CastMode::Full);
                let rays = counts.rays;
                assert_eq!(walk, rays_brute, "vertex {v} at {res}² × {ss}²");
                occluded_pixels += walk
                    .iter()
                    .flatten()
                    .flat_map(|f| &f.visible)
                    .filter(|&&k| k < (ss * ss) as u16)
                    .count();
                assert!(
                    rays <= walk
                        .iter()
                        .flatten()
                        .map(|f| f.index.len() as u64)
                        .sum::<u64>()
                        * (ss * ss) as u64
                );
                checked += 1;
            }
            // The comparison must have seen shadows, or it proves nothing.
            assert!(
                occluded_pixels > 100,
                "only {occluded_pixels} occluded pixels in {checked} vertices"
            );
        }
    }

    #[test]
    fn progress_reports_every_chunk_and_cancel_stops() {
        let b = small_baker(8, 1);
        let seen = Mutex::new(Vec::new());
        let out = b
            .bake_all(
                &|done, total| seen.lock().expect("lock").push((done, total)),
                &AtomicBool::new(false),
            )
            .expect("not cancelled");
        let seen = seen.into_inner().expect("lock");
        let n = b.header().vertex_count as u64;
        assert_eq!(seen.len() as u32, b.header().chunk_count());
        assert_eq!(seen.last(), Some(&(n, n)));
        assert!(seen.windows(2).all(|w| w[0].0 < w[1].0));
        assert_eq!(out.totals.vertices, n);

        let cancel = AtomicBool::new(false);
        let err = b
            .bake_all(&|_, _| cancel.store(true, Ordering::Relaxed), &cancel)
            .err()
            .expect("cancelled");
        assert_eq!(err.chunks_done, 1);
    }
}
