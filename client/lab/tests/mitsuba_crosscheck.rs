//! The independent cross-check: bspvt's Monte Carlo ground truth against Mitsuba 3 on the same
//! scenes (written by `bspvt_lab::mitsuba::export`), within Monte Carlo noise: the built-in
//! plate, mirror-like and two-sided-light variants, and the project's rooms given alone
//! (`assets/rooms`: the glTF room, the Cornell box OBJ/MTL, the two-lamp glTF room) with their
//! own lamps (all of them) and materials.
//!
//! Skipped (with a message) where `python3 -c "import mitsuba"` fails: `pip install mitsuba`.
//! Both renderers integrate each pixel with a box filter (ours: `render_mc_box`, jittered
//! primary rays; Mitsuba: `<rfilter type="box"/>`). Each pixel's difference is compared with
//! σ = √(σ_ours² + σ_mitsuba²): σ_ours from the per-sample variance, σ_mitsuba from the spread
//! of independent passes (render.py). Figures are printed; `docs/groundtruth.md` records them.
//!
//! Knobs (environment): BSPVT_XCHECK_SPP (our spp, default 2048), BSPVT_XCHECK_PASSES
//! (Mitsuba passes, default 16), BSPVT_XCHECK_PASS_SPP (spp per pass, default 128),
//! BSPVT_XCHECK_SEED (both renderers' seed, default 1), BSPVT_XCHECK_KEEP=DIR (keep the scenes
//! and images there).

use std::path::{Path, PathBuf};
use std::process::Command;

use bspvt_client::frame::camera::View;
use bspvt_client::frame::image::Image;
use bspvt_client::groundtruth::{Tracer, render_mc_box};
use bspvt_client::light::Light;
use bspvt_lab::mitsuba::{ExportOptions, export};
use bspvt_proto::Scene;
use bspvt_raytrace::Occluder;

const W: u32 = 64;
const H: u32 = 48;

fn env_u32(name: &str, default: u32) -> u32 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mitsuba/render.py")
}

fn mitsuba_available() -> bool {
    Command::new("python3")
        .args(["-c", "import mitsuba"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

fn read_exr(p: &Path) -> Image {
    let img = image::open(p)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", p.display()))
        .into_rgb32f();
    Image {
        width: img.width(),
        height: img.height(),
        pixels: img.pixels().map(|p| p.0).collect(),
    }
}

/// The specular test scenes: the plate-small geometry, every material `albedo 0, F0 1, α`,
/// seen from a camera that looks at the light's mirror image in the floor.
fn specular_scene(alpha: f32) -> Scene {
    let json = format!(
        r#"{{
        "meshes": [{{"path": "builtin:plate-small"}}],
        "materials": [
            {{"name": "floor", "roughness": {alpha}, "albedo": [0, 0, 0], "specular": [1, 1, 1]}},
            {{"name": "sphere", "roughness": {alpha}, "albedo": [0, 0, 0], "specular": [1, 1, 1]}},
            {{"name": "slab", "roughness": {alpha}, "albedo": [0, 0, 0], "specular": [1, 1, 1]}}
        ],
        "lights": [{{
            "vertices": [[-0.5, 3, -0.5], [0.5, 3, -0.5], [0.5, 3, 0.5], [-0.5, 3, 0.5]],
            "radiance": [12, 11, 10]
        }}],
        "camera": {{"position": [2.5, 2.0, 0.3], "target": [0, 0.3, 0], "fov_y_deg": 40}}
    }}"#
    );
    Scene::from_json(&json, Path::new(".")).expect("specular test scene")
}

/// The built-in plate-small scene lit by a vertical two-sided light between the sphere and
/// the slab (both faces light the floor; the camera sees the light, whose pixels are masked).
fn two_sided_scene() -> Scene {
    let json = r#"{
        "meshes": [{"path": "builtin:plate-small"}],
        "materials": [
            {"name": "floor", "roughness": 0.35, "albedo": [0.55, 0.55, 0.52], "specular": [0.04, 0.04, 0.04]},
            {"name": "sphere", "roughness": 0.15, "albedo": [0.6, 0.15, 0.1], "specular": [0.05, 0.05, 0.05]},
            {"name": "slab", "roughness": 0.5, "albedo": [0.2, 0.35, 0.6], "specular": [0.04, 0.04, 0.04]}
        ],
        "lights": [{
            "vertices": [[-0.1, 1.2, -0.5], [-0.1, 1.2, 0.5], [-0.1, 2.2, 0.5], [-0.1, 2.2, -0.5]],
            "radiance": [6, 6, 6],
            "two_sided": true
        }],
        "camera": {"position": [3.2, 3.0, 4.2], "target": [0, 0.5, 0], "fov_y_deg": 40}
    }"#;
    Scene::from_json(json, Path::new(".")).expect("two-sided test scene")
}

/// Pixels whose footprint may see the light polygon itself (Mitsuba stops camera rays there;
/// our renderers do not draw the light): the projected polygon's bounding box, dilated by a
/// pixel. Everything is masked if a light vertex is behind the camera.
fn light_mask(view: &View, light: &Light) -> Vec<bool> {
    let (w, h) = (view.width as usize, view.height as usize);
    let cam: Vec<_> = light.vertices.iter().map(|&v| view.to_camera(v)).collect();
    if cam.iter().any(|c| c.z <= 0.0) {
        return vec![true; w * h];
    }
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for c in cam {
        let (x, y) = view.to_image(c);
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
    }
    (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            x + 1.0 >= x0 - 1.0 && x <= x1 + 1.0 && y + 1.0 >= y0 - 1.0 && y <= y1 + 1.0
        })
        .collect()
}

struct Stats {
    pixels: usize,
    mean_ours: f64,
    mean_mitsuba: f64,
    /// Standard error of the difference of the image means.
    sigma_mean: f64,
    z_mean: f64,
    chi2_per_dof: f64,
    frac_z3: f64,
    frac_z4: f64,
    max_z: f64,
    median_rel_sigma: f64,
    block_chi2: f64,
    block_frac_z3: f64,
}

fn compare(ours: &Image, ours_se: &Image, mi: &Image, mi_se: &Image, mask: &[bool]) -> Stats {
    let (w, h) = (ours.width as usize, ours.height as usize);
    let mut zs = Vec::new();
    let (mut so, mut sm, mut var_sum, mut n) = (0.0, 0.0, 0.0, 0usize);
    let mut rel = Vec::new();
    for (i, _) in mask.iter().enumerate().filter(|(_, m)| !**m) {
        n += 1;
        for c in 0..3 {
            let (a, b) = (f64::from(ours.pixels[i][c]), f64::from(mi.pixels[i][c]));
            let (sa, sb) = (
                f64::from(ours_se.pixels[i][c]),
                f64::from(mi_se.pixels[i][c]),
            );
            so += a;
            sm += b;
            let var = sa * sa + sb * sb;
            var_sum += var;
            if var > 0.0 {
                zs.push((a - b) / var.sqrt());
                if b > 1e-3 {
                    rel.push(var.sqrt() / b);
                }
            } else {
                // Both exactly black (background, umbra): must agree.
                assert!((a - b).abs() < 1e-6, "pixel {i}: {a} vs {b} with no noise");
            }
        }
    }
    let k = (3 * n) as f64;
    // 8×8 blocks: means and their σ.
    let mut bz = Vec::new();
    for by in 0..h / 8 {
        for bx in 0..w / 8 {
            for c in 0..3 {
                let (mut d, mut v, mut m) = (0.0, 0.0, 0);
                for y in by * 8..by * 8 + 8 {
                    for x in bx * 8..bx * 8 + 8 {
                        let i = y * w + x;
                        if mask[i] {
                            continue;
                        }
                        d += f64::from(ours.pixels[i][c]) - f64::from(mi.pixels[i][c]);
                        v += f64::from(ours_se.pixels[i][c]).powi(2)
                            + f64::from(mi_se.pixels[i][c]).powi(2);
                        m += 1;
                    }
                }
                if m > 0 && v > 0.0 {
                    bz.push(d / v.sqrt());
                }
            }
        }
    }
    rel.sort_by(f64::total_cmp);
    let frac =
        |z: &[f64], t: f64| z.iter().filter(|x| x.abs() > t).count() as f64 / z.len().max(1) as f64;
    Stats {
        pixels: n,
        mean_ours: so / k,
        mean_mitsuba: sm / k,
        sigma_mean: var_sum.sqrt() / k,
        z_mean: (so - sm) / var_sum.sqrt().max(f64::MIN_POSITIVE),
        chi2_per_dof: zs.iter().map(|z| z * z).sum::<f64>() / zs.len().max(1) as f64,
        frac_z3: frac(&zs, 3.0),
        frac_z4: frac(&zs, 4.0),
        max_z: zs.iter().fold(0.0f64, |m, z| m.max(z.abs())),
        median_rel_sigma: rel.get(rel.len() / 2).copied().unwrap_or(0.0),
        block_chi2: bz.iter().map(|z| z * z).sum::<f64>() / bz.len().max(1) as f64,
        block_frac_z3: frac(&bz, 3.0),
    }
}

fn run_case(name: &str, scene: &Scene, dir: &Path) -> Stats {
    let spp = env_u32("BSPVT_XCHECK_SPP", 2048);
    let passes = env_u32("BSPVT_XCHECK_PASSES", 16);
    let pass_spp = env_u32("BSPVT_XCHECK_PASS_SPP", 128);
    let seed = env_u32("BSPVT_XCHECK_SEED", 1);
    let case_dir = dir.join(name);
    // Every light of the scene, in both renderers.
    let lights: Vec<Light> = bspvt_client::light::scene_lights(scene)
        .expect("lights")
        .into_iter()
        .map(|l| l.0)
        .collect();
    let opts = ExportOptions {
        width: W,
        height: H,
        spp: pass_spp,
    };
    let summary = export(scene, &lights, &opts, &case_dir).expect("export the Mitsuba scene");
    // The punctual room as exported says where Mitsuba's lights are not ours (its spot).
    // The checker canopy's texture is uniform in colour (only its alpha varies): its mean is it.
    if name == "punctual-room" || name == "checker-canopy" {
        eprintln!("[{name}] export: {:?}", summary.warnings);
    } else {
        assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    }

    let t = std::time::Instant::now();
    let out = Command::new("python3")
        .arg(script())
        .arg("render")
        .arg(&summary.scene_xml)
        .arg("--out")
        .arg(&case_dir)
        .args([
            "--spp",
            &pass_spp.to_string(),
            "--passes",
            &passes.to_string(),
        ])
        .args(["--seed", &seed.to_string()])
        .output()
        .expect("run render.py");
    assert!(
        out.status.success(),
        "render.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let t_mi = t.elapsed().as_secs_f64();

    let t = std::time::Instant::now();
    let view = View::new(&scene.camera, W, H);
    let tracer = Tracer::of_scene(scene);
    let occluder = Occluder::of_surfaces(&scene.mesh, &scene.materials);
    let (ours, noise) = render_mc_box(
        scene,
        &view,
        &tracer,
        &lights,
        &occluder,
        spp,
        u64::from(seed),
    );
    let t_ours = t.elapsed().as_secs_f64();
    ours.save(&case_dir.join("ours_mean.exr"), 1.0)
        .expect("save");
    noise
        .stderr
        .save(&case_dir.join("ours_stderr.exr"), 1.0)
        .expect("save");

    let mi = read_exr(&case_dir.join("mitsuba_mean.exr"));
    let mi_se = read_exr(&case_dir.join("mitsuba_stderr.exr"));
    assert_eq!((mi.width, mi.height), (W, H));
    let mut mask = vec![false; (W * H) as usize];
    for l in &lights {
        for (m, x) in mask.iter_mut().zip(light_mask(&view, l)) {
            *m |= x;
        }
    }
    let s = compare(&ours, &noise.stderr, &mi, &mi_se, &mask);
    eprintln!(
        "[{name}] {W}x{H}, {} px compared ({} masked); ours {spp} spp ({t_ours:.1} s), \
         mitsuba {passes}x{pass_spp} spp ({t_mi:.1} s)\n  ours: {noise}\n  image mean: ours \
         {:.5}, mitsuba {:.5}, difference {:+.3} % ({:+.2} σ of the mean, σ = {:.2e})\n  \
         pixels: χ²/dof {:.3}, |z|>3 {:.2} %, |z|>4 {:.3} %, max |z| {:.2}, median σ/value \
         {:.2} %\n  8x8 blocks: χ²/dof {:.3}, |z|>3 {:.2} %",
        s.pixels,
        mask.iter().filter(|&&m| m).count(),
        s.mean_ours,
        s.mean_mitsuba,
        100.0 * (s.mean_ours - s.mean_mitsuba) / s.mean_mitsuba,
        s.z_mean,
        s.sigma_mean,
        s.chi2_per_dof,
        100.0 * s.frac_z3,
        100.0 * s.frac_z4,
        s.max_z,
        100.0 * s.median_rel_sigma,
        s.block_chi2,
        100.0 * s.block_frac_z3,
    );
    s
}

#[test]
fn ground_truth_agrees_with_mitsuba() {
    if !mitsuba_available() {
        eprintln!("skipped: mitsuba not installed (pip install mitsuba)");
        return;
    }
    // The exported BSDFs are our BRDF, direction by direction.
    let out = Command::new("python3")
        .arg(script())
        .arg("check-bsdf")
        .output()
        .expect("run render.py check-bsdf");
    eprintln!("{}", String::from_utf8_lossy(&out.stdout).trim());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let keep = std::env::var_os("BSPVT_XCHECK_KEEP").map(PathBuf::from);
    let dir = keep.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("bspvt-xcheck-{}", std::process::id()))
    });
    let plate = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
    let room = bspvt_proto::builtin::scene("room").expect("built-in room");
    let cornell = Scene::from_mesh_path(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rooms/cornell-box.obj"),
    )
    .expect("the project's Cornell box");
    let two_lamps = Scene::from_mesh_path(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rooms/two-lamps.gltf"),
    )
    .expect("the project's two-lamp room");
    // Point, spot and sun lights (issue 34). Exactly the same lights in both renderers: the
    // spot as a point light's sphere, the sun's disk shrunk to Mitsuba's delta direction.
    let punctual = Scene::from_mesh_path(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rooms/punctual-room.gltf"),
    )
    .expect("the project's punctual room");
    let checker = Scene::from_mesh_path(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rooms/checker-canopy.gltf"),
    )
    .expect("the project's checker canopy");
    let mut punctual_exact = punctual.clone();
    punctual_exact
        .punctual
        .iter_mut()
        .for_each(|l| l.spot = None);
    punctual_exact
        .suns
        .iter_mut()
        .for_each(|s| s.angular_diameter = Some(1e-5));
    let cases = [
        ("plate-small", plate),
        ("specular-a0.3", specular_scene(0.3)),
        ("specular-a0.05", specular_scene(0.05)),
        ("two-sided-light", two_sided_scene()),
        // Enclosed rooms given alone: the asset's own lamp, materials and camera.
        ("room", room),
        ("cornell-box", cornell),
        // Two lamps at different heights and a board between them (issue 34).
        ("two-lamps", two_lamps),
        ("punctual-room-exact", punctual_exact),
        // Light through an alpha-masked canopy: Mitsuba's `mask` BSDF (issue 35).
        ("checker-canopy", checker),
    ];
    let mut failures = Vec::new();
    // The room as exported: Mitsuba's spot (a point, falloff linear in angle) and its delta
    // sun against our sphere, glTF falloff and 0.53° disk — the image means within 5 %.
    let s = run_case("punctual-room", &punctual, &dir);
    let rel = (s.mean_ours - s.mean_mitsuba) / s.mean_mitsuba;
    if rel.abs() > 0.05 {
        failures.push(format!(
            "punctual-room: image means differ by {:+.2} %",
            100.0 * rel
        ));
    }
    for (name, scene) in &cases {
        let s = run_case(name, scene, &dir);
        // Unbiased agreement: the image means agree within 4σ (plus 0.1 % for f32 rounding),
        // per-pixel differences are distributed like the noise.
        let rel = (s.mean_ours - s.mean_mitsuba).abs() / s.mean_mitsuba;
        if !(s.z_mean.abs() < 4.0 || rel < 1e-3) {
            failures.push(format!("{name}: image means differ by {:.2} σ", s.z_mean));
        }
        if !(s.chi2_per_dof < 1.5 && s.frac_z3 < 0.02 && s.block_chi2 < 2.0) {
            failures.push(format!(
                "{name}: χ²/dof {:.2}, |z|>3 {:.2} %, blocks χ²/dof {:.2}",
                s.chi2_per_dof,
                100.0 * s.frac_z3,
                s.block_chi2
            ));
        }
    }
    if keep.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
