//! BSPVT shading on stiff and extreme inputs (f64 references and exact identities):
//!
//! - the tree walk tiles the light: shading with trees T plus shading with the complementary
//!   trees (v̄ → 1 − v̄) equals unshadowed LTC, for random trees and random lights whose
//!   vertices may sit exactly on cube-face edges and corners;
//! - no NaN or Inf, shadowed ≤ unshadowed, for α from 1e-4 to 1, views to 89.99°, lights from
//!   1e-8 sr to nearly the whole hemisphere, crossing or below the horizon, behind one-sided
//!   lights, degenerate polygons, and scene scales from 1e-4 to 1e4;
//! - the result does not depend on the scene's scale.

mod common;

use bspvt_client::light::Light;
use bspvt_client::ltc::table::LtcTable;
use bspvt_client::shade::bspvt::{VertexLight, shade_vertex};
use bspvt_client::shade::{Lobes, unshadowed};
use bspvt_proto::bspvt::{FaceTree, LineCodec, Node, VertexTrees};
use bspvt_proto::scene::Material;
use common::random_trees;
use glam::DVec3;
use proptest::prelude::*;

fn complement(t: &VertexTrees) -> VertexTrees {
    let mut c = t.clone();
    for f in c.faces.iter_mut() {
        match f {
            Some(tree) => {
                for n in &mut tree.nodes {
                    if let Node::Leaf { value } = n {
                        *value = 255 - *value;
                    }
                }
            }
            // Absent faces are fully visible; their complement is a hidden leaf.
            None => *f = Some(FaceTree::leaf(0)),
        }
    }
    c
}

fn material(alpha: f64) -> Material {
    Material {
        roughness: alpha as f32,
        ..Material::default()
    }
}

/// A quad light of half-size `h` centred at `c`, facing the point at the origin.
fn quad(c: DVec3, h: f64, spin: f64) -> Vec<DVec3> {
    let n = -c.normalize();
    let t = n.any_orthonormal_vector();
    let b = n.cross(t);
    (0..4)
        .map(|i| {
            let a = spin + std::f64::consts::FRAC_PI_2 * i as f64;
            c + h * (a.cos() * t + a.sin() * b)
        })
        .collect()
}

fn light(vertices: Vec<DVec3>, two_sided: bool) -> Light {
    let n = (vertices[1] - vertices[0])
        .cross(vertices[2] - vertices[0])
        .normalize_or(DVec3::Y);
    Light {
        vertices,
        normal: n,
        radiance: DVec3::ONE,
        two_sided,
        texture: None,
        shape: bspvt_client::light::Shape::Polygon,
    }
}

fn shade(alpha: f64, n: DVec3, wo: DVec3, l: &Light, p: DVec3, t: &VertexTrees) -> VertexLight {
    let codec = LineCodec::for_resolution(64);
    let lobes = Lobes::new(LtcTable::builtin(), &material(alpha), n, wo);
    shade_vertex(&lobes, l, p, n, t, &codec)
}

/// Finite and non-negative (any input).
fn finite(v: &VertexLight) -> bool {
    let ok = |x: f64| x.is_finite() && x >= 0.0;
    let (s, u) = (v.shadowed.integrals, v.unshadowed.integrals);
    ok(s.diffuse)
        && ok(s.specular)
        && ok(u.diffuse)
        && ok(u.specular)
        && v.shadowed.diffuse_rgb.is_finite()
        && v.shadowed.specular_rgb.is_finite()
}

/// [`finite`], and shadowed ≤ unshadowed (valid convex lights; integrals lie in [0, 1], and a
/// specular tail of 1e-10 far from the lobe is a sum of cancelling edge terms, hence the
/// absolute 1e-12).
fn finite_nonneg(v: &VertexLight) -> bool {
    let (s, u) = (v.shadowed.integrals, v.unshadowed.integrals);
    finite(v)
        && s.diffuse <= u.diffuse * (1.0 + 1e-9) + 1e-12
        && s.specular <= u.specular * (1.0 + 1e-9) + 1e-12
}

fn view(theta_deg: f64, phi: f64) -> DVec3 {
    let t = theta_deg.to_radians();
    DVec3::new(t.sin() * phi.cos(), t.cos(), t.sin() * phi.sin())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Trees and complementary trees add up to unshadowed LTC: the pieces tile the light.
    #[test]
    fn pieces_tile_the_light(
        seed in any::<u64>(), alpha in 1e-4f64..1.0, theta in 0.0f64..89.99, phi in 0.0f64..std::f64::consts::TAU,
        cx in -3.0f64..3.0, cy in 0.2f64..4.0, cz in -3.0f64..3.0, h in 0.05f64..2.0, spin in 0.0f64..std::f64::consts::TAU,
        corner in any::<bool>(),
    ) {
        let codec = LineCodec::for_resolution(64);
        let t = random_trees(seed, &codec);
        let c = complement(&t);
        let n = DVec3::Y;
        let mut verts = quad(DVec3::new(cx, cy, cz), h, spin);
        if corner {
            // Put vertices exactly on cube-face edges and corners.
            verts[0] = DVec3::new(1.0, 1.0, 1.0) * cy;
            verts[1] = DVec3::new(0.0, 1.0, 1.0) * cy;
            verts[2] = DVec3::new(-1.0, 1.0, 0.0) * cy;
            verts[3] = DVec3::new(0.0, 1.0, -1.0) * cy;
        }
        let l = light(verts, true);
        let wo = view(theta, phi);
        let a = shade(alpha, n, wo, &l, DVec3::ZERO, &t);
        let b = shade(alpha, n, wo, &l, DVec3::ZERO, &c);
        prop_assert!(finite_nonneg(&a) && finite_nonneg(&b));
        let u = a.unshadowed.integrals;
        let (sd, ss) = (
            a.shadowed.integrals.diffuse + b.shadowed.integrals.diffuse,
            a.shadowed.integrals.specular + b.shadowed.integrals.specular,
        );
        prop_assert!((sd - u.diffuse).abs() <= 1e-12 + 1e-9 * u.diffuse, "diffuse {sd} vs {}", u.diffuse);
        prop_assert!((ss - u.specular).abs() <= 1e-12 + 1e-9 * u.specular, "specular {ss} vs {}", u.specular);
    }

    /// Extreme inputs: finite, non-negative, shadowed ≤ unshadowed, scale-invariant.
    #[test]
    fn extreme_inputs(
        seed in any::<u64>(), log_alpha in -4.0f64..0.0, theta in prop_oneof![0.0f64..89.99, Just(89.99)],
        log_sr in -8.0f64..0.3, elev in -0.5f64..1.6, log_scale in -4.0f64..4.0, two_sided in any::<bool>(),
        flip in any::<bool>(),
    ) {
        let codec = LineCodec::for_resolution(64);
        let t = random_trees(seed, &codec);
        let alpha = 10f64.powf(log_alpha);
        let scale = 10f64.powf(log_scale);
        // A light of about `10^log_sr` sr (up to nearly a hemisphere) at elevation `elev`.
        let sr = 10f64.powf(log_sr);
        let dist = 1.0;
        let half = (sr.sqrt() * 0.5).min(50.0);
        let centre = DVec3::new(elev.cos(), elev.sin(), 0.3) * dist;
        let mut verts = quad(centre, half * dist, 0.2);
        if flip {
            verts.reverse(); // one-sided light facing away from the point
        }
        let n = DVec3::Y;
        let wo = view(theta, 1.0);
        let base = shade(alpha, n, wo, &light(verts.clone(), two_sided), DVec3::ZERO, &t);
        prop_assert!(finite_nonneg(&base));
        // Huge and tiny scales: the same numbers.
        let scaled: Vec<DVec3> = verts.iter().map(|v| *v * scale).collect();
        let s = shade(alpha, n, wo, &light(scaled, two_sided), DVec3::ZERO, &t);
        prop_assert!(finite_nonneg(&s), "{:?} {:?}", s.shadowed.integrals, s.unshadowed.integrals);
        let (x, y) = (base.shadowed.integrals, s.shadowed.integrals);
        prop_assert!((x.diffuse - y.diffuse).abs() <= 1e-12 + 1e-9 * x.diffuse, "{x:?} vs {y:?}");
        prop_assert!((x.specular - y.specular).abs() <= 1e-12 + 1e-9 * x.specular, "{x:?} vs {y:?}");
    }

    /// Any vertices at all (duplicates, collinear, NaN, huge): never NaN or Inf.
    #[test]
    fn degenerate_lights(
        v in proptest::collection::vec((-1e3f64..1e3, -1e3f64..1e3, -1e3f64..1e3), 3..9),
        dup in any::<bool>(), nan in any::<bool>(), alpha in 1e-4f64..1.0, theta in 0.0f64..89.99,
    ) {
        let mut verts: Vec<DVec3> = v.iter().map(|&(x, y, z)| DVec3::new(x, y, z)).collect();
        if dup {
            verts[1] = verts[0];
            verts[2] = verts[0] * 0.5 + verts[2] * 0.5;
        }
        if nan {
            verts[0].x = f64::NAN;
        }
        let codec = LineCodec::for_resolution(64);
        let t = random_trees(7, &codec);
        let l = Light { vertices: verts, normal: DVec3::Y, radiance: DVec3::ONE, two_sided: true, texture: None, shape: bspvt_client::light::Shape::Polygon };
        let r = shade(alpha, DVec3::Y, view(theta, 0.5), &l, DVec3::ZERO, &t);
        prop_assert!(finite(&r));
        let lobes = Lobes::new(LtcTable::builtin(), &material(alpha), DVec3::Y, view(theta, 0.5));
        let u = unshadowed(&lobes, &l, DVec3::ZERO, DVec3::Y);
        prop_assert!(u.integrals.diffuse.is_finite() && u.integrals.specular.is_finite());
    }
}

/// All-visible trees (every face absent or a visible leaf) give exactly unshadowed LTC, and
/// a light entirely below the horizon or behind a one-sided light gives exactly zero.
#[test]
fn visible_trees_equal_unshadowed_and_hidden_lights_are_zero() {
    let mut t = VertexTrees::default();
    t.faces[2] = Some(FaceTree::leaf(255));
    let l = light(quad(DVec3::new(0.4, 2.0, -0.3), 0.7, 0.1), false);
    let n = DVec3::Y;
    let r = shade(0.2, n, view(40.0, 0.3), &l, DVec3::ZERO, &t);
    let (s, u) = (r.shadowed.integrals, r.unshadowed.integrals);
    assert!(u.diffuse > 0.01 && u.specular > 0.0);
    assert!((s.diffuse - u.diffuse).abs() < 1e-12 * u.diffuse.max(1.0));
    assert!((s.specular - u.specular).abs() < 1e-12 * u.specular.max(1.0));

    let below = light(quad(DVec3::new(0.4, -2.0, -0.3), 0.7, 0.1), true);
    let r = shade(0.2, n, view(40.0, 0.3), &below, DVec3::ZERO, &t);
    assert_eq!(r.unshadowed.integrals.diffuse, 0.0);
    let mut back = quad(DVec3::new(0.4, 2.0, -0.3), 0.7, 0.1);
    back.reverse();
    let r = shade(
        0.2,
        n,
        view(40.0, 0.3),
        &light(back, false),
        DVec3::ZERO,
        &t,
    );
    assert_eq!(r.unshadowed.integrals.diffuse, 0.0);
}

/// The random trees really cut the light (the tiling property above is not vacuous).
#[test]
fn random_trees_cut_the_light_into_many_pieces() {
    let codec = LineCodec::for_resolution(64);
    let l = light(quad(DVec3::new(0.3, 1.0, 0.2), 0.8, 0.3), true);
    let (mut pieces, mut dropped, mut partial) = (0, 0, 0);
    for seed in 0..200 {
        let t = random_trees(seed, &codec);
        let r = shade(0.3, DVec3::Y, view(30.0, 0.0), &l, DVec3::ZERO, &t);
        pieces += r.pieces;
        dropped += r.dropped;
        let (s, u) = (r.shadowed.integrals.diffuse, r.unshadowed.integrals.diffuse);
        if s > 0.01 * u && s < 0.99 * u {
            partial += 1;
        }
    }
    assert!(pieces > 200 * 3, "{pieces} pieces");
    assert!(dropped > 200, "{dropped} dropped");
    assert!(partial > 100, "{partial} of 200 partially shadowed");
}
