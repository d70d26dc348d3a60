//! The spatially varying, edge-aware blur of a screen-space shadow buffer.
//!
//! Each pixel p has its own half-width W(p)/2 in world units, which becomes a radius in
//! pixels per axis: W/2 over the world length one pixel covers on p's tangent plane along that
//! axis (the footprint at p's view depth, grown by the receiver's slope), capped at
//! [`Params::max_radius`] pixels. The hard shadow of the light's centre is convolved with the
//! light's image scaled by (Z_r − Z_o)/Z_o, which is what the similar-triangles width
//! describes: a box of that half-width for a square light along the screen's axes, here a tent
//! of the same second moment (two boxes of half-width r/√2, [`blur`]), applied separably, with
//! fractional coverage at the boxes' ends so the width varies smoothly. A box reads only the
//! centre's run of one surface along the line — up to the first pair of neighbours not on one
//! surface (depth off the tangent plane, or a different normal: [`Guide::same_surface`]) — so
//! shadows do not bleed across depth or normal discontinuities; taps past the run's ends take
//! the end's value (the surface goes on, hidden or off screen); prefix sums give each pixel's
//! box in O(1) at any width.
//!
//! Only occluded pixels know a width (the occluder distance comes from their shadow ray). The
//! penumbra is centred on the hard shadow's edge and extends onto the lit side too, and its
//! width is the one of the rays that graze the occluder's silhouette — those of the occluded
//! pixels on the hard shadow's edge (deeper in the umbra the first hit lies nearer the light
//! and would overestimate W). So before blurring, the edge pixels' radii are spread: each
//! pixel takes the largest radius of the same-surface edge pixels whose box reaches it
//! ([`edge_radius`], [`spread_radius`], separable).

use rayon::prelude::*;

use glam::DVec3;

use super::{Guide, Params};
use crate::frame::camera::View;
use crate::light::Light;

type Widths = [f64];

/// The half-width of occluded pixels (`hard` < 1) with a same-surface 4-neighbour that sees
/// more of the light (lit, for a hard shadow of one point); 0 elsewhere.
pub(crate) fn edge_radius(
    hard: &[f32],
    radius: &Widths,
    guide: &Guide,
    params: &Params,
) -> Vec<f64> {
    let (w, h) = (guide.width as isize, guide.height as isize);
    (0..hard.len())
        .into_par_iter()
        .map(|i| {
            let Some(c) = &guide.pixels[i] else {
                return 0.0;
            };
            if hard[i] >= 1.0 {
                return 0.0;
            }
            let (x, y) = ((i as isize) % w, (i as isize) / w);
            let edge = [(-1, 0), (1, 0), (0, -1), (0, 1)].iter().any(|&(dx, dy)| {
                let (qx, qy) = (x + dx, y + dy);
                if qx < 0 || qy < 0 || qx >= w || qy >= h {
                    return false;
                }
                let j = (qy * w + qx) as usize;
                hard[j] > hard[i]
                    && guide.pixels[j]
                        .as_ref()
                        .is_some_and(|q| guide.same_surface(c, q, params))
            });
            if edge { radius[i] } else { 0.0 }
        })
        .collect()
}

/// Largest half-width among same-surface pixels q whose box reaches p (|p − q| ≤ q's radius in
/// pixels along each axis; p's own included), in two separable passes. The boxes reach at most
/// `params.max_radius` pixels.
///
/// `within`: per pixel, a half-width of its own (0: none); a pixel that has one takes a q's
/// only when |p − q| is also within it. Where the light is split ([`super::rt::split_light`])
/// every blocked pixel knows its own parts' width, and a penumbra reaches into the umbra only
/// as far as the width there: at a contact (an occluder touching the receiver, its penumbra
/// narrowing to 0) a wider edge further along no longer lifts the umbra (docs/penumbra.md,
/// "The spread within a pixel's own width").
pub(crate) fn spread_radius(
    radius: &Widths,
    within: Option<&Widths>,
    guide: &Guide,
    params: &Params,
) -> Vec<f64> {
    let h = spread_pass(radius, within, guide, params, true);
    spread_pass(&h, within, guide, params, false)
}

/// One pass of [`spread_radius`] along rows (`horizontal`) or columns. A scatter from the
/// pixels with a width: only the few near a hard shadow's edge have one, so the pass costs
/// their boxes, not a search around every pixel. Lines are independent (run in parallel);
/// the max is order-free, so the result does not depend on the schedule.
fn spread_pass(
    radius: &Widths,
    within: Option<&Widths>,
    guide: &Guide,
    params: &Params,
    horizontal: bool,
) -> Vec<f64> {
    let lines = Lines::of(guide, horizontal);
    let (len, at) = (lines.len, |line, t| lines.index(line, t));
    let cap = params.max_radius;
    lines.update(radius, |line| {
        let mut grown = Vec::new();
        let mut best: Vec<f64> = Vec::new();
        for t in 0..len {
            let r = radius[at(line, t)];
            if !(r > 0.0) {
                continue;
            }
            let Some(q) = &guide.pixels[at(line, t)] else {
                continue;
            };
            if best.is_empty() {
                best = (0..len).map(|u| radius[at(line, u)]).collect();
            }
            let n = q.pixels(r, horizontal, cap).floor() as usize;
            let (lo, hi) = (t.saturating_sub(n), (t + n).min(len - 1));
            for u in (lo..=hi).filter(|&u| u != t) {
                if r > best[u]
                    && let Some(c) = &guide.pixels[at(line, u)]
                    && guide.same_surface(c, q, params)
                    && within.is_none_or(|own| {
                        let own = own[at(line, u)];
                        !(own > 0.0) || c.pixels(own, horizontal, cap) >= u.abs_diff(t) as f64
                    })
                {
                    best[u] = r;
                    grown.push(u);
                }
            }
        }
        grown.sort_unstable();
        grown.dedup();
        grown.into_iter().map(|u| (at(line, u), best[u])).collect()
    })
}

/// The soft shadow's kernel at every pixel p: a tent (a box convolved with itself) with the
/// second moment of a box of world half-width `radius[p]` — two boxes of half-width r/√2 —
/// separable (rows twice, then columns twice) and edge-aware. Background pixels keep their
/// value and are never sampled.
///
/// Why not the box itself: the box's linear ramp is the penumbra of a square light whose
/// sides run along the screen's axes; seen at other angles (and through perspective) the
/// light's image blurs the ramp's ends, which the tent does. On `bench-penumbra --ref-spp 512`
/// (2026-11-30) the tent lowers rt-penumbra's RMSE by 2–25 % (plate-small base 0.00508 →
/// 0.00402, contact 0.00463 → 0.00348, teapot 0.00459 → 0.00418, bunny 0.00403 → 0.00394)
/// and raises it 3 % where two penumbrae of different widths overlap (0.00352 → 0.00362);
/// three boxes (closer to a Gaussian) are no better and cost more.
///
/// `sharp` ([`sharp_pixels`]): a run of one surface also stops between a sharp pixel and one
/// that is not.
pub(crate) fn blur(
    values: &[f32],
    radius: &Widths,
    sharp: Option<&[bool]>,
    guide: &Guide,
    params: &Params,
) -> Vec<f32> {
    let half: Vec<f64> = radius
        .iter()
        .map(|r| r * std::f64::consts::FRAC_1_SQRT_2)
        .collect();
    let rows = blur_pass(values, &half, sharp, guide, params, true, 2);
    blur_pass(&rows, &half, sharp, guide, params, false, 2)
}

/// Each blocked pixel's own half-width, where it has one: with the light split
/// ([`super::rt::split_light`], `params.split` > 1) `radius` is the mean of the pixel's blocked
/// parts' widths; with one ray (paper 003 as published) it is the centre ray's, which knows
/// nothing of the pixel's own penumbra, and `None`. What [`spread_radius`]'s `within` and
/// [`sharp_pixels`] read; the one place that decides it for the CPU and the GPU.
pub(crate) fn own_widths<'a>(radius: &'a Widths, params: &Params) -> Option<&'a Widths> {
    (params.split > 1).then_some(radius)
}

/// The blocked pixels (`hard` < 1) whose own width (`own`, [`own_widths`]) spans less than
/// half a pixel along both axes: their rays found the occluder touching the receiver — a
/// contact, whose shadow has an edge as sharp as the rays resolve it (the parts' penumbrae all
/// narrow to 0 there). The blur reads across no such edge ([`blur`]): a tent on the lit side of
/// a contact would read the umbra's 0 and round the step the rays found (docs/penumbra.md,
/// "Contacts stay sharp"). `None` without own widths.
pub(crate) fn sharp_pixels(
    hard: &[f32],
    own: Option<&Widths>,
    guide: &Guide,
    params: &Params,
) -> Option<Vec<bool>> {
    let own = own?;
    let cap = params.max_radius;
    Some(
        (0..hard.len())
            .into_par_iter()
            .map(|i| {
                let r = own.get(i).copied().unwrap_or(0.0);
                hard[i] < 1.0
                    && r > 0.0
                    && guide.pixels[i]
                        .as_ref()
                        .is_some_and(|g| g.pixels(r, true, cap).max(g.pixels(r, false, cap)) < 0.5)
            })
            .collect(),
    )
}

/// `boxes` box blurs, one after the other, along rows (`horizontal`) or columns. Each box is
/// summed over the centre's run of one surface along the line (neighbours on the same surface
/// both ways, [`Guide::same_surface`]; found once for all the boxes), its taps past the run's
/// ends clamped to them, from prefix sums: O(1) per pixel at any width. Lines are independent
/// (run in parallel).
fn blur_pass(
    values: &[f32],
    radius: &Widths,
    sharp: Option<&[bool]>,
    guide: &Guide,
    params: &Params,
    horizontal: bool,
    boxes: usize,
) -> Vec<f32> {
    let lines = Lines::of(guide, horizontal);
    let (len, at) = (lines.len, |line, t| lines.index(line, t));
    let cap = params.max_radius.max(0.0);
    lines.update(values, |line| {
        let px = |t: usize| guide.pixels[at(line, t)].as_ref();
        // Each centre's radius in pixels along the line (< ½: only the centre).
        let r: Vec<f64> = (0..len)
            .map(|t| px(t).map_or(0.0, |c| c.pixels(radius[at(line, t)], horizontal, cap)))
            .collect();
        if r.iter().all(|&r| r < 0.5) {
            return Vec::new();
        }
        // The first and last tap of each pixel's run of one surface (the same for every box).
        let mut start = vec![0usize; len];
        for t in 1..len {
            let joined = match (px(t - 1), px(t)) {
                (Some(a), Some(b)) => {
                    guide.same_surface(a, b, params)
                        && guide.same_surface(b, a, params)
                        && sharp.is_none_or(|m| m[at(line, t - 1)] == m[at(line, t)])
                }
                _ => false,
            };
            start[t] = if joined { start[t - 1] } else { t };
        }
        let mut end = vec![len - 1; len];
        for t in (0..len - 1).rev() {
            end[t] = if start[t + 1] == start[t] {
                end[t + 1]
            } else {
                t
            };
        }
        let blurred: Vec<usize> = (0..len)
            .filter(|&t| r[t] >= 0.5 && px(t).is_some())
            .collect();
        let mut v: Vec<f64> = (0..len).map(|t| f64::from(values[at(line, t)])).collect();
        let mut sum = vec![0.0f64; len + 1];
        let mut next = v.clone();
        for _ in 0..boxes {
            for t in 0..len {
                sum[t + 1] = sum[t] + v[t];
            }
            for &t in &blurred {
                // Taps at distance k ≥ 1 weigh clamp(r + ½ − k, 0, 1): 1 up to
                // full = ⌊r − ½⌋, then one tap of weight frac.
                let full = (r[t] - 0.5).floor() as usize;
                let frac = r[t] + 0.5 - (full + 1) as f64;
                let (first, last) = (start[t], end[t]);
                let (lo, hi) = (t.saturating_sub(full).max(first), (t + full).min(last));
                // Taps beyond the run take its end's value (clamp to edge): the surface goes
                // on behind the occluder or past the border, and its hard shadow most likely
                // with it. Renormalising over the taps that are left instead biases the box
                // toward whatever lies on the open side (a shadow on a floor pixel just below
                // a floating sphere: RMSE 0.00577 → 0.00508 on plate-small, docs/penumbra.md).
                let (v_first, v_last) = (v[first], v[last]);
                let mut s = sum[hi + 1] - sum[lo]
                    + (full - (t - lo)) as f64 * v_first
                    + (full - (hi - t)) as f64 * v_last;
                let mut n = (2 * full + 1) as f64;
                if frac > 0.0 {
                    let left = t
                        .checked_sub(full + 1)
                        .filter(|&u| u >= first)
                        .map_or(v_first, |u| v[u]);
                    let right = if t + full < last {
                        v[t + full + 1]
                    } else {
                        v_last
                    };
                    s += frac * (left + right);
                    n += 2.0 * frac;
                }
                next[t] = s / n;
            }
            v.copy_from_slice(&next);
        }
        blurred
            .into_iter()
            .map(|t| (at(line, t), v[t] as f32))
            .collect()
    })
}

/// An image's rows (`horizontal`) or columns, as the separable passes walk them.
#[derive(Clone, Copy)]
struct Lines {
    width: usize,
    count: usize,
    /// Pixels per line.
    len: usize,
    horizontal: bool,
}

impl Lines {
    fn of(guide: &Guide, horizontal: bool) -> Lines {
        let (w, h) = (guide.width, guide.height);
        Lines {
            width: w,
            count: if horizontal { h } else { w },
            len: if horizontal { w } else { h },
            horizontal,
        }
    }

    /// The row-major index of pixel `t` of line `line`.
    #[inline]
    fn index(self, line: usize, t: usize) -> usize {
        if self.horizontal {
            line * self.width + t
        } else {
            t * self.width + line
        }
    }

    /// `base` with the (index, value) pairs each line's `f` returns written over it; the lines
    /// run in parallel.
    fn update<T: Copy + Send + Sync>(
        self,
        base: &[T],
        f: impl Fn(usize) -> Vec<(usize, T)> + Sync + Send,
    ) -> Vec<T> {
        let changed: Vec<Vec<(usize, T)>> = (0..self.count).into_par_iter().map(f).collect();
        let mut out = base.to_vec();
        for (i, v) in changed.into_iter().flatten() {
            out[i] = v;
        }
        out
    }
}

/// Light-shaped gather: the hard shadow from the light's centroid c, shifted by
/// κ (q − c) for light points q, is the hard shadow from q (similar triangles, κ =
/// (Z_r − Z_o) / Z_o = W / W_light); their mean over the light is the soft shadow. `offsets`:
/// q − c for points q spread over the light. Each offset is projected onto the receiver's
/// tangent plane along the direction to the light, then to the screen; when the kernel exceeds
/// `params.max_radius` pixels it is scaled down to it (the cap). Taps on other surfaces are
/// skipped ([`Guide::same_surface`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn light_blur(
    hard: &[f32],
    half_width: &Widths,
    guide: &Guide,
    view: &View,
    centre: DVec3,
    offsets: &[DVec3],
    w_light: f64,
    params: &Params,
) -> Vec<f32> {
    let (w, h) = (guide.width as isize, guide.height as isize);
    let cap = params.max_radius.max(0.0);
    (0..hard.len())
        .into_par_iter()
        .map(|i| {
            let own = hard[i];
            let Some(c) = &guide.pixels[i] else {
                return own;
            };
            let hw = half_width[i];
            if !(hw > 0.0) || !(w_light > 0.0) || offsets.is_empty() {
                return own;
            }
            // κ = W / W_light; an occluder at the light gives κ → ∞: bounded by the cap below.
            let kappa = (2.0 * hw / w_light).min(1e6);
            let l = (centre - c.position).normalize_or(c.geometric);
            let n = c.geometric;
            let nl = n.dot(l);
            let nl = if nl.abs() < 0.05 {
                0.05f64.copysign(nl)
            } else {
                nl
            };
            let (px, py) = ((i as isize % w) as f64 + 0.5, (i as isize / w) as f64 + 0.5);
            let taps: Vec<(f64, f64)> = offsets
                .iter()
                .filter_map(|&o| {
                    let o = o * kappa;
                    let o = o - l * (n.dot(o) / nl);
                    let cam = view.to_camera(c.position + o);
                    if !(cam.z > 0.0) {
                        return None;
                    }
                    let (x, y) = view.to_image(cam);
                    let d = (x - px, y - py);
                    (d.0.is_finite() && d.1.is_finite()).then_some(d)
                })
                .collect();
            let longest = taps.iter().map(|d| d.0.hypot(d.1)).fold(0.0, f64::max);
            let scale = if longest > cap { cap / longest } else { 1.0 };
            let (mut sum, mut n) = (0.0f64, 0u32);
            for (dx, dy) in taps {
                let (qx, qy) = (
                    (px + dx * scale).floor() as isize,
                    (py + dy * scale).floor() as isize,
                );
                if qx < 0 || qy < 0 || qx >= w || qy >= h {
                    continue;
                }
                let j = (qy * w + qx) as usize;
                if let Some(q) = &guide.pixels[j]
                    && guide.same_surface(c, q, params)
                {
                    sum += f64::from(hard[j]);
                    n += 1;
                }
            }
            if n == 0 {
                own
            } else {
                (sum / f64::from(n)) as f32
            }
        })
        .collect()
}

/// `n` × `n` points q − c spread over the light polygon (a grid over its bounding rectangle
/// in its plane, kept where inside the convex polygon), relative to its centroid c.
pub(crate) fn light_offsets(light: &Light, n: usize) -> Vec<DVec3> {
    let v = &light.vertices;
    if v.len() < 3 || n == 0 {
        return Vec::new();
    }
    let c = light.centroid();
    let e1 = (v[1] - v[0]).normalize_or(DVec3::X);
    let e2 = light.normal.cross(e1).normalize_or(DVec3::Y);
    let uv: Vec<(f64, f64)> = v
        .iter()
        .map(|&p| ((p - c).dot(e1), (p - c).dot(e2)))
        .collect();
    let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
    for &(a, b) in &uv {
        lo = (lo.0.min(a), lo.1.min(b));
        hi = (hi.0.max(a), hi.1.max(b));
    }
    // Inside a convex polygon: the same side of every edge (either winding).
    let inside = |a: f64, b: f64| {
        let mut sign = 0.0f64;
        for k in 0..uv.len() {
            let (p, q) = (uv[k], uv[(k + 1) % uv.len()]);
            let cross = (q.0 - p.0) * (b - p.1) - (q.1 - p.1) * (a - p.0);
            if cross.abs() < 1e-15 {
                continue;
            }
            if sign == 0.0 {
                sign = cross.signum();
            } else if cross.signum() != sign {
                return false;
            }
        }
        true
    };
    let mut out = Vec::with_capacity(n * n);
    for i in 0..n {
        for j in 0..n {
            let a = lo.0 + (hi.0 - lo.0) * (i as f64 + 0.5) / n as f64;
            let b = lo.1 + (hi.1 - lo.1) * (j as f64 + 0.5) / n as f64;
            if inside(a, b) {
                out.push(e1 * a + e2 * b);
            }
        }
    }
    out
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::penumbra::GuidePixel;

    /// A 32 × 8 image: the left half a wall facing the camera at depth 1, the right half at
    /// depth 3 (a depth discontinuity), or tilted (a normal discontinuity).
    fn guide(tilt_right: bool) -> Guide {
        let (w, h) = (32usize, 8usize);
        let pixels = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let right = x >= 16.0;
                let depth = if right && !tilt_right { 3.0 } else { 1.0 };
                let normal = if right && tilt_right {
                    DVec3::new(0.8, 0.0, -0.6)
                } else {
                    DVec3::NEG_Z
                };
                Some(GuidePixel {
                    position: DVec3::new(0.01 * x * depth, 0.01 * y * depth, depth),
                    normal,
                    geometric: normal,
                    depth,
                    step: [0.01 * depth; 2],
                })
            })
            .collect();
        Guide {
            width: w,
            height: h,
            pixels,
            footprint_per_depth: 0.01,
            id: Guide::next_id(),
        }
    }

    /// The same 32 × 8 image as one wall at depth 1 (one continuous surface).
    pub(crate) fn flat() -> Guide {
        let mut g = guide(false);
        for px in g.pixels.iter_mut().flatten() {
            px.depth = 1.0;
            px.position.z = 1.0;
            px.step = [0.01; 2];
        }
        g
    }

    #[test]
    fn no_bleeding_across_depth_or_normal_discontinuities() {
        let p = Params::default();
        for tilt in [false, true] {
            let g = guide(tilt);
            // Left half shadowed, right half lit; a huge width everywhere.
            let values: Vec<f32> = (0..g.pixels.len())
                .map(|i| if i % 32 < 16 { 0.0 } else { 1.0 })
                .collect();
            let radius = vec![1.0; values.len()];
            let out = blur(&values, &radius, None, &g, &p);
            assert_eq!(out, values, "tilt {tilt}: bled across the discontinuity");
        }
        // The same edge on one continuous surface is blurred (the test can fail).
        let g = flat();
        let values: Vec<f32> = (0..g.pixels.len())
            .map(|i| if i % 32 < 16 { 0.0 } else { 1.0 })
            .collect();
        let out = blur(&values, &vec![0.04; values.len()], None, &g, &p);
        assert!(out[16] < 0.9 && out[15] > 0.1, "{} {}", out[15], out[16]);
    }

    /// On one continuous surface the prefix-sum box equals the box summed tap by tap: the
    /// centre with weight 1, tap k with clamp(r + ½ − |k|, 0, 1), a tap past the image's
    /// border reading the border's pixel.
    #[test]
    fn prefix_sums_match_the_box_tap_by_tap() {
        let g = flat();
        let p = Params::default();
        let n = g.pixels.len();
        // Deterministic pseudo-random values and half-widths (0 … 12 pixels).
        let hash = |i: usize, s: u64| {
            let x = (i as u64 ^ s).wrapping_mul(0x9E37_79B9_7F4A_7C15);
            ((x >> 11) as f64) / ((1u64 << 53) as f64)
        };
        let values: Vec<f32> = (0..n).map(|i| hash(i, 1) as f32).collect();
        let radius: Vec<f64> = (0..n).map(|i| 0.12 * hash(i, 2)).collect();
        let (w, h) = (g.width as isize, g.height as isize);
        for horizontal in [true, false] {
            let got = blur_pass(&values, &radius, None, &g, &p, horizontal, 1);
            for i in 0..n {
                let c = g.pixels[i].as_ref().expect("all surface");
                let r = c.pixels(radius[i], horizontal, p.max_radius);
                let (x, y) = ((i as isize) % w, (i as isize) / w);
                let (mut sum, mut wsum) = (f64::from(values[i]), 1.0);
                let m = (r + 0.5).floor() as isize;
                for k in (-m..=m).filter(|&k| k != 0) {
                    let (qx, qy) = if horizontal {
                        ((x + k).clamp(0, w - 1), y)
                    } else {
                        (x, (y + k).clamp(0, h - 1))
                    };
                    let wk = (r + 0.5 - k.unsigned_abs() as f64).clamp(0.0, 1.0);
                    sum += wk * f64::from(values[(qy * w + qx) as usize]);
                    wsum += wk;
                }
                let want = (sum / wsum) as f32;
                assert!(
                    (got[i] - want).abs() <= 1e-6,
                    "pixel {i} horizontal {horizontal}: {} vs {want}",
                    got[i]
                );
            }
        }
    }

    /// On one continuous surface, away from the border, the blur is the tent of two boxes of
    /// half-width r/√2 along each axis (here values vary along rows only, so the columns
    /// change nothing), and the tent has the second moment of the box of half-width r it
    /// replaces: r²/3 in the continuum, within the taps' quantisation.
    #[test]
    fn the_blur_is_a_tent_of_the_boxs_variance() {
        let g = flat();
        let p = Params::default();
        let hash = |x: usize| {
            let h = (x as u64 ^ 7).wrapping_mul(0x9E37_79B9_7F4A_7C15);
            ((h >> 11) as f64 / (1u64 << 53) as f64) as f32
        };
        let values: Vec<f32> = (0..g.pixels.len()).map(|i| hash(i % 32)).collect();
        // 6 pixels at depth 1; each box 6/√2 ≈ 4.24 pixels.
        let (radius, r) = (vec![0.06; values.len()], 6.0f64);
        let got = blur(&values, &radius, None, &g, &p);
        let b = r * std::f64::consts::FRAC_1_SQRT_2;
        let m = (b + 0.5).floor() as i64;
        let bx: Vec<f64> = (-m..=m)
            .map(|k| (b + 0.5 - k.unsigned_abs() as f64).clamp(0.0, 1.0))
            .collect();
        let total: f64 = bx.iter().sum();
        // The tent's taps: the box convolved with itself, normalised.
        let mut tent = vec![0.0; 2 * bx.len() - 1];
        for (i, wi) in bx.iter().enumerate() {
            for (j, wj) in bx.iter().enumerate() {
                tent[i + j] += wi * wj / (total * total);
            }
        }
        let half = (tent.len() / 2) as i64;
        let second: f64 = (-half..=half)
            .zip(&tent)
            .map(|(k, w)| (k * k) as f64 * w)
            .sum();
        assert!((second - r * r / 3.0).abs() < 0.1 * r * r / 3.0, "{second}");
        for y in 0..8 {
            for x in (half as usize)..(32 - half as usize) {
                let want: f64 = (-half..=half)
                    .zip(&tent)
                    .map(|(k, w)| w * f64::from(hash((x as i64 + k) as usize)))
                    .sum();
                let i = y * 32 + x;
                assert!(
                    (f64::from(got[i]) - want).abs() < 1e-5,
                    "x {x}: {} vs {want}",
                    got[i]
                );
            }
        }
    }

    /// A run cut where the values go on unchanged blurs as if it were not cut: a floor pixel
    /// beside an occluder's silhouette (the floor hidden behind it lit like the pixels at the
    /// cut) is not darkened by a shadow on its open side. Renormalising over the taps left
    /// instead gives 8/9.5 lit (0.842) for 10.5/12 (0.875).
    #[test]
    fn a_cut_run_reads_its_end_past_the_cut() {
        let p = Params::default();
        // Shadow at x < 8, lit from 8 on; `guide(false)` puts x ≥ 16 on another surface.
        let values: Vec<f32> = (0..32 * 8)
            .map(|i| if i % 32 < 8 { 0.0 } else { 1.0 })
            .collect();
        // 6 pixels at depth 1 (0.01 per pixel): the box of x = 12 is 7 … 17, and 6 and 18 at
        // weight ½.
        let radius = vec![0.06; values.len()];
        let cut = blur_pass(&values, &radius, None, &guide(false), &p, true, 1);
        let whole = blur_pass(&values, &radius, None, &flat(), &p, true, 1);
        for y in 0..8 {
            for x in 0..16 {
                let i = y * 32 + x;
                assert!(
                    (cut[i] - whole[i]).abs() < 1e-6,
                    "x {x}: {} vs {}",
                    cut[i],
                    whole[i]
                );
            }
            let i = y * 32 + 12;
            assert!((cut[i] - 10.5 / 12.0).abs() < 1e-6, "{}", cut[i]);
        }
    }

    #[test]
    fn light_offsets_cover_the_polygon() {
        let square = Light {
            vertices: vec![
                DVec3::new(-0.5, 3.0, -0.5),
                DVec3::new(0.5, 3.0, -0.5),
                DVec3::new(0.5, 3.0, 0.5),
                DVec3::new(-0.5, 3.0, 0.5),
            ],
            normal: DVec3::NEG_Y,
            radiance: DVec3::ONE,
            two_sided: false,
            texture: None,
            shape: crate::light::Shape::Polygon,
        };
        let o = light_offsets(&square, 6);
        assert_eq!(o.len(), 36);
        let mean = o.iter().sum::<DVec3>() / 36.0;
        assert!(mean.length() < 1e-12, "{mean}");
        assert!(
            o.iter()
                .all(|p| p.y.abs() < 1e-12 && p.x.abs() < 0.5 && p.z.abs() < 0.5)
        );
        // A triangle keeps about half of the grid's points; a degenerate light none.
        let mut tri = square.clone();
        tri.vertices.pop();
        let n = light_offsets(&tri, 10).len();
        assert!((40..=60).contains(&n), "{n}");
        tri.vertices.pop();
        assert!(light_offsets(&tri, 10).is_empty());
    }

    /// A contact on [`flat`] with the light split: columns 0–15 the umbra, their rays' occluder
    /// touching the receiver (own half-width 0.001 = 0.1 pixel: sharp), then half the light
    /// seen (16–19), three quarters (20–23) and all of it, the blocked parts' penumbra 3 pixels
    /// wide either way. (hard, own widths.)
    pub(crate) fn contact() -> (Vec<f32>, Vec<f64>) {
        (0..32 * 8)
            .map(|i| match i % 32 {
                0..16 => (0.0, 0.001),
                16..20 => (0.5, 0.03),
                20..24 => (0.75, 0.03),
                _ => (1.0, 0.0),
            })
            .unzip()
    }

    #[test]
    fn a_contact_stays_sharp() {
        let (g, p) = (flat(), Params::default());
        let (hard, own) = contact();
        let edge = edge_radius(&hard, &own, &g, &p);
        let radius = spread_radius(&edge, Some(&own), &g, &p);
        let own_w = own_widths(&own, &p);
        assert!(own_w.is_some(), "the light is split by default");
        let sharp = sharp_pixels(&hard, own_w, &g, &p).expect("own widths give a mask");
        assert_eq!(
            sharp.iter().filter(|&&s| s).count(),
            16 * 8,
            "the umbra is sharp"
        );
        let kept = blur(&hard, &radius, Some(&sharp), &g, &p);
        let rounded = blur(&hard, &radius, None, &g, &p);
        for y in 0..8 {
            let row = y * 32;
            assert!(
                kept[row..row + 16].iter().all(|&v| v == 0.0),
                "the umbra stays 0"
            );
            // The lit side's first column keeps at least the rays' half (its tent reads the
            // quarter ahead, not the umbra behind the cut) …
            assert!((0.5..0.6).contains(&kept[row + 16]), "{}", kept[row + 16]);
            // … which without the cut it does not (the test can fail).
            assert!(rounded[row + 16] < 0.45, "{}", rounded[row + 16]);
        }
        let one_ray = Params { split: 1, ..p };
        assert!(own_widths(&own, &one_ray).is_none());
        assert!(sharp_pixels(&hard, own_widths(&own, &one_ray), &g, &one_ray).is_none());
    }

    #[test]
    fn the_spread_stays_within_a_pixels_own_width() {
        // A contact: the umbra's own blocked rays hit an occluder just above the receiver
        // (half-width 0.01 = 1 pixel), the edge's graze it higher up (0.05 = 5 pixels).
        let g = flat();
        let p = Params::default();
        let hard: Vec<f32> = (0..g.pixels.len())
            .map(|i| if i % 32 < 16 { 0.0 } else { 1.0 })
            .collect();
        let own: Vec<f64> = (0..g.pixels.len())
            .map(|i| match i % 32 {
                15 => 0.05,
                x if x < 15 => 0.01,
                _ => 0.0,
            })
            .collect();
        let edge = edge_radius(&hard, &own, &g, &p);
        let free = spread_radius(&edge, None, &g, &p);
        let within = spread_radius(&edge, Some(&own), &g, &p);
        for x in 0..32 {
            let (want_free, want_within) = match x {
                10..=13 => (0.05, 0.0),
                14..=20 => (0.05, 0.05),
                _ => (0.0, 0.0),
            };
            assert_eq!(free[3 * 32 + x], want_free, "x = {x}, free");
            assert_eq!(within[3 * 32 + x], want_within, "x = {x}, within");
        }
    }

    #[test]
    fn radius_spreads_from_the_edge_onto_the_lit_side() {
        let g = flat();
        let p = Params::default();
        let hard: Vec<f32> = (0..g.pixels.len())
            .map(|i| if i % 32 < 16 { 0.0 } else { 1.0 })
            .collect();
        // Half-width 0.05 = 5 pixels at the occluded pixels.
        let radius: Vec<f64> = hard
            .iter()
            .map(|&h| if h < 1.0 { 0.05 } else { 0.0 })
            .collect();
        let edge = edge_radius(&hard, &radius, &g, &p);
        assert_eq!(
            edge.iter().filter(|&&r| r > 0.0).count(),
            8,
            "one edge column"
        );
        let spread = spread_radius(&edge, None, &g, &p);
        for x in 0..32 {
            let want = if (10..=20).contains(&x) { 0.05 } else { 0.0 };
            assert_eq!(spread[3 * 32 + x], want, "x = {x}");
        }
    }
}
