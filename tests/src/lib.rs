//! Shared helpers for the tests: a seeded random generator, random leaf values, random
//! visibility cube maps, and a checker for the split of a spherical polygon by a vertex's
//! trees; [`service`], the one harness of every test that runs the baking service; and
//! [`browser`], the tools of the browser tests.

#![warn(unreachable_pub, missing_docs)]

pub mod browser;
pub mod fuzz;
pub mod service;

use bspvt_bake::cubemap::subpixel_offsets;
use bspvt_proto::bspvt::{
    ABSENT_FACE_VALUE, FaceTree, LineCodec, Node, QLine, VertexTrees, unquantise,
};
use bspvt_proto::cubemap::FaceFrame;
use bspvt_proto::sphere::solid_angle;
use glam::{DVec3, Vec2};

// ---------------------------------------------------------------------------------------------
// Random numbers.
// ---------------------------------------------------------------------------------------------

/// SplitMix64: tiny, seedable, good enough for test inputs (a failing seed reproduces).
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.f64()
    }
    /// Uniform in 0..n (n ≥ 1).
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        self.f64() < p
    }
    /// Uniform on the unit sphere.
    pub fn unit(&mut self) -> DVec3 {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, std::f64::consts::TAU);
        let r = (1.0 - z * z).max(0.0).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// A random leaf value: fully hidden or fully visible half the time, anything otherwise.
pub fn random_value(rng: &mut Rng) -> u8 {
    match rng.below(4) {
        0 => 0,
        1 => 255,
        _ => rng.below(256) as u8,
    }
}

// ---------------------------------------------------------------------------------------------
// Random cube-map faces.
// ---------------------------------------------------------------------------------------------

/// What a random face looks like, for messages.
#[derive(Clone, Debug)]
pub struct FaceSpec {
    /// Face resolution (pixels a side).
    pub res: u32,
    /// Supersampling per side (`s² ` rays per pixel).
    pub s: u32,
    /// The visibility pattern drawn.
    pub pattern: &'static str,
    /// Which pixels matter.
    pub subset: &'static str,
}

/// One random cube-map face: the pixels that matter (`index`, increasing) and their escape
/// counts `visible` in 0..=s². Patterns: half-planes, convex occluders (2–4 half-planes),
/// discs (inside or outside visible), thresholded noise blobs, stripes, independent random
/// fractions, uniform values. Subsets: every pixel, a random mask, a half-plane of the face,
/// a disc, a single pixel.
pub fn random_face(rng: &mut Rng, res: u32, s: u32) -> (Vec<u32>, Vec<u16>, FaceSpec) {
    let samples = s * s;
    type Shape = Box<dyn Fn(Vec2) -> bool>;
    let half_plane = |rng: &mut Rng| -> (Vec2, f32) {
        let t = rng.range(0.0, std::f64::consts::TAU);
        (
            Vec2::new(t.cos() as f32, t.sin() as f32),
            rng.range(-1.0, 1.0) as f32,
        )
    };
    let (pattern, shape, random_k): (&'static str, Option<Shape>, Option<u16>) = match rng.below(8)
    {
        0 => {
            let (n, c) = half_plane(rng);
            (
                "half-plane",
                Some(Box::new(move |p: Vec2| n.dot(p) >= c)),
                None,
            )
        }
        1 => {
            let k = 2 + rng.below(3) as usize;
            let planes: Vec<(Vec2, f32)> = (0..k)
                .map(|_| {
                    let (n, _) = half_plane(rng);
                    (n, rng.range(-0.8, 0.2) as f32)
                })
                .collect();
            let centre = Vec2::new(rng.range(-0.6, 0.6) as f32, rng.range(-0.6, 0.6) as f32);
            // Occluded inside the convex region around `centre`.
            (
                "convex occluder",
                Some(Box::new(move |p: Vec2| {
                    planes.iter().any(|(n, c)| n.dot(p - centre) < *c)
                })),
                None,
            )
        }
        2 => {
            let k = 1 + rng.below(3) as usize;
            let discs: Vec<(Vec2, f32)> = (0..k)
                .map(|_| {
                    (
                        Vec2::new(rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32),
                        rng.range(0.05, 0.8) as f32,
                    )
                })
                .collect();
            let inside = rng.chance(0.5);
            (
                "discs",
                Some(Box::new(move |p: Vec2| {
                    discs.iter().any(|(c, r)| (p - *c).length() < *r) == inside
                })),
                None,
            )
        }
        3 => {
            let k = 2 + rng.below(5) as usize;
            let bumps: Vec<(Vec2, f32, f32)> = (0..k)
                .map(|_| {
                    (
                        Vec2::new(rng.range(-1.2, 1.2) as f32, rng.range(-1.2, 1.2) as f32),
                        rng.range(0.1, 0.5) as f32,
                        rng.range(-1.0, 1.0) as f32,
                    )
                })
                .collect();
            let threshold = rng.range(-0.3, 0.3) as f32;
            (
                "noise blobs",
                Some(Box::new(move |p: Vec2| {
                    bumps
                        .iter()
                        .map(|(c, r, a)| a * (-(p - *c).length_squared() / (r * r)).exp())
                        .sum::<f32>()
                        >= threshold
                })),
                None,
            )
        }
        4 => {
            let (n, _) = half_plane(rng);
            let period = rng.range(0.1, 0.7) as f32;
            (
                "stripes",
                Some(Box::new(move |p: Vec2| {
                    (n.dot(p) / period).rem_euclid(1.0) < 0.5
                })),
                None,
            )
        }
        5 => ("random fractions", None, None),
        _ => {
            let k = match rng.below(3) {
                0 => 0,
                1 => samples,
                _ => rng.below(samples as u64 + 1) as u32,
            };
            ("uniform", None, Some(k as u16))
        }
    };
    let subset_kind = rng.below(6);
    let (sn, sc) = half_plane(rng);
    let (dc, dr) = (
        Vec2::new(rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32),
        rng.range(0.2, 1.2) as f32,
    );
    let p_mask = rng.range(0.1, 0.9);
    let single = rng.below((res * res) as u64) as u32;
    let subset: &'static str = match subset_kind {
        0 | 1 => "all",
        2 => "random mask",
        3 => "half-plane",
        4 => "disc",
        _ => "single pixel",
    };
    let uv = bspvt_proto::cubemap::pixel_centres(res);
    // The bake's own sub-pixel ray layout, so a face's counts are what the bake would give.
    let offsets = subpixel_offsets(res, s);
    let mut index = Vec::new();
    let mut visible = Vec::new();
    for (i, &p) in uv.iter().enumerate() {
        let matters = match subset_kind {
            0 | 1 => true,
            2 => rng.chance(p_mask),
            3 => sn.dot(p) >= sc,
            4 => (p - dc).length() < dr,
            _ => i as u32 == single,
        };
        if !matters {
            continue;
        }
        let k = if let Some(k) = random_k {
            k
        } else if let Some(f) = &shape {
            offsets.iter().filter(|&&o| f(p + o)).count() as u16
        } else {
            rng.below(samples as u64 + 1) as u16
        };
        index.push(i as u32);
        visible.push(k);
    }
    if index.is_empty() {
        index.push(single);
        visible.push(random_k.unwrap_or(0));
    }
    (
        index,
        visible,
        FaceSpec {
            res,
            s,
            pattern,
            subset,
        },
    )
}

// ---------------------------------------------------------------------------------------------
// Polygon split checker.
// ---------------------------------------------------------------------------------------------

/// Angular tolerance for "on the correct side" (normalised directions, normalised planes).
pub const SIDE_TOL: f64 = 1e-9;
/// Centroids closer than this (radians) to a line or a face edge skip the f32 query check.
pub const QUERY_MARGIN: f64 = 1e-5;

/// Figures of one split.
#[derive(Clone, Copy, Debug, Default)]
pub struct SplitReport {
    /// Pieces the split produced.
    pub pieces: usize,
    /// Pieces of (numerically) zero solid angle.
    pub zero_area_pieces: usize,
    /// Pieces whose leaf value was checked by a point query.
    pub query_checked: usize,
    /// Pieces too close to a line or face edge to check (see [`QUERY_MARGIN`]).
    pub query_skipped: usize,
    /// |Σ piece solid angles − polygon solid angle| / polygon solid angle.
    pub rel_sum_error: f64,
}

fn unit_plane(codec: &LineCodec, line: QLine, frame: &FaceFrame) -> DVec3 {
    codec.plane(line, frame).normalize()
}

/// Leaves that could hold the piece `verts` (unit directions): every vertex on the correct
/// side (within [`SIDE_TOL`]) of every line above the leaf; a piece along a line follows both
/// children. Also returns the lines straddled on the way (for messages).
pub fn containing_leaves(
    tree: &FaceTree,
    codec: &LineCodec,
    frame: &FaceFrame,
    verts: &[DVec3],
) -> (Vec<(usize, u8)>, Vec<String>) {
    let mut out = Vec::new();
    let mut straddled = Vec::new();
    let mut stack = vec![0usize];
    while let Some(i) = stack.pop() {
        match tree.nodes[i] {
            Node::Leaf { value } => out.push((i, value)),
            Node::Split { line, right } => {
                let n = unit_plane(codec, line, frame);
                let (lo, hi) =
                    verts
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| {
                            let x = n.dot(*d);
                            (lo.min(x), hi.max(x))
                        });
                let right_ok = lo >= -SIDE_TOL;
                let left_ok = hi <= SIDE_TOL;
                if !right_ok && !left_ok {
                    straddled.push(format!("node {i} ({line:?}): n·d in [{lo:e}, {hi:e}]"));
                }
                if right_ok {
                    stack.push(right as usize);
                }
                if left_ok {
                    stack.push(i + 1);
                }
            }
        }
    }
    (out, straddled)
}

/// f64 walk for direction `d`: the leaf value and the smallest angular distance to a line on
/// the path.
pub fn walk64(tree: &FaceTree, codec: &LineCodec, frame: &FaceFrame, d: DVec3) -> (u8, f64) {
    let mut i = 0;
    let mut margin = f64::INFINITY;
    loop {
        match tree.nodes[i] {
            Node::Leaf { value } => return (value, margin),
            Node::Split { line, right } => {
                let x = unit_plane(codec, line, frame).dot(d);
                margin = margin.min(x.abs());
                i = if x >= 0.0 { right as usize } else { i + 1 };
            }
        }
    }
}

/// Splits `poly` by `trees` and checks: finite pieces of ≥ 3 vertices; solid angles summing to
/// the polygon's (1e-6 relative); every piece inside its face's pyramid and inside a leaf of its
/// value; the centroid query (f64 walk, and the f32 [`VertexTrees::visibility`] away from
/// lines) giving the piece's value; `visible_fraction` finite in [0, 1].
pub fn check_split(
    trees: &VertexTrees,
    codec: &LineCodec,
    poly: &[DVec3],
) -> Result<SplitReport, String> {
    let mut rep = SplitReport::default();
    let total = solid_angle(poly);
    if !total.is_finite() || total <= 0.0 {
        return Err(format!("input polygon has solid angle {total}"));
    }
    let pieces = trees.pieces(codec, poly);
    let mut sum = 0.0;
    for (k, piece) in pieces.iter().enumerate() {
        rep.pieces += 1;
        let ctx = || {
            format!(
                "piece {k} (face {}, value {}, {:?})",
                piece.face, piece.value, piece.verts
            )
        };
        if piece.verts.len() < 3 {
            return Err(format!("{}: fewer than 3 vertices", ctx()));
        }
        if piece
            .verts
            .iter()
            .any(|d| !d.is_finite() || d.length() == 0.0)
        {
            return Err(format!("{}: non-finite or zero vertex", ctx()));
        }
        let om = solid_angle(&piece.verts);
        if !om.is_finite() {
            return Err(format!("{}: solid angle {om}", ctx()));
        }
        sum += om;
        if om == 0.0 {
            rep.zero_area_pieces += 1;
        }
        let frame = FaceFrame::of(piece.face);
        let (w, a, b) = (frame.w64(), frame.a64(), frame.b64());
        let unit: Vec<DVec3> = piece.verts.iter().map(|d| d.normalize()).collect();
        let face_planes = [w - a, w + a, w - b, w + b].map(|n| n.normalize());
        for d in &unit {
            for n in &face_planes {
                if n.dot(*d) < -SIDE_TOL {
                    return Err(format!(
                        "{}: vertex {d} outside its face (n·d = {:e})",
                        ctx(),
                        n.dot(*d)
                    ));
                }
            }
        }
        match &trees.faces[piece.face] {
            None if piece.value != ABSENT_FACE_VALUE => {
                return Err(format!("{}: absent face gave value {}", ctx(), piece.value));
            }
            None => {}
            Some(tree) => {
                let (leaves, straddled) = containing_leaves(tree, codec, &frame, &unit);
                if !leaves.iter().any(|&(_, v)| v == piece.value) {
                    return Err(format!(
                        "{}: lies in no leaf of its value; candidates {leaves:?}, straddled {straddled:?}",
                        ctx()
                    ));
                }
            }
        }
        let c = unit.iter().copied().sum::<DVec3>().normalize();
        let face_margin = face_planes
            .iter()
            .map(|n| n.dot(c))
            .fold(f64::INFINITY, f64::min);
        let (v64, line_margin) = match &trees.faces[piece.face] {
            Some(tree) => walk64(tree, codec, &frame, c),
            None => (ABSENT_FACE_VALUE, f64::INFINITY),
        };
        if om > 0.0 && line_margin > 1e-12 && face_margin > 1e-12 && v64 != piece.value {
            return Err(format!(
                "{}: f64 walk at the centroid gives {v64} (margin {line_margin:e})",
                ctx()
            ));
        }
        if line_margin > QUERY_MARGIN && face_margin > QUERY_MARGIN {
            rep.query_checked += 1;
            let q = trees.visibility(codec, c.as_vec3());
            if q != unquantise(piece.value) {
                return Err(format!(
                    "{}: f32 query at the centroid {c} gives {q}",
                    ctx()
                ));
            }
        } else {
            rep.query_skipped += 1;
        }
    }
    rep.rel_sum_error = (sum - total).abs() / total;
    if rep.rel_sum_error > 1e-6 {
        return Err(format!(
            "pieces sum to {sum:e} sr, polygon is {total:e} sr (relative error {:e}); {} pieces",
            rep.rel_sum_error,
            pieces.len()
        ));
    }
    let vf = trees.visible_fraction(codec, poly);
    if !(vf.is_finite() && (0.0..=1.0 + 1e-12).contains(&vf)) {
        return Err(format!("visible_fraction = {vf}"));
    }
    Ok(rep)
}

/// Pre-order structure check: every split's `right` is where its left subtree ends; returns the
/// depth of every node, or a message.
pub fn node_depths(nodes: &[Node]) -> Result<Vec<usize>, String> {
    fn go(nodes: &[Node], i: usize, depth: usize, out: &mut [usize]) -> Result<usize, String> {
        let Some(node) = nodes.get(i) else {
            return Err(format!("node {i} is past the end ({} nodes)", nodes.len()));
        };
        out[i] = depth;
        match *node {
            Node::Leaf { .. } => Ok(i + 1),
            Node::Split { right, .. } => {
                let end_left = go(nodes, i + 1, depth + 1, out)?;
                if right as usize != end_left {
                    return Err(format!(
                        "split {i}: right = {right}, left subtree ends at {end_left}"
                    ));
                }
                go(nodes, end_left, depth + 1, out)
            }
        }
    }
    let mut depths = vec![0; nodes.len()];
    let end = go(nodes, 0, 0, &mut depths)?;
    if end != nodes.len() {
        return Err(format!("tree ends at {end} of {} nodes", nodes.len()));
    }
    Ok(depths)
}
