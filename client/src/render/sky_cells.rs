//! Per-vertex frames of the sky in world-fixed cells ([`crate::sky_cells`]): each vertex's
//! cell terms are cut by its trees once and kept, their specular weights once per camera, so
//! a frame of a turning map is two dot products per vertex ([`crate::shade::sky_cells`]).

use glam::DVec3;
use rayon::prelude::*;

use super::renderer::{FrameCounts, Renderer, Trees};
use crate::frame::image::Image;
use crate::shade::Shaded;
use crate::shade::sky_cells::{CellTerm, cell_terms, gather, specular_weights};
use crate::sky_cells::SkyCells;

/// What the vertices' cell terms were made with; kept between frames by the caller.
#[derive(Debug, Default)]
pub struct CellTransfer {
    /// The trees (slice address and length) and the cells' bands the terms belong to.
    made_for: Option<(usize, usize, usize)>,
    vertices: Vec<Option<VertexCells>>,
}

#[derive(Debug)]
struct VertexCells {
    /// Cut by the vertex's trees (else unshadowed: redone when they arrive).
    with_trees: bool,
    /// Made for the vertex's back ([`Renderer::seen_from_behind`]: redone when the camera
    /// crosses to its other side).
    behind: bool,
    /// [`Renderer::shading_key`] of `weights`.
    view: u64,
    terms: Vec<CellTerm>,
    weights: Vec<f32>,
}

impl CellTransfer {
    /// Vertices whose terms are kept.
    pub fn vertices_kept(&self) -> usize {
        self.vertices.iter().filter(|v| v.is_some()).count()
    }

    /// Bytes held: the terms and weights kept (by capacity) and the per-vertex slots.
    pub fn bytes(&self) -> usize {
        let slots = self.vertices.capacity() * std::mem::size_of::<Option<VertexCells>>();
        let kept: usize = self
            .vertices
            .iter()
            .flatten()
            .map(|v| {
                v.terms.capacity() * std::mem::size_of::<CellTerm>()
                    + v.weights.capacity() * std::mem::size_of::<f32>()
            })
            .sum();
        slots + kept
    }
}

impl Renderer<'_> {
    /// One per-vertex frame of the sky in `cells` with radiances `radiance`
    /// ([`SkyCells::radiance`]) through `trees` (vertices without theirs unshadowed), reusing
    /// and updating `keep`. The counts' pieces are the tree pieces cut this frame (none once
    /// every visible vertex is kept).
    pub fn sky_cells(
        &self,
        cells: &SkyCells,
        radiance: &[DVec3],
        trees: Option<&Trees>,
        keep: &mut CellTransfer,
    ) -> (Image, FrameCounts) {
        let n = self.scene.mesh.vertex_count();
        let made_for = Some((
            trees.map_or(0, |t| t.trees.as_ptr() as usize),
            trees.map_or(0, |t| t.trees.len()),
            cells.bands(),
        ));
        if keep.made_for != made_for || keep.vertices.len() != n {
            keep.made_for = made_for;
            keep.vertices = (0..n).map(|_| None).collect();
        }
        let mut visible = vec![false; n];
        for &v in &self.visible_vertices {
            visible[v as usize] = true;
        }
        let view = self.shading_key();
        let shaded: Vec<(usize, [f32; 3], u32, u32)> = keep
            .vertices
            .par_iter_mut()
            .enumerate()
            .filter(|(v, _)| visible[*v])
            .map(|(v, slot)| {
                let (lobes, _, nrm) = self.vertex_lobes(v as u32);
                let t = trees.and_then(|t| Some((self.vertex_trees(t, v as u32)?, &t.codec)));
                let has = t.is_some();
                let behind = self.seen_from_behind(v as u32);
                let (mut pieces, mut dropped) = (0, 0);
                if slot
                    .as_ref()
                    .is_none_or(|e| e.with_trees != has || e.behind != behind)
                {
                    let mut terms = Vec::new();
                    (pieces, dropped) =
                        cell_terms(&cells.grid().polys, nrm, &lobes.to_local, t, &mut terms);
                    terms.shrink_to_fit();
                    *slot = Some(VertexCells {
                        with_trees: has,
                        behind,
                        view: !view,
                        terms,
                        weights: Vec::new(),
                    });
                }
                let Some(e) = slot.as_mut() else {
                    return (v, [0.0; 3], pieces, dropped);
                };
                if e.view != view || e.weights.len() != e.terms.len() {
                    specular_weights(cells.grid(), nrm, &lobes.to_ltc, &e.terms, &mut e.weights);
                    e.view = view;
                }
                let (d, s) = gather(&e.terms, &e.weights, radiance);
                let c = lobes.radiance(
                    DVec3::ONE,
                    &Shaded {
                        diffuse_rgb: d,
                        specular_rgb: s,
                        ..Shaded::default()
                    },
                );
                (v, c.as_vec3().to_array(), pieces, dropped)
            })
            .collect();
        let mut colour = vec![[0.0; 3]; n];
        let mut counts = FrameCounts {
            vertices_shaded: shaded.len(),
            ..FrameCounts::default()
        };
        for (v, c, pieces, dropped) in shaded {
            colour[v] = c;
            counts.pieces += u64::from(pieces);
            counts.pieces_dropped += u64::from(dropped);
        }
        (self.interpolate(&colour), counts)
    }
}
