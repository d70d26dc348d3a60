//! The renderer's side of a stream: the trees that have arrived, and which vertices have them.

use bspvt_proto::api::SceneStatus;
use bspvt_proto::bspvt::{LineCodec, VertexTrees};
use bspvt_proto::encoding::BakeHeader;

use super::fetch::Update;
use crate::render::renderer::Trees;

/// Trees received so far. Vertices without trees are shaded unshadowed until theirs arrive.
#[derive(Default)]
pub struct StreamedTrees {
    pub(crate) header: Option<BakeHeader>,
    codec: Option<LineCodec>,
    trees: Vec<VertexTrees>,
    present: Vec<bool>,
    /// Vertices whose trees have arrived.
    pub vertices_present: usize,
    /// The bake's last reported status.
    pub status: Option<SceneStatus>,
    pub(crate) done: bool,
    /// Why the fetcher gave up, if it did (what arrived stays usable).
    pub failed: Option<String>,
}

impl StreamedTrees {
    /// Applies one update; returns whether the trees changed.
    pub fn apply(&mut self, u: Update) -> bool {
        match u {
            Update::Header(h) => {
                let n = h.vertex_count as usize;
                self.codec = Some(h.codec());
                self.header = Some(h);
                self.trees = vec![VertexTrees::default(); n];
                self.present = vec![false; n];
                self.vertices_present = 0;
                true
            }
            Update::Chunk { chunk, .. } => {
                let first = chunk.first_vertex as usize;
                for (i, t) in chunk.trees.into_iter().enumerate() {
                    let v = first + i;
                    if v < self.trees.len() {
                        self.trees[v] = t;
                        if !self.present[v] {
                            self.present[v] = true;
                            self.vertices_present += 1;
                        }
                    }
                }
                true
            }
            Update::Status(s) => {
                self.status = Some(*s);
                false
            }
            Update::Done => {
                self.done = true;
                false
            }
            Update::Failed(e) => {
                self.failed = Some(e);
                false
            }
        }
    }

    /// Vertices of the baked mesh (0 before the header arrives).
    pub fn vertex_count(&self) -> usize {
        self.trees.len()
    }

    /// Every vertex has its trees.
    pub fn complete(&self) -> bool {
        !self.trees.is_empty() && self.vertices_present == self.trees.len()
    }

    /// The trees for the renderer (`None` before the header).
    pub(crate) fn view(&self) -> Option<Trees<'_>> {
        Some(Trees {
            trees: &self.trees,
            codec: self.codec.clone()?,
            present: (!self.complete()).then_some(&self.present[..]),
        })
    }

    /// The share of vertices whose trees have arrived, in [0, 1].
    pub fn fraction(&self) -> f64 {
        if self.trees.is_empty() {
            0.0
        } else {
            self.vertices_present as f64 / self.trees.len() as f64
        }
    }
}

impl StreamedTrees {
    /// Whether every vertex in `vertices` has its trees.
    pub fn has_all(&self, vertices: &[u32]) -> bool {
        !self.present.is_empty()
            && vertices
                .iter()
                .all(|&v| self.present.get(v as usize).copied().unwrap_or(false))
    }
}
