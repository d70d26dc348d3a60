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

/// Keeps the part of `poly` with `n·d ≥ 0` (Sutherland–Hodgman \[Sutherland74\]). Returns an
/// empty polygon when fewer than three vertices remain or no vertex lies strictly on the kept
/// side (what remains then lies in the plane: zero solid angle).
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

/// [`clip`] into a caller's buffer (no 1.5 KB polygon moved around), with a fast path when
/// nothing is cut. Returns false (and leaves `out` empty) when nothing remains.
pub fn clip_into(poly: &[DVec3], n: DVec3, out: &mut SphPoly) -> bool {
    out.clear();
    let len = poly.len();
    if len < 3 {
        return false;
    }
    let (mut pos, mut neg) = (false, false);
    for p in poly {
        let d = n.dot(*p);
        pos |= d > 0.0;
        neg |= d < 0.0;
    }
    if !pos {
        return false;
    }
    if !neg {
        out.extend(poly.iter().copied().take(MAX_VERTS));
        return true;
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
    !out.is_empty()
}

/// Which sides of the plane `n` a polygon has vertices strictly on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sides {
    /// No vertex strictly on either side: the polygon lies in the plane (zero solid angle).
    None,
    /// Only on the negative side (n·d ≤ 0 everywhere).
    Negative,
    /// Only on the positive side (n·d ≥ 0 everywhere).
    Positive,
    /// On both: the plane cuts it.
    Both,
}

/// Classifies `poly` against the plane `n`.
#[inline]
pub fn sides(poly: &[DVec3], n: DVec3) -> Sides {
    let (mut pos, mut neg) = (false, false);
    for p in poly {
        let d = n.dot(*p);
        pos |= d > 0.0;
        neg |= d < 0.0;
    }
    match (neg, pos) {
        (false, false) => Sides::None,
        (true, false) => Sides::Negative,
        (false, true) => Sides::Positive,
        (true, true) => Sides::Both,
    }
}

/// Cuts a polygon that the plane `n` crosses ([`Sides::Both`]) into its parts with n·d ≤ 0
/// (`neg`) and n·d ≥ 0 (`pos`), in one Sutherland–Hodgman pass; the cut points are shared
/// bit for bit by both parts.
pub(crate) fn cut_into(poly: &[DVec3], n: DVec3, neg: &mut SphPoly, pos: &mut SphPoly) {
    neg.clear();
    pos.clear();
    let len = poly.len();
    for i in 0..len {
        let (p, q) = (poly[i], poly[(i + 1) % len]);
        let (dp, dq) = (n.dot(p), n.dot(q));
        if dp <= 0.0 {
            let _ = neg.try_push(p);
        }
        if dp >= 0.0 {
            let _ = pos.try_push(p);
        }
        if (dp < 0.0 && dq > 0.0) || (dp > 0.0 && dq < 0.0) {
            let x = p + (q - p) * (dp / (dp - dq));
            let _ = neg.try_push(x);
            let _ = pos.try_push(x);
        }
    }
    if neg.len() < 3 {
        neg.clear();
    }
    if pos.len() < 3 {
        pos.clear();
    }
}

/// Splits `poly` by the plane `n`: (part with `n·d < 0`, part with `n·d ≥ 0`).
pub fn split(poly: &[DVec3], n: DVec3) -> (SphPoly, SphPoly) {
    (clip(poly, -n), clip(poly, n))
}

/// Solid angle of the spherical triangle (a, b, c) with sign by orientation
/// ([VanOosterom83]: tan(Ω/2) = [a b c] / (|a||b||c| + (a·b)|c| + (a·c)|b| + (b·c)|a|)).
pub(crate) fn triangle_solid_angle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let num = a.dot(b.cross(c));
    let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    2.0 * num.atan2(den)
}

/// Solid angle of a convex spherical polygon (fan of triangles from vertex 0,
/// \[VanOosterom83\]), ≥ 0.
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
