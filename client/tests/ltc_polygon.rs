//! Polygon integration (the cosine/LTC edge integral) against an independent f64 reference:
//! Gauss–Legendre quadrature of the point-to-area form-factor kernel over the planar light,
//! and exact identities (additivity, scale invariance, degenerate input).

use std::f64::consts::PI;

use bspvt_client::ltc::polygon::{edge_sum, form_factor};
use glam::DVec3;
use proptest::prelude::*;

/// Gauss–Legendre nodes and weights on [0, 1] (Golub–Welsch would be overkill: Newton on P_n).
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 0.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-16 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push((0.5 * (x + 1.0), 0.5 * w));
    }
    out
}

/// ∫ over the planar triangle (a, b, c) of max(x_z, 0)·|n·x| / (π |x|⁴) dA (the form-factor
/// kernel seen from the origin with normal z), by a collapsed-square Gauss rule, subdivided
/// `levels` times.
fn triangle_reference(a: DVec3, b: DVec3, c: DVec3, gl: &[(f64, f64)], levels: u32) -> f64 {
    if levels > 0 {
        let (ab, bc, ca) = ((a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5);
        return [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
            .iter()
            .map(|&(p, q, r)| triangle_reference(p, q, r, gl, levels - 1))
            .sum();
    }
    let cr = (b - a).cross(c - a);
    let area2 = cr.length();
    let n = cr / area2;
    let mut s = 0.0;
    for &(u, wu) in gl {
        for &(v, wv) in gl {
            // Duffy: (u, v) ∈ [0,1]² → barycentric (1 − u, u(1 − v), uv), Jacobian u.
            let x = a + u * (1.0 - v) * (b - a) + u * v * (c - a);
            let r2 = x.length_squared();
            let f = x.z.max(0.0) * n.dot(x).abs() / (PI * r2 * r2);
            s += wu * wv * u * f;
        }
    }
    s * area2
}

/// Reference form factor of a planar convex polygon (world points = directions from the
/// origin), clipped to z ≥ 0 as a planar polygon first so the integrand is smooth.
fn reference(poly: &[DVec3], levels: u32) -> f64 {
    let gl = gauss_legendre(16);
    let clipped = bspvt_proto::sphere::clip(poly, DVec3::Z);
    if clipped.len() < 3 {
        return 0.0;
    }
    (1..clipped.len() - 1)
        .map(|i| triangle_reference(clipped[0], clipped[i], clipped[i + 1], &gl, levels))
        .sum()
}

/// The textbook edge formula with acos and normalised vertices (what not to do).
fn naive(poly: &[DVec3]) -> f64 {
    let n = poly.len();
    let mut s = 0.0;
    for i in 0..n {
        let (p, q) = (poly[i].normalize(), poly[(i + 1) % n].normalize());
        let th = p.dot(q).clamp(-1.0, 1.0).acos();
        s += th * p.cross(q).normalize().z;
    }
    s.abs() / (2.0 * PI)
}

/// A planar convex k-gon of "radius" `size` centred at `centre`, facing the origin, rotated by
/// `spin`.
fn polygon(centre: DVec3, size: f64, k: usize, spin: f64, squash: f64) -> Vec<DVec3> {
    let n = -centre.normalize();
    let t = n.any_orthonormal_vector();
    let b = n.cross(t);
    (0..k)
        .map(|i| {
            let a = spin + 2.0 * PI * i as f64 / k as f64;
            centre + size * (a.cos() * t + squash * a.sin() * b)
        })
        .collect()
}

fn direction(theta: f64, phi: f64) -> DVec3 {
    DVec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// Moderate lights anywhere above (or across) the horizon, 3–8 vertices.
    #[test]
    fn matches_quadrature(
        theta in 0.0f64..1.55, phi in 0.0f64..std::f64::consts::TAU, dist in 0.5f64..20.0,
        rel in 0.01f64..0.8, k in 3usize..=8, spin in 0.0f64..std::f64::consts::TAU, squash in 0.2f64..1.0,
    ) {
        let p = polygon(dist * direction(theta, phi), rel * dist, k, spin, squash);
        let r = reference(&p, 3);
        let e = form_factor(&p);
        prop_assert!(e.is_finite() && e >= 0.0);
        prop_assert!((e - r).abs() <= 1e-9 + 1e-7 * r, "E {e} vs reference {r}");
    }

    /// Splitting a polygon by any plane through the origin preserves the integral.
    #[test]
    fn additive_under_splits(
        theta in 0.0f64..1.5, phi in 0.0f64..std::f64::consts::TAU, rel in 0.01f64..2.0,
        k in 3usize..=8, nx in -1.0f64..1.0, ny in -1.0f64..1.0, nz in -1.0f64..1.0,
    ) {
        let p = polygon(direction(theta, phi), rel, k, 0.3, 0.7);
        let n = DVec3::new(nx, ny, nz);
        prop_assume!(n.length() > 1e-3);
        let (a, b) = bspvt_proto::sphere::split(&p, n);
        let whole = form_factor(&p);
        let parts = form_factor(&a) + form_factor(&b);
        prop_assert!((whole - parts).abs() <= 1e-13 + 1e-12 * whole, "{whole} vs {parts}");
    }

    /// Scaling every direction by the same factor (huge and tiny scenes) changes nothing.
    #[test]
    fn scale_invariant(theta in 0.0f64..1.5, phi in 0.0f64..std::f64::consts::TAU, rel in 1e-6f64..1.0,
                       exp in prop_oneof![-300i32..300, Just(307), Just(-307)]) {
        let p = polygon(direction(theta, phi), rel, 4, 0.1, 1.0);
        let s = 10f64.powi(exp);
        let scaled: Vec<DVec3> = p.iter().map(|v| *v * s).collect();
        let (a, b) = (form_factor(&p), form_factor(&scaled));
        prop_assert!(b.is_finite());
        prop_assert!((a - b).abs() <= 1e-14 + 1e-12 * a, "{a} vs {b} at 1e{exp}");
    }

    /// Any finite or non-finite garbage gives a finite value in [0, 1].
    #[test]
    fn never_nan(v in proptest::collection::vec(
        (proptest::num::f64::ANY, proptest::num::f64::ANY, proptest::num::f64::ANY), 0..10)) {
        let p: Vec<DVec3> = v.iter().map(|&(x, y, z)| DVec3::new(x, y, z)).collect();
        let e = form_factor(&p);
        prop_assert!(e.is_finite() && (0.0..=1.0).contains(&e), "{e}");
    }
}

/// Tiny lights (down to 1e-8 sr) and slivers (nearly parallel edges): relative error against
/// the quadrature reference, and the acos formula's for comparison. Prints the table.
#[test]
fn tiny_lights_and_slivers_keep_their_digits() {
    let mut worst_stable: f64 = 0.0;
    let mut worst_naive: f64 = 0.0;
    println!("solid angle   stable rel.err   acos rel.err");
    for &sr in &[1e-2f64, 1e-4, 1e-6, 1e-8, 1e-10] {
        let mut ws: f64 = 0.0;
        let mut wn: f64 = 0.0;
        for i in 0..40 {
            let theta = 1.5 * (i as f64 + 0.5) / 40.0;
            let dist = 3.0;
            // A square of solid angle ≈ sr at distance `dist`.
            let size = dist * sr.sqrt() / 2f64.sqrt();
            let p = polygon(dist * direction(theta, 0.7 * i as f64), size, 4, 0.4, 1.0);
            let r = reference(&p, 0);
            let e = form_factor(&p);
            ws = ws.max((e - r).abs() / r);
            wn = wn.max((naive(&p) - r).abs() / r);
        }
        println!("{sr:>10.0e}   {ws:>14.2e}   {wn:>12.2e}");
        worst_stable = worst_stable.max(ws);
        worst_naive = worst_naive.max(wn);
    }
    // Slivers: a long thin triangle (two nearly parallel long edges).
    for &w in &[1e-3, 1e-6, 1e-9] {
        let c = DVec3::new(0.3, 0.2, 2.0);
        let t = DVec3::new(1.0, 0.0, 0.0);
        let b = DVec3::new(0.0, 1.0, 0.0);
        let p = vec![c - t, c + t + w * b, c + t - w * b];
        let r = reference(&p, 2);
        let e = form_factor(&p);
        let es = (e - r).abs() / r;
        println!(
            "sliver w={w:e}: stable {es:.2e}, acos {:.2e}",
            (naive(&p) - r).abs() / r
        );
        worst_stable = worst_stable.max(es);
    }
    println!("worst relative error: stable {worst_stable:.2e}, acos {worst_naive:.2e}");
    assert!(
        worst_stable < 1e-6,
        "stable formula lost digits: {worst_stable:e}"
    );
    // The comparison must show why the stable form exists.
    assert!(
        worst_naive > 1e-3,
        "acos formula unexpectedly accurate: {worst_naive:e}"
    );
}

#[test]
fn degenerate_polygons() {
    let a = DVec3::new(0.1, 0.2, 1.0);
    let b = DVec3::new(0.4, 0.1, 1.0);
    let c = DVec3::new(0.2, 0.5, 1.0);
    let tri = form_factor(&[a, b, c]);
    // Duplicate vertices change nothing.
    assert!((form_factor(&[a, a, b, b, c]) - tri).abs() < 1e-15);
    // Collinear and zero-area polygons integrate to zero.
    assert!(form_factor(&[a, (a + b) * 0.5, b]) < 1e-15);
    assert_eq!(form_factor(&[a, a, a]), 0.0);
    assert_eq!(form_factor(&[a, b]), 0.0);
    // Entirely below the horizon, and touching it from below.
    assert_eq!(form_factor(&[-a, -b, -c]), 0.0);
    let flat = [DVec3::X, DVec3::Y, DVec3::new(-1.0, -1.0, 0.0)];
    assert_eq!(form_factor(&flat), 0.0);
    // Edge sum of an empty polygon.
    assert_eq!(edge_sum(&[]), 0.0);
}
