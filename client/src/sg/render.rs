//! The SG renderer (paper 001): per pixel of the G-buffer,
//!
//! ```text
//! L_o = Σ_k rgb_k ⊙ [ albedo/π · ∫ G_k C V_k  +  F · ∫ G_k S V_k ]
//! ```
//!
//! G_k the lighting lobes ([`super::fit`]), C the clamped cosine and S the warped GGX lobe
//! ([`super::brdf`]). Each product G_k C, G_k S is one SG (axis p, sharpness λ); its visible
//! integral is S(λ) F(λ, d) ([`super::halfspace`]) with d the signed distance of p to the
//! visibility boundary: the smaller of the horizon's asin(p·n) and the occluder boundary's
//! asin(p·m_k), m_k the half-space of lobe k's SSDF at this point ([`super::ssdf`]).
//!
//! Nothing is precomputed: the screen-space depth maps are rendered from the mesh as it is
//! in this frame, so moving geometry needs nothing but a new call. A caller drawing a
//! sequence passes an [`SgCache`] ([`render_cached`]): the maps and the diffuse tables are
//! kept while the lobes and the mesh's positions are unchanged (a still scene), and rebuilt
//! the frame they change (a moving one).

use std::f64::consts::PI;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Result, bail};
use bspvt_proto::Scene;
use bspvt_proto::scene::Material;
use bspvt_raytrace::Occluder;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::Sg;
use super::brdf::{cosine_lobe, ggx_lobe};
use super::diffuse::{self, DiffuseTable};
use super::fit::SgEnv;
use super::halfspace;
use super::ssdf::{Boundary, DepthMap, Point, exact_boundary};
use crate::frame::brdf::{Brdf, Shadows};
use crate::frame::camera::View;
use crate::frame::gbuffer::GBuffer;
use crate::frame::image::Image;

/// How the SSDF is found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SsdfMode {
    /// The paper's: a depth map per lighting lobe with a MIN/MAX pyramid, coarse-to-fine.
    Screen,
    /// Ray-cast search around each lobe axis with the BVH (reference; slow).
    Exact,
    /// No occluders (horizon only): unshadowed SG shading.
    None,
}

/// Renderer settings.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct SgOptions {
    /// How the SSDF (visibility) is found.
    pub ssdf: SsdfMode,
    /// Side of the screen-space depth maps (rounded up to a power of two; paper: 256).
    pub depth_res: u32,
    /// SSDF sharing: the search runs at one pixel of every `stride`×`stride` block and the
    /// block's other pixels reuse its boundaries when they lie on the same surface (within
    /// three pixel footprints, normals within 25°); 1 = every pixel (the paper's).
    pub stride: u32,
    /// Screen SSDF: side of the neighbourhood searched at each finer pyramid level (the
    /// paper's 6; 4 visits 16 instead of 36 texels per level).
    pub window: u32,
}

impl Default for SgOptions {
    fn default() -> SgOptions {
        SgOptions {
            ssdf: SsdfMode::Screen,
            depth_res: 128,
            stride: 2,
            window: super::ssdf::DEFAULT_WINDOW,
        }
    }
}

/// Where a frame's time went.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct SgTimings {
    /// Rendering the depth maps and their pyramids (screen mode).
    pub maps_ms: f64,
    /// The per-pixel pass (SSDF search + shading).
    pub(crate) pixels_ms: f64,
    pub(crate) pixels_shaded: usize,
    pub(crate) lobes: usize,
    /// SSDF searches run (pixel × lobe), and those reused from a block's representative.
    pub(crate) searches: u64,
    pub(crate) reused: u64,
}

/// A lobe whose unshadowed bound (full-sphere integral of its products) is below this fraction
/// of the pixel's total is skipped: the image changes by less than CULL × K relative.
const CULL: f64 = 1e-4;

/// A lobe's diffuse product at one pixel: from its table, or exact (sharp lobes).
#[derive(Clone, Copy, Debug)]
enum Diffuse {
    /// ∫ G_k C over the sphere and over the horizon's half-space.
    Table { full: f64, horizon: f64 },
    /// The product SG and its sphere integral.
    Exact { sg: Sg, full: f64 },
}

impl Diffuse {
    fn full(&self) -> f64 {
        match *self {
            Diffuse::Table { full, .. } | Diffuse::Exact { full, .. } => full,
        }
    }
}

/// The visible integral of `g` (whose full-sphere integral is `full`) given the horizon `n`
/// and the lobe's boundary.
#[inline]
fn visible_integral(g: &Sg, full: f64, n: DVec3, b: &Boundary) -> f64 {
    if !(full > 0.0) {
        return 0.0;
    }
    let p = g.axis.as_vec3();
    let d = p
        .dot(n.as_vec3())
        .clamp(-1.0, 1.0)
        .asin()
        .min(b.distance(p));
    if d == f32::NEG_INFINITY {
        return 0.0;
    }
    full * f64::from(halfspace::fraction(g.lambda as f32, d))
}

/// What [`render_cached`] keeps between frames, each part with the key it was built for:
/// the diffuse tables (a function of the lobes) and the screen-space depth maps (of the lobes,
/// the mesh's positions and the maps' side).
#[derive(Default)]
pub struct SgCache {
    tables: Option<(u64, Arc<Vec<Option<DiffuseTable>>>)>,
    maps: Option<(u64, Arc<Vec<DepthMap>>)>,
}

/// Key of the lobes' shapes (axes and sharpness: what the tables and maps depend on).
fn lobes_key(env: &SgEnv) -> u64 {
    let mut h = bspvt_proto::hash::Fnv1a::default();
    for l in &env.lobes {
        for v in l.axis.iter().chain([&l.lambda]) {
            h.write(&v.to_le_bytes());
        }
    }
    h.finish()
}

/// Renders one SG frame of `scene` at the G-buffer's pixels. `occluder` is required for
/// [`SsdfMode::Exact`]. Pixels without a surface are black. Builds everything anew: a
/// sequence uses [`render_cached`].
pub fn render(
    scene: &Scene,
    view: &View,
    gbuffer: &GBuffer,
    env: &SgEnv,
    occluder: Option<&Occluder>,
    opts: &SgOptions,
) -> Result<(Image, SgTimings)> {
    render_cached(
        scene,
        view,
        gbuffer,
        env,
        occluder,
        opts,
        &mut SgCache::default(),
    )
}

/// [`render`], reusing from `cache` the tables and depth maps that this frame's lobes and
/// mesh positions leave unchanged (and storing this frame's).
pub fn render_cached(
    scene: &Scene,
    view: &View,
    gbuffer: &GBuffer,
    env: &SgEnv,
    occluder: Option<&Occluder>,
    opts: &SgOptions,
    cache: &mut SgCache,
) -> Result<(Image, SgTimings)> {
    if opts.ssdf == SsdfMode::Exact && occluder.is_none() {
        bail!("the exact SSDF needs the ray-tracing BVH (an occluder)");
    }
    halfspace::warm_up();
    let mesh = &scene.mesh;
    let t0 = Instant::now();
    let lobes_key = lobes_key(env);
    let maps: Arc<Vec<DepthMap>> = if opts.ssdf == SsdfMode::Screen {
        let mut h = bspvt_proto::hash::Fnv1a::default();
        h.write(&lobes_key.to_le_bytes());
        h.write(&opts.depth_res.to_le_bytes());
        h.write(&(mesh.triangles.len() as u64).to_le_bytes());
        for p in &mesh.positions {
            h.write_f32s(&p.to_array());
        }
        let key = h.finish();
        match &cache.maps {
            Some((k, maps)) if *k == key => maps.clone(),
            _ => {
                let b = mesh.bounds();
                let centre = b.center();
                let radius = 0.5 * b.diagonal();
                let maps: Arc<Vec<DepthMap>> = Arc::new(
                    env.lobes
                        .par_iter()
                        .map(|l| {
                            let xi = DVec3::from(l.axis).normalize_or(DVec3::Y).as_vec3();
                            DepthMap::render(mesh, centre, radius, xi, opts.depth_res as usize)
                        })
                        .collect(),
                );
                cache.maps = Some((key, maps.clone()));
                maps
            }
        }
    } else {
        Arc::new(Vec::new())
    };
    let maps_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t1 = Instant::now();
    let brdfs: Vec<Brdf> = scene.materials.iter().map(Brdf::from_material).collect();
    let fallback = Brdf::from_material(&Material::default());
    let eps = Shadows::for_scene(scene, None).epsilon as f32;
    let bias_abs = 1e-3 * mesh.bounds().diagonal();
    let lobes: Vec<(Sg, DVec3, Vec3)> = env
        .lobes
        .iter()
        .map(|l| {
            let sg = l.sg();
            (sg, l.rgb(), sg.axis.as_vec3())
        })
        .collect();
    // The diffuse term of each (not too sharp) lobe as a function of n·ξ ([`super::diffuse`]).
    let tables = match &cache.tables {
        Some((k, t)) if *k == lobes_key => t.clone(),
        _ => {
            let t: Arc<Vec<Option<DiffuseTable>>> = Arc::new(
                lobes
                    .par_iter()
                    .map(|(g, _, _)| DiffuseTable::new(g))
                    .collect(),
            );
            cache.tables = Some((lobes_key, t.clone()));
            t
        }
    };
    let search = |point: &Point, k: usize, xi: Vec3| match opts.ssdf {
        SsdfMode::None => Boundary::Visible,
        SsdfMode::Screen => maps[k].boundary(point, bias_abs, opts.window),
        SsdfMode::Exact => match occluder {
            Some(occ) => exact_boundary(occ, point, xi, eps),
            None => Boundary::Visible,
        },
    };
    let (w, h) = (gbuffer.width as usize, gbuffer.height as usize);
    let kk = lobes.len();
    // Pass 1: boundaries at each block's representative pixel (its top-left).
    let stride = if opts.ssdf == SsdfMode::None {
        1
    } else {
        opts.stride.max(1) as usize
    };
    let (bw, bh) = (w.div_ceil(stride), h.div_ceil(stride));
    // Per block: the representative's point and reuse tolerance, and its K boundaries. One
    // task per row of blocks, searched lobe by lobe (lobe-major), so that one depth map's
    // pyramid stays in cache while the row's points walk across it.
    let n_blocks = if stride > 1 { bw * bh } else { 0 };
    let mut rep_points: Vec<Option<(Point, f32)>> = vec![None; n_blocks];
    let mut rep_bounds = vec![Boundary::Visible; n_blocks * kk];
    rep_points
        .par_chunks_mut(bw)
        .zip(rep_bounds.par_chunks_mut((bw * kk).max(1)))
        .enumerate()
        .for_each(|(by, (points, bounds))| {
            for (bx, out) in points.iter_mut().enumerate() {
                let i = by * stride * w + bx * stride;
                *out = gbuffer.surface(mesh, view, i).map(|s| {
                    // Three pixel footprints at this depth.
                    let depth = (s.position - view.eye).dot(view.forward).max(0.0);
                    let tol = (6.0 * view.tan_half_fov * depth / f64::from(gbuffer.height)) as f32;
                    let point = Point {
                        position: s.position.as_vec3(),
                        geometric: s.geometric.as_vec3(),
                    };
                    (point, tol)
                });
            }
            for (k, (_, _, xi)) in lobes.iter().enumerate() {
                for (bx, p) in points.iter().enumerate() {
                    if let Some((point, _)) = p {
                        bounds[bx * kk + k] = search(point, k, *xi);
                    }
                }
            }
        });
    let searches = std::sync::atomic::AtomicU64::new(0);
    let reused = std::sync::atomic::AtomicU64::new(0);
    let mut img = Image::new(gbuffer.width, gbuffer.height);
    img.pixels
        .par_iter_mut()
        .enumerate()
        .with_min_len(32)
        .for_each_init(
            || Vec::with_capacity(kk),
            |terms, (i, px)| {
                let Some(s) = gbuffer.surface(mesh, view, i) else {
                    return;
                };
                let brdf = mesh
                    .material_ids
                    .get(s.tri as usize)
                    .and_then(|&m| brdfs.get(m as usize))
                    .unwrap_or(&fallback);
                let n = s.normal;
                let wo = (view.eye - s.position).normalize_or(n);
                let point = Point {
                    position: s.position.as_vec3(),
                    geometric: s.geometric.as_vec3(),
                };
                // The block representative's boundaries, when it lies on the same surface.
                let rep = if stride > 1 {
                    let (x, y) = (i % w, i / w);
                    let b = (y / stride) * bw + x / stride;
                    match &rep_points[b] {
                        Some((rp, tol))
                            if (rp.position - point.position).length() <= *tol
                                && rp.geometric.dot(point.geometric) > 0.9 =>
                        {
                            Some(&rep_bounds[b * kk..(b + 1) * kk])
                        }
                        _ => None,
                    }
                } else {
                    None
                };
                let cos = cosine_lobe(n);
                let spec = ggx_lobe(brdf.alpha, n, wo);
                let diffuse = brdf.albedo / PI;
                let fresnel = spec.map(|s| brdf.f0 + (DVec3::ONE - brdf.f0) * s.fresnel_weight);
                // Products first: their unshadowed integrals bound each lobe's contribution, and
                // lobes below CULL of the pixel's total skip the SSDF search and the integral.
                let zero = Sg::new(DVec3::Z, 0.0, 0.0);
                terms.clear();
                let mut total = 0.0;
                for (k, (g, rgb, _)) in lobes.iter().enumerate() {
                    let d = match &tables[k] {
                        Some(t) => {
                            let (full, horizon) = t.lookup(g.axis.dot(n));
                            Diffuse::Table { full, horizon }
                        }
                        None => {
                            let (sg, full) = g.product_and_integral_f32(&cos);
                            Diffuse::Exact { sg, full }
                        }
                    };
                    let (ps, is) = match spec {
                        Some(sp) => g.product_and_integral_f32(&sp.sg),
                        None => (zero, 0.0),
                    };
                    let bound = *rgb * (diffuse * d.full() + fresnel.unwrap_or(DVec3::ZERO) * is);
                    total += bound.element_sum();
                    terms.push((d, ps, is, bound));
                }
                let cull = CULL * total;
                let mut acc = DVec3::ZERO;
                let (mut n_search, mut n_reuse) = (0u64, 0u64);
                for (k, ((g, rgb, xi), (d, ps, is, bound))) in
                    lobes.iter().zip(terms.iter()).enumerate()
                {
                    if !(bound.element_sum() > cull) {
                        continue;
                    }
                    let b = match rep {
                        Some(bs) => {
                            n_reuse += 1;
                            bs[k]
                        }
                        None => {
                            n_search += 1;
                            search(&point, k, *xi)
                        }
                    };
                    if b == Boundary::Occluded {
                        continue;
                    }
                    // Each term alone is skipped when its bound is below the cull level too.
                    let mut c = DVec3::ZERO;
                    if (*rgb * diffuse * d.full()).element_sum() > cull {
                        let v = match *d {
                            Diffuse::Exact { sg, full } => visible_integral(&sg, full, n, &b),
                            Diffuse::Table { horizon, .. } => match b {
                                // The horizon is the nearer boundary of the product: tabulated.
                                Boundary::Plane(m) => {
                                    let p = diffuse::product_axis(g, n).as_vec3();
                                    if p.dot(m) >= p.dot(n.as_vec3()) {
                                        horizon
                                    } else {
                                        let (sg, full) = g.product_and_integral_f32(&cos);
                                        visible_integral(&sg, full, n, &b)
                                    }
                                }
                                _ => horizon,
                            },
                        };
                        c += diffuse * v;
                    }
                    if let Some(f) = fresnel
                        && (*rgb * f * *is).element_sum() > cull
                    {
                        c += f * visible_integral(ps, *is, n, &b);
                    }
                    acc += *rgb * c;
                }
                if opts.ssdf != SsdfMode::None {
                    searches.fetch_add(n_search, std::sync::atomic::Ordering::Relaxed);
                    reused.fetch_add(n_reuse, std::sync::atomic::Ordering::Relaxed);
                }
                if acc.is_finite() {
                    *px = acc.as_vec3().to_array();
                }
            },
        );
    let rep_searches = if opts.ssdf == SsdfMode::None {
        0
    } else {
        (rep_points.iter().flatten().count() * kk) as u64
    };
    let timings = SgTimings {
        maps_ms,
        pixels_ms: t1.elapsed().as_secs_f64() * 1e3,
        pixels_shaded: gbuffer.covered(),
        lobes: env.lobes.len(),
        searches: searches.into_inner() + rep_searches,
        reused: reused.into_inner(),
    };
    Ok((img, timings))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sg::fit::LightLobe;
    use bspvt_proto::{Scene, builtin};

    fn one_lobe(axis: [f64; 3], lambda: f64) -> SgEnv {
        SgEnv {
            lobes: vec![LightLobe {
                axis,
                lambda,
                rgb: [1.0, 0.5, 0.25],
            }],
            fit_error: 0.0,
            fit_error_fitted_map: 0.0,
            iterations: 0,
            seconds: 0.0,
        }
    }

    /// Every mode renders finite, non-negative images; shadows only darken (screen and exact
    /// ≤ unshadowed, up to the half-space model's smoothing), and the exact SSDF needs rays.
    #[test]
    fn modes_render_finite_images() {
        let scene = builtin::scene("plate-small").expect("built-in scene");
        let view = View::new(&scene.camera, 48, 32);
        let g = GBuffer::rasterize(&scene.mesh, &view);
        let tris = bspvt_raytrace::mesh_triangles(&scene.mesh);
        let occ = Occluder::new(&scene.mesh, &tris);
        let env = one_lobe([0.2, 1.0, 0.1], 20.0);
        let mut means = Vec::new();
        for ssdf in [SsdfMode::None, SsdfMode::Screen, SsdfMode::Exact] {
            let opts = SgOptions {
                ssdf,
                depth_res: 64,
                stride: 1,
                window: 6,
            };
            let (img, t) = render(&scene, &view, &g, &env, Some(&occ), &opts).expect("render");
            assert!(
                img.pixels
                    .iter()
                    .flatten()
                    .all(|c| c.is_finite() && *c >= 0.0),
                "{ssdf:?}"
            );
            assert_eq!(t.pixels_shaded, g.covered());
            means.push(img.mean());
        }
        eprintln!("means none/screen/exact: {means:?}");
        assert!(means[0] > 0.0);
        assert!(means[1] < means[0] && means[2] < means[0], "{means:?}");
        let opts = SgOptions {
            ssdf: SsdfMode::Exact,
            depth_res: 64,
            stride: 1,
            window: 6,
        };
        assert!(render(&scene, &view, &g, &env, None, &opts).is_err());
    }

    /// Sharing the SSDF over 2×2 blocks changes the image little and runs fewer searches.
    #[test]
    fn block_sharing_is_close_to_per_pixel() {
        let scene = builtin::scene("plate-small").expect("built-in scene");
        let view = View::new(&scene.camera, 64, 48);
        let g = GBuffer::rasterize(&scene.mesh, &view);
        let env = one_lobe([0.3, 1.0, -0.2], 8.0);
        let run = |stride| {
            let opts = SgOptions {
                ssdf: SsdfMode::Screen,
                depth_res: 64,
                stride,
                window: 6,
            };
            render(&scene, &view, &g, &env, None, &opts).expect("render")
        };
        let (a, ta) = run(1);
        let (b, tb) = run(2);
        // Pixels black in both (background) are left out.
        let e = crate::frame::stats::rmse(&a, &b, |i| {
            a.pixels[i] != [0.0; 3] || b.pixels[i] != [0.0; 3]
        });
        eprintln!(
            "stride 2 vs 1: RMSE {e:.5} (mean {:.5}); searches {} + {} reused vs {}",
            a.mean(),
            tb.searches,
            tb.reused,
            ta.searches
        );
        // Coarse on purpose: at 64×48 a 2×2 block spans a large part of a shadow edge.
        assert!(e < 0.25 * a.mean(), "{e}");
        assert!(tb.searches < ta.searches && tb.reused > 0);
        assert_eq!(ta.reused, 0);
    }

    /// No precompute: move the occluder, render again, and the shadow follows (the darkest
    /// ground pixel of the first frame is lit in the second; the depth maps are rebuilt from
    /// the mesh as it is).
    #[test]
    fn moving_geometry_moves_the_shadow() {
        let sphere = builtin::icosphere(2, 0);
        let n_sphere = sphere.positions.len();
        let sphere_tris = sphere.triangles.len() as u32;
        let mut scene = Scene::from_mesh(sphere).expect("scene");
        let camera = bspvt_proto::scene::Camera {
            position: [0.0, 12.0, 0.01],
            target: [0.0, 0.0, 0.0],
            up: [0.0, 0.0, -1.0],
            fov_y_deg: 50.0,
            aspect: None,
        };
        let env = one_lobe([0.6, 1.0, 0.0], 30.0);
        let opts = SgOptions {
            ssdf: SsdfMode::Screen,
            depth_res: 128,
            stride: 1,
            window: 6,
        };
        // One cache across the frames, as a sequence keeps it: a still frame reuses the maps,
        // a moved mesh rebuilds them; either way the image is the one built from scratch.
        let mut cache = SgCache::default();
        let mut frame = |scene: &Scene| {
            let view = View::new(&camera, 64, 64);
            let g = GBuffer::rasterize(&scene.mesh, &view);
            let (img, _) = render(scene, &view, &g, &env, None, &opts).expect("render");
            for _ in 0..2 {
                let (cached, _) =
                    render_cached(scene, &view, &g, &env, None, &opts, &mut cache).expect("render");
                assert_eq!(cached.pixels, img.pixels, "the cached frame differs");
            }
            (img, g)
        };
        let (a, ga) = frame(&scene);
        // The darkest pixel on the ground (not on the sphere).
        let lum = |p: [f32; 3]| p[0] + p[1] + p[2];
        let (dark, _) = (0..a.pixels.len())
            .filter(|&i| ga.tri[i] != crate::frame::gbuffer::NONE && ga.tri[i] >= sphere_tris)
            .map(|i| (i, lum(a.pixels[i])))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .expect("ground pixels");
        for p in &mut scene.mesh.positions[..n_sphere] {
            p.x += 3.0;
        }
        let (b, gb) = frame(&scene);
        assert!(
            gb.tri[dark] >= sphere_tris,
            "the pixel still shows the ground"
        );
        let (before, after) = (lum(a.pixels[dark]), lum(b.pixels[dark]));
        eprintln!("darkest ground pixel: {before} before, {after} after the move");
        assert!(after > 2.0 * before + 1e-4, "{before} → {after}");
    }
}
