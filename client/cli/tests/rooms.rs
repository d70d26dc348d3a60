//! Enclosed rooms given alone, as a user brings them (`--mesh`): the project's Cornell box
//! (OBJ + MTL with `Ke`), glTF room, two-lamp glTF room and the room lit by point, spot and
//! sun lights (`assets/rooms/`). Their own lights light them (all of them, summed), the
//! ceiling above a lamp does not shadow the floor, a lower lamp does not end the rays that
//! pass beside it, the sun's patch through a window is there and soft-edged, and BSPVT per
//! pixel agrees with the project's Monte Carlo reference.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use bspvt_bake::Baker;
use bspvt_client::frame::image::Image;
use bspvt_client::groundtruth::render_mc;
use bspvt_client::light::{Light, Shape, scene_lights};
use bspvt_client::render::renderer::{Mode, Renderer, Trees};
use bspvt_proto::Scene;
use bspvt_proto::encoding::decode_bake;
use bspvt_raytrace::{Occluder, mesh_triangles};

/// A round light's disk as a vertex sees it: a 12-gon of `radius` around `centre` (a direction
/// from the vertex, not normalised), across the view.
fn twelve_gon(centre: glam::DVec3, radius: f64) -> Vec<glam::DVec3> {
    let (e1, e2) = centre.normalize().any_orthonormal_pair();
    (0..12)
        .map(|k| {
            let phi = std::f64::consts::TAU * f64::from(k) / 12.0;
            centre + radius * (phi.cos() * e1 + phi.sin() * e2)
        })
        .collect()
}

/// At vertex `v`: the trees' visible share of `disk` (directions from the vertex) clipped to
/// the vertex's horizon, and the refinement's independent measure (rays to the light);
/// `None` where the disk is below the horizon.
fn baked_and_exact(
    b: &bspvt_proto::encoding::Bake,
    codec: &bspvt_proto::bspvt::LineCodec,
    s: &Scene,
    exact: &bspvt_bake::refine::Visibility,
    v: usize,
    disk: &[glam::DVec3],
) -> Option<(f64, f64)> {
    let (p, nrm) = (s.mesh.positions[v], s.mesh.normals[v]);
    let dirs = bspvt_proto::sphere::clip(disk, nrm.as_dvec3());
    (dirs.len() >= 3).then(|| {
        let baked = b.trees[v].visible_fraction(codec, &dirs);
        (baked, f64::from(exact.at(p, nrm, Some(v as u32))))
    })
}

fn room(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/rooms")
        .join(name)
}

/// Every light of `scene` (lamps, point, spot and sun lights), at rest.
fn lights_of(scene: &Scene) -> Vec<Light> {
    scene_lights(scene)
        .expect("lights")
        .into_iter()
        .map(|l| l.0)
        .collect()
}

/// `scene` baked and decoded.
fn baked(scene: &Scene) -> bspvt_proto::encoding::Bake {
    let bytes = Baker::new(scene)
        .bake_all(&|_, _| {}, &AtomicBool::new(false))
        .expect("bake")
        .bytes;
    decode_bake(&bytes).expect("decode")
}

/// Mean over pixels of the channel-mean |a − b|.
fn mean_abs_diff(a: &Image, b: &Image) -> f64 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(x, y)| (0..3).map(|k| f64::from((x[k] - y[k]).abs())).sum::<f64>() / 3.0)
        .sum::<f64>()
        / a.pixels.len() as f64
}

/// BSPVT (per pixel and per vertex) and unshadowed LTC against Monte Carlo; returns the
/// errors relative to the Monte Carlo mean: (per pixel, per vertex, shadows' effect).
fn errors(scene: &Scene, size: (u32, u32), spp: u32) -> (f64, f64, f64) {
    let lights = lights_of(scene);
    errors_with(scene, &lights, size, spp).0
}

/// [`errors`] for `lights`, and the BSPVT per-pixel and Monte Carlo images.
fn errors_with(
    scene: &Scene,
    lights: &[Light],
    size: (u32, u32),
    spp: u32,
) -> ((f64, f64, f64), Image, Image) {
    let b = baked(scene);
    // A refined scene's bake carries the refined mesh, whose hash the header names.
    // (Its geometry: the mesh frame does not carry UVs.)
    assert_eq!(
        b.mesh.as_ref().map(|m| m.content_hash()),
        Some(scene.mesh.content_hash()),
        "the bake carries its mesh"
    );
    let trees = Trees::full(&b.trees, b.header.codec());
    // The suns' own bake where the scene has other lights too (Scene::suns_in_sky_bake).
    let sky = scene.suns_in_sky_bake().then(|| baked(&scene.sky()));
    let sky = sky
        .as_ref()
        .map(|b| Trees::full(&b.trees, b.header.codec()));
    let r = Renderer::new(scene, size.0, size.1);
    // Every light of the room, summed.
    let (pixel, _) = r.bspvt_lights(lights, Some(&trees), sky.as_ref(), Mode::Pixel);
    let (vertex, _) = r.bspvt_lights(lights, Some(&trees), sky.as_ref(), Mode::Vertex);
    let (unshadowed, _) = r.ltc(lights, Mode::Pixel);
    let occ = Occluder::of_surfaces(&scene.mesh, &scene.materials);
    let (mc, _) = render_mc(scene, &r.view, &r.gbuffer, lights, &occ, spp, 7);
    for img in [&pixel, &vertex, &unshadowed, &mc] {
        assert!(
            img.pixels
                .iter()
                .flatten()
                .all(|c| c.is_finite() && *c >= 0.0)
        );
    }
    let mean = mc.mean();
    assert!(mean > 0.0, "the room is black");
    // Where the shadows are: pixels the Monte Carlo puts below 70 % of the unshadowed LTC
    // (penumbrae and umbrae), the mean |BSPVT − MC| there against the lit level (the mean
    // unshadowed radiance of those pixels). Printed, as the whole-image figures are asserted.
    let lum = |p: &[f32; 3]| f64::from(p[0] + p[1] + p[2]) / 3.0;
    let (mut diff, mut lit, mut k) = (0.0, 0.0, 0usize);
    for ((b, m), u) in pixel.pixels.iter().zip(&mc.pixels).zip(&unshadowed.pixels) {
        if lum(u) > 0.0 && lum(m) < 0.7 * lum(u) {
            diff += (0..3).map(|c| f64::from((b[c] - m[c]).abs())).sum::<f64>() / 3.0;
            lit += lum(u);
            k += 1;
        }
    }
    println!(
        "  in the shadows ({k} px below 70 % of unshadowed): mean |BSPVT per pixel − MC| = {:.4} of the lit level",
        diff / lit.max(f64::MIN_POSITIVE)
    );
    (
        (
            mean_abs_diff(&pixel, &mc) / mean,
            mean_abs_diff(&vertex, &mc) / mean,
            mean_abs_diff(&unshadowed, &mc) / mean,
        ),
        pixel,
        mc,
    )
}

#[test]
fn cornell_box_bspvt_per_pixel_matches_monte_carlo() {
    let mut s = Scene::from_mesh_path(&room("cornell-box.obj")).expect("cornell box");
    s.bake.face_res = 32;
    // A budget keeps the test quick (the default refines to ~16K vertices).
    if let Some(r) = &mut s.bake.refine {
        r.max_vertices = 4000;
    }
    let before = s.mesh.vertex_count();
    bspvt_bake::refine::refine_scene(&mut s).expect("refine");
    let (pixel, vertex, shadows) = errors(&s, (64, 64), 64);
    println!(
        "cornell box: {before} → {} vertices; vs MC: per pixel {pixel:.4}, per vertex {vertex:.4}, unshadowed {shadows:.4}",
        s.mesh.vertex_count()
    );
    assert!(pixel <= 0.05, "per-pixel error {pixel}");
}

#[test]
fn gltf_room_bspvt_per_pixel_matches_monte_carlo() {
    let mut s = Scene::from_mesh_path(&room("room.gltf")).expect("room");
    s.bake.face_res = 32;
    // A budget keeps the test quick (the default refines to ~16K vertices).
    if let Some(r) = &mut s.bake.refine {
        r.max_vertices = 4000;
    }
    let before = s.mesh.vertex_count();
    bspvt_bake::refine::refine_scene(&mut s).expect("refine");
    let (pixel, vertex, shadows) = errors(&s, (72, 48), 64);
    println!(
        "glTF room: {before} → {} vertices; vs MC: per pixel {pixel:.4}, per vertex {vertex:.4}, unshadowed {shadows:.4}",
        s.mesh.vertex_count()
    );
    assert!(pixel <= 0.05, "per-pixel error {pixel}");
}

/// Issue 34: two lamps at different heights — the ceiling lamp and a pendant lamp 1.2 m lower —
/// and a board between the pendant's height and the ceiling. Both lamps light the frame; the
/// board shadows the floor from the ceiling lamp (before, rays ended at the pendant's infinite
/// plane and it cast no shadow: 42 % mean error); BSPVT per pixel within 5 % of Monte Carlo.
#[test]
fn two_lamp_room_bspvt_per_pixel_matches_monte_carlo() {
    let mut s = Scene::from_mesh_path(&room("two-lamps.gltf")).expect("two-lamp room");
    assert_eq!(s.lights.len(), 2, "the ceiling lamp and the pendant");
    let heights: Vec<f32> = s.lights.iter().map(|l| l.vertices[0][1]).collect();
    assert!((heights[0] - heights[1]).abs() > 1.0, "{heights:?}");
    s.bake.face_res = 32;
    if let Some(r) = &mut s.bake.refine {
        r.max_vertices = 4000;
    }
    let before = s.mesh.vertex_count();
    bspvt_bake::refine::refine_scene(&mut s).expect("refine");
    let (pixel, vertex, shadows) = errors(&s, (72, 48), 64);
    println!(
        "two-lamp room: {before} → {} vertices; vs MC: per pixel {pixel:.4}, per vertex {vertex:.4}, unshadowed {shadows:.4}",
        s.mesh.vertex_count()
    );
    assert!(pixel <= 0.05, "per-pixel error {pixel}");
    assert!(
        shadows > 2.0 * pixel,
        "the shadows matter: unshadowed {shadows}"
    );
    // Control: the rule before issue 34 (both lamps moving in their planes, rays ending at
    // the pendant's plane below the board) on the same mesh.
    let mut planes = s.clone();
    planes
        .lights
        .iter_mut()
        .for_each(|l| l.moves_in_plane = true);
    let (pixel_planes, _, _) = errors(&planes, (72, 48), 64);
    println!("two-lamp room, rays ending at the lamps' planes: per pixel {pixel_planes:.4}");
    assert!(pixel_planes > 2.0 * pixel, "control {pixel_planes}");
}

/// Issue 34: a room lit only by `KHR_lights_punctual` lights, as Blender exports them — a point
/// light, a spot light and a sun through a window. They are lights for the default method
/// (spheres and a disk at infinity through the trees), BSPVT per pixel within 5 % of the Monte
/// Carlo, and the sun's patch on the floor is there, with a soft edge.
#[test]
fn punctual_room_bspvt_per_pixel_matches_monte_carlo() {
    let mut s = Scene::from_mesh_path(&room("punctual-room.gltf")).expect("punctual room");
    assert!(s.lights.is_empty(), "no emissive polygon");
    assert_eq!(s.punctual.len(), 2, "the point light and the spot");
    assert_eq!(s.suns.len(), 1, "the sun");
    s.bake.face_res = 32;
    if let Some(r) = &mut s.bake.refine {
        r.max_vertices = 4000;
    }
    let before = s.mesh.vertex_count();
    bspvt_bake::refine::refine_scene(&mut s).expect("refine");
    let all = lights_of(&s);
    for (k, l) in all.iter().enumerate() {
        let ((p, v, u), _, _) = errors_with(&s, std::slice::from_ref(l), (72, 48), 64);
        println!("  light {k} alone: per pixel {p:.4}, per vertex {v:.4}, unshadowed {u:.4}");
    }
    let (pixel, vertex, shadows) = errors(&s, (72, 48), 64);
    println!(
        "punctual room: {before} → {} vertices; vs MC: per pixel {pixel:.4}, per vertex {vertex:.4}, unshadowed {shadows:.4}",
        s.mesh.vertex_count()
    );
    assert!(pixel <= 0.05, "per-pixel error {pixel}");
    assert!(
        shadows > 2.0 * pixel,
        "the shadows matter: unshadowed {shadows}"
    );

    // The sun alone: its patch through the window, against the Monte Carlo, and its edge.
    let sun: Vec<Light> = scene_lights(&s)
        .expect("lights")
        .into_iter()
        .map(|l| l.0)
        .filter(|l| matches!(l.shape, Shape::Distant { .. }))
        .collect();
    let ((sun_pixel, _, _), bspvt, mc) = errors_with(&s, &sun, (96, 64), 64);
    let lum = |p: &[f32; 3]| f64::from(p[0] + p[1] + p[2]) / 3.0;
    let top = bspvt.pixels.iter().map(lum).fold(0.0, f64::max);
    let lit = bspvt.pixels.iter().filter(|p| lum(p) > 0.8 * top).count();
    let edge = bspvt
        .pixels
        .iter()
        .filter(|p| (0.2 * top..0.8 * top).contains(&lum(p)))
        .count();
    let mc_lit = mc.pixels.iter().filter(|p| lum(p) > 0.8 * top).count();
    println!(
        "punctual room, the sun alone: per pixel {sun_pixel:.4}; patch {lit} px (MC {mc_lit}), edge {edge} px"
    );
    assert!(lit >= 40, "the sun's patch is there: {lit} px");
    assert!(edge > 0, "its edge is soft");
    assert!(
        (lit as f64 - mc_lit as f64).abs() <= 0.25 * mc_lit as f64,
        "the patch has the Monte Carlo's size: {lit} vs {mc_lit}"
    );
}

/// A bulb's shadow at every vertex is the bulb's own: the point light's and the spot's
/// visibility as the trees give it (their share of the bulb's disk, Σ v̄ᵢ Ωᵢ / Ω) against the
/// refinement's independent measure (rays to 256 points of the sphere), at every vertex of the
/// room's flat surfaces (floor, walls, box, pillar: where the shadows fall; the ball's
/// faceted terminator is where the two measures' self-shadowing rules differ), at the default
/// bake and refinement. Both lights share one tree set: before, a face's leaf could average
/// the bulb's 1–4 pixels with the spot's (the fit's tolerance, ε · res² ≈ 4 pixels of squared
/// deviation, is a whole bulb), and vertices near a shadow's edge took the other light's
/// visibility — a dotted edge around the box's shadow (flat surfaces: mean 0.059 and 0.055,
/// 396 and 118 vertices off by more than half; now 0.019 and 0.013, none).
#[test]
fn a_bulbs_shadow_is_its_own_at_every_vertex() {
    let mut s = Scene::from_mesh_path(&room("punctual-room.gltf")).expect("punctual room");
    s.suns.clear(); // the sun is shaded through the sky's bake, not this one
    assert_eq!(s.punctual.len(), 2, "the point light and the spot");
    bspvt_bake::refine::refine_scene(&mut s).expect("refine");
    let b = baked(&s);
    let codec = b.header.codec();
    let mut stats = Vec::new();
    for light in &s.punctual {
        let exact = bspvt_bake::refine::Visibility::new(&s.mesh, &[])
            .with_spheres(std::slice::from_ref(light));
        let c = glam::DVec3::from(light.position.map(f64::from));
        let r = f64::from(light.sphere_radius());
        // (vertices, Σ |baked − exact|, off by more than half, in the penumbra)
        let mut flat = (0usize, 0.0, 0usize, 0usize);
        let mut curved = (0usize, 0.0, 0usize);
        for v in 0..b.trees.len() {
            // The bulb's disk as the vertex sees it.
            let disk = twelve_gon(c - s.mesh.positions[v].as_dvec3(), r);
            let Some((baked, truth)) = baked_and_exact(&b, &codec, &s, &exact, v, &disk) else {
                continue;
            };
            let d = (baked - truth).abs();
            if s.mesh.normals[v].abs().max_element() > 0.999 {
                flat.0 += 1;
                flat.1 += d;
                flat.2 += usize::from(d > 0.5);
                flat.3 += usize::from(truth > 0.05 && truth < 0.95);
            } else {
                curved.0 += 1;
                curved.1 += d;
                curved.2 += usize::from(d > 0.5);
            }
        }
        let mean = flat.1 / flat.0.max(1) as f64;
        println!(
            "  {}: {} vertices of flat surfaces see it ({} in its penumbra): mean |baked − exact| {mean:.4}, {} off by more than half; on the ball: {} vertices, mean {:.4}, {} off by more than half",
            light.name,
            flat.0,
            flat.3,
            flat.2,
            curved.0,
            curved.1 / curved.0.max(1) as f64,
            curved.2
        );
        stats.push((light.name.clone(), flat.0, flat.3, mean, flat.2));
    }
    for (name, n, penumbra, mean, off) in stats {
        assert!(
            n > 1000 && penumbra > 100,
            "{name}: {n} vertices, {penumbra} in the penumbra"
        );
        assert!(mean <= 0.03, "{name}: mean {mean}");
        assert!(
            off * 1000 <= n,
            "{name}: {off} of {n} vertices off by more than half"
        );
    }
}

/// The sun at rest through the sky's trees, per vertex: the trees' visible share of the sun's
/// disk (a 12-gon of its angular radius around its direction) at every vertex of the room's
/// flat surfaces, against the share of 69 rays over the disk that escape (the refinement's
/// measure, `Visibility::with_suns`, of suns spread over the disk). The disk is a third of a
/// 64² pixel: each vertex saw the sun through the pixel's own ray, at its centre, and the fit's
/// tolerance (ε · res² ≈ 4 pixels of squared deviation, face-wide) let a leaf average it with
/// its neighbours, so the window's edge moved by a pixel or two between neighbouring vertices —
/// a stair-stepped patch on the floor. Now the sky's bake aims the sun's pixels at the sun and
/// keeps them in pure leaves (`VertexRays::aim`, `FacePixels::protected`): of 6,007 vertices
/// (1,158 lit, 353 in the penumbra), mean 0.024 and 63 off by more than half (the leaves' lines
/// may still cut a sun's pixel between its centre and the disk). Before the change (the same
/// test on 66e91f6's bake): mean 0.049, 217 off by more than half.
#[test]
fn the_suns_patch_is_its_own_at_every_vertex() {
    let mut s = Scene::from_mesh_path(&room("punctual-room.gltf")).expect("punctual room");
    assert_eq!(s.suns.len(), 1, "the sun");
    bspvt_bake::refine::refine_scene(&mut s).expect("refine");
    assert!(
        s.suns_in_sky_bake(),
        "the sun is shaded through the sky's bake"
    );
    let bytes = Baker::new(&s.sky())
        .bake_all(&|_, _| {}, &AtomicBool::new(false))
        .expect("sky bake")
        .bytes;
    let b = decode_bake(&bytes).expect("decode");
    let codec = b.header.codec();
    let sun = &s.suns[0];
    let w = sun.toward().as_dvec3();
    let tan_h = f64::from(sun.half_angle()).tan();
    let (e1, e2) = w.any_orthonormal_pair();
    // The exact measure: suns of no size on a 9 × 9 grid over the disk (the 69 inside it).
    let at = |k: i32| f64::from(2 * k + 1) / 9.0 - 1.0;
    let spread: Vec<bspvt_proto::scene::SunLight> = (0..9)
        .flat_map(|y| (0..9).map(move |x| (at(x), at(y))))
        .filter(|(x, y)| x * x + y * y <= 1.0)
        .map(|(x, y)| bspvt_proto::scene::SunLight {
            name: String::new(),
            direction: (-(w + tan_h * (x * e1 + y * e2)).normalize())
                .as_vec3()
                .to_array(),
            illuminance: sun.illuminance,
            angular_diameter: Some(1e-5),
        })
        .collect();
    let exact = bspvt_bake::refine::Visibility::new(&s.mesh, &[]).with_suns(&spread);
    let disk = twelve_gon(w, tan_h);
    // (vertices, Σ |baked − exact|, off by more than half, in the penumbra, lit)
    let mut flat = (0usize, 0.0, 0usize, 0usize, 0usize);
    for v in 0..b.trees.len() {
        if s.mesh.normals[v].abs().max_element() <= 0.999 {
            continue;
        }
        let Some((baked, truth)) = baked_and_exact(&b, &codec, &s, &exact, v, &disk) else {
            continue;
        };
        let d = (baked - truth).abs();
        flat.0 += 1;
        flat.1 += d;
        flat.2 += usize::from(d > 0.5);
        flat.3 += usize::from(truth > 0.05 && truth < 0.95);
        flat.4 += usize::from(truth >= 0.5);
    }
    let mean = flat.1 / flat.0.max(1) as f64;
    println!(
        "  sun at rest, sky bake of {} bytes: {} vertices of flat surfaces face it ({} lit, {} in its penumbra): mean |baked − exact| {mean:.4}, {} off by more than half",
        bytes.len(),
        flat.0,
        flat.4,
        flat.3,
        flat.2
    );
    assert!(flat.0 > 1000 && flat.4 > 100, "{flat:?}");
    assert!(mean <= 0.03, "mean {mean}");
    assert!(
        flat.2 * 50 <= flat.0,
        "{} of {} off by more than half",
        flat.2,
        flat.0
    );
}

/// Issue 35: a canopy (one double-sided quad) over a floor that is one quad, under a lamp. Its
/// umbra — the pixels where the Monte Carlo is below 2 % of the unshadowed light — must stay
/// dark in BSPVT, per pixel and per vertex, at the default refinement and bake settings: the
/// mean there ≤ 2 % and the 99th percentile ≤ 10 % of the unshadowed level (light leaked
/// through the canopy's diagonal, where the cube maps' dyadic directions met the edge its two
/// triangles share, and no test saw it: the whole-image error was 2.3 %).
#[test]
fn canopy_umbra_does_not_leak() {
    let mut s = Scene::from_mesh_path(&room("canopy.gltf")).expect("canopy");
    let before = s.mesh.vertex_count();
    let budget = s.bake.refine.map(|r| r.max_vertices);
    let st = bspvt_bake::refine::refine_scene(&mut s)
        .expect("refine")
        .expect("an asset given alone is refined");
    let bytes = Baker::new(&s)
        .bake_all(&|_, _| {}, &AtomicBool::new(false))
        .expect("bake")
        .bytes;
    let b = decode_bake(&bytes).expect("decode");
    let trees = Trees::full(&b.trees, b.header.codec());
    let lights = lights_of(&s);
    let r = Renderer::new(&s, 96, 64);
    let (unshadowed, _) = r.ltc(&lights, Mode::Pixel);
    let occ = Occluder::new(&s.mesh, &mesh_triangles(&s.mesh));
    let (mc, _) = render_mc(&s, &r.view, &r.gbuffer, &lights, &occ, 64, 7);
    let lum = |p: &[f32; 3]| f64::from(p[0] + p[1] + p[2]) / 3.0;
    let umbra: Vec<usize> = (0..mc.pixels.len())
        .filter(|&i| {
            let u = lum(&unshadowed.pixels[i]);
            u > 0.0 && lum(&mc.pixels[i]) < 0.02 * u
        })
        .collect();
    assert!(
        umbra.len() > 200,
        "the umbra is in view: {} px",
        umbra.len()
    );
    println!(
        "canopy: {before} → {} vertices (budget {budget:?}, {} splits), {} bytes baked; umbra {} px",
        s.mesh.vertex_count(),
        st.splits,
        bytes.len(),
        umbra.len()
    );
    for mode in [Mode::Pixel, Mode::Vertex] {
        let (img, _) = r.bspvt(&lights, &trees, mode);
        let mut leak: Vec<f64> = umbra
            .iter()
            .map(|&i| lum(&img.pixels[i]) / lum(&unshadowed.pixels[i]))
            .collect();
        leak.sort_by(f64::total_cmp);
        let mean = leak.iter().sum::<f64>() / leak.len() as f64;
        let p99 = leak[(leak.len() * 99 / 100).min(leak.len() - 1)];
        let max = leak[leak.len() - 1];
        println!(
            "  {mode:?}: umbra leak mean {mean:.4}, p99 {p99:.4}, max {max:.4} of the unshadowed level"
        );
        assert!(
            mean <= 0.02 && p99 <= 0.10,
            "{mode:?}: leak mean {mean}, p99 {p99}"
        );
    }
}

/// Issue 35: the same canopy cut out by an alpha checker (`alphaMode` MASK over an 8 × 8
/// texture, half open) lets about half the lamp's light reach the floor beneath it — in BSPVT
/// and in the Monte Carlo, whose rays pass through the holes too — where the opaque board
/// leaves an umbra; BSPVT per pixel is within 5 % of the Monte Carlo over the image.
#[test]
fn checker_canopy_lets_half_the_light_through() {
    let refined = |name: &str| {
        let mut s = Scene::from_mesh_path(&room(name)).expect(name);
        let st = bspvt_bake::refine::refine_scene(&mut s)
            .expect("refine")
            .expect("an asset given alone is refined");
        (s, st)
    };
    let (opaque, _) = refined("canopy.gltf");
    let (cut, st) = refined("checker-canopy.gltf");
    assert!(
        !cut.warnings
            .iter()
            .any(|w| w.contains("surfaces are opaque")),
        "MASK is read, not ignored: {:?}",
        cut.warnings
    );
    assert!(cut.materials.iter().any(|m| m.cutout.is_some()));
    let lights = lights_of;
    let size = (96, 64);
    // Beneath the canopy: where the opaque board's Monte Carlo is below 2 % of the lit level.
    let lum = |p: &[f32; 3]| f64::from(p[0] + p[1] + p[2]) / 3.0;
    let r = Renderer::new(&opaque, size.0, size.1);
    let (unshadowed, _) = r.ltc(&lights(&opaque), Mode::Pixel);
    let occ = Occluder::of_surfaces(&opaque.mesh, &opaque.materials);
    let (mc, _) = render_mc(&opaque, &r.view, &r.gbuffer, &lights(&opaque), &occ, 64, 7);
    let beneath: Vec<usize> = (0..mc.pixels.len())
        .filter(|&i| {
            let u = lum(&unshadowed.pixels[i]);
            u > 0.0 && lum(&mc.pixels[i]) < 0.02 * u
        })
        .collect();
    assert!(
        beneath.len() > 200,
        "beneath the canopy: {} px",
        beneath.len()
    );

    let ((pixel_err, vertex_err, shadows), pixel, mc) = errors_with(&cut, &lights(&cut), size, 64);
    let r = Renderer::new(&cut, size.0, size.1);
    let (lit, _) = r.ltc(&lights(&cut), Mode::Pixel);
    let through = |img: &Image| {
        beneath
            .iter()
            .map(|&i| lum(&img.pixels[i]) / lum(&lit.pixels[i]))
            .sum::<f64>()
            / beneath.len() as f64
    };
    let (b, m) = (through(&pixel), through(&mc));
    println!(
        "checker canopy: {} → {} vertices ({} splits); beneath it {} px get {b:.3} (BSPVT) and \
         {m:.3} (MC) of the lit level; error vs MC {:.2} % per pixel, {:.2} % per vertex \
         (shadows' effect {:.1} %)",
        st.vertices_before,
        st.vertices_after,
        st.splits,
        beneath.len(),
        100.0 * pixel_err,
        100.0 * vertex_err,
        100.0 * shadows
    );
    assert!((0.3..=0.7).contains(&m), "Monte Carlo: {m}");
    assert!((0.3..=0.7).contains(&b), "BSPVT: {b}");
    assert!(pixel_err <= 0.05, "BSPVT per pixel vs MC: {pixel_err}");
}

/// The checker board's underside, which the scene's camera sees from below at the top of the
/// frame: the lamp is above the board, so the underside is black per pixel (as in the Monte
/// Carlo) — and per vertex, where each of the board's vertices is shaded on the side the
/// camera sees, though its normal faces the lamp (before: a lit checker strip, the upper
/// side's radiance interpolated over the underside). Seen from above, the board is lit.
#[test]
fn the_boards_underside_is_dark_per_vertex() {
    let mut s = Scene::from_mesh_path(&room("checker-canopy.gltf")).expect("checker canopy");
    bspvt_bake::refine::refine_scene(&mut s).expect("refine");
    let lights = lights_of(&s);
    let b = baked(&s);
    let trees = Trees::full(&b.trees, b.header.codec());
    let leaves = s
        .materials
        .iter()
        .position(|m| m.name == "leaves")
        .expect("the board's material") as u32;
    let lum = |p: &[f32; 3]| f64::from(p[0] + p[1] + p[2]) / 3.0;
    // The board's mean luminance per vertex and per pixel, BSPVT and unshadowed LTC, through
    // `r`'s camera.
    let board = |r: &Renderer| {
        let px: Vec<usize> = (0..r.gbuffer.tri.len())
            .filter(|&i| s.mesh.material_ids.get(r.gbuffer.tri[i] as usize) == Some(&leaves))
            .collect();
        assert!(px.len() > 30, "the board is seen: {} px", px.len());
        let mean =
            |img: &Image| px.iter().map(|&i| lum(&img.pixels[i])).sum::<f64>() / px.len() as f64;
        let (v, _) = r.bspvt_lights(&lights, Some(&trees), None, Mode::Vertex);
        let (p, _) = r.bspvt_lights(&lights, Some(&trees), None, Mode::Pixel);
        let (lv, _) = r.ltc(&lights, Mode::Vertex);
        let (lp, _) = r.ltc(&lights, Mode::Pixel);
        [mean(&v), mean(&p), mean(&lv), mean(&lp)]
    };
    let below = board(&Renderer::new(&s, 256, 171));
    let above = board(&Renderer::with_camera(
        &s,
        &bspvt_proto::scene::Camera {
            position: [0.4, 2.0, 1.5],
            target: [0.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 40.0,
            aspect: None,
        },
        192,
        128,
    ));
    println!(
        "the board's mean luminance, BSPVT per vertex / per pixel, LTC per vertex / per pixel: \
         from below {below:.5?}, from above {above:.5?}"
    );
    assert!(above.iter().all(|&x| x > 0.01), "lit from above: {above:?}");
    assert!(
        below.iter().all(|&x| x < 1e-3 * above[3]),
        "dark from below: {below:?} (from above {above:?})"
    );
}

/// The camera sees through the checker canopy's holes (the G-buffer's alpha test): looking
/// straight down on the board, about half its pixels show the floor beneath; the opaque board
/// covers them all.
#[test]
fn the_gbuffer_sees_through_the_holes() {
    let camera = bspvt_proto::scene::Camera {
        position: [0.0, 2.0, 0.0],
        target: [0.0, 0.0, 0.0],
        up: [0.0, 0.0, -1.0],
        fov_y_deg: 30.0,
        aspect: None,
    };
    let board_share = |name: &str| {
        let s = Scene::from_mesh_path(&room(name)).expect(name);
        let r = Renderer::with_camera(&s, &camera, 64, 64);
        let board = |t: u32| {
            s.mesh
                .material_ids
                .get(t as usize)
                .and_then(|&m| s.materials.get(m as usize))
                .is_some_and(|m| m.name == "canopy" || m.name == "leaves")
        };
        let n = r.gbuffer.tri.iter().filter(|&&t| board(t)).count();
        n as f64 / r.gbuffer.tri.len() as f64
    };
    let (opaque, cut) = (
        board_share("canopy.gltf"),
        board_share("checker-canopy.gltf"),
    );
    println!("board seen from above: opaque {opaque:.3}, cut out {cut:.3} of the pixels");
    assert!(opaque > 0.99, "the opaque board fills the view: {opaque}");
    assert!((0.4..=0.6).contains(&cut), "half the board is holes: {cut}");
}

/// The normal-mapped floor (`normal-floor.gltf`: one quad whose relief is only in its
/// `normalTexture`, MikkTSpace tangents, a box on it and a lamp off to one side): the map bends
/// the shading normal of BSPVT per pixel and of the Monte Carlo alike — they agree over the
/// image and in the box's shadow —, and the bending is real: the same floor without its map
/// is far from the mapped Monte Carlo.
#[test]
fn normal_mapped_floor_matches_monte_carlo() {
    let mut scene = Scene::from_mesh_path(&room("normal-floor.gltf")).expect("normal floor");
    assert!(
        !scene.warnings.iter().any(|w| w.contains("normal map")),
        "the normal map is read: {:?}",
        scene.warnings
    );
    assert!(scene.materials.iter().any(|m| m.normal_map.is_some()));
    let st = bspvt_bake::refine::refine_scene(&mut scene)
        .expect("refine")
        .expect("an asset given alone is refined");
    let lights = lights_of(&scene);
    let size = (96, 64);
    let ((pixel_err, vertex_err, shadows), pixel, mc) = errors_with(&scene, &lights, size, 64);

    let mut flat = scene.clone();
    for m in &mut flat.materials {
        m.normal_map = None;
    }
    let r = Renderer::new(&flat, size.0, size.1);
    let (flat_ltc, _) = r.ltc(&lights, Mode::Pixel);
    let r = Renderer::new(&scene, size.0, size.1);
    let (mapped_ltc, _) = r.ltc(&lights, Mode::Pixel);
    let mean = mc.mean();
    let bent = mean_abs_diff(&flat_ltc, &mapped_ltc) / mean;
    let flat_err = mean_abs_diff(&flat_ltc, &mc) / mean;
    println!(
        "normal-mapped floor: {} → {} vertices; error vs MC {:.2} % per pixel, {:.2} % per \
         vertex (shadows' effect {:.1} %); the map changes the unshadowed frame by {:.1} %, \
         the flat floor's LTC is {:.1} % from the mapped Monte Carlo",
        st.vertices_before,
        st.vertices_after,
        100.0 * pixel_err,
        100.0 * vertex_err,
        100.0 * shadows,
        100.0 * bent,
        100.0 * flat_err,
    );
    assert!(bent > 0.1, "the normal map bends the shading: {bent}");
    assert!(pixel_err <= 0.05, "BSPVT per pixel vs MC: {pixel_err}");
    assert!(
        flat_err > 2.0 * pixel_err,
        "the MC sees the map too: flat {flat_err} vs mapped {pixel_err}"
    );
    assert!(pixel.pixels.iter().flatten().all(|c| c.is_finite()));
}
