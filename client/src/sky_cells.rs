//! The sky as world-fixed cells, for a map that turns (issue 37 item 3).
//!
//! [`crate::sky`] cuts the *map* into pieces; turning the map moves them, so every vertex
//! must cut every piece by its trees again each frame (≈ 1 µs per tree piece). Here the
//! *sphere of world directions* is cut instead, into B equal-area latitude bands (uniform in
//! y) × 2B sectors (uniform in azimuth φ); a cell is the spherical polygon through its four
//! corners (a pole cell: three), so neighbours share their great-circle edges and the cells
//! tile the sphere exactly. The cells do not move, so what the trees let a vertex see of each
//! cell is computed once ([`crate::shade::sky_cells`]); turning the map by θ about +y only
//! changes each cell's radiance: the world direction of azimuth φ sees the map at φ + θ, so
//! a cell's mean over its band is a difference of two prefix sums along the map's rows,
//! shifted by θ — O(1) per cell and frame, and exact for the piecewise-constant map over the
//! cell's band × sector (a row enters a band by the overlap of their ranges of y).
//!
//! The price is the radiance's resolution: a cell gives one mean where a piece gave a
//! filtered texture, so a map with a sun (a piece [`crate::sky::SkyPieces`] splits for its
//! power) keeps the pieces ([`SkyCells::suits`]).

use std::f64::consts::PI;

use anyhow::{Result, bail};
use glam::DVec3;

use crate::envmap::EnvLight;
use crate::shade::sky_cells::CellGrid;
use arrayvec::ArrayVec;

/// Default latitude bands (2·B² cells; chosen by measured error: docs/benchmarks.md, "The sky
/// in cells").
pub const DEFAULT_BANDS: u32 = 12;
/// Most bands accepted (the cell index is stored in 16 bits).
pub const MAX_BANDS: u32 = 128;

/// The world-fixed cells of the sky and the map's radiance prefix sums per band (see the
/// module doc).
#[derive(Clone, Debug)]
pub struct SkyCells {
    bands: usize,
    sectors: usize,
    grid: CellGrid,
    /// Per band: Σ over the band's rows of (texel solid angle × radiance), prefix-summed
    /// along x: `prefix[b][x]` = Σ_{x' < x}; W + 1 entries.
    prefix: Vec<Vec<DVec3>>,
    /// Per band: the solid angle of one column of its rows.
    column_omega: Vec<f64>,
    width: usize,
    strength: f64,
}

impl SkyCells {
    /// The cells of `bands` latitude bands for `env` scaled by `strength`.
    pub fn new(env: &EnvLight, bands: u32, strength: f64) -> Result<SkyCells> {
        if !(2..=MAX_BANDS).contains(&bands) {
            bail!("sky cell bands must be in 2..={MAX_BANDS}, not {bands}");
        }
        if !(strength.is_finite() && strength >= 0.0) {
            bail!("the environment strength must be finite and ≥ 0, not {strength}");
        }
        let (b, s) = (bands as usize, 2 * bands as usize);
        let y_of = |i: usize| 1.0 - 2.0 * i as f64 / b as f64;
        let at = |phi: f64, y: f64| {
            let r = (1.0 - y * y).max(0.0).sqrt();
            DVec3::new(r * phi.cos(), y, r * phi.sin())
        };
        // Corner ids: the north pole 0, then latitude line i ∈ 1..b sector j at 1 + (i−1)·s + j
        // (j wraps: φ = π is φ = −π), then the south pole.
        let mut corners = vec![DVec3::Y];
        for i in 1..b {
            for j in 0..s {
                corners.push(at(-PI + 2.0 * PI * j as f64 / s as f64, y_of(i)));
            }
        }
        corners.push(DVec3::NEG_Y);
        let south = corners.len() as u32 - 1;
        let id = |i: usize, j: usize| match i {
            0 => 0,
            i if i == b => south,
            i => (1 + (i - 1) * s + j % s) as u32,
        };
        let mut cells = Vec::with_capacity(b * s);
        for band in 0..b {
            for sector in 0..s {
                let mut c = ArrayVec::<u32, 4>::new();
                c.push(id(band, sector));
                if band > 0 {
                    c.push(id(band, sector + 1));
                }
                c.push(id(band + 1, sector + 1));
                if band + 1 < b {
                    c.push(id(band + 1, sector));
                }
                cells.push(c);
            }
        }
        let grid = CellGrid::new(corners, cells);
        let (w, h) = (env.width as usize, env.height as usize);
        let mut prefix = vec![vec![DVec3::ZERO; w + 1]; b];
        let mut column_omega = vec![0.0; b];
        let mut row_sum = vec![DVec3::ZERO; w + 1];
        // Row y covers z = cos θ ∈ [cos(π(y+1)/H), cos(πy/H)], a column of it 2π/W in φ; its
        // part in band b is the overlap of the two z ranges (solid angle = Δz · Δφ), so the
        // bands hold exactly the piecewise-constant map's integral.
        for y in 0..h {
            let z_top = (PI * y as f64 / h as f64).cos();
            let z_bottom = (PI * (y + 1) as f64 / h as f64).cos();
            let mut row_done = false;
            for band in 0..b {
                let overlap = z_top.min(y_of(band)) - z_bottom.max(y_of(band + 1));
                if overlap <= 0.0 {
                    continue;
                }
                let omega = overlap * 2.0 * PI / w as f64;
                column_omega[band] += omega;
                if !row_done {
                    for x in 0..w {
                        let p = env.pixels[y * w + x];
                        let l = DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
                        row_sum[x + 1] = row_sum[x] + l;
                    }
                    row_done = true;
                }
                for (acc, r) in prefix[band].iter_mut().zip(&row_sum) {
                    *acc += *r * omega;
                }
            }
        }
        Ok(SkyCells {
            bands: b,
            sectors: s,
            grid,
            prefix,
            column_omega,
            width: w,
            strength,
        })
    }

    /// Whether the cells can stand for the pieces of `pieces`' map: not when the pieces had
    /// to split a piece for its power (a sun), whose sharp shadow one cell's mean would blur.
    pub fn suits(pieces: &crate::sky::SkyPieces) -> bool {
        !pieces.has_sun
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.grid.polys.len()
    }

    /// True when there are no cells (never: at least 2).
    pub fn is_empty(&self) -> bool {
        self.grid.polys.is_empty()
    }

    /// Latitude bands.
    pub fn bands(&self) -> usize {
        self.bands
    }

    /// The cells' corners and edges.
    pub(crate) fn grid(&self) -> &CellGrid {
        &self.grid
    }

    /// Every cell's mean radiance for the map turned by `rotation_deg` about +y (as
    /// [`crate::sky::SkyPieces::posed`] turns the pieces), scaled by the strength.
    pub fn radiance(&self, rotation_deg: f64) -> Vec<DVec3> {
        let w = self.width as f64;
        let theta = rotation_deg.to_radians();
        let mut out = Vec::with_capacity(self.len());
        for (band, prefix) in self.prefix.iter().enumerate() {
            // F(t) = Σ over columns [0, t) of the band, continued periodically.
            let total = prefix[self.width];
            let f = |t: f64| {
                let wraps = (t / w).floor();
                let r = t - wraps * w;
                let k = (r as usize).min(self.width - 1);
                let frac = r - k as f64;
                total * wraps + prefix[k] + (prefix[k + 1] - prefix[k]) * frac
            };
            let span = w / self.sectors as f64;
            let omega = self.column_omega[band] * span;
            for sector in 0..self.sectors {
                let phi0 = -PI + 2.0 * PI * sector as f64 / self.sectors as f64;
                // u = φ/(2π) + ½ of the map's azimuth φ + θ.
                let x0 = ((phi0 + theta) / (2.0 * PI) + 0.5) * w;
                let l = if omega > 0.0 {
                    (f(x0 + span) - f(x0)) / omega
                } else {
                    DVec3::ZERO
                };
                out.push(l * self.strength);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DMat3;

    #[test]
    fn cells_tile_the_sphere() {
        for bands in [2, 3, 5, 12] {
            let c = SkyCells::new(&EnvLight::constant([1.0; 3]), bands, 1.0).expect("cells");
            assert_eq!(c.len(), 2 * (bands * bands) as usize);
            let total: f64 = (0..c.len())
                .map(|i| bspvt_proto::sphere::solid_angle(&c.grid().polys[i]))
                .sum();
            assert!((total - 4.0 * PI).abs() < 1e-9, "{bands} bands: {total}");
        }
        assert!(SkyCells::new(&EnvLight::constant([1.0; 3]), 1, 1.0).is_err());
        // A map coarser than the bands still lights every band.
        let c = SkyCells::new(&EnvLight::constant([1.0; 3]), 12, 1.0).expect("cells");
        for l in c.radiance(17.0) {
            assert!((l - DVec3::ONE).abs().max_element() < 1e-12, "{l}");
        }
        assert!(SkyCells::new(&EnvLight::constant([1.0; 3]), 4, f64::NAN).is_err());
    }

    /// A cell's radiance is the mean of the turned map over the cell: against a brute-force
    /// mean of `eval(R⁻¹ d)` over directions uniform in the cell's band and sector, with R the
    /// turn [`crate::sky::SkyPieces::posed`] applies.
    #[test]
    fn a_cell_holds_the_turned_maps_mean() {
        let dir = tempfile::tempdir().expect("temp dir");
        let env = EnvLight::load(&crate::envmap::write_test_map(dir.path())).expect("map");
        let bands = 6;
        let cells = SkyCells::new(&env, bands, 2.0).expect("cells");
        for deg in [0.0, 37.0, -123.5, 400.0] {
            let l = cells.radiance(deg);
            let r_inv = glam::DMat3::from_rotation_y(-f64::to_radians(deg));
            let (b, s) = (bands as usize, 2 * bands as usize);
            let (mut worst, mut scale) = (0.0f64, 0.0f64);
            for band in 0..b {
                for sector in 0..s {
                    let n = 192;
                    let mut sum = DVec3::ZERO;
                    for i in 0..n {
                        for j in 0..n {
                            let y =
                                1.0 - 2.0 * (band as f64 + (i as f64 + 0.5) / n as f64) / b as f64;
                            let phi = -PI
                                + 2.0 * PI * (sector as f64 + (j as f64 + 0.5) / n as f64)
                                    / s as f64;
                            let r = (1.0 - y * y).sqrt();
                            let d = DVec3::new(r * phi.cos(), y, r * phi.sin());
                            sum += env.eval(r_inv * d);
                        }
                    }
                    let brute = sum * 2.0 / (n * n) as f64;
                    let got = l[band * s + sector];
                    worst = worst.max((got - brute).abs().max_element());
                    scale = scale.max(brute.max_element());
                }
            }
            assert!(scale > 0.0);
            eprintln!("{deg}°: worst |cell − brute-force mean| {worst:.3e} of {scale:.3e}");
            // Exact but for the brute force's 64² samples of a piecewise-constant map.
            assert!(worst < 0.01 * scale, "{deg}°: {worst} of {scale}");
        }
    }

    /// The shared-edge sums equal each cell clipped and integrated alone, in f64, for normals
    /// and views all round and glossy to rough lobes (cells across either horizon take the
    /// clipped path, the others the edge sums).
    #[test]
    fn edge_sums_equal_the_cells_integrated_alone() {
        use crate::frame::shading::ShadingFrame;
        use crate::ltc::polygon::integrate;
        use crate::ltc::table::LtcTable;
        use crate::shade::sky_cells::{CellTerm, specular_weights};
        let cells = SkyCells::new(&EnvLight::constant([1.0; 3]), 12, 1.0).expect("cells");
        let table = LtcTable::builtin();
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut unit = || {
            let mut r = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
            };
            DVec3::new(r(), r(), r()).normalize_or(DVec3::Y)
        };
        let (mut fast, mut worst) = (0usize, 0.0f64);
        for i in 0..40 {
            let n = unit();
            let wo = (unit() + n * 1.2).normalize();
            let alpha = [0.02, 0.1, 0.3, 0.7, 1.0][i % 5];
            let frame = ShadingFrame::new(n, wo);
            let ltc = table.lookup(alpha, frame.cos_view(wo));
            let to_ltc = ltc.m_inv * DMat3::from_cols(frame.x, frame.y, frame.z).transpose();
            let terms: Vec<CellTerm> = (0..cells.len())
                .map(|c| CellTerm {
                    cell: c as u16,
                    diffuse: 1.0,
                    visible: 1.0,
                })
                .collect();
            let mut got = Vec::new();
            specular_weights(cells.grid(), n, &to_ltc, &terms, &mut got);
            for (c, &g) in got.iter().enumerate() {
                let poly = &cells.grid().polys[c];
                let clipped = bspvt_proto::sphere::clip(poly, n);
                let want = if clipped.len() >= 3 {
                    integrate(&to_ltc, &clipped)
                } else {
                    0.0
                };
                fast += usize::from(poly.iter().all(|&d| n.dot(d) > 0.0 && (to_ltc * d).z > 0.0));
                worst = worst.max((f64::from(g) - want).abs() / want.max(1e-6));
            }
        }
        eprintln!("edge sums: {fast} cells by shared edges, worst relative difference {worst:.2e}");
        assert!(
            fast > 1000,
            "the shared-edge path was hardly taken ({fast})"
        );
        // f32 storage of the weights.
        assert!(worst < 1e-6, "{worst}");
    }
}
