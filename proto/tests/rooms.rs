//! The project's own rooms (`assets/rooms/`, written by `make_rooms.py`) given alone, as a
//! user gives an asset with `--mesh`: the importer's materials, lamps and camera against values
//! computed by hand from the files, and the warnings for what it leaves out.

use std::path::{Path, PathBuf};

use bspvt_proto::Scene;
use bspvt_proto::import::{Format, Limits, load_asset, load_asset_bytes, load_asset_uploaded};
use glam::Vec3;

fn rooms() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/rooms")
}

fn close3(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
    a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tol)
}

fn area(p: &[Vec3]) -> f32 {
    let mut n = Vec3::ZERO;
    for i in 0..p.len() {
        n += p[i].cross(p[(i + 1) % p.len()]);
    }
    0.5 * n.length()
}

#[test]
fn cornell_box_obj_mtl_lamp_materials_and_no_added_ground() {
    let s = Scene::from_mesh_path(&rooms().join("cornell-box.obj")).expect("cornell box");
    // The lamp: Ke 17 12 4 on a 130 × 105 mm quad 0.8 mm under the ceiling, facing down.
    assert_eq!(s.lights.len(), 1, "{:?}", s.lights);
    let l = &s.lights[0];
    assert_eq!(l.radiance, [17.0, 12.0, 4.0]);
    assert_eq!(l.vertices.len(), 4);
    assert!(l.normal().dot(Vec3::NEG_Y) > 0.9999, "{}", l.normal());
    assert!((area(&l.points()) - 0.130 * 0.105).abs() < 1e-6);
    assert!(l.vertices.iter().all(|v| (v[1] - 0.548).abs() < 1e-6));
    assert!(!l.two_sided && l.region.is_none());
    // Materials by name, Kd as written, Ns 0 → α = 1, Ks 0 → F0 = 0.
    let find = |n: &str| {
        s.materials
            .iter()
            .position(|m| m.name == n)
            .unwrap_or_else(|| panic!("no material {n}: {:?}", s.materials))
    };
    let red = &s.materials[find("red")];
    assert_eq!(red.albedo, [0.63, 0.065, 0.05]);
    assert_eq!(red.roughness, 1.0);
    assert_eq!(red.specular, [0.0; 3]);
    assert_eq!(s.materials[find("green")].albedo, [0.14, 0.45, 0.091]);
    // The lamp's quad is not geometry (not an occluder): 16 quads − 1 = 15, 4 vertices each,
    // 2 triangles each; the floor keeps its 4 vertices; no ground plane, no default light.
    assert_eq!(s.mesh.triangles.len(), 30);
    assert_eq!(s.mesh.vertex_count(), 60);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let red_tris = s
        .mesh
        .material_ids
        .iter()
        .filter(|&&m| m as usize == find("red"))
        .count();
    assert_eq!(red_tris, 2);
    // Framed on the model: the camera sees the box's centre.
    let c = &s.camera;
    let f = (Vec3::from(c.target) - Vec3::from(c.position)).normalize();
    let to_centre = (Vec3::new(0.278, 0.274, 0.2796) - Vec3::from(c.position)).normalize();
    assert!(f.dot(to_centre) > 0.99);
    // The same file read from memory (an upload) without its MTL: defaults and a warning
    // that names the missing file.
    let bytes = std::fs::read(rooms().join("cornell-box.obj")).expect("read");
    let a = load_asset_bytes(&bytes, Format::Obj, &Limits::default()).expect("from memory");
    assert!(a.lights.is_empty());
    assert!(
        a.warnings.iter().any(|w| w.contains("mtllib")
            && w.contains("not uploaded")
            && w.contains("\"cornell-box.mtl\"")),
        "{:?}",
        a.warnings
    );
    // With the files the disk load read, uploaded beside it: the same asset, lamp and all.
    let disk = load_asset(&rooms().join("cornell-box.obj")).expect("disk");
    assert_eq!(disk.files, ["cornell-box.mtl"]);
    let files: std::collections::BTreeMap<String, Vec<u8>> = disk
        .files
        .iter()
        .map(|f| (f.clone(), std::fs::read(rooms().join(f)).expect("sidecar")))
        .collect();
    let up = load_asset_uploaded(&bytes, Format::Obj, &Limits::default(), &files).expect("upload");
    assert_eq!(up, disk);
    assert_eq!(up.lights.len(), 1);
}

#[test]
fn gltf_room_materials_lamp_camera_and_node_hierarchy() {
    let a = load_asset(&rooms().join("room.gltf")).expect("room");
    assert!(a.warnings.is_empty(), "{:?}", a.warnings);
    // Lamp: emissiveFactor (1, 0.9, 0.75) × emissiveStrength 12, a 0.8 m square at y = 2.48.
    assert_eq!(a.lights.len(), 1);
    let l = &a.lights[0];
    assert!(
        close3(l.radiance, [12.0, 10.8, 9.0], 1e-5),
        "{:?}",
        l.radiance
    );
    assert!((area(&l.points()) - 0.64).abs() < 1e-5);
    assert!(l.vertices.iter().all(|v| (v[1] - 2.48).abs() < 1e-6));
    assert!(l.normal().dot(Vec3::NEG_Y) > 0.9999);
    // Metallic-roughness: α = r², albedo = base·(1 − m), F0 = mix(0.04, base, m).
    let m = |n: &str| {
        a.materials
            .iter()
            .find(|m| m.name == n)
            .unwrap_or_else(|| panic!("no material {n}"))
    };
    let gold = m("brushed gold");
    assert!((gold.roughness - 0.1225).abs() < 1e-6);
    assert_eq!(gold.albedo, [0.0; 3]);
    assert!(close3(gold.specular, [1.0, 0.78, 0.34], 1e-6));
    let plastic = m("glossy plastic");
    assert!((plastic.roughness - 0.04).abs() < 1e-6);
    assert!(close3(plastic.albedo, [0.05, 0.3, 0.1], 1e-6));
    assert!(close3(plastic.specular, [0.04; 3], 1e-6));
    // Node hierarchy: the box sits at furniture (0, 0, −0.3) + box (−0.7, 0.35, 0), rotated
    // 30° about +Y, half-size 0.35: its gold triangles' centre is the composed translation.
    let gold_id = a
        .materials
        .iter()
        .position(|x| x.name == "brushed gold")
        .expect("id") as u32;
    let pts: Vec<Vec3> = a
        .mesh
        .triangles
        .iter()
        .zip(&a.mesh.material_ids)
        .filter(|(_, m)| **m == gold_id)
        .flat_map(|(t, _)| t.map(|i| a.mesh.positions[i as usize]))
        .collect();
    assert_eq!(pts.len(), 36);
    let c = pts.iter().copied().sum::<Vec3>() / pts.len() as f32;
    assert!((c - Vec3::new(-0.7, 0.35, -0.3)).length() < 1e-5, "{c}");
    let (lo, hi) = pts.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| {
        (lo.min(p.y), hi.max(p.y))
    });
    assert!((lo - 0.0).abs() < 1e-5 && (hi - 0.7).abs() < 1e-5);
    // Camera: node at (0, 1.4, 1.8) rotated −12° about X, looking down its −Z; yfov 0.9 rad.
    let cam = a.camera.as_ref().expect("camera");
    assert!(close3(cam.position, [0.0, 1.4, 1.8], 1e-6));
    let f = (Vec3::from(cam.target) - Vec3::from(cam.position)).normalize();
    let t = (-12f32).to_radians();
    assert!(
        (f - Vec3::new(0.0, t.sin(), -t.cos())).length() < 1e-5,
        "{f}"
    );
    assert!((cam.fov_y_deg - 0.9f32.to_degrees()).abs() < 1e-4);
    // As a scene: the asset's lamp, materials and camera; nothing added.
    let s = Scene::from_asset(a.clone()).expect("scene");
    assert_eq!(s.lights, a.lights);
    assert_eq!(s.camera, *cam);
    assert_eq!(s.mesh.vertex_count(), a.mesh.vertex_count());
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
}

/// What the importer leaves out is named: unreadable textures, occlusion maps, unsupported
/// extensions, orthographic cameras; punctual lights are said to feed the point-light methods
/// only.
#[test]
fn gltf_warnings_name_what_is_ignored() {
    let text = std::fs::read_to_string(rooms().join("room.gltf")).expect("read");
    let mut doc: serde_json::Value = serde_json::from_str(&text).expect("json");
    doc["extensionsUsed"].as_array_mut().expect("list").extend([
        "KHR_materials_clearcoat".into(),
        "KHR_lights_punctual".into(),
    ]);
    doc["extensions"] = serde_json::json!({"KHR_lights_punctual": {"lights": [
        {"type": "point", "intensity": 10.0}, {"type": "spot", "spot": {}}]}});
    doc["images"] = serde_json::json!([{"uri": "data:image/png;base64,AAAA"}]);
    let light_node = doc["nodes"].as_array().expect("nodes").len();
    doc["nodes"]
        .as_array_mut()
        .expect("nodes")
        .push(serde_json::json!({"translation": [0.0, 1.0, 0.0],
            "extensions": {"KHR_lights_punctual": {"light": 0}}}));
    doc["scenes"][0]["nodes"]
        .as_array_mut()
        .expect("roots")
        .push(light_node.into());
    doc["textures"] = serde_json::json!([{"source": 0}]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] =
        serde_json::json!({"index": 0});
    doc["materials"][1]["occlusionTexture"] = serde_json::json!({"index": 0});
    doc["cameras"][0] = serde_json::json!({"type": "orthographic", "orthographic":
        {"xmag": 1.0, "ymag": 1.0, "znear": 0.1, "zfar": 10.0}});
    let bytes = serde_json::to_vec(&doc).expect("json");
    let a = load_asset_bytes(&bytes, Format::Gltf, &Limits::default()).expect("room");
    let has = |s: &str| a.warnings.iter().any(|w| w.contains(s));
    for s in [
        "KHR_materials_clearcoat",
        "texture \"image 0\" could not be read: not a PNG or JPEG image; using the factor alone",
        "occlusion textures",
        "orthographic",
    ] {
        assert!(has(s), "no warning on {s}: {:?}", a.warnings);
    }
    assert!(a.camera.is_none());
    assert_eq!(a.lights.len(), 1);
    assert_eq!(a.punctual.len(), 1, "the light its node instances");
    assert_eq!(a.punctual[0].position, [0.0, 1.0, 0.0]);
}

/// The checker canopy's board (`alphaMode` MASK, default cut-off, an 8 × 8 texture whose alpha
/// is a checker) becomes a cut-out: factor 1, cut-off 0.5, the texture kept, half its texels
/// open; no warning names it (every view and every ray honours it); and the stored scene
/// (version 8) keeps it.
#[test]
fn alpha_mask_is_a_cutout_and_is_stored() {
    let s = Scene::from_mesh_path(&rooms().join("checker-canopy.gltf")).expect("checker canopy");
    assert!(
        !s.warnings.iter().any(|w| w.contains("surfaces are opaque")),
        "{:?}",
        s.warnings
    );
    // Nothing of it is left out: no warning names it.
    assert!(
        !s.warnings
            .iter()
            .any(|w| w.contains("cut out") || w.contains("alpha")),
        "{:?}",
        s.warnings
    );
    let leaves = s
        .materials
        .iter()
        .find(|m| m.name == "leaves")
        .expect("the board's material");
    let c = leaves.cutout.as_ref().expect("a cut-out");
    assert_eq!((c.alpha, c.cutoff, c.blend), (1.0, 0.5, false));
    let t = c.texture.as_ref().expect("its alpha texture");
    assert_eq!((t.texture.width, t.texture.height), (8, 8));
    let open = t.texture.rgba.chunks_exact(4).filter(|p| p[3] == 0).count();
    assert_eq!(open, 32);
    // The floor and the lamp are opaque.
    assert_eq!(s.materials.iter().filter(|m| m.cutout.is_some()).count(), 1);
    // Open texel (1, 0) and solid texel (0, 0), at their centres.
    assert!(!c.covers(Some(glam::Vec2::new(1.5 / 8.0, 0.5 / 8.0))));
    assert!(c.covers(Some(glam::Vec2::new(0.5 / 8.0, 0.5 / 8.0))));
    let back = bspvt_proto::api::decode_scene(&bspvt_proto::api::encode_scene(&s)).expect("decode");
    assert_eq!(back.materials, s.materials);
    assert_eq!(back.mesh.uvs, s.mesh.uvs);
    // The opaque canopy has none.
    let opaque = Scene::from_mesh_path(&rooms().join("canopy.gltf")).expect("canopy");
    assert!(opaque.materials.iter().all(|m| m.cutout.is_none()));
}

/// `KHR_texture_transform` is read: the checker canopy with its board's texture offset by one
/// texel along u (`offset` [0.125, 0]) is open where it was solid, no warning names the
/// extension, and the stored scene keeps the transform. The transform is the extension's
/// T · R · S: a quarter turn takes u to v.
#[test]
fn texture_transform_moves_the_texture() {
    let text = std::fs::read_to_string(rooms().join("checker-canopy.gltf")).expect("read");
    let mut doc: serde_json::Value = serde_json::from_str(&text).expect("json");
    doc["extensionsUsed"]
        .as_array_mut()
        .expect("extensionsUsed")
        .push("KHR_texture_transform".into());
    let leaves = doc["materials"]
        .as_array_mut()
        .expect("materials")
        .iter_mut()
        .find(|m| m["name"] == "leaves")
        .expect("the board");
    leaves["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] =
        serde_json::json!({"KHR_texture_transform": {"offset": [0.125, 0.0]}});
    let dir = std::env::temp_dir().join(format!("bspvt-uvt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("moved.gltf");
    std::fs::write(&path, serde_json::to_string(&doc).expect("json")).expect("write");
    let s = Scene::from_mesh_path(&path).expect("moved canopy");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        !s.warnings
            .iter()
            .any(|w| w.contains("KHR_texture_transform")),
        "{:?}",
        s.warnings
    );
    let c = s
        .materials
        .iter()
        .find_map(|m| m.cutout.as_ref())
        .expect("the cut-out");
    let t = c.texture.as_ref().expect("its texture");
    assert!(t.transform.is_some());
    // Texel (0, 0) was solid; one texel on, its centre reads texel (1, 0): open.
    assert!(!c.covers(Some(glam::Vec2::new(0.5 / 8.0, 0.5 / 8.0))));
    assert!(c.covers(Some(glam::Vec2::new(1.5 / 8.0, 0.5 / 8.0))));
    let back = bspvt_proto::api::decode_scene(&bspvt_proto::api::encode_scene(&s)).expect("decode");
    assert_eq!(back.materials, s.materials);
    let quarter = bspvt_proto::texture::UvTransform {
        offset: [0.0, 0.0],
        rotation: std::f32::consts::FRAC_PI_2,
        scale: [2.0, 1.0],
    };
    let uv = quarter.apply(glam::Vec2::new(1.0, 0.0));
    assert!((uv - glam::Vec2::new(0.0, 2.0)).length() < 1e-6, "{uv}");
}

/// The normal-mapped floor's `normalTexture` (scale 1, repeated, no `TANGENT` in the file)
/// becomes the floor's normal map; the mesh keeps its UVs for it though the floor has no other
/// texture; no warning names it; the stored scene (version 9) keeps it.
#[test]
fn normal_map_is_read_and_stored() {
    let s = Scene::from_mesh_path(&rooms().join("normal-floor.gltf")).expect("normal floor");
    assert!(
        !s.warnings.iter().any(|w| w.contains("normal")),
        "{:?}",
        s.warnings
    );
    let floor = s
        .materials
        .iter()
        .find(|m| m.name == "floor")
        .expect("the floor's material");
    assert!(floor.maps.is_none(), "the floor has no other texture");
    let n = floor.normal_map.as_ref().expect("a normal map");
    assert_eq!(n.scale, 1.0);
    assert_eq!(
        (n.texture.texture.width, n.texture.texture.height),
        (64, 64)
    );
    assert_eq!(
        s.mesh.uvs.len(),
        s.mesh.positions.len(),
        "UVs kept for the map"
    );
    // The ridges: at u = 0 the texel leans toward −u (the height rises along u there).
    let t = n.at(glam::Vec2::new(0.0, 0.25));
    assert!(t.x < -0.3 && t.z > 0.8, "{t}");
    assert_eq!(
        s.materials
            .iter()
            .filter(|m| m.normal_map.is_some())
            .count(),
        1
    );
    let back = bspvt_proto::api::decode_scene(&bspvt_proto::api::encode_scene(&s)).expect("decode");
    assert_eq!(back.materials, s.materials);
    assert_eq!(back.mesh.uvs, s.mesh.uvs);
}
