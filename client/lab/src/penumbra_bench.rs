//! `bspvt bench-penumbra`: speed and error of rt-penumbra (paper 003) and the shadow-map
//! baselines against Monte Carlo area-light shadows, in one run.
//!
//! Per scene and case (the scene as given, and variants that break the paper's assumptions):
//! - reference: `ltc-exact` (unshadowed LTC × Monte Carlo visibility of the area light) at
//!   `ref_spp`, twice with independent seeds; the reference is their mean (2 × `ref_spp`
//!   rays), and RMSE(A, B) / 2 estimates its own RMSE (independent noise of variance σ²
//!   each: Var(A − B) = 2σ², Var((A + B)/2) = σ²/2);
//! - rt-penumbra, rt-hard, pcf, vsm, pcss: median ms/frame over `frames` renders at the same
//!   light pose, RMSE and mean absolute error over covered pixels;
//! - `ltc-exact` at 1, 2, 4, …, 256 spp: ms/frame and RMSE, and the equal-RMSE speed-up of
//!   rt-penumbra, interpolated log-log between the two spp counts that bracket its RMSE.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use bspvt_proto::Scene;
use bspvt_raytrace::Occluder;
use glam::Vec3;
use serde::Serialize;

use crate::bench::{file_stem, load_named_scene, median_ms as timed, named_scene_path};
use crate::compare::heatmap::{error_scale, heat_map};
use crate::compare::metrics::{covered as covered_pixels, mean_image, rmse_mae as errors};
use bspvt_client::frame::image::Image;
use bspvt_client::gpu::Gpu;
use bspvt_client::gpu::shadow_rays::GpuShadowRays;
use bspvt_client::groundtruth::ltcvis::{builtin_lookup, render_ltc_exact_visibility};
use bspvt_client::light::Light;
use bspvt_client::penumbra::{self, Guide, Params, Technique};
use bspvt_client::render::renderer::Renderer;

/// `bspvt bench-penumbra`: rt-penumbra and the shadow-map baselines against Monte Carlo area-light shadows.
#[derive(clap::Args, Clone, Debug)]
pub struct BenchPenumbraArgs {
    /// Scenes: built-in names (plate-small, plate), mesh names in the assets folder (teapot,
    /// bunny, dragon → teapot.obj, bunny.ply, dragon_res4.ply), or paths to a mesh or scene
    /// JSON file.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "plate-small,plate,teapot,bunny"
    )]
    pub scenes: Vec<String>,
    /// Image width and height (default 512, 128 with --quick).
    #[arg(long)]
    pub size: Option<u32>,
    /// Fewer rays and frames: reference 128 spp, Monte Carlo up to 16 spp, 1 frame.
    #[arg(long)]
    pub quick: bool,
    /// Reference spp per estimate (default 1024, 128 with --quick).
    #[arg(long)]
    pub ref_spp: Option<u32>,
    /// Timed renders per method (median reported; default 3, 1 with --quick).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Only the scene as given (no assumption-breaking cases).
    #[arg(long)]
    pub base_only: bool,
    /// Folder holding the meshes (default: $BSPVT_ASSETS/meshes or ../shared/assets/meshes).
    #[arg(long)]
    pub meshes_dir: Option<PathBuf>,
    /// Output folder: results.csv/.md/.json and the images.
    #[arg(long, default_value = "out/bench-penumbra")]
    pub out: PathBuf,
    /// Also rt-penumbra and rt-hard on the GPU: rows `rt-penumbra-gpu` (the shadow rays and
    /// the blur there), `rt-penumbra-gpu-rays` (the rays there, the blur on the CPU) and
    /// `rt-hard-gpu`. The unshadowed shading stays on the CPU's G-buffer, as the reference's
    /// (`--backend gpu` shades it in the GPU's MSAA frames, whose anti-aliased edges the
    /// reference does not have). An error without an adapter; a software one (lavapipe) is
    /// used when it is the only one.
    #[arg(long)]
    pub gpu: bool,
}

/// The settings a run resolves from [`BenchPenumbraArgs`].
#[derive(Clone, Debug, Serialize)]
pub struct Settings {
    pub(crate) size: u32,
    pub(crate) ref_spp: u32,
    pub(crate) frames: usize,
    pub(crate) mc_spp: Vec<u32>,
}

impl Settings {
    pub(crate) fn from_args(a: &BenchPenumbraArgs) -> Result<Settings> {
        let size = a.size.unwrap_or(if a.quick { 128 } else { 512 });
        let ref_spp = a.ref_spp.unwrap_or(if a.quick { 128 } else { 1024 });
        let frames = a.frames.unwrap_or(if a.quick { 1 } else { 3 });
        if !(8..=8192).contains(&size) {
            bail!("--size {size}: expected 8 ..= 8192");
        }
        if ref_spp == 0 || frames == 0 {
            bail!("--ref-spp and --frames must be at least 1");
        }
        let top = if a.quick { 16 } else { 256 };
        let mc_spp = (0..).map(|k| 1u32 << k).take_while(|&n| n <= top).collect();
        Ok(Settings {
            size,
            ref_spp,
            frames,
            mc_spp,
        })
    }
}

/// One measured method in one scene/case.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub(crate) scene: String,
    pub(crate) case: String,
    /// `rt-penumbra`, `rt-hard`, `pcf`, `vsm`, `pcss`, `unshadowed` or `ltc-exact`
    /// (`rt-penumbra-gpu`, `rt-penumbra-gpu-rays`, `rt-hard-gpu` with `--gpu`).
    pub method: String,
    /// Shadow rays per pixel (`ltc-exact` only).
    pub(crate) spp: Option<u32>,
    /// Median frame time, ms.
    pub ms_per_frame: f64,
    /// RMSE against the reference over covered pixels.
    pub rmse: f64,
    /// Mean absolute error against the reference.
    pub mae: f64,
}

/// A method's time (rt-penumbra, its one-ray form or its GPU rows) against Monte Carlo
/// area-light shadows at equal RMSE.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum SpeedUp {
    /// MC time at rt-penumbra's RMSE (log-log interpolation) / rt-penumbra's time.
    Interpolated {
        /// The spp at which MC reaches rt-penumbra's RMSE.
        spp: f64,
        /// The speed-up.
        factor: f64,
    },
    /// MC never reaches rt-penumbra's RMSE within the largest spp: at least this factor.
    AtLeast {
        /// The largest spp measured.
        max_spp: u32,
        /// The speed-up's lower bound.
        factor: f64,
    },
    /// rt-penumbra is worse than 1 spp: MC at 1 spp / rt-penumbra's time is an upper bound.
    WorseThanOneSpp {
        /// MC's time at 1 spp over rt-penumbra's.
        factor: f64,
    },
}

impl SpeedUp {
    fn describe(&self) -> String {
        match self {
            SpeedUp::Interpolated { spp, factor } => {
                format!("{factor:.1}× (MC reaches its RMSE at ≈ {spp:.1} spp)")
            }
            SpeedUp::AtLeast { max_spp, factor } => {
                format!("> {factor:.1}× (MC never reaches its RMSE within {max_spp} spp)")
            }
            SpeedUp::WorseThanOneSpp { factor } => {
                format!("none: worse than 1 spp (MC at 1 spp / its time = {factor:.2}×)")
            }
        }
    }
}

/// The results of one scene/case.
#[derive(Clone, Debug, Serialize)]
pub struct CaseReport {
    pub(crate) scene: String,
    /// The case: `default`, or which assumption it breaks.
    pub case: String,
    /// Which of the paper's assumptions the case breaks (or "none").
    pub(crate) breaks: String,
    /// Pixels the scene covers.
    pub pixels_covered: usize,
    /// RMSE between the two reference estimates, and the reference's own RMSE (half of it).
    pub(crate) ref_rmse_between_seeds: f64,
    /// The reference's own RMSE (half the RMSE between its two estimates).
    pub ref_rmse: f64,
    /// One row per method (and Monte Carlo spp).
    pub rows: Vec<Row>,
    /// rt-penumbra's speed-up over Monte Carlo at equal RMSE.
    pub speed_up: SpeedUp,
    /// The same for paper 003 as published: one ray toward the light's centroid everywhere
    /// (row `rt-penumbra-point`, [`Params::split`] 1).
    pub speed_up_point: SpeedUp,
    /// The same with its rays and blur on the GPU (`--gpu`).
    pub speed_up_gpu: Option<SpeedUp>,
}

/// What `bspvt bench-penumbra` measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// The settings it ran with.
    pub settings: Settings,
    /// Worker threads.
    pub threads: usize,
    /// The GPU adapter of the `-gpu` rows (`--gpu`).
    pub adapter: Option<String>,
    /// Every scene and case.
    pub cases: Vec<CaseReport>,
    /// Scenes skipped (missing assets), with the reason.
    pub skipped: Vec<String>,
}

/// Runs the benchmark and writes results.csv, results.md, results.json and the images.
pub fn run(a: &BenchPenumbraArgs) -> Result<Report> {
    let settings = Settings::from_args(a)?;
    let meshes_dir = a
        .meshes_dir
        .clone()
        .unwrap_or_else(|| bspvt_proto::paths::assets_dir().join("meshes"));
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let gpu = if a.gpu {
        Some(Gpu::shared().context("bench-penumbra --gpu")?)
    } else {
        None
    };
    let mut report = Report {
        settings: settings.clone(),
        threads: rayon::current_num_threads(),
        adapter: gpu.map(|g| g.adapter.clone()),
        cases: Vec::new(),
        skipped: Vec::new(),
    };
    for name in a.scenes.iter().filter(|s| !s.is_empty()) {
        let Some(scene) = load_named_scene(name, &meshes_dir)? else {
            let msg = format!(
                "{name}: {} not found, skipped",
                named_scene_path(name, &meshes_dir).display()
            );
            eprintln!("bench-penumbra: {msg}");
            report.skipped.push(msg);
            continue;
        };
        for case in cases(name, &scene, a.base_only) {
            eprintln!("bench-penumbra: {name} / {} …", case.name);
            let c = measure_case(name, &case, &settings, gpu, &a.out)?;
            eprintln!("  rt-penumbra vs MC: {}", c.speed_up.describe());
            eprintln!(
                "  rt-penumbra-point (one ray per pixel) vs MC: {}",
                c.speed_up_point.describe()
            );
            if let Some(s) = &c.speed_up_gpu {
                eprintln!(
                    "  rt-penumbra on the GPU (rays and blur) vs MC: {}",
                    s.describe()
                );
            }
            report.cases.push(c);
        }
    }
    write_outputs(&report, &a.out)?;
    Ok(report)
}

/// A scene variant.
struct Case {
    name: String,
    breaks: String,
    scene: Scene,
}

/// The scene as given, and variants that break the paper's assumptions.
fn cases(name: &str, scene: &Scene, base_only: bool) -> Vec<Case> {
    let is_plate = name == "plate" || name == "plate-small";
    let breaks = match name {
        "plate-small" => "none",
        "plate" => "none (two occluders, sphere and slab, whose shadows barely meet)",
        _ => "non-planar receiver (the mesh shadows itself and the ground)",
    };
    let mut out = vec![Case {
        name: "base".into(),
        breaks: breaks.into(),
        scene: scene.clone(),
    }];
    if base_only {
        return out;
    }
    if is_plate {
        out.push(Case {
            name: "contact".into(),
            breaks: "occluder touching the receiver (sphere lowered onto the floor)".into(),
            scene: plate_contact(scene),
        });
        out.push(Case {
            name: "overlap".into(),
            breaks: "overlapping penumbrae of different widths (slab lowered into the sphere's penumbra)"
                .into(),
            scene: plate_overlap(scene),
        });
    }
    out.push(Case {
        name: "big-light".into(),
        breaks: "large light close to the occluder (light ×3, moved halfway down)".into(),
        scene: big_light(scene),
    });
    out
}

/// The plate sphere's centre and radius (`proto/src/builtin.rs`).
const SPHERE: (Vec3, f32) = (Vec3::new(-0.7, 0.9, 0.2), 0.5);
/// The plate slab's centre; its vertices lie within 0.7 of it (half-extents 0.55, 0.04, 0.4).
const SLAB: (Vec3, f32) = (Vec3::new(0.7, 1.3, -0.2), 0.7);

/// Moves the vertices within `radius` of `centre` by `by`.
fn move_part(scene: &Scene, (centre, radius): (Vec3, f32), by: Vec3) -> Scene {
    let mut s = scene.clone();
    for p in &mut s.mesh.positions {
        if (*p - centre).length() <= radius + 0.01 {
            *p += by;
        }
    }
    s
}

/// The sphere lowered by 0.4 so it rests on the floor (y = 0): contact, Z_r − Z_o → 0.
fn plate_contact(scene: &Scene) -> Scene {
    move_part(scene, SPHERE, Vec3::new(0.0, -0.4, 0.0))
}

/// The slab moved to (−0.5, 0.25, 0.7), under the sphere (its top ≤ 0.39 < the sphere's
/// bottom at 0.4): its sharp shadow overlaps the sphere's wide penumbra on the floor.
fn plate_overlap(scene: &Scene) -> Scene {
    move_part(scene, SLAB, Vec3::new(-0.5, 0.25, 0.7) - SLAB.0)
}

/// The light scaled ×3 about its centroid (radiance ÷ 9: the same power) and moved along its
/// normal halfway to the nearest scene point in front of it.
fn big_light(scene: &Scene) -> Scene {
    let mut s = scene.clone();
    let Some(l) = s.lights.first_mut() else {
        return s;
    };
    let n = l.normal();
    let c = l.vertices.iter().map(|v| Vec3::from(*v)).sum::<Vec3>() / l.vertices.len() as f32;
    let nearest = scene
        .mesh
        .positions
        .iter()
        .map(|p| n.dot(*p - c))
        .filter(|d| *d > 0.0)
        .fold(f32::INFINITY, f32::min);
    let shift = if nearest.is_finite() {
        n * 0.5 * nearest
    } else {
        Vec3::ZERO
    };
    for v in &mut l.vertices {
        *v = (c + (Vec3::from(*v) - c) * 3.0 + shift).to_array();
    }
    l.radiance = l.radiance.map(|r| r / 9.0);
    l.region = None;
    s
}

const METHODS: [(Technique, &str); 5] = [
    (Technique::RtPenumbra, "rt-penumbra"),
    (Technique::RtHard, "rt-hard"),
    (Technique::Pcf, "pcf"),
    (Technique::Vsm, "vsm"),
    (Technique::Pcss, "pcss"),
];

/// Seeds of the two reference estimates and of the Monte Carlo sweep (all distinct).
const SEED_A: u64 = 0x5eed_0001;
const SEED_B: u64 = 0x5eed_0002;
const SEED_MC: u64 = 0x5eed_1000;

fn measure_case(
    scene_name: &str,
    case: &Case,
    st: &Settings,
    gpu: Option<&'static Gpu>,
    out: &Path,
) -> Result<CaseReport> {
    let scene = &case.scene;
    let Some(pl) = scene.lights.first() else {
        bail!("{scene_name}: the scene has no light");
    };
    let light = Light::load(pl)?;
    let r = Renderer::new(scene, st.size, st.size);
    let occ = Occluder::of_surfaces(&scene.mesh, &scene.materials);
    let covered = covered_pixels(&r.gbuffer);
    let dir = out.join(format!("{}-{}", file_stem(scene_name), case.name));
    let ltc_exact = |spp: u32, seed: u64| {
        render_ltc_exact_visibility(
            scene,
            &r.view,
            &r.gbuffer,
            &light,
            &occ,
            &builtin_lookup,
            spp,
            seed,
        )
    };
    let ref_a = ltc_exact(st.ref_spp, SEED_A);
    let ref_b = ltc_exact(st.ref_spp, SEED_B);
    let ref_between = errors(&ref_a, &ref_b, &covered).0;
    let reference = mean_image(&ref_a, &ref_b);
    reference.save(&dir.join("reference.png"), 1.0)?;
    let scale = error_scale(&reference, &covered);
    let row = |method: &str, spp: Option<u32>, ms: f64, img: &Image| -> Result<Row> {
        let (rmse, mae) = errors(img, &reference, &covered);
        let stem = match spp {
            Some(n) => format!("{method}-{n:03}spp"),
            None => method.to_string(),
        };
        img.save(&dir.join(format!("{stem}.png")), 1.0)?;
        heat_map(img, &reference, &covered, scale)
            .save(dir.join(format!("{stem}-error.png")))
            .with_context(|| format!("cannot write the error map of {stem}"))?;
        Ok(Row {
            scene: scene_name.to_string(),
            case: case.name.clone(),
            method: method.to_string(),
            spp,
            ms_per_frame: ms,
            rmse,
            mae,
        })
    };
    let mut rows = Vec::new();
    let params = Params::default();
    // Per camera, like the G-buffer: outside the timed frames (the methods cache it).
    let guide = Guide::new(&r);
    for (t, name) in METHODS {
        let (ms, img) = timed(st.frames, || {
            penumbra::render(&r, &guide, &light, t, Some(&occ), &params)
        })?;
        rows.push(row(name, None, ms, &img)?);
    }
    // Paper 003 as published: the light's centroid as the point light for every pixel.
    let point = Params { split: 1, ..params };
    let (ms, img) = timed(st.frames, || {
        penumbra::render(
            &r,
            &guide,
            &light,
            Technique::RtPenumbra,
            Some(&occ),
            &point,
        )
    })?;
    rows.push(row("rt-penumbra-point", None, ms, &img)?);
    if let Some(g) = gpu {
        // The BVH's upload and the pipeline's compilation are setup, as the CPU's BVH build
        // is: outside the timed frames.
        let rays = GpuShadowRays::new(g, &occ, false)?;
        let all = GpuShadowRays::new(g, &occ, true)?;
        for (t, name, caster) in [
            (Technique::RtPenumbra, "rt-penumbra-gpu", &all),
            (Technique::RtPenumbra, "rt-penumbra-gpu-rays", &rays),
            (Technique::RtHard, "rt-hard-gpu", &rays),
        ] {
            let (ms, img) = timed(st.frames, || {
                penumbra::render(&r, &guide, &light, t, Some(caster), &params)
            })?;
            rows.push(row(name, None, ms, &img)?);
        }
    }
    let (ms, img) = timed(st.frames, || {
        Ok(r.shade_pixels(std::slice::from_ref(&light), None))
    })?;
    rows.push(row("unshadowed", None, ms, &img)?);
    for (k, &spp) in st.mc_spp.iter().enumerate() {
        let mut seed = SEED_MC + 100 * k as u64;
        let (ms, img) = timed(st.frames, || {
            seed += 1;
            Ok(ltc_exact(spp, seed))
        })?;
        rows.push(row("ltc-exact", Some(spp), ms, &img)?);
    }
    let speed_up = equal_rmse_speed_up(&rows, "rt-penumbra")?;
    let speed_up_point = equal_rmse_speed_up(&rows, "rt-penumbra-point")?;
    let speed_up_gpu = match gpu {
        Some(_) => Some(equal_rmse_speed_up(&rows, "rt-penumbra-gpu")?),
        None => None,
    };
    Ok(CaseReport {
        scene: scene_name.to_string(),
        case: case.name.clone(),
        breaks: case.breaks.clone(),
        pixels_covered: covered.iter().filter(|&&c| c).count(),
        ref_rmse_between_seeds: ref_between,
        ref_rmse: ref_between / 2.0,
        rows,
        speed_up,
        speed_up_point,
        speed_up_gpu,
    })
}

/// Equal-RMSE speed-up of `method`'s row (rt-penumbra) over MC (`ltc-exact` rows, increasing
/// spp): with e the rt-penumbra RMSE and (e_i, t_i), (e_j, t_j) the MC points bracketing it,
/// log t = log t_i + (log e − log e_i) / (log e_j − log e_i) · (log t_j − log t_i)
/// (and the same for spp); factor = t / t_rt.
pub(crate) fn equal_rmse_speed_up(rows: &[Row], method: &str) -> Result<SpeedUp> {
    let rt = rows
        .iter()
        .find(|r| r.method == method)
        .with_context(|| format!("no {method} row"))?;
    let mc: Vec<&Row> = rows.iter().filter(|r| r.method == "ltc-exact").collect();
    let (Some(first), Some(last)) = (mc.first(), mc.last()) else {
        bail!("no Monte Carlo rows");
    };
    let t_rt = rt.ms_per_frame.max(1e-9);
    let e = rt.rmse;
    if e > first.rmse {
        return Ok(SpeedUp::WorseThanOneSpp {
            factor: first.ms_per_frame / t_rt,
        });
    }
    for w in mc.windows(2) {
        let (a, b) = (w[0], w[1]);
        if a.rmse >= e && e >= b.rmse {
            let f = log_fraction(e, a.rmse, b.rmse);
            let lerp = |x: f64, y: f64| (x.ln() + f * (y.ln() - x.ln())).exp();
            let t = lerp(a.ms_per_frame.max(1e-9), b.ms_per_frame.max(1e-9));
            let spp = lerp(f64::from(a.spp.unwrap_or(1)), f64::from(b.spp.unwrap_or(1)));
            return Ok(SpeedUp::Interpolated {
                spp,
                factor: t / t_rt,
            });
        }
    }
    Ok(SpeedUp::AtLeast {
        max_spp: last.spp.unwrap_or(0),
        factor: last.ms_per_frame / t_rt,
    })
}

/// (log e − log a) / (log b − log a), 0 when a = b (flat).
fn log_fraction(e: f64, a: f64, b: f64) -> f64 {
    let (e, a, b) = (e.max(1e-30).ln(), a.max(1e-30).ln(), b.max(1e-30).ln());
    if (b - a).abs() < 1e-12 {
        0.0
    } else {
        ((e - a) / (b - a)).clamp(0.0, 1.0)
    }
}

fn write_outputs(report: &Report, out: &Path) -> Result<()> {
    let write = |name: &str, text: String| {
        let p = out.join(name);
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))
    };
    write("results.csv", csv(report))?;
    write("results.md", markdown(report))?;
    write("results.json", serde_json::to_string_pretty(report)?)
}

fn csv(report: &Report) -> String {
    let mut s = String::from("scene,case,method,spp,ms_per_frame,rmse,mae\n");
    for c in &report.cases {
        for r in &c.rows {
            let spp = r.spp.map(|n| n.to_string()).unwrap_or_default();
            let _ = writeln!(
                s,
                "{},{},{},{},{:.3},{:.6},{:.6}",
                r.scene, r.case, r.method, spp, r.ms_per_frame, r.rmse, r.mae
            );
        }
        let _ = writeln!(
            s,
            "{},{},reference-noise,{},0,{:.6},",
            c.scene,
            c.case,
            2 * report.settings.ref_spp,
            c.ref_rmse
        );
    }
    s
}

fn markdown(report: &Report) -> String {
    let st = &report.settings;
    let mut s = format!(
        "# bench-penumbra\n\n{0}×{0}, {1} thread(s), median of {2} frame(s). Reference: \
         `ltc-exact`, mean of two {3}-spp estimates (seeds differ). Errors over covered pixels, \
         linear radiance.\n\n",
        st.size, report.threads, st.frames, st.ref_spp
    );
    for c in &report.cases {
        let _ = write!(
            s,
            "## {} / {}\n\nBreaks: {}. Covered pixels: {}. Reference RMSE ≈ {:.5} (two \
             estimates differ by {:.5}).\n\n| method | spp | ms/frame | RMSE | MAE |\n|---|---|---|---|---|\n",
            c.scene, c.case, c.breaks, c.pixels_covered, c.ref_rmse, c.ref_rmse_between_seeds
        );
        for r in &c.rows {
            let spp = r.spp.map(|n| n.to_string()).unwrap_or_default();
            let _ = writeln!(
                s,
                "| {} | {} | {:.1} | {:.5} | {:.5} |",
                r.method, spp, r.ms_per_frame, r.rmse, r.mae
            );
        }
        let _ = writeln!(
            s,
            "\nEqual-RMSE speed-up of rt-penumbra over MC area-light shadows: {}\n",
            c.speed_up.describe()
        );
        let _ = writeln!(
            s,
            "The same for paper 003 as published (`rt-penumbra-point`: one ray per pixel toward \
             the light's centroid): {}\n",
            c.speed_up_point.describe()
        );
        if let Some(g) = &c.speed_up_gpu {
            let _ = writeln!(
                s,
                "The same with its rays and blur on the GPU ({}): {}\n",
                report.adapter.as_deref().unwrap_or("?"),
                g.describe()
            );
        }
    }
    for k in &report.skipped {
        let _ = writeln!(s, "Skipped: {k}");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene's frame at `w` × `h` for the tests: its renderer, occluder, light, guide,
    /// covered pixels and the `ltc-exact` reference at `spp`.
    fn frame_and_reference(
        s: &Scene,
        (w, h): (u32, u32),
        spp: u32,
    ) -> (Renderer<'_>, Occluder, Light, Guide, Vec<bool>, Image) {
        let r = Renderer::new(s, w, h);
        let occ = Occluder::of_surfaces(&s.mesh, &s.materials);
        let l = Light::load(&s.lights[0]).expect("light");
        let g = Guide::new(&r);
        let covered = covered_pixels(&r.gbuffer);
        let reference =
            render_ltc_exact_visibility(s, &r.view, &r.gbuffer, &l, &occ, &builtin_lookup, spp, 1);
        (r, occ, l, g, covered, reference)
    }

    /// The light split where the shadow is soft ([`Params::split`], `rt::split_light`): closer
    /// to LTC with ray-traced visibility than paper 003's one ray toward the centroid, on the
    /// built-in scene and, by far, under the `big-light` case's light (its slab shadow has no
    /// umbra, which the point light's hard shadow cannot lose), the more so where the split
    /// region grows past the one ray's blur ([`Params::grow`]); only pixels near the shadows
    /// change.
    #[test]
    fn the_split_light_is_closer_to_the_area_lights_shadow() {
        use bspvt_client::penumbra::rt;
        let base = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
        let point = Params {
            split: 1,
            ..Params::default()
        };
        let split = Params::default();
        assert_eq!(split.split, 2, "the default splits the light in 2 × 2");
        for (name, s, most) in [
            ("base", base.clone(), 0.9),
            ("big light", big_light(&base), 0.7),
        ] {
            let (r, occ, l, g, covered, reference) = frame_and_reference(&s, (128, 80), 256);
            let mae = |p: &Params| {
                let img = penumbra::render(&r, &g, &l, Technique::RtPenumbra, Some(&occ), p)
                    .expect("frame");
                errors(&img, &reference, &covered).1
            };
            let fixed = Params { grow: 0.0, ..split };
            let (e_point, e_fixed, e_split) = (mae(&point), mae(&fixed), mae(&split));
            eprintln!(
                "{name}: mean abs. error vs ltc-exact (256 spp): one ray {e_point:.5}, 2 × 2 \
                 {e_fixed:.5} where the one ray's blur reaches, {e_split:.5} grown"
            );
            assert!(
                e_split < most * e_point,
                "{name}: split {e_split} not below {most} × one ray's {e_point}"
            );
            assert!(
                e_split < e_fixed,
                "{name}: the grown split region's {e_split} not below the one ray's reach's \
                 {e_fixed}"
            );
            let mut b = rt::hard_shadows(&g, &l, &occ, 1e-4).expect("rays");
            let hard = b.hard.clone();
            rt::split_light(&mut b, &g, &l, &split, &occ, 1e-4).expect("rays");
            let changed = hard.iter().zip(&b.hard).filter(|(a, c)| a != c).count();
            let kept = hard.iter().zip(&b.hard).filter(|(a, c)| a == c).count();
            eprintln!("{name}: the split changed {changed} pixels' visibility, kept {kept}");
            assert!(
                changed > 0 && kept > changed,
                "{name}: {changed} changed, {kept} kept"
            );
            assert!(
                b.hard
                    .iter()
                    .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
            );
        }
    }

    /// A CPU caster that counts the segments it is asked about.
    struct Counting<'a>(&'a Occluder, std::sync::atomic::AtomicUsize);

    impl penumbra::rt::ShadowCaster for Counting<'_> {
        fn first_hits(&self, segments: &[bspvt_raytrace::Segment]) -> Result<Vec<Option<f32>>> {
            self.1
                .fetch_add(segments.len(), std::sync::atomic::Ordering::Relaxed);
            self.0.first_hits(segments)
        }
    }

    /// The wide split ([`Params::wide_split`]: 4 × 4 parts on every third pixel where the
    /// penumbra is wide, interpolated between): under the `big-light` case's light (penumbrae
    /// tens of pixels wide) far closer to the area light's shadow than 2 × 2 at every pixel of
    /// the region, for about as many rays; on the built-in scene, whose penumbrae at this size
    /// are a few pixels wide (only the grown region is split wide), no worse.
    #[test]
    fn the_wide_split_is_closer_for_about_as_many_rays() {
        let base = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
        let wide = Params::default();
        assert_eq!(
            (wide.wide_split, wide.sparse_step, wide.wide_reach),
            (4, 3, 8.0)
        );
        let dense = Params {
            wide_split: wide.split,
            ..wide
        };
        // (case, most error, most rays: × 2 × 2 at every pixel's)
        for (name, s, most, most_rays) in [
            ("big light", big_light(&base), 0.5, 1.2),
            ("base", base.clone(), 1.05, 1.2),
        ] {
            let (r, occ, l, g, covered, reference) = frame_and_reference(&s, (192, 120), 512);
            let run = |p: &Params| {
                let caster = Counting(&occ, Default::default());
                let img = penumbra::render(&r, &g, &l, Technique::RtPenumbra, Some(&caster), p)
                    .expect("frame");
                assert!(img.pixels.iter().flatten().all(|v| v.is_finite()));
                (errors(&img, &reference, &covered).1, caster.1.into_inner())
            };
            let ((e_wide, n_wide), (e_dense, n_dense)) = (run(&wide), run(&dense));
            eprintln!(
                "{name}: mean abs. error vs ltc-exact (512 spp): 2 × 2 at every pixel \
                 {e_dense:.5} ({n_dense} rays), 4 × 4 sparse where wide {e_wide:.5} \
                 ({n_wide} rays)"
            );
            assert!(
                e_wide < most * e_dense,
                "{name}: wide split {e_wide} not below {most} × 2 × 2's {e_dense}"
            );
            assert!(
                (n_wide as f64) < most_rays * n_dense as f64,
                "{name}: the wide split cast {n_wide} rays, 2 × 2 {n_dense}"
            );
        }
    }

    fn row(method: &str, spp: Option<u32>, ms: f64, rmse: f64) -> Row {
        Row {
            scene: "s".into(),
            case: "c".into(),
            method: method.into(),
            spp,
            ms_per_frame: ms,
            rmse,
            mae: rmse,
        }
    }

    #[test]
    fn speed_up_interpolates_log_log_and_reports_bounds() {
        // MC: RMSE ∝ 1/√spp, time ∝ spp.
        let mc: Vec<Row> = [1u32, 4, 16]
            .iter()
            .map(|&n| {
                row(
                    "ltc-exact",
                    Some(n),
                    10.0 * f64::from(n),
                    0.1 / f64::from(n).sqrt(),
                )
            })
            .collect();
        let with = |rmse: f64| {
            let mut v = vec![row("rt-penumbra", None, 2.0, rmse)];
            v.extend(mc.iter().cloned());
            equal_rmse_speed_up(&v, "rt-penumbra").expect("rows")
        };
        match with(0.1 / 2f64.sqrt()) {
            SpeedUp::Interpolated { spp, factor } => {
                assert!((spp - 2.0).abs() < 1e-9, "{spp}");
                assert!((factor - 10.0).abs() < 1e-9, "{factor}");
            }
            o => panic!("{o:?}"),
        }
        assert!(matches!(with(0.2), SpeedUp::WorseThanOneSpp { .. }));
        assert!(matches!(with(0.001), SpeedUp::AtLeast { max_spp: 16, .. }));
    }
}
