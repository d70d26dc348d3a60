//! The report's files: `report.md` (tables), `results.csv` (one row per method and setting),
//! `bakes.csv` (the amortised precompute), `results.json` (everything).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};

use super::Report;
use super::analysis::{EQUAL_TIME_TARGET, Reading, VISIBILITY_TARGET};
use super::scene::SceneReport;
use crate::bench::file_stem;

pub(crate) fn write_all(report: &Report, out: &Path) -> Result<()> {
    let write = |name: &str, text: String| {
        let p = out.join(name);
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))
    };
    write("results.csv", results_csv(report))?;
    write("bakes.csv", bakes_csv(report))?;
    write("report.md", markdown(report))?;
    write("results.json", serde_json::to_string_pretty(report)?)
}

fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

pub(crate) fn results_csv(report: &Report) -> String {
    let mut s = String::from(
        "scene,method,mode,face_res,epsilon,lobes,spp,ms_per_frame,rmse,rel_mse,mae,flip,share_over_8,umbra_leak_mean,umbra_leak_p99,image\n",
    );
    for sc in &report.scenes {
        let env = sc.env.iter().flat_map(|v| &v.entries);
        for e in sc.entries.iter().chain(env) {
            let m = &e.metrics;
            let _ = writeln!(
                s,
                "{},{},{},{},{},{},{},{:.4},{:.6e},{:.6e},{:.6e},{:.6},{:.6},{},{},{}",
                sc.name,
                e.method,
                opt(e.mode.map(|m| format!("{m:?}").to_lowercase())),
                opt(e.face_res),
                opt(e.epsilon),
                opt(e.lobes),
                opt(e.spp),
                e.ms_per_frame,
                m.rmse,
                m.rel_mse,
                m.mae,
                m.flip,
                m.share_over_8,
                opt(e.umbra.map(|u| format!("{:.6}", u.mean))),
                opt(e.umbra.map(|u| format!("{:.6}", u.p99))),
                e.image
            );
        }
    }
    s
}

pub(crate) fn bakes_csv(report: &Report) -> String {
    let mut s = String::from(
        "scene,face_res,epsilon,vertices,seconds,threads,ms_per_vertex_per_thread,bytes,bytes_per_vertex\n",
    );
    for sc in &report.scenes {
        for b in &sc.bakes {
            let _ = writeln!(
                s,
                "{},{},{},{},{:.2},{},{:.4},{},{:.1}",
                sc.name,
                b.face_res,
                b.epsilon,
                b.vertices,
                b.seconds,
                b.threads,
                b.ms_per_vertex_per_thread,
                b.bytes,
                b.bytes_per_vertex
            );
        }
    }
    s
}

fn pct(x: f64) -> String {
    format!("{:.2} %", 100.0 * x)
}

pub(crate) fn markdown(report: &Report) -> String {
    let st = &report.settings;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Error against run time\n\n`bspvt report{q}`: {size}×{size} images, {threads} thread(s); fast methods \
         timed as the median of {frames} frames after a warm-up (one frame when a frame takes over a \
         second); the G-buffer (once per camera) and the trees' decoding (once per stream) are not \
         in the frame time. Whole run: {secs:.0} s.\n",
        q = if st.quick { " --quick" } else { "" },
        size = st.size,
        threads = report.threads,
        frames = st.frames,
        secs = report.seconds,
    );
    let _ = writeln!(
        s,
        "Ground truth: Monte Carlo with the exact GGX BRDF and shadow rays (MIS of light and \
         BRDF sampling) until each pixel's relative standard error is ≤ {} ({}–{} spp), cached. \
         Errors are over the pixels that see a surface, in linear radiance (RMSE, relative MSE \
         with floor 1 % of the mean, MAE), and on the tone-mapped PNG (mean LDR-FLIP; share of \
         pixels off by more than 8 % of the display range in some channel).\n",
        pct(st.gt_target_rel_stderr),
        st.gt_min_spp,
        st.gt_max_spp
    );
    for m in &report.skipped {
        let _ = writeln!(s, "- skipped: {m}");
    }
    if !report.skipped.is_empty() {
        s.push('\n');
    }
    summary(&mut s, report);
    for sc in &report.scenes {
        scene_section(&mut s, sc, report);
    }
    s
}

fn summary(s: &mut String, report: &Report) {
    let _ = writeln!(
        s,
        "## Targets\n\n| scene | BSPVT visibility part (default bake, per pixel) | target ≤ {} | best BSPVT RMSE / best stochastic at equal time | target ≤ {} |\n|---|---:|---|---:|---|",
        pct(VISIBILITY_TARGET),
        EQUAL_TIME_TARGET
    );
    let (res, eps) = report.settings.budget_bake();
    for sc in &report.scenes {
        let b = sc.budget.iter().find(|b| {
            b.face_res == res
                && b.epsilon == eps
                && b.mode == bspvt_client::render::renderer::Mode::Pixel
        });
        let best = sc
            .equal_time
            .iter()
            .min_by(|a, b| a.ratio.total_cmp(&b.ratio));
        let yes = |m: bool| if m { "met" } else { "**not met**" };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} |",
            sc.name,
            b.map(|b| pct(b.visibility_share)).unwrap_or_default(),
            b.map(|b| yes(b.visibility_target_met)).unwrap_or_default(),
            best.map(|e| format!("{:.3} ({})", e.ratio, e.bspvt))
                .unwrap_or_default(),
            best.map(|e| yes(e.target_met)).unwrap_or_default(),
        );
    }
    s.push('\n');
}

fn scene_section(s: &mut String, sc: &SceneReport, report: &Report) {
    let gt = &sc.ground_truth;
    let _ = writeln!(
        s,
        "## {}\n\n{} vertices, {} triangles, {} pixels covered. Ground truth: {:.0} spp on \
         average (max {}), mean relative standard error {}, its own RMSE ≈ {:.2e} (the floor \
         under every RMSE below); {:.1} s on {} threads{}. LTC with exact visibility: {} shadow \
         rays per pixel (two estimates), its noise RMSE ≈ {:.2e}, MAE ≈ {:.2e}. Mean \
         unshadowed radiance {:.4}.\n",
        sc.name,
        sc.vertices,
        sc.triangles,
        sc.pixels_covered,
        gt.spp_mean,
        gt.spp_max,
        pct(gt.mean_rel_stderr),
        gt.rmse_floor,
        gt.seconds,
        gt.threads,
        if gt.from_cache {
            ", from the cache"
        } else {
            ""
        },
        sc.exact.spp,
        sc.exact.rmse_noise,
        sc.exact.mae_noise,
        sc.unshadowed_mean
    );
    let _ = writeln!(
        s,
        "![{0} grid]({1})\n\nTop: each method; below: |error| against the ground truth (black 0 → \
         blue → red → yellow → white at half the mean radiance).\n",
        sc.name, sc.grid
    );
    for p in sc.plots.iter().filter(|p| !p.contains("/env/")) {
        let _ = writeln!(s, "![{} plot]({p})\n", sc.name);
    }
    let _ = writeln!(
        s,
        "### Bakes (amortised precompute)\n\n| face | ε | vertices | wall s | threads | ms/vertex/thread | bytes | B/vertex |\n|---|---|---:|---:|---:|---:|---:|---:|"
    );
    for b in &sc.bakes {
        let _ = writeln!(
            s,
            "| {0}² | {1:.0e} | {2} | {3:.1}{4} | {5} | {6:.3} | {7} | {8:.1} |",
            b.face_res,
            b.epsilon,
            b.vertices,
            b.seconds,
            if b.from_cache { " (cached)" } else { "" },
            b.threads,
            b.ms_per_vertex_per_thread,
            b.bytes,
            b.bytes_per_vertex
        );
    }
    let _ = writeln!(
        s,
        "\n### Methods\n\nEach method's image and error map are `{}/<method>.png` and \
         `<method>-error.png` in the report's folder (`results.csv` names them).\n\n| method | ms/frame | RMSE | rel. MSE | MAE | FLIP | > 8 % | umbra leak mean / p99 |\n|---|---:|---:|---:|---:|---:|---:|---:|",
        file_stem(&sc.name)
    );
    method_rows(s, &sc.entries);
    let _ = writeln!(
        s,
        "\n### Error budget of BSPVT (mean absolute error)\n\nLTC-fit part: LTC with exact \
         visibility vs ground truth. Visibility part: BSPVT vs LTC with exact visibility (in \
         per-vertex mode it includes the interpolation across triangles; the reference's own \
         noise, MAE ≈ {:.2e}, is included). Shares are of the mean unshadowed radiance.\n\n\
         | bake | mode | total MAE | visibility | LTC fit | visibility share | ≤ {} |\n|---|---|---:|---:|---:|---:|---|",
        sc.exact.mae_noise,
        pct(VISIBILITY_TARGET)
    );
    for b in &sc.budget {
        let _ = writeln!(
            s,
            "| {}² ε={:.0e} | {:?} | {:.3e} | {:.3e} | {:.3e} | {} | {} |",
            b.face_res,
            b.epsilon,
            b.mode,
            b.total_mae,
            b.visibility_mae,
            b.ltc_fit_mae,
            pct(b.visibility_share),
            if b.visibility_target_met {
                "met"
            } else {
                "**not met**"
            }
        );
    }
    let _ = writeln!(
        s,
        "\n### BSPVT against the best stochastic method at equal frame time\n\nStochastic: Monte \
         Carlo shadow rays, the ratio estimator, and the ratio estimator denoised ({} px \
         edge-aware box), at {} spp; their RMSE at BSPVT's frame time is read log-log between \
         sample counts.\n\n| BSPVT | ms/frame | RMSE | best stochastic | its RMSE | read | ratio | ≤ {} |\n|---|---:|---:|---|---:|---|---:|---|",
        report.settings.denoise_radius,
        report
            .settings
            .spp
            .iter()
            .map(u32::to_string)
            .collect::<Vec<_>>()
            .join(", "),
        EQUAL_TIME_TARGET
    );
    for e in &sc.equal_time {
        let read = match e.reading {
            Reading::Interpolated => "interpolated",
            Reading::SlowerAtOneSample => "1 spp is slower",
            Reading::Extrapolated => "extrapolated t^-½",
        };
        let _ = writeln!(
            s,
            "| {} | {:.2} | {:.3e} | {} | {:.3e} | {} | {:.3} | {} |",
            e.bspvt,
            e.ms_per_frame,
            e.rmse,
            e.best,
            e.best_rmse,
            read,
            e.ratio,
            if e.target_met { "met" } else { "**not met**" }
        );
    }
    s.push('\n');
    if let Some(env) = &sc.env {
        env_section(s, sc, env);
    }
}

/// One table row per entry: label, ms/frame and every metric.
fn method_rows(s: &mut String, entries: &[super::scene::Entry]) {
    for e in entries {
        let m = &e.metrics;
        let _ = writeln!(
            s,
            "| {} | {:.2} | {:.3e} | {:.3e} | {:.3e} | {:.4} | {} | {} |",
            e.label(),
            e.ms_per_frame,
            m.rmse,
            m.rel_mse,
            m.mae,
            m.flip,
            pct(m.share_over_8),
            e.umbra.map_or("–".into(), |u| format!(
                "{} / {}",
                pct(u.mean),
                pct(u.p99)
            ))
        );
    }
}

fn env_section(s: &mut String, sc: &SceneReport, env: &super::env::EnvReport) {
    let _ = writeln!(
        s,
        "### Environment lighting (paper 001)\n\nMap `{}`. Its own ground truth: Monte Carlo \
         with the exact GGX BRDF and shadow rays, the map importance-sampled, {} spp (mean \
         relative standard error {}, own RMSE ≈ {:.2e}; {:.1} s{}). SG methods: the map fitted \
         with K lobes (precompute per map), shaded per pixel with visibility from the \
         screen-space SSDF (`sg-screen`, depth maps rendered every frame: dynamic scenes), the \
         exact ray-cast SSDF (`sg-exact`) or none (`sg-unshadowed`).\n",
        env.map,
        env.gt_spp,
        pct(env.gt_mean_rel_stderr),
        env.gt_rmse_floor,
        env.gt_seconds,
        if env.gt_from_cache {
            ", from the cache"
        } else {
            ""
        }
    );
    if env.dark {
        let _ = writeln!(
            s,
            "The ground truth is black on every pixel the camera sees: no path from them \
             reaches the map (a closed scene). The environment methods are not measured here.\n"
        );
        return;
    }
    let _ = writeln!(
        s,
        "| K | fit error (relative L2) | fit s |\n|---:|---:|---:|"
    );
    for (k, err, secs) in &env.fits {
        let _ = writeln!(s, "| {k} | {} | {secs:.2} |", pct(*err));
    }
    let _ = writeln!(
        s,
        "\n| method | ms/frame | RMSE | rel. MSE | MAE | FLIP | > 8 % | umbra leak mean / p99 |\n|---|---:|---:|---:|---:|---:|---:|---:|"
    );
    method_rows(s, &env.entries);
    let _ = writeln!(
        s,
        "\n![{} environment plot]({}/env/rmse-vs-time.png)\n",
        sc.name,
        file_stem(&sc.name)
    );
}
