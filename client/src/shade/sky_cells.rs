//! The sky's world-fixed cells (`crate::sky_cells`) at one vertex, split into what the
//! trees and the normal fix (once per vertex) and what the view changes (once per camera):
//!
//! ```text
//! L_o = albedo ⊙ Σ_c D_c L_c  +  spec ⊙ Σ_c ρ_c S_c L_c
//! D_c = Σᵢ v̄ᵢ ∫_{Ωᵢ} cos θ/π   (the cell's tree pieces, eq. 2 of paper 000)
//! ρ_c = D_c / ∫_{c ∩ H(n)} cos θ/π,     S_c = ∫_{c ∩ H(n)} D_ltc
//! ```
//!
//! The diffuse term is exact for a cell of constant radiance; the specular one takes the
//! cell's visible fraction (cosine-weighted) times the LTC integral of the whole cell — within a
//! cell of ~15° the lobe is not weighted by where the cell is shadowed. L_c is the only thing
//! a turning map changes: a frame is two dot products per vertex.

use arrayvec::ArrayVec;
use bspvt_proto::bspvt::{LineCodec, VertexTrees};
use bspvt_proto::sphere::{self, SphPoly};
use glam::{DMat3, DVec3};

use crate::ltc::polygon::{edge, integrate};

/// A cell's corners (unit directions): four, or three at a pole.
pub(crate) type CellPoly = ArrayVec<DVec3, 4>;

/// One cell above a vertex's horizon.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CellTerm {
    /// Cell index.
    pub(crate) cell: u16,
    /// D_c: Σ v̄ ∫ cos/π over the cell's visible pieces.
    pub(crate) diffuse: f32,
    /// ρ_c: D_c over the cell's unshadowed ∫ cos/π (1 without trees).
    pub(crate) visible: f32,
}

/// The cells above the horizon of `n` with anything visible: D_c and ρ_c through `trees`
/// (`None`: unshadowed), into `out`. `to_local`: world → the vertex's frame (z = n). Returns
/// the tree pieces integrated and dropped (v̄ = 0).
pub(crate) fn cell_terms(
    cells: &[CellPoly],
    n: DVec3,
    to_local: &DMat3,
    trees: Option<(&VertexTrees, &LineCodec)>,
    out: &mut Vec<CellTerm>,
) -> (u32, u32) {
    out.clear();
    let (mut pieces, mut dropped) = (0, 0);
    let mut dirs = SphPoly::new();
    for (c, poly) in cells.iter().enumerate() {
        if !sphere::clip_into(poly, n, &mut dirs) {
            continue;
        }
        let whole = integrate(to_local, &dirs);
        if !(whole > 0.0) {
            continue;
        }
        let d = match trees {
            None => whole,
            Some((t, codec)) => {
                let mut d = 0.0;
                t.split_polygon(codec, &dirs, &mut |poly, value, _face| {
                    if value == 0 {
                        dropped += 1;
                        return;
                    }
                    pieces += 1;
                    // v̄ = value / 255 in f64, as for a lamp (shade::bspvt).
                    d += f64::from(value) / 255.0 * integrate(to_local, poly);
                });
                d
            }
        };
        if d > 0.0 {
            out.push(CellTerm {
                cell: c as u16,
                diffuse: d as f32,
                visible: (d / whole).min(1.0) as f32,
            });
        }
    }
    (pieces, dropped)
}

/// The cells as a grid: corners and edges shared between neighbours, so that a vertex
/// integrates each edge of the cells it sees once (the integral is a sum over the polygon's
/// edges, [`crate::ltc::polygon`]: an edge shared by two cells enters them with opposite signs).
#[derive(Clone, Debug)]
pub(crate) struct CellGrid {
    /// Each cell's corners.
    pub(crate) polys: Vec<CellPoly>,
    corners: Vec<DVec3>,
    /// Per cell: its corner ids, and its edges as (edge id, traversed backwards).
    cell_corners: Vec<ArrayVec<u32, 4>>,
    cell_edges: Vec<ArrayVec<(u32, bool), 4>>,
    /// Edge id → its two corner ids, (lower, higher).
    edges: Vec<[u32; 2]>,
}

impl CellGrid {
    /// The grid of cells given by corner ids into `corners`, all wound the same way.
    pub(crate) fn new(corners: Vec<DVec3>, cells: Vec<ArrayVec<u32, 4>>) -> CellGrid {
        let mut ids = std::collections::HashMap::new();
        let mut edges = Vec::new();
        let cell_edges = cells
            .iter()
            .map(|c| {
                (0..c.len())
                    .map(|i| {
                        let (a, b) = (c[i], c[(i + 1) % c.len()]);
                        let key = [a.min(b), a.max(b)];
                        let id = *ids.entry(key).or_insert_with(|| {
                            edges.push(key);
                            edges.len() as u32 - 1
                        });
                        (id, a > b)
                    })
                    .collect()
            })
            .collect();
        let polys = cells
            .iter()
            .map(|c| c.iter().map(|&i| corners[i as usize]).collect())
            .collect();
        CellGrid {
            polys,
            corners,
            cell_corners: cells,
            cell_edges,
            edges,
        }
    }
}

/// ρ_c S_c for each of `terms` (the view's part): `to_ltc` maps world directions into the
/// specular LTC's cosine space; `n` the normal the terms were made for. A cell wholly above
/// both horizons (the normal's, and z = 0 in the LTC's space) is the sum of its edges, each
/// computed once per vertex; the others are clipped and integrated alone
/// ([`integrate`]): the same integral either way, to rounding.
pub(crate) fn specular_weights(
    grid: &CellGrid,
    n: DVec3,
    to_ltc: &DMat3,
    terms: &[CellTerm],
    out: &mut Vec<f32>,
) {
    out.clear();
    out.reserve_exact(terms.len());
    let mut local = vec![None; grid.corners.len()];
    let mut edge_value = vec![f64::NAN; grid.edges.len()];
    let mut dirs = SphPoly::new();
    for t in terms {
        let c = usize::from(t.cell);
        let mut above = true;
        for &k in &grid.cell_corners[c] {
            let k = k as usize;
            let p = *local[k].get_or_insert_with(|| {
                let w = grid.corners[k];
                (n.dot(w), *to_ltc * w)
            });
            above &= p.0 > 0.0 && p.1.z > 0.0;
        }
        let s = if above {
            let mut sum = 0.0;
            for &(e, backwards) in &grid.cell_edges[c] {
                let v = &mut edge_value[e as usize];
                if v.is_nan() {
                    let [a, b] = grid.edges[e as usize];
                    let at = |k: u32| local[k as usize].map_or(DVec3::ZERO, |p| p.1);
                    *v = edge(at(a), at(b));
                }
                sum += if backwards { -*v } else { *v };
            }
            let s = sum.abs() / (2.0 * std::f64::consts::PI);
            if s.is_finite() { s.min(1.0) } else { 0.0 }
        } else if sphere::clip_into(&grid.polys[c], n, &mut dirs) {
            integrate(to_ltc, &dirs)
        } else {
            0.0
        };
        out.push((f64::from(t.visible) * s) as f32);
    }
}

/// Σ_c D_c L_c and Σ_c w_c L_c (`weights` from [`specular_weights`]) for cell radiances `l`.
#[inline]
pub(crate) fn gather(terms: &[CellTerm], weights: &[f32], l: &[DVec3]) -> (DVec3, DVec3) {
    let (mut d, mut s) = (DVec3::ZERO, DVec3::ZERO);
    for (t, &w) in terms.iter().zip(weights) {
        let lc = l[usize::from(t.cell)];
        d += lc * f64::from(t.diffuse);
        s += lc * f64::from(w);
    }
    (d, s)
}
