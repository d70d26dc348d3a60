//! Visibility of a lighting lobe at a shading point as a spherical signed distance: the
//! nearest occlusion boundary direction t to the lobe's axis ξ, turned into a half-space
//! (great circle through t, perpendicular to the arc ξ→t) that [`super::halfspace`]
//! integrates (Wang et al. 2009, §5; paper 001, eq. 3–4).
//!
//! Two searches find t:
//!
//! - [`exact_boundary`]: with the ray-tracing BVH. One ray along ξ gives the axis's state;
//!   rings of directions around ξ at growing angular radii (0.0123 rad doubling to 0.39, then
//!   steps of ≈ 0.2 to 1.52; 12 azimuths each) find the first direction of the opposite
//!   state; 5 bisection steps along that azimuth place the boundary.
//! - [`ScreenMaps`] (the paper's run-time SSDF): for every lighting lobe, an orthographic depth
//!   map looking along −ξ (world positions recoverable from depth), with a pyramid keeping the
//!   MIN (and, ours, the MAX) of each 2×2 block and the world position of the minimum. Per
//!   pixel: a shadow-map test along ξ gives the axis's state; then the coarse-to-fine search of
//!   the paper — every texel of the coarsest level, then the 6×6 neighbourhood of the candidate
//!   at each finer level — for the boundary texel whose direction from the point is closest to
//!   ξ. A block is a boundary candidate when it holds both texels in front of the point
//!   (depth < the point's − bias) and texels not in front (min/max straddle); at the finest
//!   level, a front texel with a non-front 4-neighbour. The paper keeps MIN only and leaves the
//!   occluded case's search vague; the straddle test handles both cases with one rule.
//!
//! Directions below the point's geometric tangent plane are ignored by both searches: the
//! horizon is applied analytically by the renderer (signed distance asin(p·n)), and the
//! point's own surface must not count as an occluder.

use bspvt_proto::Mesh;
use bspvt_raytrace::Occluder;
use glam::Vec3;

/// A lobe's visibility at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Boundary {
    /// No occluder boundary within π/2 of the axis; the axis is unoccluded.
    Visible,
    /// No boundary within π/2; the axis is occluded.
    Occluded,
    /// Kept side {v : v·m ≥ 0} of a great circle; `m` is its unit normal.
    Plane(Vec3),
}

impl Boundary {
    /// The half-space through boundary direction `t` for an axis `xi` whose state is
    /// `occluded`: m ∝ ξ − (ξ·t)t, flipped when ξ is occluded so that ξ·m = ±sin δ.
    pub(crate) fn from_direction(xi: Vec3, t: Vec3, occluded: bool) -> Boundary {
        let m = xi - t * xi.dot(t);
        let len = m.length();
        // δ beyond π/2 (t behind ξ) or degenerate: no usable boundary.
        if !(len > 1e-7) || xi.dot(t) < 0.0 || !m.is_finite() {
            return if occluded {
                Boundary::Occluded
            } else {
                Boundary::Visible
            };
        }
        let m = m / len;
        Boundary::Plane(if occluded { -m } else { m })
    }

    /// Signed angular distance of a lobe axis `p` from the boundary: +∞ when visible, −∞ when
    /// occluded, asin(p·m) for a plane.
    #[inline]
    pub(crate) fn distance(&self, p: Vec3) -> f32 {
        match self {
            Boundary::Visible => f32::INFINITY,
            Boundary::Occluded => f32::NEG_INFINITY,
            Boundary::Plane(m) => p.dot(*m).clamp(-1.0, 1.0).asin(),
        }
    }
}

/// A shading point as the searches see it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Point {
    pub(crate) position: Vec3,
    /// Unit geometric normal (viewer's side).
    pub(crate) geometric: Vec3,
}

/// Ring radii of the exact search (radians): doubling up to 0.39, then steps of ≈ 0.2 to the
/// horizon.
const RINGS: [f32; 12] = [
    0.0123, 0.0245, 0.049, 0.098, 0.196, 0.39, 0.59, 0.785, 0.98, 1.18, 1.37, 1.52,
];
const AZIMUTHS: usize = 12;
const BISECTIONS: usize = 5;

/// Ray-traced visibility of direction `w` from `p` (origin offset by `eps` along the normal).
#[inline]
fn ray_occluded(occ: &Occluder, p: &Point, w: Vec3, eps: f32) -> bool {
    occ.occluded_segment(p.position + p.geometric * eps, w, f32::INFINITY)
}

/// The nearest boundary to `xi` by ray casting (see the module docs). `eps`: ray offset.
pub(crate) fn exact_boundary(occ: &Occluder, p: &Point, xi: Vec3, eps: f32) -> Boundary {
    if !(xi.dot(p.geometric) > 0.0) {
        return Boundary::Visible;
    }
    let s0 = ray_occluded(occ, p, xi, eps);
    let (t1, t2) = xi.any_orthonormal_pair();
    let dir = |delta: f32, phi: f32| {
        let (sd, cd) = delta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        (xi * cd + (t1 * cp + t2 * sp) * sd).normalize()
    };
    let mut inner = 0.0f32;
    for (j, &delta) in RINGS.iter().enumerate() {
        let twist = if j % 2 == 0 { 0.5 } else { 0.0 };
        for a in 0..AZIMUTHS {
            let phi = std::f32::consts::TAU * (a as f32 + twist) / AZIMUTHS as f32;
            let w = dir(delta, phi);
            if !(w.dot(p.geometric) > 0.0) {
                continue;
            }
            if ray_occluded(occ, p, w, eps) != s0 {
                // Bisection between the inner ring and this one along φ.
                let (mut lo, mut hi) = (inner, delta);
                for _ in 0..BISECTIONS {
                    let mid = 0.5 * (lo + hi);
                    let wm = dir(mid, phi);
                    if wm.dot(p.geometric) > 0.0 && ray_occluded(occ, p, wm, eps) != s0 {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                return Boundary::from_direction(xi, dir(0.5 * (lo + hi), phi), s0);
            }
        }
        inner = delta;
    }
    if s0 {
        Boundary::Occluded
    } else {
        Boundary::Visible
    }
}

/// max(⌈v⌉, 0) without `ceil` (a libm call on baseline x86-64); 0 for NaN.
#[inline]
fn ceil_nonneg(v: f32) -> f32 {
    if !(v > 0.0) {
        return 0.0;
    }
    // `as` truncates (saturating): floor for v ≥ 0; beyond 2^23 every f32 is an integer.
    let t = v as u32 as f32;
    if t < v { t + 1.0 } else { t }
}

/// min(⌊v⌋, `hi`) for the last texel of a span: −1 (an empty span) for v < 0 or NaN.
#[inline]
fn floor_upto(v: f32, hi: f32) -> f32 {
    if !(v >= 0.0) {
        return -1.0;
    }
    (v as u32 as f32).min(hi)
}

/// One level of a depth-map pyramid.
#[derive(Clone, Debug)]
struct Level {
    res: usize,
    /// Smallest and largest depth of the block (+∞: empty).
    min: Vec<f32>,
    max: Vec<f32>,
    /// World position of the block's minimum-depth texel.
    arg: Vec<Vec3>,
}

/// An orthographic depth map looking along −ξ, with its MIN/MAX pyramid.
#[derive(Clone, Debug)]
pub(crate) struct DepthMap {
    pub(crate) xi: Vec3,
    centre: Vec3,
    right: Vec3,
    up: Vec3,
    /// Half the side of the square the map covers (world units).
    half: f32,
    levels: Vec<Level>,
}

/// Side of the coarsest pyramid level.
const TOP: usize = 8;
/// Neighbourhood searched at each finer level by default (the paper's 6×6).
pub(crate) const DEFAULT_WINDOW: u32 = 6;

impl DepthMap {
    /// Renders `mesh` (bounding sphere `centre`, `radius`) along −`xi` at `res`² (a power of
    /// two ≥ 8 is used: `res` rounded up).
    pub(crate) fn render(mesh: &Mesh, centre: Vec3, radius: f32, xi: Vec3, res: usize) -> DepthMap {
        let res = res.clamp(TOP, 4096).next_power_of_two();
        let (right, up) = xi.any_orthonormal_pair();
        let half = radius.max(1e-6) * 1.001;
        let scale = res as f32 / (2.0 * half);
        let n = res * res;
        let mut depth = vec![f32::INFINITY; n];
        // Texel coordinates and depth (along −ξ: larger is farther from the light).
        let proj = |p: Vec3| {
            let d = p - centre;
            (
                (d.dot(right) + half) * scale,
                (d.dot(up) + half) * scale,
                -d.dot(xi),
            )
        };
        // Every vertex once (a vertex is shared by ≈ 6 triangles).
        let projected: Vec<(f32, f32, f32)> = mesh.positions.iter().map(|&p| proj(p)).collect();
        for tri in &mesh.triangles {
            let v = tri.map(|i| projected[i as usize]);
            let area =
                (v[1].0 - v[0].0) * (v[2].1 - v[0].1) - (v[2].0 - v[0].0) * (v[1].1 - v[0].1);
            if !(area.abs() > 1e-12) {
                continue;
            }
            let inv = 1.0 / area;
            let xs = [v[0].0, v[1].0, v[2].0];
            let ys = [v[0].1, v[1].1, v[2].1];
            // Texel centres x + ½ inside the bounding box, clipped to the map.
            let max_t = res as f32 - 1.0;
            let x0 = ceil_nonneg(xs.iter().copied().fold(f32::INFINITY, f32::min) - 0.5);
            let x1 = floor_upto(
                xs.iter().copied().fold(f32::NEG_INFINITY, f32::max) - 0.5,
                max_t,
            );
            let y0 = ceil_nonneg(ys.iter().copied().fold(f32::INFINITY, f32::min) - 0.5);
            let y1 = floor_upto(
                ys.iter().copied().fold(f32::NEG_INFINITY, f32::max) - 0.5,
                max_t,
            );
            if !(x0 <= x1 && y0 <= y1) {
                continue;
            }
            for y in y0 as usize..=y1 as usize {
                let py = y as f32 + 0.5;
                for x in x0 as usize..=x1 as usize {
                    let px = x as f32 + 0.5;
                    let w0 = ((v[1].0 - px) * (v[2].1 - py) - (v[2].0 - px) * (v[1].1 - py)) * inv;
                    let w1 = ((v[2].0 - px) * (v[0].1 - py) - (v[0].0 - px) * (v[2].1 - py)) * inv;
                    let w2 = 1.0 - w0 - w1;
                    if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                        continue;
                    }
                    let z = w0 * v[0].2 + w1 * v[1].2 + w2 * v[2].2;
                    let k = y * res + x;
                    if z < depth[k] {
                        depth[k] = z;
                    }
                }
            }
        }
        let world = |x: usize, y: usize, z: f32| {
            centre
                + right * ((x as f32 + 0.5) / scale - half)
                + up * ((y as f32 + 0.5) / scale - half)
                - xi * z
        };
        let arg0 = (0..n)
            .map(|k| {
                let z = depth[k];
                if z.is_finite() {
                    world(k % res, k / res, z)
                } else {
                    Vec3::ZERO
                }
            })
            .collect();
        let mut levels = vec![Level {
            res,
            min: depth.clone(),
            max: depth,
            arg: arg0,
        }];
        while levels.last().is_some_and(|l| l.res > TOP) {
            let prev = levels.last().expect("non-empty");
            let r = prev.res / 2;
            let mut l = Level {
                res: r,
                min: vec![f32::INFINITY; r * r],
                max: vec![f32::NEG_INFINITY; r * r],
                arg: vec![Vec3::ZERO; r * r],
            };
            for y in 0..r {
                for x in 0..r {
                    let k = y * r + x;
                    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let c = (2 * y + dy) * prev.res + 2 * x + dx;
                        if prev.min[c] < l.min[k] {
                            l.min[k] = prev.min[c];
                            l.arg[k] = prev.arg[c];
                        }
                        l.max[k] = l.max[k].max(prev.max[c]);
                    }
                }
            }
            levels.push(l);
        }
        DepthMap {
            xi,
            centre,
            right,
            up,
            half,
            levels,
        }
    }

    /// Side of the finest level.
    pub(crate) fn res(&self) -> usize {
        self.levels[0].res
    }

    /// Texel coordinates (finest level, fractional) and depth of a world point.
    #[inline]
    fn project(&self, p: Vec3) -> (f32, f32, f32) {
        let d = p - self.centre;
        let scale = self.res() as f32 / (2.0 * self.half);
        (
            (d.dot(self.right) + self.half) * scale,
            (d.dot(self.up) + self.half) * scale,
            -d.dot(self.xi),
        )
    }

    /// The nearest boundary to ξ seen from `p` (see the module docs). `bias_abs`: depth bias
    /// in world units added to the slope-scaled texel bias; `window`: side of the
    /// neighbourhood searched at each finer level (clamped to 2..=16; the paper's is 6).
    pub(crate) fn boundary(&self, p: &Point, bias_abs: f32, window: u32) -> Boundary {
        let neigh = window.clamp(2, 16) as isize;
        let xi = self.xi;
        let cos_l = xi.dot(p.geometric);
        if !(cos_l > 0.0) || !p.position.is_finite() {
            return Boundary::Visible;
        }
        let l0 = &self.levels[0];
        let res = l0.res;
        let texel = 2.0 * self.half / res as f32;
        // Slope-scaled bias: the surface's depth changes by tan θ per unit of map distance.
        let tan = ((1.0 - cos_l * cos_l).max(0.0).sqrt() / cos_l).min(8.0);
        let bias = texel * (1.0 + 1.5 * tan) + bias_abs;
        let (fx, fy, z) = self.project(p.position);
        let zf = z - bias;
        let front = |d: f32| d < zf;
        let inside =
            |x: isize, y: isize, r: usize| x >= 0 && y >= 0 && (x as usize) < r && (y as usize) < r;
        // The point's texel (no `floor`: it is a libm call on baseline x86-64; `as` truncates,
        // which equals floor for the non-negative coordinates of texels inside the map).
        let s0 = fx >= 0.0
            && fy >= 0.0
            && (fx as usize) < res
            && (fy as usize) < res
            && front(l0.min[fy as usize * res + fx as usize]);
        // Score of a candidate world position: cos of its direction to ξ (above the tangent
        // plane only).
        let score = |w: Vec3| -> f32 {
            let v = w - p.position;
            let h = v.dot(p.geometric);
            if !(h > bias) {
                return f32::NEG_INFINITY;
            }
            v.dot(xi) / v.length()
        };
        let top = self.levels.len() - 1;
        let mut best: Option<(usize, usize, Vec3)> = None;
        let mut best_s = f32::NEG_INFINITY;
        {
            let l = &self.levels[top];
            for y in 0..l.res {
                for x in 0..l.res {
                    let k = y * l.res + x;
                    if front(l.min[k]) && !front(l.max[k]) {
                        let s = score(l.arg[k]);
                        if s > best_s {
                            best_s = s;
                            best = Some((x, y, l.arg[k]));
                        }
                    }
                }
            }
        }
        let Some(mut cand) = best else {
            return if s0 {
                Boundary::Occluded
            } else {
                Boundary::Visible
            };
        };
        for lv in (0..top).rev() {
            let l = &self.levels[lv];
            let r = l.res;
            let (cx, cy) = (2 * cand.0 as isize, 2 * cand.1 as isize);
            let mut next: Option<(usize, usize, Vec3)> = None;
            let mut next_s = f32::NEG_INFINITY;
            for y in cy - (neigh / 2 - 1)..cy - (neigh / 2 - 1) + neigh {
                for x in cx - (neigh / 2 - 1)..cx - (neigh / 2 - 1) + neigh {
                    if !inside(x, y, r) {
                        continue;
                    }
                    let k = y as usize * r + x as usize;
                    let is_cand = if lv > 0 {
                        front(l.min[k]) && !front(l.max[k])
                    } else {
                        front(l.min[k])
                            && [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|&(dx, dy)| {
                                let (nx, ny) = (x + dx, y + dy);
                                !inside(nx, ny, r) || !front(l.min[ny as usize * r + nx as usize])
                            })
                    };
                    if is_cand {
                        let s = score(l.arg[k]);
                        if s > next_s {
                            next_s = s;
                            next = Some((x as usize, y as usize, l.arg[k]));
                        }
                    }
                }
            }
            match next {
                Some(c) if next_s > f32::NEG_INFINITY => cand = c,
                // Nothing finer around the candidate: keep the coarser estimate.
                _ => break,
            }
        }
        let t = (cand.2 - p.position).normalize_or_zero();
        if t == Vec3::ZERO || best_s == f32::NEG_INFINITY {
            return if s0 {
                Boundary::Occluded
            } else {
                Boundary::Visible
            };
        }
        Boundary::from_direction(xi, t, s0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bspvt_proto::Mesh;

    /// A unit square occluder at height 1 over the origin (x, z ∈ [−0.5, 0.5]) and a large
    /// ground quad at y = 0.
    fn scene() -> Mesh {
        let positions = vec![
            [-0.5, 1.0, -0.5],
            [0.5, 1.0, -0.5],
            [0.5, 1.0, 0.5],
            [-0.5, 1.0, 0.5],
            [-4.0, 0.0, -4.0],
            [4.0, 0.0, -4.0],
            [4.0, 0.0, 4.0],
            [-4.0, 0.0, 4.0],
        ]
        .into_iter()
        .map(glam::Vec3::from)
        .collect();
        let mut m = Mesh {
            positions,
            normals: Vec::new(),
            triangles: vec![[0, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6]],
            material_ids: vec![0; 4],
            uvs: Vec::new(),
        };
        m.compute_normals();
        m
    }

    /// Under a square at height 1, at (0.1, 0, 0.05), the true SSDF of the up axis is
    /// −atan(0.4) (occluded; the nearest free direction passes the edge x = 0.5); both
    /// searches find it.
    #[test]
    fn both_searches_find_the_square_edge() {
        let mesh = scene();
        let tris = bspvt_raytrace::mesh_triangles(&mesh);
        let occ = Occluder::new(&mesh, &tris);
        let p = Point {
            position: Vec3::new(0.1, 0.0, 0.05),
            geometric: Vec3::Y,
        };
        let want = -(0.4f32).atan();
        let b = exact_boundary(&occ, &p, Vec3::Y, 1e-4);
        let d = b.distance(Vec3::Y);
        assert!((d - want).abs() < 0.03, "exact {b:?}: {d} vs {want}");
        let map = DepthMap::render(&mesh, Vec3::ZERO, 6.0, Vec3::Y, 256);
        let b = map.boundary(&p, 1e-3, DEFAULT_WINDOW);
        let d = b.distance(Vec3::Y);
        assert!((d - want).abs() < 0.06, "screen {b:?}: {d} vs {want}");
        // Beside the square (x = 1.6): unoccluded, nearest occluded direction towards the
        // square's near edge at x = 0.5: angle atan(1.1 / 1) from the vertical.
        let q = Point {
            position: Vec3::new(1.6, 0.0, 0.0),
            geometric: Vec3::Y,
        };
        let want = 1.1f32.atan();
        let b = exact_boundary(&occ, &q, Vec3::Y, 1e-4);
        assert!((b.distance(Vec3::Y) - want).abs() < 0.03, "exact {b:?}");
        let b = map.boundary(&q, 1e-3, DEFAULT_WINDOW);
        assert!((b.distance(Vec3::Y) - want).abs() < 0.06, "screen {b:?}");
        // Far away: nothing within reach → the searches see no boundary or a far one.
        let r = Point {
            position: Vec3::new(3.9, 0.0, 3.9),
            geometric: Vec3::Y,
        };
        let b = exact_boundary(&occ, &r, Vec3::Y, 1e-4);
        assert!(b.distance(Vec3::Y) > 1.0, "{b:?}");
    }

    #[test]
    fn plane_from_direction_is_signed() {
        let xi = Vec3::Y;
        let t = Vec3::new(0.3f32.sin(), 0.3f32.cos(), 0.0);
        let b = Boundary::from_direction(xi, t, false);
        assert!((b.distance(xi) - 0.3).abs() < 1e-5);
        let b = Boundary::from_direction(xi, t, true);
        assert!((b.distance(xi) + 0.3).abs() < 1e-5);
        assert_eq!(Boundary::from_direction(xi, xi, true), Boundary::Occluded);
        assert_eq!(Boundary::from_direction(xi, -xi, false), Boundary::Visible);
    }
}
