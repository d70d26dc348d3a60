//! `bspvt report --quick` on the built-in plate-small at a tiny size (the CI smoke test), and
//! the ratio estimator of stochastic shadows against LTC with ray-traced visibility.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeSet;

use bspvt_client::groundtruth::ltcvis::{builtin_lookup, render_ltc_exact_visibility};
use bspvt_client::light::Light;
use bspvt_client::penumbra::Guide;
use bspvt_client::ratio::render_ratio;
use bspvt_client::render::renderer::Renderer;
use bspvt_lab::compare::metrics::{covered, rmse_mae};
use bspvt_lab::report::{ReportArgs, run};
use bspvt_raytrace::{Occluder, mesh_triangles};

fn args(out: &std::path::Path) -> ReportArgs {
    ReportArgs {
        scenes: vec!["plate-small".into(), "no-such-mesh.obj".into()],
        quick: true,
        size: Some(40),
        frames: Some(1),
        meshes_dir: None,
        env: None,
        no_env: false,
        cache: None,
        out: out.to_path_buf(),
    }
}

#[test]
fn quick_report_measures_every_method_and_reuses_its_cache() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("report");
    let report = run(&args(&out)).unwrap();
    assert_eq!(report.scenes.len(), 1);
    assert!(
        report
            .skipped
            .iter()
            .any(|s| s.contains("no-such-mesh.obj"))
    );
    let sc = &report.scenes[0];
    assert!(!sc.ground_truth.from_cache);
    assert!(sc.bakes.iter().all(|b| !b.from_cache && b.bytes > 0));

    // Every family, every setting of the quick plan.
    let families: BTreeSet<&str> = sc.entries.iter().map(|e| e.method.as_str()).collect();
    let expected = [
        "bspvt",
        "ltc",
        "ltc-exact",
        "mc",
        "pcf",
        "pcss",
        "ratio",
        "ratio-denoised",
        "rt-hard",
        "rt-penumbra",
        "vsm",
    ];
    assert_eq!(families, expected.into_iter().collect());
    let count = |m: &str| sc.entries.iter().filter(|e| e.method == m).count();
    assert_eq!(count("bspvt"), 2 * 2, "two bakes × two modes");
    assert_eq!(count("mc"), report.settings.spp.len());
    for e in &sc.entries {
        let m = &e.metrics;
        for v in [m.rmse, m.rel_mse, m.mae, e.ms_per_frame] {
            assert!(v.is_finite() && v >= 0.0, "{}: {m:?}", e.label());
        }
        assert!((0.0..=1.0).contains(&m.flip), "{}: {m:?}", e.label());
        assert!(
            (0.0..=1.0).contains(&m.share_over_8),
            "{}: {m:?}",
            e.label()
        );
        assert!(out.join(&e.image).is_file(), "{} missing", e.image);
        assert!(out.join(&e.heat_map).is_file(), "{} missing", e.heat_map);
    }
    // The numbers mean something: the shadows of plate-small matter, so every shadowed
    // analytic method is far closer to the ground truth than unshadowed LTC, and Monte Carlo
    // converges.
    let rmse = |label: &str| {
        sc.entries
            .iter()
            .find(|e| e.label() == label)
            .unwrap_or_else(|| panic!("no {label}"))
            .metrics
            .rmse
    };
    let unshadowed = rmse("ltc pixel");
    // Where the ground truth is in an umbra (issue 35): unshadowed LTC puts all its light there
    // (the lit level itself), BSPVT per pixel next to none.
    let umbra = |label: &str| {
        sc.entries
            .iter()
            .find(|e| e.label() == label)
            .and_then(|e| e.umbra)
            .unwrap_or_else(|| panic!("{label}: no umbra in view"))
    };
    let lit = umbra("ltc pixel");
    assert!(lit.pixels > 0 && (lit.mean - 1.0).abs() < 1e-3, "{lit:?}");
    let bspvt = umbra("bspvt 64² ε=1e-3 pixel");
    assert!(bspvt.mean < 0.1 && bspvt.p99 <= 1.0, "{bspvt:?}");
    for l in [
        "bspvt 64² ε=1e-3 pixel",
        "bspvt 32² ε=1e-3 vertex",
        "ltc-exact 512 spp",
    ] {
        assert!(
            rmse(l) < 0.5 * unshadowed,
            "{l}: {} vs {unshadowed}",
            rmse(l)
        );
    }
    assert!(rmse("mc 64 spp") < 0.5 * rmse("mc 1 spp"));
    assert_eq!(sc.budget.len(), 4);
    for b in &sc.budget {
        assert!(b.visibility_share.is_finite() && b.ltc_fit_share.is_finite());
    }
    assert_eq!(sc.equal_time.len(), 4);

    // Environment lighting, against its own ground truth, when the shared map is there.
    match &sc.env {
        Some(env) => {
            assert!(!env.dark, "the plate is open to the sky");
            let methods: BTreeSet<&str> = env.entries.iter().map(|e| e.method.as_str()).collect();
            assert_eq!(
                methods,
                [
                    "bspvt-env",
                    "bspvt-env-cells",
                    "bspvt-env-pixel",
                    "mc-env",
                    "sg-exact",
                    "sg-screen",
                    "sg-unshadowed"
                ]
                .into_iter()
                .collect()
            );
            for e in &env.entries {
                let m = &e.metrics;
                assert!(m.rmse.is_finite() && m.flip.is_finite(), "{}", e.label());
                assert!(out.join(&e.image).is_file());
            }
            let env_rmse = |m: &str| {
                env.entries
                    .iter()
                    .find(|e| e.method == m)
                    .unwrap()
                    .metrics
                    .rmse
            };
            // The SSDF's visibility brings SG shading closer to the truth than none, and the
            // sky through its trees closer than either (k = 1, 2, 4 in the quick report).
            assert!(env_rmse("sg-screen") < env_rmse("sg-unshadowed"));
            let sky: Vec<_> = env
                .entries
                .iter()
                .filter(|e| e.method == "bspvt-env")
                .collect();
            assert_eq!(sky.len(), 3);
            assert!(sky.iter().all(|e| e.metrics.rmse < env_rmse("sg-screen")));
            // The cells (the shared map has no sun): within 10 % of the pieces' error at k = 2.
            let k2 = sky[1].metrics.rmse; // k = 1, 2, 4 in that order
            let cells = env_rmse("bspvt-env-cells");
            assert!(cells < 1.1 * k2, "cells {cells} vs pieces {k2}");
            assert!(env.fits.iter().all(|f| f.1.is_finite() && f.1 < 1.0));
        }
        None => {
            assert!(
                report.skipped.iter().any(|s| s.contains("environment")),
                "{:?}",
                report.skipped
            );
            eprintln!("environment lighting skipped: no map in ../shared/assets");
        }
    }

    // The files a reader opens.
    for f in ["report.md", "results.csv", "bakes.csv", "results.json"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert!(out.join(&sc.grid).is_file());
    if sc.plots.is_empty() {
        // Only when no font could be found, and the report says so.
        assert!(
            report.skipped.iter().any(|s| s.contains("font")),
            "{:?}",
            report.skipped
        );
        eprintln!("plots skipped: no TrueType font on this machine");
    } else {
        for p in &sc.plots {
            let img = image::open(out.join(p)).unwrap();
            assert_eq!((img.width(), img.height()), (900, 600));
        }
    }
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let env_rows = sc.env.as_ref().map_or(0, |e| e.entries.len());
    assert_eq!(csv.lines().count(), 1 + sc.entries.len() + env_rows);
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("## plate-small") && md.contains("### Error budget"));

    // A rerun finds the ground truth and the bakes in the cache, and the same ground truth.
    let again = run(&args(&out)).unwrap();
    let sc2 = &again.scenes[0];
    assert!(sc2.ground_truth.from_cache);
    assert!(sc2.bakes.iter().all(|b| b.from_cache));
    assert_eq!(sc2.ground_truth.spp_mean, sc.ground_truth.spp_mean);
    assert_eq!(
        sc2.entries
            .iter()
            .find(|e| e.method == "ltc-exact")
            .unwrap()
            .metrics,
        sc.entries
            .iter()
            .find(|e| e.method == "ltc-exact")
            .unwrap()
            .metrics
    );
}

/// Heitz et al. 2018: the ratio estimator is exact wherever every sample is visible, converges
/// to LTC × the BRDF-weighted visibility, and its denoised form has less error at few samples.
#[test]
fn ratio_estimator_is_exact_when_unoccluded_and_converges() {
    let scene = bspvt_proto::builtin::scene("plate-small").unwrap();
    let r = Renderer::new(&scene, 48, 40);
    let light = Light::load(&scene.lights[0]).unwrap();
    let occ = Occluder::new(&scene.mesh, &mesh_triangles(&scene.mesh));
    let guide = Guide::new(&r);
    let cov = covered(&r.gbuffer);
    let unshadowed = r.shade_pixels(std::slice::from_ref(&light), None);
    let exact = render_ltc_exact_visibility(
        &scene,
        &r.view,
        &r.gbuffer,
        &light,
        &occ,
        &builtin_lookup,
        1024,
        7,
    );
    let ratio = |spp, denoise| render_ratio(&r, &guide, &light, &occ, spp, 11, denoise);

    // Unoccluded pixels (1024 exact rays all visible) that the light reaches well above their
    // horizon (at grazing light the BRDF samples and the LTC rays see different slivers): the
    // ratio is exactly 1.
    let few = ratio(4, None);
    let floor = 0.05 * bspvt_lab::compare::metrics::covered_mean(&unshadowed, &cov) as f32;
    let mut lit = 0;
    for (i, &c) in cov.iter().enumerate() {
        if c && exact.pixels[i] == unshadowed.pixels[i] && unshadowed.pixels[i][0] > floor {
            assert_eq!(few.pixels[i], unshadowed.pixels[i], "pixel {i}");
            lit += 1;
        }
    }
    assert!(lit > 100, "{lit} unoccluded pixels");

    let (base, _) = rmse_mae(&unshadowed, &exact, &cov);
    let (many, _) = rmse_mae(&ratio(256, None), &exact, &cov);
    assert!(
        many < 0.25 * base,
        "ratio 256 spp {many} vs unshadowed {base}"
    );
    let (noisy, _) = rmse_mae(&few, &exact, &cov);
    let (denoised, _) = rmse_mae(&ratio(4, Some(3.0)), &exact, &cov);
    assert!(denoised < noisy, "denoised {denoised} vs {noisy}");
}
