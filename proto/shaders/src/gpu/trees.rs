//! The trees as the shaders read them (`shade.wgsl`): one flat array of node words and six
//! root indices per vertex; the line codec's normal table and half step.

use bspvt_proto::bspvt::{LineCodec, Node, VertexTrees};

/// Root of a face without a tree (visible: `bspvt::ABSENT_FACE_VALUE`).
pub const ABSENT: u32 = u32::MAX;
/// Face 0's root of a vertex whose trees have not arrived (shaded unshadowed).
pub const NO_TREES: u32 = u32::MAX - 1;
/// A leaf's node word: this bit | v̄ (0..255). A split's: angle << 16 | offset.
pub const LEAF: u32 = 0x8000_0000;

/// Appends the node words of one face tree: \[word, right child relative to the tree's root\].
pub fn encode(nodes: &[Node], out: &mut Vec<[u32; 2]>) {
    out.extend(nodes.iter().map(|n| match *n {
        Node::Leaf { value } => [LEAF | u32::from(value), 0],
        Node::Split { line, right } => {
            [u32::from(line.angle) << 16 | u32::from(line.offset), right]
        }
    }));
}

/// Appends the words of a vertex's six face trees to `nodes`, whose first word has index
/// `base` in the shader's node array; returns the six roots (or [`ABSENT`]).
pub fn encode_vertex(trees: &VertexTrees, base: u64, nodes: &mut Vec<[u32; 2]>) -> [u32; 6] {
    let mut roots = [ABSENT; 6];
    for (root, face) in roots.iter_mut().zip(&trees.faces) {
        if let Some(tree) = face {
            *root = u32::try_from(base + nodes.len() as u64).unwrap_or(ABSENT);
            encode(&tree.nodes, nodes);
        }
    }
    roots
}

/// `codec`'s line normals n(θ) (`line_normals` of the shader), f32 as on the CPU.
pub fn line_normals(codec: &LineCodec) -> Vec<[f32; 2]> {
    (0..codec.angles())
        .map(|a| codec.normal(a as u16).to_array())
        .collect()
}

/// (offsets O, half step √2 / O) of `codec` (`counts.z` and `codec.x` of the shader), the
/// half step computed as LineCodec computes it.
pub fn codec_params(codec: &LineCodec) -> (u32, f32) {
    let o = codec.offsets();
    (o, bspvt_proto::bspvt::line::MAX_OFFSET / o as f32)
}
