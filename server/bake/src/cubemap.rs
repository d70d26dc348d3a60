//! A vertex's visibility cube map: which pixels matter and what fraction of their rays escape.

use bspvt_proto::Aabb;
use bspvt_proto::cubemap::{FACES, FaceFrame, pixel_centres};
use glam::{Vec2, Vec3};
use serde::Serialize;

use super::frustum::{FrustumCuller, Pyramid};
use super::walk::SurfaceWalk;
use bspvt_raytrace::Occluder;
use obvhs::ray::Ray;

/// Ray directions shared by every vertex (the cube map is world-aligned).
pub(crate) struct RayTable {
    pub res: u32,
    /// Supersamples per pixel (s²).
    pub samples: u32,
    /// Pixel-centre face coordinates, index `j·res + i`.
    pub uv: Vec<Vec2>,
    /// Unit pixel-centre directions per face.
    pub centre: [Vec<Vec3>; FACES],
    /// Unit sub-pixel directions per face, `samples` per pixel (the centre when s = 1).
    pub sub: [Vec<Vec3>; FACES],
}

impl RayTable {
    pub(crate) fn new(res: u32, supersampling: u32) -> RayTable {
        let uv = pixel_centres(res);
        let s = supersampling.max(1);
        let offsets = subpixel_offsets(res, s);
        let centre = std::array::from_fn(|f| {
            let fr = FaceFrame::of(f);
            uv.iter().map(|&p| fr.direction(p).normalize()).collect()
        });
        let sub = std::array::from_fn(|f| {
            let fr = FaceFrame::of(f);
            uv.iter()
                .flat_map(|&p| {
                    offsets
                        .iter()
                        .map(move |&o| fr.direction(p + o).normalize())
                })
                .collect()
        });
        RayTable {
            res,
            samples: s * s,
            uv,
            centre,
            sub,
        }
    }
}

/// Offsets from a pixel's centre (face coordinates) of its s×s sub-pixel ray centres, row by
/// row: a regular grid, so the bake is deterministic.
pub fn subpixel_offsets(res: u32, s: u32) -> Vec<Vec2> {
    let h = 1.0 / res as f32; // half a pixel in face coordinates
    (0..s)
        .flat_map(|y| {
            (0..s).map(move |x| {
                Vec2::new(
                    (2 * x + 1) as f32 / s as f32 - 1.0,
                    (2 * y + 1) as f32 / s as f32 - 1.0,
                ) * h
            })
        })
        .collect()
}

/// The pixels of one face that matter, with the number of their rays that escape (0..=samples).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FacePixels {
    /// Pixel indices (`j · res + i`), ascending.
    pub index: Vec<u32>,
    /// Escaping rays of each pixel: V(p) = visible / samples [paper000 §3.1].
    pub visible: Vec<u16>,
    /// How many of these pixels the smallest light seen on the face reaches (`u32::MAX`:
    /// no light stops, the sky's bake): it bounds the fit's tolerance on the face
    /// (`Fitter::for_face`).
    pub light_pixels: u32,
    /// Pixel indices (`j · res + i`, ascending, each one of `index`) whose count was aimed at
    /// a sun at rest ([`VertexRays::aim`]): a leaf that holds one must be pure, all its
    /// pixels' counts equal (`Fitter::fit_protected`). Empty but in the sky's bake of a scene
    /// with suns.
    pub protected: Vec<u32>,
}

impl Default for FacePixels {
    /// No pixels, and no light to tighten the fit's tolerance.
    fn default() -> Self {
        FacePixels {
            index: Vec::new(),
            visible: Vec::new(),
            light_pixels: u32::MAX,
            protected: Vec::new(),
        }
    }
}

/// A vertex's cube map: per face, its pixels that matter (`None`: none).
pub type CubeMap = [Option<FacePixels>; FACES];

/// How a vertex's rays are cast. Both give the same cube map, bit for bit (tested against
/// casting every ray on the shared meshes); `Adaptive` is cheaper.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CastMode {
    /// The culled quadtree walk: every ray of a block that may hold geometry is answered by
    /// its candidate list or a BVH traversal.
    Full,
    /// As `Full`, but a ray first tries the triangles that blocked nearby rays (its pixel's
    /// earlier sub-rays, the pixels left of and above it, the face's last blocked ray), then,
    /// before a BVH traversal, walks the mesh from a neighbouring pixel's blocker to the
    /// triangle it passes through (`walk.rs`): most occluded rays (the costliest: an any-hit
    /// traversal through a self-occluding mesh) end after a few triangle tests. Only hits well
    /// inside a triangle's edges count; a ray no such triangle blocks is cast as in `Full`.
    #[default]
    Adaptive,
}

/// What casting one vertex's cube map cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CastCounts {
    /// Rays tested against geometry (a BVH traversal, a candidate list or a neighbour's
    /// blocker); rays answered by culling alone are not counted.
    pub rays: u64,
    /// Rays that traversed the BVH.
    pub traversals: u64,
    /// GPU cast: sub-rays cast again on the CPU, those of pixels where the device's rounding
    /// could have decided a ray otherwise than the CPU's (counted in `rays` too).
    pub recast: u64,
}

impl std::ops::AddAssign for CastCounts {
    fn add_assign(&mut self, o: CastCounts) {
        self.rays += o.rays;
        self.traversals += o.traversals;
        self.recast += o.recast;
    }
}

/// Where a visibility ray ends: at the light it looks for. V(p, ω) = 1 when the ray from p
/// along ω reaches the light before any occluder, so geometry beyond the light (a ceiling over
/// a lamp, the wall behind it) never shadows it. A ray ends at the nearest stop it *reaches*;
/// crossing a lamp's plane beside the lamp ends nothing. Occluders inside a light's region,
/// between the region's boundary and the light itself, are not seen (docs/bake.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightStop {
    /// A light's declared region: the ray ends where it enters the box (a vertex inside the
    /// box casts its rays unbounded).
    Region(Aabb),
    /// A light that moves in its plane: the ray ends where it crosses that plane.
    Plane {
        /// A point of the plane (the polygon's centroid).
        point: Vec3,
        /// The plane's unit normal.
        normal: Vec3,
    },
    /// A fixed lamp: the ray ends where it crosses the lamp's polygon, grown by the cone of
    /// the cube-map pixel around it ([`LampStop`]).
    Lamp(LampStop),
    /// A point or spot light's sphere: the ray ends where it enters the sphere, grown by the
    /// pixel's cone ([`SphereStop`]).
    Sphere(SphereStop),
}

/// A point or spot light's sphere as a ray stop (docs/scene-format.md). The pixel matters
/// when its cone (tan θ ≤ `spread`, as for [`LampStop`]) meets the sphere: when its centre's
/// ray passes within `r + t_c · spread` of the centre (t_c: the distance to the point of
/// closest approach; [`SphereStop::reaches`]). A sphere is often smaller than a pixel, so
/// every sub-ray of such a pixel must end at it, not run past it to the wall behind (which
/// would darken a fully visible bulb by the share of the pixel it does not cover): a ray
/// stops where it passes within `r + 2 t_c · spread` — where it enters the sphere, or at its
/// closest approach when it only grazes the grown sphere ([`SphereStop::distance`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphereStop {
    /// The sphere's centre.
    pub centre: Vec3,
    /// Its radius.
    pub radius: f32,
    /// tan θ of the pixels' cones.
    pub spread: f32,
}

impl SphereStop {
    /// Where the ray from `origin` along unit `d` stops here, if it does (never from inside
    /// the sphere: nothing there is lit by it).
    #[inline]
    pub(crate) fn distance(&self, origin: Vec3, d: Vec3) -> Option<f32> {
        self.within(origin, d, 2.0)
    }

    /// Whether a pixel whose centre's ray is `d` can see the sphere.
    #[inline]
    pub(crate) fn reaches(&self, origin: Vec3, d: Vec3) -> bool {
        self.within(origin, d, 1.0).is_some()
    }

    /// Where the ray stops if it passes within r + `cones` · t_c · spread of the centre.
    #[inline]
    fn within(&self, origin: Vec3, d: Vec3, cones: f32) -> Option<f32> {
        let oc = self.centre - origin;
        let tc = oc.dot(d);
        if !(tc > 0.0) {
            return None;
        }
        let perp2 = (oc.length_squared() - tc * tc).max(0.0);
        let grown = self.radius + cones * tc * self.spread;
        if !(perp2 <= grown * grown) {
            return None;
        }
        let t = tc - (self.radius * self.radius - perp2).max(0.0).sqrt();
        (t > 0.0 && t.is_finite()).then_some(t)
    }
}

/// A fixed lamp's polygon as a ray stop. A pixel's rays lie in a cone of half-angle θ
/// around its centre (tan θ ≤ `spread` = √2 / res: half a pixel's diagonal at the face's
/// centre, its widest), and the pixel matters when that cone meets the lamp; so the centre's
/// ray stops where it crosses the lamp's plane within `t · spread / |cos|` (the cone's
/// footprint there, t the distance, cos the incidence) of the polygon — the same test for the
/// pixel mask and for the rays, so a pixel straddling the lamp's outline is traced to the lamp,
/// not beyond it. A one-sided lamp is reached only from its emitting side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LampStop {
    /// The plane's unit normal (the emitting side's).
    pub normal: Vec3,
    /// The plane: normal · x = `offset`.
    pub offset: f32,
    /// Per edge, the in-plane unit normal pointing inside and its offset: a point x of the
    /// plane is inside the polygon when `m · x ≥ c` for every edge (first `edge_count`).
    pub edges: [(Vec3, f32); MAX_LAMP_EDGES],
    /// Edges in use (3 to 8).
    pub edge_count: u32,
    /// tan θ of the pixels' cones.
    pub spread: f32,
    /// Reached from both sides.
    pub two_sided: bool,
}

/// The most edges a lamp has (a scene's light has 3 to 8 vertices).
pub const MAX_LAMP_EDGES: usize = 8;

impl LampStop {
    /// `light`'s polygon as a stop for cube maps of `res` pixels a side (`None`: degenerate).
    pub fn new(light: &bspvt_proto::scene::PolygonLight, res: u32) -> Option<LampStop> {
        let pts = light.points();
        let normal = light.normal();
        if pts.len() < 3 || pts.len() > MAX_LAMP_EDGES || normal == Vec3::ZERO {
            return None;
        }
        let mut edges = [(Vec3::ZERO, 0.0); MAX_LAMP_EDGES];
        for (i, e) in edges.iter_mut().enumerate().take(pts.len()) {
            let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
            // Counter-clockwise seen from the emitting side: n × edge points inside.
            let m = normal.cross(b - a).normalize_or_zero();
            *e = (m, m.dot(a));
        }
        let c = pts.iter().copied().sum::<Vec3>() / pts.len() as f32;
        Some(LampStop {
            normal,
            offset: normal.dot(c),
            edges,
            edge_count: pts.len() as u32,
            spread: std::f32::consts::SQRT_2 / res.max(1) as f32,
            two_sided: light.two_sided,
        })
    }

    /// Which pixels of face `fr` (`res` a side, index `j · res + i`) may reach the lamp from
    /// `origin`: `out[p]` is false only where [`Self::distance`] surely fails for the pixel's
    /// centre. For d = w + u a + v b unnormalised, N = n·d, M_k = m_k·d, L² = |d|² and the
    /// height h = offset − n·o, the centre's test is N h > 0 and, for every edge,
    /// e_k N²/|h| + |N| M_k + s L² ≥ 0 (its edge test times N²/|h|; e_k = m_k·o − c_k).
    /// Blocks of pixels are bounded in interval arithmetic (f64, with a relative slack for
    /// the f32 test) and split down to 4×4: a block where no direction heads to the plane, or
    /// some edge's bound is negative, holds no pixel that reaches the lamp.
    pub(crate) fn candidates(&self, origin: Vec3, fr: &FaceFrame, res: usize, out: &mut [bool]) {
        out.fill(false);
        let o = origin.as_dvec3();
        let n = self.normal.as_dvec3();
        let h = f64::from(self.offset) - n.dot(o);
        if !(h.abs() > 0.0) || (!self.two_sided && !(h < 0.0)) {
            return;
        }
        let sigma = h.signum();
        // An affine g(u, v) = g0 + u gu + v gv as (g0, gu, gv), for g = x · d.
        let affine = |x: glam::DVec3| (x.dot(fr.w64()), x.dot(fr.a64()), x.dot(fr.b64()));
        let nd = affine(n * sigma);
        let edges: Vec<(f64, (f64, f64, f64))> = self.edges[..self.edge_count as usize]
            .iter()
            .map(|&(m, c)| {
                let m = m.as_dvec3();
                ((m.dot(o) - f64::from(c)) / h.abs(), affine(m))
            })
            .collect();
        let spread = f64::from(self.spread);
        let e = |i: usize| 2.0 * i as f64 / res as f64 - 1.0;
        let range = |g: (f64, f64, f64), u: (f64, f64), v: (f64, f64)| {
            let (a, b) = ((u.0 * g.1).min(u.1 * g.1), (u.0 * g.1).max(u.1 * g.1));
            let (c, d) = ((v.0 * g.2).min(v.1 * g.2), (v.0 * g.2).max(v.1 * g.2));
            (g.0 + a + c, g.0 + b + d)
        };
        // May any centre of the block [i0, i1) × [j0, j1) reach the lamp?
        let may = |i0: usize, i1: usize, j0: usize, j1: usize| -> bool {
            let (u, v) = ((e(i0), e(i1)), (e(j0), e(j1)));
            // |N| where N heads toward the plane (σN > 0).
            let (p_lo, p_hi) = range(nd, u, v);
            if !(p_hi > 0.0) {
                return false;
            }
            let p_lo = p_lo.max(0.0);
            let l2 = 1.0 + u.0.powi(2).max(u.1.powi(2)) + v.0.powi(2).max(v.1.powi(2));
            edges.iter().all(|&(ek, mk)| {
                let (m_lo, m_hi) = range(mk, u, v);
                let t1 = if ek >= 0.0 {
                    ek * p_hi * p_hi
                } else {
                    ek * p_lo * p_lo
                };
                let t2 = (p_lo * m_lo)
                    .max(p_lo * m_hi)
                    .max(p_hi * m_lo)
                    .max(p_hi * m_hi);
                let t3 = spread * l2;
                let slack = 1e-5 * (t1.abs() + t2.abs() + t3.abs()) + 1e-12;
                t1 + t2 + t3 >= -slack
            })
        };
        let mut stack = vec![(0, res, 0, res)];
        while let Some((i0, i1, j0, j1)) = stack.pop() {
            if !may(i0, i1, j0, j1) {
                continue;
            }
            if i1 - i0 <= 4 && j1 - j0 <= 4 {
                for j in j0..j1 {
                    out[j * res + i0..j * res + i1].fill(true);
                }
                continue;
            }
            let (im, jm) = (i0 + (i1 - i0).div_ceil(2), j0 + (j1 - j0).div_ceil(2));
            for (a, b) in [(i0, im), (im, i1)] {
                for (c, d) in [(j0, jm), (jm, j1)] {
                    if a < b && c < d {
                        stack.push((a, b, c, d));
                    }
                }
            }
        }
    }

    /// Where the ray from `origin` along unit `d` stops here, if it does.
    #[inline]
    pub(crate) fn distance(&self, origin: Vec3, d: Vec3) -> Option<f32> {
        let height = self.offset - self.normal.dot(origin);
        // A one-sided lamp sends nothing to the points behind it (height ≥ 0 there).
        if !self.two_sided && !(height < 0.0) {
            return None;
        }
        let den = d.dot(self.normal);
        let t = height / den;
        if !(den != 0.0 && t > 0.0 && t.is_finite()) {
            return None;
        }
        let x = origin + t * d;
        let grow = t * self.spread / den.abs();
        self.edges[..self.edge_count as usize]
            .iter()
            .all(|&(m, c)| m.dot(x) - c >= -grow)
            .then_some(t)
    }
}

impl LightStop {
    /// The stops of a scene's lights, for its bake's cube maps: its polygon lights'
    /// ([`LightStop::of_light`]) and its point and spot lights' spheres. Suns have none: they
    /// are shaded through the sky's bake (`Scene::suns_in_sky_bake`), or, in a scene lit by
    /// suns alone, this bake is the sky's (no stops: every direction, rays to infinity).
    pub fn of_scene(scene: &bspvt_proto::Scene) -> Vec<LightStop> {
        let res = scene.bake.face_res;
        let mut stops: Vec<LightStop> = scene
            .lights
            .iter()
            .filter_map(|l| LightStop::of_light(l, res))
            .collect();
        stops.extend(scene.punctual.iter().map(|l| {
            LightStop::Sphere(SphereStop {
                centre: Vec3::from(l.position),
                radius: l.sphere_radius(),
                spread: std::f32::consts::SQRT_2 / res.max(1) as f32,
            })
        }));
        stops
    }

    /// The stop of one light, for cube maps of `res` pixels a side: its region where it
    /// declares one, its plane where it moves in it, else its polygon (`None`: a degenerate
    /// lamp, which a validated scene has not).
    pub fn of_light(light: &bspvt_proto::scene::PolygonLight, res: u32) -> Option<LightStop> {
        use bspvt_proto::scene::LightMotion;
        match light.motion() {
            LightMotion::Region(r) => Some(LightStop::Region(r.aabb())),
            LightMotion::Plane => {
                let pts = light.points();
                let c = pts.iter().copied().sum::<Vec3>() / pts.len().max(1) as f32;
                Some(LightStop::Plane {
                    point: c,
                    normal: light.normal(),
                })
            }
            LightMotion::Fixed => LampStop::new(light, res).map(LightStop::Lamp),
            // A polygon light does not turn freely (only a sun does, through the sky's bake).
            LightMotion::Turns => None,
        }
    }

    /// The distance along unit `d` from `origin` at which the ray ends here, if it does.
    #[inline(always)]
    pub(crate) fn distance(&self, origin: Vec3, d: Vec3) -> Option<f32> {
        match *self {
            LightStop::Region(b) => b.ray_entry(origin, d),
            LightStop::Plane { point, normal } => {
                let den = d.dot(normal);
                let t = (point - origin).dot(normal) / den;
                (den != 0.0 && t > 0.0 && t.is_finite()).then_some(t)
            }
            LightStop::Lamp(ref l) => l.distance(origin, d),
            LightStop::Sphere(ref l) => l.distance(origin, d),
        }
    }
}

/// One light stop's test of which pixels of a face can reach it ([`VertexRays::face_mask`]).
enum Reach<'a> {
    /// The centre's ray meets the box.
    Region(Aabb),
    /// w·k + u\[i\] + v\[j\] > 0 for pixel (i, j).
    Plane(f32, Vec<f32>, Vec<f32>),
    /// The centre's ray reaches the lamp ([`LampStop::distance`]), tested where
    /// [`LampStop::candidates`] leaves it possible.
    Lamp(&'a LampStop, Vec<bool>),
    /// The centre's ray reaches the sphere ([`SphereStop::reaches`]).
    Sphere(&'a SphereStop),
}

/// Where a vertex's rays start and which directions can matter.
pub(crate) struct VertexRays<'a> {
    /// Where the rays start: the vertex lifted off its surface ([`crate::origin`]).
    pub origin: Vec3,
    pub normal: Vec3,
    pub vertex: u32,
    /// Hits nearer than this are not counted ([`crate::RAY_T_MIN_SCALE`] of the scene's
    /// diagonal).
    pub t_min: f32,
    /// Geometry this far below the horizon plane through `origin` is culled
    /// ([`crate::RAY_HORIZON_MARGIN_SCALE`] of the scene's diagonal; `frustum::Pyramid`).
    pub horizon_margin: f32,
    /// Where rays end (at the first stop they reach); a direction matters when it can reach
    /// one of them ([`LightStop::reachable`]), every direction when there are none (the sky's
    /// bake).
    pub stops: &'a [LightStop],
    /// The suns at rest the sky's bake aims at ([`VertexRays::aim`]; empty elsewhere).
    pub suns: &'a [SunDisk],
}

/// A sun at rest as the sky's bake sees it: a disk at infinity ([`VertexRays::aim`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunDisk {
    /// Unit direction toward the sun.
    pub toward: Vec3,
    /// tan of the disk's half-angle.
    pub tan_half_angle: f32,
}

impl SunDisk {
    /// The suns of `scene` at rest (those whose direction is a direction).
    pub fn of_scene(scene: &bspvt_proto::Scene) -> Vec<SunDisk> {
        scene
            .suns
            .iter()
            .filter_map(|s| {
                let toward = s.toward();
                let tan_half_angle = s.half_angle().tan();
                (toward != Vec3::ZERO && tan_half_angle > 0.0 && tan_half_angle.is_finite())
                    .then_some(SunDisk {
                        toward,
                        tan_half_angle,
                    })
            })
            .collect()
    }
}

/// A disk a vertex's rays are aimed at ([`VertexRays::aim_at_disks`]).
#[derive(Clone, Copy, Debug)]
struct Disk {
    /// Unit direction to its centre.
    w: Vec3,
    /// tan of its half-angle as the vertex sees it.
    tan_a: f32,
    /// Whether the pixels it falls in are kept pure by the fit ([`FacePixels::protected`]).
    protect: bool,
}

impl VertexRays<'_> {
    /// Sub-pixel rays below the horizon (of a pixel whose centre is above it) are counted as
    /// escaping without casting: the cosine term clips those directions at shading time, and
    /// casting them would shadow the pixel with the vertex's own surface.
    #[inline]
    pub(crate) fn escapes_below_horizon(&self, d: Vec3) -> bool {
        d.dot(self.normal) <= 0.0
    }

    /// How many of a pixel's sub-rays escape, given `hit(d)`: the occlusion test to use.
    #[inline]
    fn escaping(&self, subs: &[Vec3], hit: impl Fn(Vec3) -> bool) -> u16 {
        subs.iter()
            .filter(|&&d| self.escapes_below_horizon(d) || !hit(d))
            .count() as u16
    }

    /// How far a ray from `origin` along unit `d` is traced: to the first light it reaches.
    /// Inlined into the rays' loops, and a scene with one light (a bare mesh's lamp, most
    /// assets' one lamp) tests its stop without the loop: as a call, the loop cost 4 % of a
    /// bake, and inlined as a loop still 6 % more rays' time than this (docs/benchmarks.md).
    #[inline(always)]
    pub(crate) fn t_max(&self, origin: Vec3, d: Vec3) -> f32 {
        if let [stop] = self.stops {
            return stop.distance(origin, d).unwrap_or(f32::INFINITY);
        }
        self.stops
            .iter()
            .filter_map(|s| s.distance(origin, d))
            .fold(f32::INFINITY, f32::min)
    }

    /// Which pixels of face `f` can matter (`out[p]`, one per pixel).
    ///
    /// A pixel matters when its centre is above the horizon and it can reach a light's stop
    /// (every pixel above the horizon when there are none: the sky's bake):
    /// * a region: the centre's ray meets its box;
    /// * a fixed lamp: the pixel's cone meets the lamp ([`LampStop`]);
    /// * a point or spot light: the pixel's cone meets its sphere ([`SphereStop`]);
    /// * a plane: some direction of the pixel crosses it ahead of the origin. A light without
    ///   a region moves in its plane (docs/bake.md, "Where a ray ends"), so a direction that
    ///   never meets the plane never meets the light: it is "don't care". With k the plane's
    ///   normal turned toward the plane, the corner (u, v) of the face's cone gives
    ///   (w + u a + v b)·k, linear and separable in u and v; the pixel's cone is spanned by its
    ///   corners, so it crosses the plane iff w·k + max over its two u of u a·k + max over its
    ///   two v of v b·k > 0. An origin on the plane keeps every direction.
    ///
    /// Returns `None` when no pixel matters, else how many pixels the light that reaches the
    /// fewest (and some) reaches (`u32::MAX` without stops) ([`FacePixels::light_pixels`]).
    pub(crate) fn face_mask(&self, table: &RayTable, f: usize, out: &mut [bool]) -> Option<u32> {
        let res = table.res as usize;
        let centre = &table.centre[f];
        let fr = FaceFrame::of(f);
        // Pass by pass, without a branch per pixel where the test allows (the horizon, a
        // plane): `out` first holds the pixels above the horizon, `reaches` those of them that
        // reach some stop; each stop's count is of the pixels above the horizon it reaches.
        let n = res * res;
        let mut above = false;
        for (m, &d) in out[..n].iter_mut().zip(centre) {
            *m = d.dot(self.normal) > 0.0;
            above |= *m;
        }
        if !above {
            return None;
        }
        // Per stop, its test: a region's box, or a plane's w·k and, per pixel column and row,
        // the larger corner term.
        let e = |i: usize| 2.0 * i as f32 / res as f32 - 1.0;
        let reach: Vec<Reach> = self
            .stops
            .iter()
            .map(|s| match s {
                LightStop::Region(b) => Reach::Region(*b),
                LightStop::Lamp(l) => {
                    let mut may = vec![false; res * res];
                    l.candidates(self.origin, &fr, res, &mut may);
                    Reach::Lamp(l, may)
                }
                LightStop::Sphere(l) => Reach::Sphere(l),
                &LightStop::Plane { point, normal } => {
                    let side = (point - self.origin).dot(normal);
                    let k = normal * side.signum();
                    let terms = |axis: Vec3| -> Vec<f32> {
                        let g = axis.dot(k);
                        (0..res).map(|i| (e(i) * g).max(e(i + 1) * g)).collect()
                    };
                    // On the plane (or NaN): a constant 1 keeps every pixel.
                    match side.abs() > 0.0 {
                        true => Reach::Plane(fr.w.dot(k), terms(fr.a), terms(fr.b)),
                        false => Reach::Plane(1.0, vec![0.0; res], vec![0.0; res]),
                    }
                }
            })
            .collect();
        if reach.is_empty() {
            return Some(u32::MAX);
        }
        let mut reaches = vec![false; n];
        let mut fewest = u32::MAX;
        for r in &reach {
            let mut count = 0u32;
            match r {
                Reach::Plane(w, u, v) => {
                    for (j, row) in out[..n].chunks_exact(res).enumerate() {
                        let at = &mut reaches[j * res..(j + 1) * res];
                        for ((hit, &above), &ui) in at.iter_mut().zip(row).zip(u) {
                            let h = above & (w + ui + v[j] > 0.0);
                            count += u32::from(h);
                            *hit |= h;
                        }
                    }
                }
                _ => {
                    for (p, (hit, &d)) in reaches.iter_mut().zip(centre).enumerate() {
                        if !out[p] {
                            continue;
                        }
                        let h = match r {
                            Reach::Region(b) => b.hit_by_ray(self.origin, d),
                            Reach::Lamp(l, may) => may[p] && l.distance(self.origin, d).is_some(),
                            Reach::Sphere(l) => l.reaches(self.origin, d),
                            Reach::Plane(w, u, v) => w + u[p % res] + v[p / res] > 0.0,
                        };
                        count += u32::from(h);
                        *hit |= h;
                    }
                }
            }
            if count > 0 {
                fewest = fewest.min(count);
            }
        }
        let mut any = false;
        for (m, &hit) in out[..n].iter_mut().zip(&reaches) {
            *m &= hit;
            any |= *m;
        }
        any.then_some(fewest)
    }

    /// Casts the rays of every pixel that matters; returns per-face pixel sets (`None` for
    /// faces with none) and what it cost.
    ///
    /// Each face is walked as a quadtree of pixel blocks carrying a list of the triangles that
    /// may lie in the block's pyramid ([`FrustumCuller`]): a block with an empty list is
    /// visible without casting; a small block with a short list tests its rays against that
    /// list; otherwise rays traverse the BVH. Every path gives what casting every ray against
    /// the whole mesh gives (the lists are conservative); [`CastMode::Adaptive`] only answers
    /// some occluded rays by a triangle known to block them, which the full cast would find
    /// blocking too.
    pub(crate) fn cast(
        &self,
        occ: &Occluder,
        culler: &FrustumCuller,
        walk: &SurfaceWalk,
        table: &RayTable,
        mode: CastMode,
    ) -> ([Option<FacePixels>; FACES], CastCounts) {
        let origin = self.origin;
        let res = table.res as usize;
        let mut counts = CastCounts::default();
        let mut matters = vec![false; res * res];
        let mut blocker = match mode {
            CastMode::Full => Vec::new(),
            CastMode::Adaptive => vec![NO_BLOCKER; res * res],
        };
        let mut stack = Vec::new();
        let mut faces = std::array::from_fn(|f| {
            let light_pixels = self.face_mask(table, f, &mut matters)?;
            blocker.fill(NO_BLOCKER);
            let mut vis = vec![0u16; res * res];
            let mut walk = BlockWalk {
                rays: self,
                occ,
                culler,
                walk,
                table,
                face: f,
                origin,
                matters: &matters,
                vis: &mut vis,
                stack: &mut stack,
                blocker: &mut blocker,
                last_blocker: NO_BLOCKER,
                counts: CastCounts::default(),
            };
            walk.block(0, 0, res as u32, None);
            counts += walk.counts;
            let mut px = FacePixels {
                light_pixels,
                ..FacePixels::default()
            };
            for (p, &m) in matters.iter().enumerate() {
                if m {
                    px.index.push(p as u32);
                    px.visible.push(vis[p]);
                }
            }
            Some(px)
        });
        let aimed = self.aim(occ, table, &mut faces);
        counts.rays += aimed;
        counts.traversals += aimed;
        (faces, counts)
    }

    /// Every ray of every pixel that matters, against the BVH: the reference for [`Self::cast`].
    pub(crate) fn cast_brute_force(
        &self,
        occ: &Occluder,
        table: &RayTable,
    ) -> [Option<FacePixels>; FACES] {
        let mut matters = vec![false; table.centre[0].len()];
        let mut map = std::array::from_fn(|f| {
            let light_pixels = self.face_mask(table, f, &mut matters)?;
            let mut px = FacePixels {
                light_pixels,
                ..FacePixels::default()
            };
            for p in (0..matters.len()).filter(|&p| matters[p]) {
                px.index.push(p as u32);
                px.visible.push(self.reference_pixel(occ, table, f, p));
            }
            Some(px)
        });
        self.aim(occ, table, &mut map);
        map
    }

    /// The escaping sub-rays of pixel `p` of face `f`, every one cast against the BVH (the
    /// reference every cast must equal; the GPU's unsure pixels are cast again by it).
    pub(crate) fn reference_pixel(
        &self,
        occ: &Occluder,
        table: &RayTable,
        f: usize,
        p: usize,
    ) -> u16 {
        let s = table.samples as usize;
        let origin = self.origin;
        self.escaping(&table.sub[f][p * s..(p + 1) * s], |d| {
            let t_max = self.t_max(origin, d);
            occ.occluded_between(origin, d, self.t_min, t_max, self.vertex)
        })
    }
}

/// Rays aimed at a disk (a point or spot light's sphere, a sun) from one vertex
/// ([`VertexRays::aim_at_disks`]): an n × n grid over its disk's square, n = 4 · tan α · res
/// (four rays a pixel across the disk) within these bounds.
const AIM_GRID: (usize, usize) = (8, 32);

impl VertexRays<'_> {
    /// Every cast's last step: the pixels the point and spot lights' spheres cover, and in the
    /// sky's bake those its suns at rest cover, cast again toward the light itself
    /// ([`Self::aim_at_disks`]). Returns the rays cast.
    pub(crate) fn aim(&self, occ: &Occluder, table: &RayTable, map: &mut CubeMap) -> u64 {
        let spheres = self.stops.iter().filter_map(|stop| {
            let LightStop::Sphere(l) = stop else {
                return None;
            };
            let oc = l.centre - self.origin;
            let d2 = oc.length_squared();
            let r2 = l.radius * l.radius;
            if !(d2 > r2) || !d2.is_finite() {
                return None;
            }
            Some(Disk {
                w: oc / d2.sqrt(),
                tan_a: l.radius / (d2 - r2).sqrt(),
                protect: false,
            })
        });
        let suns = self.suns.iter().map(|s| Disk {
            w: s.toward,
            tan_a: s.tan_half_angle,
            protect: true,
        });
        let disks: Vec<Disk> = spheres.chain(suns).collect();
        if disks.is_empty() {
            return 0;
        }
        self.aim_at_disks(occ, table, map, &disks)
    }

    /// The pixels a light's disk covers, cast again toward the disk itself.
    ///
    /// A bulb is usually smaller than a cube-map pixel (5 cm at 2 m: 0.025 rad against
    /// ≈ 0.03), and the sun's disk is a third of one (0.009 rad), so a pixel's own sub-rays
    /// sample it at the pixel's offsets, not where the light is: from one vertex to the next
    /// its shadow would be cast from points up to half a pixel apart (a dotted shadow edge,
    /// docs/bake.md). Here the disk as the vertex sees it (half-angle α; a sphere's
    /// tan α = r / √(|c − o|² − r²)) is sampled by a grid of rays toward it, each traced as
    /// far as the pixel's own rays are (to the first stop, to infinity without one); each pixel
    /// that matters and holds some of them gets the share of them that escape, as a count out
    /// of the pixel's samples S (rounded half up): the visibility of the part of the light that
    /// lies in the pixel, which is what the shading weighs that pixel's piece of the light by.
    /// Rays below the horizon are left out (the cosine clips them), and a pixel none of them
    /// falls in keeps its own rays. A sun's pixels are also marked [`FacePixels::protected`].
    /// Every cast (culled, adaptive, brute force, GPU) applies this after its own, so all give
    /// one cube map. Returns the rays cast.
    fn aim_at_disks(
        &self,
        occ: &Occluder,
        table: &RayTable,
        map: &mut CubeMap,
        disks: &[Disk],
    ) -> u64 {
        // (face, index in the face's pixels) → (rays that escape, rays, protected).
        let mut tally: std::collections::BTreeMap<(usize, usize), (u32, u32, bool)> =
            Default::default();
        let mut rays = 0;
        for disk in disks {
            let (w, tan_a) = (disk.w, disk.tan_a);
            let (e1, e2) = w.any_orthonormal_pair();
            let n =
                ((4.0 * tan_a * table.res as f32).ceil() as usize).clamp(AIM_GRID.0, AIM_GRID.1);
            let at = |k: usize| (2 * k + 1) as f32 / n as f32 - 1.0;
            for (x, y) in (0..n).flat_map(|y| (0..n).map(move |x| (at(x), at(y)))) {
                if x * x + y * y > 1.0 {
                    continue;
                }
                let d = (w + tan_a * (x * e1 + y * e2)).normalize();
                if self.escapes_below_horizon(d) {
                    continue;
                }
                let Some((f, uv)) = bspvt_proto::cubemap::face_uv(d) else {
                    continue;
                };
                let p = bspvt_proto::cubemap::pixel_index(uv, table.res) as u32;
                let Some(k) = map[f]
                    .as_ref()
                    .and_then(|px| px.index.binary_search(&p).ok())
                else {
                    continue;
                };
                rays += 1;
                let t_max = self.t_max(self.origin, d);
                let blocked = occ.occluded_between(self.origin, d, self.t_min, t_max, self.vertex);
                let e = tally.entry((f, k)).or_default();
                e.0 += u32::from(!blocked);
                e.1 += 1;
                e.2 |= disk.protect;
            }
        }
        let s = table.samples;
        for ((f, k), (seen, all, protect)) in tally {
            if let Some(px) = map[f].as_mut() {
                px.visible[k] = ((2 * seen * s + all) / (2 * all)) as u16;
                if protect {
                    // The tally is ordered by (face, k): each face's protected pixels ascend.
                    px.protected.push(px.index[k]);
                }
            }
        }
        rays
    }
}

/// Candidate lists longer than this are not kept (the block's rays traverse the BVH);
/// kept lists are short enough to test a block's rays against directly.
const MAX_CANDIDATES: usize = 32;
/// Blocks of this size or smaller gather candidate lists; larger ones only test for any.
const COLLECT_BLOCK: u32 = 8;

/// The quadtree walk over one face of one vertex's cube map.
struct BlockWalk<'a> {
    rays: &'a VertexRays<'a>,
    occ: &'a Occluder,
    culler: &'a FrustumCuller,
    walk: &'a SurfaceWalk,
    table: &'a RayTable,
    face: usize,
    origin: Vec3,
    matters: &'a [bool],
    vis: &'a mut [u16],
    stack: &'a mut Vec<[u32; 2]>,
    /// Adaptive cast: per pixel of the face, the occluder primitive that blocked one of its
    /// rays ([`NO_BLOCKER`]: none yet); empty for the full cast.
    blocker: &'a mut [u32],
    /// Adaptive cast: the primitive that blocked the face's last blocked ray.
    last_blocker: u32,
    counts: CastCounts,
}

/// No blocker recorded.
const NO_BLOCKER: u32 = u32::MAX;

impl BlockWalk<'_> {
    fn pixels(&self, i0: u32, j0: u32, size: u32) -> impl Iterator<Item = usize> + use<> {
        let res = self.table.res as usize;
        let (i0, j0, size) = (i0 as usize, j0 as usize, size as usize);
        (j0..j0 + size).flat_map(move |j| (i0..i0 + size).map(move |i| j * res + i))
    }

    fn pyramid(&self, i0: u32, j0: u32, size: u32) -> Pyramid {
        let r = self.table.res as f32;
        let fr = FaceFrame::of(self.face);
        let e = |i: u32| 2.0 * i as f32 / r - 1.0;
        let (u0, u1, v0, v1) = (e(i0), e(i0 + size), e(j0), e(j0 + size));
        let normals = [
            fr.a - u0 * fr.w,
            u1 * fr.w - fr.a,
            fr.b - v0 * fr.w,
            v1 * fr.w - fr.b,
        ];
        Pyramid::new(
            self.origin,
            normals,
            self.rays.normal,
            self.rays.horizon_margin,
        )
    }

    /// `parent`: the parent block's candidate list, when it was kept.
    fn block(&mut self, i0: u32, j0: u32, size: u32, parent: Option<&[u32]>) {
        if !self.pixels(i0, j0, size).any(|p| self.matters[p]) {
            return;
        }
        let pyr = self.pyramid(i0, j0, size);
        let s = self.table.samples as usize;
        let h = size / 2;
        let leaf = size <= MIN_BLOCK || !size.is_multiple_of(2);
        let mut list = Vec::new();
        // Large blocks: only ask whether anything may be inside (stops at the first
        // candidate). Blocks of COLLECT_BLOCK pixels or fewer: gather the candidates.
        let kept = match parent {
            Some(from) => {
                self.culler.filter(&pyr, from, &mut list);
                true
            }
            None if size > COLLECT_BLOCK && !leaf => {
                let empty = self
                    .culler
                    .collect(&pyr, self.rays.vertex, 0, &mut list, self.stack);
                if !empty {
                    for (i, j) in [(i0, j0), (i0 + h, j0), (i0, j0 + h), (i0 + h, j0 + h)] {
                        self.block(i, j, h, None);
                    }
                    return;
                }
                true
            }
            None => self.culler.collect(
                &pyr,
                self.rays.vertex,
                MAX_CANDIDATES,
                &mut list,
                self.stack,
            ),
        };
        if kept && list.is_empty() {
            for p in self.pixels(i0, j0, size) {
                self.vis[p] = s as u16;
            }
            return;
        }
        if !leaf && kept {
            let l = list.as_slice();
            for (i, j) in [(i0, j0), (i0 + h, j0), (i0, j0 + h), (i0 + h, j0 + h)] {
                self.block(i, j, h, Some(l));
            }
            return;
        }
        let f = self.face;
        for p in self.pixels(i0, j0, size) {
            if !self.matters[p] {
                continue;
            }
            self.counts.rays += s as u64;
            let subs = &self.table.sub[f][p * s..(p + 1) * s];
            self.vis[p] = if !self.blocker.is_empty() {
                self.adaptive_pixel(p, subs, kept.then_some(list.as_slice()))
            } else if kept {
                self.rays.escaping(subs, |d| {
                    let t = [self.rays.t_min, self.rays.t_max(self.origin, d)];
                    self.culler.ray_hits_any(self.occ, self.origin, d, t, &list)
                })
            } else {
                let above = subs
                    .iter()
                    .filter(|&&d| !self.rays.escapes_below_horizon(d));
                self.counts.traversals += above.count() as u64;
                self.rays.escaping(subs, |d| {
                    let t_max = self.rays.t_max(self.origin, d);
                    let t_min = self.rays.t_min;
                    self.occ
                        .occluded_between(self.origin, d, t_min, t_max, self.rays.vertex)
                })
            };
        }
    }

    /// Escaping sub-rays of pixel `p` in the adaptive cast: each above-horizon sub-ray first
    /// tries the blockers already known near it (this pixel's, its left and upper neighbours',
    /// the face's last), then, without a list, a walk from a neighbour's blocker, then `list`
    /// (the block's candidates, when kept) or the BVH.
    ///
    /// Same answer as the full cast: a blocker that hits the ray in \[t_min, t_max), well
    /// inside its edges ([`SurfaceWalk::interior`]), is a triangle not using the vertex (the
    /// traversal skips those) inside the block's pyramid, so the conservative candidate list
    /// holds it and the full cast's list test finds a hit too; without a list, the full cast's
    /// traversal reaches its leaf (the hit is inside the leaf's box, not on its face). A ray no
    /// blocker stops is tested exactly as in the full cast.
    fn adaptive_pixel(&mut self, p: usize, subs: &[Vec3], list: Option<&[u32]>) -> u16 {
        let res = self.table.res as usize;
        let mut hints = [NO_BLOCKER; 8];
        let mut n = 0;
        let (i, j) = (p % res, p / res);
        // This pixel, then its left, upper, upper-left and upper-right neighbours (done before
        // it in the walk's Z order, or not at all: then NO_BLOCKER).
        let near = [
            p,
            if i > 0 { p - 1 } else { p },
            if j > 0 { p - res } else { p },
            if i > 0 && j > 0 { p - res - 1 } else { p },
            if i + 1 < res && j > 0 { p - res + 1 } else { p },
        ];
        for b in near.map(|q| self.blocker[q]) {
            if b != NO_BLOCKER && !hints[..n].contains(&b) {
                hints[n] = b;
                n += 1;
            }
        }
        // Walk only from a neighbour's blocker: a ray none of whose neighbours was blocked
        // mostly escapes, and a walk from far away rarely arrives.
        let near_hints = n;
        if self.last_blocker != NO_BLOCKER && !hints[..n].contains(&self.last_blocker) {
            hints[n] = self.last_blocker;
            n += 1;
        }
        let (origin, t_min) = (self.origin, self.rays.t_min);
        let mut escaping = 0u16;
        for &d in subs {
            if self.rays.escapes_below_horizon(d) {
                escaping += 1;
                continue;
            }
            let t_max = self.rays.t_max(origin, d);
            let ray = Ray::new(origin.into(), d.into(), t_min, t_max);
            // The walk starts from the near hint the ray passes closest to.
            let (mut start, mut nearest) = (hints[0], f32::NEG_INFINITY);
            let mut hit = None;
            for (k, &h) in hints[..n].iter().enumerate() {
                let (blocks, near) = self.occ.primitive_blocks_near(h, &ray);
                if blocks && self.walk.interior(h, origin, d) {
                    hit = Some(h);
                    break;
                }
                if k < near_hints && near > nearest {
                    (start, nearest) = (h, near);
                }
            }
            if hit.is_none() && near_hints > 0 && list.is_none() {
                hit = self.walk.find(self.occ, start, &ray, self.rays.vertex);
            }
            if hit.is_none() {
                hit = match list {
                    Some(l) => self.culler.ray_first_hit(self.occ, &ray, l),
                    None => {
                        self.counts.traversals += 1;
                        self.occ.blocker(ray, self.rays.vertex)
                    }
                };
            }
            if let Some(b) = hit
                && n < hints.len()
                && !hints[..n].contains(&b)
            {
                hints[n] = b;
                n += 1;
            }
            match hit {
                Some(b) => {
                    self.blocker[p] = b;
                    self.last_blocker = b;
                }
                None => escaping += 1,
            }
        }
        escaping
    }
}

/// Blocks of this size or smaller are always ray-cast.
const MIN_BLOCK: u32 = 4;

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use proptest::prelude::*;

    /// f64 reference of the plane test: whether some corner of pixel (i, j) of face `f` points
    /// toward the plane (`None` when the answer is within rounding of 0: a tie).
    fn crosses(f: usize, i: usize, j: usize, res: usize, k: DVec3) -> Option<bool> {
        let fr = FaceFrame::of(f);
        let e = |i: usize| 2.0 * i as f64 / res as f64 - 1.0;
        let mut best = f64::NEG_INFINITY;
        for (u, v) in [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)] {
            let c = fr.w.as_dvec3() + e(u) * fr.a.as_dvec3() + e(v) * fr.b.as_dvec3();
            best = best.max(c.dot(k));
        }
        (best.abs() > 1e-5).then_some(best > 0.0)
    }

    proptest! {
        /// A fixed lamp's block bound never drops a pixel whose centre reaches the lamp:
        /// `face_mask` is the same with it as testing every pixel, for any lamp (square, one- or
        /// two-sided, any size and orientation), origin and resolution.
        #[test]
        fn the_lamp_candidates_keep_every_pixel_that_reaches_the_lamp(
            res in 1u32..48,
            o in prop::array::uniform3(-2.0f32..2.0),
            c in prop::array::uniform3(-2.0f32..2.0),
            n in prop::array::uniform3(-1.0f32..1.0),
            half in 0.001f32..1.5,
            two_sided in any::<bool>(),
        ) {
            let normal = Vec3::from(n);
            prop_assume!(normal.length() > 0.1);
            let normal = normal.normalize();
            let t1 = normal.any_orthonormal_vector();
            let t2 = normal.cross(t1);
            let c = Vec3::from(c);
            let corner = |a: f32, b: f32| (c + half * (a * t1 + b * t2)).to_array();
            let light = bspvt_proto::scene::PolygonLight {
                vertices: vec![corner(-1.0, -1.0), corner(1.0, -1.0), corner(1.0, 1.0), corner(-1.0, 1.0)],
                radiance: [1.0; 3],
                two_sided,
                texture: None,
                region: None,
                moves_in_plane: false,
                image: None,
            };
            let lamp = LampStop::new(&light, res).expect("a lamp");
            let table = RayTable::new(res, 1);
            let r = res as usize;
            let origin = Vec3::from(o);
            let mut may = vec![false; r * r];
            for f in 0..FACES {
                lamp.candidates(origin, &FaceFrame::of(f), r, &mut may);
                for (q, &d) in table.centre[f].iter().enumerate() {
                    if lamp.distance(origin, d).is_some() {
                        prop_assert!(may[q], "face {} pixel {} reaches the lamp", f, q);
                    }
                }
            }
        }

        /// `face_mask`'s separable plane test keeps exactly the pixels above the horizon some
        /// corner of which points toward the light's plane, for any plane, origin and normal.
        #[test]
        fn the_plane_test_is_the_corner_test(
            res in 1u32..40,
            o in prop::array::uniform3(-2.0f32..2.0),
            p in prop::array::uniform3(-2.0f32..2.0),
            n in prop::array::uniform3(-1.0f32..1.0),
            vn in prop::array::uniform3(-1.0f32..1.0),
        ) {
            let (normal, vertex_normal) = (Vec3::from(n), Vec3::from(vn));
            prop_assume!(normal.length() > 0.1 && vertex_normal.length() > 0.1);
            let (normal, vertex_normal) = (normal.normalize(), vertex_normal.normalize());
            let (origin, point) = (Vec3::from(o), Vec3::from(p));
            let side = (point - origin).dot(normal);
            prop_assume!(side.abs() > 1e-3);
            let stops = [LightStop::Plane { point, normal }];
            let rays = VertexRays {
                origin,
                normal: vertex_normal,
                vertex: 0,
                t_min: 0.0,
                horizon_margin: 0.0,
                stops: &stops,
                suns: &[],
            };
            let table = RayTable::new(res, 1);
            let r = res as usize;
            let k = normal.as_dvec3() * side.signum() as f64;
            let mut mask = vec![false; r * r];
            for f in 0..FACES {
                rays.face_mask(&table, f, &mut mask);
                for (q, &m) in mask.iter().enumerate() {
                    let above = table.centre[f][q].dot(vertex_normal) > 0.0;
                    if let Some(c) = crosses(f, q % r, q / r, r, k) {
                        prop_assert_eq!(m, above && c, "face {} pixel {}", f, q);
                    }
                }
            }
        }
    }

    /// An origin on the plane keeps every pixel above its horizon; no stops (the sky) too.
    #[test]
    fn on_the_plane_or_without_lights_every_direction_matters() {
        let table = RayTable::new(8, 1);
        let plane = [LightStop::Plane {
            point: Vec3::new(3.0, 1.0, -2.0),
            normal: Vec3::Y,
        }];
        for stops in [&plane[..], &[]] {
            let rays = VertexRays {
                origin: Vec3::new(0.0, 1.0, 0.0),
                normal: Vec3::new(0.6, 0.0, 0.8),
                vertex: 0,
                t_min: 0.0,
                horizon_margin: 0.0,
                stops,
                suns: &[],
            };
            let mut mask = vec![false; 64];
            for f in 0..FACES {
                rays.face_mask(&table, f, &mut mask);
                for (q, &m) in mask.iter().enumerate() {
                    assert_eq!(m, table.centre[f][q].dot(rays.normal) > 0.0, "{f} {q}");
                }
            }
        }
    }
}
