//! Primary visibility by rasterisation: the triangle seen through every pixel centre, with
//! the exact hit point of the primary ray (barycentrics by ray–triangle intersection, so
//! positions are not affected by the rasteriser's interpolation).
//!
//! Triangles are clipped against the near plane in camera space, projected, and rasterised
//! with edge functions and a 1/z depth test (1/z is affine in screen space), in parallel over
//! bands of rows, each band reading only the triangles that reach it. Computed once per
//! camera; every frame while the light moves reuses it.

use bspvt_proto::Mesh;
use bspvt_raytrace::Cutouts;
use glam::{DVec2, DVec3, Vec2};
use rayon::prelude::*;

use super::camera::View;
use super::normal_map::NormalMaps;
use std::sync::Arc;

/// No triangle at this pixel.
pub const NONE: u32 = u32::MAX;

/// Rows per parallel band.
const BAND: usize = 16;

/// What each pixel sees.
#[derive(Clone, Debug)]
pub struct GBuffer {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Triangle index per pixel (row-major), or [`NONE`].
    pub tri: Vec<u32>,
    /// Barycentrics (of vertices 1 and 2) of the primary-ray hit per pixel.
    pub(crate) bary: Vec<[f32; 2]>,
    /// The scene's normal maps, which bend every surface's shading normal.
    pub(crate) normal_maps: Option<Arc<NormalMaps>>,
    /// Pixels with a triangle (counted once: frames report it).
    covered: usize,
}

/// A screen-space point: pixels, and 1/z (affine in screen space).
type ScreenPoint = (DVec2, f64);

/// A triangle in screen space: its index, the pixel box it covers [x0, y0, x1, y1], and,
/// where the near plane cut it, the polygon left (one plane leaves at most 4 corners); an
/// uncut triangle's corners are its vertices' [`ScreenPoint`]s, kept once per vertex.
struct ScreenPoly {
    t: u32,
    bounds: [u32; 4],
    clipped: Option<Box<([ScreenPoint; 4], usize)>>,
}

/// A shading point on the mesh.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Surface {
    pub(crate) tri: u32,
    /// Barycentric weights of the triangle's three vertices.
    pub(crate) weights: [f64; 3],
    pub(crate) position: DVec3,
    /// Interpolated, normalised shading normal, flipped to face the viewer side of `geometric`.
    pub(crate) normal: DVec3,
    /// Unit geometric normal, facing the viewer.
    pub(crate) geometric: DVec3,
    /// The UV's change to the next pixel right and down, [∂uv/∂x, ∂uv/∂y] (the texture
    /// footprint that picks a mip level), where the mesh has UVs and the point is a pixel's.
    pub(crate) duv: Option<[Vec2; 2]>,
}

impl GBuffer {
    /// Rasterises `mesh` as seen by `view`.
    pub fn rasterize(mesh: &Mesh, view: &View) -> GBuffer {
        GBuffer::rasterize_cut(mesh, view, None)
    }

    /// [`GBuffer::rasterize`], seeing through the holes of `cut`: a fragment of a cut-out
    /// triangle is kept only where its alpha at the pixel's exact hit reaches the cut-off (the
    /// rasteriser's alpha test, [`Cutouts::covers_triangle`]).
    pub fn rasterize_cut(mesh: &Mesh, view: &View, cut: Option<&Cutouts>) -> GBuffer {
        let (w, h) = (view.width as usize, view.height as usize);
        let near = 1e-4 * f64::from(mesh.bounds().diagonal()).max(1e-12);
        // Camera-space vertices once, and the image of those in front of the near plane (1/z
        // > 0; 0 marks a vertex behind it, whose triangles are clipped).
        let cam: Vec<DVec3> = mesh
            .positions
            .par_iter()
            .map(|p| view.to_camera(p.as_dvec3()))
            .collect();
        let image = |q: DVec3| {
            let (x, y) = view.to_image(q);
            (DVec2::new(x, y), 1.0 / q.z)
        };
        let screen: Vec<ScreenPoint> = cam
            .par_iter()
            .map(|&q| {
                if q.z >= near {
                    image(q)
                } else {
                    (DVec2::NAN, 0.0)
                }
            })
            .collect();
        // Screen-space polygons (near-clipped), with their triangle index and pixel bounds.
        let polys: Vec<ScreenPoly> = mesh
            .triangles
            .par_iter()
            .enumerate()
            .filter_map(|(t, tri)| {
                let corners = tri.map(|i| screen[i as usize]);
                let (pts, n, clipped) = if corners.iter().all(|p| p.1 > 0.0) {
                    let [a, b, c] = corners;
                    ([a, b, c, c], 3, false)
                } else {
                    let (q, n) = clip_near(&tri.map(|i| cam[i as usize]), near);
                    if n < 3 {
                        return None;
                    }
                    (q.map(image), n, true)
                };
                let (mut lo, mut hi) =
                    (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
                for (p, _) in &pts[..n] {
                    lo = lo.min(*p);
                    hi = hi.max(*p);
                }
                if !(lo.x.is_finite() && hi.x.is_finite() && lo.y.is_finite() && hi.y.is_finite()) {
                    return None;
                }
                // Pixel centres (i + 0.5) inside [lo, hi].
                let x0 = (lo.x - 0.5).ceil().max(0.0);
                let y0 = (lo.y - 0.5).ceil().max(0.0);
                let x1 = (hi.x - 0.5).floor().min(w as f64 - 1.0);
                let y1 = (hi.y - 0.5).floor().min(h as f64 - 1.0);
                if x0 > x1 || y0 > y1 {
                    return None;
                }
                Some(ScreenPoly {
                    t: t as u32,
                    bounds: [x0 as u32, y0 as u32, x1 as u32, y1 as u32],
                    clipped: clipped.then(|| Box::new((pts, n))),
                })
            })
            .collect();
        let bands = Bands::of(&polys, h);

        let mut tri = vec![NONE; w * h];
        tri.par_chunks_mut(BAND * w)
            .enumerate()
            .for_each(|(band, ids)| {
                let row0 = band * BAND;
                let rows = ids.len() / w;
                let mut depth = vec![0.0f64; ids.len()];
                // The alpha test: the fragment's exact barycentrics of its mesh triangle.
                let covers = |t: u32, x: usize, y: usize| {
                    cut.is_none_or(|c| {
                        let d = view.ray_dir(x as f64 + 0.5, y as f64 + 0.5);
                        let p = mesh.triangles[t as usize]
                            .map(|v| mesh.positions[v as usize].as_dvec3());
                        let (b1, b2) = ray_plane_barycentrics(view.eye, d, p);
                        c.covers_triangle(t, [(1.0 - b1 - b2) as f32, b1 as f32, b2 as f32])
                    })
                };
                for &k in bands.of_band(band) {
                    let p = &polys[k as usize];
                    let [x0, y0, x1, y1] = p.bounds.map(|b| b as usize);
                    let (ya, yb) = (y0.max(row0), y1.min(row0 + rows - 1));
                    let mut raster = |corners| {
                        raster_triangle(
                            corners,
                            (x0, x1, ya, yb),
                            (row0, w),
                            p.t,
                            ids,
                            &mut depth,
                            &covers,
                        )
                    };
                    match p.clipped.as_deref() {
                        None => raster(mesh.triangles[p.t as usize].map(|v| screen[v as usize])),
                        // Fan triangulation of the (convex) clipped polygon.
                        Some((pts, n)) => {
                            for k in 1..n - 1 {
                                raster([pts[0], pts[k], pts[k + 1]]);
                            }
                        }
                    }
                }
            });

        // Exact hit points of the primary rays.
        let bary = tri
            .par_iter()
            .enumerate()
            .map(|(i, &t)| {
                if t == NONE {
                    return [0.0; 2];
                }
                let d = view.ray_dir((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
                let p = mesh.triangles[t as usize].map(|v| mesh.positions[v as usize].as_dvec3());
                let (b1, b2) = ray_plane_barycentrics(view.eye, d, p);
                [b1 as f32, b2 as f32]
            })
            .collect();
        GBuffer {
            width: w as u32,
            height: h as u32,
            covered: tri.iter().filter(|&&t| t != NONE).count(),
            tri,
            bary,
            normal_maps: None,
        }
    }

    /// This G-buffer's surfaces with their shading normals bent by `maps`
    /// ([`NormalMaps::of`] the scene).
    pub(crate) fn with_normal_maps(mut self, maps: Option<Arc<NormalMaps>>) -> GBuffer {
        self.normal_maps = maps;
        self
    }

    /// The surface seen through pixel `i` (row-major), if any.
    pub(crate) fn surface(&self, mesh: &Mesh, view: &View, i: usize) -> Option<Surface> {
        let t = *self.tri.get(i)?;
        if t == NONE {
            return None;
        }
        let idx = mesh.triangles[t as usize];
        let [b1, b2] = self.bary[i].map(f64::from);
        let weights = [1.0 - b1 - b2, b1, b2];
        let p = idx.map(|v| mesh.positions[v as usize].as_dvec3());
        let position = weights[0] * p[0] + weights[1] * p[1] + weights[2] * p[2];
        let mut geometric = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or(DVec3::Z);
        let to_eye = view.eye - position;
        if geometric.dot(to_eye) < 0.0 {
            geometric = -geometric;
        }
        let w = self.width as usize;
        let duv = uv_footprint(
            mesh,
            view,
            t,
            p,
            ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5),
        );
        let normal = shading_normal(
            mesh,
            t,
            weights,
            geometric,
            to_eye.normalize_or(geometric),
            duv,
            self.normal_maps.as_deref(),
        );
        Some(Surface {
            tri: t,
            weights,
            position,
            normal,
            geometric,
            duv,
        })
    }

    /// Per vertex, whether some pixel sees it (a corner of a triangle in the G-buffer) and
    /// whether the camera sees it from behind: the side [`shading_normal`] turns its normal
    /// to, voted by the pixels of the visible triangles that use it (a triangle shows the back
    /// of vertex v when v's normal points away from the triangle's face the eye sees). The
    /// underside of a two-sided sheet lit from above is seen from behind; a closed mesh's
    /// silhouette vertex, whose normal turns slightly away from the eye over a face that looks
    /// at it, is not. A vertex seen from both sides takes the side most pixels see.
    pub(crate) fn vertex_sides(&self, mesh: &Mesh, eye: DVec3) -> (Vec<bool>, Vec<bool>) {
        let mut pixels = vec![0u32; mesh.triangles.len()];
        for &t in &self.tri {
            if let Some(c) = pixels.get_mut(t as usize) {
                *c += 1;
            }
        }
        let mut seen = vec![false; mesh.vertex_count()];
        // Pixels that see vertex v's back minus those that see its front.
        let mut vote = vec![0i64; mesh.vertex_count()];
        for (idx, &c) in mesh.triangles.iter().zip(&pixels) {
            if c == 0 {
                continue;
            }
            let p = idx.map(|v| mesh.positions[v as usize].as_dvec3());
            let mut g = (p[1] - p[0]).cross(p[2] - p[0]);
            if g.dot(eye - p[0]) < 0.0 {
                g = -g;
            }
            for &v in idx {
                seen[v as usize] = true;
                let n = mesh
                    .normals
                    .get(v as usize)
                    .map_or(DVec3::ZERO, |n| n.as_dvec3());
                let d = n.dot(g);
                if d < 0.0 {
                    vote[v as usize] += i64::from(c);
                } else if d > 0.0 {
                    vote[v as usize] -= i64::from(c);
                }
            }
        }
        (seen, vote.into_iter().map(|x| x > 0).collect())
    }

    /// Pixels that see a surface.
    pub(crate) fn covered(&self) -> usize {
        self.covered
    }
}

/// Sutherland–Hodgman against the plane z = near (camera space).
fn clip_near(c: &[DVec3; 3], near: f64) -> ([DVec3; 4], usize) {
    let (mut out, mut n) = ([DVec3::ZERO; 4], 0);
    for i in 0..3 {
        let (a, b) = (c[i], c[(i + 1) % 3]);
        let (ia, ib) = (a.z >= near, b.z >= near);
        if ia {
            out[n] = a;
            n += 1;
        }
        if ia != ib {
            let t = (near - a.z) / (b.z - a.z);
            out[n] = a + (b - a) * t;
            n += 1;
        }
    }
    (out, n)
}

/// The polygons each band of [`BAND`] rows meets, each band's in triangle order (the order the
/// depth test meets them in, so ties resolve as in one pass over all), as one list of indices
/// into the polygons with each band's start: a band reads its own polygons only, not every
/// polygon of the mesh.
struct Bands {
    start: Vec<usize>,
    members: Vec<u32>,
}

impl Bands {
    fn of(polys: &[ScreenPoly], height: usize) -> Bands {
        let count = height.div_ceil(BAND);
        let rows = |p: &ScreenPoly| p.bounds[1] as usize / BAND..=p.bounds[3] as usize / BAND;
        let mut start = vec![0usize; count + 1];
        for p in polys {
            for b in rows(p) {
                start[b + 1] += 1;
            }
        }
        for b in 0..count {
            start[b + 1] += start[b];
        }
        let mut next = start.clone();
        let mut members = vec![0u32; start[count]];
        for (k, p) in polys.iter().enumerate() {
            for b in rows(p) {
                members[next[b]] = k as u32;
                next[b] += 1;
            }
        }
        Bands { start, members }
    }

    fn of_band(&self, band: usize) -> &[u32] {
        &self.members[self.start[band]..self.start[band + 1]]
    }
}

/// Edge-function rasterisation of one screen triangle into a band, with a 1/z depth test
/// (larger 1/z is nearer).
fn raster_triangle(
    v: [(DVec2, f64); 3],
    (x0, x1, ya, yb): (usize, usize, usize, usize),
    (row0, w): (usize, usize),
    t: u32,
    ids: &mut [u32],
    depth: &mut [f64],
    covers: &dyn Fn(u32, usize, usize) -> bool,
) {
    let [(a, za), (b, zb), (c, zc)] = v;
    let area = (b - a).perp_dot(c - a);
    if !(area.abs() > 0.0) {
        return;
    }
    let inv = 1.0 / area;
    for y in ya..=yb {
        let py = y as f64 + 0.5;
        for x in x0..=x1 {
            let p = DVec2::new(x as f64 + 0.5, py);
            let w0 = (c - b).perp_dot(p - b) * inv;
            let w1 = (a - c).perp_dot(p - c) * inv;
            let w2 = (b - a).perp_dot(p - a) * inv;
            if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                continue;
            }
            let z = w0 * za + w1 * zb + w2 * zc;
            let k = (y - row0) * w + x;
            if z > depth[k] && covers(t, x, y) {
                depth[k] = z;
                ids[k] = t;
            }
        }
    }
}

/// Barycentrics (b1, b2) of the intersection of a ray with the plane of triangle `p`
/// (Möller–Trumbore without the inside test: the rasteriser, or a traversal, already chose the
/// triangle), clamped into it; the centroid where the ray runs along the plane. Shared with
/// the Monte Carlo's camera rays (`groundtruth::primary`).
pub(crate) fn ray_plane_barycentrics(o: DVec3, d: DVec3, p: [DVec3; 3]) -> (f64, f64) {
    let Some((_, u, v)) = plane_hit(o, d, p) else {
        return (1.0 / 3.0, 1.0 / 3.0);
    };
    // Pixel centres on a triangle's edge may land a hair outside: clamp into the triangle.
    let (u, v) = (u.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
    let s = u + v;
    if s > 1.0 { (u / s, v / s) } else { (u, v) }
}

/// Where the line `o + t d` meets the plane of `p`: (t, b1, b2), barycentrics unclamped;
/// `None` where it runs along the plane (or the input is not finite).
fn plane_hit(o: DVec3, d: DVec3, p: [DVec3; 3]) -> Option<(f64, f64, f64)> {
    let e1 = p[1] - p[0];
    let e2 = p[2] - p[0];
    let pv = d.cross(e2);
    let det = e1.dot(pv);
    if !(det.abs() > 1e-300) {
        return None;
    }
    let inv = 1.0 / det;
    let tv = o - p[0];
    let q = tv.cross(e1);
    Some((e2.dot(q) * inv, tv.dot(pv) * inv, d.dot(q) * inv))
}

/// The texture footprint of the pixel at image point `(x, y)` on triangle `t` (corners `p`):
/// the UV where the rays through the next pixel right and down meet the triangle's plane (its
/// barycentrics unclamped: a plane, not a triangle, is what the footprint lies on), less the
/// UV here — a ray differential [Igehy99] by finite differences. `None` without UVs or where a
/// ray runs along the plane.
pub(crate) fn uv_footprint(
    mesh: &Mesh,
    view: &View,
    t: u32,
    p: [DVec3; 3],
    (x, y): (f64, f64),
) -> Option<[Vec2; 2]> {
    let idx = mesh.triangles.get(t as usize)?;
    let uv = idx.map(|v| mesh.uvs.get(v as usize).map(|u| u.as_dvec2()));
    let [Some(u0), Some(u1), Some(u2)] = uv else {
        return None;
    };
    let at = |x: f64, y: f64| -> Option<DVec2> {
        let (t, b1, b2) = plane_hit(view.eye, view.ray_dir(x, y), p)?;
        (t > 0.0).then(|| (1.0 - b1 - b2) * u0 + b1 * u1 + b2 * u2)
    };
    let here = at(x, y)?;
    let dx = at(x + 1.0, y)? - here;
    let dy = at(x, y + 1.0)? - here;
    (dx.is_finite() && dy.is_finite()).then(|| [dx.as_vec2(), dy.as_vec2()])
}

/// The shading normal at the point of triangle `t` with barycentric `weights`, seen along
/// unit `wo` (toward the eye): the interpolated vertex normal (the geometric one where that is
/// degenerate), bent by the material's normal map, on the side of `geometric` (the viewer's).
/// *The* shading normal of every per-pixel method and of the Monte Carlo's camera rays.
/// A bent normal is kept facing the viewer ([`NormalMaps::facing`]).
pub(crate) fn shading_normal(
    mesh: &Mesh,
    t: u32,
    weights: [f64; 3],
    geometric: DVec3,
    wo: DVec3,
    duv: Option<[Vec2; 2]>,
    maps: Option<&NormalMaps>,
) -> DVec3 {
    let Some(idx) = mesh.triangles.get(t as usize) else {
        return geometric;
    };
    let n = idx.map(|v| {
        mesh.normals
            .get(v as usize)
            .map_or(DVec3::ZERO, |n| n.as_dvec3())
    });
    let interpolated =
        (weights[0] * n[0] + weights[1] * n[1] + weights[2] * n[2]).normalize_or(geometric);
    // A back face seen: its whole tangent frame turns over with it (glTF 2.0 §3.9.3).
    let flip = interpolated.dot(geometric) < 0.0;
    let side = |v: DVec3| if flip { -v } else { v };
    match maps {
        None => side(interpolated),
        Some(m) => NormalMaps::facing(
            side(m.bend(mesh, t, weights, interpolated, duv)),
            side(interpolated),
            wo,
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bspvt_proto::builtin;

    /// Rasterised primary visibility agrees with ray casting (closest hit by brute force) on
    /// the built-in scene, except on a thin set of silhouette/edge pixels.
    #[test]
    fn rasterisation_matches_ray_casting() {
        let scene = builtin::scene("plate-small").expect("built-in scene");
        let view = View::new(&scene.camera, 96, 64);
        let g = GBuffer::rasterize(&scene.mesh, &view);
        let m = &scene.mesh;
        let mut differ = 0;
        for i in 0..g.tri.len() {
            let d = view.ray_dir((i % 96) as f64 + 0.5, (i / 96) as f64 + 0.5);
            let mut best = (f64::INFINITY, NONE);
            for (t, tri) in m.triangles.iter().enumerate() {
                let p = tri.map(|v| m.positions[v as usize].as_dvec3());
                if let Some(tt) = hit(view.eye, d, p)
                    && tt < best.0
                {
                    best = (tt, t as u32);
                }
            }
            if best.1 != g.tri[i] {
                // Only acceptable when the two are at (nearly) the same depth: shared edges.
                let depth = |t: u32| {
                    if t == NONE {
                        return f64::INFINITY;
                    }
                    let p = m.triangles[t as usize].map(|v| m.positions[v as usize].as_dvec3());
                    let n = (p[1] - p[0]).cross(p[2] - p[0]);
                    n.dot(p[0] - view.eye) / n.dot(d)
                };
                let (a, b) = (depth(best.1), depth(g.tri[i]));
                if !((a - b).abs() < 1e-3 * a.abs().max(1.0)) {
                    differ += 1;
                }
            }
        }
        assert!(g.covered() > 96 * 64 / 4, "covered {}", g.covered());
        eprintln!("{} covered, {differ} differ", g.covered());
        assert!(differ <= 96 * 64 / 500, "{differ} pixels differ");
    }

    /// The banded rasteriser (each band reading only the triangles that reach it, uncut
    /// triangles' corners projected once per vertex) sees through every pixel what one pass
    /// over all triangles in mesh order sees, where the near plane cuts the ground under and
    /// behind the eye and the image's last band is partial.
    #[test]
    fn the_bands_see_what_one_pass_over_every_triangle_sees() {
        let scene = builtin::scene("plate-small").expect("built-in scene");
        let b = scene.mesh.bounds();
        let (lo, hi) = (b.min, b.max);
        let camera = bspvt_proto::scene::Camera {
            position: [
                0.5 * (lo.x + hi.x),
                lo.y + 0.05 * (hi.y - lo.y),
                0.5 * (lo.z + hi.z),
            ],
            target: [hi.x, lo.y, hi.z],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 70.0,
            aspect: None,
        };
        let (w, h) = (80usize, 50usize);
        let view = View::new(&camera, w as u32, h as u32);
        let g = GBuffer::rasterize(&scene.mesh, &view);
        let m = &scene.mesh;
        let near = 1e-4 * f64::from(m.bounds().diagonal()).max(1e-12);
        let mut reference = vec![NONE; w * h];
        let mut depth = vec![0.0f64; w * h];
        let mut cut = 0;
        for (t, tri) in m.triangles.iter().enumerate() {
            let c = tri.map(|v| view.to_camera(m.positions[v as usize].as_dvec3()));
            let (q, n) = clip_near(&c, near);
            if n < 3 {
                continue;
            }
            cut += usize::from(c.iter().any(|q| q.z < near));
            let pts: Vec<ScreenPoint> = q[..n]
                .iter()
                .map(|&q| {
                    let (x, y) = view.to_image(q);
                    (DVec2::new(x, y), 1.0 / q.z)
                })
                .collect();
            for k in 1..n - 1 {
                raster_triangle(
                    [pts[0], pts[k], pts[k + 1]],
                    (0, w - 1, 0, h - 1),
                    (0, w),
                    t as u32,
                    &mut reference,
                    &mut depth,
                    &|_, _, _| true,
                );
            }
        }
        assert!(cut > 0, "the near plane cuts some triangles");
        assert!(g.covered() > w * h / 4, "covered {}", g.covered());
        assert_eq!(g.tri, reference);
    }

    /// The side each vertex is seen from: a sheet whose normals face up is seen from behind
    /// from below and from the front from above; no vertex of a closed smooth sphere is seen
    /// from behind, though the normals of its silhouette's vertices turn away from the eye.
    #[test]
    fn vertices_seen_from_behind_follow_the_faces_seen() {
        let camera = |y: f32| bspvt_proto::scene::Camera {
            position: [0.3, y, 2.5],
            target: [0.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
            aspect: None,
        };
        let sheet = builtin::grid_plane(glam::Vec3::ZERO, glam::Vec3::Z, glam::Vec3::X, 5, 0);
        assert!(
            sheet.normals.iter().all(|n| n.y > 0.99),
            "the sheet faces up"
        );
        for (y, behind) in [(-1.0, true), (1.0, false)] {
            let view = View::new(&camera(y), 48, 48);
            let g = GBuffer::rasterize(&sheet, &view);
            let (seen, side) = g.vertex_sides(&sheet, view.eye);
            assert!(
                seen.iter().filter(|&&s| s).count() > 20,
                "the sheet is seen"
            );
            for (v, (&s, &b)) in seen.iter().zip(&side).enumerate() {
                assert!(!s || b == behind, "eye at y = {y}: vertex {v} behind {b}");
            }
        }
        let sphere = builtin::icosphere(3, 0);
        let view = View::new(&camera(0.5), 64, 64);
        let g = GBuffer::rasterize(&sphere, &view);
        let (seen, side) = g.vertex_sides(&sphere, view.eye);
        // Vertices seen whose normals turn away from the eye: the silhouette's.
        let turned = seen
            .iter()
            .enumerate()
            .filter(|&(v, &s)| {
                let p = sphere.positions[v].as_dvec3();
                s && sphere.normals[v].as_dvec3().dot(view.eye - p) < 0.0
            })
            .count();
        assert!(turned > 0, "the silhouette has vertices facing away");
        assert!(
            !side.iter().any(|&b| b),
            "a closed mesh is seen from the front"
        );
    }

    fn hit(o: DVec3, d: DVec3, p: [DVec3; 3]) -> Option<f64> {
        let e1 = p[1] - p[0];
        let e2 = p[2] - p[0];
        let pv = d.cross(e2);
        let det = e1.dot(pv);
        if det.abs() < 1e-14 {
            return None;
        }
        let tv = o - p[0];
        let u = tv.dot(pv) / det;
        let q = tv.cross(e1);
        let v = d.dot(q) / det;
        let t = e2.dot(q) / det;
        (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0).then_some(t)
    }
}
