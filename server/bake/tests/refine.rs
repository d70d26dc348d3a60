//! Adaptive refinement where the lights' visibility varies: shadows get vertices, lit areas
//! stay coarse, the result is crack-free, deterministic and within budget.

use std::collections::HashMap;

use bspvt_bake::refine::{
    RefineSettings, RefineStats, Visibility, refine, refine_uniform, try_refine,
};
use bspvt_proto::Mesh;
use bspvt_proto::scene::{PolygonLight, Region};
use glam::Vec3;
use proptest::prelude::*;

// ---------------------------------------------------------------- scene builders

/// A square light of half-size `h` centred at (0, y, 0), emitting downward (counter-clockwise
/// seen from below).
fn down_light(y: f32, h: f32) -> PolygonLight {
    PolygonLight {
        vertices: vec![[-h, y, -h], [h, y, -h], [h, y, h], [-h, y, h]],
        radiance: [1.0; 3],
        two_sided: false,
        texture: None,
        region: None,
        moves_in_plane: true,
        image: None,
    }
}

/// A horizontal square facing +Y, centred at (cx, y, cz), half-size `h`, two triangles.
fn tile(cx: f32, y: f32, cz: f32, h: f32, material: u32) -> Mesh {
    Mesh {
        positions: vec![
            Vec3::new(cx - h, y, cz - h),
            Vec3::new(cx - h, y, cz + h),
            Vec3::new(cx + h, y, cz + h),
            Vec3::new(cx + h, y, cz - h),
        ],
        normals: vec![Vec3::Y; 4],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![material; 2],
        uvs: Vec::new(),
    }
}

/// A cube (24 vertices, flat normals, 12 triangles wound outward).
fn cube(centre: Vec3, h: f32, material: u32) -> Mesh {
    let mut m = Mesh::default();
    for n in [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z] {
        let u = if n.x != 0.0 { Vec3::Y } else { Vec3::X };
        let v = n.cross(u); // u × v = n
        let b = m.positions.len() as u32;
        for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            m.positions.push(centre + h * (n + su * u + sv * v));
            m.normals.push(n);
        }
        m.triangles.push([b, b + 1, b + 2]);
        m.triangles.push([b, b + 2, b + 3]);
        m.material_ids.extend([material; 2]);
    }
    m
}

/// The floor (4 m square at y = 0, two triangles) under a 0.5 m cube hovering at y = 0.5
/// (bottom face at y = 0.5), lit by a 0.5 m square light at y = 2 facing down.
fn floor_and_box() -> (Mesh, Vec<PolygonLight>) {
    let mut m = tile(0.0, 0.0, 0.0, 2.0, 0);
    m.append(&cube(Vec3::new(0.0, 0.75, 0.0), 0.25, 1), 0);
    (m, vec![down_light(2.0, 0.25)])
}

/// The default settings with visibility alone deciding (the lighting term has its own test).
fn settings() -> RefineSettings {
    RefineSettings {
        lighting: 0.0,
        ..RefineSettings::default()
    }
}

// ---------------------------------------------------------------- checks

fn edge(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

fn edge_counts(m: &Mesh) -> HashMap<(u32, u32), usize> {
    let mut c = HashMap::new();
    for t in &m.triangles {
        for i in 0..3 {
            *c.entry(edge(t[i], t[(i + 1) % 3])).or_insert(0) += 1;
        }
    }
    c
}

/// Whether `p` lies on segment ab (within `eps` of it, between its ends).
fn on_segment(p: Vec3, a: Vec3, b: Vec3, eps: f32) -> bool {
    let ab = b - a;
    let l2 = ab.length_squared();
    if l2 == 0.0 {
        return (p - a).length() <= eps;
    }
    let t = (p - a).dot(ab) / l2;
    let len = l2.sqrt();
    t >= -eps / len && t <= 1.0 + eps / len && (a + t * ab - p).length() <= eps
}

fn area(m: &Mesh) -> f64 {
    m.triangles
        .iter()
        .map(|t| {
            let p = t.map(|i| m.positions[i as usize]);
            0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length() as f64
        })
        .sum()
}

/// The refined mesh conforms to the input: every sub-edge of an input edge is shared by as
/// many triangles as the input edge was (two inside, one on the boundary), every new edge
/// inside an input triangle by exactly two, no vertex lies inside another triangle's edge
/// (no T-junction), and the area is unchanged.
fn assert_conforming(input: &Mesh, out: &Mesh) {
    out.validate().expect("refined mesh validates");
    let scale = input.bounds().diagonal().max(1e-6);
    let eps = 1e-5 * scale;
    let in_edges = edge_counts(input);
    let out_edges = edge_counts(out);
    let mut in_list: Vec<_> = in_edges.iter().map(|(&e, &c)| (e, c)).collect();
    in_list.sort_unstable();
    let mut out_list: Vec<_> = out_edges.iter().map(|(&e, &c)| (e, c)).collect();
    out_list.sort_unstable();
    for &((a, b), c) in &out_list {
        let (pa, pb) = (out.positions[a as usize], out.positions[b as usize]);
        let on_input = in_list.iter().find(|&&((i, j), _)| {
            let (pi, pj) = (input.positions[i as usize], input.positions[j as usize]);
            on_segment(pa, pi, pj, eps) && on_segment(pb, pi, pj, eps)
        });
        match on_input {
            Some(&((i, j), ci)) => assert_eq!(
                c, ci,
                "edge {a}-{b} lies on input edge {i}-{j} (shared by {ci}) but is shared by {c}"
            ),
            None => assert_eq!(c, 2, "new edge {a}-{b} is shared by {c} triangles"),
        }
    }
    for &((a, b), _) in &out_list {
        let (pa, pb) = (out.positions[a as usize], out.positions[b as usize]);
        let lo = pa.min(pb) - Vec3::splat(eps);
        let hi = pa.max(pb) + Vec3::splat(eps);
        for (v, &p) in out.positions.iter().enumerate() {
            let v = v as u32;
            if v == a || v == b || p.cmplt(lo).any() || p.cmpgt(hi).any() {
                continue;
            }
            let strictly_inside =
                on_segment(p, pa, pb, eps) && (p - pa).length() > eps && (p - pb).length() > eps;
            assert!(
                !strictly_inside,
                "T-junction: vertex {v} inside edge {a}-{b}"
            );
        }
    }
    let (ai, ao) = (area(input), area(out));
    assert!(
        (ai - ao).abs() <= 1e-4 * ai.max(1e-12),
        "area {ai} became {ao}"
    );
}

/// Original vertices keep index, position and normal; every input triangle slot either
/// holds its triangle unchanged or a half of it (which uses a new vertex); materials follow.
fn assert_prefix_kept(input: &Mesh, out: &Mesh) {
    let n = input.positions.len();
    assert_eq!(&out.positions[..n], &input.positions[..]);
    assert_eq!(&out.normals[..n], &input.normals[..]);
    for (i, t) in input.triangles.iter().enumerate() {
        let o = out.triangles[i];
        assert!(
            o == *t || o.iter().any(|&v| v as usize >= n),
            "slot {i}: {t:?} became {o:?} without a new vertex"
        );
        assert_eq!(out.material_ids[i], input.material_ids[i]);
    }
}

/// Every output triangle lies inside an input triangle of the same material.
fn assert_materials_follow(input: &Mesh, out: &Mesh) {
    for (k, t) in out.triangles.iter().enumerate() {
        if input.triangles.get(k) == Some(t) {
            continue; // unsplit (materials checked by assert_prefix_kept)
        }
        let p = t.map(|i| out.positions[i as usize]);
        let c = (p[0] + p[1] + p[2]) / 3.0;
        let host = input.triangles.iter().enumerate().find(|(_, s)| {
            let q = s.map(|i| input.positions[i as usize]);
            let n = (q[1] - q[0]).cross(q[2] - q[0]);
            let a2 = n.length_squared();
            if a2 == 0.0 {
                return false;
            }
            let bary = |x: Vec3, y: Vec3| (y - x).cross(c - x).dot(n) / a2;
            (c - q[0]).dot(n).abs() / a2.sqrt() < 1e-4
                && bary(q[0], q[1]) >= -1e-4
                && bary(q[1], q[2]) >= -1e-4
                && bary(q[2], q[0]) >= -1e-4
        });
        let (h, _) = host.unwrap_or_else(|| panic!("triangle {k} lies in no input triangle"));
        assert_eq!(out.material_ids[k], input.material_ids[h], "triangle {k}");
    }
}

fn mesh_bits(m: &Mesh) -> Vec<u32> {
    let mut b: Vec<u32> = Vec::new();
    for p in m.positions.iter().chain(&m.normals) {
        b.extend(p.to_array().map(f32::to_bits));
    }
    b.extend(m.triangles.iter().flatten());
    b.extend(&m.material_ids);
    b
}

/// Per-vertex V of `m` (a refinement of `base`, whose original vertices skip themselves).
fn vertex_v(vis: &Visibility, base: &Mesh, m: &Mesh) -> Vec<f32> {
    let n = base.positions.len();
    (0..m.positions.len())
        .map(|v| {
            let skip = (v < n).then_some(v as u32);
            vis.at(m.positions[v], m.normals[v], skip)
        })
        .collect()
}

/// V interpolated linearly at (x, 0, z) from the floor triangles (all corners at y = 0).
fn floor_interpolated(m: &Mesh, v: &[f32], x: f32, z: f32) -> Option<f32> {
    for t in &m.triangles {
        let p = t.map(|i| m.positions[i as usize]);
        if p.iter().any(|q| q.y != 0.0) {
            continue;
        }
        let (a, b, c) = (p[0], p[1], p[2]);
        let d = (b.x - a.x) * (c.z - a.z) - (c.x - a.x) * (b.z - a.z);
        if d == 0.0 {
            continue;
        }
        let l1 = ((x - a.x) * (c.z - a.z) - (c.x - a.x) * (z - a.z)) / d;
        let l2 = ((b.x - a.x) * (z - a.z) - (x - a.x) * (b.z - a.z)) / d;
        let l0 = 1.0 - l1 - l2;
        if l0 >= -1e-6 && l1 >= -1e-6 && l2 >= -1e-6 {
            return Some(l0 * v[t[0] as usize] + l1 * v[t[1] as usize] + l2 * v[t[2] as usize]);
        }
    }
    None
}

/// Mean |V_interpolated − V| over a 40 × 40 grid of cell centres on the floor.
fn floor_error(vis: &Visibility, base: &Mesh, m: &Mesh) -> f64 {
    let v = vertex_v(vis, base, m);
    let g = 40;
    let mut sum = 0.0f64;
    for j in 0..g {
        for i in 0..g {
            let x = -2.0 + 4.0 * (i as f32 + 0.5) / g as f32;
            let z = -2.0 + 4.0 * (j as f32 + 0.5) / g as f32;
            let exact = vis.at(Vec3::new(x, 0.0, z), Vec3::Y, None);
            let interp = floor_interpolated(m, &v, x, z).expect("point on the floor");
            sum += (interp - exact).abs() as f64;
        }
    }
    sum / (g * g) as f64
}

fn same_stats(a: &RefineStats, b: &RefineStats) -> bool {
    RefineStats { seconds: 0.0, ..*a } == RefineStats { seconds: 0.0, ..*b }
}

// ---------------------------------------------------------------- tests

/// Vertices go to the box's shadow boundary, not to the lit corners, and the interpolated
/// per-vertex visibility of the floor gets much closer to the true one.
#[test]
fn floor_under_a_box_is_refined_at_the_shadow_edge() {
    let (mesh, lights) = floor_and_box();
    let (out, st) = refine(&mesh, &lights, &settings());
    assert_conforming(&mesh, &out);
    assert_prefix_kept(&mesh, &out);
    assert!(st.splits > 50, "{st:?}");
    assert!(!st.budget_reached);
    assert_eq!(st.vertices_after, out.positions.len());
    assert_eq!(st.vertices_after, st.vertices_before + st.splits);
    assert_eq!(st.triangles_after, out.triangles.len());
    assert!(st.samples_cast > 0);

    // New floor vertices: near the shadow's edge (umbra |x|,|z| < 0.25, penumbra out to
    // 0.75) against the lit corners (both |x| and |z| > 1.25: 9 m² of the 16 m² floor).
    let n = mesh.positions.len();
    let new_floor = || out.positions[n..].iter().filter(|p| p.y == 0.0);
    let near = new_floor()
        .filter(|p| {
            let r = p.x.abs().max(p.z.abs());
            (0.1..=0.9).contains(&r)
        })
        .count();
    let corners = new_floor()
        .filter(|p| p.x.abs() > 1.25 && p.z.abs() > 1.25)
        .count();
    assert!(
        near > 20 * corners.max(1),
        "near the shadow {near}, in the lit corners {corners}"
    );

    let vis = Visibility::new(&mesh, &lights);
    let before = floor_error(&vis, &mesh, &mesh);
    let after = floor_error(&vis, &mesh, &out);
    eprintln!(
        "floor+box: vertices {} -> {}, triangles {} -> {}, splits {}, rays {}, {:.3} s; \
         new floor vertices near the shadow {near}, in the lit corners {corners}; \
         mean |V error| {before:.5} -> {after:.5}",
        st.vertices_before,
        st.vertices_after,
        st.triangles_before,
        st.triangles_after,
        st.splits,
        st.samples_cast,
        st.seconds
    );
    assert!(before > 0.02, "the shadow must matter: {before}");
    assert!(after < before / 5.0, "mean |V error| {before} -> {after}");
}

/// A box's shadow that falls inside one of a two-triangle floor's triangles, away from every
/// corner and edge midpoint (the shadow's centre is near (0.94, 0, −0.94); the floor's six
/// points per triangle are its corners and (±2, 0), (0, ±2), (0, 0)): the interior probes
/// find it and the floor is refined there, and only there.
#[test]
fn a_shadow_inside_a_large_triangle_is_found() {
    let mut mesh = tile(0.0, 0.0, 0.0, 2.0, 0);
    mesh.append(&cube(Vec3::new(0.8, 0.3, -0.8), 0.15, 1), 0);
    let lights = vec![down_light(2.0, 0.25)];
    let vis = Visibility::new(&mesh, &lights);
    for p in [
        [-2.0, -2.0],
        [-2.0, 0.0],
        [0.0, 0.0],
        [2.0, 0.0],
        [0.0, -2.0],
        [2.0, -2.0],
    ] {
        let v = vis.at(Vec3::new(p[0], 0.0, p[1]), Vec3::Y, None);
        assert!(v > 0.99, "the six points must all be lit: V{p:?} = {v}");
    }
    let (out, st) = refine(&mesh, &lights, &settings());
    assert_conforming(&mesh, &out);
    let n = mesh.positions.len();
    let new_floor: Vec<Vec3> = out.positions[n..]
        .iter()
        .copied()
        .filter(|p| p.y == 0.0)
        .collect();
    let near = new_floor
        .iter()
        .filter(|p| (p.x - 0.94).abs() < 0.6 && (p.z + 0.94).abs() < 0.6)
        .count();
    let far = new_floor.iter().filter(|p| p.x < -0.5 && p.z > 0.5).count();
    assert!(
        near > 20 && far * 50 <= near,
        "{st:?}: near {near}, far {far}"
    );
    let before = floor_error(&vis, &mesh, &mesh);
    let after = floor_error(&vis, &mesh, &out);
    assert!(after < before / 4.0, "mean |V error| {before} -> {after}");
}

/// The uniform baseline: crack-free, exactly at its budget, and even — the longest edge left
/// is at most twice as long as the shortest edge it made.
#[test]
fn uniform_subdivision_is_crack_free_and_meets_its_budget() {
    let (mesh, _) = floor_and_box();
    let budget = mesh.positions.len() as u32 + 500;
    let (out, st) = refine_uniform(&mesh, budget).expect("uniform");
    assert_conforming(&mesh, &out);
    assert_prefix_kept(&mesh, &out);
    assert_eq!(out.positions.len() as u32, budget, "{st:?}");
    assert!(st.budget_reached && st.samples_cast == 0);
    let floor_edges: Vec<f32> = out
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&i| out.positions[i as usize].y == 0.0))
        .flat_map(|t| {
            (0..3).map(|k| {
                (out.positions[t[k] as usize] - out.positions[t[(k + 1) % 3] as usize]).length()
            })
        })
        .collect();
    let longest = floor_edges.iter().copied().fold(0.0f32, f32::max);
    assert!(
        longest <= 4.0 * 2f32.sqrt() / 8.0 + 1e-4,
        "longest floor edge {longest}"
    );
    let again = refine_uniform(&mesh, budget).expect("uniform").0;
    assert_eq!(mesh_bits(&out), mesh_bits(&again));
}

/// The lighting term: a large floor under a small lamp, nothing in between (visibility is the
/// same everywhere), is refined for the irradiance's falloff — most where it changes fastest
/// (near the lamp's foot) — and not at all with the term off.
#[test]
fn lighting_term_refines_the_falloff() {
    let mesh = tile(0.0, 0.0, 0.0, 4.0, 0);
    let lights = vec![down_light(1.0, 0.1)];
    let off = refine(&mesh, &lights, &settings()).1;
    assert_eq!(off.splits, 0, "{off:?}");
    let (out, st) = refine(&mesh, &lights, &RefineSettings::default());
    assert_conforming(&mesh, &out);
    assert!(st.splits > 50 && !st.budget_reached, "{st:?}");
    let n = mesh.positions.len();
    let count = |r0: f32, r1: f32| {
        out.positions[n..]
            .iter()
            .filter(|p| (r0..r1).contains(&p.x.abs().max(p.z.abs())))
            .count() as f64
            / (r1 * r1 - r0 * r0) as f64
    };
    // Vertex density (per unit area) near the lamp's foot against the far band.
    let (near, far) = (count(0.0, 1.5), count(2.5, 4.0));
    assert!(near > 2.5 * far, "density near {near:.1}, far {far:.1}");
}

/// One thread or two: the same bytes.
#[test]
fn refinement_is_deterministic_across_thread_counts() {
    let (mesh, lights) = floor_and_box();
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool")
            .install(|| refine(&mesh, &lights, &settings()))
    };
    let (m1, s1) = run(1);
    let (m2, s2) = run(2);
    assert!(s1.splits > 0);
    assert_eq!(mesh_bits(&m1), mesh_bits(&m2));
    assert_eq!(m1, m2);
    assert!(same_stats(&s1, &s2), "{s1:?} vs {s2:?}");
}

/// A small budget is respected exactly and reported.
#[test]
fn budget_is_respected() {
    let (mesh, lights) = floor_and_box();
    let n = mesh.positions.len();
    for extra in [0u32, 1, 7, 40] {
        let s = RefineSettings {
            max_vertices: n as u32 + extra,
            ..settings()
        };
        let (out, st) = refine(&mesh, &lights, &s);
        assert!(out.positions.len() <= s.max_vertices as usize);
        assert_eq!(out.positions.len(), st.vertices_after);
        assert!(st.budget_reached, "{extra}: {st:?}");
        assert_eq!(st.splits, extra as usize);
        assert_conforming(&mesh, &out);
        assert_prefix_kept(&mesh, &out);
    }
    // A budget below the input's own size: nothing is split.
    let s = RefineSettings {
        max_vertices: 3,
        ..settings()
    };
    let (out, st) = refine(&mesh, &lights, &s);
    assert_eq!(out, mesh);
    assert!(st.budget_reached && st.splits == 0);
}

/// The largest errors (× size) are split first: two separate floor tiles of the same size,
/// the first (lower triangle indices) under a faint shadow (a small plate blocks at most
/// ~16 % of the light), the second under the box's deep shadow. Unbudgeted, both are
/// refined; with a small budget the deep shadow gets most of the vertices, although an index
/// order would start with the faint one (the faint tile's large triangles get their turn once
/// the deep shadow's triangles are small).
#[test]
fn budget_goes_to_the_largest_errors_first() {
    let mut mesh = tile(-1.5, 0.0, 0.0, 1.0, 0);
    mesh.append(&tile(1.5, 0.0, 0.0, 1.0, 0), 0);
    mesh.append(&cube(Vec3::new(1.0, 0.75, 0.0), 0.25, 1), 0);
    let mut plate = tile(-0.7, 1.0, 0.0, 0.05, 2);
    plate.normals = vec![-Vec3::Y; 4];
    mesh.append(&plate, 0);
    let lights = vec![down_light(2.0, 0.25)];
    let n = mesh.positions.len();
    let split = |max_vertices: u32| {
        let s = RefineSettings {
            max_vertices,
            ..settings()
        };
        let (out, st) = refine(&mesh, &lights, &s);
        assert_conforming(&mesh, &out);
        let faint = out.positions[n..]
            .iter()
            .filter(|p| p.y == 0.0 && p.x < 0.0)
            .count();
        let deep = out.positions[n..]
            .iter()
            .filter(|p| p.y == 0.0 && p.x > 0.0)
            .count();
        (faint, deep, st)
    };
    let (faint, deep, st) = split(RefineSettings::MAX_VERTICES);
    assert!(!st.budget_reached);
    assert!(
        faint >= 10 && deep >= 10,
        "unbudgeted: faint {faint}, deep {deep}"
    );
    let (faint, deep, st) = split(n as u32 + 40);
    assert!(st.budget_reached);
    assert!(
        deep >= 3 * faint && deep >= 28,
        "budgeted: faint {faint}, deep {deep}"
    );
}

/// No occluder: V is the same everywhere and nothing is split.
#[test]
fn uniformly_lit_mesh_is_not_refined() {
    let mesh = tile(0.0, 0.0, 0.0, 2.0, 0);
    let lights = vec![down_light(2.0, 0.25)];
    let (out, st) = refine(&mesh, &lights, &settings());
    assert_eq!(out, mesh);
    assert_eq!(st.splits, 0);
    assert!(!st.budget_reached);
    assert!(st.samples_cast > 0, "V was measured: {st:?}");
    // And the measure agrees: fully lit everywhere.
    let vis = Visibility::new(&mesh, &lights);
    assert_eq!(vis.at(Vec3::new(1.9, 0.0, -1.9), Vec3::Y, None), 1.0);
}

/// A lit tile far from the shadow keeps its triangles and slots; original vertices stay;
/// every triangle keeps its material.
#[test]
fn unsplit_triangles_and_original_vertices_are_kept() {
    let (mut mesh, lights) = floor_and_box();
    let first_tile = mesh.triangles.len();
    mesh.append(&tile(10.0, 0.0, 0.0, 0.5, 2), 0);
    let (out, st) = refine(&mesh, &lights, &settings());
    assert!(st.splits > 0);
    assert_prefix_kept(&mesh, &out);
    assert_eq!(
        &out.triangles[first_tile..first_tile + 2],
        &mesh.triangles[first_tile..]
    );
    // The box's top is fully lit and its other faces see no light: left alone too.
    for t in 2..14 {
        assert_eq!(out.triangles[t], mesh.triangles[t], "box triangle {t}");
    }
    assert_materials_follow(&mesh, &out);
    assert_conforming(&mesh, &out);
}

/// The visibility measure: 0 under the box, 1 in the open, in between in the penumbra,
/// and counted as unseen below the horizon.
#[test]
fn visibility_measure() {
    let (mesh, lights) = floor_and_box();
    let vis = Visibility::new(&mesh, &lights);
    assert!((45..=64).contains(&vis.sample_count()));
    assert_eq!(vis.at(Vec3::ZERO, Vec3::Y, None), 0.0);
    assert_eq!(vis.at(Vec3::new(1.5, 0.0, 0.0), Vec3::Y, None), 1.0);
    let pen = vis.at(Vec3::new(0.5, 0.0, 0.0), Vec3::Y, None);
    assert!(pen > 0.1 && pen < 0.9, "{pen}");
    assert_eq!(vis.at(Vec3::new(1.5, 0.0, 0.0), -Vec3::Y, None), 0.0);
    // Monotone across the penumbra.
    let xs: Vec<f32> = (0..=20)
        .map(|i| vis.at(Vec3::new(i as f32 * 0.05, 0.0, 0.0), Vec3::Y, None))
        .collect();
    assert!(xs.windows(2).all(|w| w[0] <= w[1]), "{xs:?}");
}

/// A light that moves inside a region is sampled over the region: a wider penumbra, and
/// refinement still conforms.
#[test]
fn region_light_refines_and_conforms() {
    let (mesh, _) = floor_and_box();
    let mut light = down_light(2.0, 0.25);
    light.region = Some(Region {
        min: [-1.0, 1.9, -0.25],
        max: [1.0, 2.1, 0.25],
    });
    let lights = vec![light];
    let vis = Visibility::new(&mesh, &lights);
    let v = vis.at(Vec3::new(1.0, 0.0, 0.0), Vec3::Y, None);
    assert!(v > 0.05 && v < 0.95, "region penumbra: {v}");
    let (out, st) = refine(&mesh, &lights, &settings());
    assert!(st.splits > 20, "{st:?}");
    assert_conforming(&mesh, &out);
}

/// Inputs that cannot be refined come back unchanged; odd but valid ones do not panic.
#[test]
fn odd_inputs_do_not_panic() {
    let lights = vec![down_light(2.0, 0.25)];
    // Empty mesh.
    let empty = Mesh::default();
    let (out, st) = refine(&empty, &lights, &settings());
    assert_eq!(out, empty);
    assert_eq!(st.splits, 0);
    assert!(try_refine(&empty, &lights, &settings()).is_err());
    // An index out of range.
    let mut bad = tile(0.0, 0.0, 0.0, 1.0, 0);
    bad.triangles.push([0, 1, 99]);
    bad.material_ids.push(0);
    assert_eq!(refine(&bad, &lights, &settings()).0, bad);
    // Invalid settings.
    let (mesh, lights_box) = floor_and_box();
    let nan = RefineSettings {
        tolerance: f32::NAN,
        ..settings()
    };
    let err = try_refine(&mesh, &lights_box, &nan)
        .err()
        .map(|e| e.to_string());
    assert!(err.is_some_and(|e| e.contains("tolerance")));
    assert_eq!(refine(&mesh, &lights_box, &nan).0, mesh);
    // No lights, unusable lights: V = 0 everywhere, nothing to do.
    let mut broken = down_light(2.0, 0.25);
    broken.vertices[1][0] = f32::NAN;
    let mut two = down_light(2.0, 0.25);
    two.vertices.truncate(2);
    for ls in [vec![], vec![broken, two]] {
        let (out, st) = refine(&mesh, &ls, &settings());
        assert_eq!(out, mesh);
        assert_eq!(st.samples_cast, 0);
    }
    // Degenerate triangles (a repeated corner, collinear corners) next to a shadowed floor.
    let mut deg = mesh.clone();
    let b = deg.positions.len() as u32;
    deg.positions.extend([
        Vec3::new(-1.0, 0.3, 0.0),
        Vec3::new(0.0, 0.3, 0.0),
        Vec3::new(1.0, 0.3, 0.0),
    ]);
    deg.normals.extend([Vec3::Y; 3]);
    deg.triangles.extend([[b, b, b + 1], [b, b + 1, b + 2]]);
    deg.material_ids.extend([0, 0]);
    let (out, st) = refine(&deg, &lights_box, &settings());
    out.validate().expect("valid");
    assert!(st.splits > 0);
    // Zero and opposite normals, a tiny min_edge.
    let mut odd = mesh.clone();
    odd.normals[0] = Vec3::ZERO;
    odd.normals[2] = -Vec3::Y;
    let tiny = RefineSettings {
        min_edge: 1e-30,
        max_vertices: 3000,
        ..settings()
    };
    let (out, _) = refine(&odd, &lights_box, &tiny);
    out.validate().expect("valid");
    assert!(out.normals.iter().all(|n| n.is_finite()));
    // Huge and tiny coordinates: the scene scaled by 1e36, 1.5e38 (its diagonal overflows
    // f32) and 1e-30 refines like the scene itself (up to rounding).
    let unit = refine(&mesh, &lights_box, &settings()).1.splits as f64;
    for k in [1e36f32, 1.5e38, 1e-30] {
        let mut scaled = mesh.clone();
        for p in &mut scaled.positions {
            *p *= k;
        }
        let mut light = down_light(2.0, 0.25);
        for v in &mut light.vertices {
            *v = v.map(|x| x * k);
        }
        let (out, st) = refine(&scaled, &[light], &settings());
        out.validate().expect("valid");
        assert!(out.positions.iter().all(|p| p.is_finite()), "{k}");
        let ratio = st.splits as f64 / unit;
        assert!(
            (0.95..=1.05).contains(&ratio),
            "scale {k:e}: {st:?}, unit {unit}"
        );
    }
}

// ---------------------------------------------------------------- property

/// A jittered n × n grid on y ≈ 0 (normals +Y) plus one occluder triangle above it.
fn grid_scene(n: usize, jitter: &[(f32, f32, f32)], occ: [(f32, f32, f32); 3]) -> Mesh {
    let mut m = Mesh::default();
    let step = 2.0 / (n - 1) as f32;
    for j in 0..n {
        for i in 0..n {
            let (dx, dy, dz) = jitter[j * n + i];
            let interior = i > 0 && j > 0 && i + 1 < n && j + 1 < n;
            let k = if interior { 0.3 * step } else { 0.0 };
            m.positions.push(Vec3::new(
                -1.0 + i as f32 * step + k * dx,
                0.05 * dy,
                -1.0 + j as f32 * step + k * dz,
            ));
            m.normals.push(Vec3::Y);
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let v = (j * n + i) as u32;
            let (a, b, c, d) = (v, v + 1, v + n as u32, v + n as u32 + 1);
            // Alternate the diagonal so both orientations occur.
            if (i + j) % 2 == 0 {
                m.triangles.extend([[a, c, d], [a, d, b]]);
            } else {
                m.triangles.extend([[a, c, b], [b, c, d]]);
            }
            m.material_ids.extend([(i % 3) as u32, (j % 3) as u32]);
        }
    }
    let b = m.positions.len() as u32;
    for (x, y, z) in occ {
        m.positions.push(Vec3::new(x, 0.3 + y, z));
        m.normals.push(-Vec3::Y);
    }
    m.triangles.push([b, b + 1, b + 2]);
    m.material_ids.push(7);
    m
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Crack-free, valid and within budget on random small meshes.
    #[test]
    fn random_meshes_refine_crack_free_within_budget(
        n in 2usize..=5,
        jitter in prop::collection::vec((-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0), 25),
        occ in prop::array::uniform3((-1.0f32..1.0, 0.0f32..0.6, -1.0f32..1.0)),
        tolerance in 0.02f32..0.5,
        extra in 0u32..400,
        min_edge in prop_oneof![Just(0.0f32), 0.01f32..0.2],
        region in any::<bool>(),
    ) {
        let mesh = grid_scene(n, &jitter, occ);
        prop_assume!(mesh.validate().is_ok());
        let mut light = down_light(2.0, 0.3);
        if region {
            light.region = Some(Region { min: [-0.6, 1.9, -0.6], max: [0.6, 2.1, 0.6] });
        }
        let s = RefineSettings {
            tolerance,
            lighting: tolerance,
            min_edge,
            max_vertices: mesh.positions.len() as u32 + extra,
        };
        let (out, st) = refine(&mesh, &[light], &s);
        prop_assert!(out.positions.len() <= s.max_vertices as usize);
        prop_assert_eq!(st.vertices_after, out.positions.len());
        prop_assert_eq!(st.vertices_after, st.vertices_before + st.splits);
        if st.budget_reached {
            // Each split adds one vertex; refinement stops only when the next would not fit.
            prop_assert_eq!(st.vertices_after, s.max_vertices as usize);
        }
        assert_conforming(&mesh, &out);
        assert_prefix_kept(&mesh, &out);
        assert_materials_follow(&mesh, &out);
    }
}
