//! `bspvt bench-methods`: every registered method's frame time on one scene, against a
//! committed baseline, so that a slowdown shows whatever the machine's speed.
//!
//! Absolute times differ between machines and between runs on a shared one, so each
//! sequence's median frame time is divided by the time of a **calibration workload** run just
//! before and just after it in the same process (a fixed, project-independent mix of
//! transcendental arithmetic and table reads on every worker thread); a row is the median of
//! three such ratios. The baseline stores these ratios; a method whose ratio grew by more than
//! `--threshold` is reported `SLOWER` (`--strict` makes that an error).
//!
//! The baseline belongs to a build profile: `.ci/run` compares the test-profile binary that
//! `cargo test` builds with `assets/bench/methods-baseline.json`, recorded with that binary.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bspvt_client::method::sequence::{Options, render_sequence};
use bspvt_client::method::trees::{cached_bake, cached_sky_bake, load_checked};
use bspvt_client::method::{EnvOptions, FrameMethod, Settings, registry};
use bspvt_client::render::renderer::{Mode, Trees};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Wall time a method's timed frames cover at least (fast methods get more frames).
const MIN_TIMED_MS: f64 = 200.0;
/// Timed sequences per method and mode, each between two calibrations; the median ratio is
/// kept.
const REPEATS: usize = 3;

/// `bspvt bench-methods`: each method's frames against a committed baseline.
#[derive(clap::Args, Clone, Debug)]
pub struct BenchMethodsArgs {
    /// Scene: builtin:NAME, a shared mesh's name or a scene/mesh file.
    #[arg(default_value = "builtin:plate-small")]
    pub(crate) scene: String,
    /// Image side.
    #[arg(long, default_value_t = 128)]
    pub(crate) size: u32,
    /// Timed frames per sequence (the light moves; a sequence's median frame time is kept);
    /// fast methods get more frames, to cover 200 ms.
    #[arg(long, default_value_t = 7)]
    pub(crate) frames: usize,
    /// Samples per pixel of the stochastic methods (speed only: no error is measured).
    #[arg(long, default_value_t = 4)]
    pub(crate) spp: u32,
    /// Only these methods (default: every method in the registry).
    #[arg(long, value_delimiter = ',')]
    pub(crate) methods: Vec<String>,
    /// Baseline to compare with (JSON written by --write-baseline).
    #[arg(long)]
    pub(crate) baseline: Option<PathBuf>,
    /// Write this run as a baseline.
    #[arg(long)]
    pub(crate) write_baseline: Option<PathBuf>,
    /// Relative growth of a method's ratio reported as a slowdown.
    #[arg(long, default_value_t = 0.2)]
    pub(crate) threshold: f64,
    /// Exit with an error when a method is slower than the baseline by more than --threshold.
    #[arg(long)]
    pub(crate) strict: bool,
    /// Environment map of the environment methods (default: the shared map; without it they
    /// are skipped with a message).
    #[arg(long)]
    pub(crate) env: Option<PathBuf>,
    /// Where the trees are cached.
    #[arg(long, default_value = "out/bench-methods")]
    pub(crate) cache: PathBuf,
    /// Also write this run's rows as JSON here.
    #[arg(long)]
    pub(crate) json: Option<PathBuf>,
}

/// One method in one mode.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Row {
    pub(crate) method: String,
    pub(crate) mode: Mode,
    /// Median frame time.
    pub(crate) ms_per_frame: f64,
    /// The median over three sequences of a sequence's median frame over the calibration
    /// around it.
    pub(crate) ratio: f64,
}

/// A run (and the baseline file's format).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Run {
    pub(crate) scene: String,
    pub(crate) size: u32,
    pub(crate) frames: usize,
    pub(crate) spp: u32,
    pub(crate) threads: usize,
    /// Whether the binary has debug assertions (the dev and test profiles): ratios are
    /// compared only between runs of the same kind.
    pub(crate) debug_assertions: bool,
    /// Median wall time of the calibration workload (each sequence is divided by the mean of
    /// the two runs either side of it).
    pub(crate) calibration_ms: f64,
    pub(crate) rows: Vec<Row>,
}

/// Runs `bspvt bench-methods`.
pub fn run(a: &BenchMethodsArgs) -> Result<()> {
    let baseline: Option<Run> = match &a.baseline {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read the baseline {}", p.display()))?;
            Some(
                serde_json::from_str(&text)
                    .with_context(|| format!("{} is not a bench-methods baseline", p.display()))?,
            )
        }
        None => None,
    };
    let dir = bspvt_proto::paths::meshes_dir();
    let name = a.scene.strip_prefix("builtin:").unwrap_or(&a.scene);
    let scene = crate::bench::load_named_scene(name, &dir)?.with_context(|| {
        format!(
            "no scene {} (builtin:NAME, a mesh or a scene file)",
            a.scene
        )
    })?;
    let methods: Vec<&'static dyn FrameMethod> = if a.methods.is_empty() {
        registry::METHODS.to_vec()
    } else {
        a.methods
            .iter()
            .map(|m| registry::lookup(m))
            .collect::<Result<_>>()?
    };
    let env_path = a
        .env
        .clone()
        .unwrap_or_else(bspvt_client::envmap::default_env_path);
    let env_ok = env_path.exists();
    if !env_ok {
        println!(
            "bench-methods: no environment map at {} (--env): the environment methods are skipped",
            env_path.display()
        );
    }

    // The trees borrow from their bakes: both kept for the whole run.
    let needs_trees = methods.iter().any(|m| m.needs().lamp_trees(&scene));
    let bake = if needs_trees {
        let c = cached_bake("bench-methods", &scene, &a.cache, &|_, _| {})?;
        Some(load_checked(&c.path, &scene)?)
    } else {
        None
    };
    let trees = bake
        .as_ref()
        .map(|b| Trees::full(&b.trees, b.header.codec()));
    let needs_sky = env_ok && methods.iter().any(|m| m.needs().sky_trees_for(&scene));
    let sky_bake = if needs_sky {
        Some(cached_sky_bake(&scene, &a.cache, &|_, _| {})?.1)
    } else {
        None
    };
    let sky = sky_bake
        .as_ref()
        .map(|b| Trees::full(&b.trees, b.header.codec()));

    let mut calibration = Vec::new();
    let mut rows = Vec::new();
    for &method in &methods {
        let needs = method.needs();
        if needs.env_map && !env_ok {
            continue;
        }
        let modes = match method.fixed_mode() {
            Some(m) => vec![m],
            None => vec![Mode::Vertex, Mode::Pixel],
        };
        for mode in modes {
            let opts = Options {
                method,
                width: a.size,
                height: a.size,
                frames: a.frames.max(1),
                light: None,
                env_spin_deg: if needs.sky_trees { 1.0 } else { 0.0 },
                settings: Settings {
                    mode,
                    spp: a.spp,
                    env: EnvOptions {
                        path: env_path.clone(),
                        ..EnvOptions::default()
                    }
                    .for_scene(&scene),
                    ..Settings::default()
                },
            };
            let run = |opts: &Options| {
                render_sequence(&scene, trees.as_ref(), sky.as_ref(), opts, |_, _| Ok(()))
                    .with_context(|| format!("--method {}", method.name()))
            };
            let first = run(&opts)?;
            // Fast methods get more frames: a median over at least MIN_TIMED_MS of frames.
            let frames = if first.ms_per_frame * (first.frames as f64) < MIN_TIMED_MS {
                ((MIN_TIMED_MS / first.ms_per_frame.max(0.01)).ceil() as usize)
                    .clamp(opts.frames, 16 * opts.frames)
            } else {
                opts.frames
            };
            // REPEATS sequences, each between two calibrations: a sequence's ratio is its median
            // frame over the mean of the calibrations either side of it (slow drifts of the
            // machine's speed cancel), and the row keeps the median of the ratios.
            let mut before = calibrate();
            let mut samples: Vec<(f64, f64, Mode)> = Vec::with_capacity(REPEATS);
            for _ in 0..REPEATS {
                let s = run(&Options {
                    frames,
                    ..opts.clone()
                })?;
                let after = calibrate();
                let cal = 0.5 * (before + after);
                calibration.push(cal);
                samples.push((s.ms_per_frame / cal, s.ms_per_frame, s.mode));
                before = after;
            }
            samples.sort_by(|x, y| x.0.total_cmp(&y.0));
            let (ratio, ms_per_frame, shaded_in) = samples[samples.len() / 2];
            // A method that ignores the mode asked for draws the same frames twice: one row.
            if rows
                .iter()
                .any(|r: &Row| r.method == method.name() && r.mode == shaded_in)
            {
                continue;
            }
            rows.push(Row {
                method: method.name().to_string(),
                mode: shaded_in,
                ms_per_frame,
                ratio,
            });
        }
    }
    calibration.sort_by(f64::total_cmp);
    let calibration_ms = calibration
        .get(calibration.len() / 2)
        .copied()
        .unwrap_or(0.0);
    let run = Run {
        scene: a.scene.clone(),
        size: a.size,
        frames: a.frames,
        spp: a.spp,
        threads: rayon::current_num_threads(),
        debug_assertions: cfg!(debug_assertions),
        calibration_ms,
        rows,
    };
    let slower = print(&run, baseline.as_ref(), a.threshold);
    for p in [&a.write_baseline, &a.json].into_iter().flatten() {
        if let Some(d) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
        }
        std::fs::write(p, serde_json::to_string_pretty(&run)? + "\n")
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    if a.strict && !slower.is_empty() {
        bail!(
            "slower than the baseline by more than {:.0} %: {}",
            100.0 * a.threshold,
            slower.join(", ")
        );
    }
    Ok(())
}

/// Prints the run beside the baseline; returns the rows slower than it by more than
/// `threshold`.
fn print(run: &Run, baseline: Option<&Run>, threshold: f64) -> Vec<String> {
    println!(
        "bench-methods: {} at {}², {} frames, {} spp, {} threads; calibration {:.2} ms",
        run.scene, run.size, run.frames, run.spp, run.threads, run.calibration_ms
    );
    let comparable = baseline.and_then(|b| {
        let why = if b.scene != run.scene || b.size != run.size || b.spp != run.spp {
            Some(format!(
                "it measured {} at {}², {} spp",
                b.scene, b.size, b.spp
            ))
        } else if b.debug_assertions != run.debug_assertions {
            Some("it was recorded with another build profile".to_string())
        } else {
            None
        };
        match why {
            Some(why) => {
                println!("the baseline is not compared: {why}");
                None
            }
            None => Some(b),
        }
    });
    println!("| method | mode | ms/frame | ratio | baseline ratio | change |");
    println!("|---|---|---:|---:|---:|---|");
    let mut slower = Vec::new();
    for r in &run.rows {
        let base = comparable.and_then(|b| {
            b.rows
                .iter()
                .find(|x| x.method == r.method && x.mode == r.mode)
        });
        let (base_s, change) = match base {
            Some(b) if b.ratio > 0.0 => {
                let c = r.ratio / b.ratio - 1.0;
                let flag = if c > threshold {
                    slower.push(format!("{} {:?} (+{:.0} %)", r.method, r.mode, 100.0 * c));
                    " SLOWER"
                } else if c < -threshold {
                    " faster"
                } else {
                    ""
                };
                (
                    format!("{:.3}", b.ratio),
                    format!("{:+.1} %{flag}", 100.0 * c),
                )
            }
            _ => ("–".to_string(), "–".to_string()),
        };
        println!(
            "| {} | {:?} | {:.2} | {:.3} | {base_s} | {change} |",
            r.method, r.mode, r.ms_per_frame, r.ratio
        );
    }
    if let Some(b) = comparable {
        let missing: Vec<String> = b
            .rows
            .iter()
            .filter(|x| {
                !run.rows
                    .iter()
                    .any(|r| r.method == x.method && r.mode == x.mode)
            })
            .map(|x| format!("{} {:?}", x.method, x.mode))
            .collect();
        if !missing.is_empty() {
            println!("in the baseline but not run: {}", missing.join(", "));
        }
        if slower.is_empty() {
            println!(
                "no method is slower than the baseline by more than {:.0} %",
                100.0 * threshold
            );
        } else {
            println!(
                "SLOWER than the baseline by more than {:.0} %: {}",
                100.0 * threshold,
                slower.join(", ")
            );
        }
    }
    slower
}

/// Wall time (ms) of a fixed workload on every worker thread: per item, a chain of
/// transcendental arithmetic and reads at pseudo-random places in a 64 KiB table (cache
/// resident, as the benchmark's small scene is: a table out of cache made the calibration
/// follow other tenants' memory traffic, which the methods do not), independent of the
/// project's code.
fn calibrate() -> f64 {
    // The fastest of three: interference from elsewhere only adds time.
    (0..3)
        .map(|_| calibration_once())
        .fold(f64::INFINITY, f64::min)
}

/// One timed run of [`calibrate`]'s workload.
fn calibration_once() -> f64 {
    const TABLE: usize = 1 << 13;
    const ITEMS: u32 = 1 << 14;
    const STEPS: u32 = 48;
    let table: Vec<f64> = (0..TABLE).map(|i| (i as f64 * 0.618_034).fract()).collect();
    let t = Instant::now();
    let sum: f64 = (0..ITEMS)
        .into_par_iter()
        .map(|i| {
            // xorshift32 state per item.
            let mut s = i.wrapping_mul(2_654_435_761) | 1;
            let mut acc = 0.0f64;
            for _ in 0..STEPS {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                let v = table[s as usize % TABLE];
                acc += (v * 3.0).sin() * (-v).exp() + (1.0 + v).sqrt().ln();
            }
            acc
        })
        .sum();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    std::hint::black_box(sum);
    ms
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run_of(ratios: &[(&str, f64)]) -> Run {
        Run {
            scene: "builtin:plate-small".into(),
            size: 64,
            frames: 3,
            spp: 4,
            threads: 2,
            debug_assertions: cfg!(debug_assertions),
            calibration_ms: 10.0,
            rows: ratios
                .iter()
                .map(|&(m, r)| Row {
                    method: m.into(),
                    mode: Mode::Pixel,
                    ms_per_frame: r * 10.0,
                    ratio: r,
                })
                .collect(),
        }
    }

    #[test]
    fn a_ratio_grown_past_the_threshold_is_reported_slower() {
        let base = run_of(&[("ltc", 1.0), ("bspvt", 2.0)]);
        let now = run_of(&[("ltc", 1.1), ("bspvt", 2.5)]);
        assert_eq!(print(&now, Some(&base), 0.2), vec!["bspvt Pixel (+25 %)"]);
        assert!(print(&base, Some(&base), 0.2).is_empty());
        // Another scene or size: not compared.
        let mut other = now.clone();
        other.size = 128;
        assert!(print(&other, Some(&base), 0.2).is_empty());
    }

    #[test]
    fn the_calibration_takes_measurable_time() {
        let ms = calibrate();
        assert!(ms.is_finite() && ms > 0.0, "{ms}");
    }
}
