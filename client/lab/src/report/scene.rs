//! One scene of the report: ground truth, bakes, every method timed and measured.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bspvt_proto::Scene;
use bspvt_proto::encoding::decode_bake;
use bspvt_raytrace::Occluder;
use serde::{Deserialize, Serialize};

use super::Settings;
use super::analysis::{self, Budget, EqualTime};
use super::grid::{Grid, Tile};
use crate::bench::{cached_bake, file_stem, median_ms};
use crate::compare::heatmap::{error_scale, heat_map};
use crate::compare::metrics::{
    Metrics, UmbraLeak, covered as covered_pixels, covered_mean, mean_image, umbra_leak,
    umbra_pixels,
};
use crate::compare::metrics::{measure as measure_metrics, rmse_mae};
use bspvt_client::frame::image::Image;
use bspvt_client::groundtruth::{Convergence, render_mc_until};
use bspvt_client::light::Light;
use bspvt_client::method::{FrameInput, SceneData, registry};
use bspvt_client::render::renderer::{Mode, Renderer, Trees};

/// Exposure of every PNG and of the display metrics (FLIP, share over 8 %).
pub(crate) const EXPOSURE: f32 = 1.0;

/// Samples per pixel of the stochastic methods shown in the image grid.
const GRID_SPP: u32 = 16;

/// Seeds: ground truth, the two LTC-with-exact-visibility estimates, the stochastic methods.
const SEED_GT: u64 = 0x6a7e_0001;
const SEED_EXACT_A: u64 = 0x6a7e_0002;
const SEED_EXACT_B: u64 = 0x6a7e_0003;
const SEED_STOCHASTIC: u64 = 0x6a7e_1000;

/// One method at one setting in one scene.
#[derive(Clone, Debug, Serialize)]
pub struct Entry {
    pub(crate) scene: String,
    /// `bspvt`, `ltc` (unshadowed), `ltc-exact`, `mc`, `ratio`, `ratio-denoised`,
    /// `rt-penumbra`, `rt-hard`, `pcf`, `vsm` or `pcss`.
    pub method: String,
    /// `vertex` or `pixel` (BSPVT and unshadowed LTC).
    pub(crate) mode: Option<Mode>,
    pub(crate) face_res: Option<u32>,
    pub(crate) epsilon: Option<f32>,
    /// Spherical Gaussians of the environment fit (the `sg-*` methods).
    pub(crate) lobes: Option<u32>,
    /// Pieces per cube-face side of the environment (`bspvt-env`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) pieces: Option<u32>,
    /// Samples (or shadow rays) per pixel.
    pub(crate) spp: Option<u32>,
    /// Median wall time of one frame on all threads (the G-buffer, made once per camera, and
    /// the trees' decoding, done once per stream, are not included).
    pub ms_per_frame: f64,
    pub metrics: Metrics,
    /// Light where the ground truth is in an umbra (`None`: the scene has none in view).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub umbra: Option<UmbraLeak>,
    /// The image and its error heat map, relative to the output folder.
    pub image: String,
    pub heat_map: String,
}

impl Entry {
    /// A short name of the method and setting: "bspvt 64² ε=1e-3 pixel", "mc 16 spp".
    pub fn label(&self) -> String {
        let mut s = self.method.clone();
        if let Some(r) = self.face_res {
            s += &format!(" {r}²");
        }
        if let Some(e) = self.epsilon {
            s += &format!(" ε={e:.0e}");
        }
        if let Some(m) = self.mode {
            s += match m {
                Mode::Vertex => " vertex",
                Mode::Pixel => " pixel",
            };
        }
        if let Some(k) = self.lobes {
            s += &format!(" K={k}");
        }
        if let Some(k) = self.pieces {
            s += &format!(" k={k}");
        }
        if let Some(n) = self.spp {
            s += &format!(" {n} spp");
        }
        s
    }

    /// A file name for the label.
    pub(super) fn slug(&self) -> String {
        self.label()
            .replace('²', "")
            .replace("ε=", "eps")
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
            .collect()
    }
}

/// The converged Monte Carlo reference.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GroundTruth {
    pub spp_mean: f64,
    pub(crate) spp_max: u64,
    pub(crate) mean_rel_stderr: f64,
    /// √(mean σ²) over covered pixels and channels: the reference's own RMSE, the floor under
    /// every method's measured RMSE.
    pub(crate) rmse_floor: f64,
    pub(crate) seconds: f64,
    pub(crate) threads: usize,
    #[serde(skip_deserializing)]
    pub from_cache: bool,
}

/// The cost of one bake (amortised precompute).
#[derive(Clone, Debug, Serialize)]
pub struct BakeCost {
    pub(crate) face_res: u32,
    pub(crate) epsilon: f32,
    pub(crate) vertices: usize,
    pub(crate) seconds: f64,
    pub(crate) threads: usize,
    /// Wall seconds × threads / vertices, in ms.
    pub(crate) ms_per_vertex_per_thread: f64,
    pub bytes: usize,
    pub(crate) bytes_per_vertex: f64,
    pub from_cache: bool,
}

/// The two LTC-with-exact-visibility estimates and their own noise.
#[derive(Clone, Debug, Serialize)]
pub struct ExactReference {
    /// Shadow rays per pixel in all (two estimates).
    pub(crate) spp: u32,
    /// RMSE and mean absolute error of their mean, from the difference of the two:
    /// RMSE(A, B) / 2 and MAE(A, B) / 2 (independent noise; see `analysis`).
    pub(crate) rmse_noise: f64,
    pub(crate) mae_noise: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct SceneReport {
    pub(crate) name: String,
    pub(crate) vertices: usize,
    pub(crate) triangles: usize,
    pub(crate) pixels_covered: usize,
    /// Mean unshadowed radiance (per-pixel LTC) over covered pixels: the unit of the budget.
    pub(crate) unshadowed_mean: f64,
    pub ground_truth: GroundTruth,
    pub exact: ExactReference,
    pub bakes: Vec<BakeCost>,
    pub entries: Vec<Entry>,
    pub equal_time: Vec<EqualTime>,
    pub budget: Vec<Budget>,
    /// Environment lighting (paper 001) against its own ground truth; `None` without a map.
    pub env: Option<super::env::EnvReport>,
    /// The image grid and plots, relative to the output folder.
    pub grid: String,
    pub plots: Vec<String>,
}

/// Measures every method on `scene`; images go to `out/<scene>/`.
pub(crate) fn measure(
    name: &str,
    scene: &Scene,
    st: &Settings,
    cache: &Path,
    out: &Path,
) -> Result<SceneReport> {
    // Every method and the ground truth are lit by all of the scene's lights.
    let lights: Vec<Light> = bspvt_client::light::scene_lights(scene)?
        .into_iter()
        .map(|l| l.0)
        .collect();
    if lights.is_empty() {
        bail!("{name}: the scene has no light");
    }
    let stem = file_stem(name);
    let dir = out.join(&stem);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let r = Renderer::new(scene, st.size, st.size);
    let covered = covered_pixels(&r.gbuffer);
    let occ = Occluder::of_surfaces(&scene.mesh, &scene.materials);
    // Every method draws through the registry's interface, on one shared BVH.
    let data = SceneData::new(scene);
    let draw = Draw {
        data: &data,
        r: &r,
        lights: &lights,
        frames: st.frames,
    };

    let (gt_img, gt) = ground_truth(name, scene, &r, &lights, &occ, st, cache)?;
    gt_img.save(&dir.join("ground-truth.png"), EXPOSURE)?;
    gt_img.save(&dir.join("ground-truth.exr"), EXPOSURE)?;
    let scale = error_scale(&gt_img, &covered);
    let mut grid = Grid::new(st.size);
    grid.push(Tile::new("ground truth", gt_img.to_srgb8(EXPOSURE), None));

    // The umbrae: where the ground truth is below 2 % of the unshadowed light.
    let (lit, _) = r.ltc(&lights, Mode::Pixel);
    let umbra = umbra_pixels(&gt_img, &lit, &covered);
    let mut entries: Vec<Entry> = Vec::new();
    let mut record = |mut e: Entry, img: &Image| -> Result<()> {
        e.umbra = umbra_leak(img, &lit, &umbra);
        let (e, map) = finish_entry(e, img, &gt_img, &covered, scale, out, &stem)?;
        if in_grid(&e, st) {
            grid.push(Tile::new(&e.label(), img.to_srgb8(EXPOSURE), Some(map)));
        }
        entries.push(e);
        Ok(())
    };
    let entry = |method: &str, ms: f64| Entry {
        scene: name.to_string(),
        method: method.to_string(),
        mode: None,
        face_res: None,
        epsilon: None,
        lobes: None,
        pieces: None,
        spp: None,
        ms_per_frame: ms,
        metrics: Metrics::default(),
        umbra: None,
        image: String::new(),
        heat_map: String::new(),
    };

    // Unshadowed LTC: the cost floor of every analytic method, and the budget's unit.
    let mut unshadowed_pixel = None;
    for mode in [Mode::Vertex, Mode::Pixel] {
        let (ms, img) = draw.timed("ltc", &draw.settings(1), None, None, 0, mode)?;
        record(
            Entry {
                mode: Some(mode),
                ..entry("ltc", ms)
            },
            &img,
        )?;
        if mode == Mode::Pixel {
            unshadowed_pixel = Some(img);
        }
    }
    let unshadowed = unshadowed_pixel.context("unshadowed image")?;
    let unshadowed_mean = covered_mean(&unshadowed, &covered);

    // LTC × ray-traced visibility: two independent estimates, their mean is the reference of
    // the visibility error.
    let t = Instant::now();
    let exact_settings = draw.settings(st.exact_spp);
    let exact_a = draw.once("ltc-exact", &exact_settings, SEED_EXACT_A)?;
    let exact_b = draw.once("ltc-exact", &exact_settings, SEED_EXACT_B)?;
    let exact_ms = t.elapsed().as_secs_f64() * 1e3;
    let (rmse_ab, mae_ab) = rmse_mae(&exact_a, &exact_b, &covered);
    let exact_ref = mean_image(&exact_a, &exact_b);
    let exact_info = ExactReference {
        spp: 2 * st.exact_spp,
        rmse_noise: rmse_ab / 2.0,
        mae_noise: mae_ab / 2.0,
    };
    record(
        Entry {
            spp: Some(2 * st.exact_spp),
            ..entry("ltc-exact", exact_ms)
        },
        &exact_ref,
    )?;

    // BSPVT at every bake setting, both modes.
    let mut bakes = Vec::new();
    let mut budget = Vec::new();
    for &(face_res, epsilon) in &st.bakes {
        let mut s = scene.clone();
        s.bake.face_res = face_res;
        s.bake.epsilon = epsilon;
        let b = cached_bake(name, &s, &cache.join("bakes"), &|_, _| {})?;
        let bytes =
            std::fs::read(&b.path).with_context(|| format!("cannot read {}", b.path.display()))?;
        let decoded = decode_bake(&bytes).with_context(|| format!("{}", b.path.display()))?;
        let trees = Trees::full(&decoded.trees, decoded.header.codec());
        // The suns' trees, where the scene bakes them apart (Scene::suns_in_sky_bake).
        let sky = match s.suns_in_sky_bake() {
            true => {
                let c = cached_bake(name, &s.sky(), &cache.join("bakes"), &|_, _| {})?;
                let bytes = std::fs::read(&c.path)
                    .with_context(|| format!("cannot read {}", c.path.display()))?;
                Some(decode_bake(&bytes).with_context(|| format!("{}", c.path.display()))?)
            }
            false => None,
        };
        let sky = sky
            .as_ref()
            .map(|d| Trees::full(&d.trees, d.header.codec()));
        let v = b.vertices.max(1) as f64;
        bakes.push(BakeCost {
            face_res,
            epsilon,
            vertices: b.vertices,
            seconds: b.seconds,
            threads: b.threads,
            ms_per_vertex_per_thread: b.seconds * 1e3 * b.threads as f64 / v,
            bytes: b.bytes,
            bytes_per_vertex: b.bytes as f64 / v,
            from_cache: b.from_cache,
        });
        for mode in [Mode::Vertex, Mode::Pixel] {
            let (ms, img) = draw.timed(
                "bspvt",
                &draw.settings(1),
                Some(&trees),
                sky.as_ref(),
                0,
                mode,
            )?;
            budget.push(analysis::budget(
                face_res,
                epsilon,
                mode,
                unshadowed_mean,
                rmse_mae(&img, &exact_ref, &covered).1,
                rmse_mae(&exact_ref, &gt_img, &covered).1,
                rmse_mae(&img, &gt_img, &covered).1,
                exact_info.mae_noise,
            ));
            record(
                Entry {
                    mode: Some(mode),
                    face_res: Some(face_res),
                    epsilon: Some(epsilon),
                    ..entry("bspvt", ms)
                },
                &img,
            )?;
        }
    }

    // Stochastic shadows at every sample count.
    for (k, &spp) in st.spp.iter().enumerate() {
        let seed = SEED_STOCHASTIC + 16 * k as u64;
        let mut settings = draw.settings(spp);
        settings.denoise_radius = st.denoise_radius;
        let (ms, img) = draw.timed("mc", &settings, None, None, seed, Mode::Pixel)?;
        record(
            Entry {
                spp: Some(spp),
                ..entry("mc", ms)
            },
            &img,
        )?;
        for method in ["ratio", "ratio-denoised"] {
            let (ms, img) = draw.timed(method, &settings, None, None, seed + 1, Mode::Pixel)?;
            record(
                Entry {
                    spp: Some(spp),
                    ..entry(method, ms)
                },
                &img,
            )?;
        }
    }

    // The point-light methods (paper 003 and the shadow-map baselines) against the area
    // light's ground truth: the light they stand in for.
    for method in ["rt-penumbra", "rt-hard", "pcf", "vsm", "pcss"] {
        let (ms, img) = draw.timed(method, &draw.settings(1), None, None, 0, Mode::Pixel)?;
        record(entry(method, ms), &img)?;
    }

    let env = match &st.env_map {
        Some(map) => Some(super::env::measure_env(
            name, scene, &r, &occ, &covered, map, st, cache, out,
        )?),
        None => None,
    };

    let grid_file = format!("{stem}/grid.png");
    grid.save(&out.join(&grid_file))?;
    let equal_time = analysis::equal_time(&entries);
    Ok(SceneReport {
        name: name.to_string(),
        vertices: scene.mesh.vertex_count(),
        triangles: scene.mesh.triangles.len(),
        pixels_covered: covered.iter().filter(|&&c| c).count(),
        unshadowed_mean,
        ground_truth: gt,
        exact: exact_info,
        bakes,
        entries,
        equal_time,
        budget,
        env,
        grid: grid_file,
        plots: Vec::new(),
    })
}

/// Measures `img` against `reference`, writes it and its heat map to `out/<folder>/`, names
/// both in the entry and prints its line; returns the heat map too (for the grid).
pub(super) fn finish_entry(
    mut e: Entry,
    img: &Image,
    reference: &Image,
    covered: &[bool],
    scale: f32,
    out: &Path,
    folder: &str,
) -> Result<(Entry, image::RgbImage)> {
    e.metrics = measure_metrics(img, reference, covered, EXPOSURE);
    let slug = e.slug();
    e.image = format!("{folder}/{slug}.png");
    e.heat_map = format!("{folder}/{slug}-error.png");
    img.save(&out.join(&e.image), EXPOSURE)?;
    let map = heat_map(img, reference, covered, scale);
    map.save(out.join(&e.heat_map))
        .with_context(|| format!("cannot write {}", e.heat_map))?;
    eprintln!(
        "  {:<32} {:>9.2} ms  RMSE {:.5}  FLIP {:.4}",
        e.label(),
        e.ms_per_frame,
        e.metrics.rmse,
        e.metrics.flip
    );
    Ok((e, map))
}

/// The grid shows the default bake, unshadowed LTC per pixel, LTC with exact visibility, the
/// stochastic methods at [`GRID_SPP`] and the point-light methods.
fn in_grid(e: &Entry, st: &Settings) -> bool {
    let (res, eps) = st.budget_bake();
    match e.method.as_str() {
        "bspvt" => e.face_res == Some(res) && e.epsilon == Some(eps),
        "ltc" => e.mode == Some(Mode::Pixel),
        "mc" | "ratio" | "ratio-denoised" => e.spp == Some(GRID_SPP),
        "rt-hard" | "pcf" => false,
        _ => true,
    }
}

/// Median time of `frames` renders after one warm-up render; a method whose one render takes
/// over a second is timed once (Monte Carlo at high sample counts).
fn timed(frames: usize, mut f: impl FnMut() -> Result<Image>) -> Result<(f64, Image)> {
    let (ms, img) = median_ms(1, &mut f)?;
    if frames <= 1 || ms > 1000.0 {
        return Ok((ms, img));
    }
    median_ms(frames, f)
}

/// The Monte Carlo ground truth, from the cache when the scene, view and settings match.
fn ground_truth(
    name: &str,
    scene: &Scene,
    r: &Renderer,
    lights: &[Light],
    occ: &Occluder,
    st: &Settings,
    cache: &Path,
) -> Result<(Image, GroundTruth)> {
    let conv = Convergence {
        target_rel_stderr: st.gt_target_rel_stderr,
        min_spp: st.gt_min_spp,
        max_spp: st.gt_max_spp,
    };
    let mut h = bspvt_proto::hash::Fnv1a::default();
    h.write(
        format!(
            "gt2 {:x} {:x} {:?} {:?} {:?} {} {:?} {SEED_GT}",
            scene.mesh.content_hash(),
            bspvt_client::method::trees::cutout_hash(scene),
            scene.lights,
            scene.materials,
            scene.camera,
            st.size,
            conv
        )
        .as_bytes(),
    );
    let base = cache
        .join("ground-truth")
        .join(format!("{}-{:016x}", file_stem(name), h.finish()));
    let (exr, meta) = (base.with_extension("exr"), base.with_extension("json"));
    if let (Ok(img), Ok(text)) = (load_exr(&exr), std::fs::read_to_string(&meta))
        && let Ok(mut gt) = serde_json::from_str::<GroundTruth>(&text)
        && img.width == st.size
        && img.height == st.size
    {
        gt.from_cache = true;
        eprintln!("  ground truth from {}", exr.display());
        return Ok((img, gt));
    }
    eprintln!(
        "  ground truth: Monte Carlo to {:.2} % relative error ({}–{} spp) …",
        100.0 * conv.target_rel_stderr,
        conv.min_spp,
        conv.max_spp
    );
    let t = Instant::now();
    let (img, noise) = render_mc_until(scene, &r.view, &r.gbuffer, lights, occ, &conv, SEED_GT);
    let seconds = t.elapsed().as_secs_f64();
    let covered = covered_pixels(&r.gbuffer);
    let gt = GroundTruth {
        spp_mean: noise.spp_mean,
        spp_max: noise.spp_max,
        mean_rel_stderr: noise.mean_rel_stderr,
        rmse_floor: crate::compare::metrics::rmse_floor(&noise.stderr, &covered),
        seconds,
        threads: rayon::current_num_threads(),
        from_cache: false,
    };
    eprintln!("  ground truth in {seconds:.1} s: {noise}");
    img.save(&exr, 1.0)?;
    std::fs::write(&meta, serde_json::to_string_pretty(&gt)?)
        .with_context(|| format!("cannot write {}", meta.display()))?;
    Ok((img, gt))
}

pub(super) fn load_exr(path: &Path) -> Result<Image> {
    let img = image::open(path)
        .with_context(|| format!("cannot read {}", path.display()))?
        .into_rgb32f();
    let (width, height) = img.dimensions();
    let pixels = img.pixels().map(|p| p.0).collect();
    Ok(Image {
        width,
        height,
        pixels,
    })
}

/// Frames of registered methods on the report's camera and light.
struct Draw<'a> {
    data: &'a SceneData<'a>,
    r: &'a Renderer<'a>,
    lights: &'a [Light],
    frames: usize,
}

impl Draw<'_> {
    /// The methods' settings with `spp` samples per pixel (defaults otherwise).
    fn settings(&self, spp: u32) -> bspvt_client::method::Settings {
        bspvt_client::method::Settings {
            spp,
            ..bspvt_client::method::Settings::default()
        }
    }

    /// One frame of method `name` (prepared first), with seed `index`, per pixel.
    fn once(
        &self,
        name: &str,
        settings: &bspvt_client::method::Settings,
        index: u64,
    ) -> Result<Image> {
        Ok(self
            .timed_n(name, settings, (None, None), index, Mode::Pixel, 1)?
            .1)
    }

    /// The median time of `self.frames` frames of method `name` and the last image; the
    /// preparation (BVH, …) is not timed.
    fn timed(
        &self,
        name: &str,
        settings: &bspvt_client::method::Settings,
        trees: Option<&Trees>,
        sky: Option<&Trees>,
        index: u64,
        mode: Mode,
    ) -> Result<(f64, Image)> {
        self.timed_n(name, settings, (trees, sky), index, mode, self.frames)
    }

    fn timed_n(
        &self,
        name: &str,
        settings: &bspvt_client::method::Settings,
        (trees, sky): (Option<&Trees>, Option<&Trees>),
        index: u64,
        mode: Mode,
        frames: usize,
    ) -> Result<(f64, Image)> {
        let mut state = registry::lookup(name)?.prepare(self.data, settings)?;
        let input = FrameInput {
            scene: self.data,
            renderer: self.r,
            lights: self.lights,
            trees,
            sky_trees: sky,
            env_rotation_deg: 0.0,
            index,
            time: 0.0,
            mode,
            on_gpu: false,
        };
        timed(frames, || state.frame(&input).map(|f| f.image))
    }
}
