//! Every registered method renders the built-in scene from the bare command
//! `bspvt render builtin:plate-small --method NAME --width 64 --height 64 --out F.png`: the
//! registry is the one list, and a method that needs trees bakes them (cached) by itself.

use std::path::Path;
use std::process::Command;

use bspvt_client::method::METHODS;

const BIN: &str = env!("CARGO_BIN_EXE_bspvt");

#[test]
fn methods_lists_every_registered_method_one_a_line() {
    let out = Command::new(BIN)
        .arg("methods")
        .output()
        .expect("run bspvt methods");
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).expect("utf-8");
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), METHODS.len(), "{text}");
    for (line, m) in lines.iter().zip(METHODS) {
        assert_eq!(line.split_whitespace().next(), Some(m.name()), "{line}");
        assert!(line.contains(m.description()), "{line}");
        assert!(line.contains(&m.needs().describe()), "{line}");
    }
}

#[test]
fn every_method_renders_the_builtin_scene_with_no_other_flag() {
    let env_map = bspvt_proto::paths::default_env_map();
    let dir = tempfile::tempdir().expect("temp dir");
    for m in METHODS {
        if m.needs().env_map && !env_map.is_file() {
            eprintln!(
                "skipped {}: no environment map at {} (set BSPVT_ASSETS)",
                m.name(),
                env_map.display()
            );
            continue;
        }
        let png = dir.path().join(format!("{}.png", m.name()));
        let out = Command::new(BIN)
            .current_dir(dir.path())
            .env("BSPVT_ASSETS", bspvt_proto::paths::assets_dir())
            .args(["render", "builtin:plate-small", "--method", m.name()])
            .args(["--width", "64", "--height", "64", "--out"])
            .arg(&png)
            .output()
            .expect("run bspvt render");
        assert!(
            out.status.success(),
            "{}: {}",
            m.name(),
            String::from_utf8_lossy(&out.stderr)
        );
        let img = image::open(&png).expect("a PNG").to_rgb8();
        assert_eq!(img.dimensions(), (64, 64));
        // Something is lit: the scene covers most of the frame and every method shades it.
        let lit = img.pixels().filter(|p| p.0.iter().any(|&c| c > 8)).count();
        assert!(lit > 64 * 64 / 4, "{}: only {lit} lit pixels", m.name());
    }
    // The bake a tree method made is cached by the scene's hash: a second run reuses it.
    let bakes = dir.path().join("out/cache/bakes");
    let files: Vec<_> = std::fs::read_dir(&bakes)
        .expect("the bake cache")
        .filter_map(Result::ok)
        .filter(|e| e.path().extension().is_some_and(|x| x == "bspvt"))
        .collect();
    // One for the lamp, and one for the sky when the sky's method ran (`bspvt-env`).
    let sky = files
        .iter()
        .filter(|e| e.file_name().to_string_lossy().starts_with("sky-"))
        .count();
    assert_eq!(files.len() - sky, 1, "one lamp bake in {}", bakes.display());
    assert_eq!(sky, usize::from(env_map.is_file()), "sky bakes");
    let again = Command::new(BIN)
        .current_dir(dir.path())
        .args(["render", "builtin:plate-small", "--method", "bspvt"])
        .args(["--width", "16", "--height", "16", "--out", "again.png"])
        .output()
        .expect("run bspvt render");
    assert!(again.status.success());
    assert!(
        !String::from_utf8_lossy(&again.stderr).contains("baking"),
        "the second run baked again"
    );
    assert!(Path::new(&dir.path().join("again.png")).is_file());
}

#[test]
fn an_unknown_method_is_refused_with_the_known_names() {
    let out = Command::new(BIN)
        .args([
            "render",
            "builtin:plate-small",
            "--method",
            "nope",
            "--out",
            "x.png",
        ])
        .output()
        .expect("run bspvt render");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bspvt") && err.contains("mc-env"), "{err}");
}

/// docs/methods.md lists exactly the registry's methods, in order, with their descriptions.
#[test]
fn the_methods_page_agrees_with_the_registry() {
    let page = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/methods.md"),
    )
    .expect("docs/methods.md");
    let rows: Vec<&str> = page.lines().filter(|l| l.starts_with("| `")).collect();
    assert_eq!(rows.len(), METHODS.len(), "docs/methods.md rows");
    for (row, m) in rows.iter().zip(METHODS) {
        assert!(
            row.starts_with(&format!(
                "| `{}` | {} | {} |",
                m.name(),
                m.description(),
                m.needs().describe()
            )),
            "docs/methods.md: {row}\nregistry: {} {}",
            m.name(),
            m.description()
        );
    }
}

/// A light wound away from the scene lights nothing: the render says so on stderr instead
/// of writing a silent black image.
#[test]
fn a_light_facing_away_is_reported() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut file = bspvt_proto::builtin::scene_file("plate-small").expect("builtin");
    file.lights[0].vertices.reverse();
    let scene = dir.path().join("away.json");
    std::fs::write(&scene, serde_json::to_string(&file).expect("json")).expect("write");
    let out = Command::new(BIN)
        .current_dir(dir.path())
        .arg("render")
        .arg(&scene)
        .args([
            "--method", "ltc", "--width", "16", "--height", "16", "--out", "a.png",
        ])
        .output()
        .expect("run bspvt render");
    assert!(out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("faces away from every vertex"), "{err}");
}
