//! The project's own fit of linearly transformed cosines to GGX (separable Smith masking),
//! after Heitz, Dupuy, Hill and Neubelt 2016, "Real-Time Polygonal-Light Shading with Linearly
//! Transformed Cosines" (*LTC*), §4, and the authors' `fitLTC.cpp`. `bspvt ltc-fit` writes the
//! table `assets/ltc/ggx.json` ([`super::table`] has the parameterisation and the lookup;
//! `docs/ltc.md` the method's measured accuracy).
//!
//! # Per entry (α, θ)
//!
//! 1. **BRDF integrals**: magnitude = ∫ f cos θi dωi, fresnel = ∫ f cos θi (1 − ωi·h)⁵ dωi and
//!    the lobe's average direction ∫ f cos θi ωi dωi, by a deterministic quadrature over the
//!    half vector in which the horizon is an analytic bound ([`brdf_moments`]); converged to
//!    ~1e-8 relative, and checked against an independent quadrature over ωi by
//!    `client/tests/ltc_table.rs`.
//! 2. **Frame**: Z = the average direction (its y component is zero by symmetry), X in the
//!    plane of incidence, as `fitLTC.cpp` does; at θ = 0 the lobe is rotationally symmetric and
//!    the fit is isotropic (m11 = m22, m13 = m31 = 0).
//! 3. **Shape**: M = [X Y Z]·[[m11, 0, m13], [0, m22, 0], [m31, 0, 1]] minimises the Lᵖ distance
//!    ∫ |f cos θi/magnitude − D|ᵖ dω between the normalised lobe and the LTC density D. The
//!    default is p = 1 over the upper hemisphere: the L¹ (total-variation) distance bounds the
//!    error of the normalised lobe's integral over *any* region, which is what the polygon
//!    integral (clipped at the horizon) computes; `fitLTC.cpp` uses p = 3 over the sphere
//!    (`--power 3 --whole-sphere`; `docs/ltc.md` compares them). The integral is estimated by
//!    multiple importance sampling (balance heuristic) between visible-normal sampling of the
//!    BRDF (Heitz 2018) and sampling of the LTC, both driven by the same fixed
//!    `lattice_points`-point rank-1 lattice (golden-ratio Kronecker sequence), so the
//!    objective is a deterministic function of M.
//! 4. **Optimiser**: Nelder–Mead downhill simplex (coefficients 1, 2, ½, ½) over
//!    x = (ln m11, ln m22, m13/m11, m31) — scale free, so the same step (0.05) and tolerance
//!    (1e-7) serve α = 1e-4 and α = 1 — restarted from its best vertex until a restart gains
//!    less than 1e-10 relative (at most 8 runs; guards against premature collapse). Starting
//!    point: the fitted neighbour at the previous view angle of the same roughness
//!    (`fitLTC.cpp` sweeps the view angle the same way); at θ = 0 a scan of ln m over
//!    [ln α − 4, ln α + 4] followed by a 1-D simplex. Rows (one roughness each) are independent,
//!    so they run in parallel and the output does not depend on the thread count.
//!
//! Every stored number is a JSON fixed point ([`super::table::json_roundtrip`]) and the next
//! entry starts from the stored numbers, so refitting an entry from the *file's* neighbour
//! reproduces the file bit for bit (`client/tests/ltc_table.rs` checks that).

use std::f64::consts::PI;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use glam::DVec3;
use rayon::prelude::*;

use bspvt_client::ggx::{self, MIN_ALPHA};
use bspvt_client::ltc::table::{
    FORMAT, FitRecord, LtcShape, LtcTable, THETA_MAX_DEG, TableEntry, TableFile, alpha_node,
    json_roundtrip, theta_max, theta_node,
};

/// Default number of lattice points per sampling strategy in the error estimate.
pub(crate) const DEFAULT_LATTICE: usize = 2048;
/// Default grading depth of the moment quadrature (see [`brdf_moments`]).
pub(crate) const DEFAULT_MOMENT_LEVELS: u32 = 16;
/// Default Nelder–Mead simplex tolerance.
pub(crate) const DEFAULT_TOLERANCE: f64 = 1e-7;

/// The default fit settings (what `bspvt ltc-fit` uses unless told otherwise).
pub fn default_settings() -> FitRecord {
    settings(DEFAULT_LATTICE, DEFAULT_MOMENT_LEVELS, 1, true)
}

/// Fit settings with the given sample counts and error norm.
pub(crate) fn settings(
    lattice_points: usize,
    moment_levels: u32,
    error_power: i32,
    upper_hemisphere_only: bool,
) -> FitRecord {
    let region = if upper_hemisphere_only {
        "upper hemisphere"
    } else {
        "sphere"
    };
    FitRecord {
        lattice_points,
        moment_levels,
        simplex_tolerance: DEFAULT_TOLERANCE,
        error_power,
        upper_hemisphere_only,
        method: format!(
            "Nelder-Mead over (ln m11, ln m22, m13/m11, m31) minimising the MIS estimate of the \
             L{error_power} distance over the {region} between the normalised GGX lobe and the \
             LTC; frame Z = the lobe's average direction; started from the previous view angle"
        ),
    }
}

/// Arguments of `bspvt ltc-fit`.
#[derive(clap::Args, Debug)]
pub struct FitArgs {
    /// Nodes per axis (roughness × view angle).
    #[arg(long, default_value_t = 64)]
    pub(crate) size: usize,
    /// Where to write the table.
    #[arg(long, default_value = "assets/ltc/ggx.json")]
    pub(crate) out: PathBuf,
    /// Lattice points per sampling strategy in the fit's error estimate.
    #[arg(long, default_value_t = DEFAULT_LATTICE)]
    pub(crate) lattice: usize,
    /// Grading depth of the magnitude / Fresnel / average-direction quadrature.
    #[arg(long, default_value_t = DEFAULT_MOMENT_LEVELS)]
    pub(crate) moment_levels: u32,
    /// p of the Lᵖ distance the fit minimises (1, 2 or 3; Heitz et al. use 3).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(i32).range(1..=3))]
    pub(crate) power: i32,
    /// Measure the distance over the whole sphere (as `fitLTC.cpp`) instead of the upper
    /// hemisphere.
    #[arg(long)]
    pub(crate) whole_sphere: bool,
    /// Also write per-entry fit diagnostics (CSV: i, j, α, θ°, L1, upper mass, evaluations).
    #[arg(long)]
    pub(crate) report: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub(crate) quiet: bool,
}

/// Runs `bspvt ltc-fit`: fits the table and writes it.
pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.size >= 2, "--size must be at least 2");
    anyhow::ensure!(
        args.lattice >= 16 && (4..=40).contains(&args.moment_levels),
        "--lattice must be ≥ 16 and --moment-levels in 4..=40"
    );
    let settings = settings(
        args.lattice,
        args.moment_levels,
        args.power,
        !args.whole_sphere,
    );
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new((args.size * args.size) as u64)
    };
    let start = Instant::now();
    let (entries, reports) = fit_table(args.size, &settings, &|| bar.inc(1));
    bar.finish_and_clear();
    let elapsed = start.elapsed().as_secs_f64();
    let file = table_file(args.size, &settings, &entries);
    // Validate before writing.
    LtcTable::from_file(file.clone()).context("the fitted table does not validate")?;
    let text = file.to_json()?;
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(&args.out, text)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    println!(
        "fitted {n}×{n} entries in {elapsed:.1} s on {} threads → {}",
        rayon::current_num_threads(),
        args.out.display(),
        n = args.size
    );
    print_summary(args.size, &reports);
    if let Some(path) = &args.report {
        use std::fmt::Write;
        let mut csv = String::from("i,j,alpha,theta_deg,l1,upper_mass,evaluations\n");
        for (k, r) in reports.iter().enumerate() {
            let (i, j) = (k / args.size, k % args.size);
            writeln!(
                csv,
                "{i},{j},{:e},{},{},{},{}",
                alpha_node(i, args.size),
                theta_node(j, args.size).to_degrees(),
                r.l1,
                r.upper_mass,
                r.evaluations
            )?;
        }
        std::fs::write(path, csv).with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

/// Assembles the file for a fitted table.
pub fn table_file(size: usize, settings: &FitRecord, entries: &[TableEntry]) -> TableFile {
    TableFile {
        format: FORMAT.to_string(),
        description: "LTC fit of GGX (separable Smith G1·G1, no Fresnel in the shape); \
                      entries [rho, m11, m22, m13, m31, magnitude, fresnel], see assets/ltc/README.md"
            .to_string(),
        size,
        alpha_min: MIN_ALPHA,
        theta_max_deg: THETA_MAX_DEG,
        command: format!(
            "cargo run --release -p bspvt -- ltc-fit --size {size} --lattice {} --moment-levels {} \
             --power {}{} --out assets/ltc/ggx.json",
            settings.lattice_points,
            settings.moment_levels,
            settings.error_power,
            if settings.upper_hemisphere_only { "" } else { " --whole-sphere" }
        ),
        fit: settings.clone(),
        alpha: (0..size).map(|i| alpha_node(i, size)).collect(),
        theta: (0..size).map(|j| theta_node(j, size)).collect(),
        entries: entries.iter().map(TableEntry::to_array).collect(),
    }
}

/// What the fit of one entry achieved.
#[derive(Clone, Copy, Debug)]
pub struct FitReport {
    /// Final value of the objective (MIS estimate of ∫ |f/‖f‖ − D|ᵖ; for p > 1 not comparable
    /// between entries: it scales with the lobe's width to the power 2 − 2p).
    pub objective: f64,
    /// MIS estimate of the L¹ distance ∫ |f/‖f‖ − D| dω ∈ [0, 2] (scale free: twice the largest
    /// error of the normalised lobe's integral over any region).
    pub(crate) l1: f64,
    /// Fraction of the LTC's mass above the horizon.
    pub(crate) upper_mass: f64,
    /// Objective evaluations.
    pub(crate) evaluations: usize,
}

/// Fits the whole table: rows (roughness nodes) in parallel, each swept from θ = 0 to θ_max.
/// `tick` is called once per entry. Returns entries and reports, index i·size + j.
pub(crate) fn fit_table(
    size: usize,
    settings: &FitRecord,
    tick: &(dyn Fn() + Sync),
) -> (Vec<TableEntry>, Vec<FitReport>) {
    let rows: Vec<Vec<(TableEntry, FitReport)>> = (0..size)
        .into_par_iter()
        .map(|i| {
            let alpha = alpha_node(i, size);
            let mut prev: Option<LtcShape> = None;
            (0..size)
                .map(|j| {
                    let r = fit_entry(alpha, theta_node(j, size), prev.as_ref(), settings);
                    prev = Some(r.0.shape);
                    tick();
                    r
                })
                .collect()
        })
        .collect();
    rows.into_iter().flatten().unzip()
}

/// The lobe's integrals: see the module documentation, step 1.
#[derive(Clone, Copy, Debug)]
pub struct Moments {
    /// ∫ f cos θi dωi.
    pub magnitude: f64,
    /// ∫ f cos θi (1 − ωi·h)⁵ dωi.
    pub fresnel: f64,
    /// ∫ f cos θi ωi dωi (not normalised).
    pub average: DVec3,
}

/// Gauss–Legendre nodes and weights on [−1, 1], 8 points.
const GL8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_3, 0.101_228_536_290_376_26),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (0.960_289_856_497_536_3, 0.101_228_536_290_376_26),
];

/// Panels of [a, b] refined geometrically (ratio ½, `levels` times) toward a and/or b.
fn graded(a: f64, b: f64, toward_a: bool, toward_b: bool, levels: u32) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut one_side = |p: f64, q: f64, toward_p: bool| {
        let mut l = q - p;
        for _ in 0..levels {
            out.push(if toward_p {
                (p + l / 2.0, p + l)
            } else {
                (q - l, q - l / 2.0)
            });
            l /= 2.0;
        }
        out.push(if toward_p { (p, p + l) } else { (q - l, q) });
    };
    match (toward_a, toward_b) {
        (true, true) => {
            let m = 0.5 * (a + b);
            one_side(a, m, true);
            one_side(m, b, false);
        }
        (true, false) => one_side(a, b, true),
        (false, true) => one_side(a, b, false),
        (false, false) => {
            for k in 0..4 {
                out.push((
                    a + (b - a) * k as f64 / 4.0,
                    a + (b - a) * (k + 1) as f64 / 4.0,
                ));
            }
        }
    }
    out
}

/// Integrates magnitude, Fresnel term and average direction of the GGX lobe for view `wo`
/// (in the xz-plane, x ≥ 0) by quadrature over the half vector.
///
/// With the slope s = tan θh and its azimuth φ (h = (s cos φ, s sin φ, 1)/√(1 + s²)),
/// D(h) dωh = √(1 + s²) du dφ / 2π where u = s²/(α² + s²) (the GGX slope distribution's
/// CDF), and ∫ f cos θi dωi = ∫ G₁(ωo) G₁(ωi) (ωo·h)/cos θo · D(h) dωh over the half vectors
/// whose reflection ωi = 2(ωo·h)h − ωo is above the horizon. That condition is analytic:
/// cos φ > k(s) = cos θo (s² − 1)/(2 s sin θo), all φ for s ≤ s_c = cos θo/(1 + sin θo), none
/// for s ≥ s_max = (1 + sin θo)/cos θo. The outer variable is τ = atan(α/s) (u = cos²τ,
/// du = sin 2τ dτ, which resolves the largest slopes of narrow lobes), on [τ(s_max), τ(s_c)]
/// and [τ(s_c), π/2]; the inner one φ ∈ [0, φ*] (the lobe is symmetric in y). Both are
/// composite 8-point Gauss–Legendre rules graded geometrically `levels` times toward the
/// kinks (s_c, s_max, and φ* where G₁(ωi) drops to zero at the horizon).
pub fn brdf_moments(alpha: f64, wo: DVec3, levels: u32) -> Moments {
    let (sin_o, cos_o) = (wo.x.max(0.0), wo.z);
    if !(cos_o > 0.0) {
        return Moments {
            magnitude: 0.0,
            fresnel: 0.0,
            average: DVec3::ZERO,
        };
    }
    let g1o_over_cos = ggx::g1(alpha, cos_o) / cos_o;
    let s_c = cos_o / (1.0 + sin_o);
    let tau_c = (alpha / s_c).atan();
    let tau_max = (alpha * cos_o / (1.0 + sin_o)).atan();
    let mut outer = Vec::new();
    if sin_o > 0.0 {
        outer.extend(graded(tau_max, tau_c, true, true, levels));
    }
    outer.extend(graded(
        tau_c,
        std::f64::consts::FRAC_PI_2,
        true,
        false,
        levels,
    ));
    let (mut mag, mut fres, mut avg) = (0.0, 0.0, DVec3::ZERO);
    for (a, b) in outer {
        let (c, hw) = (0.5 * (a + b), 0.5 * (b - a));
        for (x, w) in GL8 {
            let tau = c + hw * x;
            let s = alpha / tau.tan();
            let phi_max = if s <= s_c || sin_o == 0.0 {
                PI
            } else {
                (cos_o * (s * s - 1.0) / (2.0 * s * sin_o))
                    .clamp(-1.0, 1.0)
                    .acos()
            };
            let inner = if phi_max < PI {
                graded(0.0, phi_max, false, true, levels)
            } else {
                graded(0.0, PI, false, false, levels)
            };
            let norm = (1.0 + s * s).sqrt();
            let weight_tau = w * hw * (2.0 * tau).sin();
            for (p, q) in inner {
                let (cp, hp) = (0.5 * (p + q), 0.5 * (q - p));
                for (y, v) in GL8 {
                    let (sn, cs) = (cp + hp * y).sin_cos();
                    let h = DVec3::new(s * cs, s * sn, 1.0) / norm;
                    let woh = wo.dot(h);
                    let wi = 2.0 * woh * h - wo;
                    if !(woh > 0.0 && wi.z > 0.0) {
                        continue;
                    }
                    let val =
                        weight_tau * v * hp * g1o_over_cos * ggx::g1(alpha, wi.z) * woh * norm;
                    mag += val;
                    fres += val * ggx::schlick_weight(woh);
                    avg += val * wi;
                }
            }
        }
    }
    // ×2 for φ ∈ [−φ*, 0], and du dφ / 2π.
    let k = 2.0 / (2.0 * PI);
    Moments {
        magnitude: mag * k,
        fresnel: fres * k,
        average: DVec3::new(avg.x, 0.0, avg.z) * k,
    }
}

/// The `n` points of the lattice that drives both sampling strategies:
/// ((i + ½)/n, frac(½ + i/φ)) with φ the golden ratio.
pub(crate) fn lattice(n: usize) -> Vec<[f64; 2]> {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    (0..n)
        .map(|i| [(i as f64 + 0.5) / n as f64, (0.5 + i as f64 * g).fract()])
        .collect()
}

/// The fitting problem of one entry: the BRDF side is fixed (samples, values, densities), the
/// LTC side depends on its shape.
struct Problem {
    alpha: f64,
    wo: DVec3,
    g1o: f64,
    inv4co: f64,
    inv_mag: f64,
    /// BRDF samples: direction, normalised f cos, pdf.
    brdf: Vec<(DVec3, f64, f64)>,
    /// Cosine-distributed directions.
    cosine: Vec<DVec3>,
    /// Exponent of the error norm.
    power: i32,
    /// Count only errors above the horizon.
    upper_only: bool,
}

/// Per-sample terms of the error estimate.
#[derive(Clone, Copy, Default)]
struct Terms {
    lp: f64,
    l1: f64,
    upper: f64,
}

impl Problem {
    fn new(alpha: f64, wo: DVec3, magnitude: f64, settings: &FitRecord) -> Problem {
        let n = settings.lattice_points;
        let mut p = Problem {
            alpha,
            wo,
            g1o: ggx::g1(alpha, wo.z),
            inv4co: 1.0 / (4.0 * wo.z),
            inv_mag: if magnitude > 0.0 {
                1.0 / magnitude
            } else {
                0.0
            },
            brdf: Vec::with_capacity(n),
            cosine: Vec::with_capacity(n),
            power: settings.error_power,
            upper_only: settings.upper_hemisphere_only,
        };
        for u in lattice(n) {
            let wi = ggx::sample_vndf(alpha, wo, u);
            let (f, pdf) = p.brdf_eval(wi);
            p.brdf.push((wi, f, pdf));
            let r = u[0].sqrt();
            let (s, c) = (2.0 * PI * u[1]).sin_cos();
            p.cosine
                .push(DVec3::new(r * c, r * s, (1.0 - u[0]).max(0.0).sqrt()));
        }
        p
    }

    /// Normalised f cos θi and the visible-normal sampling density at `wi`.
    #[inline]
    fn brdf_eval(&self, wi: DVec3) -> (f64, f64) {
        let h = self.wo + wi;
        let len = h.length();
        if !(len > 0.0) {
            return (0.0, 0.0);
        }
        let h = h / len;
        if self.wo.dot(h) <= 0.0 {
            return (0.0, 0.0);
        }
        let pdf = self.g1o * ggx::d(self.alpha, h.z) * self.inv4co;
        let f = if wi.z > 0.0 {
            pdf * ggx::g1(self.alpha, wi.z) * self.inv_mag
        } else {
            0.0
        };
        (f, pdf)
    }

    /// MIS estimates of ∫ |f − D|^p, ∫ |f − D| and of the LTC's mass above the horizon.
    fn terms(&self, shape: &LtcShape) -> Terms {
        let LtcShape {
            m11, m22, m13, m31, ..
        } = *shape;
        let (x, z) = shape.frame();
        let det = m22 * shape.xz_det();
        let inv_det = 1.0 / det;
        let k = 1.0 / shape.xz_det();
        let inv22 = 1.0 / m22;
        let mut t = Terms::default();
        let power = self.power;
        let upper_only = self.upper_only;
        let mut add = |f: f64, g: f64, pdf: f64, up: bool| {
            let e = (f - g).abs();
            let w = pdf + g;
            if w > 0.0 {
                t.l1 += e / w;
                if up || !upper_only {
                    t.lp += match power {
                        1 => e,
                        2 => e * e,
                        _ => e * e * e,
                    } / w;
                }
            }
        };
        for &(wi, f, pdf) in &self.brdf {
            let p = DVec3::new(x.dot(wi), wi.y, z.dot(wi));
            let q = DVec3::new(
                (p.x - m13 * p.z) * k,
                p.y * inv22,
                (m11 * p.z - m31 * p.x) * k,
            );
            let g = if q.z > 0.0 {
                let l2 = q.length_squared();
                q.z * inv_det / (PI * l2 * l2)
            } else {
                0.0
            };
            add(f, g, pdf, wi.z > 0.0);
        }
        let mut upper = 0.0;
        for &s in &self.cosine {
            let a = m11 * s.x + m13 * s.z;
            let b = m22 * s.y;
            let c = m31 * s.x + s.z;
            let w = a * x + DVec3::new(0.0, b, 0.0) + c * z;
            let l = w.length();
            let w = w / l;
            let g = s.z / PI * inv_det * l * l * l;
            let (f, pdf) = self.brdf_eval(w);
            add(f, g, pdf, w.z > 0.0);
            if w.z > 0.0 {
                upper += 1.0;
            }
        }
        let n = self.brdf.len() as f64;
        Terms {
            lp: t.lp / n,
            l1: t.l1 / n,
            upper: upper / n,
        }
    }

    /// The objective: the Lᵖ estimate; +∞ for an invalid shape or a non-finite value.
    fn objective(&self, shape: &LtcShape) -> f64 {
        if !shape.is_valid() {
            return f64::INFINITY;
        }
        let v = self.terms(shape).lp;
        if v.is_finite() { v } else { f64::INFINITY }
    }
}

/// The shape from the optimiser's variables (ln m11, ln m22, m13/m11, m31) in the frame ρ.
#[inline]
fn from_vars(x: &[f64; 4], rho: f64) -> LtcShape {
    let m11 = x[0].clamp(-700.0, 700.0).exp();
    LtcShape {
        rho,
        m11,
        m22: x[1].clamp(-700.0, 700.0).exp(),
        m13: x[2] * m11,
        m31: x[3],
    }
}

/// Fits the entry at roughness `alpha` and view angle `theta` (radians, clamped to
/// [0, θ_max]); `init` is the starting shape and the view angle it was fitted at (the
/// neighbouring entry; `None`: an isotropic scan gives it). Deterministic: the same inputs give the same bits. The returned numbers are
/// already round-tripped through JSON (what the file stores).
pub fn fit_entry(
    alpha: f64,
    theta: f64,
    init: Option<&LtcShape>,
    settings: &FitRecord,
) -> (TableEntry, FitReport) {
    let alpha = ggx::clamp_alpha(alpha);
    let theta = if theta.is_nan() {
        0.0
    } else {
        theta.clamp(0.0, theta_max())
    };
    let wo = DVec3::new(theta.sin(), 0.0, theta.cos());
    let mom = brdf_moments(alpha, wo, settings.moment_levels);
    let isotropic = theta == 0.0;
    let rho = if isotropic {
        0.0
    } else {
        mom.average.x.atan2(mom.average.z)
    };
    let prob = Problem::new(alpha, wo, mom.magnitude, settings);
    let tol = settings.simplex_tolerance;
    let mut evaluations = 0;

    // Isotropic start (θ = 0, or no neighbour): scan ln m, then a 1-D simplex.
    let iso = |evaluations: &mut usize| {
        let centre = alpha.ln();
        let at = |l: f64| prob.objective(&from_vars(&[l, l, 0.0, 0.0], rho));
        let mut best = (f64::INFINITY, centre);
        for k in 0..=40 {
            let x = centre - 4.0 + 0.2 * k as f64;
            let v = at(x);
            *evaluations += 1;
            if v < best.0 {
                best = (v, x);
            }
        }
        let (x, _, e) = minimise([best.1], 0.1, tol, |x: &[f64; 1]| at(x[0]));
        *evaluations += e;
        x[0]
    };

    let shape = if isotropic {
        let l = iso(&mut evaluations);
        from_vars(&[l, l, 0.0, 0.0], 0.0)
    } else {
        // Starting point: the neighbour's shape in this entry's frame, or the isotropic fit.
        let x0 = match init {
            Some(s) => [s.m11.ln(), s.m22.ln(), s.m13 / s.m11, s.m31],
            None => {
                let l = iso(&mut evaluations);
                [l, l, 0.0, 0.0]
            }
        };
        let (x, _, e) = minimise(x0, 0.05, tol, |x: &[f64; 4]| {
            prob.objective(&from_vars(x, rho))
        });
        evaluations += e;
        from_vars(&x, rho)
    };
    let terms = prob.terms(&shape);
    let r = json_roundtrip;
    let entry = TableEntry {
        shape: LtcShape {
            rho: r(shape.rho),
            m11: r(shape.m11),
            m22: r(shape.m22),
            m13: r(shape.m13),
            m31: r(shape.m31),
        },
        magnitude: r(mom.magnitude),
        fresnel: r(mom.fresnel.min(mom.magnitude)),
    };
    let report = FitReport {
        objective: terms.lp,
        l1: terms.l1,
        upper_mass: terms.upper,
        evaluations,
    };
    (entry, report)
}
/// Nelder–Mead, restarted from the best vertex (with the initial step) until a restart gains
/// less than 1e-10 relative (at most 8 runs). Returns (best x, best value, evaluations).
fn minimise<const D: usize>(
    x0: [f64; D],
    step: f64,
    tol: f64,
    mut f: impl FnMut(&[f64; D]) -> f64,
) -> ([f64; D], f64, usize) {
    let mut evals = 0;
    let (mut x, mut fx, e) = nelder_mead(x0, step, tol, 4000, &mut f);
    evals += e;
    for _ in 0..7 {
        let (y, fy, e) = nelder_mead(x, step, tol, 4000, &mut f);
        evals += e;
        let gain = fx - fy;
        if fy < fx {
            x = y;
            fx = fy;
        }
        if !(gain > 1e-10 * fx.abs()) {
            break;
        }
    }
    (x, fx, evals)
}

/// One Nelder–Mead run (reflection 1, expansion 2, contraction ½, shrink ½), stopping when
/// every vertex is within `tol` (max norm) of the best one or after `max_evals` evaluations.
fn nelder_mead<const D: usize>(
    x0: [f64; D],
    step: f64,
    tol: f64,
    max_evals: usize,
    f: &mut impl FnMut(&[f64; D]) -> f64,
) -> ([f64; D], f64, usize) {
    let mut evals = 0;
    let mut eval = |x: &[f64; D], evals: &mut usize| {
        *evals += 1;
        let v = f(x);
        if v.is_nan() { f64::INFINITY } else { v }
    };
    let mut simplex: Vec<([f64; D], f64)> = Vec::with_capacity(D + 1);
    simplex.push((x0, eval(&x0, &mut evals)));
    for i in 0..D {
        let mut x = x0;
        x[i] += step;
        simplex.push((x, eval(&x, &mut evals)));
    }
    let lerp = |a: &[f64; D], b: &[f64; D], t: f64| -> [f64; D] {
        let mut r = [0.0; D];
        for k in 0..D {
            r[k] = a[k] + t * (b[k] - a[k]);
        }
        r
    };
    loop {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let best = simplex[0].0;
        let size = simplex[1..]
            .iter()
            .flat_map(|(x, _)| x.iter().zip(&best).map(|(a, b)| (a - b).abs()))
            .fold(0.0, f64::max);
        if size <= tol || evals >= max_evals {
            break;
        }
        let mut c = [0.0; D];
        for (x, _) in &simplex[..D] {
            for k in 0..D {
                c[k] += x[k] / D as f64;
            }
        }
        let (xw, fw) = simplex[D];
        let xr = lerp(&c, &xw, -1.0);
        let fr = eval(&xr, &mut evals);
        if fr < simplex[0].1 {
            let xe = lerp(&c, &xw, -2.0);
            let fe = eval(&xe, &mut evals);
            simplex[D] = if fe < fr { (xe, fe) } else { (xr, fr) };
            continue;
        }
        if fr < simplex[D - 1].1 {
            simplex[D] = (xr, fr);
            continue;
        }
        let (xc, fc) = if fr < fw {
            let xc = lerp(&c, &xr, 0.5);
            (xc, eval(&xc, &mut evals))
        } else {
            let xc = lerp(&c, &xw, 0.5);
            (xc, eval(&xc, &mut evals))
        };
        if fc < fr.min(fw) {
            simplex[D] = (xc, fc);
            continue;
        }
        for vertex in simplex.iter_mut().skip(1) {
            let x = lerp(&best, &vertex.0, 0.5);
            *vertex = (x, eval(&x, &mut evals));
        }
    }
    (simplex[0].0, simplex[0].1, evals)
}

/// Prints the fit's L¹ error and horizon leak per roughness band.
fn print_summary(size: usize, reports: &[FitReport]) {
    let bands = [
        (1e-4, 1e-3),
        (1e-3, 1e-2),
        (1e-2, 1e-1),
        (1e-1, 0.4),
        (0.4, 1.0 + 1e-9),
    ];
    println!("band α          entries  mean L1   worst L1  (at α, θ°)          min upper mass");
    for (lo, hi) in bands {
        let mut n = 0;
        let (mut sum, mut worst, mut at, mut minup) = (0.0, 0.0, (0.0, 0.0), 1.0f64);
        for i in 0..size {
            let a = alpha_node(i, size);
            if !(a >= lo && a < hi) {
                continue;
            }
            for j in 0..size {
                let r = &reports[i * size + j];
                n += 1;
                sum += r.l1;
                if r.l1 > worst {
                    worst = r.l1;
                    at = (a, theta_node(j, size).to_degrees());
                }
                minup = minup.min(r.upper_mass);
            }
        }
        if n > 0 {
            println!(
                "[{lo:.0e}, {hi:.0e}) {n:8}  {:.5}   {worst:.5}   ({:.2e}, {:.3})      {minup:.4}",
                sum / n as f64,
                at.0,
                at.1
            );
        }
    }
    let evals: usize = reports.iter().map(|r| r.evaluations).sum();
    println!(
        "objective evaluations: {evals} ({:.0} per entry)",
        evals as f64 / reports.len() as f64
    );
}
