//! A frame sequence while the light moves (or a moving scene plays), timed: what
//! `bspvt render`, the benchmarks and the tests share. Setup (the camera's G-buffer, the
//! method's [`FrameMethod::prepare`]) is timed apart from the frames.

use std::time::Instant;

use anyhow::{Result, bail};
use bspvt_proto::Scene;
use serde::Serialize;

use super::{FrameInput, FrameMethod, SceneData, Settings};
use crate::frame::image::Image;
use crate::frame::stats::median;
use crate::light::{Light, light_count, scene_lights};
use crate::render::path::LightPath;
use crate::render::renderer::{FrameCounts, Mode, Renderer, Trees};

/// A sequence to render.
#[derive(Clone, Debug, Serialize)]
pub struct Options {
    /// The method (from [`super::registry`]).
    #[serde(serialize_with = "super::serialize_name")]
    pub method: &'static dyn FrameMethod,
    /// Image size.
    pub width: u32,
    /// See `width`.
    pub height: u32,
    /// Frames along the light path (1: the light at rest); for a moving scene with an
    /// environment method, frame k is at cycle time k / frames.
    pub frames: usize,
    /// Only this scene light (`--light K`; `None`: every light, each on its own path).
    pub light: Option<usize>,
    /// Turns the environment by this many degrees about +y per frame (the sky methods that
    /// turn it at run time: `bspvt-env`).
    pub env_spin_deg: f64,
    /// What the method reads (mode, samples, environment).
    #[serde(skip)]
    pub settings: Settings,
}

/// Timings and counters of a sequence (STATS.json of `bspvt render`).
#[derive(Clone, Debug, Serialize)]
pub struct Stats {
    /// The method's name.
    #[serde(serialize_with = "super::serialize_name")]
    pub method: &'static dyn FrameMethod,
    /// Where it shaded.
    pub mode: Mode,
    /// Image size.
    pub width: u32,
    /// See `width`.
    pub height: u32,
    /// Frames drawn.
    pub frames: usize,
    /// Worker threads.
    pub threads: usize,
    /// Whole run: setup + all frames (excluding image writing).
    pub seconds: f64,
    /// Rasterising the G-buffer (once per camera) and preparing the method.
    pub setup_seconds: f64,
    /// Median shading time per frame.
    pub ms_per_frame: f64,
    /// Mean shading time per frame.
    pub ms_per_frame_mean: f64,
    /// 1000 / `ms_per_frame`.
    pub fps: f64,
    /// Median frame time per vertex shaded (µs, wall clock on `threads` threads).
    pub us_per_vertex: f64,
    /// The same per core: `us_per_vertex × threads`.
    pub us_per_vertex_per_core: f64,
    /// Vertices shaded in the last frame.
    pub vertices_shaded: usize,
    /// Pixels the scene covers.
    pub pixels_covered: usize,
    /// BSPVT pieces integrated (v̄ > 0) per shaded vertex.
    pub pieces_per_vertex: f64,
    /// BSPVT pieces dropped (v̄ = 0) per shaded vertex.
    pub dropped_per_vertex: f64,
    /// Samples per pixel of the stochastic methods.
    pub spp: Option<u32>,
    /// Monte Carlo: mean relative standard error per covered pixel (last frame).
    pub mean_rel_stderr: Option<f64>,
    /// SG: the lobes.
    pub sg_lobes: Option<usize>,
    /// SG: the fit's relative L2 error over the sphere.
    pub sg_fit_error: Option<f64>,
    /// SG: the fit's time (in setup).
    pub sg_fit_seconds: Option<f64>,
    /// SG: how visibility was found.
    pub ssdf: Option<crate::sg::SsdfMode>,
    /// SG: median depth-map time per frame (screen SSDF), ms.
    pub sg_maps_ms: Option<f64>,
    /// A moving scene (environment methods): median time per frame to pose the meshes,
    /// rasterise the G-buffer and rebuild the BVH when rays are used, ms (inside
    /// `ms_per_frame`).
    pub pose_ms: Option<f64>,
}

/// Renders `opts.frames` frames, handing each image to `sink` (frame index, image).
/// `trees`: the scene's bake, for methods that need trees (see [`super::trees`] to get one).
pub fn render_sequence(
    scene: &Scene,
    trees: Option<&Trees>,
    sky_trees: Option<&Trees>,
    opts: &Options,
    mut sink: impl FnMut(usize, &Image) -> Result<()>,
) -> Result<Stats> {
    let method = opts.method;
    let needs = method.needs();
    if needs.sky_trees_for(scene) && sky_trees.is_none() {
        bail!("--method {} needs the sky's baked trees", method.name());
    }
    // Polygon-light methods follow the light's path, and so do the lamps a sky method draws
    // beside the sky; the environment methods play the scene's motion (frame k at cycle time
    // k / frames).
    // The point-light methods shade the scene's punctual lights as points where it has any
    // (`penumbra::render_punctual`), else each polygon light from its centroid.
    let punctual_only = needs.punctual && !scene.punctual.is_empty() && scene.lights.is_empty();
    // The environment methods draw the lamps beside the sky (`sg` ignores them).
    let lamp = (needs.polygon_light && !punctual_only)
        || ((needs.sky_trees || needs.env_map) && light_count(scene) > 0);
    let lights: Vec<(LightPath, Light)> = if lamp {
        let all = scene_lights(scene)?;
        let chosen: Vec<usize> = match opts.light {
            Some(k) if k >= all.len() => {
                bail!(
                    "--light {k}: the scene has {} light(s) (0 to {})",
                    all.len(),
                    all.len().saturating_sub(1)
                )
            }
            Some(k) => vec![k],
            None => (0..all.len()).collect(),
        };
        if chosen.is_empty() {
            bail!("the scene has no light (no lamp, no punctual light, no sun)");
        }
        if needs.lamp_trees(scene) && trees.is_none() {
            bail!("--method {} needs baked trees", method.name());
        }
        if scene.is_dynamic() && !needs.env_map {
            tracing::warn!(
                "the scene's meshes move, but --method {} renders them at t = 0 (motion is \
                 for the run-time environment methods, sg and mc-env)",
                method.name()
            );
        }
        let away = scene.lights_facing_away();
        let mut out = Vec::with_capacity(chosen.len());
        for k in chosen {
            if away.contains(&k) {
                tracing::warn!(
                    "light {k} faces away from every vertex of the scene: it lights nothing \
                     (wind its vertices the other way round, or make it two_sided)"
                );
            }
            let (rest, motion) = all[k].clone();
            out.push((LightPath::new(motion, rest.clone()), rest));
        }
        out
    } else {
        Vec::new()
    };
    let start = Instant::now();
    let r = Renderer::new(scene, opts.width, opts.height);
    let data = SceneData::new(scene);
    let mut state = method.prepare(&data, &opts.settings)?;
    let setup_seconds = start.elapsed().as_secs_f64();
    let frames = opts.frames.max(1);
    let (mut ms, mut maps_ms, mut pose_ms) = (Vec::new(), Vec::new(), Vec::new());
    let mut counts = FrameCounts::default();
    let mut noise = None;
    for k in 0..frames {
        let posed: Vec<Light> = lights
            .iter()
            .map(|(path, rest)| {
                if frames == 1 {
                    rest.clone()
                } else {
                    path.frame(k, frames)
                }
            })
            .collect();
        let t = Instant::now();
        let f = state.frame(&FrameInput {
            scene: &data,
            renderer: &r,
            lights: &posed,
            trees,
            sky_trees,
            env_rotation_deg: opts.env_spin_deg * k as f64,
            index: k as u64,
            time: k as f32 / frames as f32,
            mode: opts.settings.mode,
            on_gpu: false,
        })?;
        let mut image = f.image;
        r.draw_emitters(&mut image, &posed);
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        maps_ms.extend(f.maps_ms);
        pose_ms.extend(f.pose_ms);
        noise = f.noise.or(noise);
        counts = f.counts;
        sink(k, &image)?;
    }
    let seconds = setup_seconds + ms.iter().sum::<f64>() / 1e3;
    let mean = ms.iter().sum::<f64>() / ms.len() as f64;
    let median_ms = median(&mut ms);
    let threads = rayon::current_num_threads();
    let nv = counts.vertices_shaded.max(1) as f64;
    let us_per_vertex = if counts.vertices_shaded > 0 {
        median_ms * 1e3 / nv
    } else {
        0.0
    };
    let report = state.report();
    Ok(Stats {
        method,
        mode: method.fixed_mode().unwrap_or(opts.settings.mode),
        width: opts.width,
        height: opts.height,
        frames,
        threads,
        seconds,
        setup_seconds,
        ms_per_frame: median_ms,
        ms_per_frame_mean: mean,
        fps: 1e3 / median_ms.max(1e-9),
        us_per_vertex,
        us_per_vertex_per_core: us_per_vertex * threads as f64,
        vertices_shaded: counts.vertices_shaded,
        pixels_covered: r.gbuffer.covered(),
        pieces_per_vertex: counts.pieces as f64 / nv,
        dropped_per_vertex: counts.pieces_dropped as f64 / nv,
        spp: report.spp,
        mean_rel_stderr: noise,
        sg_lobes: report.sg_lobes,
        sg_fit_error: report.sg_fit_error,
        sg_fit_seconds: report.sg_fit_seconds,
        ssdf: report.ssdf,
        sg_maps_ms: (!maps_ms.is_empty()).then(|| median(&mut maps_ms)),
        pose_ms: (!pose_ms.is_empty()).then(|| median(&mut pose_ms)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::EnvOptions;

    fn dynamic() -> Scene {
        bspvt_proto::builtin::scene("dynamic").expect("built-in dynamic scene")
    }

    /// SG and its Monte Carlo reference on a moving scene: every frame is posed (the frame at
    /// t = ½ is the static render of the scene posed at ½), the frames differ, and the pose's
    /// time is reported.
    #[test]
    fn env_methods_render_the_scene_as_it_moves() {
        let dir = tempfile::tempdir().expect("temp dir");
        let base = dynamic();
        let mut opts = Options {
            method: crate::method::registry::lookup("sg").expect("sg"),
            width: 48,
            height: 40,
            frames: 2,
            light: None,
            env_spin_deg: 0.0,
            settings: Settings {
                mode: Mode::Pixel,
                spp: 4,
                env: EnvOptions {
                    path: crate::envmap::write_test_map(dir.path()),
                    lobes: 4,
                    ..EnvOptions::default()
                },
                ..Settings::default()
            },
        };
        let mut frames: Vec<Image> = Vec::new();
        let stats = render_sequence(&base, None, None, &opts, |_, img| {
            frames.push(img.clone());
            Ok(())
        })
        .expect("sg sequence");
        assert_eq!(frames.len(), 2);
        assert!(stats.pose_ms.is_some_and(|ms| ms >= 0.0));
        assert!(frames[0].pixels != frames[1].pixels, "the scene moved");
        let mut still: Vec<Image> = Vec::new();
        opts.frames = 1;
        render_sequence(&base.at(0.5), None, None, &opts, |_, img| {
            still.push(img.clone());
            Ok(())
        })
        .expect("static sequence");
        assert!(
            still[0].pixels == frames[1].pixels,
            "the frame at t = ½ differs from the scene frozen at ½"
        );
        opts.method = crate::method::registry::lookup("mc-env").expect("mc-env");
        opts.frames = 2;
        let mut mc: Vec<Image> = Vec::new();
        let stats = render_sequence(&base, None, None, &opts, |_, img| {
            mc.push(img.clone());
            Ok(())
        })
        .expect("mc-env sequence");
        assert!(stats.pose_ms.is_some());
        assert!(
            mc.iter()
                .all(|i| i.pixels.iter().flatten().all(|c| c.is_finite()))
        );
        assert!(mc[1].mean() > 0.0);
    }
}
