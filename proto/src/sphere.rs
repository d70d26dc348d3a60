//! Spherical polygons as cones of directions.
//!
//! A convex spherical polygon is stored as its (unnormalised) vertex directions; an edge is the
//! minor great-circle arc between two vertices. Clipping by a plane through the origin is then
//! plain Sutherland–Hodgman on the 3-D vectors: the linear interpolation of two directions
//! spans the same arc, so every cut is exact (up to rounding), with no trigonometry.

use arrayvec::ArrayVec;
use glam::DVec3;

/// Capacity of a clipped polygon: a light's 8 vertices, the horizon, four face planes and one
/// cut per tree level (depth ≤ [`crate::bspvt::MAX_DEPTH`]) each add at most one vertex.
pub const MAX_VERTS: usize = 64;

/// A convex spherical polygon (directions, not necessarily unit).
pub type SphPoly = ArrayVec<DVec3, MAX_VERTS>;

/// Keeps the part of `poly` with `n·d ≥ 0` (Sutherland–Hodgman). Returns an empty polygon
/// when fewer than three vertices remain or no vertex lies strictly on the kept side (what
/// remains then lies in the plane: zero solid angle).
pub fn clip(poly: &[DVec3], n: DVec3) -> SphPoly {
    let mut out = SphPoly::new();
    let len = poly.len();
    if len < 3 || !poly.iter().any(|p| n.dot(*p) > 0.0) {
        return out;
    }
    for i in 0..len {
        let (p, q) = (poly[i], poly[(i + 1) % len]);
        let (dp, dq) = (n.dot(p), n.dot(q));
        if dp >= 0.0 {
            let _ = out.try_push(p);
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            let t = dp / (dp - dq);
            let _ = out.try_push(p + (q - p) * t);
        }
    }
    if out.len() < 3 {
        out.clear();
    }
    out
}

/// Splits `poly` by the plane `n`: (part with `n·d < 0`, part with `n·d ≥ 0`).
pub fn split(poly: &[DVec3], n: DVec3) -> (SphPoly, SphPoly) {
    (clip(poly, -n), clip(poly, n))
}

/// Solid angle of the spherical triangle (a, b, c) with sign by orientation
/// (Van Oosterom & Strackee 1983: tan(Ω/2) = [a b c] / (|a||b||c| + (a·b)|c| + (a·c)|b| + (b·c)|a|)).
pub fn triangle_solid_angle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let num = a.dot(b.cross(c));
    let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    2.0 * num.atan2(den)
}

/// Solid angle of a convex spherical polygon (fan from vertex 0), ≥ 0.
pub fn solid_angle(poly: &[DVec3]) -> f64 {
    if poly.len() < 3 {
        return 0.0;
    }
    let mut s = 0.0;
    for i in 1..poly.len() - 1 {
        s += triangle_solid_angle(poly[0], poly[i], poly[i + 1]);
    }
    s.abs()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn octant_is_an_eighth_of_the_sphere() {
        let o = solid_angle(&[DVec3::X, DVec3::Y, DVec3::Z]);
        assert!((o - PI / 2.0).abs() < 1e-12);
    }

    #[test]
    fn splitting_preserves_solid_angle() {
        let quad = [
            DVec3::new(-0.5, 1.0, -0.4),
            DVec3::new(0.6, 1.0, -0.5),
            DVec3::new(0.5, 1.0, 0.7),
            DVec3::new(-0.4, 1.0, 0.5),
        ];
        let whole = solid_angle(&quad);
        let n = DVec3::new(0.3, -0.1, 1.0);
        let (l, r) = split(&quad, n);
        assert!(((solid_angle(&l) + solid_angle(&r)) - whole).abs() < 1e-12 * whole);
        assert!(r.iter().all(|d| n.dot(*d) >= -1e-15));
    }
}
