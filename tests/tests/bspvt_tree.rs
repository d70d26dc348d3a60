//! BSPVT trees on the sphere: splitting convex spherical polygons by the faces of the cube map
//! and by the trees' lines (great circles).
//!
//! Properties checked for random polygons (random planar polygons in random frames from tiny,
//! ~1e-7 sr, to nearly a hemisphere; polygons with vertices exactly on cube-face edges and
//! corners; light quads in front of a random vertex position) against random trees (random
//! [`Node`] arrays with random [`QLine`]s, depth ≤ 12, every leaf kind):
//!
//! - the pieces' solid angles sum to the polygon's (1e-6 relative);
//! - every piece lies in its face's pyramid and on the correct side of every line above a leaf
//!   of the piece's value (tolerance 1e-9 rad on normalised directions);
//! - the point query at the piece's centroid (f64 walk, and the f32 [`VertexTrees::visibility`]
//!   where the centroid is not within 1e-5 of a line) gives the piece's value;
//! - nothing is NaN, and `visible_fraction` is in [0, 1].
//!
//! The checker ([`check_split`]) and the random generator are shared with the fitted-tree
//! variant of the same property in `fit_properties.rs` (see `src/lib.rs`).

use bspvt_proto::bspvt::tree::clip_to_face;
use bspvt_proto::bspvt::{FaceTree, LineCodec, MAX_DEPTH, Node, QLine, VertexTrees, unquantise};
use bspvt_proto::cubemap::{FACES, FaceFrame, face_uv, pixel_centres};
use bspvt_proto::sphere::{self, solid_angle};
use bspvt_tests::{QUERY_MARGIN, Rng, SplitReport, check_split, node_depths, random_value, walk64};
use glam::{DVec2, DVec3, Vec2};
use proptest::prelude::*;

// ---------------------------------------------------------------------------------------------
// Random generation (the seeded SplitMix64 `Rng` of the lib, so a failing proptest seed
// reproduces).
// ---------------------------------------------------------------------------------------------

/// A random line; offsets mostly inside the face (|c| ≤ 1.1), sometimes anywhere.
fn random_line(rng: &mut Rng, codec: &LineCodec) -> QLine {
    let angle = rng.below(codec.angles() as u64) as u16;
    let o = codec.offsets() as u64;
    let offset = if rng.chance(0.8) {
        let lo = (o as f64 * (1.0 - 1.1 / std::f64::consts::SQRT_2) / 2.0) as u64;
        (lo + rng.below(o - 2 * lo)) as u16
    } else {
        rng.below(o) as u16
    };
    QLine { angle, offset }
}

/// A random pre-order tree of depth ≤ `max_depth`. With `anchors` (face points inside the
/// polygon to be split), most lines pass through one of them, so the polygon is really cut.
fn random_tree_near(
    rng: &mut Rng,
    codec: &LineCodec,
    max_depth: usize,
    anchors: &[Vec2],
) -> FaceTree {
    fn go(
        rng: &mut Rng,
        codec: &LineCodec,
        depth: usize,
        max_depth: usize,
        anchors: &[Vec2],
        nodes: &mut Vec<Node>,
    ) {
        let p_leaf = if depth == 0 { 0.1 } else { 0.3 };
        if depth >= max_depth || rng.chance(p_leaf) {
            nodes.push(Node::Leaf {
                value: random_value(rng),
            });
            return;
        }
        let mut line = random_line(rng, codec);
        if !anchors.is_empty() && rng.chance(0.7) {
            // The quantised offset nearest to n·p: c(o) = (2o + 1 − O)·h.
            let p = anchors[rng.below(anchors.len() as u64) as usize];
            let n = codec.normal(line.angle);
            let o = codec.offsets() as f64;
            let h = bspvt_proto::bspvt::line::MAX_OFFSET as f64 / o;
            let t = (n.x * p.x + n.y * p.y) as f64;
            line.offset = ((t / h + o - 1.0) * 0.5).round().clamp(0.0, o - 1.0) as u16;
        }
        let at = nodes.len();
        nodes.push(Node::Split { line, right: 0 });
        go(rng, codec, depth + 1, max_depth, anchors, nodes);
        let right = nodes.len() as u32;
        nodes[at] = Node::Split { line, right };
        go(rng, codec, depth + 1, max_depth, anchors, nodes);
    }
    let mut nodes = Vec::new();
    go(rng, codec, 0, max_depth, anchors, &mut nodes);
    FaceTree { nodes }
}

fn random_tree(rng: &mut Rng, codec: &LineCodec, max_depth: usize) -> FaceTree {
    random_tree_near(rng, codec, max_depth, &[])
}

/// Random trees for the six faces (some absent); with `poly`, lines mostly cut through it.
fn random_vertex_trees_for(
    rng: &mut Rng,
    codec: &LineCodec,
    poly: Option<&[DVec3]>,
) -> VertexTrees {
    let mut trees = VertexTrees::default();
    for f in 0..FACES {
        if rng.chance(0.85) {
            let depth = rng.below(13) as usize;
            let frame = FaceFrame::of(f);
            let (w, a, b) = (frame.w64(), frame.a64(), frame.b64());
            let mut anchors = Vec::new();
            if let Some(c) = poly.and_then(|p| clip_to_face(p, &frame)) {
                for _ in 0..16 {
                    let d: DVec3 = c.iter().map(|v| v.normalize() * rng.f64()).sum();
                    let dw = d.dot(w);
                    if dw > 0.0 {
                        anchors.push(Vec2::new((d.dot(a) / dw) as f32, (d.dot(b) / dw) as f32));
                    }
                }
            }
            trees.faces[f] = Some(random_tree_near(rng, codec, depth, &anchors));
        }
    }
    trees
}

fn random_vertex_trees(rng: &mut Rng, codec: &LineCodec) -> VertexTrees {
    random_vertex_trees_for(rng, codec, None)
}

fn random_codec(rng: &mut Rng) -> LineCodec {
    LineCodec::for_resolution([8, 16, 32, 64][rng.below(4) as usize])
}

fn frame_from(w: DVec3) -> (DVec3, DVec3, DVec3) {
    let w = w.normalize();
    let a = w.any_orthonormal_vector();
    (w, a, w.cross(a))
}

/// Convex hull (counter-clockwise, no collinear points) of 2-D points; monotone chain.
fn hull(mut p: Vec<DVec2>) -> Vec<DVec2> {
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let mut h: Vec<DVec2> = Vec::new();
    for pass in 0..2 {
        let start = h.len();
        let iter: Box<dyn Iterator<Item = &DVec2>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while h.len() >= start + 2 && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
                h.pop();
            }
            h.push(q);
        }
        h.pop();
    }
    h
}

/// A convex planar polygon on the plane `w + x·a + y·b`, seen from the origin: a convex
/// spherical polygon. Points on an ellipse (circle → random affine map), radius 10^U(−3.5, 3):
/// from ~1e-7 sr to nearly a hemisphere.
fn random_frame_polygon(rng: &mut Rng) -> Vec<DVec3> {
    let (w, a, b) = frame_from(rng.unit());
    let n = 3 + rng.below(6) as usize;
    let r = 10f64.powf(rng.range(-3.5, 3.0));
    let mut angles: Vec<f64> = (0..n)
        .map(|_| rng.range(0.0, std::f64::consts::TAU))
        .collect();
    angles.sort_by(f64::total_cmp);
    let (sx, sy, k) = (
        rng.range(0.3, 1.0),
        rng.range(0.3, 1.0),
        rng.range(-0.5, 0.5),
    );
    let (ox, oy) = (rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
    angles
        .iter()
        .map(|t| {
            let (x, y) = (r * t.cos(), r * t.sin());
            let (x, y) = (sx * x + k * y + ox, sy * y + oy);
            w + x * a + y * b
        })
        .collect()
}

/// A convex polygon in a cube face's own (u, v) coordinates with vertices mostly on the lattice
/// {−2, −1.5, …, 2}²: vertices exactly on face edges (u or v = ±1) and corners ((±1, ±1), the
/// cube's corner directions), edges exactly along face edges; directions are exact in f64.
fn random_lattice_polygon(rng: &mut Rng) -> Vec<DVec3> {
    let f = FaceFrame::of(rng.below(6) as usize);
    let (w, a, b) = (f.w64(), f.a64(), f.b64());
    loop {
        let k = 3 + rng.below(4) as usize;
        let pts: Vec<DVec2> = (0..k)
            .map(|_| {
                let mut c = || {
                    if rng.chance(0.75) {
                        (rng.below(9) as f64 - 4.0) * 0.5
                    } else {
                        rng.range(-2.0, 2.0)
                    }
                };
                DVec2::new(c(), c())
            })
            .collect();
        let h = hull(pts);
        if h.len() >= 3 {
            return h.iter().map(|p| w + p.x * a + p.y * b).collect();
        }
    }
}

/// A light polygon (3–8 vertices, planar, convex) in front of a random vertex position; the
/// directions from the vertex to the light's vertices.
fn random_light_polygon(rng: &mut Rng) -> Vec<DVec3> {
    let p = DVec3::new(
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
    );
    let dist = 10f64.powf(rng.range(-1.5, 1.0));
    let centre = p + rng.unit() * dist;
    let (_, e1, e2) = frame_from(rng.unit());
    let (h1, h2) = (
        dist * 10f64.powf(rng.range(-3.0, 0.3)),
        dist * 10f64.powf(rng.range(-3.0, 0.3)),
    );
    let n = if rng.chance(0.5) {
        4
    } else {
        3 + rng.below(6) as usize
    };
    let phase = rng.range(0.0, 1.0);
    (0..n)
        .map(|i| {
            let t = std::f64::consts::TAU * (i as f64 + phase) / n as f64;
            centre + e1 * (h1 * t.cos()) + e2 * (h2 * t.sin()) - p
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Figures over all cases (the checker itself is `check_split` in the lib).
// ---------------------------------------------------------------------------------------------

#[derive(Default)]
struct Totals {
    cases: usize,
    pieces: usize,
    zero_area: usize,
    checked: usize,
    skipped: usize,
    worst_rel: f64,
    min_sr: f64,
    max_sr: f64,
}

impl Totals {
    fn add(&mut self, r: &SplitReport, sr: f64) {
        if self.cases == 0 {
            self.min_sr = f64::INFINITY;
        }
        self.cases += 1;
        self.pieces += r.pieces;
        self.zero_area += r.zero_area_pieces;
        self.checked += r.query_checked;
        self.skipped += r.query_skipped;
        self.worst_rel = self.worst_rel.max(r.rel_sum_error);
        self.min_sr = self.min_sr.min(sr);
        self.max_sr = self.max_sr.max(sr);
    }
    fn merge(&mut self, o: &Totals) {
        if o.cases == 0 {
            return;
        }
        if self.cases == 0 {
            self.min_sr = f64::INFINITY;
        }
        self.cases += o.cases;
        self.pieces += o.pieces;
        self.zero_area += o.zero_area;
        self.checked += o.checked;
        self.skipped += o.skipped;
        self.worst_rel = self.worst_rel.max(o.worst_rel);
        self.min_sr = self.min_sr.min(o.min_sr);
        self.max_sr = self.max_sr.max(o.max_sr);
    }
    fn print(&self, what: &str) {
        eprintln!(
            "{what}: {} cases, {} pieces ({} of zero area), polygons {:.3e}..{:.3} sr, worst relative \
             sum error {:.2e}, centroid queries checked {} / skipped (within {QUERY_MARGIN:e} of a line) {}",
            self.cases,
            self.pieces,
            self.zero_area,
            self.min_sr,
            self.max_sr,
            self.worst_rel,
            self.checked,
            self.skipped
        );
    }
}

/// Totals per property over all proptest cases of this process, printed as they grow.
static TOTALS: std::sync::Mutex<Vec<(&'static str, Totals)>> = std::sync::Mutex::new(Vec::new());

const PROPTEST_CASES: u32 = 128;

fn run_property(seed: u64, cases: usize, what: &'static str, gen_poly: fn(&mut Rng) -> Vec<DVec3>) {
    let mut rng = Rng(seed);
    let mut totals = Totals::default();
    for case in 0..cases {
        let codec = random_codec(&mut rng);
        let poly = gen_poly(&mut rng);
        let near = rng.chance(0.7);
        let trees = random_vertex_trees_for(&mut rng, &codec, near.then_some(&poly[..]));
        match check_split(&trees, &codec, &poly) {
            Ok(rep) => totals.add(&rep, solid_angle(&poly)),
            Err(e) => panic!(
                "{what}, seed {seed:#x}, case {case}: {e}\npolygon {poly:?}\ncodec bits {} / {}\ntrees {trees:?}",
                codec.angle_bits, codec.offset_bits
            ),
        }
    }
    let mut all = TOTALS.lock().unwrap_or_else(|e| e.into_inner());
    let i = match all.iter().position(|(w, _)| *w == what) {
        Some(i) => i,
        None => {
            all.push((what, Totals::default()));
            all.len() - 1
        }
    };
    all[i].1.merge(&totals);
    if all[i]
        .1
        .cases
        .is_multiple_of(PROPTEST_CASES as usize * cases)
    {
        all[i].1.print(what);
    }
}

// ---------------------------------------------------------------------------------------------
// Properties.
// ---------------------------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig::with_cases(PROPTEST_CASES))]

    // Each proptest case runs 100 random (trees, polygon) pairs from its seed.
    #[test]
    fn split_random_frame_polygons(seed in any::<u64>()) {
        run_property(seed, 100, "random-frame polygons", random_frame_polygon);
    }

    #[test]
    fn split_polygons_on_face_edges_and_corners(seed in any::<u64>()) {
        run_property(seed, 100, "lattice polygons (face edges/corners)", random_lattice_polygon);
    }

    #[test]
    fn split_light_polygons_from_a_vertex(seed in any::<u64>()) {
        run_property(seed, 100, "light polygons", random_light_polygon);
    }
}

/// Hand-picked polygons that sit exactly on the cube's structure, against a few trees.
#[test]
fn split_exact_face_structures() {
    let f = FaceFrame::of(0);
    let (w, a, b) = (f.w64(), f.a64(), f.b64());
    let at = |u: f64, v: f64| w + u * a + v * b;
    let cases: Vec<(&str, Vec<DVec3>)> = vec![
        (
            "whole +X face",
            vec![at(-1., -1.), at(1., -1.), at(1., 1.), at(-1., 1.)],
        ),
        (
            "quarter face at a corner",
            vec![at(0., 0.), at(1., 0.), at(1., 1.), at(0., 1.)],
        ),
        (
            "triangle at a cube corner",
            vec![
                DVec3::new(1., 1., 1.),
                DVec3::new(1., 0., 0.5),
                DVec3::new(0.5, 1., 0.),
            ],
        ),
        (
            "corner-centred triangle",
            vec![
                DVec3::new(1., 1., 0.2),
                DVec3::new(0.2, 1., 1.),
                DVec3::new(1., 0.2, 1.),
            ],
        ),
        (
            "straddles an edge",
            vec![at(0.5, -0.5), at(2., -0.5), at(2., 0.5), at(0.5, 0.5)],
        ),
        ("octant", vec![DVec3::X, DVec3::Y, DVec3::Z]),
        (
            "nearly a hemisphere",
            vec![at(-1e4, -1e4), at(1e4, -1e4), at(1e4, 1e4), at(-1e4, 1e4)],
        ),
        (
            "tiny",
            vec![at(0.3, 0.3), at(0.3 + 1e-3, 0.3), at(0.3, 0.3 + 1e-3)],
        ),
    ];
    let mut rng = Rng(7);
    for (name, poly) in &cases {
        let mut totals = Totals::default();
        for _ in 0..200 {
            let codec = random_codec(&mut rng);
            let trees = random_vertex_trees(&mut rng, &codec);
            match check_split(&trees, &codec, poly) {
                Ok(rep) => totals.add(&rep, solid_angle(poly)),
                Err(e) => panic!("{name}: {e}\ntrees {trees:?}"),
            }
        }
        totals.print(name);
    }
    // The octant is exactly π/2 and, with no trees, all visible.
    let none = VertexTrees::default();
    let codec = LineCodec::for_resolution(16);
    let oct = [DVec3::X, DVec3::Y, DVec3::Z];
    let pieces = none.pieces(&codec, &oct);
    let s: f64 = pieces.iter().map(|p| solid_angle(&p.verts)).sum();
    assert!(
        (s - std::f64::consts::FRAC_PI_2).abs() < 1e-12,
        "octant pieces sum to {s}"
    );
    assert_eq!(none.visible_fraction(&codec, &oct), 1.0);
}

/// Uniform trees: the visible fraction is the leaf value for any polygon, and the pieces cover
/// each face exactly (the six faces of a cube partition the sphere).
#[test]
fn uniform_trees_and_face_partition() {
    let codec = LineCodec::for_resolution(32);
    let mut rng = Rng(11);
    for _ in 0..300 {
        let v = random_value(&mut rng);
        let trees = VertexTrees {
            faces: std::array::from_fn(|_| Some(FaceTree::leaf(v))),
        };
        let poly = random_frame_polygon(&mut rng);
        let vf = trees.visible_fraction(&codec, &poly);
        assert!(
            (vf - unquantise(v) as f64).abs() < 1e-6,
            "value {v}: fraction {vf}"
        );
    }
    // Clipping a random polygon to all six faces loses and duplicates nothing.
    for _ in 0..300 {
        let poly = random_light_polygon(&mut rng);
        let total = solid_angle(&poly);
        let s: f64 = (0..FACES)
            .filter_map(|f| clip_to_face(&poly, &FaceFrame::of(f)))
            .map(|p| solid_angle(&p))
            .sum();
        assert!(
            (s - total).abs() <= 1e-9 * total,
            "faces sum to {s}, polygon {total}"
        );
    }
}

/// `leaf_index` and `query` agree with the f64 plane test for every pixel centre of a random
/// tree, away from the lines (where f32 and f64 rounding may legitimately differ).
#[test]
fn point_query_matches_the_planes() {
    let mut rng = Rng(13);
    let mut checked = 0usize;
    for _ in 0..200 {
        let res = [8u32, 16, 32, 64][rng.below(4) as usize];
        let codec = LineCodec::for_resolution(res);
        let tree = random_tree(&mut rng, &codec, 12);
        let face = rng.below(6) as usize;
        let frame = FaceFrame::of(face);
        for uv in pixel_centres(res) {
            let d = frame.direction(uv).as_dvec3().normalize();
            let (v64, margin) = walk64(&tree, &codec, &frame, d);
            let i = tree.leaf_index(&codec, uv);
            let Node::Leaf { value } = tree.nodes[i] else {
                panic!("leaf_index returned split node {i}");
            };
            assert_eq!(tree.query(&codec, uv), value);
            let (g, back) = face_uv(frame.direction(uv)).expect("finite direction");
            assert_eq!(g, face);
            assert!((back - uv).length() < 1e-6);
            if margin > 1e-5 {
                assert_eq!(v64, value, "pixel {uv}: f64 walk {v64}, leaf_index {value}");
                checked += 1;
            }
        }
    }
    assert!(checked > 100_000, "{checked}");
    eprintln!("point queries: {checked} pixel centres agree with the f64 planes");
}

/// Generated trees are valid pre-order arrays within the decoder's depth limit (a guard on the
/// generator this file relies on).
#[test]
fn generated_trees_are_well_formed() {
    let mut rng = Rng(17);
    for case in 0..200 {
        let codec = random_codec(&mut rng);
        let t = random_tree(&mut rng, &codec, 12);
        let depths = node_depths(&t.nodes).unwrap_or_else(|e| panic!("tree {case}: {e}"));
        let deepest = depths.iter().copied().max().unwrap_or(0);
        assert!(deepest <= MAX_DEPTH, "tree {case}: depth {deepest}");
    }
    // Splitting by a single line through the face centre halves the face.
    let codec = LineCodec::for_resolution(64);
    let line = QLine {
        angle: 0,
        offset: (codec.offsets() / 2) as u16,
    };
    let tree = FaceTree {
        nodes: vec![
            Node::Split { line, right: 2 },
            Node::Leaf { value: 0 },
            Node::Leaf { value: 255 },
        ],
    };
    let frame = FaceFrame::of(2);
    let face = [(-1., -1.), (1., -1.), (1., 1.), (-1., 1.)]
        .map(|(u, v)| frame.direction(Vec2::new(u, v)).as_dvec3());
    let mut parts = Vec::new();
    tree.split_polygon(&codec, &frame, &face, &mut |p, v| {
        parts.push((sphere::solid_angle(p), v))
    });
    assert_eq!(parts.len(), 2);
    let c = codec.offset(line.offset) as f64;
    // The line is u = c (c = half a step right of 0): the right part is u ≥ c.
    let whole = 4.0 * std::f64::consts::PI / 6.0;
    let right = parts.iter().find(|p| p.1 == 255).expect("right piece").0;
    let left = parts.iter().find(|p| p.1 == 0).expect("left piece").0;
    assert!((left + right - whole).abs() < 1e-12, "{left} + {right}");
    assert!(
        right < left && (left - right) < 4.0 * c,
        "left {left}, right {right}, c {c}"
    );
}
