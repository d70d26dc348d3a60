//! `bspvt bench-penumbra --quick` on plate-small at a tiny size: every output exists and every
//! number is finite.
#![allow(clippy::unwrap_used)]

use bspvt_lab::penumbra_bench::{BenchPenumbraArgs, SpeedUp, run};

#[test]
fn quick_bench_writes_finite_results() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bp");
    let args = BenchPenumbraArgs {
        scenes: vec!["plate-small".into(), "no-such-mesh.obj".into()],
        size: Some(40),
        quick: true,
        ref_spp: Some(16),
        frames: None,
        base_only: false,
        meshes_dir: None,
        out: out.clone(),
        // The shadow rays on the GPU too where there is an adapter (lavapipe in CI).
        gpu: bspvt_client::gpu::Gpu::shared().is_ok(),
    };
    let gpu = args.gpu;
    eprintln!("GPU rows: {gpu}");
    let report = run(&args).unwrap();
    if gpu {
        for c in &report.cases {
            let rmse = |m: &str| c.rows.iter().find(|r| r.method == m).unwrap().rmse;
            // The same rays answered by another machine: the same error.
            let cpu = rmse("rt-penumbra");
            for m in ["rt-penumbra-gpu", "rt-penumbra-gpu-rays"] {
                let on_gpu = rmse(m);
                assert!(
                    (cpu - on_gpu).abs() <= 0.02 * cpu,
                    "{}: rt-penumbra RMSE {cpu} on the CPU, {on_gpu} as {m}",
                    c.case
                );
            }
            assert!(c.speed_up_gpu.is_some());
        }
    }
    // base, contact, overlap, big-light; the missing mesh is skipped, not an error.
    assert_eq!(report.cases.len(), 4);
    assert_eq!(report.skipped.len(), 1);
    for c in &report.cases {
        assert!(c.ref_rmse.is_finite() && c.ref_rmse >= 0.0);
        assert!(c.pixels_covered > 0);
        for r in &c.rows {
            assert!(r.ms_per_frame.is_finite() && r.ms_per_frame >= 0.0, "{r:?}");
            assert!(r.rmse.is_finite() && r.mae.is_finite(), "{r:?}");
        }
        let f = match c.speed_up {
            SpeedUp::Interpolated { spp, factor } => {
                assert!(spp.is_finite());
                factor
            }
            SpeedUp::AtLeast { factor, .. } | SpeedUp::WorseThanOneSpp { factor } => factor,
        };
        assert!(f.is_finite() && f > 0.0);
        let case_dir = out.join(format!("plate-small-{}", c.case));
        for f in [
            "reference.png",
            "rt-penumbra.png",
            "rt-penumbra-error.png",
            "pcss-error.png",
        ] {
            assert!(case_dir.join(f).is_file(), "{} missing", f);
        }
    }
    for f in ["results.csv", "results.md", "results.json"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("scene,case,method,spp,ms_per_frame,rmse,mae")
    );
    let mut n = 0;
    for line in lines {
        let cols: Vec<&str> = line.split(',').collect();
        assert_eq!(cols.len(), 7, "{line}");
        for v in cols[4..].iter().filter(|v| !v.is_empty()) {
            let x: f64 = v.parse().unwrap();
            assert!(x.is_finite(), "{line}");
        }
        n += 1;
    }
    // Per case: 5 methods + rt-penumbra-point (+ 3 on the GPU) + unshadowed + 5 MC spp
    // counts (quick: 1..16) + reference noise.
    assert_eq!(n, 4 * (13 + 3 * usize::from(gpu)));
}
