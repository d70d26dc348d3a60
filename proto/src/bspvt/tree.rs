//! The per-face tree, the per-vertex set of six, point queries and polygon splitting.

use glam::{DVec3, Vec2, Vec3};

use super::line::{LineCodec, QLine};
use super::{ABSENT_FACE_VALUE, unquantise};
use crate::cubemap::{FACES, FaceFrame, face_uv};
use crate::sphere::{self, Sides, SphPoly};

/// A tree node. Nodes are stored in pre-order: the left child of a split at index `i` is
/// `i + 1`, its right child is at `right`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Node {
    /// A leaf [paper000 §3.2].
    Leaf {
        /// The mean visibility v̄ of the leaf's pixels, quantised ([`super::quantise`]).
        value: u8,
    },
    /// An internal node: pixels with n·p − c < 0 go left (the next node), the rest right.
    Split {
        /// The split line.
        line: QLine,
        /// Index of the right child.
        right: u32,
    },
}

/// A BSPVT over one cube face [paper000 §3.2].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FaceTree {
    /// The nodes in pre-order (the root first).
    pub nodes: Vec<Node>,
}

/// A piece of a split polygon: its directions, the leaf's visibility and the face it is on.
#[derive(Clone, Debug)]
pub struct Piece {
    /// The piece's corners: unit directions, a convex spherical polygon.
    pub verts: SphPoly,
    /// The leaf's quantised mean visibility v̄ [paper000 §3.2].
    pub value: u8,
    /// The cube face the piece lies on.
    pub face: usize,
}

impl FaceTree {
    /// A tree of one leaf with value `value`.
    pub fn leaf(value: u8) -> FaceTree {
        FaceTree {
            nodes: vec![Node::Leaf { value }],
        }
    }

    /// The value of a single-leaf tree.
    pub(crate) fn uniform_value(&self) -> Option<u8> {
        match self.nodes.as_slice() {
            [Node::Leaf { value }] => Some(*value),
            _ => None,
        }
    }

    /// Number of leaves.
    pub fn leaf_count(&self) -> usize {
        self.nodes
            .iter()
            .filter(|n| matches!(n, Node::Leaf { .. }))
            .count()
    }

    /// Index of the leaf node containing face point `p`.
    pub fn leaf_index(&self, codec: &LineCodec, p: Vec2) -> usize {
        let mut i = 0;
        loop {
            match self.nodes[i] {
                Node::Leaf { .. } => return i,
                Node::Split { line, right } => {
                    i = if codec.side(line, p) {
                        right as usize
                    } else {
                        i + 1
                    };
                }
            }
        }
    }

    /// Quantised visibility at face point `p`.
    pub fn query(&self, codec: &LineCodec, p: Vec2) -> u8 {
        match self.nodes[self.leaf_index(codec, p)] {
            Node::Leaf { value } => value,
            Node::Split { .. } => unreachable!("leaf_index returns a leaf"),
        }
    }

    /// Cuts the spherical polygon `poly` (already inside this face's pyramid) by the tree's lines,
    /// calling `visit(piece, leaf value)` for every non-empty piece [paper000 §3.3]. Each line is a
    /// plane through the origin ([`LineCodec::plane`]), so every cut is an exact great circle.
    pub fn split_polygon(
        &self,
        codec: &LineCodec,
        frame: &FaceFrame,
        poly: &[DVec3],
        visit: &mut impl FnMut(&[DVec3], u8),
    ) {
        self.split_from(0, codec, frame, poly, visit);
    }

    fn split_from(
        &self,
        mut i: usize,
        codec: &LineCodec,
        frame: &FaceFrame,
        poly: &[DVec3],
        visit: &mut impl FnMut(&[DVec3], u8),
    ) {
        loop {
            match self.nodes[i] {
                Node::Leaf { value } => {
                    visit(poly, value);
                    return;
                }
                Node::Split { line, right } => {
                    let n = codec.plane(line, frame);
                    // Most lines miss a small light: walk on without copying anything.
                    match sphere::sides(poly, n) {
                        Sides::None => return,
                        Sides::Negative => i += 1,
                        Sides::Positive => i = right as usize,
                        Sides::Both => {
                            let (mut left, mut rest) = (SphPoly::new(), SphPoly::new());
                            sphere::cut_into(poly, n, &mut left, &mut rest);
                            if !left.is_empty() {
                                self.split_from(i + 1, codec, frame, &left, visit);
                            }
                            if !rest.is_empty() {
                                self.split_from(right as usize, codec, frame, &rest, visit);
                            }
                            return;
                        }
                    }
                }
            }
        }
    }
}

/// The six face trees of one vertex. `None`: no pixel of that face matters for the scene.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct VertexTrees {
    /// One tree per cube face, in [`crate::cubemap`] face order.
    pub faces: [Option<FaceTree>; FACES],
}

impl VertexTrees {
    /// Leaves in all faces.
    pub fn leaf_count(&self) -> usize {
        self.faces.iter().flatten().map(FaceTree::leaf_count).sum()
    }

    /// Visibility in [0, 1] in world direction `dir`.
    pub fn visibility(&self, codec: &LineCodec, dir: Vec3) -> f32 {
        match face_uv(dir) {
            Some((f, uv)) => unquantise(match &self.faces[f] {
                Some(t) => t.query(codec, uv),
                None => ABSENT_FACE_VALUE,
            }),
            None => 1.0,
        }
    }

    /// Splits a convex spherical polygon (world directions from the vertex) into pieces, each
    /// inside one face's pyramid and one leaf of that face's tree [paper000 §3.3, fig. 5].
    pub fn split_polygon(
        &self,
        codec: &LineCodec,
        poly: &[DVec3],
        visit: &mut impl FnMut(&[DVec3], u8, usize),
    ) {
        for f in 0..FACES {
            let frame = FaceFrame::of(f);
            let Some(inside) = clip_to_face(poly, &frame) else {
                continue;
            };
            match &self.faces[f] {
                Some(tree) => {
                    tree.split_polygon(codec, &frame, &inside, &mut |p, v| visit(p, v, f))
                }
                None => visit(&inside, ABSENT_FACE_VALUE, f),
            }
        }
    }

    /// The pieces of [`Self::split_polygon`], collected.
    pub fn pieces(&self, codec: &LineCodec, poly: &[DVec3]) -> Vec<Piece> {
        let mut out = Vec::new();
        self.split_polygon(codec, poly, &mut |p, value, face| {
            out.push(Piece {
                verts: p.iter().copied().collect(),
                value,
                face,
            })
        });
        out
    }

    /// Visible fraction of the solid angle of `poly`: Σ v̄ᵢ Ωᵢ / Ω ([paper000 §3.1 eq. 2]
    /// with f_r = 1).
    pub fn visible_fraction(&self, codec: &LineCodec, poly: &[DVec3]) -> f64 {
        let mut num = 0.0;
        let mut den = 0.0;
        self.split_polygon(codec, poly, &mut |p, v, _| {
            let o = sphere::solid_angle(p);
            num += unquantise(v) as f64 * o;
            den += o;
        });
        if den > 0.0 { num / den } else { 0.0 }
    }
}

/// The part of `poly` inside face `frame`'s pyramid (|d·a| ≤ d·w, |d·b| ≤ d·w).
pub fn clip_to_face(poly: &[DVec3], frame: &FaceFrame) -> Option<SphPoly> {
    let (w, a, b) = (frame.w64(), frame.a64(), frame.b64());
    let planes = [w - a, w + a, w - b, w + b];
    // Most polygons miss most faces: reject on the polygon as given, before any copy (a
    // polygon outside one of the planes stays outside it however the others clip it).
    if planes
        .iter()
        .any(|&n| matches!(sphere::sides(poly, n), Sides::None | Sides::Negative))
    {
        return None;
    }
    let (mut cur, mut next) = (SphPoly::new(), SphPoly::new());
    cur.extend(poly.iter().copied().take(sphere::MAX_VERTS));
    for n in planes {
        match sphere::sides(&cur, n) {
            Sides::Positive => continue,
            Sides::None | Sides::Negative => return None,
            Sides::Both => {
                if !sphere::clip_into(&cur, n, &mut next) {
                    return None;
                }
                std::mem::swap(&mut cur, &mut next);
            }
        }
    }
    Some(cur)
}
