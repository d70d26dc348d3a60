//! Environment lighting in the report (paper 001): spherical-Gaussian shading with the
//! screen-space SSDF, the exact (ray-cast) SSDF and no visibility, and Monte Carlo environment
//! lighting at a few samples per pixel, and the map as quad lights shadowed by the baked sky
//! trees (`bspvt-env`, for k pieces per cube-face side), all against their own ground truth — Monte Carlo with
//! the exact GGX BRDF under the same map, shadow rays, the map importance-sampled (cached).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use bspvt_proto::Scene;
use bspvt_raytrace::Occluder;
use serde::{Deserialize, Serialize};

use super::Settings;
use super::scene::{EXPOSURE, Entry, finish_entry, load_exr};
use crate::bench::{file_stem, median_ms};
use crate::compare::heatmap::error_scale;
use crate::compare::metrics::Metrics;
use bspvt_client::envmap::EnvLight;
use bspvt_client::frame::image::Image;
use bspvt_client::groundtruth::render_mc_env;
use bspvt_client::method::trees::cached_sky_bake;
use bspvt_client::render::renderer::Renderer;
use bspvt_client::render::renderer::{Mode, Trees};
use bspvt_client::render::sky_cells::CellTransfer;
use bspvt_client::sg::{self, SgOptions, SsdfMode};
use bspvt_client::sky::{DEFAULT_THRESHOLD, SkyPieces};
use bspvt_client::sky_cells::{DEFAULT_BANDS, SkyCells};

const SEED_GT: u64 = 0x5e6e_0001;
const SEED_MC: u64 = 0x5e6e_1000;

/// The environment section of one scene.
#[derive(Clone, Debug, Serialize)]
pub struct EnvReport {
    pub(crate) map: String,
    /// Ground truth: Monte Carlo spp, mean relative standard error, its own RMSE, seconds.
    pub(crate) gt_spp: u32,
    pub(crate) gt_mean_rel_stderr: f64,
    pub(crate) gt_rmse_floor: f64,
    pub(crate) gt_seconds: f64,
    pub(crate) gt_from_cache: bool,
    /// The ground truth is black on every covered pixel (a closed scene): nothing measured.
    pub dark: bool,
    /// Per lobe count: the fit's relative L2 error and its time (precompute per map).
    pub fits: Vec<(usize, f64, f64)>,
    pub entries: Vec<Entry>,
}

#[derive(Serialize, Deserialize)]
struct GtMeta {
    mean_rel_stderr: f64,
    rmse_floor: f64,
    seconds: f64,
}

/// Measures the environment-lit methods of `scene` under the map at `map`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn measure_env(
    name: &str,
    scene: &Scene,
    r: &Renderer,
    occ: &Occluder,
    covered: &[bool],
    map: &Path,
    st: &Settings,
    cache: &Path,
    out: &Path,
) -> Result<EnvReport> {
    let env = EnvLight::load(map)?;
    let stem = file_stem(name);
    let dir = out.join(&stem).join("env");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;

    // Ground truth, cached by scene, camera, map and settings.
    let mut h = bspvt_proto::hash::Fnv1a::default();
    h.write(
        format!(
            "env1 {:x} {:x} {:?} {:?} {} {} {} {SEED_GT}",
            scene.mesh.content_hash(),
            bspvt_client::method::trees::cutout_hash(scene),
            scene.materials,
            scene.camera,
            map.display(),
            st.size,
            st.env_gt_spp
        )
        .as_bytes(),
    );
    let base = cache
        .join("ground-truth")
        .join(format!("{stem}-env-{:016x}", h.finish()));
    let (exr, meta) = (base.with_extension("exr"), base.with_extension("json"));
    let cached = load_exr(&exr).ok().zip(
        std::fs::read_to_string(&meta)
            .ok()
            .and_then(|t| serde_json::from_str::<GtMeta>(&t).ok()),
    );
    let (gt, gm, from_cache) = match cached {
        Some((img, m)) if img.width == st.size && img.height == st.size => (img, m, true),
        _ => {
            eprintln!("  environment ground truth: {} spp …", st.env_gt_spp);
            let t = Instant::now();
            let (img, noise) = render_mc_env(
                scene,
                &r.view,
                &r.gbuffer,
                &env,
                occ,
                st.env_gt_spp,
                SEED_GT,
            );
            let m = GtMeta {
                mean_rel_stderr: noise.mean_rel_stderr,
                rmse_floor: crate::compare::metrics::rmse_floor(&noise.stderr, covered),
                seconds: t.elapsed().as_secs_f64(),
            };
            std::fs::create_dir_all(cache.join("ground-truth"))?;
            img.save(&exr, 1.0)?;
            std::fs::write(&meta, serde_json::to_string_pretty(&m)?)
                .with_context(|| format!("cannot write {}", meta.display()))?;
            (img, m, false)
        }
    };
    gt.save(&dir.join("ground-truth.png"), EXPOSURE)?;
    let report = |fits, entries, dark| EnvReport {
        map: map.display().to_string(),
        gt_spp: st.env_gt_spp,
        gt_mean_rel_stderr: gm.mean_rel_stderr,
        gt_rmse_floor: gm.rmse_floor,
        gt_seconds: gm.seconds,
        gt_from_cache: from_cache,
        dark,
        fits,
        entries,
    };
    // A closed scene (the room): no sample reached the map from any pixel the camera sees.
    // Every method's error would be measured against black, relative errors are undefined,
    // and the sky's bake (a minute for the room) would be spent on nothing.
    if !gt
        .pixels
        .iter()
        .zip(covered)
        .any(|(p, &c)| c && p.iter().any(|&v| v > 0.0))
    {
        eprintln!("  the environment lights none of the camera's pixels: methods not measured");
        return Ok(report(Vec::new(), Vec::new(), true));
    }
    let scale = error_scale(&gt, covered);

    let folder = format!("{stem}/env");
    let mut entries: Vec<Entry> = Vec::new();
    let mut record = |method: &str,
                      lobes: Option<u32>,
                      pieces: Option<u32>,
                      spp: Option<u32>,
                      ms: f64,
                      img: &Image| {
        let e = Entry {
            scene: name.to_string(),
            method: method.to_string(),
            mode: None,
            face_res: None,
            epsilon: None,
            lobes,
            pieces,
            spp,
            ms_per_frame: ms,
            metrics: Metrics::default(),
            umbra: None,
            image: String::new(),
            heat_map: String::new(),
        };
        entries.push(finish_entry(e, img, &gt, covered, scale, out, &folder)?.0);
        anyhow::Ok(())
    };

    let mut fits = Vec::new();
    for &k in &st.env_lobes {
        let t = Instant::now();
        let lobes = sg::fit(&env, k);
        fits.push((k, lobes.fit_error, t.elapsed().as_secs_f64()));
        let kk = Some(k as u32);
        for (method, ssdf) in [
            ("sg-screen", SsdfMode::Screen),
            ("sg-unshadowed", SsdfMode::None),
            ("sg-exact", SsdfMode::Exact),
        ] {
            // The exact SSDF is the slow reference: only at the smallest lobe count.
            if ssdf == SsdfMode::Exact && Some(&k) != st.env_lobes.first() {
                continue;
            }
            let opts = SgOptions {
                ssdf,
                ..SgOptions::default()
            };
            let frames = if ssdf == SsdfMode::Exact {
                1
            } else {
                st.frames
            };
            let (ms, (img, _)) = median_ms(frames, || {
                sg::render(scene, &r.view, &r.gbuffer, &lobes, Some(occ), &opts)
            })?;
            record(method, kk, None, None, ms, &img)?;
        }
    }
    for (i, &spp) in st.env_spp.iter().enumerate() {
        let seed = SEED_MC + i as u64;
        let (ms, img) = median_ms(if spp > 4 { 1 } else { st.frames }, || {
            Ok(render_mc_env(scene, &r.view, &r.gbuffer, &env, occ, spp, seed).0)
        })?;
        record("mc-env", None, None, Some(spp), ms, &img)?;
    }
    // The sky through the baked sky trees, per vertex, for each k (pieces per face side).
    let (_, sky_bake) = cached_sky_bake(scene, &cache.join("bakes"), &|_, _| {})?;
    let sky_trees = Trees::full(&sky_bake.trees, sky_bake.header.codec());
    for &k in &st.env_sky_pieces {
        let pieces = SkyPieces::new(&env, k, DEFAULT_THRESHOLD, 1.0)?.posed(0.0);
        for mode in [Mode::Vertex, Mode::Pixel] {
            let (ms, img) = median_ms(st.frames, || Ok(r.sky(&pieces, Some(&sky_trees), mode).0))?;
            let method = match mode {
                Mode::Vertex => "bspvt-env",
                Mode::Pixel => "bspvt-env-pixel",
            };
            record(method, None, Some(k), None, ms, &img)?;
        }
    }
    // The same sky in world-fixed cells, per vertex: the time of a frame of a turning map
    // (the cells' terms made by a first frame, outside the timing).
    let cells = SkyCells::new(&env, DEFAULT_BANDS, 1.0)?;
    let mut keep = CellTransfer::default();
    let (first, _) = r.sky_cells(&cells, &cells.radiance(0.0), Some(&sky_trees), &mut keep);
    let mut turn = 0.0;
    let (ms, _) = median_ms(st.frames, || {
        turn += 1.0;
        Ok(r.sky_cells(&cells, &cells.radiance(turn), Some(&sky_trees), &mut keep))
    })?;
    record("bspvt-env-cells", None, None, None, ms, &first)?;
    Ok(report(fits, entries, false))
}
