//! rt-penumbra (paper 003) on the GPU (`--backend gpu`: the hard shadow rays in
//! `first_hit.wgsl` over the scene's BVH, the edge-aware blur in `penumbra.wgsl`) against the
//! CPU, on the built-in plate, the alpha-masked canopy and the room lit by glTF punctual
//! lights: the same hard shadow up to the device's rounding on grazing rays, the same soft
//! shadow up to f32's, and through the method registry as the CLI draws it (the unshadowed
//! shading then from the GPU's frames too) the frame within the GPU methods' bound. Skips
//! (with a message) where no adapter exists.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use bspvt_client::frame::image::Image;
use bspvt_client::gpu::shadow_rays::GpuShadowRays;
use bspvt_client::gpu::{Backend, Gpu};
use bspvt_client::light::Light;
use bspvt_client::method::Settings;
use bspvt_client::penumbra::{self, Guide, Params, Technique, rt};
use bspvt_client::render::renderer::{Mode, Renderer};
use bspvt_proto::Scene;
use bspvt_raytrace::Occluder;

mod common;

fn gpu() -> Option<&'static Gpu> {
    match Gpu::shared() {
        Ok(g) => {
            eprintln!("adapter: {}", g.adapter);
            Some(g)
        }
        Err(e) => {
            eprintln!(
                "SKIPPED: no GPU adapter ({e:#}); CI installs lavapipe (mesa-vulkan-drivers)"
            );
            None
        }
    }
}

fn room(name: &str) -> Scene {
    let rooms = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/rooms");
    Scene::from_mesh_path(&rooms.join(name)).unwrap()
}

/// One frame of `method` with `backend` per pixel through the registry, as `bspvt render`
/// draws it.
fn frame(scene: &Scene, r: &Renderer, method: &str, backend: Backend) -> Image {
    let settings = Settings {
        backend,
        mode: Mode::Pixel,
        ..Settings::default()
    };
    common::registry_frame(method, scene, r, &settings, None, None)
}

/// The share of pixels whose colour differs by more than 10⁻² of the frame's peak, and the
/// mean difference over the peak; panics on NaN or Inf.
fn differences(cpu: &Image, gpu: &Image) -> (f64, f64) {
    let peak = cpu
        .pixels
        .iter()
        .flatten()
        .fold(0.0f32, |m, &x| m.max(x))
        .max(1e-20);
    let mut off = 0usize;
    let mut sum = 0.0f64;
    for (a, b) in cpu.pixels.iter().zip(&gpu.pixels) {
        assert!(b.iter().all(|x| x.is_finite()), "{b:?}");
        let d = (0..3).map(|c| (a[c] - b[c]).abs()).fold(0.0, f32::max) / peak;
        sum += f64::from(d);
        if d > 1e-2 {
            off += 1;
        }
    }
    let n = cpu.pixels.len() as f64;
    (off as f64 / n, sum / n)
}

#[test]
fn gpu_shadow_rays_give_the_cpus_penumbrae() {
    let Some(gpu) = gpu() else {
        return;
    };
    let cases = [
        (
            "plate-small",
            bspvt_proto::builtin::scene("plate-small").unwrap(),
        ),
        ("checker-canopy.gltf", room("checker-canopy.gltf")),
        ("punctual-room.gltf", room("punctual-room.gltf")),
    ];
    for (name, scene) in cases {
        let r = Renderer::new(&scene, 128, 96);
        let guide = Guide::new(&r);
        let occ = Occluder::of_surfaces(&scene.mesh, &scene.materials);
        let rays = GpuShadowRays::new(gpu, &occ, false).unwrap();
        // The hard shadow pass from the first light polygon's centroid (the punctual room
        // has none: its lights are points, drawn through the registry below).
        if let Some(l) = scene.lights.first() {
            let light = Light::load(l).unwrap();
            let cpu_hard = rt::hard_shadows(&guide, &light, &occ, 1e-4).unwrap();
            let gpu_hard = rt::hard_shadows(&guide, &light, &rays, 1e-4).unwrap();
            let shadowed = cpu_hard.radius.iter().filter(|&&w| w > 0.0).count();
            let flipped = cpu_hard
                .radius
                .iter()
                .zip(&gpu_hard.radius)
                .filter(|(a, b)| (**a > 0.0) != (**b > 0.0))
                .count();
            let n = cpu_hard.radius.len();
            eprintln!("{name}: {shadowed} of {n} pixels in the hard shadow, {flipped} flipped");
            assert!(
                shadowed > n / 50,
                "{name}: the light casts a shadow in view"
            );
            assert!(flipped * 1000 <= n, "{name}: {flipped} pixels flipped");
            // The blur on the GPU (`penumbra.wgsl`, f32) against the CPU's (f64), of the
            // split light's fractions (`Params::split`: the rays of both through the caster).
            let params = Params::default();
            let all = GpuShadowRays::new(gpu, &occ, true).unwrap();
            let factor = |c: &dyn rt::ShadowCaster| {
                penumbra::shadow_factor(&r, &guide, &light, Technique::RtPenumbra, Some(c), &params)
                    .unwrap()
            };
            let (cpu_soft, gpu_soft) = (factor(&occ), factor(&all));
            let soft = cpu_soft.iter().filter(|&&s| s > 0.01 && s < 0.99).count();
            let mut worst = 0.0f32;
            let mut off = 0;
            for (a, b) in cpu_soft.iter().zip(&gpu_soft) {
                assert!(
                    b.is_finite() && (0.0..=1.0).contains(b),
                    "{name}: factor {b}"
                );
                worst = worst.max((a - b).abs());
                off += usize::from((a - b).abs() > 1e-3);
            }
            eprintln!(
                "{name}: {soft} pixels in a penumbra; the GPU's blur: {off} pixels off by > 1e-3, \
                 largest |Δ| {worst:.2e}"
            );
            assert!(soft > n / 100, "{name}: the blur makes penumbrae");
            assert!(off * 1000 <= n, "{name}: {off} pixels blurred otherwise");
        }
        // Through the registry, as `bspvt render --method rt-penumbra --backend gpu`: the
        // unshadowed per-pixel LTC then comes from the GPU's frames (MSAA 4×, f32), so the
        // frames compare within the GPU methods' bound (tests/gpu_frames.rs: under 10 % of
        // the pixels off by more than 1 % of the peak, mostly the anti-aliased edges; mean
        // under 1 %).
        let cpu = frame(&scene, &r, "rt-penumbra", Backend::Cpu);
        let on_gpu = frame(&scene, &r, "rt-penumbra", Backend::Gpu);
        let (off, mean) = differences(&cpu, &on_gpu);
        eprintln!(
            "{name}: rt-penumbra frames, {:.2} % of pixels differ by > 1 % of the peak, mean \
             |Δ| {mean:.2e} of the peak",
            100.0 * off
        );
        assert!(off < 0.1 && mean < 1e-2, "{name}: {off} {mean}");
        // Polygon lights are shaded by the GPU's frames (their f32 differs); the punctual
        // room's points are shaded on the CPU, their unblurred shadows the same.
        assert!(
            (mean > 0.0) != scene.lights.is_empty(),
            "{name}: mean |Δ| {mean}: who shaded the frame?"
        );
    }
}
