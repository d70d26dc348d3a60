//! Adaptive, crack-free, budgeted refinement of a triangle mesh where the lights' visibility
//! varies.
//!
//! Per-vertex visibility is interpolated linearly across each triangle, so a shadow can only
//! be as sharp as the mesh is fine: a floor made of two triangles has four vertices and shows
//! no shadow at all. [`refine`] splits the triangles across which the visibility of the
//! lights varies, before the bake, so that the shadows stop depending on the tessellation.
//!
//! * The measure ([`Visibility`]): V(p, n) ∈ \[0, 1\], the fraction of a fixed set of sample
//!   points on the lights that the point sees (see [`Visibility::at`]).
//! * The error of a triangle: V at its three vertices and its three edge midpoints (see
//!   [`triangle_error`]), and on a grid of interior probes when the triangle is large.
//! * The lighting term (`lighting`, on by default): the range of the lights' unshadowed
//!   irradiance over the same points, relative to its largest value there
//!   ([`Visibility::irradiance`]), because per-vertex shading interpolates the lighting too:
//!   a wall of two triangles has no shadow to refine but its light falls off across it.
//! * The split: conforming longest-edge bisection (Rivara's LEPP, generalised to edges shared
//!   by more than two triangles): an edge is only ever split in every triangle that shares it,
//!   with one midpoint vertex, so the refined mesh has no T-junction.
//! * The order: largest error × size first, within a vertex budget.
//!
//! A math kernel: no I/O; deterministic whatever the number of rayon threads (rays are cast in
//! parallel, every decision is taken sequentially in a fixed order).

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap, HashSet};
use std::time::Instant;

use bspvt_proto::scene::{Material, PolygonLight, PunctualLight, SunLight};
use bspvt_proto::{Aabb, Mesh, MeshError};
use bspvt_raytrace::{Cutouts, Occluder};
use glam::Vec3;
use rayon::prelude::*;

use crate::RAY_OFFSET_SCALE;
use crate::cubemap::LightStop;

/// What [`refine`] may do: the scene file's `bake.refine` ([`Refinement`], one definition of
/// the settings shared by the scene files, the service and the bake).
pub use bspvt_proto::scene::Refinement as RefineSettings;

/// The scene's diagonal is divided by this to give the default shortest splittable edge.
pub const MIN_EDGE_DIVISOR: f32 = 256.0;

/// Interior probes of a large triangle are spaced this many shortest splittable edges apart
/// (the default: the scene's diagonal / 64), so that a shadow that misses a triangle's corners
/// and edge midpoints is still seen.
const PROBE_SPACING_EDGES: f32 = 4.0;

/// At most this many divisions per edge for the interior probes (≤ 253 probes a triangle).
const MAX_PROBE_DIVISIONS: u32 = 24;

/// The shortest splittable edge for `mesh`: `settings.min_edge`, or when it is 0 the diagonal
/// of the mesh's bounding box / [`MIN_EDGE_DIVISOR`].
pub fn resolved_min_edge(settings: &RefineSettings, mesh: &Mesh) -> f32 {
    if settings.min_edge > 0.0 {
        settings.min_edge
    } else {
        (scene_diagonal(mesh) / MIN_EDGE_DIVISOR as f64) as f32
    }
}

/// Refines `scene`'s mesh in place when its bake settings ask for it (`bake.refine`) and it
/// does not move; for its lamps, and for the sky too when it has an environment (the sky's
/// trees are baked on the same mesh, [`Visibility::with_sky`]) (a moving part's vertex ranges must stay as they are). Returns what was done.
pub fn refine_scene(scene: &mut bspvt_proto::Scene) -> Result<Option<RefineStats>, RefineError> {
    let Some(settings) = scene.bake.refine else {
        return Ok(None);
    };
    if scene.is_dynamic() {
        return Ok(None);
    }
    // A sun turns freely: what it needs refined is what the sky does.
    let sky = scene.environment.is_some() || !scene.suns.is_empty();
    let (mesh, stats) = refine_for(
        &scene.mesh,
        &scene.materials,
        &scene.lights,
        &scene.punctual,
        &scene.suns,
        sky,
        &settings,
    )?;
    scene.mesh = mesh;
    Ok(Some(stats))
}

/// Why [`try_refine`] refused to work.
#[derive(Debug, thiserror::Error)]
pub enum RefineError {
    /// A setting is out of range (the message names it).
    #[error("invalid refine settings: {0}")]
    Settings(String),
    /// The mesh fails [`Mesh::validate`].
    #[error("mesh cannot be refined: {0}")]
    Mesh(#[from] MeshError),
}

/// What [`refine`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RefineStats {
    /// Vertices of the input mesh.
    pub vertices_before: usize,
    /// Vertices of the refined mesh (= before + splits).
    pub vertices_after: usize,
    /// Triangles of the input mesh.
    pub triangles_before: usize,
    /// Triangles of the refined mesh.
    pub triangles_after: usize,
    /// Edges split (each adds one vertex, and one triangle per triangle sharing the edge).
    pub splits: usize,
    /// Visibility rays cast (samples below a point's horizon are not cast).
    pub samples_cast: u64,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// A split was refused because it would have exceeded `max_vertices`.
    pub budget_reached: bool,
}

/// Rays toward a light sample stop this fraction of its distance short of it.
const SHORT_OF_SAMPLE: f32 = 1e-4;
/// Samples per light without a region, aimed at (fan triangles get ⌈√(target / triangles)⌉²
/// each: 49 for a triangle, 50 for a quad, 45–64 for 5 to 8 corners).
const POLYGON_SAMPLES: usize = 40;
/// Directions of the sky's measure ([`Visibility::with_sky`]): ~32 above any horizon, about
/// 20° apart.
pub const SKY_DIRECTIONS: usize = 64;

/// `n` unit directions spread evenly over the sphere (the spherical Fibonacci lattice).
fn fibonacci_sphere(n: usize) -> Vec<Vec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f64;
            glam::DVec3::new(r * phi.cos(), z, r * phi.sin()).as_vec3()
        })
        .collect()
}

/// Samples per light with a region, aimed at (at most [`MAX_REGION_SAMPLES`]).
const REGION_SAMPLES: f32 = 48.0;
const MAX_REGION_SAMPLES: usize = 64;

/// Samples per point or spot light's sphere ([`Visibility::with_spheres`]).
const SPHERE_SAMPLES: usize = 32;

/// Directions per sun ([`Visibility::with_suns`]): its centre and a ring.
const SUN_SAMPLES: usize = 7;

/// How far a sun's sample points are, in scene diagonals.
const SUN_DISTANCE: f32 = 1024.0;

/// One light's sample points and their weights (area or volume they stand for).
struct LightSamples {
    points: Vec<Vec3>,
    weights: Vec<f64>,
    total: f64,
    /// A light without a region: what its unshadowed irradiance needs.
    emitter: Option<Emitter>,
    /// A spot's cone and a range's window scale a sphere's irradiance (in working units).
    falloff: Option<PunctualLight>,
}

/// A fixed polygon light (or a sphere) as [`Visibility::irradiance`] sees it.
#[derive(Clone, Copy)]
struct Emitter {
    /// Unit normal of the emitting side.
    normal: Vec3,
    two_sided: bool,
    /// A sphere: seen the same from every side (cos θₗ = 1; `power` is its intensity).
    isotropic: bool,
    /// Area × the radiance's luminance.
    power: f64,
}

impl LightSamples {
    /// `None` for a light that cannot be sampled (fewer than 3 corners, or not finite).
    fn of(light: &PolygonLight) -> Option<LightSamples> {
        if let Some(r) = light.region {
            let b = r.aabb();
            if b.min.is_finite() && b.max.is_finite() && b.min.cmple(b.max).all() {
                return Some(Self::equal(region_samples(b)));
            }
        }
        let pts = light.points();
        if pts.len() < 3 || pts.iter().any(|p| !p.is_finite()) {
            return None;
        }
        let (points, weights) = polygon_samples(&pts);
        let total: f64 = weights.iter().sum();
        if !(total > 0.0) || !total.is_finite() {
            return Some(Self::equal(points));
        }
        // Newell's normal: length = 2 × area.
        let n: Vec3 = (0..pts.len())
            .map(|i| pts[i].cross(pts[(i + 1) % pts.len()]))
            .sum();
        let power = 0.5 * f64::from(n.length()) * luminance(light.radiance);
        let emitter = (power > 0.0 && power.is_finite()).then(|| Emitter {
            normal: n.normalize_or_zero(),
            two_sided: light.two_sided,
            isotropic: false,
            power,
        });
        Some(LightSamples {
            points,
            weights,
            total,
            emitter,
            falloff: None,
        })
    }

    /// Equal-weight `points` of a light seen the same from every side, of intensity
    /// (luminance) `power`: a sphere, or the sun's disk far away.
    fn isotropic(points: Vec<Vec3>, power: f64) -> LightSamples {
        let mut s = LightSamples::equal(points);
        s.emitter = (power > 0.0 && power.is_finite()).then_some(Emitter {
            normal: Vec3::ZERO,
            two_sided: true,
            isotropic: true,
            power,
        });
        s
    }

    fn equal(points: Vec<Vec3>) -> LightSamples {
        LightSamples {
            weights: vec![1.0; points.len()],
            total: points.len() as f64,
            emitter: None,
            falloff: None,
            points,
        }
    }
}

/// Rec. 709 luminance of linear RGB.
fn luminance(rgb: [f32; 3]) -> f64 {
    let [r, g, b] = rgb.map(f64::from);
    0.2126 * r + 0.7152 * g + 0.0722 * b
}

/// Stratified points on a convex polygon: each fan triangle (p0, pᵢ, pᵢ₊₁) is cut into k²
/// congruent triangles (k per side) and sampled at their centroids, each weighted by its area.
fn polygon_samples(pts: &[Vec3]) -> (Vec<Vec3>, Vec<f64>) {
    let fans = pts.len() - 2;
    let k = ((POLYGON_SAMPLES as f64 / fans as f64).sqrt().ceil() as usize).max(1);
    let mut points = Vec::with_capacity(fans * k * k);
    let mut weights = Vec::with_capacity(fans * k * k);
    let kf = k as f32;
    for f in 1..pts.len() - 1 {
        let (a, b, c) = (pts[0], pts[f], pts[f + 1]);
        let (u, v) = (b - a, c - a);
        let w = 0.5 * u.as_dvec3().cross(v.as_dvec3()).length() / (k * k) as f64;
        for i in 0..k {
            for j in 0..k - i {
                // The "upward" cell with corners (i, j), (i+1, j), (i, j+1) in lattice units.
                let (s, t) = ((i as f32 + 1.0 / 3.0) / kf, (j as f32 + 1.0 / 3.0) / kf);
                points.push(a + s * u + t * v);
                weights.push(w);
                if i + j + 2 <= k {
                    // The "downward" cell with corners (i+1, j), (i, j+1), (i+1, j+1).
                    let (s, t) = ((i as f32 + 2.0 / 3.0) / kf, (j as f32 + 2.0 / 3.0) / kf);
                    points.push(a + s * u + t * v);
                    weights.push(w);
                }
            }
        }
    }
    (points, weights)
}

/// Cell centres of a grid over the box with near-cubic cells, about [`REGION_SAMPLES`] of
/// them (at most [`MAX_REGION_SAMPLES`]); axes thinner than 5 % of the longest get one cell.
fn region_samples(b: Aabb) -> Vec<Vec3> {
    let e = b.max - b.min;
    let emax = e.max_element();
    if !(emax > 0.0) || !emax.is_finite() {
        return vec![b.center()];
    }
    let active: Vec<bool> = e.to_array().iter().map(|&x| x > 0.05 * emax).collect();
    let dims = active.iter().filter(|&&a| a).count().max(1) as f32;
    let vol: f32 = e
        .to_array()
        .iter()
        .zip(&active)
        .filter(|(_, a)| **a)
        .map(|(x, _)| x / emax)
        .product();
    let mut h = (vol / REGION_SAMPLES).powf(1.0 / dims) * emax;
    let mut counts = [1usize; 3];
    for _ in 0..200 {
        for a in 0..3 {
            counts[a] = if active[a] {
                ((e[a] / h).round() as usize).clamp(1, MAX_REGION_SAMPLES)
            } else {
                1
            };
        }
        if counts.iter().product::<usize>() <= MAX_REGION_SAMPLES {
            break;
        }
        h *= 1.1;
    }
    if counts.iter().product::<usize>() > MAX_REGION_SAMPLES {
        return vec![b.center()];
    }
    let cell = |a: usize, i: usize| (i as f32 + 0.5) / counts[a] as f32;
    let mut out = Vec::with_capacity(counts.iter().product());
    for z in 0..counts[2] {
        for y in 0..counts[1] {
            for x in 0..counts[0] {
                out.push(b.min + e * Vec3::new(cell(0, x), cell(1, y), cell(2, z)));
            }
        }
    }
    out
}

/// The diagonal of the mesh's bounding box, computed in f64 so that it cannot overflow (0 for
/// a mesh without vertices).
fn scene_diagonal(mesh: &Mesh) -> f64 {
    let b = mesh.bounds();
    let d = (b.max.as_dvec3() - b.min.as_dvec3()).length();
    if d.is_finite() { d } else { 0.0 }
}

/// The visibility measure the refinement uses.
///
/// V(p, n) = (1/L) Σ_lights Σ_{samples s seen} wₛ / Σ_s wₛ ∈ \[0, 1\]: for each light, the
/// weighted fraction of its sample points that p, offset along n by `RAY_OFFSET_SCALE` ×
/// the scene's diagonal (as the baker does), sees unoccluded; averaged over the lights (each
/// light counts the same). A sample is seen when it lies above the horizon (n·d > 0, d the
/// unit direction toward it: samples below are unseen) and the ray toward it is clear up to
/// t_max = min(0.9999 × its distance, the first [`LightStop`] along the ray) — short of the
/// sample so that a lamp's own geometry beyond it does not count (the importer removes
/// emitters), and ending where the baker's rays end so that V is what the bake can show.
///
/// Samples: a light without a region gets stratified points on its polygon (each fan
/// triangle cut into k² congruent triangles, sampled at their centroids and weighted by area;
/// 45–64 points per light); a light with a region (it moves inside that box) gets the centres
/// of a grid of near-cubic cells over the box (up to 64 points, equal weights). The set is
/// fixed, so V is deterministic. Lights with fewer than 3 corners or non-finite corners (that
/// `Scene` validation rejects) are ignored; with no light V = 0.
pub struct Visibility {
    /// `None`: no usable triangle, nothing occludes.
    occluder: Option<Occluder>,
    lights: Vec<LightSamples>,
    /// The sky's sample directions ([`Visibility::with_sky`]); empty without a sky.
    sky: Vec<Vec3>,
    stops: Vec<LightStop>,
    offset: f32,
    /// Hits nearer than this are not counted, as in the bake ([`crate::RAY_T_MIN_SCALE`]).
    t_min: f32,
    /// Positions are multiplied by this (a power of two, 1 for scenes within 2²⁰ units).
    scale: f32,
}

/// Largest coordinate the measure works with unscaled.
const MAX_WORKING_COORDINATE: f32 = 1048576.0; // 2²⁰

/// 1, or the power of two that brings the scene's largest finite coordinate to at most
/// [`MAX_WORKING_COORDINATE`] (large scenes) or to about 1 (scenes within 2⁻²⁰ units, whose
/// squared distances would underflow).
fn working_scale(mesh: &Mesh, lights: &[PolygonLight]) -> f32 {
    let coords = mesh
        .positions
        .iter()
        .flat_map(|p| p.to_array())
        .chain(lights.iter().flat_map(|l| {
            let r = l.region.iter().flat_map(|r| r.min.into_iter().chain(r.max));
            l.vertices.iter().flatten().copied().chain(r)
        }));
    let max = coords
        .filter(|x| x.is_finite())
        .fold(0.0f32, |m, x| m.max(x.abs()));
    let e = (max as f64).log2().ceil() as i32;
    if max > MAX_WORKING_COORDINATE {
        // max < 2¹²⁸, so the exponent is at least -108: a normal f32.
        2.0f32.powi(20 - e)
    } else if max > 0.0 && max < 1.0 / MAX_WORKING_COORDINATE {
        2.0f32.powi((-e).min(126))
    } else {
        1.0
    }
}

/// `light` with every coordinate multiplied by `scale`.
fn scaled_light(light: &PolygonLight, scale: f32) -> PolygonLight {
    let mut l = light.clone();
    for v in &mut l.vertices {
        *v = v.map(|x| x * scale);
    }
    if let Some(r) = &mut l.region {
        r.min = r.min.map(|x| x * scale);
        r.max = r.max.map(|x| x * scale);
    }
    l
}

impl Visibility {
    /// The measure for `mesh` lit by `lights` (builds the BVH). Triangles with an index out of
    /// range or a non-finite corner are left out of the occluder.
    ///
    /// Scenes larger than 2²⁰ units (or within 2⁻²⁰) are measured scaled by a power of two
    /// (exact in floating point), so that the BVH builder never sees areas that overflow f32
    /// and squared distances do not underflow.
    pub fn new(mesh: &Mesh, lights: &[PolygonLight]) -> Visibility {
        Visibility::with_sky(mesh, lights, false)
    }

    /// [`Visibility::new`], and with `sky` the sky counted as one more light: V_sky(p, n) =
    /// Σ_{d seen} n·d / Σ_d n·d over [`SKY_DIRECTIONS`] fixed directions (a spherical
    /// Fibonacci set) above the horizon, rays to infinity — the cosine-weighted share of the
    /// sky a point sees, whatever the map (it turns at run time).
    pub fn with_sky(mesh: &Mesh, lights: &[PolygonLight], sky: bool) -> Visibility {
        Visibility::with_cutouts(mesh, &[], lights, sky)
    }

    /// [`Visibility::with_sky`], its rays passing through the cut-outs of `materials`
    /// (`bspvt_raytrace::Cutouts`).
    pub fn with_cutouts(
        mesh: &Mesh,
        materials: &[Material],
        lights: &[PolygonLight],
        sky: bool,
    ) -> Visibility {
        let scale = working_scale(mesh, lights);
        let n = mesh.positions.len();
        let usable = |t: &[u32; 3]| {
            t.iter()
                .all(|&i| (i as usize) < n && mesh.positions[i as usize].is_finite())
        };
        let kept: Vec<usize> = (0..mesh.triangles.len())
            .filter(|&t| usable(&mesh.triangles[t]))
            .collect();
        let occ_mesh = Mesh {
            positions: mesh.positions.iter().map(|&p| p * scale).collect(),
            normals: Vec::new(),
            triangles: kept.iter().map(|&t| mesh.triangles[t]).collect(),
            material_ids: kept
                .iter()
                .map(|&t| mesh.material_ids.get(t).copied().unwrap_or(0))
                .collect(),
            uvs: mesh.uvs.clone(),
        };
        let occluder = (!occ_mesh.triangles.is_empty()).then(|| {
            let tris = bspvt_raytrace::mesh_triangles(&occ_mesh);
            Occluder::new(&occ_mesh, &tris).cut_out(Cutouts::of(&occ_mesh, materials))
        });
        let sampled: Vec<(LightSamples, LightStop)> = lights
            .iter()
            .map(|l| scaled_light(l, scale))
            // Rays aim at points of the lamps: a lamp stops them exactly at its polygon (no
            // pixel's cone to grow it by).
            .filter_map(|l| Some((LightSamples::of(&l)?, LightStop::of_light(&l, u32::MAX)?)))
            .collect();
        let offset = RAY_OFFSET_SCALE * scene_diagonal(&occ_mesh) as f32;
        let offset = if offset.is_finite() { offset } else { 0.0 };
        let t_min = crate::RAY_T_MIN_SCALE * scene_diagonal(&occ_mesh) as f32;
        let t_min = if t_min.is_finite() { t_min } else { 0.0 };
        let (lights, stops) = sampled.into_iter().unzip();
        Visibility {
            occluder,
            lights,
            sky: if sky {
                fibonacci_sphere(SKY_DIRECTIONS)
            } else {
                Vec::new()
            },
            stops,
            offset,
            t_min,
            scale,
        }
    }

    /// This measure with the point and spot lights `spheres` counted as lights too: each
    /// sphere sampled at [`SPHERE_SAMPLES`] points of its surface (a spherical Fibonacci set,
    /// equal weights), its rays ending where they enter it; its irradiance that of a point
    /// of its intensity (the spot's cone left out).
    pub fn with_spheres(mut self, spheres: &[PunctualLight]) -> Visibility {
        for l in spheres {
            let c = Vec3::from(l.position) * self.scale;
            let r = l.sphere_radius() * self.scale;
            if !(c.is_finite() && r > 0.0 && r.is_finite()) {
                continue;
            }
            let points: Vec<Vec3> = fibonacci_sphere(SPHERE_SAMPLES)
                .into_iter()
                .map(|d| c + d * r)
                .collect();
            let mut samples = LightSamples::isotropic(points, luminance(l.intensity));
            let mut scaled = l.clone();
            scaled.position = c.to_array();
            scaled.range = l.range.map(|r| r * self.scale);
            samples.falloff = Some(scaled);
            self.lights.push(samples);
            self.stops
                .push(LightStop::Sphere(crate::cubemap::SphereStop {
                    centre: c,
                    radius: r,
                    spread: 0.0,
                }));
        }
        self
    }

    /// This measure with the suns at rest counted as lights too (a sun may turn, which the
    /// sky's measure covers; at rest its patch's edges must be refined): each sampled at
    /// [`SUN_SAMPLES`] directions across its disk, as points [`SUN_DISTANCE`] scene
    /// diagonals away; its irradiance E max(0, n·d).
    pub fn with_suns(mut self, suns: &[SunLight]) -> Visibility {
        let far = SUN_DISTANCE * self.offset / RAY_OFFSET_SCALE;
        if !(far > 0.0 && far.is_finite()) {
            return self;
        }
        for sun in suns {
            let d = sun.toward();
            let h = sun.half_angle();
            if d == Vec3::ZERO {
                continue;
            }
            let (a, b) = d.any_orthonormal_pair();
            let points: Vec<Vec3> = std::iter::once(d)
                .chain((0..SUN_SAMPLES - 1).map(|k| {
                    let phi = std::f32::consts::TAU * k as f32 / (SUN_SAMPLES - 1) as f32;
                    (d + (a * phi.cos() + b * phi.sin()) * (0.7 * h.tan())).normalize()
                }))
                .map(|x| x * far)
                .collect();
            // E at the scene = P / far²: P = E far².
            let power = luminance(sun.illuminance) * f64::from(far).powi(2);
            self.lights.push(LightSamples::isotropic(points, power));
        }
        self
    }

    /// Number of light sample points (all lights together).
    pub fn sample_count(&self) -> usize {
        self.lights.iter().map(|l| l.points.len()).sum()
    }

    /// V(p, n) of the point `position` with normal `normal` (see [`Visibility`]); `skip_vertex`:
    /// the mesh vertex the point is, whose own triangles cannot shadow it (as in the bake).
    pub fn at(&self, position: Vec3, normal: Vec3, skip_vertex: Option<u32>) -> f32 {
        self.eval(position, normal, skip_vertex.unwrap_or(u32::MAX))
            .0
    }

    /// The unshadowed irradiance (luminance) at `position` with `normal` from the lights
    /// without a region, from the same sample points: E ≈ Σ_lights P Σ_s (wₛ/W) max(0, n·d)
    /// cos θₗ / r² (P = area × luminance; cos θₗ = −nₗ·d, or |nₗ·d| two-sided). No rays: what
    /// per-vertex shading must interpolate besides the shadows.
    fn irradiance(&self, position: Vec3, normal: Vec3) -> f64 {
        let n = normal.normalize_or_zero().as_dvec3();
        let o = (position * self.scale).as_dvec3();
        let mut e = 0.0f64;
        for l in &self.lights {
            let Some(em) = l.emitter else { continue };
            let ln = em.normal.as_dvec3();
            let mut sum = 0.0f64;
            for (&s, &w) in l.points.iter().zip(&l.weights) {
                let v = s.as_dvec3() - o;
                let r2 = v.length_squared();
                if !(r2 > 0.0) || !r2.is_finite() {
                    continue;
                }
                let d = v / r2.sqrt();
                let cos_l = if em.isotropic {
                    1.0
                } else if em.two_sided {
                    ln.dot(d).abs()
                } else {
                    (-ln.dot(d)).max(0.0)
                };
                sum += w * n.dot(d).max(0.0) * cos_l / r2;
            }
            let f = l
                .falloff
                .as_ref()
                .map_or(1.0, |pl| f64::from(pl.falloff(position * self.scale)));
            e += f * em.power * sum / l.total;
        }
        // Area / r² in the same (working) units: E does not depend on the working scale.
        if e.is_finite() { e } else { 0.0 }
    }

    /// V and the number of rays cast.
    fn eval(&self, position: Vec3, normal: Vec3, skip: u32) -> (f32, u64) {
        if self.lights.is_empty() && self.sky.is_empty() {
            return (0.0, 0);
        }
        let n = normal.normalize_or_zero();
        let o = position * self.scale + n * self.offset;
        let mut rays = 0u64;
        let mut sum = 0.0f64;
        for l in &self.lights {
            let mut seen = 0.0f64;
            for (&s, &w) in l.points.iter().zip(&l.weights) {
                let v = s - o;
                let dist = v.length();
                if !(dist > 0.0) || !dist.is_finite() {
                    continue;
                }
                let d = v / dist;
                if !(d.dot(n) > 0.0) {
                    continue; // below the horizon: unseen
                }
                let t_max = self
                    .stops
                    .iter()
                    .filter_map(|st| st.distance(o, d))
                    .fold(dist * (1.0 - SHORT_OF_SAMPLE), f32::min);
                let clear = if t_max > 0.0 {
                    rays += 1;
                    self.occluder
                        .as_ref()
                        .is_none_or(|occ| !occ.occluded_between(o, d, self.t_min, t_max, skip))
                } else {
                    true
                };
                if clear {
                    seen += w;
                }
            }
            sum += seen / l.total;
        }
        let mut count = self.lights.len();
        if !self.sky.is_empty() {
            let (mut seen, mut total) = (0.0f64, 0.0f64);
            for &d in &self.sky {
                let w = f64::from(d.dot(n));
                if !(w > 0.0) {
                    continue;
                }
                total += w;
                rays += 1;
                let clear = self
                    .occluder
                    .as_ref()
                    .is_none_or(|occ| !occ.occluded_between(o, d, self.t_min, f32::INFINITY, skip));
                if clear {
                    seen += w;
                }
            }
            if total > 0.0 {
                sum += seen / total;
            }
            count += 1;
        }
        (((sum / count as f64) as f32).clamp(0.0, 1.0), rays)
    }

    /// How far a point's rays start inside its own surface on an open boundary, in world
    /// units (the bake's rule, [`crate::origin`]).
    fn boundary_push(&self) -> f32 {
        if self.scale > 0.0 {
            self.offset / self.scale
        } else {
            0.0
        }
    }
}

/// The error of a triangle from V at its corners a, b, c and at its edge midpoints
/// m_ab, m_bc, m_ca: returns (δ, ρ) with
/// δ = max over edges |V(m) − (V(a) + V(b)) / 2| (how far V departs from linear along an
/// edge) and ρ = max − min of the six values (how much V varies across the triangle).
/// The triangle needs refinement when δ > tolerance or ρ > tolerance (and its longest edge is
/// longer than `min_edge`); its priority is max(δ, ρ).
///
/// Why it catches a shadow edge crossing the triangle: a shadow boundary (a curve where V
/// drops by more than the tolerance over a short distance) that crosses the triangle enters
/// through one edge and leaves through another, so it separates one corner from the other two
/// and ρ exceeds the tolerance; a boundary running between a corner and a midpoint, or a
/// shadow band narrower than the triangle lying across an edge's midpoint, shows as the
/// midpoint's departure δ. Penumbrae (V varying smoothly) are split until V varies by at most
/// the tolerance per triangle, which is what linear interpolation needs.
///
/// What it misses on its own: it only looks at six points. A shadow smaller than the triangle
/// that touches none of them (a box's shadow in the middle of a two-triangle floor) leaves all
/// six values equal. The refiner therefore also probes the inside of every triangle longer
/// than 4 shortest splittable edges on a barycentric grid (spacing the diagonal / 64 by
/// default, at most 24 divisions an edge) and takes the range over those probes too; what a
/// grid still misses is a shadow narrower than its spacing. Note also that both values
/// lie in \[min, max\] of the six, so δ ≤ ρ always: the ρ test alone decides, δ is kept as
/// the documented non-linearity term.
pub fn triangle_error(corners: [f32; 3], midpoints: [f32; 3]) -> (f32, f32) {
    let mut dev = 0.0f32;
    for e in 0..3 {
        let lin = 0.5 * (corners[e] + corners[(e + 1) % 3]);
        dev = dev.max((midpoints[e] - lin).abs());
    }
    let all = corners.iter().chain(&midpoints);
    let lo = all.clone().copied().fold(f32::INFINITY, f32::min);
    let hi = all.copied().fold(f32::NEG_INFINITY, f32::max);
    (dev, (hi - lo).max(0.0))
}

/// Refines `mesh` where the visibility of `lights` varies (see the module documentation):
/// returns the refined mesh and what it cost. Original vertices keep their indices (new ones
/// are appended); a triangle that is never split keeps its index and its corners; a split
/// triangle's first half takes its slot and the second is appended, both with its material.
/// Byte-identical output on any number of rayon threads.
///
/// Rays from original vertices skip the vertex's own triangles, as the bake's do; edge
/// midpoints and new vertices skip none (they lie on the surface and rely on the origin
/// offset), so on a smooth-shaded curved mesh a direction just above a new point's shading
/// horizon but below its triangle's plane reads as shadowed where the bake might see it lit.
/// Triangles with a repeated corner are never split and not linked to their neighbours (they
/// have no area, so an edge split beside one opens no crack).
///
/// An input that [`try_refine`] refuses (invalid settings, a mesh failing
/// [`Mesh::validate`], e.g. an empty one) is returned unchanged with `splits` = 0.
pub fn refine(
    mesh: &Mesh,
    lights: &[PolygonLight],
    settings: &RefineSettings,
) -> (Mesh, RefineStats) {
    let start = Instant::now();
    try_refine(mesh, lights, settings).unwrap_or_else(|_| {
        (
            mesh.clone(),
            RefineStats {
                vertices_before: mesh.positions.len(),
                vertices_after: mesh.positions.len(),
                triangles_before: mesh.triangles.len(),
                triangles_after: mesh.triangles.len(),
                seconds: start.elapsed().as_secs_f64(),
                ..RefineStats::default()
            },
        )
    })
}

/// [`refine`], or why the input cannot be refined.
pub fn try_refine(
    mesh: &Mesh,
    lights: &[PolygonLight],
    settings: &RefineSettings,
) -> Result<(Mesh, RefineStats), RefineError> {
    refine_for(mesh, &[], lights, &[], &[], false, settings)
}

/// [`try_refine`] for `lights`, the point and spot lights' spheres `spheres`
/// ([`Visibility::with_spheres`]), the suns at rest ([`Visibility::with_suns`]) and, when
/// `sky`, the sky's visibility ([`Visibility::with_sky`]); rays pass through the cut-outs of
/// `materials` ([`Visibility::with_cutouts`]; empty: every surface opaque).
pub fn refine_for(
    mesh: &Mesh,
    materials: &[Material],
    lights: &[PolygonLight],
    spheres: &[PunctualLight],
    suns: &[SunLight],
    sky: bool,
    settings: &RefineSettings,
) -> Result<(Mesh, RefineStats), RefineError> {
    let start = Instant::now();
    settings
        .validate()
        .map_err(|e| RefineError::Settings(e.to_string()))?;
    mesh.validate()?;
    let vis = Visibility::with_cutouts(mesh, materials, lights, sky)
        .with_spheres(spheres)
        .with_suns(suns);
    let mut r = Refiner::new(mesh, &vis, settings);
    r.run();
    Ok(r.finish(mesh, start))
}

/// The baseline that [`refine`] is measured against: the same crack-free bisection, longest
/// edges first everywhere (uniform subdivision, whatever the lights), until the mesh has
/// `max_vertices` vertices (or no edge is longer than the mesh's diagonal / 256). Used by
/// the refinement benchmark to compare at equal vertex count.
pub fn refine_uniform(mesh: &Mesh, max_vertices: u32) -> Result<(Mesh, RefineStats), RefineError> {
    let start = Instant::now();
    mesh.validate()?;
    let vis = Visibility::new(&Mesh::default(), &[]);
    let settings = RefineSettings {
        tolerance: 0.0,
        lighting: 0.0,
        min_edge: 0.0,
        max_vertices,
    };
    let mut r = Refiner::new(mesh, &vis, &settings);
    r.uniform = true;
    r.run();
    Ok(r.finish(mesh, start))
}

/// An edge: its two vertex indices, smaller first.
type Edge = (u32, u32);

fn edge(a: u32, b: u32) -> Edge {
    if a < b { (a, b) } else { (b, a) }
}

/// A point whose V the refinement needs.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum Point {
    Vertex(u32),
    Midpoint(Edge),
}

/// A triangle waiting to be split; the heap pops the largest error × longest edge² (uniform
/// mode: the longest edge), then the longest edge (so that equal errors refine evenly), then
/// the lowest triangle index.
#[derive(PartialEq, Eq, PartialOrd, Ord)]
struct Entry {
    /// `f32::to_bits` of the priority (≥ 0, so the bits order like the values).
    error: u32,
    /// `f64::to_bits` of the longest edge's squared length.
    longest: u64,
    tri: Reverse<usize>,
    /// The slot's version when the entry was made (a split bumps it: stale entries are
    /// skipped).
    version: u32,
}

/// Why a split did not happen.
enum Stop {
    /// It would exceed `max_vertices`: refinement ends.
    Budget,
    /// The edge is too short for its midpoint to differ from its ends in f32 (or the chain of
    /// neighbours is inconsistent): this triangle is given up.
    Degenerate,
}

struct Refiner<'a> {
    vis: &'a Visibility,
    n_orig: usize,
    tolerance: f32,
    min_edge: f32,
    /// Triangles longer than this are probed inside too ([`Refiner::interior_probes`]).
    probe_spacing: f32,
    max_vertices: u32,
    /// Split by edge length alone (the baseline of [`refine_uniform`]).
    uniform: bool,
    /// `settings.lighting` (0: the lighting term is off).
    lighting: f64,
    /// Triangles whose irradiance stays below this (10⁻³ × the brightest original vertex's)
    /// are not refined for their lighting: too dark to matter.
    dark: f64,
    pos: Vec<Vec3>,
    nrm: Vec<Vec3>,
    /// Per vertex: the unit direction into its own surface on an open boundary, else zero
    /// (the bake's ray origins, [`crate::origin`]).
    inward: Vec<Vec3>,
    /// Texture coordinates, one per vertex, or empty (a mesh without UVs).
    uvs: Vec<glam::Vec2>,
    tris: Vec<[u32; 3]>,
    mats: Vec<u32>,
    version: Vec<u32>,
    /// Triangles using each edge (triangles with a repeated corner are left out).
    edges: HashMap<Edge, Vec<u32>>,
    /// V of each vertex, once needed.
    vert_v: Vec<Option<f32>>,
    /// V of edge midpoints, with the normal it was evaluated with.
    mid_v: HashMap<Edge, (Vec3, f32)>,
    heap: BinaryHeap<Entry>,
    /// Triangles created or changed since the last [`Refiner::flush`].
    dirty: Vec<usize>,
    splits: usize,
    rays: u64,
    budget_reached: bool,
}

impl<'a> Refiner<'a> {
    fn new(mesh: &Mesh, vis: &'a Visibility, settings: &RefineSettings) -> Refiner<'a> {
        let mut edges: HashMap<Edge, Vec<u32>> = HashMap::new();
        for (t, tri) in mesh.triangles.iter().enumerate() {
            if distinct(tri) {
                for e in tri_edges(tri) {
                    edges.entry(e).or_default().push(t as u32);
                }
            }
        }
        Refiner {
            vis,
            n_orig: mesh.positions.len(),
            tolerance: settings.tolerance,
            min_edge: resolved_min_edge(settings, mesh),
            probe_spacing: PROBE_SPACING_EDGES * resolved_min_edge(settings, mesh),
            max_vertices: settings.max_vertices,
            uniform: false,
            lighting: f64::from(settings.lighting),
            dark: DARK_FRACTION * brightest_irradiance(mesh, vis),
            pos: mesh.positions.clone(),
            nrm: mesh.normals.clone(),
            inward: crate::origin::boundary_inward(mesh),
            uvs: mesh.uvs.clone(),
            tris: mesh.triangles.clone(),
            mats: mesh.material_ids.clone(),
            version: vec![0; mesh.triangles.len()],
            edges,
            vert_v: vec![None; mesh.positions.len()],
            mid_v: HashMap::new(),
            heap: BinaryHeap::new(),
            dirty: (0..mesh.triangles.len()).collect(),
            splits: 0,
            rays: 0,
            budget_reached: false,
        }
    }

    /// The refined mesh and what it cost (`input`: the mesh it started from).
    fn finish(self, input: &Mesh, start: Instant) -> (Mesh, RefineStats) {
        let stats = RefineStats {
            vertices_before: input.positions.len(),
            vertices_after: self.pos.len(),
            triangles_before: input.triangles.len(),
            triangles_after: self.tris.len(),
            splits: self.splits,
            samples_cast: self.rays,
            seconds: start.elapsed().as_secs_f64(),
            budget_reached: self.budget_reached,
        };
        let out = Mesh {
            positions: self.pos,
            normals: self.nrm,
            triangles: self.tris,
            material_ids: self.mats,
            uvs: self.uvs,
        };
        (out, stats)
    }

    fn run(&mut self) {
        self.flush();
        while let Some(top) = self.heap.pop() {
            let t = top.tri.0;
            if self.version[t] != top.version {
                continue;
            }
            let result = self.lepp(t);
            if let Err(Stop::Budget) = result {
                break;
            }
            self.flush();
        }
    }

    /// Squared length of an edge, in f64 so that it cannot overflow (computed from the
    /// ordered pair, so always the same bits).
    fn len2(&self, e: Edge) -> f64 {
        (self.pos[e.1 as usize].as_dvec3() - self.pos[e.0 as usize].as_dvec3()).length_squared()
    }

    /// The longest edge of triangle `t` under the strict order (squared length, then indices):
    /// ties are broken the same way by every triangle sharing the edges.
    fn longest_edge(&self, t: usize) -> Edge {
        let key = |e: Edge| (self.len2(e).to_bits(), e);
        tri_edges(&self.tris[t])
            .into_iter()
            .max_by_key(|&e| key(e))
            .unwrap_or((0, 0))
    }

    /// Whether triangle `t` may be split for its own error: distinct corners, non-zero area,
    /// longest edge longer than `min_edge`.
    fn candidate(&self, t: usize) -> bool {
        let tri = &self.tris[t];
        if !distinct(tri) {
            return false;
        }
        let p = tri.map(|i| self.pos[i as usize].as_dvec3());
        let area2 = (p[1] - p[0]).cross(p[2] - p[0]).length_squared();
        area2 > 0.0 && self.len2(self.longest_edge(t)).sqrt() > self.min_edge as f64
    }

    /// The normal of edge `e`'s midpoint (and of the vertex that splits it):
    /// normalize(n_a + n_b), else the face normal of the lowest-index triangle in `tris`,
    /// else n_a, else +Y.
    fn edge_normal(&self, e: Edge, tris: &[u32]) -> Vec3 {
        let (na, nb) = (self.nrm[e.0 as usize], self.nrm[e.1 as usize]);
        (na + nb)
            .try_normalize()
            .or_else(|| {
                let t = tris.iter().min()?;
                let p = self.tris[*t as usize].map(|i| self.pos[i as usize]);
                (p[1] - p[0]).cross(p[2] - p[0]).try_normalize()
            })
            .or_else(|| na.try_normalize())
            .unwrap_or(Vec3::Y)
    }

    /// An edge used by one triangle is on an open boundary: the unit direction from its
    /// midpoint into that triangle, along the surface of normal `n`; zero otherwise.
    fn edge_inward(&self, e: Edge, tris: &[u32], n: Vec3) -> Vec3 {
        let [t] = tris else {
            return Vec3::ZERO;
        };
        let c = self.tris[*t as usize].map(|i| self.pos[i as usize].as_dvec3());
        let m = midpoint(self.pos[e.0 as usize], self.pos[e.1 as usize]).as_dvec3();
        crate::origin::tangential_unit((c[0] + c[1] + c[2]) / 3.0 - m, n)
    }

    /// Where a point's rays start (on an open boundary, inside its own surface), its normal
    /// and the vertex its rays skip.
    fn geometry(&self, p: Point) -> (Vec3, Vec3, u32) {
        match p {
            Point::Vertex(v) => {
                let skip = if (v as usize) < self.n_orig {
                    v
                } else {
                    u32::MAX
                };
                let push = self.inward[v as usize] * self.vis.boundary_push();
                (self.pos[v as usize] + push, self.nrm[v as usize], skip)
            }
            Point::Midpoint(e) => {
                let tris = self.edges.get(&e).map(Vec::as_slice).unwrap_or(&[]);
                let n = self.edge_normal(e, tris);
                let push = self.edge_inward(e, tris, n) * self.vis.boundary_push();
                (
                    midpoint(self.pos[e.0 as usize], self.pos[e.1 as usize]) + push,
                    n,
                    u32::MAX,
                )
            }
        }
    }

    /// Evaluates V where the dirty triangles need it (rays in parallel, results stored in a
    /// fixed order) and queues those that need refinement.
    fn flush(&mut self) {
        let mut dirty = std::mem::take(&mut self.dirty);
        dirty.sort_unstable();
        dirty.dedup();
        dirty.retain(|&t| self.candidate(t));
        if self.uniform {
            // Longest edges first, whatever the light: the error is the edge's length.
            for t in dirty {
                let longest = self.len2(self.longest_edge(t));
                self.heap.push(Entry {
                    error: (longest.sqrt() as f32).to_bits(),
                    longest: longest.to_bits(),
                    tri: Reverse(t),
                    version: self.version[t],
                });
            }
            return;
        }
        let mut need = Vec::new();
        let mut seen = HashSet::new();
        for &t in &dirty {
            let tri = self.tris[t];
            for v in tri {
                if self.vert_v[v as usize].is_none() && seen.insert(Point::Vertex(v)) {
                    need.push(Point::Vertex(v));
                }
            }
            for e in tri_edges(&tri) {
                if !self.mid_v.contains_key(&e) && seen.insert(Point::Midpoint(e)) {
                    need.push(Point::Midpoint(e));
                }
            }
        }
        let mut geo: Vec<(Vec3, Vec3, u32)> = need.iter().map(|&p| self.geometry(p)).collect();
        // Interior probes of the large triangles, after the shared points: (first, count).
        let probes: Vec<(usize, usize)> = dirty
            .iter()
            .map(|&t| {
                let first = geo.len();
                geo.extend(self.interior_probes(t).map(|(p, n)| (p, n, u32::MAX)));
                (first, geo.len() - first)
            })
            .collect();
        let vis = self.vis;
        let values: Vec<(f32, u64)> = geo
            .par_iter()
            .map(|&(p, n, skip)| vis.eval(p, n, skip))
            .collect();
        self.rays += values[need.len()..].iter().map(|v| v.1).sum::<u64>();
        for ((&pt, &(_, n, _)), &(v, rays)) in need.iter().zip(&geo).zip(&values) {
            self.rays += rays;
            match pt {
                Point::Vertex(i) => self.vert_v[i as usize] = Some(v),
                Point::Midpoint(e) => {
                    self.mid_v.insert(e, (n, v));
                }
            }
        }
        for (t, (first, count)) in dirty.into_iter().zip(probes) {
            let tri = self.tris[t];
            let corners = tri.map(|i| self.vert_v[i as usize].unwrap_or(0.0));
            let mids = tri_edges(&tri).map(|e| self.mid_v.get(&e).map_or(0.0, |m| m.1));
            let (dev, range) = triangle_error(corners, mids);
            // A shadow inside a large triangle that misses its six points shows in the probes.
            let inside = values[first..first + count].iter().map(|v| v.0);
            let all = corners.into_iter().chain(mids).chain(inside);
            let lo = all.clone().fold(f32::INFINITY, f32::min);
            let mut range = range.max(all.fold(f32::NEG_INFINITY, f32::max) - lo);
            if self.lighting > 0.0 {
                // The lighting term, in units of the tolerance's: (range of E / largest E) /
                // lighting × tolerance, so that one threshold and one priority serve both.
                let corners = tri.map(|i| self.geometry(Point::Vertex(i)));
                let mids = tri_edges(&tri).map(|e| self.geometry(Point::Midpoint(e)));
                let inside = geo[first..first + count].iter();
                let e = corners
                    .iter()
                    .chain(&mids)
                    .chain(inside)
                    .map(|&(p, n, _)| self.vis.irradiance(p, n));
                let (lo, hi) = e.fold((f64::INFINITY, 0.0f64), |(l, h), x| (l.min(x), h.max(x)));
                if hi > self.dark && hi > 0.0 {
                    let light = ((hi - lo) / hi / self.lighting) as f32 * self.tolerance.max(1e-6);
                    range = range.max(light);
                }
            }
            if dev > self.tolerance || range > self.tolerance {
                // Largest error × size first: what a split takes off the image's L¹ error
                // (a triangle's error covers its area; the longest edge² stands for it).
                let longest = self.len2(self.longest_edge(t));
                let priority = (f64::from(dev.max(range)) * longest) as f32;
                self.heap.push(Entry {
                    error: priority.max(0.0).to_bits(),
                    longest: longest.to_bits(),
                    tri: Reverse(t),
                    version: self.version[t],
                });
            }
        }
    }

    /// The interior probe points of triangle `t` (position, normal): none for a triangle whose
    /// longest edge is at most `probe_spacing`; otherwise the interior nodes of the barycentric
    /// grid (i, j, k) / n, i + j + k = n, all of i, j, k ≥ 1, with n = ⌈longest / spacing⌉
    /// capped at [`MAX_PROBE_DIVISIONS`]. Normals are the corners' interpolated (else the face
    /// normal). Corners and edge midpoints are measured once per vertex and edge, these per
    /// triangle.
    fn interior_probes(&self, t: usize) -> impl Iterator<Item = (Vec3, Vec3)> + '_ {
        let tri = self.tris[t];
        let longest = self.len2(self.longest_edge(t)).sqrt();
        let n = if longest > self.probe_spacing as f64 && self.probe_spacing > 0.0 {
            ((longest / self.probe_spacing as f64).ceil() as u32).min(MAX_PROBE_DIVISIONS)
        } else {
            0
        };
        let p = tri.map(|i| self.pos[i as usize]);
        let nv = tri.map(|i| self.nrm[i as usize]);
        let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or(Vec3::Y);
        (1..n.max(1)).flat_map(move |i| {
            (1..n - i).map(move |j| {
                let k = n - i - j;
                let w = [i, j, k].map(|x| x as f32 / n as f32);
                let at = p[0] * w[0] + p[1] * w[1] + p[2] * w[2];
                let nrm = (nv[0] * w[0] + nv[1] * w[1] + nv[2] * w[2]).normalize_or(face);
                (at, nrm)
            })
        })
    }

    /// Rivara's longest-edge propagation path: bisects triangle `target` by its longest edge,
    /// first bisecting the neighbours across that edge whose own longest edge is another (and
    /// so on, recursively), so that every edge split is the longest edge of every triangle
    /// sharing it (a "terminal" edge) and is split in all of them at once. Edges grow strictly
    /// along the path (squared length, then indices), so it ends.
    fn lepp(&mut self, target: usize) -> Result<(), Stop> {
        let mut stack = vec![target];
        while let Some(&u) = stack.last() {
            let e = self.longest_edge(u);
            let next = self.edges.get(&e).and_then(|ts| {
                ts.iter()
                    .copied()
                    .filter(|&w| w as usize != u && self.longest_edge(w as usize) != e)
                    .min()
            });
            match next {
                Some(w) if stack.contains(&(w as usize)) => return Err(Stop::Degenerate),
                Some(w) => stack.push(w as usize),
                None => {
                    self.split_edge(e)?;
                    stack.pop();
                }
            }
        }
        Ok(())
    }

    /// Splits edge `e` at its midpoint in every triangle sharing it.
    fn split_edge(&mut self, e: Edge) -> Result<(), Stop> {
        if self.pos.len() >= self.max_vertices as usize {
            self.budget_reached = true;
            return Err(Stop::Budget);
        }
        let (pa, pb) = (self.pos[e.0 as usize], self.pos[e.1 as usize]);
        let pm = midpoint(pa, pb);
        if pm == pa || pm == pb {
            return Err(Stop::Degenerate);
        }
        let mut ts = self.edges.remove(&e).unwrap_or_default();
        if ts.is_empty() {
            return Err(Stop::Degenerate);
        }
        ts.sort_unstable();
        ts.dedup();
        let normal = self.edge_normal(e, &ts);
        let inward = self.edge_inward(e, &ts, normal);
        let m = self.pos.len() as u32;
        self.pos.push(pm);
        self.nrm.push(normal);
        self.inward.push(inward);
        // Texture coordinates are affine over a triangle: the edge's midpoint has the mean UV
        // (UV seams split vertices, so an edge has one UV at each end).
        if !self.uvs.is_empty() {
            let (ua, ub) = (self.uvs[e.0 as usize], self.uvs[e.1 as usize]);
            self.uvs.push(0.5 * (ua + ub));
        }
        let cached = self
            .mid_v
            .remove(&e)
            .filter(|(n, _)| n.to_array() == normal.to_array());
        self.vert_v.push(cached.map(|c| c.1));
        for t in ts {
            let t = t as usize;
            let tri = self.tris[t];
            let Some(i) = (0..3).find(|&i| edge(tri[i], tri[(i + 1) % 3]) == e) else {
                continue;
            };
            let (p, q, c) = (tri[i], tri[(i + 1) % 3], tri[(i + 2) % 3]);
            let t2 = self.tris.len();
            self.detach(edge(q, c), t as u32);
            self.tris[t] = [p, m, c];
            self.version[t] = self.version[t].wrapping_add(1);
            self.tris.push([m, q, c]);
            self.mats.push(self.mats[t]);
            self.version.push(0);
            for (e2, tt) in [
                (edge(p, m), t),
                (edge(m, c), t),
                (edge(m, q), t2),
                (edge(q, c), t2),
                (edge(c, m), t2),
            ] {
                self.edges.entry(e2).or_default().push(tt as u32);
            }
            self.dirty.push(t);
            self.dirty.push(t2);
        }
        self.splits += 1;
        Ok(())
    }

    fn detach(&mut self, e: Edge, t: u32) {
        if let Some(list) = self.edges.get_mut(&e) {
            list.retain(|&x| x != t);
            if list.is_empty() {
                self.edges.remove(&e);
            }
        }
    }
}

/// Lighting below this fraction of the brightest vertex's is not refined for.
const DARK_FRACTION: f64 = 1e-3;

/// The largest unshadowed irradiance at a vertex of `mesh`.
fn brightest_irradiance(mesh: &Mesh, vis: &Visibility) -> f64 {
    mesh.positions
        .par_iter()
        .zip(&mesh.normals)
        .map(|(&p, &n)| vis.irradiance(p, n))
        .reduce(|| 0.0, f64::max)
}

/// (a + b) / 2, computed so that it cannot overflow.
fn midpoint(a: Vec3, b: Vec3) -> Vec3 {
    a * 0.5 + b * 0.5
}

fn distinct(t: &[u32; 3]) -> bool {
    t[0] != t[1] && t[1] != t[2] && t[2] != t[0]
}

/// The edges (v0, v1), (v1, v2), (v2, v0).
fn tri_edges(t: &[u32; 3]) -> [Edge; 3] {
    [edge(t[0], t[1]), edge(t[1], t[2]), edge(t[2], t[0])]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygon_samples_cover_the_polygon_with_equal_area_cells() {
        let quad = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, 1.0),
        ];
        let (pts, w) = polygon_samples(&quad);
        assert_eq!(pts.len(), 50);
        assert!((w.iter().sum::<f64>() - 2.0).abs() < 1e-9);
        let mean = pts.iter().copied().sum::<Vec3>() / pts.len() as f32;
        assert!((mean - Vec3::new(1.0, 0.0, 0.5)).length() < 1e-5, "{mean}");
        assert!(
            pts.iter()
                .all(|p| p.x > 0.0 && p.x < 2.0 && p.z > 0.0 && p.z < 1.0)
        );
        for n in 3..=8usize {
            let poly: Vec<Vec3> = (0..n)
                .map(|i| {
                    let a = i as f32 / n as f32 * std::f32::consts::TAU;
                    Vec3::new(a.cos(), 0.0, a.sin())
                })
                .collect();
            let c = polygon_samples(&poly).0.len();
            assert!((16..=64).contains(&c), "{n} corners: {c} samples");
        }
    }

    #[test]
    fn region_samples_follow_the_box_shape() {
        let b = |max: Vec3| Aabb {
            min: Vec3::ZERO,
            max,
        };
        assert_eq!(region_samples(b(Vec3::ONE)).len(), 64);
        let flat = region_samples(b(Vec3::new(1.0, 0.0, 1.0)));
        assert_eq!(flat.len(), 49);
        assert!(flat.iter().all(|p| p.y == 0.0));
        let long = region_samples(b(Vec3::new(4.0, 1.0, 1.0)));
        assert!((16..=64).contains(&long.len()), "{}", long.len());
        assert_eq!(region_samples(b(Vec3::ZERO)).len(), 1);
    }

    #[test]
    fn error_is_the_range_and_the_midpoint_departure() {
        let (d, r) = triangle_error([0.0, 1.0, 1.0], [0.5, 1.0, 0.5]);
        assert_eq!((d, r), (0.0, 1.0));
        let (d, r) = triangle_error([1.0, 1.0, 1.0], [0.0, 1.0, 1.0]);
        assert_eq!((d, r), (1.0, 1.0));
        assert_eq!(triangle_error([0.3; 3], [0.3; 3]), (0.0, 0.0));
    }

    #[test]
    fn settings_are_checked() {
        assert!(RefineSettings::default().validate().is_ok());
        for s in [
            RefineSettings {
                tolerance: f32::NAN,
                ..RefineSettings::default()
            },
            RefineSettings {
                tolerance: -0.1,
                ..RefineSettings::default()
            },
            RefineSettings {
                min_edge: f32::INFINITY,
                ..RefineSettings::default()
            },
            RefineSettings {
                min_edge: -1.0,
                ..RefineSettings::default()
            },
        ] {
            let msg = s
                .validate()
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(
                msg.contains("tolerance") || msg.contains("min_edge"),
                "{s:?}: {msg:?}"
            );
        }
    }
}
