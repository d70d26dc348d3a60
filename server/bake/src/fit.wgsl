// The BSP tree fit on the GPU (gpu_fit.rs): one workgroup of WG invocations per face, the
// same tree and statistics as `Fitter::fit` with `SplitMethod::Default` (fit.rs), or a flag
// asking the CPU to fit the face again. See gpu_fit.rs's module doc for the design and the
// exactness argument; each stage below names the CPU function it mirrors.

const WG: u32 = 64u;
const MAX_DEPTH: u32 = 40u;
// DFS stack entries: at most one pending right child per level, and the node itself.
const STACK: u32 = 48u;
// fit.rs `partition`'s MARGIN.
const MARGIN: f32 = 1e-5;
// Offset bins 0..=O with O ≤ 256 (faces up to 64²).
const MAX_BINS: u32 = 257u;
const SLOTS: u32 = 4u;
const HEADER: u32 = 8u;
const NONE: u32 = 0xffffffffu;
const LEAF: u32 = 0x80000000u;

// Why a face is left to the CPU (header word 0).
const FLAG_BUDGET: u32 = 1u;
const FLAG_NODES: u32 = 2u;
const FLAG_STACK: u32 = 3u;
// llvmpipe's loop limiter ran out (the canary): the count fell short.
const FLAG_LIMIT: u32 = 4u;

struct Params {
    res: u32,
    samples: u32,
    // Angles in [0, π): the sweeps' angles; a + half is a's mirror.
    half: u32,
    // Quantised offsets O.
    offsets: u32,
    faces: u32,
    // Loop iterations a face may spend (llvmpipe ends an invocation at 65,535).
    budget: u32,
    // T_fx = floor(ε_pixels · S² · 2¹⁶), the leaf test's threshold, as two words.
    t_fx_lo: u32,
    t_fx_hi: u32,
    // Words per face in `work` and `out`.
    work_words: u32,
    out_words: u32,
    max_nodes: u32,
    // Words per face of `grid`.
    grid_words: u32,
    // Words of the cell-merge levels at the start of a face's `work`.
    level_words: u32,
    // Test hook: 1 breaks E ties the wrong way (a deliberately wrong shader).
    wrong_ties: u32,
    // 2: the canary loop's passes.
    canary: u32,
    pad1: u32,
}

@group(0) @binding(0) var<storage, read> params: Params;
// PX[a][m] = n(a).x · X[m] at [a·(2res+1) + m], then PY[a][m] = n(a).y · X[m] at
// [half·(2res+1) + a·(2res+1) + m], X[m] = m/res − 1: products computed on the CPU.
@group(0) @binding(1) var<storage, read> proj: array<f32>;
// c(o), o < O (`LineCodec::offset`).
@group(0) @binding(2) var<storage, read> offs: array<f32>;
// [b], b in 1..=O: the smallest f32 t with `OffsetBins::bin(t) ≥ b`.
@group(0) @binding(3) var<storage, read> thresh: array<f32>;
// Per face res² bytes, 4 a word: a pixel's escape count, 0xff where it does not matter.
@group(0) @binding(4) var<storage, read> grid: array<u32>;
// Per face: the merge levels, the cell arena (res² words), the partition's scratch (res²).
@group(0) @binding(5) var<storage, read_write> work: array<u32>;
// Per face: HEADER words (flag, nodes, cell visits, pixels, misclassified, leaves, loop
// iterations, 0), then 2 words per node.
@group(0) @binding(6) var<storage, read_write> out: array<u32>;

// Up to SLOTS angles are swept in one pass (the 4 coarse angles; the 2 candidates of a
// bisection step): a loop's pass serves all of them, so passes, not angles, spend the budget.
// Per slot q and bin b at [q·MAX_BINS + b]: n | Σk << 13 (n ≤ 4096 < 2¹³, Σk ≤ 2¹⁸ at 64²,
// fit.rs `pack`), and Σk².
var<workgroup> h_w: array<atomic<u32>, 1028>;
var<workgroup> h_s2: array<atomic<u32>, 1028>;
// Per slot q and invocation at [q·WG + lid]: its run's (n | Σk << 13, Σk²), then the scan
// (two halves of SCAN words, read from one while the other is written).
const SCAN: u32 = 256u;
var<workgroup> part: array<vec2<u32>, 512>;
var<workgroup> red_e: array<atomic<u32>, 4>;
var<workgroup> red_key: array<atomic<u32>, 4>;
// The wrong-ties test hook's key (the last least E instead of the first), + 1.
var<workgroup> red_last: array<atomic<u32>, 4>;
var<workgroup> next_e: array<atomic<u32>, 4>;
var<workgroup> next_s: array<atomic<u32>, 4>;
var<workgroup> ssd_num: array<vec4<u32>, WG>;
var<workgroup> ssd_den: array<vec2<u32>, WG>;
var<workgroup> ssd_b: array<u32, WG>;
// Counters: 0 cells, 1 left pieces, 2 right pieces, 3 loop iterations (max), 4 |error|,
// 5 misclassified; moments: 0..3 root or left, 3..6 right.
var<workgroup> ctr: array<atomic<u32>, 8>;
var<workgroup> mom: array<atomic<u32>, 6>;

// Loop iterations so far, the same in every invocation (strided loops count their longest
// share): meant as an upper bound of what llvmpipe's limiter has counted (a model, measured on
// lavapipe; the canary in `main` catches it falling short). The limiter counts a loop's
// last pass too (the one that finds the condition false and breaks: lanes are masked off, the
// vector still reaches the loop's end), so every loop counts one more than its iterations.
var<private> spent: u32;

fn share(n: u32) -> u32 {
    return (n + WG - 1u) / WG;
}

// ---- Integers of 64 and 128 bits (x the lowest limb) ----

fn mul32(a: u32, b: u32) -> vec2<u32> {
    let al = a & 0xffffu;
    let ah = a >> 16u;
    let bl = b & 0xffffu;
    let bh = b >> 16u;
    let ll = al * bl;
    let lh = al * bh;
    let hl = ah * bl;
    let mid = (ll >> 16u) + (lh & 0xffffu) + (hl & 0xffffu);
    return vec2<u32>(a * b, ah * bh + (lh >> 16u) + (hl >> 16u) + (mid >> 16u));
}

fn sub64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    return vec2<u32>(a.x - b.x, a.y - b.y - select(0u, 1u, a.x < b.x));
}

fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

// Straight-line code, no loops: loops count against llvmpipe's limit.
fn add128(a: vec4<u32>, b: vec4<u32>) -> vec4<u32> {
    let lo = add64(a.xy, b.xy);
    let carry = select(0u, 1u, lo.y < a.y || (lo.y == a.y && lo.x < a.x));
    let hi = add64(add64(a.zw, b.zw), vec2<u32>(carry, 0u));
    return vec4<u32>(lo, hi);
}

fn lt128(a: vec4<u32>, b: vec4<u32>) -> bool {
    if a.w != b.w {
        return a.w < b.w;
    }
    if a.z != b.z {
        return a.z < b.z;
    }
    if a.y != b.y {
        return a.y < b.y;
    }
    return a.x < b.x;
}

// a (64 bits) · b (32 bits).
fn mul64x32(a: vec2<u32>, b: u32) -> vec4<u32> {
    let p0 = mul32(a.x, b);
    let p1 = mul32(a.y, b);
    return add128(vec4<u32>(p0.x, p0.y, 0u, 0u), vec4<u32>(0u, p1.x, p1.y, 0u));
}

// a (128 bits) · b (64 bits), mod 2¹²⁸ (the products compared here stay below 2⁸⁰ at 64²).
fn mul128x64(a: vec4<u32>, b: vec2<u32>) -> vec4<u32> {
    let lo = add128(mul64x32(a.xy, b.x), mul64x32(vec2<u32>(0u, a.x), b.y));
    let hi = add128(mul64x32(a.zw, b.x), mul64x32(vec2<u32>(0u, a.z), b.y));
    let ay = mul32(a.y, b.y);
    return add128(add128(lo, vec4<u32>(0u, 0u, ay.x, ay.y)), vec4<u32>(0u, 0u, hi.x, hi.y));
}

// ---- Moments (fit.rs `Moments`): (n, Σk, Σk²) ----

// Σ (S − k)² = n S² + Σk² − 2 S Σk (`err_as_one`).
fn err_one(m: vec3<u32>) -> u32 {
    let s = params.samples;
    return m.x * s * s + m.z - 2u * s * m.y;
}

// D = n Σk² − (Σk)² = n² × the squared deviation (S² scaled).
fn dev(m: vec3<u32>) -> vec2<u32> {
    return sub64(mul32(m.x, m.z), mul32(m.y, m.y));
}

// The children's squared deviation DL/nL + DR/nR as num/den (`ssd_scaled` summed).
struct Ratio {
    num: vec4<u32>,
    den: vec2<u32>,
}

fn children_ssd(l: vec3<u32>, r: vec3<u32>) -> Ratio {
    return Ratio(add128(mul64x32(dev(l), r.x), mul64x32(dev(r), l.x)), mul32(l.x, r.x));
}

// Exact: num_a · den_b against num_b · den_a (below 2⁸⁰ at 64²: D < 2³⁶, n < 2¹³).
fn ratio_lt(a: Ratio, b: Ratio) -> bool {
    return lt128(mul128x64(a.num, b.den), mul128x64(b.num, a.den));
}

// ---- Cells (fit.rs `Cell`), one word: i | j << 8 | size << 16 | k << 21 ----

fn cell_pack(i: u32, j: u32, size: u32, k: u32) -> u32 {
    return i | (j << 8u) | (size << 16u) | (k << 21u);
}

// (i, j, size, k)
fn cell_unpack(c: u32) -> vec4<u32> {
    return vec4<u32>(c & 0xffu, (c >> 8u) & 0xffu, (c >> 16u) & 31u, c >> 21u);
}

// n·X, the CPU's f32 `n.x * p.x + n.y * p.y` exactly: one correctly rounded add of the CPU's
// products; an angle of [π, 2π) has the exactly negated normal, so the negated sum.
fn project(angle: u32, mx: u32, my: u32) -> f32 {
    let stride = 2u * params.res + 1u;
    var a = angle;
    var neg = false;
    if a >= params.half {
        a -= params.half;
        neg = true;
    }
    let t = proj[a * stride + mx] + proj[(params.half + a) * stride + my];
    return select(t, -t, neg);
}

// `OffsetBins::bin(t)`: the float formula's guess, corrected against the CPU's thresholds
// (the guess may be off by one where the device fuses or rounds otherwise).
fn bin_of(t: f32) -> u32 {
    let o = params.offsets;
    let k = (t * (f32(o) / 1.4142135) + f32(o) - 1.0) * 0.5 + 1.0;
    var b = 0u;
    if k > 0.0 {
        b = min(u32(k), o);
    }
    if b < o && thresh[b + 1u] <= t {
        b += 1u;
    }
    if b < o && thresh[b + 1u] <= t {
        b += 1u;
    }
    if b > 0u && thresh[b] > t {
        b -= 1u;
    }
    if b > 0u && thresh[b] > t {
        b -= 1u;
    }
    return b;
}

// `LineCodec::distance` of pixel centre (2i + 1, 2j + 1)/res − 1: one correctly rounded
// subtraction of the CPU's offset.
fn distance(line: u32, i: u32, j: u32) -> f32 {
    return project(line & 0xffffu, 2u * i + 1u, 2u * j + 1u) - offs[line >> 16u];
}

// ---- Cells of a face (fit.rs `cells`, `merge`) ----

// Level l holds, per aligned block of side 2^l inside a whole top block, its escape count
// when all its pixels matter and share it, else NONE. A block is a cell when it is uniform
// and its parent is not (or it is a top block): what `merge`'s quadtree emits. Cells are
// written in any order (their sums do not depend on it).
fn level_start(l: u32) -> u32 {
    var s = 0u;
    for (var q = 0u; q < l; q++) {
        let d = params.res >> q;
        s += d * d;
    }
    spent += l + 1u;
    return s;
}

fn build_cells(lid: u32, face: u32, lv: u32, arena: u32) -> u32 {
    let res = params.res;
    let top = min(16u, res);
    let levels = firstTrailingBit(top);
    let gbase = face * params.grid_words;
    for (var p = lid; p < res * res; p += WG) {
        let k = (grid[gbase + p / 4u] >> (8u * (p % 4u))) & 0xffu;
        work[lv + p] = select(k, NONE, k == 0xffu);
    }
    spent += share(res * res) + 1u;
    if lid == 0u {
        atomicStore(&ctr[0], 0u);
        atomicStore(&mom[0], 0u);
        atomicStore(&mom[1], 0u);
        atomicStore(&mom[2], 0u);
    }
    storageBarrier();
    workgroupBarrier();
    for (var l = 1u; l <= levels; l++) {
        let d = res >> l;
        let pd = res >> (l - 1u);
        let here = lv + level_start(l);
        let below = lv + level_start(l - 1u);
        let s = 1u << l;
        for (var q = lid; q < d * d; q += WG) {
            let bi = q % d;
            let bj = q / d;
            var v = NONE;
            let whole = ((bi * s) / top + 1u) * top <= res && ((bj * s) / top + 1u) * top <= res;
            if whole {
                let c = below + 2u * bj * pd + 2u * bi;
                let a = work[c];
                if a != NONE && work[c + 1u] == a && work[c + pd] == a && work[c + pd + 1u] == a {
                    v = a;
                }
            }
            work[here + q] = v;
        }
        spent += share(d * d) + 2u;
        storageBarrier();
        workgroupBarrier();
    }
    for (var l = 0u; l <= levels; l++) {
        let d = res >> l;
        let here = lv + level_start(l);
        let above = lv + level_start(l + 1u);
        let s = 1u << l;
        for (var q = lid; q < d * d; q += WG) {
            let v = work[here + q];
            if v == NONE {
                continue;
            }
            let bi = q % d;
            let bj = q / d;
            if l < levels && work[above + (bj / 2u) * (d / 2u) + bi / 2u] != NONE {
                continue;
            }
            let w = s * s;
            let at = atomicAdd(&ctr[0], 1u);
            work[arena + at] = cell_pack(bi * s, bj * s, s, v);
            atomicAdd(&mom[0], w);
            atomicAdd(&mom[1], w * v);
            atomicAdd(&mom[2], w * v * v);
        }
        spent += share(d * d) + 2u;
    }
    storageBarrier();
    workgroupBarrier();
    return atomicLoad(&ctr[0]);
}

// ---- The split search (fit.rs `sweep`, `coarse_to_fine`, `Best`) ----

struct Sweep {
    // The least E and its line (NONE: no line splits the cells).
    err: u32,
    line: u32,
    // The least children's deviation and its line (NONE: not computed or no line).
    ssd: Ratio,
    sline: u32,
}

fn unpack_w(w: u32, s2: u32) -> vec3<u32> {
    return vec3<u32>(w & 0x1fffu, w >> 13u, s2);
}

fn bin_moments(q: u32, b: u32) -> vec3<u32> {
    return unpack_w(atomicLoad(&h_w[q * MAX_BINS + b]), atomicLoad(&h_s2[q * MAX_BINS + b]));
}

// One cell into slot q's histogram (angle a; NONE: the slot is unused).
fn hist_cell(q: u32, a: u32, x: vec4<u32>) {
    if a == NONE {
        return;
    }
    let b = bin_of(project(a, 2u * x.x + x.z, 2u * x.y + x.z));
    let w = x.z * x.z;
    atomicAdd(&h_w[q * MAX_BINS + b], w | ((w * x.w) << 13u));
    atomicAdd(&h_s2[q * MAX_BINS + b], w * x.w * x.w);
}

// Bin b of slot q in the E loop: the lines after each non-empty bin but the last (left =
// bins ≤ b), e1 then its mirror e2, the first least kept.
fn e_step(q: u32, b: u32, total: vec3<u32>, left: ptr<function, vec3<u32>>, be: ptr<function, u32>, bk: ptr<function, u32>) {
    let m = bin_moments(q, b);
    if m.x == 0u {
        return;
    }
    *left += m;
    let right = total - *left;
    if right.x == 0u {
        return;
    }
    let e1 = (*left).z + err_one(right);
    let e2 = err_one(*left) + right.z;
    let wrong = params.wrong_ties != 0u;
    if e1 < *be || (wrong && e1 == *be) {
        *be = e1;
        *bk = 2u * b;
    }
    if e2 < *be || (wrong && e2 == *be) {
        *be = e2;
        *bk = 2u * b + 1u;
    }
}

fn e_reduce(q: u32, be: u32, bk: u32) {
    if be == atomicLoad(&red_e[q]) && be != NONE {
        atomicMin(&red_key[q], bk);
        atomicMax(&red_last[q], bk + 1u);
    }
}

fn next_step(q: u32, b: u32, eb: u32, sb: u32) {
    if atomicLoad(&h_w[q * MAX_BINS + b]) != 0u {
        if eb != NONE && b > eb {
            atomicMin(&next_e[q], b);
        }
        if sb != NONE && b > sb {
            atomicMin(&next_s[q], b);
        }
    }
}

// Slot q's winning key 2·bin + mirrored (NONE: no line).
fn slot_key(q: u32) -> u32 {
    var k = atomicLoad(&red_key[q]);
    if params.wrong_ties != 0u && k != NONE {
        k = atomicLoad(&red_last[q]) - 1u;
    }
    return k;
}

// Slot q's result: its E and lines (the line sits mid-gap, before the next non-empty bin).
fn slot_lines(s: Sweep, q: u32, a: u32, err: u32, key: u32, sb: u32) -> Sweep {
    var r = s;
    r.err = NONE;
    r.line = NONE;
    r.sline = NONE;
    if a == NONE {
        return r;
    }
    r.err = err;
    let o = params.offsets;
    if key != NONE {
        let off = ((key >> 1u) + atomicLoad(&next_e[q]) - 1u) / 2u;
        if (key & 1u) == 0u {
            r.line = a | (off << 16u);
        } else {
            // `LineCodec::mirror`.
            r.line = (a + params.half) | ((o - 1u - off) << 16u);
        }
    }
    if sb != NONE {
        let off = (sb + atomicLoad(&next_s[q]) - 1u) / 2u;
        r.sline = a | (off << 16u);
    }
    return r;
}

// Zeroes every histogram bin (before the first pass of a face).
fn clear_histograms(lid: u32) {
    for (var b = lid; b < SLOTS * MAX_BINS; b += WG) {
        atomicStore(&h_w[b], 0u);
        atomicStore(&h_s2[b], 0u);
    }
    spent += share(SLOTS * MAX_BINS) + 1u;
    workgroupBarrier();
}

struct Pass {
    s: array<Sweep, 4>,
}

// `sweep` at the angles of `angles` (each < half, NONE: unused), one pass for all: per
// angle the histogram of the cells over the offset bins, then E for every line between two
// non-empty bins, both orientations, in the CPU's offer order (bin, then e1 before its mirror
// e2): the first least E wins. Where E does not beat the constant, the children's deviation
// is ranked the same way.
fn sweep_pass(lid: u32, angles: vec4<u32>, arena: u32, base: u32, count: u32, total: vec3<u32>) -> Pass {
    let nb = params.offsets + 1u;
    let chunk = share(nb);
    // The histograms are zero here (`clear_histograms`, then each pass's last loop).
    if lid < SLOTS {
        atomicStore(&red_e[lid], NONE);
        atomicStore(&red_key[lid], NONE);
        atomicStore(&red_last[lid], 0u);
        atomicStore(&next_e[lid], NONE);
        atomicStore(&next_s[lid], NONE);
    }
    workgroupBarrier();
    for (var c = lid; c < count; c += WG) {
        let x = cell_unpack(work[arena + base + c]);
        hist_cell(0u, angles.x, x);
        hist_cell(1u, angles.y, x);
        hist_cell(2u, angles.z, x);
        hist_cell(3u, angles.w, x);
    }
    spent += share(count) + 1u;
    workgroupBarrier();
    // Each invocation's run of `chunk` bins; an exclusive prefix over the runs.
    let b0 = min(lid * chunk, nb);
    let b1 = min(b0 + chunk, nb);
    var own = array<vec2<u32>, 4>();
    for (var b = b0; b < b1; b++) {
        own[0] += vec2<u32>(atomicLoad(&h_w[b]), atomicLoad(&h_s2[b]));
        own[1] += vec2<u32>(atomicLoad(&h_w[MAX_BINS + b]), atomicLoad(&h_s2[MAX_BINS + b]));
        own[2] += vec2<u32>(atomicLoad(&h_w[2u * MAX_BINS + b]), atomicLoad(&h_s2[2u * MAX_BINS + b]));
        own[3] += vec2<u32>(atomicLoad(&h_w[3u * MAX_BINS + b]), atomicLoad(&h_s2[3u * MAX_BINS + b]));
    }
    spent += chunk + 1u;
    part[lid] = own[0];
    part[WG + lid] = own[1];
    part[2u * WG + lid] = own[2];
    part[3u * WG + lid] = own[3];
    workgroupBarrier();
    // Hillis–Steele, double-buffered (one barrier a step): 6 steps, from half 0 back to 0.
    var src = 0u;
    for (var d = 1u; d < WG; d <<= 1u) {
        let dst = SCAN - src;
        var v0 = part[src + lid];
        var v1 = part[src + WG + lid];
        var v2 = part[src + 2u * WG + lid];
        var v3 = part[src + 3u * WG + lid];
        if lid >= d {
            v0 += part[src + lid - d];
            v1 += part[src + WG + lid - d];
            v2 += part[src + 2u * WG + lid - d];
            v3 += part[src + 3u * WG + lid - d];
        }
        part[dst + lid] = v0;
        part[dst + WG + lid] = v1;
        part[dst + 2u * WG + lid] = v2;
        part[dst + 3u * WG + lid] = v3;
        workgroupBarrier();
        src = dst;
    }
    spent += 7u;
    var before = array<vec3<u32>, 4>(
        unpack_w(part[src + lid].x - own[0].x, part[src + lid].y - own[0].y),
        unpack_w(part[src + WG + lid].x - own[1].x, part[src + WG + lid].y - own[1].y),
        unpack_w(part[src + 2u * WG + lid].x - own[2].x, part[src + 2u * WG + lid].y - own[2].y),
        unpack_w(part[src + 3u * WG + lid].x - own[3].x, part[src + 3u * WG + lid].y - own[3].y),
    );
    var l0 = before[0];
    var l1 = before[1];
    var l2 = before[2];
    var l3 = before[3];
    var be0 = NONE;
    var be1 = NONE;
    var be2 = NONE;
    var be3 = NONE;
    var bk0 = NONE;
    var bk1 = NONE;
    var bk2 = NONE;
    var bk3 = NONE;
    for (var b = b0; b < b1; b++) {
        if angles.x != NONE {
            e_step(0u, b, total, &l0, &be0, &bk0);
        }
        if angles.y != NONE {
            e_step(1u, b, total, &l1, &be1, &bk1);
        }
        if angles.z != NONE {
            e_step(2u, b, total, &l2, &be2, &bk2);
        }
        if angles.w != NONE {
            e_step(3u, b, total, &l3, &be3, &bk3);
        }
    }
    spent += chunk + 1u;
    atomicMin(&red_e[0], be0);
    atomicMin(&red_e[1], be1);
    atomicMin(&red_e[2], be2);
    atomicMin(&red_e[3], be3);
    workgroupBarrier();
    e_reduce(0u, be0, bk0);
    e_reduce(1u, be1, bk1);
    e_reduce(2u, be2, bk2);
    e_reduce(3u, be3, bk3);
    workgroupBarrier();
    let constant = min(total.z, err_one(total));
    var r: Pass;
    var sb = vec4<u32>(NONE);
    let key = vec4<u32>(slot_key(0u), slot_key(1u), slot_key(2u), slot_key(3u));
    let err = vec4<u32>(atomicLoad(&red_e[0]), atomicLoad(&red_e[1]), atomicLoad(&red_e[2]), atomicLoad(&red_e[3]));
    let eb = select(key >> vec4<u32>(1u), vec4<u32>(NONE), key == vec4<u32>(NONE));
    // The slots whose E does not beat the constant rank the children's deviation.
    let ssd = angles != vec4<u32>(NONE) & err >= vec4<u32>(constant);
    for (var q = 0u; q < SLOTS && any(ssd); q++) {
        if !ssd[q] {
            continue;
        }
        // fit.rs `sweep`'s second loop: `offer_ssd` in bin order, first least kept.
        var left = before[q];
        var have = false;
        var best: Ratio;
        var bb = NONE;
        for (var b = b0; b < b1; b++) {
            let m = bin_moments(q, b);
            if m.x == 0u {
                continue;
            }
            left += m;
            let right = total - left;
            if right.x == 0u {
                continue;
            }
            let v = children_ssd(left, right);
            if !have || ratio_lt(v, best) {
                have = true;
                best = v;
                bb = b;
            }
        }
        spent += chunk + 1u;
        ssd_b[lid] = bb;
        ssd_num[lid] = best.num;
        ssd_den[lid] = best.den;
        workgroupBarrier();
        // A tree reduction: the lower ratio, then the lower bin.
        for (var d = WG / 2u; d > 0u; d >>= 1u) {
            if lid < d {
                let ob = ssd_b[lid + d];
                let mb = ssd_b[lid];
                if ob != NONE {
                    let o = Ratio(ssd_num[lid + d], ssd_den[lid + d]);
                    let me = Ratio(ssd_num[lid], ssd_den[lid]);
                    var take = mb == NONE;
                    if !take {
                        let x = mul128x64(o.num, me.den);
                        let y = mul128x64(me.num, o.den);
                        take = lt128(x, y) || (all(x == y) && ob < mb);
                    }
                    if take {
                        ssd_b[lid] = ob;
                        ssd_num[lid] = o.num;
                        ssd_den[lid] = o.den;
                    }
                }
            }
            workgroupBarrier();
        }
        spent += 7u;
        sb[q] = ssd_b[0];
        r.s[q].ssd = Ratio(ssd_num[0], ssd_den[0]);
        // Everyone has read the slot's result before the next slot's reduction writes.
        workgroupBarrier();
    }
    spent += select(0u, SLOTS + 1u, any(ssd));
    // The next non-empty bin after each winner: the line sits mid-gap.
    // The last reads of the invocation's own bins: it zeroes them for the next pass.
    for (var b = b0; b < b1; b++) {
        next_step(0u, b, eb.x, sb.x);
        next_step(1u, b, eb.y, sb.y);
        next_step(2u, b, eb.z, sb.z);
        next_step(3u, b, eb.w, sb.w);
        atomicStore(&h_w[b], 0u);
        atomicStore(&h_s2[b], 0u);
        atomicStore(&h_w[MAX_BINS + b], 0u);
        atomicStore(&h_s2[MAX_BINS + b], 0u);
        atomicStore(&h_w[2u * MAX_BINS + b], 0u);
        atomicStore(&h_s2[2u * MAX_BINS + b], 0u);
        atomicStore(&h_w[3u * MAX_BINS + b], 0u);
        atomicStore(&h_s2[3u * MAX_BINS + b], 0u);
    }
    spent += chunk + 1u;
    workgroupBarrier();
    r.s[0] = slot_lines(r.s[0], 0u, angles.x, err.x, key.x, sb.x);
    r.s[1] = slot_lines(r.s[1], 1u, angles.y, err.y, key.y, sb.y);
    r.s[2] = slot_lines(r.s[2], 2u, angles.z, err.z, key.z, sb.z);
    r.s[3] = slot_lines(r.s[3], 3u, angles.w, err.w, key.w, sb.w);
    // Everyone has read the shared results before the next pass clears them.
    workgroupBarrier();
    // What llvmpipe counts beyond the loops above (not understood; measured on lavapipe, Mesa
    // 22.3: the count fell 5-10 % short with 4 here, i.e. about 7 a pass; the canary in `main`
    // catches any shortfall).
    spent += 8u;
    return r;
}

// An angle's rank in `coarse_to_fine`: (0, E) where E beats the constant, else (1, the
// children's deviation); tier 2: no line (the deviation is infinite).
struct Score {
    tier: u32,
    err: u32,
    ssd: Ratio,
}

fn score_of(s: Sweep, constant: u32) -> Score {
    if s.err < constant {
        return Score(0u, s.err, s.ssd);
    }
    if s.sline == NONE {
        return Score(2u, 0u, s.ssd);
    }
    return Score(1u, 0u, s.ssd);
}

fn score_lt(a: Score, b: Score) -> bool {
    if a.tier != b.tier {
        return a.tier < b.tier;
    }
    if a.tier == 0u {
        return a.err < b.err;
    }
    if a.tier == 1u {
        return ratio_lt(a.ssd, b.ssd);
    }
    return false;
}

// `Best::take`.
fn take(best: ptr<function, Sweep>, s: Sweep) {
    if s.line != NONE && s.err < (*best).err {
        (*best).err = s.err;
        (*best).line = s.line;
    }
    if s.sline != NONE && ((*best).sline == NONE || ratio_lt(s.ssd, (*best).ssd)) {
        (*best).ssd = s.ssd;
        (*best).sline = s.sline;
    }
}

fn coarse_to_fine(lid: u32, arena: u32, base: u32, count: u32, total: vec3<u32>) -> u32 {
    let half = params.half;
    let step_coarse = half / 4u;
    let constant = min(total.z, err_one(total));
    var best: Sweep;
    best.err = NONE;
    best.line = NONE;
    best.sline = NONE;
    var start: Score;
    var a0 = NONE;
    // The 4 coarse angles in one pass, taken in the CPU's order.
    let coarse = sweep_pass(lid, vec4<u32>(0u, step_coarse, 2u * step_coarse, 3u * step_coarse), arena, base, count, total);
    for (var q = 0u; q < SLOTS; q++) {
        let s = coarse.s[q];
        let sc = score_of(s, constant);
        if a0 == NONE || score_lt(sc, start) {
            start = sc;
            a0 = q * step_coarse;
        }
        take(&best, s);
    }
    spent += SLOTS + 1u;
    var centre = a0;
    var cscore = start;
    for (var step = step_coarse / 2u; step > 0u; step /= 2u) {
        // Both candidates around the centre before either moves it: one pass.
        let c0 = (centre + step) % half;
        let c1 = (centre + half - step) % half;
        let two = sweep_pass(lid, vec4<u32>(c0, c1, NONE, NONE), arena, base, count, total);
        for (var q = 0u; q < 2u; q++) {
            let s = two.s[q];
            let sc = score_of(s, constant);
            if score_lt(sc, cscore) {
                centre = select(c1, c0, q == 0u);
                cscore = sc;
            }
            take(&best, s);
        }
        spent += 4u;
    }
    spent += 1u;
    // `Best::choose`.
    if best.err < constant {
        return best.line;
    }
    return best.sline;
}

// Sweeps per node (cell visits): 4 coarse angles, then two per bisection step.
fn sweeps() -> u32 {
    return 4u + 2u * firstTrailingBit(params.half / 4u);
}

// An upper bound on the loop iterations one node may still spend (its passes, partition,
// copies and leaf), checked before the node is started.
fn node_bound(count: u32) -> u32 {
    let cells = share(count);
    let chunk = share(params.offsets + 1u);
    let passes = 1u + firstTrailingBit(params.half / 4u);
    let per_pass = 4u * chunk + cells + SLOTS * (chunk + 9u) + 48u;
    return passes * per_pass + 4u * cells + 2048u;
}

// ---- The partition (fit.rs `partition`) ----

// Splits the node's cells by the line, exactly per pixel (a cell whose corner pixel centres
// are not all clearly on one side is split into quadrants), into the scratch (left from its
// start, right from its end), then back into the arena: right at `base`, left after it.
// Returns (left count, right count); the children's moments are left in `mom`.
fn split_cells(lid: u32, arena: u32, scratch: u32, base: u32, count: u32, line: u32) -> vec2<u32> {
    let cap = params.res * params.res;
    if lid == 0u {
        atomicStore(&ctr[1], 0u);
        atomicStore(&ctr[2], 0u);
        atomicStore(&ctr[3], 0u);
        for (var q = 0u; q < 6u; q++) {
            atomicStore(&mom[q], 0u);
        }
    }
    spent += 7u;
    workgroupBarrier();
    var iters = 0u;
    // One flat loop (a cell taken when the stack is empty): the lanes of a SIMD vector run
    // a loop until all are done, so nested loops would count each cell's pieces at the
    // most any lane needed, not at this lane's own count.
    var stack: array<u32, 16>;
    var sp = 0u;
    var next = lid;
    loop {
        if sp == 0u {
            if next >= count {
                break;
            }
            stack[0] = work[arena + base + next];
            sp = 1u;
            next += WG;
        }
        iters += 1u;
        {
            sp -= 1u;
            let cell = stack[sp];
            let x = cell_unpack(cell);
            var side = 0u; // 1 left, 2 right, 0 split
            if x.z == 1u {
                side = select(1u, 2u, distance(line, x.x, x.y) >= 0.0);
            } else {
                let e = x.z - 1u;
                let d0 = distance(line, x.x, x.y);
                let d1 = distance(line, x.x + e, x.y);
                let d2 = distance(line, x.x, x.y + e);
                let d3 = distance(line, x.x + e, x.y + e);
                if d0 >= MARGIN && d1 >= MARGIN && d2 >= MARGIN && d3 >= MARGIN {
                    side = 2u;
                } else if d0 < -MARGIN && d1 < -MARGIN && d2 < -MARGIN && d3 < -MARGIN {
                    side = 1u;
                }
            }
            if side == 0u {
                let h = x.z / 2u;
                stack[sp] = cell_pack(x.x, x.y, h, x.w);
                stack[sp + 1u] = cell_pack(x.x + h, x.y, h, x.w);
                stack[sp + 2u] = cell_pack(x.x, x.y + h, h, x.w);
                stack[sp + 3u] = cell_pack(x.x + h, x.y + h, h, x.w);
                sp += 4u;
                continue;
            }
            let w = x.z * x.z;
            if side == 2u {
                let at = atomicAdd(&ctr[2], 1u);
                work[scratch + cap - 1u - at] = cell;
                atomicAdd(&mom[3], w);
                atomicAdd(&mom[4], w * x.w);
                atomicAdd(&mom[5], w * x.w * x.w);
            } else {
                let at = atomicAdd(&ctr[1], 1u);
                work[scratch + at] = cell;
                atomicAdd(&mom[0], w);
                atomicAdd(&mom[1], w * x.w);
                atomicAdd(&mom[2], w * x.w * x.w);
            }
        }
    }
    atomicMax(&ctr[3], iters);
    storageBarrier();
    workgroupBarrier();
    let nl = atomicLoad(&ctr[1]);
    let nr = atomicLoad(&ctr[2]);
    spent += atomicLoad(&ctr[3]) + 1u;
    for (var q = lid; q < nr; q += WG) {
        work[arena + base + q] = work[scratch + cap - 1u - q];
    }
    for (var q = lid; q < nl; q += WG) {
        work[arena + base + nr + q] = work[scratch + q];
    }
    spent += share(nl) + share(nr) + 2u;
    storageBarrier();
    workgroupBarrier();
    return vec2<u32>(nl, nr);
}

// ---- The leaf (fit.rs `leaf`) ----

// value = round-half-up(255 Σk / (n S)) (255 for no pixel); the |error| numerator
// Σ w |255 k − value S| (abs_error = it / 255 S) and the misclassified pixels
// (2 |255 k − value S| > 255 S) are left in ctr[4], ctr[5].
fn leaf(lid: u32, arena: u32, base: u32, count: u32, m: vec3<u32>) -> u32 {
    let s = params.samples;
    var value = 255u;
    if m.x > 0u {
        value = (510u * m.y + m.x * s) / (2u * m.x * s);
    }
    if lid == 0u {
        atomicStore(&ctr[4], 0u);
        atomicStore(&ctr[5], 0u);
    }
    workgroupBarrier();
    var abs_sum = 0u;
    var mis = 0u;
    for (var c = lid; c < count; c += WG) {
        let x = cell_unpack(work[arena + base + c]);
        let w = x.z * x.z;
        let a = 255u * x.w;
        let b = value * s;
        let d = select(b - a, a - b, a >= b);
        abs_sum += w * d;
        if 2u * d > 255u * s {
            mis += w;
        }
    }
    spent += share(count) + 1u;
    atomicAdd(&ctr[4], abs_sum);
    atomicAdd(&ctr[5], mis);
    workgroupBarrier();
    return value;
}

// ---- The tree (fit.rs `build`), depth first with an explicit stack ----

@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let face = wid.x;
    spent = 0u;
    let res = params.res;
    let lv = face * params.work_words;
    let arena = lv + params.level_words;
    let scratch = arena + res * res;
    let ob = face * params.out_words;
    let count = build_cells(lid, face, lv, arena);
    clear_histograms(lid);
    let root = vec3<u32>(atomicLoad(&mom[0]), atomicLoad(&mom[1]), atomicLoad(&mom[2]));
    workgroupBarrier();
    // The stack: base, count, depth, n, Σk, Σk², node to patch with this node's index.
    var st_base: array<u32, STACK>;
    var st_count: array<u32, STACK>;
    var st_depth: array<u32, STACK>;
    var st_m: array<vec3<u32>, STACK>;
    var st_patch: array<u32, STACK>;
    st_base[0] = 0u;
    st_count[0] = count;
    st_depth[0] = 0u;
    st_m[0] = root;
    st_patch[0] = NONE;
    var sp = 1u;
    var nodes = 0u;
    var flag = 0u;
    var visits = 0u;
    var pixels = 0u;
    var mis = 0u;
    var leaves = 0u;
    let t_fx = vec2<u32>(params.t_fx_lo, params.t_fx_hi);
    loop {
        if sp == 0u {
            break;
        }
        spent += 1u;
        sp -= 1u;
        let base = st_base[sp];
        let n_cells = st_count[sp];
        let depth = st_depth[sp];
        let m = st_m[sp];
        let to_patch = st_patch[sp];
        if to_patch != NONE && lid == 0u {
            out[ob + HEADER + 2u * to_patch + 1u] = nodes;
        }
        if nodes >= params.max_nodes {
            flag = FLAG_NODES;
            break;
        }
        if spent + node_bound(n_cells) > params.budget {
            flag = FLAG_BUDGET;
            break;
        }
        // The leaf test: D · 2¹⁶ ≤ T_fx · n, or the depth limit.
        let d = dev(m);
        let lhs = vec4<u32>(d.x << 16u, (d.y << 16u) | (d.x >> 16u), d.y >> 16u, 0u);
        var is_leaf = depth >= MAX_DEPTH || !lt128(mul64x32(t_fx, m.x), lhs);
        var line = NONE;
        if !is_leaf {
            line = coarse_to_fine(lid, arena, base, n_cells, m);
            visits += sweeps() * n_cells;
        }
        var leaf_count = n_cells;
        if line != NONE {
            let lr = split_cells(lid, arena, scratch, base, n_cells, line);
            leaf_count = lr.x + lr.y;
            if lr.x > 0u && lr.y > 0u {
                let ml = vec3<u32>(atomicLoad(&mom[0]), atomicLoad(&mom[1]), atomicLoad(&mom[2]));
                let mr = vec3<u32>(atomicLoad(&mom[3]), atomicLoad(&mom[4]), atomicLoad(&mom[5]));
                workgroupBarrier();
                if sp + 2u > STACK {
                    flag = FLAG_STACK;
                    break;
                }
                if lid == 0u {
                    out[ob + HEADER + 2u * nodes] = line;
                    out[ob + HEADER + 2u * nodes + 1u] = 0u;
                }
                st_base[sp] = base;
                st_count[sp] = lr.y;
                st_depth[sp] = depth + 1u;
                st_m[sp] = mr;
                st_patch[sp] = nodes;
                st_base[sp + 1u] = base + lr.y;
                st_count[sp + 1u] = lr.x;
                st_depth[sp + 1u] = depth + 1u;
                st_m[sp + 1u] = ml;
                st_patch[sp + 1u] = NONE;
                sp += 2u;
                nodes += 1u;
                continue;
            }
        }
        let value = leaf(lid, arena, base, leaf_count, m);
        if lid == 0u {
            out[ob + HEADER + 2u * nodes] = LEAF | value;
            out[ob + HEADER + 2u * nodes + 1u] = atomicLoad(&ctr[4]);
        }
        mis += atomicLoad(&ctr[5]);
        workgroupBarrier();
        pixels += m.x;
        leaves += 1u;
        nodes += 1u;
    }
    spent += 1u;
    // The canary: once llvmpipe's limiter has run out, every loop ends after one pass, so a
    // loop of `canary` (2, not known to the compiler: not unrolled) passes that ends early
    // shows that some loop before it was cut short: nothing of this face is trusted.
    var passes = 0u;
    for (var q = 0u; q < params.canary; q++) {
        passes += 1u;
    }
    if passes != params.canary {
        flag = FLAG_LIMIT;
    }
    if lid == 0u {
        out[ob + 0u] = flag;
        out[ob + 1u] = nodes;
        out[ob + 2u] = visits;
        out[ob + 3u] = pixels;
        out[ob + 4u] = mis;
        out[ob + 5u] = leaves;
        out[ob + 6u] = spent;
        out[ob + 7u] = 0u;
    }
}
