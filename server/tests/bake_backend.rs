//! The GPU backend from the outside: `bspvt-server bake --backend gpu` and a service started
//! with `--bake-backend gpu` write the CPU bake's bytes; without a GPU adapter both refuse to
//! run, saying why. The GPU runs skip, saying so, where wgpu finds no adapter (CI installs
//! Mesa's lavapipe, a software Vulkan driver, so they run there).

#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use common::*;

/// `bspvt-server bake SCENE --out OUT` with extra flags and environment; the bytes, or the
/// failure's stderr.
fn bake(
    dir: &Path,
    scene: &Path,
    name: &str,
    extra: &[&str],
    env: &[(&str, &str)],
) -> Result<Vec<u8>, String> {
    let out = dir.join(format!("{name}.bspvt"));
    let mut cmd = Command::new(BIN);
    cmd.arg("bake")
        .arg(scene)
        .arg("--out")
        .arg(&out)
        .args(extra);
    for (k, v) in env {
        cmd.env(k, v);
    }
    let r = cmd.output().expect("run bspvt-server bake");
    if !r.status.success() {
        return Err(String::from_utf8_lossy(&r.stderr).into_owned());
    }
    Ok(std::fs::read(&out).expect("read the bake"))
}

/// wgpu with only the DirectX 12 backend: no adapter on Linux.
#[cfg(target_os = "linux")]
const NO_ADAPTER: (&str, &str) = ("WGPU_BACKEND", "dx12");

#[cfg(target_os = "linux")]
#[test]
fn gpu_backend_without_an_adapter_fails_clearly() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let scene = tmp.path().join("plate.json");
    std::fs::write(&scene, plate_small_json(8, 512)).expect("write scene");
    let err = bake(
        tmp.path(),
        &scene,
        "none",
        &["--backend", "gpu"],
        &[NO_ADAPTER],
    )
    .expect_err("a GPU bake without an adapter");
    assert!(err.contains("no GPU adapter found"), "stderr: {err}");
    assert!(
        !tmp.path().join("none.bspvt").exists(),
        "wrote a file anyway"
    );

    let out = Command::new(BIN)
        .args([
            "serve",
            "--addr",
            "127.0.0.1:0",
            "--bake-backend",
            "gpu",
            "--data-dir",
        ])
        .arg(tmp.path().join("data"))
        .env(NO_ADAPTER.0, NO_ADAPTER.1)
        .output()
        .expect("run bspvt-server serve");
    assert!(!out.status.success(), "the service started without a GPU");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no GPU adapter found"), "stderr: {err}");
}

#[test]
fn gpu_bake_and_gpu_service_write_the_cpu_bytes() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let json = plate_small_json(16, 512);
    let scene = tmp.path().join("plate.json");
    std::fs::write(&scene, &json).expect("write scene");
    let cpu = bake(tmp.path(), &scene, "cpu", &[], &[]).expect("CPU bake");
    let gpu = match bake(tmp.path(), &scene, "gpu", &["--backend", "gpu"], &[]) {
        Ok(b) => b,
        Err(e) if e.contains("no GPU adapter found") => {
            eprintln!("skipped: no GPU adapter ({})", e.trim());
            return;
        }
        Err(e) => panic!("GPU bake failed: {e}"),
    };
    assert!(
        gpu == cpu,
        "the GPU bake's bytes differ from the CPU bake's"
    );

    // Two workers share the GPU and the fit threads.
    let srv = start(
        &tmp.path().join("data"),
        &["--workers", "2", "--bake-backend", "gpu"],
    );
    let a = agent();
    let id = submit_ok(&a, &srv, &[("scene", None, json.as_bytes())], None);
    let t0 = Instant::now();
    wait_done(&a, &srv, &id);
    assert!(t0.elapsed() < Duration::from_secs(600));
    let r = get(&a, &srv.url(&format!("/v1/scenes/{id}/trees")));
    assert_eq!(r.status, 200);
    assert!(
        r.body == cpu,
        "the GPU service's bake differs from the CPU bake"
    );
    // The GPU's utilisation: busy for some of the bake, never longer than the process ran.
    let m = get(&a, &srv.url("/metrics"));
    let text = String::from_utf8_lossy(&m.body);
    let value = |name: &str| -> f64 {
        text.lines()
            .find_map(|l| l.strip_prefix(name)?.trim().parse().ok())
            .unwrap_or_else(|| panic!("{name} missing from /metrics:\n{text}"))
    };
    let busy = value("bspvt_gpu_busy_seconds_total ");
    let up = value("bspvt_uptime_seconds ");
    eprintln!("GPU busy {busy:.3} s of {up:.3} s up");
    assert!(busy > 0.0 && busy <= up, "GPU busy {busy} s, up {up} s");
}
