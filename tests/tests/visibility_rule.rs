//! Visibility ends at the light (issue 19, docs/bake.md "Where a ray ends"): V(p, ω) = 1 when
//! the ray from p along ω reaches the light — its declared region, or its plane when it has
//! none — before an occluder. A floor under a ceiling with a lamp between them sees the lamp;
//! an occluder between floor and lamp still shadows; without the rule the ceiling would
//! shadow everything.

use std::path::Path;

use bspvt_bake::Baker;
use bspvt_proto::Scene;
use bspvt_proto::bspvt::VertexTrees;
use glam::Vec3;

/// A room slice: a 3×3-vertex floor at y = 0 (centre vertex first), a ceiling at y = 2 facing
/// down, and optionally a small blocker at y = 1 over the floor's centre.
fn room_obj(blocker: bool) -> String {
    let mut s = String::new();
    // Floor: centre vertex 1, then a ring; normals up.
    for (x, z) in [
        (0.0, 0.0),
        (-2.0, -2.0),
        (0.0, -2.0),
        (2.0, -2.0),
        (2.0, 0.0),
        (2.0, 2.0),
        (0.0, 2.0),
        (-2.0, 2.0),
        (-2.0, 0.0),
    ] {
        s += &format!("v {x} 0 {z}\n");
    }
    // Counter-clockwise seen from above (+y): fan around the centre.
    for k in 0..8 {
        let a = 2 + k;
        let b = 2 + (k + 1) % 8;
        s += &format!("f 1 {b} {a}\n");
    }
    // Ceiling at y = 2, facing down.
    s += "v -3 2 -3\nv 3 2 -3\nv 3 2 3\nv -3 2 3\n";
    s += "f 10 11 12\nf 10 12 13\n";
    if blocker {
        // Its diagonal is not along x = z: no cube-map pixel centre lies on the shared edge
        // (obvhs's ray/triangle test is not watertight there).
        s += "v -0.3 1 -0.25\nv 0.35 1 -0.25\nv 0.35 1 0.3\nv -0.3 1 0.3\n";
        s += "f 14 16 15\nf 14 17 16\n";
    }
    s
}

/// The scene: the room and a downward-facing lamp at y = 1.8 (with a region around it when
/// `region`).
fn scene(dir: &Path, blocker: bool, region: bool) -> Scene {
    std::fs::write(dir.join("room.obj"), room_obj(blocker)).expect("write obj");
    let region = if region {
        r#", "region": {"min": [-0.6, 1.7, -0.6], "max": [0.6, 1.9, 0.6]}"#
    } else {
        ""
    };
    let json = format!(
        r#"{{"meshes": [{{"path": "room.obj"}}],
            "lights": [{{"vertices": [[-0.3, 1.8, -0.3], [-0.3, 1.8, 0.3], [0.3, 1.8, 0.3], [0.3, 1.8, -0.3]],
                         "radiance": [10, 10, 10]{region}}}],
            "camera": {{"position": [0, 1, 5], "target": [0, 0, 0]}},
            "bake": {{"face_res": 16}}}}"#
    );
    Scene::from_json(&json, dir).expect("scene")
}

/// The floor centre's visibility toward the lamp (a direction just off its centre, which is
/// a pixel corner of the cube face).
fn centre_visibility(baker: &Baker) -> f32 {
    let trees: VertexTrees = baker.bake_vertex(0).trees;
    trees.visibility(baker.codec(), Vec3::new(0.05, 1.0, 0.03).normalize())
}

#[test]
fn a_floor_under_a_ceiling_sees_the_lamp_between_them() {
    let dir = tempfile::tempdir().expect("temp dir");
    for region in [false, true] {
        let s = scene(dir.path(), false, region);
        assert_eq!(s.mesh.positions[0], Vec3::ZERO);
        let v = centre_visibility(&Baker::new(&s));
        assert_eq!(v, 1.0, "region {region}: the ceiling shadowed the lamp");
    }
}

#[test]
fn an_occluder_between_floor_and_lamp_still_shadows() {
    let dir = tempfile::tempdir().expect("temp dir");
    for region in [false, true] {
        let s = scene(dir.path(), true, region);
        let v = centre_visibility(&Baker::new(&s));
        assert_eq!(v, 0.0, "region {region}: the blocker did not shadow");
    }
}

#[test]
fn without_the_rule_the_ceiling_would_shadow() {
    // The same room baked with unbounded rays (no light stops): the control that shows the
    // two tests above test the rule and not the geometry.
    let dir = tempfile::tempdir().expect("temp dir");
    let s = scene(dir.path(), false, false);
    let baker = Baker::with_settings(s.mesh.clone(), s.bake.clone(), None);
    assert_eq!(centre_visibility(&baker), 0.0);
}
