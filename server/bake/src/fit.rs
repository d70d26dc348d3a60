//! The BSPVT builder [paper000 §3.2, Alg. 1].
//!
//! A node holding pixel set P becomes a leaf when its own squared deviation Σ (V − v̄)² is at
//! most `ε · res²`; otherwise it is split by the line l minimising
//! E(P, l) = Σ_p (H0(d(p)) − V(p))² (eq. 3). Visibility is kept as integer escape counts
//! k ∈ 0..=S per pixel (V = k / S), so every sum below is exact and the bake is deterministic.
//! Every decision is made in integers — E, the leaf test (D·2¹⁶ ≤ T·n with D = n Σk² − (Σk)²),
//! the children's squared deviation as an exact ratio, the leaf value by integer rounding — so
//! a device without f64 (a GPU fit) can make the same ones.
//!
//! Split searches ([`SplitMethod`]):
//! - `Exhaustive`: for every quantised angle θ in [0, π), a histogram of the pixels over the
//!   quantised offsets and one prefix sweep give E for every offset at once, for both
//!   orientations (left→0/right→1 and its mirror); O(n + O) per angle, exact over the stored
//!   line set. Slow: the quality reference.
//! - `Default`: the same line search over a coarse-to-fine angle set (every 45°, then
//!   bisection ±22.5°, ±11.25°, … down to one angle step around the best), on pixels merged
//!   into uniform blocks (cells, scored at their centres; partitions stay exact per pixel).
//!
//! Where E cannot improve on predicting the whole node with one binary value (E's blind spot:
//! a small blob of one value inside the other), the line minimising the children's squared
//! deviation is used instead (`Best::choose`).
//! - `NelderMead`: the paper's baseline — Nelder–Mead over continuous (θ, c), E evaluated on
//!   the quantised line. When its search ends on no line that splits the node, the node
//!   becomes a leaf even if it exceeds ε (the paper's algorithm has no fallback): part of why
//!   the baseline's trees are less accurate.

use bspvt_proto::SplitMethod;
use bspvt_proto::bspvt::{FaceTree, LineCodec, MAX_DEPTH, Node, QLine, quantise_ratio};
use glam::Vec2;

/// The leaf tolerance on a face is at most this share of the pixels of the smallest light
/// seen there, in pixels of squared deviation ([`Fitter::for_face`]): a leaf that mixes the
/// pixels of a light that small with others must be split.
pub(crate) const LIGHT_SHARE: f64 = 0.1;

/// Builder settings for one bake.
pub struct Fitter<'a> {
    /// The quantisation of the candidate lines.
    pub codec: &'a LineCodec,
    /// Face resolution in pixels.
    pub res: u32,
    /// Pixel-centre face coordinates, index `j·res + i`.
    pub uv: &'a [Vec2],
    /// Escape count of a fully visible pixel (rays per pixel).
    pub samples: u32,
    /// Leaf threshold on Σ (V − v̄)² in pixels.
    pub epsilon_pixels: f64,
    /// How split lines are searched.
    pub method: SplitMethod,
}

/// Per-face fit statistics against the cube map.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FitStats {
    /// Pixels fitted.
    pub pixels: u64,
    /// Σ |V(p) − v̄_q(leaf(p))| over the pixels (v̄ after 8-bit quantisation).
    pub abs_error: f64,
    /// Pixels whose leaf rounds to the other binary value (|V − v̄| > 0.5).
    pub misclassified: u64,
    /// Leaves made.
    pub leaves: u64,
    /// Cells the split search visited (its cost).
    pub cell_visits: u64,
}

impl std::ops::AddAssign for FitStats {
    fn add_assign(&mut self, o: FitStats) {
        self.pixels += o.pixels;
        self.abs_error += o.abs_error;
        self.misclassified += o.misclassified;
        self.leaves += o.leaves;
        self.cell_visits += o.cell_visits;
    }
}

/// Largest uniform block merged into one cell.
const MAX_CELL: u16 = 16;

/// Angles of the default split search's first pass, evenly over [0, π).
const COARSE_ANGLES: u32 = 4;

/// A square block of pixels `[i, i+size) × [j, j+size)` that all matter and share escape count
/// `k`. Uniform blocks are merged (quadtree) so the search visits the boundary, not the area;
/// the search scores a cell at its centre, but partitions are always exact per pixel: a cell a
/// line crosses is split until every part lies on one side ([`Fitter::partition`]).
#[derive(Clone, Copy, Debug)]
struct Cell {
    i: u16,
    j: u16,
    size: u16,
    k: u16,
    /// The face point the search scores the cell at ([`Fitter::centre`]), computed once.
    at: Vec2,
    /// Its pixels w = size² and w·k, [`pack`]ed.
    wk: u64,
    /// w·k² (at most 16² · 64² < 2³²).
    wk2: u32,
    /// Every pixel of the cell is protected (a sun's, `FacePixels::protected`), or none is:
    /// protected pixels merge only with each other ([`Fitter::cells`]).
    protected: bool,
}

/// Added to a protected pixel's count in the merge's grid ([`Fitter::cells`]), so that it merges
/// only with protected pixels of its count (counts are < 2¹⁶).
const PROTECTED: i32 = 1 << 16;

/// Count and Σk of a pixel set in one word, `n | Σk << 32`: a face has at most 512² = 2¹⁸
/// pixels of k ≤ 8² (`BakeSettings::MAX_FACE_RES`, `MAX_SUPERSAMPLING`), so Σk < 2²⁴ and
/// the low half never carries into the high one. The split search's histogram adds one
/// word per cell instead of three.
#[inline]
fn pack(n: u32, s1: u32) -> u64 {
    u64::from(n) | u64::from(s1) << 32
}

/// Sums over a pixel set: count, Σk, Σk².
#[derive(Clone, Copy, Default)]
struct Moments {
    n: u64,
    s1: u64,
    s2: u64,
}

impl Moments {
    /// The moments of a [`pack`]ed count and Σk, and Σk² (`None`: one ray per pixel, k ∈
    /// {0, 1}, so Σk² = Σk).
    #[inline]
    fn unpack(w: u64, s2: Option<u64>) -> Moments {
        let s1 = w >> 32;
        Moments {
            n: w & 0xffff_ffff,
            s1,
            s2: s2.unwrap_or(s1),
        }
    }

    /// Adds a cell's moments.
    #[inline]
    fn add_cell(&mut self, c: &Cell) {
        *self = self.plus(Moments::unpack(c.wk, Some(u64::from(c.wk2))));
    }

    fn plus(self, o: Moments) -> Moments {
        Moments {
            n: self.n + o.n,
            s1: self.s1 + o.s1,
            s2: self.s2 + o.s2,
        }
    }
    fn minus(self, o: Moments) -> Moments {
        Moments {
            n: self.n - o.n,
            s1: self.s1 - o.s1,
            s2: self.s2 - o.s2,
        }
    }
    /// S² · Σ (H − V)² with H ≡ 0 over the set: Σ k².
    fn err_as_zero(&self) -> u64 {
        self.s2
    }
    /// S² · Σ (H − V)² with H ≡ 1: Σ (S − k)² = n S² − 2 S Σk + Σk².
    fn err_as_one(&self, s: u64) -> u64 {
        self.n * s * s + self.s2 - 2 * s * self.s1
    }
    /// n · S² · Σ (V − v̄)² = n Σk² − (Σk)², exact (≥ 0 by Cauchy–Schwarz; < 2⁴⁹ for a
    /// face of at most 2¹⁸ pixels of k ≤ 2⁶).
    fn deviation_times_n(&self) -> u64 {
        self.n * self.s2 - self.s1 * self.s1
    }
    /// S² · Σ (V − v̄)² = Σk² − (Σk)²/n as an exact ratio.
    fn ssd(&self) -> Ratio {
        if self.n == 0 {
            return Ratio::ZERO;
        }
        Ratio {
            num: u128::from(self.deviation_times_n()),
            den: u128::from(self.n),
        }
    }
}

/// A non-negative rational `num / den` compared exactly (cross-multiplied), so the fit's
/// decisions are the same on every device (the GPU fit, `gpu_fit.rs`, has no f64). `den = 0`
/// is +∞. Holds sums of two squared deviations: num < 2⁶⁷, den ≤ 2³⁶, products < 2¹⁰⁴.
#[derive(Clone, Copy, Debug)]
struct Ratio {
    num: u128,
    den: u128,
}

impl Ratio {
    const ZERO: Ratio = Ratio { num: 0, den: 1 };
    const INFINITY: Ratio = Ratio { num: 1, den: 0 };

    fn whole(n: u64) -> Ratio {
        Ratio {
            num: u128::from(n),
            den: 1,
        }
    }

    /// a/b + c/d = (a d + c b) / (b d), for finite ratios.
    fn plus(self, o: Ratio) -> Ratio {
        Ratio {
            num: self.num * o.den + o.num * self.den,
            den: self.den * o.den,
        }
    }
}

impl Ord for Ratio {
    fn cmp(&self, o: &Ratio) -> std::cmp::Ordering {
        (self.num * o.den).cmp(&(o.num * self.den))
    }
}
impl PartialOrd for Ratio {
    fn partial_cmp(&self, o: &Ratio) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl PartialEq for Ratio {
    fn eq(&self, o: &Ratio) -> bool {
        self.cmp(o).is_eq()
    }
}
impl Eq for Ratio {}

/// Which power-of-two blocks of a face's merge grid are uniform ([`Fitter::cells`]): per block
/// of 2ˡ × 2ˡ pixels, l = 1 … log₂ `top`, the value all its pixels hold (≥ 0), or −1 when they
/// differ or one does not matter. Built bottom up, each level from the four blocks below.
struct Uniform {
    /// Level l − 1: blocks per row, and their values row by row (whole blocks only).
    levels: Vec<(usize, Vec<i32>)>,
}

impl Uniform {
    /// The levels of `grid` (`res` × `res`) up to blocks of `top` pixels (none above 1 when
    /// `top` is not a power of two).
    fn new(grid: &[i32], res: usize, top: usize) -> Uniform {
        let mut levels: Vec<(usize, Vec<i32>)> = Vec::new();
        let mut size = 2;
        while top.is_power_of_two() && size <= top {
            let (below_w, below) = match levels.last() {
                Some((w, v)) => (*w, v.as_slice()),
                None => (res, grid),
            };
            let w = res / size;
            let mut cur = vec![-1; w * w];
            // w ≥ 1: size ≤ top ≤ res.
            for (bj, row) in cur.chunks_exact_mut(w).enumerate() {
                let (up, down) = (2 * bj * below_w, (2 * bj + 1) * below_w);
                for (bi, c) in row.iter_mut().enumerate() {
                    let x = 2 * bi;
                    let a = below[up + x];
                    if a >= 0
                        && below[up + x + 1] == a
                        && below[down + x] == a
                        && below[down + x + 1] == a
                    {
                        *c = a;
                    }
                }
            }
            levels.push((w, cur));
            size *= 2;
        }
        Uniform { levels }
    }

    /// Block (i, j, size)'s value when `size` is a level's (aligned blocks only, as the
    /// quadtree makes them); `None` for other sizes.
    #[inline]
    fn value(&self, i: u16, j: u16, size: u16) -> Option<i32> {
        if !size.is_power_of_two() || size < 2 {
            return None;
        }
        let (w, v) = self.levels.get(size.trailing_zeros() as usize - 1)?;
        let (bi, bj) = (i as usize / size as usize, j as usize / size as usize);
        v.get(bj * w + bi).copied()
    }
}

impl<'a> Fitter<'a> {
    /// The tree builder of `res`² faces at `samples` rays per pixel, a leaf's tolerance ε of
    /// the face's pixels [paper000 §3.2].
    pub fn new(
        codec: &'a LineCodec,
        uv: &'a [Vec2],
        res: u32,
        samples: u32,
        epsilon: f64,
        method: SplitMethod,
    ) -> Fitter<'a> {
        Fitter {
            codec,
            res,
            uv,
            samples,
            epsilon_pixels: epsilon * (f64::from(res) * f64::from(res)),
            method,
        }
    }

    /// Builds the tree of one face from its pixels that matter (`index`, escape counts),
    /// splitting by the line that minimises E(P, l) [paper000 §3.2 eq. 3].
    pub fn fit(&self, index: &[u32], visible: &[u16]) -> (FaceTree, FitStats) {
        self.fit_protected(index, visible, &[])
    }

    /// [`Self::fit`] where the pixels `protected` (ascending, each one of `index`: the pixels a
    /// sun's disk at rest falls in, `FacePixels::protected`) must end in pure leaves: a node
    /// that holds one is a leaf only when all its pixels' counts are equal, besides the ε test
    /// (the ε test lets a leaf average a pixel with its neighbours, which moves a sun smaller
    /// than a pixel by a pixel or two between neighbouring vertices: a stair-stepped patch).
    /// Without protected pixels every decision is [`Self::fit`]'s.
    pub fn fit_protected(
        &self,
        index: &[u32],
        visible: &[u16],
        protected: &[u32],
    ) -> (FaceTree, FitStats) {
        let cells = self.cells(index, visible, protected);
        let mut nodes = Vec::new();
        let mut stats = FitStats::default();
        let mut scratch = Scratch::new(self.codec);
        self.build(cells, 0, &mut nodes, &mut stats, &mut scratch);
        (FaceTree { nodes }, stats)
    }

    /// Quadtree-merges uniform blocks (up to [`MAX_CELL`]²) of pixels that matter.
    /// `Exhaustive` keeps single pixels, so its search is exact over the stored lines.
    /// A protected pixel merges only with protected pixels (of its count).
    fn cells(&self, index: &[u32], visible: &[u16], protected: &[u32]) -> Vec<Cell> {
        let res = self.res as usize;
        if self.method == SplitMethod::Exhaustive {
            return index
                .iter()
                .zip(visible)
                .map(|(&p, &k)| Cell {
                    protected: protected.binary_search(&p).is_ok(),
                    ..self.cell((p as usize % res) as u16, (p as usize / res) as u16, 1, k)
                })
                .collect();
        }
        let mut grid = vec![-1i32; res * res];
        for (&i, &k) in index.iter().zip(visible) {
            grid[i as usize] = k as i32;
        }
        for &p in protected {
            if let Some(g) = grid.get_mut(p as usize).filter(|g| **g >= 0) {
                *g += PROTECTED;
            }
        }
        let mut out = Vec::new();
        let r = self.res as u16;
        let top = MAX_CELL.min(r).max(1);
        let uniform = Uniform::new(&grid, res, top as usize);
        for j in (0..r).step_by(top as usize) {
            for i in (0..r).step_by(top as usize) {
                if i + top <= r && j + top <= r {
                    self.merge(&grid, &uniform, i, j, top, &mut out);
                } else {
                    // A partial block at the face's edge (res not a multiple of MAX_CELL).
                    for jj in j..(j + top).min(r) {
                        for ii in i..(i + top).min(r) {
                            self.merge(&grid, &uniform, ii, jj, 1, &mut out);
                        }
                    }
                }
            }
        }
        out
    }

    /// Emits block (i, j, size) as one cell when uniform, else its quadrants.
    fn merge(
        &self,
        grid: &[i32],
        uniform: &Uniform,
        i: u16,
        j: u16,
        size: u16,
        out: &mut Vec<Cell>,
    ) {
        let res = self.res as usize;
        let pixel = |out: &mut Vec<Cell>, i: u16, j: u16| {
            let k = grid[j as usize * res + i as usize];
            if k >= 0 {
                out.push(self.grid_cell(i, j, 1, k));
            }
        };
        if size == 1 {
            pixel(out, i, j);
            return;
        }
        let h = size / 2;
        let quads = [(i, j), (i + h, j), (i, j + h), (i + h, j + h)];
        // Power-of-two blocks (every block of a power-of-two face): whether the block is
        // uniform is looked up. One that is not has a quadrant that is not, or two that
        // differ, so its quadrants are never merged back.
        if let Some(v) = uniform.value(i, j, size) {
            if v >= 0 {
                out.push(self.grid_cell(i, j, size, v));
            } else if size == 2 {
                // The quadrants are pixels: emitted here, without four more calls (the hot
                // path of a noisy face).
                for (qi, qj) in quads {
                    pixel(out, qi, qj);
                }
            } else {
                for (qi, qj) in quads {
                    self.merge(grid, uniform, qi, qj, h, out);
                }
            }
            return;
        }
        // Other sizes (a face's resolution that is not a power of two): only even ones are
        // halved, and no block of another size is merged.
        if !size.is_multiple_of(2) {
            // Odd sizes only happen at a face's edge for odd resolutions: emit pixels.
            for jj in j..j + size {
                for ii in i..i + size {
                    pixel(out, ii, jj);
                }
            }
            return;
        }
        for (qi, qj) in quads {
            self.merge(grid, uniform, qi, qj, h, out);
        }
    }

    /// The cell `[i, i+size) × [j, j+size)` of the merge grid's value `g` (a count, plus
    /// [`PROTECTED`] for protected pixels).
    #[inline]
    fn grid_cell(&self, i: u16, j: u16, size: u16, g: i32) -> Cell {
        Cell {
            protected: g >= PROTECTED,
            ..self.cell(i, j, size, (g % PROTECTED) as u16)
        }
    }

    /// The cell `[i, i+size) × [j, j+size)` of escape count `k` (not protected).
    #[inline]
    fn cell(&self, i: u16, j: u16, size: u16, k: u16) -> Cell {
        let w = size as u32 * size as u32;
        Cell {
            i,
            j,
            size,
            k,
            at: self.centre(i, j, size),
            wk: pack(w, w * k as u32),
            wk2: w * k as u32 * k as u32,
            protected: false,
        }
    }

    /// Where a cell is scored: its pixel's centre, or the block's centre.
    #[inline]
    fn centre(&self, i: u16, j: u16, size: u16) -> Vec2 {
        if size == 1 {
            return self.uv[j as usize * self.res as usize + i as usize];
        }
        let r = self.res as f32;
        Vec2::new(
            (2 * i + size) as f32 / r - 1.0,
            (2 * j + size) as f32 / r - 1.0,
        )
    }

    fn moments(cells: &[Cell]) -> Moments {
        let mut m = Moments::default();
        for c in cells {
            m.add_cell(c);
        }
        m
    }

    fn build(
        &self,
        cells: Vec<Cell>,
        depth: usize,
        nodes: &mut Vec<Node>,
        stats: &mut FitStats,
        scratch: &mut Scratch,
    ) {
        let m = Self::moments(&cells);
        // A node that holds a protected pixel is a leaf only when pure (n Σk² = (Σk)²).
        let pure = || !cells.iter().any(|c| c.protected) || m.deviation_times_n() == 0;
        let is_leaf = depth >= MAX_DEPTH || (self.within_epsilon(m) && pure());
        let split = if is_leaf {
            None
        } else {
            self.best_line(&cells, m, stats, scratch)
        };
        let Some(line) = split else {
            self.leaf(&cells, m, nodes, stats);
            return;
        };
        let (left, right) = self.partition(&cells, line);
        if left.is_empty() || right.is_empty() {
            self.leaf(&cells, m, nodes, stats);
            return;
        }
        let at = nodes.len();
        nodes.push(Node::Split { line, right: 0 });
        self.build(left, depth + 1, nodes, stats, scratch);
        let r = nodes.len() as u32;
        nodes[at] = Node::Split { line, right: r };
        self.build(right, depth + 1, nodes, stats, scratch);
    }

    /// Splits cells by the shared side test, exactly per pixel: a cell whose corner pixel
    /// centres are not all clearly on one side is split into quadrants down to pixels.
    fn partition(&self, cells: &[Cell], line: QLine) -> (Vec<Cell>, Vec<Cell>) {
        let (mut left, mut right) = (Vec::new(), Vec::new());
        let mut stack: Vec<Cell> = Vec::new();
        let res = self.res as usize;
        let px = |i: u16, j: u16| self.uv[j as usize * res + i as usize];
        for &c in cells {
            stack.push(c);
            while let Some(c) = stack.pop() {
                if c.size == 1 {
                    if self.codec.side(line, px(c.i, c.j)) {
                        right.push(c);
                    } else {
                        left.push(c);
                    }
                    continue;
                }
                let e = c.size - 1;
                let d = [(0, 0), (e, 0), (0, e), (e, e)]
                    .map(|(di, dj)| self.codec.distance(line, px(c.i + di, c.j + dj)));
                // A half-plane is convex: if all four corner centres are clearly on one side,
                // so is every pixel centre between them. The margin keeps rounding out of it.
                const MARGIN: f32 = 1e-5;
                if d.iter().all(|&x| x >= MARGIN) {
                    right.push(c);
                } else if d.iter().all(|&x| x < -MARGIN) {
                    left.push(c);
                } else {
                    let h = c.size / 2;
                    for (qi, qj) in [
                        (c.i, c.j),
                        (c.i + h, c.j),
                        (c.i, c.j + h),
                        (c.i + h, c.j + h),
                    ] {
                        stack.push(Cell {
                            protected: c.protected,
                            ..self.cell(qi, qj, h, c.k)
                        });
                    }
                }
            }
        }
        (left, right)
    }

    /// The fitter for a face whose smallest light reaches `light_pixels` of its pixels
    /// (`FacePixels::light_pixels`): the leaf tolerance ε · res² is a share of the whole face
    /// [paper000 §3.2], up to ~4 pixels of squared deviation at 64², which is a whole bulb (a
    /// point light's sphere covers 1–4 pixels) — averaged with another light's pixels in one
    /// leaf it takes their visibility (a dotted shadow edge). So on a face the tolerance is also
    /// at most [`LIGHT_SHARE`] of the smallest light's pixels there; lights of ≥ ε · res² /
    /// LIGHT_SHARE pixels (41 at 64²) leave it as it is.
    pub(crate) fn for_face(&self, light_pixels: u32) -> Fitter<'a> {
        Fitter {
            epsilon_pixels: self
                .epsilon_pixels
                .min(LIGHT_SHARE * f64::from(light_pixels)),
            ..*self
        }
    }

    /// The leaf threshold S² · ε · res² in units of 2⁻¹⁶ (rounded down), the integer the
    /// leaf test compares against ([`Self::within_epsilon`]).
    pub(crate) fn leaf_threshold(&self) -> u64 {
        let s = self.samples as f64;
        (self.epsilon_pixels * s * s * 65536.0).floor() as u64
    }

    /// The leaf test Σ (V − v̄)² ≤ ε · res² [paper000 §3.2], exactly in integers:
    /// D / n ≤ T / 2¹⁶ ⇔ D · 2¹⁶ ≤ T · n, D = n Σk² − (Σk)², T = [`Self::leaf_threshold`].
    fn within_epsilon(&self, m: Moments) -> bool {
        u128::from(m.deviation_times_n()) << 16
            <= u128::from(self.leaf_threshold()) * u128::from(m.n)
    }

    fn leaf(&self, cells: &[Cell], m: Moments, nodes: &mut Vec<Node>, stats: &mut FitStats) {
        let s = u64::from(self.samples);
        // v̄ = Σk / (n S), quantised by the integer rule (an empty set: fully visible).
        let value = if m.n > 0 {
            quantise_ratio(m.s1, m.n * s)
        } else {
            255
        };
        // |V − v̄_q| = |255 k − v S| / (255 S): summed as integers, divided once.
        let (mut abs_num, mut misclassified) = (0u64, 0u64);
        for c in cells {
            let w = u64::from(c.size).pow(2);
            let d = (255 * u64::from(c.k)).abs_diff(u64::from(value) * s);
            abs_num += w * d;
            if 2 * d > 255 * s {
                misclassified += w;
            }
        }
        stats.abs_error += abs_num as f64 / (255 * s) as f64;
        stats.misclassified += misclassified;
        stats.pixels += m.n;
        stats.leaves += 1;
        nodes.push(Node::Leaf { value });
    }

    fn best_line(
        &self,
        cells: &[Cell],
        total: Moments,
        stats: &mut FitStats,
        scratch: &mut Scratch,
    ) -> Option<QLine> {
        match self.method {
            SplitMethod::Exhaustive => {
                let half = self.codec.angles() / 2;
                let mut best = Best::default();
                for a in 0..half {
                    self.sweep(cells, total, a as u16, &mut best, stats, scratch);
                }
                best.choose(total, self.samples as u64)
            }
            SplitMethod::Default => self.coarse_to_fine(cells, total, stats, scratch),
            SplitMethod::NelderMead => self.nelder_mead(cells, stats),
        }
    }

    fn coarse_to_fine(
        &self,
        cells: &[Cell],
        total: Moments,
        stats: &mut FitStats,
        scratch: &mut Scratch,
    ) -> Option<QLine> {
        let half = self.codec.angles() / 2;
        // Every 45°, then bisection around the best (at 64², 4 + 10 sweeps instead of the 16
        // coarse + 12 refining sweeps of every 8th angle around the two best: 0.6× the fit
        // time, with fewer leaves and a lower error on every shared mesh, docs/bake.md).
        let step_coarse = (half / COARSE_ANGLES).max(1);
        let s = self.samples as u64;
        let constant = total.err_as_zero().min(total.err_as_one(s));
        // Rank an angle by E where E improves on a constant, else by the children's deviation.
        let score = |b: &Best| -> (u8, Ratio) {
            if b.err < constant {
                (0, Ratio::whole(b.err))
            } else {
                (1, b.ssd)
            }
        };
        let mut best = Best::default();
        // The best coarse angle: the lowest (score, angle).
        let mut start: Option<((u8, Ratio), u32)> = None;
        for a in (0..half).step_by(step_coarse as usize) {
            let mut b = Best::default();
            self.sweep(cells, total, a as u16, &mut b, stats, scratch);
            let here = (score(&b), a);
            start = Some(start.map_or(here, |s| s.min(here)));
            best.take(b);
        }
        // Refine it by bisection: ±step/2, ±step/4, … ±1 around the current best.
        if let Some((sc, a0)) = start {
            let (mut centre, mut centre_score) = (a0, sc);
            let mut step = step_coarse / 2;
            while step > 0 {
                for a in [centre + step, centre + half - step] {
                    let mut b = Best::default();
                    self.sweep(cells, total, (a % half) as u16, &mut b, stats, scratch);
                    let sc = score(&b);
                    if sc < centre_score {
                        (centre, centre_score) = (a % half, sc);
                    }
                    best.take(b);
                }
                step /= 2;
            }
        }
        best.choose(total, s)
    }

    /// Evaluates E for every quantised offset at angle `a` (and its mirror) with one
    /// histogram pass and one prefix sweep; keeps the best line that splits the set.
    fn sweep(
        &self,
        cells: &[Cell],
        total: Moments,
        a: u16,
        best: &mut Best,
        stats: &mut FitStats,
        scratch: &mut Scratch,
    ) {
        if cells.is_empty() {
            return;
        }
        let n = self.codec.normal(a);
        let Scratch {
            hist,
            hist_k2,
            bins,
        } = scratch;
        let binner = self.codec.offset_bins();
        // One ray per pixel: k ∈ {0, 1}, so Σk² = Σk and only the packed word is summed.
        let squares = self.samples > 1;
        // The bins' range, in registers: a per-cell mark in memory (a bitmap) would chain
        // each cell's update to the last one's store whenever neighbours share a word.
        let (mut lo, mut hi) = (usize::MAX, 0);
        for c in cells {
            let p = c.at;
            let bin = binner.bin(n.x * p.x + n.y * p.y) as usize;
            hist[bin] += c.wk;
            if squares {
                hist_k2[bin] += u64::from(c.wk2);
            }
            lo = lo.min(bin);
            hi = hi.max(bin);
        }
        stats.cell_visits += cells.len() as u64;
        // The non-empty bins, in order: a cell has at least one pixel, so a bin holds a
        // non-zero count exactly when a cell fell in it.
        // Without a branch per bin (whether one is empty is a coin toss): every index is
        // written, the count moves past the non-empty ones.
        let mut len = 0;
        for (b, &w) in hist[lo..=hi].iter().enumerate() {
            bins[len] = (lo + b) as u32;
            len += usize::from(w != 0);
        }
        let bins = &bins[..len];
        let moments =
            |b: u32| Moments::unpack(hist[b as usize], squares.then(|| hist_k2[b as usize]));
        let s = self.samples as u64;
        // Line o: left = bins ≤ o, right = bins > o. The partition changes only at non-empty
        // bins: "left = bins ≤ b" holds for every o in [b, b′ − 1], b′ the next non-empty bin,
        // and the line is placed mid-gap, so an edge between two pixel rows is not pulled
        // toward one of them (mirror-image inputs get mirror-image lines).
        let line = |b: u32, next: u32| QLine {
            angle: a,
            offset: ((b + next - 1) / 2) as u16,
        };
        let mut left = Moments::default();
        for pair in bins.windows(2) {
            let (b, next) = (pair[0], pair[1]);
            left = left.plus(moments(b));
            let right = total.minus(left);
            let e1 = left.err_as_zero() + right.err_as_one(s);
            let e2 = left.err_as_one(s) + right.err_as_zero();
            best.offer(e1, line(b, next));
            if e2 < best.err {
                best.offer(e2, self.codec.mirror(line(b, next)));
            }
        }
        // The children's squared deviation decides only where no line's E beats the best
        // constant (`Best::choose`, and the angle ranking of `coarse_to_fine`); E only falls
        // as lines are offered, so once it beats the constant the deviations are not needed.
        // Offered in the same order as E, so the result is as if both were offered together.
        if best.err >= total.err_as_zero().min(total.err_as_one(s)) {
            let mut left = Moments::default();
            for pair in bins.windows(2) {
                let (b, next) = (pair[0], pair[1]);
                left = left.plus(moments(b));
                let right = total.minus(left);
                best.offer_ssd(left.ssd().plus(right.ssd()), line(b, next));
            }
        }
        for &b in bins.iter() {
            hist[b as usize] = 0;
            if squares {
                hist_k2[b as usize] = 0;
            }
        }
    }

    /// E(P, l) for a quantised line, by a direct pass (cells scored at their centres).
    fn energy(&self, cells: &[Cell], line: QLine) -> (u64, usize) {
        let s = self.samples as u64;
        let mut e = 0;
        let mut right = 0;
        for c in cells {
            let k = c.k as u64;
            let w = (c.size as u64).pow(2);
            if self.codec.side(line, c.at) {
                right += 1;
                e += w * (s - k) * (s - k);
            } else {
                e += w * k * k;
            }
        }
        (e, right)
    }

    /// The paper's baseline: Nelder–Mead over (θ, c) from a fixed start (θ = 0, c = 0, steps
    /// π/2 and 0.5), standard coefficients (1, 2, ½, ½), at most 100 evaluations.
    fn nelder_mead(&self, cells: &[Cell], stats: &mut FitStats) -> Option<QLine> {
        let quant = |x: [f64; 2]| -> QLine {
            let a = self.codec.angles() as f64;
            let angle = ((x[0] / std::f64::consts::TAU * a).round().rem_euclid(a)) as u16;
            let o = self.codec.offsets() as f64;
            let h = bspvt_proto::bspvt::line::MAX_OFFSET as f64 / o;
            let offset = ((x[1] / h + o - 1.0) * 0.5).round().clamp(0.0, o - 1.0) as u16;
            QLine { angle, offset }
        };
        let evals = std::cell::Cell::new(0u32);
        let mut f = |x: [f64; 2]| -> f64 {
            evals.set(evals.get() + 1);
            stats.cell_visits += cells.len() as u64;
            let (e, right) = self.energy(cells, quant(x));
            // A line that does not split the set is no split at all.
            if right == 0 || right == cells.len() {
                f64::INFINITY
            } else {
                e as f64
            }
        };
        let mut simplex = [[0.0, 0.0], [std::f64::consts::FRAC_PI_2, 0.0], [0.0, 0.5]];
        let mut fx = simplex.map(&mut f);
        while evals.get() < 100 {
            // Order: best, worst.
            let mut idx = [0usize, 1, 2];
            idx.sort_by(|&i, &j| fx[i].total_cmp(&fx[j]));
            simplex = idx.map(|i| simplex[i]);
            fx = idx.map(|i| fx[i]);
            let c = [
                0.5 * (simplex[0][0] + simplex[1][0]),
                0.5 * (simplex[0][1] + simplex[1][1]),
            ];
            let along = |t: f64| {
                [
                    c[0] + t * (simplex[2][0] - c[0]),
                    c[1] + t * (simplex[2][1] - c[1]),
                ]
            };
            let xr = along(-1.0);
            let fr = f(xr);
            if fr < fx[0] {
                let xe = along(-2.0);
                let fe = f(xe);
                (simplex[2], fx[2]) = if fe < fr { (xe, fe) } else { (xr, fr) };
            } else if fr < fx[1] {
                (simplex[2], fx[2]) = (xr, fr);
            } else {
                let xc = along(0.5);
                let fc = f(xc);
                if fc < fx[2] {
                    (simplex[2], fx[2]) = (xc, fc);
                } else {
                    for i in 1..3 {
                        simplex[i] = [
                            0.5 * (simplex[0][0] + simplex[i][0]),
                            0.5 * (simplex[0][1] + simplex[i][1]),
                        ];
                        fx[i] = f(simplex[i]);
                    }
                }
            }
        }
        let (i, e) = fx
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, e)| (i, *e))?;
        e.is_finite().then(|| quant(simplex[i]))
    }
}

/// Buffers the split search reuses across the nodes of a face.
struct Scratch {
    /// Count and Σk per offset bin, [`pack`]ed (zero between sweeps).
    hist: Vec<u64>,
    /// Σk² per offset bin, where a pixel has more than one ray (zero between sweeps).
    hist_k2: Vec<u64>,
    /// The non-empty bins of the current sweep, in order, at its start (one slot per bin).
    bins: Vec<u32>,
}

impl Scratch {
    fn new(codec: &LineCodec) -> Scratch {
        let bins = codec.offsets() as usize + 1;
        Scratch {
            hist: vec![0; bins],
            hist_k2: vec![0; bins],
            bins: vec![0; bins],
        }
    }
}

/// The best lines seen so far by E and by the children's squared deviation (ties keep the
/// first, so the search order fixes the result).
#[derive(Clone, Copy)]
struct Best {
    err: u64,
    line: Option<QLine>,
    ssd: Ratio,
    ssd_line: Option<QLine>,
}

impl Default for Best {
    fn default() -> Self {
        Best {
            err: u64::MAX,
            line: None,
            ssd: Ratio::INFINITY,
            ssd_line: None,
        }
    }
}

impl Best {
    #[inline]
    fn offer(&mut self, err: u64, line: QLine) {
        if err < self.err {
            self.err = err;
            self.line = Some(line);
        }
    }
    #[inline]
    fn offer_ssd(&mut self, ssd: Ratio, line: QLine) {
        if ssd < self.ssd {
            self.ssd = ssd;
            self.ssd_line = Some(line);
        }
    }
    fn take(&mut self, o: Best) {
        if let Some(l) = o.line {
            self.offer(o.err, l);
        }
        if let Some(l) = o.ssd_line {
            self.offer_ssd(o.ssd, l);
        }
    }

    /// The E-minimising line when it beats predicting the whole node with one binary value;
    /// otherwise (E cannot improve: e.g. a small occluded blob inside a visible region, where
    /// the E-optimal line only peels off a sliver) the line that minimises the children's
    /// squared deviation Σ_L (V − v̄_L)² + Σ_R (V − v̄_R)².
    fn choose(&self, total: Moments, samples: u64) -> Option<QLine> {
        let constant = total.err_as_zero().min(total.err_as_one(samples));
        if self.err < constant {
            self.line
        } else {
            self.ssd_line
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bspvt_proto::cubemap::pixel_centres;

    /// Moments of `n` pixels with random escape counts in 0..=s.
    fn random_moments(seed: &mut u64, n: u64, s: u64) -> Moments {
        let mut m = Moments::default();
        for _ in 0..n {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let k = (*seed >> 33) % (s + 1);
            m = m.plus(Moments {
                n: 1,
                s1: k,
                s2: k * k,
            });
        }
        m
    }

    /// The exact ratios order the children's squared deviations as the reals do: against f64
    /// wherever f64 can tell them apart, equal sums of different shape compare equal, and ∞
    /// is above every finite sum.
    #[test]
    fn ratios_order_as_reals() {
        let mut seed = 7u64;
        let mut compared = 0;
        for _ in 0..4000 {
            let sum = |seed: &mut u64| {
                let s = 1 + (*seed >> 40) % 16;
                let (a, b) = (1 + (*seed >> 20) % 300, 1 + (*seed >> 30) % 300);
                let (l, r) = (random_moments(seed, a, s), random_moments(seed, b, s));
                let real = |m: Moments| m.s2 as f64 - (m.s1 as f64).powi(2) / m.n as f64;
                (l.ssd().plus(r.ssd()), real(l) + real(r))
            };
            let ((x, fx), (y, fy)) = (sum(&mut seed), sum(&mut seed));
            assert!(x < Ratio::INFINITY && Ratio::ZERO <= x);
            if (fx - fy).abs() > 1e-9 * fx.abs().max(fy.abs()).max(1.0) {
                assert_eq!(x < y, fx < fy, "{x:?} {fx} vs {y:?} {fy}");
                compared += 1;
            }
        }
        assert!(compared > 3000, "{compared}");
        // Equal values in different terms are equal (the search's ties keep the first line).
        let (l, r) = (
            random_moments(&mut seed, 30, 4),
            random_moments(&mut seed, 50, 4),
        );
        assert_eq!(l.ssd().plus(r.ssd()), r.ssd().plus(l.ssd()));
        let half = Ratio { num: 3, den: 6 };
        assert_eq!(half.plus(half), Ratio::whole(1));
        assert!(Ratio::whole(1) < Ratio::INFINITY && Ratio::INFINITY == Ratio::INFINITY);
    }

    /// The integer leaf test is Σ (V − v̄)² ≤ ε·res²: the f64 rule wherever f64 is clear of
    /// the threshold's 2⁻¹⁶ rounding.
    #[test]
    fn leaf_test_is_the_threshold() {
        let codec = LineCodec::for_resolution(16);
        let uv = pixel_centres(16);
        let mut seed = 11u64;
        let (mut leaves, mut splits) = (0, 0);
        for i in 0..3000 {
            let samples = [1u32, 4, 16, 64][i % 4];
            let eps = [0.0, 1e-4, 1e-3, 1e-2][(i / 4) % 4];
            let f = Fitter::new(&codec, &uv, 16, samples, eps, SplitMethod::Default);
            // Mostly uniform sets with a few odd pixels, so both answers occur.
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let n = 1 + (seed >> 50) % 200;
            let odd = (seed >> 45) % 16;
            let mut m = random_moments(&mut seed, odd, u64::from(samples));
            let k = (seed >> 37) % (u64::from(samples) + 1);
            m = m.plus(Moments {
                n,
                s1: n * k,
                s2: n * k * k,
            });
            let s = f64::from(samples);
            let ssd = m.s2 as f64 - (m.s1 as f64).powi(2) / m.n as f64;
            let limit = f.epsilon_pixels * s * s;
            if (ssd - limit).abs() > 1e-4 * s * s {
                assert_eq!(f.within_epsilon(m), ssd <= limit, "{ssd} vs {limit}");
                if ssd <= limit {
                    leaves += 1;
                } else {
                    splits += 1;
                }
            }
        }
        assert!(
            leaves > 300 && splits > 300,
            "{leaves} leaves, {splits} splits"
        );
    }

    /// The bake's fitter at one ray per pixel and the default ε = 10⁻³ of the face's pixels.
    fn one_ray_fitter<'a>(
        codec: &'a LineCodec,
        uv: &'a [Vec2],
        res: u32,
        method: SplitMethod,
    ) -> Fitter<'a> {
        Fitter::new(codec, uv, res, 1, 1e-3, method)
    }

    /// Two bulbs of 4 pixels each on a 64² face, one shadowed and one lit: the face's
    /// tolerance (ε · res² ≈ 4.1 pixels of squared deviation) takes the 8 pixels as one leaf
    /// of 0.5 (a squared deviation of 2), both bulbs half lit; bounded by a tenth of the
    /// smaller light's 4 pixels (`for_face`), each keeps its own visibility. A light of
    /// ≥ 41 pixels leaves the tolerance as it is.
    #[test]
    fn a_small_light_keeps_its_own_leaves() {
        let res = 64u32;
        let codec = LineCodec::for_resolution(res);
        let uv = pixel_centres(res);
        let f = one_ray_fitter(&codec, &uv, res, SplitMethod::Default);
        // Bulb A: a 2×2 block at (10, 10), shadowed; bulb B: at (40, 30), lit.
        let block = |i0: u32, j0: u32| [(i0, j0), (i0 + 1, j0), (i0, j0 + 1), (i0 + 1, j0 + 1)];
        let mut px: Vec<(u32, u16)> = block(10, 10)
            .into_iter()
            .map(|(i, j)| (j * res + i, 0))
            .chain(block(40, 30).into_iter().map(|(i, j)| (j * res + i, 1)))
            .collect();
        px.sort();
        let (index, visible): (Vec<u32>, Vec<u16>) = px.into_iter().unzip();
        let values = |f: &Fitter| -> Vec<u8> {
            let (tree, _) = f.fit(&index, &visible);
            index
                .iter()
                .map(|&p| tree.query(&codec, uv[p as usize]))
                .collect()
        };
        assert!(values(&f).iter().all(|&v| v == 128), "{:?}", values(&f));
        assert_eq!(values(&f.for_face(u32::MAX)), values(&f));
        assert_eq!(values(&f.for_face(41)), values(&f));
        assert_eq!(values(&f.for_face(4)), vec![0, 0, 0, 0, 255, 255, 255, 255]);
    }

    /// A sun's pixel, lit, in an 8 × 8 shadowed block of a 64² face: the face's tolerance
    /// (ε · res² ≈ 4.1 pixels of squared deviation) takes the block as one leaf of 1/64 (a squared
    /// deviation of 63/64), the sun shadowed; protected (`fit_protected`), its leaf must be pure
    /// and the sun keeps its own visibility, for every split search. A protected pixel among
    /// pixels of its own count changes nothing, nor does an empty protected set.
    #[test]
    fn a_suns_pixel_keeps_its_own_leaf() {
        let res = 64u32;
        let codec = LineCodec::for_resolution(res);
        let uv = pixel_centres(res);
        for method in [
            SplitMethod::Default,
            SplitMethod::Exhaustive,
            SplitMethod::NelderMead,
        ] {
            let f = one_ray_fitter(&codec, &uv, res, method);
            let sun = 20 * res + 21;
            let index: Vec<u32> = (16..24)
                .flat_map(|j| (16..24).map(move |i| j * res + i))
                .collect();
            let visible: Vec<u16> = index.iter().map(|&p| u16::from(p == sun)).collect();
            let at_sun = |protected: &[u32]| {
                let (tree, _) = f.fit_protected(&index, &visible, protected);
                tree.query(&codec, uv[sun as usize])
            };
            assert!(at_sun(&[]) < 128, "{method:?}: the sun averaged away");
            assert_eq!(
                f.fit(&index, &visible),
                f.fit_protected(&index, &visible, &[])
            );
            if method != SplitMethod::NelderMead {
                assert_eq!(at_sun(&[sun]), 255, "{method:?}");
            }
            // All lit: one leaf, protected or not.
            let lit = vec![1u16; index.len()];
            let (tree, _) = f.fit_protected(&index, &lit, &[sun]);
            assert_eq!(tree, f.fit(&index, &lit).0, "{method:?}");
        }
    }

    /// Every pixel that matters reaches exactly one leaf, at resolutions that are not multiples
    /// of the largest cell (16) too.
    #[test]
    fn every_pixel_is_fitted_at_any_resolution() {
        for res in [8u32, 24, 50, 64, 100] {
            let codec = LineCodec::for_resolution(res);
            let uv = pixel_centres(res);
            // A disc of occluded pixels, and a quarter of the face that does not matter.
            let (index, visible): (Vec<u32>, Vec<u16>) = uv
                .iter()
                .enumerate()
                .filter(|(_, p)| p.x < 0.5 || p.y < 0.5)
                .map(|(i, p)| {
                    (
                        i as u32,
                        u16::from((*p - Vec2::new(-0.2, 0.1)).length() > 0.4),
                    )
                })
                .unzip();
            for method in [SplitMethod::Default, SplitMethod::Exhaustive] {
                let f = Fitter::new(&codec, &uv, res, 1, 0.0, method);
                let (tree, stats) = f.fit(&index, &visible);
                assert_eq!(stats.pixels, index.len() as u64, "{res}² {method:?}");
                for (&i, &k) in index.iter().zip(&visible) {
                    let v = tree.query(&codec, uv[i as usize]);
                    assert_eq!(
                        v,
                        if k == 1 { 255 } else { 0 },
                        "{res}² {method:?} pixel {i}"
                    );
                }
            }
        }
    }

    /// The cells by their definition: each pixel that matters lies in the largest aligned
    /// power-of-two block of at most `top` pixels (inside a whole one of the face's top
    /// blocks; `top` a power of two) whose pixels all matter and hold one merge value.
    fn cells_by_definition(
        grid: &[i32],
        res: usize,
        top: usize,
    ) -> std::collections::BTreeSet<(u16, u16, u16, i32)> {
        let whole = |i: usize, j: usize| (i / top + 1) * top <= res && (j / top + 1) * top <= res;
        let uniform = |i: usize, j: usize, s: usize| {
            let v = grid[j * res + i];
            v >= 0 && (j..j + s).all(|y| (i..i + s).all(|x| grid[y * res + x] == v))
        };
        let mut out = std::collections::BTreeSet::new();
        for j in 0..res {
            for i in 0..res {
                let v = grid[j * res + i];
                if v < 0 {
                    continue;
                }
                let mut cell = (i, j, 1);
                let mut s = 2;
                while top.is_power_of_two() && s <= top && whole(i, j) {
                    let (bi, bj) = (i / s * s, j / s * s);
                    if uniform(bi, bj, s) {
                        cell = (bi, bj, s);
                    }
                    s *= 2;
                }
                out.insert((cell.0 as u16, cell.1 as u16, cell.2 as u16, v));
            }
        }
        out
    }

    proptest::proptest! {
        /// The merge's cells (found through the `Uniform` levels) are the definition's, on
        /// faces of power-of-two and other sizes, with protected pixels.
        #[test]
        fn cells_are_the_largest_uniform_blocks(
            res in proptest::sample::select(vec![1u32, 4, 8, 12, 16, 20, 24, 32, 48, 64]),
            patches in proptest::collection::vec((0u32..64, 0u32..64, 0u32..5, 0u16..3, proptest::bool::ANY), 0..24),
            holes in proptest::collection::vec((0u32..64, 0u32..64), 0..16),
            protect in proptest::collection::vec((0u32..64, 0u32..64, 0u32..6), 0..4),
        ) {
            // Every pixel matters, count 0, then patches of other counts (aligned or not),
            // pixels that do not matter, and protected squares.
            let n = (res * res) as usize;
            let mut k = vec![Some(0u16); n];
            for &(i, j, l, v, aligned) in &patches {
                let s = 1 << l;
                let (i, j) = if aligned { (i / s * s, j / s * s) } else { (i, j) };
                for y in j..(j + s).min(res) {
                    for x in i..(i + s).min(res) {
                        if x < res && y < res {
                            k[(y * res + x) as usize] = Some(v);
                        }
                    }
                }
            }
            for &(i, j) in &holes {
                if i < res && j < res {
                    k[(j * res + i) as usize] = None;
                }
            }
            let mut protected = Vec::new();
            for &(i, j, s) in &protect {
                for y in j..(j + s).min(res) {
                    for x in i..(i + s).min(res) {
                        protected.push(y * res + x);
                    }
                }
            }
            protected.sort_unstable();
            protected.dedup();
            let (index, visible): (Vec<u32>, Vec<u16>) = (0..n as u32)
                .filter_map(|p| k[p as usize].map(|v| (p, v)))
                .unzip();
            protected.retain(|p| index.binary_search(p).is_ok());
            let codec = LineCodec::for_resolution(res);
            let uv = pixel_centres(res);
            let f = one_ray_fitter(&codec, &uv, res, SplitMethod::Default);
            let cells = f.cells(&index, &visible, &protected);
            let mut grid = vec![-1i32; n];
            for (&p, &v) in index.iter().zip(&visible) {
                grid[p as usize] = i32::from(v)
                    + if protected.binary_search(&p).is_ok() { PROTECTED } else { 0 };
            }
            let top = MAX_CELL.min(res as u16).max(1) as usize;
            let expected = cells_by_definition(&grid, res as usize, top);
            let got: std::collections::BTreeSet<(u16, u16, u16, i32)> = cells
                .iter()
                .map(|c| (c.i, c.j, c.size, i32::from(c.k) + if c.protected { PROTECTED } else { 0 }))
                .collect();
            proptest::prop_assert_eq!(cells.len(), got.len(), "a cell emitted twice");
            proptest::prop_assert_eq!(got, expected);
        }
    }
}
