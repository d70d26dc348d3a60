//! Visibility ends at the light (issues 19 and 34, docs/bake.md "Where a ray ends"): V(p, ω) = 1
//! when the ray from p along ω reaches the light — its declared region, its plane when it moves
//! in it, else the lamp's own polygon — before an occluder. A floor under a ceiling with a lamp
//! between them sees the lamp; an occluder between floor and lamp still shadows; without the
//! rule the ceiling would shadow everything; a second, lower lamp does not end the rays that
//! pass beside it.

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
/// `region`; else fixed, its rays ending at its polygon).
fn scene(dir: &Path, blocker: bool, region: bool) -> Scene {
    std::fs::write(dir.join("room.obj"), room_obj(blocker)).expect("write obj");
    let region = if region {
        r#", "region": {"min": [-0.6, 1.7, -0.6], "max": [0.6, 1.9, 0.6]}"#
    } else {
        ""
    };
    let json = format!(
        r#"{{"meshes": [{{"path": "room.obj"}}],
            "lights": [{{"vertices": [[-0.3, 1.8, -0.3], [0.3, 1.8, -0.3], [0.3, 1.8, 0.3], [-0.3, 1.8, 0.3]],
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

/// A wall facing +x under the lamp of [`scene`]: a 4×4-vertex grid at x = −2, y ∈ [0, 1.5],
/// z ∈ [−1.5, 1.5], alone (nothing occludes it).
fn wall_scene(dir: &Path) -> Scene {
    let mut s = String::new();
    for j in 0..4 {
        for k in 0..4 {
            s += &format!("v -2 {} {}\n", 0.5 * j as f32, -1.5 + k as f32);
        }
    }
    for j in 0..3 {
        for k in 0..3 {
            let a = 1 + 4 * j + k;
            // Counter-clockwise seen from +x (y up, z toward −x × y).
            s += &format!("f {a} {} {}\nf {a} {} {}\n", a + 5, a + 1, a + 4, a + 5);
        }
    }
    std::fs::write(dir.join("wall.obj"), s).expect("write obj");
    let json = r#"{"meshes": [{"path": "wall.obj"}],
        "lights": [{"vertices": [[-0.3, 1.8, -0.3], [0.3, 1.8, -0.3], [0.3, 1.8, 0.3], [-0.3, 1.8, 0.3]],
                    "radiance": [10, 10, 10], "moves_in_plane": true}],
        "camera": {"position": [3, 1, 0], "target": [-2, 0.75, 0]},
        "bake": {"face_res": 16}}"#;
    Scene::from_json(json, dir).expect("scene")
}

/// A fixed lamp (no region, not moving in its plane) is reached only through its polygon:
/// the wall's pixels that matter are those whose cone meets the lamp — every pixel whose
/// centre's ray hits it, and none farther than a pixel's cone from it — a small share of those
/// that rise to its plane; and the map there is the one casting toward the plane gives.
#[test]
fn a_fixed_lamp_keeps_only_the_directions_that_reach_it() {
    use bspvt_proto::cubemap::{FACES, FaceFrame, pixel_centres};
    let dir = tempfile::tempdir().expect("temp dir");
    let plane = wall_scene(dir.path());
    let mut fixed = plane.clone();
    fixed.lights[0].moves_in_plane = false;
    let res = fixed.bake.face_res;
    let (b_fixed, b_plane) = (Baker::new(&fixed), Baker::new(&plane));
    let centres = pixel_centres(res);
    let (lo, hi) = (Vec3::new(-0.3, 1.8, -0.3), Vec3::new(0.3, 1.8, 0.3));
    let (mut n_fixed, mut n_plane) = (0, 0);
    for v in 0..fixed.mesh.vertex_count() as u32 {
        let o = fixed.mesh.positions[v as usize];
        let kept = b_fixed.reference_cube_map(v);
        assert_eq!(
            kept,
            b_fixed.cube_map(v).0,
            "vertex {v}: the casts disagree"
        );
        let in_plane = b_plane.reference_cube_map(v);
        for f in 0..FACES {
            let frame = FaceFrame::of(f);
            let kept_px = kept[f].as_ref().map(|p| p.index.as_slice()).unwrap_or(&[]);
            let plane_px = in_plane[f].as_ref();
            n_fixed += kept_px.len();
            n_plane += plane_px.map_or(0, |p| p.index.len());
            for (p, uv) in centres.iter().enumerate() {
                let d = frame.direction(*uv).normalize();
                if d.dot(fixed.mesh.normals[v as usize]) <= 0.0 || d.y <= 0.0 {
                    continue;
                }
                let q = o + d * ((1.8 - o.y) / d.y);
                let hits = q.x >= lo.x && q.x <= hi.x && q.z >= lo.z && q.z <= hi.z;
                let is_kept = kept_px.contains(&(p as u32));
                if hits {
                    assert!(is_kept, "vertex {v} face {f} pixel {p}: {d} hits the lamp");
                }
                // A 16² pixel's cone is at most 1.5 / 16 rad wide; at distance t the lamp
                // grows by at most t · 0.09 / cos.
                let grow = (q - o).length() * 0.09 / d.y + 1e-4;
                let near = q.x >= lo.x - grow
                    && q.x <= hi.x + grow
                    && q.z >= lo.z - grow
                    && q.z <= hi.z + grow;
                if is_kept {
                    assert!(
                        near,
                        "vertex {v} face {f} pixel {p}: {d} kept, far from the lamp"
                    );
                    // Nothing occludes the wall: the same value as toward the plane.
                    let k = kept_px.iter().position(|&x| x == p as u32).expect("kept");
                    let j = plane_px
                        .and_then(|px| px.index.iter().position(|&x| x == p as u32))
                        .expect("a pixel that reaches the lamp reaches its plane");
                    assert_eq!(
                        kept[f].as_ref().map(|x| x.visible[k]),
                        plane_px.map(|x| x.visible[j])
                    );
                }
            }
        }
    }
    eprintln!(
        "wall under a 0.6 m lamp, 16²: {n_fixed} pixels matter (fixed lamp), {n_plane} (plane)"
    );
    assert!(
        n_fixed > 0 && n_fixed * 3 < n_plane,
        "{n_fixed} of {n_plane}"
    );
}

/// Two lamps at different heights (issue 34): the ceiling lamp and a small pendant lamp lower
/// down, beside the floor's centre, with a board between the pendant's height and the ceiling.
/// The floor's centre looks up through the board at the ceiling lamp: the board shadows it
/// (the ray passes beside the pendant and does not end at the pendant's plane). Control: with
/// both lights moving in their planes the ray ends at the pendant's plane below the board, and
/// the board casts no shadow — the bug the issue describes.
#[test]
fn a_lower_lamp_does_not_end_the_rays_that_pass_beside_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut s = scene(dir.path(), true, false);
    let mut pendant = s.lights[0].clone();
    // Facing down, as the ceiling lamp (counter-clockwise seen from below).
    pendant.vertices = vec![
        [1.1, 0.8, -0.1],
        [1.3, 0.8, -0.1],
        [1.3, 0.8, 0.1],
        [1.1, 0.8, 0.1],
    ];
    s.lights.push(pendant);
    s.validate().expect("valid");
    assert!(
        s.lights
            .iter()
            .all(|l| !l.moves_in_plane && l.region.is_none())
    );
    assert_eq!(
        centre_visibility(&Baker::new(&s)),
        0.0,
        "the board did not shadow"
    );
    for l in &mut s.lights {
        l.moves_in_plane = true;
    }
    assert_eq!(
        centre_visibility(&Baker::new(&s)),
        1.0,
        "control: rays ending at the pendant's plane pass the board"
    );
}

/// A light without a region moves in its plane (docs/bake.md, "Where a ray ends"), so a
/// direction that never meets the plane never meets the light: its pixels are "don't care",
/// neither cast nor stored. For a wall under a ceiling lamp that is the lower half of every
/// vertex's hemisphere; a pixel is kept when any of its directions rises toward the plane.
#[test]
fn directions_that_never_reach_the_lights_plane_do_not_matter() {
    use bspvt_proto::cubemap::{FACES, FaceFrame, pixel_centres};
    let dir = tempfile::tempdir().expect("temp dir");
    let s = wall_scene(dir.path());
    let res = s.bake.face_res;
    let baker = Baker::new(&s);
    let unbounded = Baker::with_settings(s.mesh.clone(), s.bake.clone(), None);
    let half_pixel = 1.5 / res as f32; // > a 16² pixel's angular radius anywhere on a face
    let centres = pixel_centres(res);
    for v in 0..s.mesh.vertex_count() as u32 {
        let n = s.mesh.normals[v as usize];
        assert!(n.x > 0.99, "vertex {v}: normal {n}");
        let kept = baker.reference_cube_map(v);
        assert_eq!(kept, baker.cube_map(v).0, "vertex {v}: the casts disagree");
        let all = unbounded.reference_cube_map(v);
        let (mut n_kept, mut n_all) = (0, 0);
        for f in 0..FACES {
            let frame = FaceFrame::of(f);
            let kept_px = kept[f].as_ref().map(|p| p.index.as_slice()).unwrap_or(&[]);
            let all_px = all[f].as_ref().map(|p| p.index.as_slice()).unwrap_or(&[]);
            n_kept += kept_px.len();
            n_all += all_px.len();
            for (p, uv) in centres.iter().enumerate() {
                let d = frame.direction(*uv).normalize();
                let above = d.dot(n) > 0.0;
                let is_kept = kept_px.contains(&(p as u32));
                assert_eq!(above, all_px.contains(&(p as u32)), "vertex {v}: horizon");
                if above && d.y > 0.0 {
                    assert!(
                        is_kept,
                        "vertex {v} face {f} pixel {p}: {d} rises to the lamp"
                    );
                }
                if is_kept {
                    assert!(d.y > -half_pixel, "vertex {v} face {f} pixel {p}: {d} kept");
                }
            }
        }
        // About half of the hemisphere rises toward the plane (plus the pixels across the
        // plane's horizon).
        let ratio = n_kept as f64 / n_all as f64;
        assert!(
            (0.45..0.62).contains(&ratio),
            "vertex {v}: kept {n_kept} of {n_all}"
        );
    }
}

/// Leaving out the directions that cannot reach the light costs no accuracy where it can be:
/// on a shared mesh with its default lamp (a quad above it, no region), the trees baked
/// without those directions fit the pixels that can see the lamp's plane at least as well as
/// trees fitted to every pixel above the horizon (the previous rule, reproduced here by a
/// second light whose region holds the whole scene: every direction reaches it, and a region
/// that contains a ray's origin does not end the ray). Mean |ΔV| over those pixels, the trees
/// read at pixel centres.
#[test]
fn leaving_out_unreachable_directions_keeps_the_error_where_the_light_can_be() {
    use bspvt_proto::cubemap::{FACES, FaceFrame, pixel_centres};
    use bspvt_proto::scene::Region;
    let path = bspvt_proto::paths::meshes_dir().join("bunny_res4.ply");
    if !path.is_file() {
        eprintln!("skipped: {} not found (set BSPVT_ASSETS)", path.display());
        return;
    }
    let mut scene = Scene::from_mesh_path(&path).expect("mesh scene");
    scene.bake.face_res = 32;
    let mut every = scene.clone();
    let b = scene.mesh.bounds();
    let pad = Vec3::splat(b.diagonal());
    let mut all = every.lights[0].clone();
    all.region = Some(Region {
        min: (b.min - pad).to_array(),
        max: (b.max + pad).to_array(),
    });
    every.lights.push(all);
    let (kept, previous) = (Baker::new(&scene), Baker::new(&every));
    let centres = pixel_centres(scene.bake.face_res);
    let samples = scene.bake.supersampling.max(1).pow(2) as f32;
    let n = scene.mesh.vertex_count() as u32;
    let (mut err_kept, mut err_prev, mut pixels, mut pixels_prev) = (0.0, 0.0, 0usize, 0usize);
    // The bunny's own vertices that do not face straight up (the added ground's all do: every
    // direction above their horizon rises to the lamp).
    let sides: Vec<u32> = (0..n)
        .filter(|&v| scene.mesh.normals[v as usize].y < 0.9)
        .collect();
    for &v in sides.iter().step_by((sides.len() / 300).max(1)) {
        let map = kept.cube_map(v).0;
        let map_prev = previous.cube_map(v).0;
        let (t_kept, t_prev) = (kept.bake_vertex(v).trees, previous.bake_vertex(v).trees);
        for f in 0..FACES {
            pixels_prev += map_prev[f].as_ref().map_or(0, |p| p.index.len());
            let Some(px) = &map[f] else { continue };
            let frame = FaceFrame::of(f);
            for (&p, &vis) in px.index.iter().zip(&px.visible) {
                let d = frame.direction(centres[p as usize]).normalize();
                let truth = vis as f32 / samples;
                err_kept += (t_kept.visibility(kept.codec(), d) - truth).abs() as f64;
                err_prev += (t_prev.visibility(previous.codec(), d) - truth).abs() as f64;
                pixels += 1;
            }
        }
    }
    let (e_kept, e_prev) = (err_kept / pixels as f64, err_prev / pixels as f64);
    eprintln!(
        "bunny_res4, 32²: {pixels} pixels can reach the lamp of {pixels_prev} above the \
         horizon; mean |ΔV| there {e_kept:.5} (their own trees) vs {e_prev:.5} (trees of every \
         pixel above the horizon)"
    );
    assert!(
        pixels > 0 && pixels < pixels_prev * 3 / 4,
        "{pixels} of {pixels_prev}"
    );
    assert!(e_kept <= e_prev * 1.05, "{e_kept} > {e_prev}");
}

/// A bulb smaller than a cube-map pixel is sampled where it is, not at its pixel's centre
/// (`VertexRays::aim`): from the floor's centre, at 8² faces, a bulb of radius 0.02
/// 1.5 above the floor lies wholly inside the pixel whose centre is at direction
/// (0.125, 1, 0.125), 0.05 off that centre; a small board at y = 1 blocks the pixel's centre
/// ray but not the bulb. The bulb is visible. The control: the same bulb moved onto the
/// pixel's centre ray is shadowed by the board.
#[test]
fn a_bulb_is_sampled_where_it_is_not_at_its_pixels_centre() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut obj = room_obj(false);
    // The board: x, z ∈ [0.09, 0.2] at y = 1, facing down (vertices 14–17).
    obj += "v 0.09 1 0.09\nv 0.2 1 0.09\nv 0.2 1 0.2\nv 0.09 1 0.2\n";
    obj += "f 14 15 16\nf 14 16 17\n";
    std::fs::write(dir.path().join("room.obj"), obj).expect("write obj");
    let visibility = |t: f32| {
        let bulb = Vec3::new(t, 1.0, t) * 1.5;
        let json = format!(
            r#"{{"meshes": [{{"path": "room.obj"}}],
                "punctual": [{{"name": "bulb", "position": [{}, {}, {}], "intensity": [1, 1, 1], "radius": 0.02}}],
                "camera": {{"position": [0, 1, 5], "target": [0, 0, 0]}},
                "bake": {{"face_res": 8}}}}"#,
            bulb.x, bulb.y, bulb.z
        );
        let scene = Scene::from_json(&json, dir.path()).expect("scene");
        let baker = Baker::new(&scene);
        let trees: VertexTrees = baker.bake_vertex(0).trees;
        trees.visibility(baker.codec(), bulb.normalize())
    };
    let beside = visibility(0.05);
    let behind = visibility(0.125);
    assert_eq!(
        beside, 1.0,
        "the bulb beside its pixel's centre ray is visible"
    );
    assert_eq!(
        behind, 0.0,
        "on the pixel's centre ray the board shadows it"
    );
}
