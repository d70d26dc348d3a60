//! The LTC table of GGX: one fitted linearly transformed cosine per (roughness, view angle),
//! stored in `assets/ltc/ggx.json` (fitted by [`super::fit`], regenerated with
//! `bspvt ltc-fit`), and its lookup. Method and measured accuracy: `docs/ltc.md`.
//!
//! # What an entry is
//!
//! Heitz, Dupuy, Hill and Neubelt 2016, "Real-Time Polygonal-Light Shading with Linearly
//! Transformed Cosines" (*LTC*), §3: a distribution D is obtained from the clamped cosine
//! D_o(ω_o) = max(z, 0)/π by a 3×3 matrix M, ω = Mω_o/‖Mω_o‖, with density (the definition and
//! its Jacobian)
//!
//! D(ω) = D_o(M⁻¹ω/‖M⁻¹ω‖) · |det M⁻¹| / ‖M⁻¹ω‖³.
//!
//! For an isotropic BRDF seen from ω_o = (sin θ, 0, cos θ) the lobe is symmetric about the
//! xz-plane, so M keeps y apart (LTC §4) and, up to scale, has four free entries. We write
//! M = [X Y Z] · A in the frame of the lobe's average direction, as the authors' fitting code
//! `fitLTC.cpp` does — X = (cos ρ, 0, −sin ρ), Y = (0, 1, 0), Z = (sin ρ, 0, cos ρ), ρ < 0 for a
//! reflection lobe — with
//!
//! A = [[m11, 0, m13], [0, m22, 0], [m31, 0, 1]].
//!
//! `fitLTC.cpp` fits m11, m22, m13 and keeps m31 = 0; the fourth entry m31 (a perspective term
//! that skews the lobe along X) is what lets a rough or grazing lobe be fitted well. It is
//! used instead of a free frame angle ρ because, for narrow lobes, rotating the frame and
//! shearing (m13) are nearly the same transform, an almost flat valley of the objective along
//! which the optimiser drifts from entry to entry and which bilinear interpolation then mixes
//! inconsistently; m31 has no such valley. det M = m22·(m11 − m13·m31) > 0 for every entry.
//!
//! Each entry also stores the BRDF integrals magnitude = ∫ f cos θi dωi (Fresnel = 1) and
//! fresnel = ∫ f cos θi (1 − ωi·h)⁵ dωi (the Fresnel split of the published LTC tables), so that
//! the specular response to a polygon P is (F0·magnitude + (1 − F0)·fresnel) · ∫_P D.
//!
//! # Axes
//!
//! Both axes put resolution where published tables are weakest (low roughness, grazing view):
//!
//! - roughness node i of n: α_i = α_min^(1 − i/(n−1)), α_min = [`ggx::MIN_ALPHA`] = 1e-4,
//!   i.e. uniform in ln α (a ratio of 1.157 between neighbours at n = 64). Narrow lobes scale
//!   with α, so a uniform step in ln α is a uniform *relative* step in lobe width.
//! - view node j of n: θ_j = θ_max · v (2 − v), v = j/(n−1), θ_max = 89.99°. The distance to the
//!   horizon, 90° − θ, shrinks quadratically toward grazing: steps of 2.9° near normal
//!   incidence, 0.023° (4·10⁻⁴ rad) at the last node, resolving the horizon clipping of narrow
//!   lobes (which happens within ~2α of the horizon).
//!
//! # What is interpolated
//!
//! [`LtcTable::lookup`] interpolates bilinearly in (i, j) (continuous indices on the axes above)
//! the quantities
//!
//! - δ = ρ + θ_j: the frame direction relative to the mirror direction. The lookup adds back
//!   −θ of the *query*, so the direction of narrow lobes (which follows −θ to within a fraction
//!   of α) is exact whatever the spacing of the view nodes;
//! - ln m11, ln m22 (the lobe widths: narrow lobes scale ∝ α, which is linear in ln α),
//!   q = m13/m11 (the shear in units of the width) and m31 (dimensionless);
//! - magnitude and fresnel, linearly.
//!
//! Queries are clamped to α ∈ [α_min, 1] (NaN → 1) and θ ∈ [0, θ_max] (cos θ NaN → 1, i.e.
//! normal incidence); views beyond 89.99° get the 89.99° entry. M⁻¹ is returned normalised as in
//! Heitz's code ((1, 1) entry = 1). If an interpolated shape were ever singular
//! (m11 − m13·m31 ≤ 10⁻⁶ m11; `client/tests/ltc_table.rs` checks that it does not happen with the
//! shipped table) the nearest node's shape is used, so the output is always finite with
//! det M⁻¹ > 0.

use std::f64::consts::PI;
use std::sync::OnceLock;

use anyhow::{Context, bail, ensure};
use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

use crate::ggx::{self, MIN_ALPHA};

/// The format tag of the table file.
pub const FORMAT: &str = "bspvt-ltc-ggx/1";

/// Largest view angle with a table node, in degrees.
pub const THETA_MAX_DEG: f64 = 89.99;

/// Largest view angle with a table node, in radians.
#[inline]
pub fn theta_max() -> f64 {
    THETA_MAX_DEG.to_radians()
}

/// α at roughness node `i` of `n`: α_min^(1 − i/(n−1)) (uniform in ln α; node n−1 is α = 1).
pub fn alpha_node(i: usize, n: usize) -> f64 {
    let s = i as f64 / (n - 1).max(1) as f64;
    ggx::clamp_alpha(((1.0 - s) * MIN_ALPHA.ln()).exp())
}

/// The continuous node coordinate s ∈ [0, 1] of a (clamped) α: α = α_min^(1 − s).
#[inline]
pub fn alpha_coord(alpha: f64) -> f64 {
    (1.0 - ggx::clamp_alpha(alpha).ln() / MIN_ALPHA.ln()).clamp(0.0, 1.0)
}

/// View angle θ (radians) at view node `j` of `n`: θ_max · v (2 − v), v = j/(n−1).
pub fn theta_node(j: usize, n: usize) -> f64 {
    let v = j as f64 / (n - 1).max(1) as f64;
    theta_max() * v * (2.0 - v)
}

/// The continuous node coordinate v ∈ [0, 1] of a view angle θ (radians), clamped to
/// [0, θ_max]: v = 1 − √(1 − θ/θ_max).
#[inline]
pub fn theta_coord(theta: f64) -> f64 {
    let t = (theta / theta_max()).clamp(0.0, 1.0);
    (1.0 - (1.0 - t).sqrt()).clamp(0.0, 1.0)
}

/// One fitted LTC for a given (α, view angle): the inverse transform, and the BRDF integrals.
#[derive(Clone, Copy, Debug)]
pub struct Ltc {
    /// M⁻¹ (column-major glam DMat3) mapping directions of the GGX lobe (local frame, view in
    /// the xz-plane with x ≥ 0) to the clamped cosine's frame. Normalised as in Heitz's code:
    /// the (1, 1) entry (y row, y column) is 1; the y row and column are otherwise zero.
    pub m_inv: DMat3,
    /// ∫ f cosθi dωi over the hemisphere, Fresnel = 1 (the "magnitude"/norm).
    pub magnitude: f64,
    /// ∫ f cosθi (1 − ωi·h)⁵ dωi (Hill's Fresnel term: specular = F0·magnitude + (1 − F0)·fresnel).
    pub fresnel: f64,
}

impl Ltc {
    /// Density of the LTC distribution (normalised to integrate to 1 over the sphere) in
    /// direction `w` (need not be unit length): D_o(M⁻¹w/|M⁻¹w|)·|det M⁻¹|/|M⁻¹w|³ with
    /// D_o = max(z, 0)/π (LTC eq. 1–2), scaled by |w|³ so that it is a density per solid
    /// angle of w/|w|. Zero for a zero, non-finite or back-facing (clamped) direction.
    pub fn density(&self, w: DVec3) -> f64 {
        let wl = w.length();
        if !(wl > 0.0) || !wl.is_finite() {
            return 0.0;
        }
        let w = w / wl;
        let p = self.m_inv * w;
        let l2 = p.length_squared();
        if !(p.z > 0.0) || !(l2 > 0.0) {
            return 0.0;
        }
        let v = p.z * self.m_inv.determinant().abs() / (PI * l2 * l2);
        if v.is_finite() { v } else { 0.0 }
    }
}

/// The shape of one LTC: M = [X Y Z] · A, A = [[m11, 0, m13], [0, m22, 0], [m31, 0, 1]], with the
/// frame X = (cos ρ, 0, −sin ρ), Y = (0, 1, 0), Z = (sin ρ, 0, cos ρ) (see the module
/// documentation). det M = m22 (m11 − m13 m31), kept positive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LtcShape {
    /// Angle of the frame's Z axis from the normal, toward +x (radians; negative for a
    /// reflection lobe): the lobe's average direction.
    pub rho: f64,
    /// Scale along X (> 0).
    pub m11: f64,
    /// Scale along Y (> 0).
    pub m22: f64,
    /// Shear of Z toward X (moves the peak off the frame's Z axis).
    pub m13: f64,
    /// Perspective term: X feeds the output's Z (skews the lobe along X).
    pub m31: f64,
}

impl LtcShape {
    /// The frame axes X, Z (Y = (0, 1, 0)).
    #[inline]
    pub fn frame(&self) -> (DVec3, DVec3) {
        let (s, c) = self.rho.sin_cos();
        (DVec3::new(c, 0.0, -s), DVec3::new(s, 0.0, c))
    }

    /// m11 − m13·m31: det M = m22 times this; a well-formed shape has it > 0.
    #[inline]
    pub fn xz_det(&self) -> f64 {
        self.m11 - self.m13 * self.m31
    }

    /// Whether the shape is usable: finite, m11, m22 > 0, det M > 0.
    pub fn is_valid(&self) -> bool {
        [self.rho, self.m11, self.m22, self.m13, self.m31]
            .iter()
            .all(|v| v.is_finite())
            && self.m11 > 0.0
            && self.m22 > 0.0
            && self.xz_det() > 0.0
    }

    #[cfg(test)]
    /// M (maps the clamped cosine's frame to the lobe), column-major.
    pub fn m(&self) -> DMat3 {
        let (x, z) = self.frame();
        DMat3::from_cols(
            self.m11 * x + self.m31 * z,
            self.m22 * DVec3::Y,
            self.m13 * x + z,
        )
    }

    /// M⁻¹ normalised so that its (1, 1) entry is 1: rows (m22/Δ)(X − m13 Z), Y,
    /// (m22/Δ)(m11 Z − m31 X) with Δ = m11 − m13 m31. Its determinant is m22²/Δ > 0.
    pub fn m_inv(&self) -> DMat3 {
        let (x, z) = self.frame();
        let k = self.m22 / self.xz_det();
        let r0 = k * (x - self.m13 * z);
        let r2 = k * (self.m11 * z - self.m31 * x);
        DMat3::from_cols(r0, DVec3::Y, r2).transpose()
    }
}

/// One table entry: the fitted shape and the BRDF integrals at a node (α_i, θ_j).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TableEntry {
    /// The LTC's shape.
    pub shape: LtcShape,
    /// ∫ f cos θi dωi (Fresnel = 1).
    pub magnitude: f64,
    /// ∫ f cos θi (1 − ωi·h)⁵ dωi.
    pub fresnel: f64,
}

impl TableEntry {
    /// The entry as stored in the file: [ρ, m11, m22, m13, m31, magnitude, fresnel].
    pub fn to_array(&self) -> [f64; 7] {
        let s = &self.shape;
        [
            s.rho,
            s.m11,
            s.m22,
            s.m13,
            s.m31,
            self.magnitude,
            self.fresnel,
        ]
    }

    /// The inverse of [`TableEntry::to_array`].
    pub fn from_array(a: [f64; 7]) -> Self {
        TableEntry {
            shape: LtcShape {
                rho: a[0],
                m11: a[1],
                m22: a[2],
                m13: a[3],
                m31: a[4],
            },
            magnitude: a[5],
            fresnel: a[6],
        }
    }

    /// The entry as an [`Ltc`].
    pub fn ltc(&self) -> Ltc {
        Ltc {
            m_inv: self.shape.m_inv(),
            magnitude: self.magnitude,
            fresnel: self.fresnel,
        }
    }
}

/// How the table was fitted (recorded in the file so that entries can be refitted exactly).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitRecord {
    /// Points of the rank-1 (Fibonacci) lattice per sampling strategy in the error estimate.
    pub lattice_points: usize,
    /// Grading depth of the half-vector quadrature that integrates magnitude, Fresnel and
    /// the average direction.
    pub moment_levels: u32,
    /// Nelder–Mead stops when the simplex is smaller than this (in ln m11, ln m22, m13/m11,
    /// m31).
    pub simplex_tolerance: f64,
    /// p of the Lᵖ distance minimised (1: total variation; Heitz et al. use 3).
    pub error_power: i32,
    /// Whether the distance is taken over the upper hemisphere only (the polygon integral
    /// clips at the horizon) or over the whole sphere (as `fitLTC.cpp` does).
    pub upper_hemisphere_only: bool,
    /// Human-readable summary of the method.
    pub method: String,
}

/// The file `assets/ltc/ggx.json` (see `assets/ltc/README.md`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TableFile {
    /// Always [`FORMAT`].
    pub format: String,
    /// What the file is.
    pub description: String,
    /// Nodes per axis.
    pub size: usize,
    /// α of roughness node 0.
    pub alpha_min: f64,
    /// θ of the last view node, degrees.
    pub theta_max_deg: f64,
    /// The command that regenerates the file.
    pub command: String,
    /// The fit's settings.
    pub fit: FitRecord,
    /// α at each roughness node (for reference; the loader checks them against the formula).
    pub alpha: Vec<f64>,
    /// θ (radians) at each view node.
    pub theta: Vec<f64>,
    /// [ρ, m11, m22, m13, m31, magnitude, fresnel] per node, index i·size + j (roughness i,
    /// view j).
    pub entries: Vec<[f64; 7]>,
}

impl TableFile {
    /// Serialises with one entry per line (stable bytes: the same table gives the same file).
    pub fn to_json(&self) -> anyhow::Result<String> {
        use std::fmt::Write;
        fn j<T: Serialize + ?Sized>(v: &T) -> anyhow::Result<String> {
            Ok(serde_json::to_string(v)?)
        }
        let mut s = String::new();
        s.push_str("{\n");
        writeln!(s, "  \"format\": {},", j(&self.format)?)?;
        writeln!(s, "  \"description\": {},", j(&self.description)?)?;
        writeln!(s, "  \"size\": {},", self.size)?;
        writeln!(s, "  \"alpha_min\": {},", j(&self.alpha_min)?)?;
        writeln!(s, "  \"theta_max_deg\": {},", j(&self.theta_max_deg)?)?;
        writeln!(s, "  \"command\": {},", j(&self.command)?)?;
        writeln!(s, "  \"fit\": {},", j(&self.fit)?)?;
        writeln!(s, "  \"alpha\": {},", j(&self.alpha)?)?;
        writeln!(s, "  \"theta\": {},", j(&self.theta)?)?;
        s.push_str("  \"entries\": [\n");
        for (k, e) in self.entries.iter().enumerate() {
            let sep = if k + 1 == self.entries.len() { "" } else { "," };
            writeln!(s, "    {}{sep}", j(e)?)?;
        }
        s.push_str("  ]\n}\n");
        Ok(s)
    }
}

/// The value nearest `x` (x itself, else its neighbours 1, 2, … ulps away) that reads back
/// from its JSON text bit for bit. serde_json's float parser (without the `float_roundtrip`
/// feature) can be an ulp off, and for some values it alternates between two neighbours; the
/// fit stores — and starts the next entry from — only such fixed points, so a reader of the
/// file gets exactly the numbers the fit used.
pub fn json_roundtrip(x: f64) -> f64 {
    let reads_back = |v: f64| {
        serde_json::to_string(&v)
            .ok()
            .and_then(|s| serde_json::from_str::<f64>(&s).ok())
            .is_some_and(|r| r.to_bits() == v.to_bits())
    };
    if !x.is_finite() || reads_back(x) {
        return x;
    }
    let (mut up, mut down) = (x, x);
    for _ in 0..64 {
        up = up.next_up();
        if reads_back(up) {
            return up;
        }
        down = down.next_down();
        if reads_back(down) {
            return down;
        }
    }
    x
}

/// Per-node quantities that [`LtcTable::lookup`] interpolates.
#[derive(Clone, Copy, Debug)]
struct Node {
    delta: f64,
    ln_m11: f64,
    ln_m22: f64,
    q: f64,
    m31: f64,
    magnitude: f64,
    fresnel: f64,
}

/// The fitted table: `size`×`size` entries over (α, θ), see the module documentation.
#[derive(Clone, Debug)]
pub struct LtcTable {
    size: usize,
    alpha: Vec<f64>,
    theta: Vec<f64>,
    entries: Vec<TableEntry>,
    nodes: Vec<Node>,
    fit: FitRecord,
}

static BUILTIN: OnceLock<LtcTable> = OnceLock::new();

impl LtcTable {
    /// The table in `assets/ltc/ggx.json`, embedded in the binary and parsed once.
    pub fn builtin() -> &'static LtcTable {
        BUILTIN.get_or_init(|| {
            LtcTable::from_json(include_str!("../../../assets/ltc/ggx.json"))
                .expect("the built-in LTC table (assets/ltc/ggx.json) is valid")
        })
    }

    /// Parses and validates a table file.
    pub fn from_json(text: &str) -> anyhow::Result<LtcTable> {
        let file: TableFile = serde_json::from_str(text).context("not an LTC table file")?;
        Self::from_file(file)
    }

    /// Validates a parsed file: format, axes (must match the formulas of this module), and
    /// every entry finite with m11, m22 > 0 and 0 ≤ fresnel ≤ magnitude.
    pub fn from_file(file: TableFile) -> anyhow::Result<LtcTable> {
        ensure!(
            file.format == FORMAT,
            "format {:?}, expected {FORMAT:?}",
            file.format
        );
        let n = file.size;
        ensure!(n >= 2, "size {n} < 2");
        ensure!(
            file.alpha.len() == n && file.theta.len() == n,
            "axes of the wrong length"
        );
        ensure!(
            file.entries.len() == n * n,
            "{} entries, expected {}",
            file.entries.len(),
            n * n
        );
        ensure!(
            file.alpha_min == MIN_ALPHA && file.theta_max_deg == THETA_MAX_DEG,
            "the axes' range differs from this build's"
        );
        for k in 0..n {
            let (a, t) = (alpha_node(k, n), theta_node(k, n));
            if (file.alpha[k] - a).abs() > 1e-12 * a || (file.theta[k] - t).abs() > 1e-12 {
                bail!("node {k}: axes differ from this build's parameterisation");
            }
        }
        let mut entries = Vec::with_capacity(n * n);
        let mut nodes = Vec::with_capacity(n * n);
        for (k, a) in file.entries.iter().enumerate() {
            let e = TableEntry::from_array(*a);
            let s = e.shape;
            let ok = a.iter().all(|v| v.is_finite())
                && s.is_valid()
                && e.magnitude >= 0.0
                && e.fresnel >= 0.0
                && e.fresnel <= e.magnitude;
            ensure!(
                ok,
                "entry {k} (α node {}, θ node {}) is malformed: {a:?}",
                k / n,
                k % n
            );
            let theta = theta_node(k % n, n);
            nodes.push(Node {
                delta: s.rho + theta,
                ln_m11: s.m11.ln(),
                ln_m22: s.m22.ln(),
                q: s.m13 / s.m11,
                m31: s.m31,
                magnitude: e.magnitude,
                fresnel: e.fresnel,
            });
            entries.push(e);
        }
        Ok(LtcTable {
            size: n,
            alpha: (0..n).map(|i| alpha_node(i, n)).collect(),
            theta: (0..n).map(|j| theta_node(j, n)).collect(),
            entries,
            nodes,
            fit: file.fit,
        })
    }

    /// Nodes per axis.
    pub fn size(&self) -> usize {
        self.size
    }

    /// α of roughness node `i`.
    pub fn alpha(&self, i: usize) -> f64 {
        self.alpha[i]
    }

    /// θ (radians) of view node `j`.
    pub fn theta(&self, j: usize) -> f64 {
        self.theta[j]
    }

    /// The stored entry at roughness node `i`, view node `j`.
    pub fn entry(&self, i: usize, j: usize) -> &TableEntry {
        &self.entries[i * self.size + j]
    }

    /// The settings the table was fitted with.
    pub fn fit_record(&self) -> &FitRecord {
        &self.fit
    }

    /// The per-node quantities [`Self::lookup`] interpolates, in f32 for the GPU's copy of
    /// the lookup (`gpu/common.wgsl`): per node (δ, ln m11, ln m22, q), (m31, magnitude,
    /// fresnel, 0), index i·size + j.
    pub fn gpu_nodes(&self) -> Vec<[f32; 4]> {
        self.nodes
            .iter()
            .flat_map(|n| {
                [
                    [n.delta, n.ln_m11, n.ln_m22, n.q].map(|x| x as f32),
                    [n.m31, n.magnitude, n.fresnel, 0.0].map(|x| x as f32),
                ]
            })
            .collect()
    }

    /// Bilinear lookup (see the module documentation for what is interpolated). Clamps α to
    /// [α_min, 1] (NaN → 1) and cos θ to [cos θ_max, 1] (NaN → 1); never returns NaN or Inf,
    /// and M⁻¹ always has a positive determinant.
    pub fn lookup(&self, alpha: f64, cos_theta: f64) -> Ltc {
        let alpha = ggx::clamp_alpha(alpha);
        let c = if cos_theta.is_nan() {
            1.0
        } else {
            cos_theta.clamp(0.0, 1.0)
        };
        let theta = c.acos().min(theta_max());
        let last = (self.size - 1) as f64;
        let (i0, fi) = split(alpha_coord(alpha) * last, self.size);
        let (j0, fj) = split(theta_coord(theta) * last, self.size);
        let n = self.size;
        let at = |i: usize, j: usize| &self.nodes[i * n + j];
        let (a, b, c2, d) = (
            at(i0, j0),
            at(i0, j0 + 1),
            at(i0 + 1, j0),
            at(i0 + 1, j0 + 1),
        );
        let w = [
            (1.0 - fi) * (1.0 - fj),
            (1.0 - fi) * fj,
            fi * (1.0 - fj),
            fi * fj,
        ];
        let mix = |g: fn(&Node) -> f64| w[0] * g(a) + w[1] * g(b) + w[2] * g(c2) + w[3] * g(d);
        let m11 = mix(|n| n.ln_m11).exp();
        let mut shape = LtcShape {
            rho: mix(|n| n.delta) - theta,
            m11,
            m22: mix(|n| n.ln_m22).exp(),
            m13: mix(|n| n.q) * m11,
            m31: mix(|n| n.m31),
        };
        if !(shape.xz_det() > 1e-6 * shape.m11) {
            // Not reached with the shipped table (`interpolated_shapes_are_invertible` scans
            // every cell): the nearest node's shape, valid by construction.
            let (i, j) = (i0 + usize::from(fi > 0.5), j0 + usize::from(fj > 0.5));
            let near = self.entries[i * n + j].shape;
            shape = LtcShape {
                rho: near.rho - self.theta[j] + theta,
                ..near
            };
        }
        let magnitude = mix(|n| n.magnitude).max(0.0);
        let fresnel = mix(|n| n.fresnel).clamp(0.0, magnitude);
        Ltc {
            m_inv: shape.m_inv(),
            magnitude,
            fresnel,
        }
    }
}

/// Splits a continuous node coordinate into a cell index (≤ n − 2) and a fraction in [0, 1].
#[inline]
fn split(x: f64, n: usize) -> (usize, f64) {
    let x = if x.is_nan() {
        0.0
    } else {
        x.clamp(0.0, (n - 1) as f64)
    };
    let i = (x.floor() as usize).min(n - 2);
    (i, (x - i as f64).clamp(0.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_invert() {
        for k in 0..64 {
            let a = alpha_node(k, 64);
            assert!(
                (alpha_coord(a) * 63.0 - k as f64).abs() < 1e-9,
                "α node {k}"
            );
            let t = theta_node(k, 64);
            assert!(
                (theta_coord(t) * 63.0 - k as f64).abs() < 1e-6,
                "θ node {k}"
            );
        }
        assert_eq!(alpha_node(63, 64), 1.0);
        assert!((alpha_node(0, 64) - MIN_ALPHA).abs() < 1e-15);
        assert!((theta_node(63, 64) - theta_max()).abs() < 1e-15);
    }

    #[test]
    fn m_inv_inverts_m() {
        let s = LtcShape {
            rho: -0.7,
            m11: 0.3,
            m22: 0.2,
            m13: 0.05,
            m31: -0.4,
        };
        let p = s.m_inv() * s.m();
        // M⁻¹ is normalised by m22: M⁻¹·M = m22·I.
        assert!(
            (p - DMat3::IDENTITY * s.m22)
                .abs()
                .to_cols_array()
                .iter()
                .all(|v| *v < 1e-14)
        );
        assert!((s.m_inv().determinant() - s.m22 * s.m22 / s.xz_det()).abs() < 1e-14);
    }
}
