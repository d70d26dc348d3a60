//! Rendering a frame sequence while the light moves, with timings: what `bspvt render`,
//! `bspvt demo` and the benchmarks share.

use std::time::Instant;

use anyhow::{Context, Result, bail};
use bspvt_proto::Scene;
use serde::Serialize;

use super::image::Image;
use super::path::LightPath;
use super::posed::Posed;
use super::renderer::{FrameCounts, Mode, Renderer, Trees};
use crate::groundtruth;
use crate::penumbra;

/// Shading method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Baked BSPVT visibility × LTC GGX (paper 000).
    Bspvt,
    /// Unshadowed LTC GGX (no visibility).
    Ltc,
    /// Monte Carlo ground truth: exact GGX, shadow rays, MIS.
    Mc,
    /// LTC BRDF with visibility by many shadow rays (separates LTC-fit and visibility error).
    LtcExact,
    /// Paper 003: one hard shadow ray per pixel to the light's centroid, blurred by the
    /// similar-triangles penumbra width, × unshadowed per-pixel LTC.
    RtPenumbra,
    /// The same hard shadow ray, unblurred, × unshadowed per-pixel LTC.
    RtHard,
    /// Shadow map from the light, percentage-closer filtering (fixed kernel).
    Pcf,
    /// Variance shadow map (Chebyshev bound, light-bleeding reduction).
    Vsm,
    /// Percentage-closer soft shadows (blocker search, PCF of the penumbra width).
    Pcss,
    /// Paper 001: environment light as spherical Gaussians, visibility by a run-time SSDF
    /// (needs `--env`; `--lobes`, `--ssdf`).
    Sg,
    /// Monte Carlo ground truth under the environment map: exact GGX, shadow rays, MIS of map
    /// and BRDF sampling.
    McEnv,
}

impl Method {
    /// The penumbra technique of this method, if it is one.
    pub fn penumbra(self) -> Option<penumbra::Technique> {
        match self {
            Method::RtPenumbra => Some(penumbra::Technique::RtPenumbra),
            Method::RtHard => Some(penumbra::Technique::RtHard),
            Method::Pcf => Some(penumbra::Technique::Pcf),
            Method::Vsm => Some(penumbra::Technique::Vsm),
            Method::Pcss => Some(penumbra::Technique::Pcss),
            _ => None,
        }
    }

    /// True for the environment-light methods (no polygonal light involved).
    pub fn is_env(self) -> bool {
        matches!(self, Method::Sg | Method::McEnv)
    }
}

/// The environment light of [`Method::Sg`] and [`Method::McEnv`].
#[derive(Clone, Debug, Serialize)]
pub struct EnvOptions {
    /// Equirectangular map (Radiance `.hdr`).
    pub path: std::path::PathBuf,
    /// SG lobes fitted to the map.
    pub lobes: usize,
    pub sg: crate::sg::SgOptions,
}

#[derive(Clone, Debug, Serialize)]
pub struct Options {
    pub method: Method,
    pub mode: Mode,
    pub spp: u32,
    pub width: u32,
    pub height: u32,
    /// Frames along the light path (1: the light at rest).
    pub frames: usize,
    pub light: usize,
    /// Environment lighting (required by the env methods, ignored by the others).
    pub env: Option<EnvOptions>,
}

/// Timings and counters of a sequence (STATS.json of `bspvt render`).
#[derive(Clone, Debug, Serialize)]
pub struct Stats {
    pub method: Method,
    pub mode: Mode,
    pub width: u32,
    pub height: u32,
    pub frames: usize,
    pub threads: usize,
    /// Whole run: setup + all frames (excluding image writing).
    pub seconds: f64,
    /// Rasterising the G-buffer (once per camera).
    pub setup_seconds: f64,
    /// Median and mean shading time per frame.
    pub ms_per_frame: f64,
    pub ms_per_frame_mean: f64,
    pub fps: f64,
    /// Median frame time per vertex shaded (µs, wall clock on `threads` threads).
    pub us_per_vertex: f64,
    /// The same per core: `us_per_vertex × threads`.
    pub us_per_vertex_per_core: f64,
    pub vertices_shaded: usize,
    pub pixels_covered: usize,
    /// BSPVT pieces integrated (v̄ > 0) and dropped (v̄ = 0) per shaded vertex.
    pub pieces_per_vertex: f64,
    pub dropped_per_vertex: f64,
    pub spp: Option<u32>,
    /// Monte Carlo: mean relative standard error per covered pixel (last frame).
    pub mean_rel_stderr: Option<f64>,
    /// SG: the lobes, the fit's relative L2 error over the sphere and its time (in setup).
    pub sg_lobes: Option<usize>,
    pub sg_fit_error: Option<f64>,
    pub sg_fit_seconds: Option<f64>,
    pub ssdf: Option<crate::sg::SsdfMode>,
    /// SG: median depth-map time per frame (screen SSDF), ms.
    pub sg_maps_ms: Option<f64>,
    /// A moving scene (environment methods): median time per frame to pose the meshes,
    /// rasterise the G-buffer and rebuild the BVH when rays are used, ms (inside
    /// `ms_per_frame`).
    pub pose_ms: Option<f64>,
}

/// Renders `opts.frames` frames along the scene light's default path, handing each image to
/// `sink` (frame index, image). `trees` is required for [`Method::Bspvt`].
pub fn render_sequence(
    scene: &Scene,
    trees: Option<&Trees>,
    opts: &Options,
    mut sink: impl FnMut(usize, &Image) -> Result<()>,
) -> Result<Stats> {
    if opts.method.is_env() {
        return render_env_sequence(scene, opts, sink);
    }
    let Some(light) = scene.lights.get(opts.light) else {
        bail!("the scene has no light {}", opts.light);
    };
    if opts.method == Method::Bspvt && trees.is_none() {
        bail!("--method bspvt needs baked trees (--trees FILE)");
    }
    if scene.is_dynamic() {
        tracing::warn!(
            "the scene's meshes move, but --method {:?} renders them at t = 0 (motion is for \
             the run-time environment methods, sg and mc-env)",
            opts.method
        );
    }
    let start = Instant::now();
    let r = Renderer::new(scene, opts.width, opts.height);
    // Shadow rays for the references: one BVH per scene, built before the clock starts.
    let rays = matches!(opts.method, Method::Mc | Method::LtcExact)
        || opts.method.penumbra().is_some_and(|t| t.needs_rays());
    let occluder = rays.then(|| {
        let tris = bspvt_server::bake::raycast::mesh_triangles(&scene.mesh);
        bspvt_server::bake::raycast::Occluder::new(&scene.mesh, &tris)
    });
    let setup_seconds = start.elapsed().as_secs_f64();
    let mut noise = None;
    let rest = crate::light::Light::load(light)?;
    let path = LightPath::new(light, rest.clone());
    let frames = opts.frames.max(1);
    let mut ms = Vec::with_capacity(frames);
    let mut counts = FrameCounts::default();
    let mut shading_seconds = 0.0;
    for k in 0..frames {
        let l = if frames == 1 {
            rest.clone()
        } else {
            path.frame(k, frames)
        };
        let t = Instant::now();
        let (img, c) = match (opts.method, trees) {
            (Method::Bspvt, Some(trees)) => r.bspvt(&l, trees, opts.mode),
            (Method::Bspvt, None) => unreachable!("checked above"),
            (Method::Ltc, _) => r.ltc(&l, opts.mode),
            (Method::Mc, _) => {
                let occ = occluder.as_ref().context("occluder")?;
                let (img, report) =
                    groundtruth::render_mc(scene, &r.view, &r.gbuffer, &l, occ, opts.spp, k as u64);
                noise = Some(report.mean_rel_stderr);
                (img, FrameCounts::default())
            }
            (Method::LtcExact, _) => {
                let occ = occluder.as_ref().context("occluder")?;
                let img = groundtruth::ltcvis::render_ltc_exact_visibility(
                    scene,
                    &r.view,
                    &r.gbuffer,
                    &l,
                    occ,
                    &groundtruth::ltcvis::builtin_lookup,
                    opts.spp,
                    k as u64,
                );
                (img, FrameCounts::default())
            }
            (m, _) => {
                let technique = m
                    .penumbra()
                    .with_context(|| format!("{m:?}: not a shadow technique"))?;
                let img = penumbra::render(
                    &r,
                    &l,
                    technique,
                    occluder.as_ref(),
                    &penumbra::Params::default(),
                )?;
                (
                    img,
                    FrameCounts {
                        pixels_shaded: r.gbuffer.covered(),
                        ..FrameCounts::default()
                    },
                )
            }
        };
        let dt = t.elapsed().as_secs_f64();
        shading_seconds += dt;
        ms.push(dt * 1e3);
        counts = c;
        sink(k, &img)?;
    }
    let seconds = setup_seconds + shading_seconds;
    let mean = ms.iter().sum::<f64>() / ms.len() as f64;
    ms.sort_by(f64::total_cmp);
    let median = ms[ms.len() / 2];
    let threads = rayon::current_num_threads();
    let nv = counts.vertices_shaded.max(1) as f64;
    let us_per_vertex = if counts.vertices_shaded > 0 {
        median * 1e3 / nv
    } else {
        0.0
    };
    Ok(Stats {
        method: opts.method,
        // The penumbra methods shade per pixel whatever the mode.
        mode: if opts.method.penumbra().is_some() {
            Mode::Pixel
        } else {
            opts.mode
        },
        width: opts.width,
        height: opts.height,
        frames,
        threads,
        seconds,
        setup_seconds,
        ms_per_frame: median,
        ms_per_frame_mean: mean,
        fps: 1e3 / median.max(1e-9),
        us_per_vertex,
        us_per_vertex_per_core: us_per_vertex * threads as f64,
        vertices_shaded: counts.vertices_shaded,
        pixels_covered: r.gbuffer.covered(),
        pieces_per_vertex: counts.pieces as f64 / nv,
        dropped_per_vertex: counts.pieces_dropped as f64 / nv,
        spp: matches!(opts.method, Method::Mc | Method::LtcExact).then_some(opts.spp),
        mean_rel_stderr: noise,
        sg_lobes: None,
        sg_fit_error: None,
        sg_fit_seconds: None,
        ssdf: None,
        sg_maps_ms: None,
        pose_ms: None,
    })
}

/// [`render_sequence`] for the environment-light methods: the map is loaded (and fitted, for
/// SG, or read from the fit cache) in setup; the environment does not move, the scene's
/// meshes do when it has motion (frame k at cycle time k / frames).
fn render_env_sequence(
    scene: &Scene,
    opts: &Options,
    mut sink: impl FnMut(usize, &Image) -> Result<()>,
) -> Result<Stats> {
    let Some(eo) = &opts.env else {
        bail!(
            "--method {:?} needs an environment map (--env FILE.hdr)",
            opts.method
        );
    };
    let start = Instant::now();
    let env = crate::sg::EnvLight::load(&eo.path)?;
    let r = Renderer::new(scene, opts.width, opts.height);
    let rays = opts.method == Method::McEnv || eo.sg.ssdf == crate::sg::SsdfMode::Exact;
    // A moving scene is posed, rasterised and (for rays) given a new BVH inside every frame's
    // time; a static one gets its BVH here, once.
    let dynamic = scene.is_dynamic();
    let mut posed = dynamic.then(|| Posed::new(scene, 0.0, &r.view, rays));
    let occluder = (rays && !dynamic).then(|| {
        let tris = bspvt_server::bake::raycast::mesh_triangles(&scene.mesh);
        bspvt_server::bake::raycast::Occluder::new(&scene.mesh, &tris)
    });
    let sg = match opts.method {
        Method::Sg => Some(crate::sg::fit_cached(
            &env,
            eo.lobes,
            &std::env::temp_dir().join("bspvt-sg-fit"),
        )),
        _ => None,
    };
    crate::sg::halfspace::warm_up();
    let setup_seconds = start.elapsed().as_secs_f64();
    let frames = opts.frames.max(1);
    let (mut ms, mut maps_ms, mut pose_ms) = (
        Vec::with_capacity(frames),
        Vec::with_capacity(frames),
        Vec::with_capacity(frames),
    );
    let mut noise = None;
    for k in 0..frames {
        let t = Instant::now();
        let (sc, gbuffer, occ) = match posed.as_mut() {
            Some(p) => {
                p.update(scene, k as f32 / frames as f32, &r.view);
                pose_ms.push(t.elapsed().as_secs_f64() * 1e3);
                (&p.scene, &p.gbuffer, p.occluder.as_ref())
            }
            None => (scene, &r.gbuffer, occluder.as_ref()),
        };
        let img = match &sg {
            Some(sg) => {
                let (img, timings) = crate::sg::render(sc, &r.view, gbuffer, sg, occ, &eo.sg)?;
                maps_ms.push(timings.maps_ms);
                img
            }
            None => {
                let occ = occ.context("the Monte Carlo reference needs rays")?;
                let (img, report) =
                    groundtruth::render_mc_env(sc, &r.view, gbuffer, &env, occ, opts.spp, k as u64);
                noise = Some(report.mean_rel_stderr);
                img
            }
        };
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        sink(k, &img)?;
    }
    let seconds = setup_seconds + ms.iter().sum::<f64>() / 1e3;
    let mean = ms.iter().sum::<f64>() / ms.len() as f64;
    ms.sort_by(f64::total_cmp);
    maps_ms.sort_by(f64::total_cmp);
    pose_ms.sort_by(f64::total_cmp);
    let median = ms[ms.len() / 2];
    Ok(Stats {
        method: opts.method,
        mode: Mode::Pixel,
        width: opts.width,
        height: opts.height,
        frames,
        threads: rayon::current_num_threads(),
        seconds,
        setup_seconds,
        ms_per_frame: median,
        ms_per_frame_mean: mean,
        fps: 1e3 / median.max(1e-9),
        us_per_vertex: 0.0,
        us_per_vertex_per_core: 0.0,
        vertices_shaded: 0,
        pixels_covered: r.gbuffer.covered(),
        pieces_per_vertex: 0.0,
        dropped_per_vertex: 0.0,
        spp: (opts.method == Method::McEnv).then_some(opts.spp),
        mean_rel_stderr: noise,
        sg_lobes: sg.as_ref().map(|s| s.lobes.len()),
        sg_fit_error: sg.as_ref().map(|s| s.fit_error),
        sg_fit_seconds: sg.as_ref().map(|s| s.seconds),
        ssdf: sg.as_ref().map(|_| eo.sg.ssdf),
        sg_maps_ms: maps_ms.get(maps_ms.len() / 2).copied(),
        pose_ms: pose_ms.get(pose_ms.len() / 2).copied(),
    })
}
