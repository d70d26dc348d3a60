//! `--backend`: without an adapter (Vulkan pointed at no driver, no other wgpu backend),
//! `auto` falls back to the CPU and says why, and `gpu` fails with a clear error. The adapter
//! is found once per process, so the checks run in a child process of this test binary.
#![allow(clippy::unwrap_used)]

use bspvt_client::gpu::Backend;

const CHILD: &str = "BSPVT_TEST_NO_ADAPTER_CHILD";

/// Run in the child only: the environment has no adapter.
#[test]
fn no_adapter_child() {
    if std::env::var_os(CHILD).is_none() {
        return;
    }
    let (gpu, line) = Backend::Auto.resolve().unwrap();
    assert!(gpu.is_none(), "an adapter was found: {line}");
    assert!(line.starts_with("backend: CPU (no GPU"), "{line}");
    eprintln!("auto: {line}");
    let e = Backend::Gpu.resolve().err().unwrap();
    let msg = format!("{e:#}");
    assert!(
        msg.contains("--backend gpu") && msg.contains("no GPU adapter"),
        "{msg}"
    );
    eprintln!("gpu: {msg}");
    let (gpu, line) = Backend::Cpu.resolve().unwrap();
    assert!(gpu.is_none() && line == "backend: CPU");
}

#[test]
fn without_an_adapter_auto_falls_back_and_gpu_fails() {
    let exe = std::env::current_exe().unwrap();
    let out = std::process::Command::new(exe)
        .args(["no_adapter_child", "--exact", "--nocapture"])
        .env(CHILD, "1")
        .env("WGPU_BACKEND", "vulkan")
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stderr);
    eprintln!("{text}");
    assert!(out.status.success(), "child failed:\n{text}");
    assert!(text.contains("auto: backend: CPU (no GPU"), "{text}");
}

/// No shader takes its parameters as a uniform buffer: lavapipe (the GPU path of CI and of
/// machines without a GPU) specializes a shader on the uniform values its branches read and
/// compiles it again whenever they change — a minute of LLVM on 2 cores for the resolve and
/// per-vertex passes, each time the light's vertex count, the visible vertices or the mode
/// changed (measured, docs/gpu.md). Parameters live in read-only storage buffers.
#[test]
fn no_shader_reads_a_uniform_buffer() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut seen = 0;
    for dir in ["proto/shaders/src/gpu", "proto/raytrace/src"] {
        for entry in std::fs::read_dir(root.join(dir)).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_none_or(|x| x != "wgsl") {
                continue;
            }
            let src = std::fs::read_to_string(&path).unwrap();
            seen += 1;
            assert!(
                !src.lines().any(|l| l.contains("var<uniform>")),
                "{} declares a uniform buffer; bind a read-only storage buffer instead",
                path.display()
            );
        }
    }
    assert!(seen >= 7, "found only {seen} WGSL files");
}
