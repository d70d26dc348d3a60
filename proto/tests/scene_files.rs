//! The scene files shipped in `assets/scenes/` load and validate, and invalid scenes are
//! refused with messages that say what is wrong.

use std::path::{Path, PathBuf};

use bspvt_proto::scene::SceneFile;
use bspvt_proto::{Scene, SceneError};

fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/scenes")
}

/// The mesh files a scene file names that are not on this machine.
fn missing_meshes(path: &Path) -> Vec<PathBuf> {
    let text = std::fs::read_to_string(path).expect("read scene file");
    let file: SceneFile = serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("{} is not a valid scene file: {e}", path.display()));
    let base = path.parent().unwrap_or(Path::new("."));
    file.meshes
        .iter()
        .filter(|m| !m.path.starts_with("builtin:"))
        .map(|m| base.join(&m.path))
        .filter(|p| !p.is_file())
        .collect()
}

#[test]
fn every_shipped_scene_loads() {
    let dir = scenes_dir();
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    paths.sort();
    assert!(
        paths.iter().any(|p| p.ends_with("plate.json")),
        "plate.json is missing from {}",
        dir.display()
    );
    let mut loaded = 0;
    for path in &paths {
        let missing = missing_meshes(path);
        if !missing.is_empty() {
            println!(
                "skipped: {} (mesh not found: {})",
                path.display(),
                missing[0].display()
            );
            continue;
        }
        let scene =
            Scene::load(path).unwrap_or_else(|e| panic!("{} does not load: {e}", path.display()));
        scene.validate().expect("a loaded scene validates");
        println!(
            "{}: {} vertices, {} triangles, {} materials, {} lights",
            path.file_name().unwrap_or_default().to_string_lossy(),
            scene.mesh.vertex_count(),
            scene.mesh.triangles.len(),
            scene.materials.len(),
            scene.lights.len()
        );
        match path.file_name().and_then(|n| n.to_str()) {
            // The built-in plate scene, written out: the same mesh, materials, light and camera.
            Some("plate.json") => {
                let builtin = bspvt_proto::builtin::scene("plate").expect("built-in plate");
                assert_eq!(scene.mesh, builtin.mesh);
                assert_eq!(scene.materials, builtin.materials);
                assert_eq!(scene.lights, builtin.lights);
                assert_eq!(scene.camera, builtin.camera);
                // 160 × 160 grid + icosphere (subdivided 4 times) + cuboid of 4 × 4 faces.
                assert_eq!(scene.mesh.vertex_count(), 160 * 160 + 2562 + 6 * 16);
            }
            // The bunny's 34,834 used vertices plus the 96 × 96 ground grid.
            Some("bunny.json") => {
                assert_eq!(scene.mesh.vertex_count(), 34_834 + 96 * 96);
                assert_eq!(scene.mesh.triangles.len(), 69_451 + 2 * 95 * 95);
                assert!(scene.light_region().is_some());
                let ground = scene.mesh.material_ids.iter().filter(|&&m| m == 1).count();
                assert_eq!(ground, 2 * 95 * 95);
            }
            // The built-in moving scene is this file: a sphere that orbits and a bar that twists.
            Some("dynamic.json") => {
                let builtin = bspvt_proto::builtin::scene("dynamic").expect("built-in dynamic");
                assert_eq!(scene, builtin);
                assert_eq!(scene.motion.len(), 2);
                let (a, b) = (scene.at(0.0), scene.at(0.25));
                let sphere = &scene.motion[0];
                let v = sphere.first_vertex as usize..sphere.first_vertex as usize + 2562;
                let centre = |s: &Scene| {
                    s.mesh.positions[v.clone()]
                        .iter()
                        .copied()
                        .sum::<glam::Vec3>()
                        / 2562.0
                };
                // A quarter of the orbit (radius 1 about the pivot's vertical) moves the sphere's
                // centre by √2, and the key lifts it by 0.35 · ½.
                let moved = centre(&b) - centre(&a);
                assert!(
                    (moved.length() - (2.0f32 + 0.175 * 0.175).sqrt()).abs() < 1e-3,
                    "{moved}"
                );
                // The ground plane does not move.
                let last = scene.mesh.vertex_count() - 1;
                assert_eq!(a.mesh.positions[last], b.mesh.positions[last]);
                b.validate().expect("a posed scene validates");
            }
            _ => {}
        }
        loaded += 1;
    }
    assert!(loaded >= 1);
}

/// A small valid scene; tests replace parts of it.
const BASE: &str = r#"{
  "meshes": [{"path": "builtin:plate-small"}],
  "materials": [
    {"name": "floor", "roughness": 0.35},
    {"name": "sphere", "roughness": 0.15},
    {"name": "slab", "roughness": 0.5}
  ],
  "lights": [{
    "vertices": [[-0.5, 3.0, -0.5], [0.5, 3.0, -0.5], [0.5, 3.0, 0.5], [-0.5, 3.0, 0.5]],
    "radiance": [12.0, 11.0, 10.0],
    "region": {"min": [-2.5, 2.0, -2.5], "max": [2.5, 4.0, 2.5]}
  }],
  "bake": {"face_res": 16}
}"#;

const BASE_LIGHT: &str =
    r#""vertices": [[-0.5, 3.0, -0.5], [0.5, 3.0, -0.5], [0.5, 3.0, 0.5], [-0.5, 3.0, 0.5]]"#;

fn load(text: &str) -> Result<Scene, SceneError> {
    Scene::from_json(text, &scenes_dir())
}

/// Replaces `from` (which must occur) in the base scene, loads it and returns the error text.
fn error_with(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "{from:?} is not in the base scene");
    match load(&BASE.replace(from, to)) {
        Ok(_) => panic!("replacing {from:?} by {to:?} should make the scene invalid"),
        Err(e) => e.to_string(),
    }
}

fn assert_contains(message: &str, needle: &str) {
    assert!(
        message.contains(needle),
        "error {message:?} does not contain {needle:?}"
    );
}

#[test]
fn base_scene_is_valid() {
    let scene = load(BASE).unwrap_or_else(|e| panic!("{e}"));
    // Defaults filled in: camera framed automatically, default bake settings but face_res.
    assert_eq!(scene.bake.face_res, 16);
    assert_eq!(scene.bake.chunk_vertices, 1024);
    assert_eq!(scene.materials[0].albedo, [0.6, 0.6, 0.6]);
    assert_eq!(scene.camera.fov_y_deg, 40.0);
}

#[test]
fn light_with_two_vertices() {
    let m = error_with(
        BASE_LIGHT,
        r#""vertices": [[-0.5, 3.0, -0.5], [0.5, 3.0, -0.5]]"#,
    );
    assert_contains(&m, "lights[0]: has 2 vertices; a light needs 3 to 8");
}

#[test]
fn non_convex_light() {
    // A dart: the third vertex is pushed inside the square, making a reflex corner.
    let m = error_with(
        BASE_LIGHT,
        r#""vertices": [[-0.5, 3.0, -0.5], [0.5, 3.0, -0.5], [-0.2, 3.0, -0.2], [-0.5, 3.0, 0.5]]"#,
    );
    assert_contains(&m, "lights[0]: polygon is not convex");
}

#[test]
fn light_outside_its_region_and_non_planar_light() {
    let m = error_with(r#""max": [2.5, 4.0, 2.5]"#, r#""max": [2.5, 2.5, 2.5]"#);
    assert_contains(&m, "the light starts outside its declared region");
    let m = error_with(
        BASE_LIGHT,
        r#""vertices": [[-0.5, 3.0, -0.5], [0.5, 3.0, -0.5], [0.5, 3.5, 0.5], [-0.5, 3.0, 0.5]]"#,
    );
    assert_contains(&m, "vertices are not coplanar");
}

#[test]
fn roughness_zero() {
    let m = error_with(r#""roughness": 0.35"#, r#""roughness": 0"#);
    assert_contains(&m, "materials[0]: roughness 0 must be in (0, 1]");
}

#[test]
fn unknown_field() {
    let m = error_with(r#""radiance""#, r#""colour": [1, 1, 1], "radiance""#);
    assert_contains(&m, "unknown field `colour`");
    let m = error_with(r#""face_res": 16"#, r#""face_resolution": 16"#);
    assert_contains(&m, "unknown field `face_resolution`");
}

#[test]
fn face_res_zero() {
    let m = error_with(r#""face_res": 16"#, r#""face_res": 0"#);
    assert_contains(&m, "bake.face_res = 0 is outside 4..=512");
}

#[test]
fn other_invalid_scenes() {
    let m = error_with(r#""face_res": 16"#, r#""split": "random""#);
    assert_contains(&m, "unknown variant `random`");
    let m = error_with("builtin:plate-small", "builtin:teapot");
    assert_contains(&m, "unknown built-in mesh \"teapot\"");
    let m = error_with("builtin:plate-small", "no/such/mesh.ply");
    assert_contains(&m, "cannot read mesh file");
    let m = error_with("builtin:plate-small", "mesh.stl");
    assert_contains(&m, "unsupported mesh format");
    let m = error_with(
        r#"{"path": "builtin:plate-small"}"#,
        r#"{"path": "builtin:plate-small", "material": 1}"#,
    );
    assert_contains(&m, "material index 3 used, but the scene has 3 materials");
    let m = error_with(
        r#""radiance": [12.0, 11.0, 10.0]"#,
        r#""radiance": [-1, 0, 0]"#,
    );
    assert_contains(&m, "radiance must be finite and ≥ 0");
}

/// Placement and motion: a transform moves the mesh, a motion is checked with a message that
/// names the entry and the field.
#[test]
fn transforms_place_meshes_and_bad_motion_is_refused() {
    let placed = load(&BASE.replace(
        r#"{"path": "builtin:plate-small"}"#,
        r#"{"path": "builtin:plate-small", "transform": {"translation": [1, 2, 3], "scale": [2, 2, 2]}}"#,
    ))
    .expect("placed scene");
    let rest = load(BASE).expect("base scene");
    let (a, b) = (rest.mesh.bounds(), placed.mesh.bounds());
    assert!((b.center() - (a.center() * 2.0 + glam::Vec3::new(1.0, 2.0, 3.0))).length() < 1e-4);
    assert!(!placed.is_dynamic());
    let entry = r#"{"path": "builtin:plate-small"}"#;
    let e = error_with(
        entry,
        r#"{"path": "builtin:plate-small", "motion": {"keys": [{"t": 0.6}, {"t": 0.1}]}}"#,
    );
    assert!(
        e.contains("meshes[0].motion.keys[1]") && e.contains("time order"),
        "{e}"
    );
    let e = error_with(
        entry,
        r#"{"path": "builtin:plate-small", "transform": {"scale": [1, -1, 1]}}"#,
    );
    assert!(
        e.contains("meshes[0].transform") && e.contains("scale"),
        "{e}"
    );
    let e = error_with(
        entry,
        r#"{"path": "builtin:plate-small", "motion": {"deform": {"wave": {"direction": [1, 0, 0], "normal": [0, 1, 0], "amplitude": 0.1, "wavelength": 0}}}}"#,
    );
    assert!(e.contains("wavelength"), "{e}");
    let e = error_with(
        entry,
        r#"{"path": "builtin:plate-small", "motion": {"spin": 3}}"#,
    );
    assert!(e.contains("spin"), "{e}");
    let moving = load(&BASE.replace(
        entry,
        r#"{"path": "builtin:plate-small", "motion": {"deform": {"wave": {"direction": [1, 0, 0], "normal": [0, 1, 0], "amplitude": 0.05, "wavelength": 0.5}}}}"#,
    ))
    .expect("moving scene");
    assert!(moving.is_dynamic());
    let p = moving.at(0.3);
    assert!(
        p.mesh
            .positions
            .iter()
            .zip(&moving.mesh.positions)
            .any(|(x, y)| x != y)
    );
    assert!(p.mesh.positions.iter().all(|x| x.is_finite()));
    assert!(
        p.mesh
            .normals
            .iter()
            .all(|n| (n.length() - 1.0).abs() < 1e-3)
    );
}

/// A one-sided light wound away from the scene lights nothing: it is named, so that the
/// front ends warn instead of drawing a silent black image. Turned round, or two-sided, it is
/// not; the shipped scenes have none.
#[test]
fn lights_facing_away_are_found() {
    let mut s = bspvt_proto::builtin::scene("plate-small").expect("builtin");
    assert!(s.lights_facing_away().is_empty());
    s.lights[0].vertices.reverse();
    assert_eq!(s.lights_facing_away(), vec![0]);
    s.lights[0].two_sided = true;
    assert!(s.lights_facing_away().is_empty());
    for name in bspvt_proto::builtin::NAMES {
        let s = bspvt_proto::builtin::scene(name).expect("builtin");
        assert!(s.lights_facing_away().is_empty(), "{name}");
    }
}
