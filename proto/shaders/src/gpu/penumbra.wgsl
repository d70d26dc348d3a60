// rt-penumbra's edge-aware blur (paper 003) on the GPU, the twin of the CPU's
// `client/src/penumbra/blur.rs`: one invocation per pixel and stage, each stage a dispatch —
// the edge pixels' half-widths (`edge_radius`), their spread along rows then columns
// (`spread_radius`, here a gather: a pixel takes the largest width of the same-surface pixels
// whose box reaches it, the CPU's scatter read the other way), then the tent as two boxes of
// half-width r/√2 along rows, then two along columns (`blur`). A box reads the centre's run of
// one surface along the line, its taps past the run's ends clamped to them; the CPU sums it
// from prefix sums along the line, here the taps are walked (at most 2·⌈cap⌉ + 1 of them), so
// no invocation loops over a whole line (llvmpipe ends an invocation after 65,535 loop
// iterations).

// Per pixel three vec4: the world position and 1 (0: background); the unit shading normal and
// the view depth; the world length one pixel covers along x and along y (GuidePixel::step).
@group(0) @binding(0) var<storage, read> guide: array<vec4<f32>>;
// The values the stage reads: the hard shadow (edge), the pixels' own half-widths (spread), or
// the values being blurred (box).
@group(0) @binding(1) var<storage, read> values: array<f32>;
// World half-widths: each pixel's (edge), the widths being spread (spread), the blur's (box).
@group(0) @binding(2) var<storage, read> widths: array<f32>;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;
struct BlurParams {
    // width, height, stage (0 edge, 1 spread, 2 box, 3 spread within the pixels' own widths),
    // axis (0 rows, 1 columns).
    shape: vec4<u32>,
    // cap (pixels), plane tolerance, normal cosine, the scale of the widths (1/√2 for a box of
    // the tent).
    limits: vec4<f32>,
}
// Storage, not uniform (lavapipe specializes a shader on uniform values: docs/gpu.md).
@group(0) @binding(4) var<storage, read> bp: BlurParams;
// 1 per sharp pixel (blur::sharp_pixels: a contact's umbra, with the light split): a box's run
// never joins a sharp pixel and one that is not.
@group(0) @binding(5) var<storage, read> sharp: array<u32>;

const F32_MAX: f32 = 3.40282347e38;

fn valid(i: u32) -> bool {
    return guide[3u * i].w != 0.0;
}

// Guide::same_surface(c, q): q near c's tangent plane (relative to c's view depth) and with a
// similar normal.
fn same_surface(c: u32, q: u32) -> bool {
    let cn = guide[3u * c + 1u];
    let qn = guide[3u * q + 1u];
    let plane = abs(dot(cn.xyz, guide[3u * q].xyz - guide[3u * c].xyz));
    return plane <= bp.limits.y * cn.w && dot(cn.xyz, qn.xyz) >= bp.limits.z;
}

// Two neighbours along a line are one surface both ways, and both sharp or neither (blur_pass's
// runs).
fn joined(a: u32, b: u32) -> bool {
    return valid(a) && valid(b) && same_surface(a, b) && same_surface(b, a) && sharp[a] == sharp[b];
}

// GuidePixel::pixels: a world half-width in pixels along the stage's axis, capped.
fn pixels(i: u32, half_width: f32) -> f32 {
    let r = half_width / guide[3u * i + 2u][bp.shape.w];
    let cap = max(bp.limits.x, 0.0);
    if r <= F32_MAX && r >= -F32_MAX {
        return clamp(r, 0.0, cap);
    }
    return select(0.0, cap, r > 0.0);
}

// Pixel i's place along the stage's axis, the line's length and the index step along it.
struct Line {
    at: i32,
    len: i32,
    stride: i32,
}

fn line_of(i: u32) -> Line {
    if bp.shape.w == 0u {
        return Line(i32(i % bp.shape.x), i32(bp.shape.x), 1);
    }
    return Line(i32(i / bp.shape.x), i32(bp.shape.y), i32(bp.shape.x));
}

// Pixel `t` steps along the line from `i` (t may be negative), or -1 past the image's edge.
fn along(i: u32, l: Line, t: i32) -> i32 {
    let a = l.at + t;
    if a < 0 || a >= l.len {
        return -1;
    }
    return i32(i) + t * l.stride;
}

// edge_radius: the half-width of an occluded pixel with a same-surface 4-neighbour that sees
// more of the light.
fn edge(i: u32) -> f32 {
    if !valid(i) || values[i] >= 1.0 {
        return 0.0;
    }
    let w = i32(bp.shape.x);
    let h = i32(bp.shape.y);
    let x = i32(i % bp.shape.x);
    let y = i32(i / bp.shape.x);
    let d = array<vec2<i32>, 4>(vec2<i32>(-1, 0), vec2<i32>(1, 0), vec2<i32>(0, -1), vec2<i32>(0, 1));
    for (var k = 0u; k < 4u; k++) {
        let q = vec2<i32>(x, y) + d[k];
        if q.x < 0 || q.y < 0 || q.x >= w || q.y >= h {
            continue;
        }
        let j = u32(q.y * w + q.x);
        if values[j] > values[i] && valid(j) && same_surface(i, j) {
            return widths[i];
        }
    }
    return 0.0;
}

// spread_pass: the largest width among same-surface pixels q on the line whose box (⌊pixels⌋
// of their own width) reaches this one, its own included; `within` (the light split): a pixel
// with a width of its own (`values`, the pixels' own half-widths, in the spread stages) takes
// only the q within it.
fn spread(i: u32, within: bool) -> f32 {
    var best = widths[i];
    if !valid(i) {
        return best;
    }
    var reach = i32(floor(max(bp.limits.x, 0.0)));
    let own = values[i];
    if within && own > 0.0 {
        reach = min(reach, i32(floor(pixels(i, own))));
    }
    let l = line_of(i);
    for (var d = 1; d <= reach; d++) {
        for (var s = -1; s <= 1; s += 2) {
            let q = along(i, l, s * d);
            if q < 0 {
                continue;
            }
            let r = widths[q];
            if r > best && valid(u32(q)) && i32(floor(pixels(u32(q), r))) >= d && same_surface(i, u32(q)) {
                best = r;
            }
        }
    }
    return best;
}

// One box of blur_pass at pixel i: taps at distance k ≥ 1 weigh clamp(r + ½ − k, 0, 1), taps
// past the centre's run of one surface take the run end's value.
fn box_blur(i: u32) -> f32 {
    if !valid(i) {
        return values[i];
    }
    let r = pixels(i, widths[i] * bp.limits.w);
    if r < 0.5 {
        return values[i];
    }
    let full = i32(floor(r - 0.5));
    let frac = r + 0.5 - f32(full + 1);
    var sum = values[i];
    let l = line_of(i);
    for (var s = -1; s <= 1; s += 2) {
        // Walk out along the run to full + 1 taps; past its end, the end's value.
        var last = i32(i);
        var v_end = values[i];
        var open = true;
        for (var k = 1; k <= full + 1; k++) {
            if open {
                let q = along(i, l, s * k);
                if q < 0 || !joined(u32(last), u32(q)) {
                    open = false;
                } else {
                    last = q;
                    v_end = values[q];
                }
            }
            let weight = select(1.0, frac, k == full + 1);
            sum += weight * v_end;
        }
    }
    return sum / (f32(2 * full + 1) + 2.0 * frac);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = bp.shape.x * bp.shape.y;
    let i = gid.x + gid.y * 65535u * 64u;
    if i >= n {
        return;
    }
    switch bp.shape.z {
        case 0u: {
            out[i] = edge(i);
        }
        case 1u: {
            out[i] = spread(i, false);
        }
        case 3u: {
            out[i] = spread(i, true);
        }
        default: {
            out[i] = box_blur(i);
        }
    }
}
