//! rt-penumbra (paper 003): one hard shadow ray per pixel toward the point light (the light
//! polygon's centroid), the occluder's distance from its closest hit, and a blur of the hard
//! shadow only, of width W = (Z_receiver − Z_occluder) / Z_occluder · W_light projected to
//! screen pixels (W / the pixel's footprint on the receiver's tangent plane), capped at
//! [`Params::max_radius`] pixels ([`super::blur`]). Ours, not the paper's: where that blur
//! reaches, the light split into [`Params::split`]² parts, one ray each ([`split_light`]).

use anyhow::Result;
use bspvt_raytrace::{Occluder, Segment};
use rayon::prelude::*;

use glam::DVec3;

use super::{Guide, GuidePixel, Kernel, Params, blur, light_width, penumbra_width};
use crate::frame::camera::View;
use crate::light::Light;

/// Per-pixel buffers of the hard shadow pass (row-major; background pixels: lit, no width).
#[derive(Clone, Debug)]
pub struct RtBuffers {
    /// Hard shadow: 1 when the ray to the light's centroid is clear, else 0; where the light
    /// is split ([`split_light`]), the weighted fraction of its parts that the pixel sees.
    pub hard: Vec<f32>,
    /// Distance from the light point to the receiver, Z_receiver (split: the blocked rays'
    /// weighted mean).
    pub(crate) z_receiver: Vec<f64>,
    /// Distance from the light point to the occluder hit, Z_occluder (`NAN`: none).
    pub(crate) z_occluder: Vec<f64>,
    /// Half the penumbra width, W / 2, in world units, of the whole light (split: of one part)
    /// (0 where unoccluded; `f64::MAX` for an occluder at the light — the blur caps it in
    /// pixels).
    pub radius: Vec<f64>,
}

/// Who casts the hard shadow rays: the CPU's BVH ([`Occluder`], the reference) or the GPU's
/// ([`crate::gpu::shadow_rays::GpuShadowRays`]).
pub trait ShadowCaster: Sync {
    /// The closest hit of each segment (`None`: clear), as [`Occluder::first_hit`].
    fn first_hits(&self, segments: &[Segment]) -> Result<Vec<Option<f32>>>;

    /// The box kernel's soft shadow of `buffers` ([`blur::edge_radius`],
    /// [`blur::spread_radius`], [`blur::blur`]) where this caster's machine blurs it too;
    /// `None`: the CPU does.
    fn blur(
        &self,
        _buffers: &RtBuffers,
        _guide: &Guide,
        _params: &Params,
    ) -> Option<Result<Vec<f32>>> {
        None
    }
}

impl ShadowCaster for Occluder {
    fn first_hits(&self, segments: &[Segment]) -> Result<Vec<Option<f32>>> {
        Ok(segments.par_iter().map(|s| s.first_hit(self)).collect())
    }
}

/// A pixel's shadow ray toward one light point: the receiver's distance to it Z_receiver, the
/// point's weight in the pixel's unshadowed light, and the segment cast with its length before
/// the stop short of the light (`None`: nothing to cast).
type PixelRay = (f64, f64, Option<(Segment, f64)>);

/// The hard shadow pass (paper 003): one shadow ray per pixel toward the light's centroid, the
/// point light. `epsilon`: the shadow-ray offset (origins move by ε along the geometric normal
/// toward the light's side, segments stop ε short of the light).
pub fn hard_shadows(
    guide: &Guide,
    light: &Light,
    caster: &dyn ShadowCaster,
    epsilon: f64,
) -> Result<RtBuffers> {
    let all: Vec<usize> = (0..guide.pixels.len()).collect();
    let mut out = RtBuffers {
        hard: vec![1.0; all.len()],
        z_receiver: vec![f64::NAN; all.len()],
        z_occluder: vec![f64::NAN; all.len()],
        radius: vec![0.0; all.len()],
    };
    cast(
        &mut out,
        &all,
        guide,
        light,
        &[light.centroid()],
        caster,
        epsilon,
    )?;
    Ok(out)
}

/// The light split into `split` × `split` parts where the point light's shadow is soft: the
/// pixels of `buffers` (the point light's hard shadow) that the blur would change — within
/// reach of a hard shadow's edge ([`blur::spread_radius`]) by half a pixel or more — cast one
/// ray toward each part's
/// centre ([`blur::light_offsets`]) instead.
///
/// Such a pixel's `hard` becomes the fraction of its unshadowed light that reaches it — the
/// parts weighted by cos θ_receiver · cos θ_light / d², so parts below its horizon, which the
/// unshadowed LTC integral already leaves out, do not count as shadow — and its `radius` the
/// same weighted mean of its blocked parts' half-widths for a part of width
/// W_light / `split`. Why: a light's soft shadow is the sum of its parts' (for a planar
/// occluder and receiver, the box of width W is the sum of `split` shifted boxes of width
/// W / `split` along each axis), and each part's penumbra is `split` times narrower, so one
/// width per pixel is less wrong where penumbrae of different widths overlap, and a large
/// light whose umbra vanishes is not drawn with the point light's umbra.
///
/// Where the blur reaches [`Params::wide_reach`] pixels or more, and where the region grows,
/// the light is split [`Params::wide_split`]² ways instead, on a sparse grid ([`Sparse`]).
pub fn split_light(
    buffers: &mut RtBuffers,
    guide: &Guide,
    light: &Light,
    params: &Params,
    caster: &dyn ShadowCaster,
    epsilon: f64,
) -> Result<()> {
    if params.split <= 1 {
        return Ok(());
    }
    let centre = light.centroid();
    let parts = |n: usize| -> Vec<DVec3> {
        blur::light_offsets(light, n)
            .into_iter()
            .map(|o| centre + o)
            .collect()
    };
    let points = parts(params.split);
    if points.len() < 2 {
        return Ok(());
    }
    let wide = (params.wide_split > params.split)
        .then(|| parts(params.wide_split))
        .filter(|p| p.len() > points.len())
        .map(|fine| Sparse {
            points: fine,
            step: params.sparse_step.max(1),
        });
    let edge = blur::edge_radius(&buffers.hard, &buffers.radius, guide, params);
    let reach = blur::spread_radius(&edge, None, guide, params);
    // Pixels whose blur spans less than half a pixel either way (a punctual light's stand-in)
    // keep their one ray: the blur leaves them as they are.
    let soft: Vec<usize> = (0..reach.len())
        .filter(|&i| {
            guide.pixels[i].as_ref().is_some_and(|g| {
                let cap = params.max_radius;
                reach[i] > 0.0
                    && g.pixels(reach[i], true, cap)
                        .max(g.pixels(reach[i], false, cap))
                        >= 0.5
            })
        })
        .collect();
    let one_ray = buffers.hard.clone();
    let mut split = vec![false; reach.len()];
    for &i in &soft {
        split[i] = true;
    }
    let mut last = soft;
    let rays = Rays {
        guide,
        light,
        caster,
        epsilon,
    };
    match &wide {
        Some(sparse) => {
            let cap = params.max_radius;
            let reach_px = |i: usize| {
                guide.pixels[i].as_ref().map_or(0.0, |g| {
                    g.pixels(reach[i], true, cap)
                        .min(g.pixels(reach[i], false, cap))
                })
            };
            let (far, near): (Vec<usize>, Vec<usize>) = last
                .iter()
                .partition(|&&i| reach_px(i) >= params.wide_reach);
            rays.cast(buffers, &near, &points)?;
            let added = sparse.cast(buffers, &far, &mut split, &rays, params)?;
            last.extend(added);
        }
        None => rays.cast(buffers, &last, &points)?,
    }
    for _ in 0..grow_rounds(params) {
        last = seam_band(&last, &mut split, &buffers.hard, &one_ray, guide, params);
        if last.is_empty() {
            break;
        }
        match &wide {
            // The grown region lies past the one ray's capped reach: a wide penumbra.
            Some(sparse) => {
                let added = sparse.cast(buffers, &last, &mut split, &rays, params)?;
                last.extend(added);
            }
            None => rays.cast(buffers, &last, &points)?,
        }
    }
    Ok(())
}

/// The most a [`Sparse`] cell's corners' fractions may differ for the pixels between to be
/// interpolated: 2 of the 16 parts. (0.25 on `canopy.gltf`: 8.9 % in the shadows against
/// 8.3 %, for about 20 % less time on the bunny's base case.)
const CONTRAST: f32 = 0.125;

/// What [`cast`] needs besides the pixels and the light's points.
struct Rays<'a> {
    guide: &'a Guide,
    light: &'a Light,
    caster: &'a dyn ShadowCaster,
    epsilon: f64,
}

impl Rays<'_> {
    /// [`cast`] of `pixels` toward `points`.
    fn cast(&self, out: &mut RtBuffers, pixels: &[usize], points: &[DVec3]) -> Result<()> {
        cast(
            out,
            pixels,
            self.guide,
            self.light,
            points,
            self.caster,
            self.epsilon,
        )
    }
}

/// The wide split: rays toward `points` (the light's [`Params::wide_split`]² parts) from the
/// pixels on a grid of spacing `step`; a pixel between takes its cell's corners' values,
/// bilinearly, where they differ little ([`CONTRAST`]). Why: a penumbra
/// [`Params::wide_reach`] pixels wide or more changes slowly from pixel to pixel, so its
/// visibility is sampled more finely over the light (a part's penumbra is `wide_split` times
/// narrower than the light's, and the blur's one-width assumption spans that much less) and
/// more coarsely over the screen: 16 / 3² ≈ 1.8 rays per pixel by default where the split
/// casts 4.
struct Sparse {
    points: Vec<DVec3>,
    step: usize,
}

impl Sparse {
    /// Fills the buffers of `pixels` (all marked in `split`): those on the grid cast; those
    /// whose cell's corners lie on their surface ([`Guide::same_surface`]) and whose corners'
    /// fractions differ by at most [`CONTRAST`] by interpolation (the corners not yet split
    /// are cast too, marked in `split` and returned); the rest cast their own.
    fn cast(
        &self,
        out: &mut RtBuffers,
        pixels: &[usize],
        split: &mut [bool],
        rays: &Rays,
        params: &Params,
    ) -> Result<Vec<usize>> {
        let guide = rays.guide;
        let mut to_cast = Vec::new();
        let mut added = Vec::new();
        let mut between = Vec::new();
        for &i in pixels {
            let Some(p) = guide.pixels[i].as_ref() else {
                continue;
            };
            let Some(corners) = self.corners(guide, i).filter(|c| {
                c.len() > 1
                    && c.iter().all(|&(j, _)| {
                        guide.pixels[j]
                            .as_ref()
                            .is_some_and(|q| guide.same_surface(p, q, params))
                    })
            }) else {
                // On the grid, or its cell leaves the image or its surface.
                to_cast.push(i);
                continue;
            };
            for &(j, _) in &corners {
                if !split[j] {
                    split[j] = true;
                    added.push(j);
                    to_cast.push(j);
                }
            }
            between.push((i, corners));
        }
        to_cast.sort_unstable();
        rays.cast(out, &to_cast, &self.points)?;
        // The fractions are sums of the parts' hard shadows, steps that only the blur of a
        // part's width smooths: a pixel is interpolated where its corners' fractions differ by
        // at most CONTRAST, else it casts its own (where the staircase is steep, moving a step
        // shows: without this test `canopy.gltf`'s error in the shadows rose 8.7 → 10.8 %).
        let gentle = |hard: &[f32], corners: &[(usize, f64)]| {
            let (lo, hi) = corners
                .iter()
                .fold((f32::MAX, f32::MIN), |(lo, hi), &(j, _)| {
                    (lo.min(hard[j]), hi.max(hard[j]))
                });
            hi - lo <= CONTRAST
        };
        let mut own = Vec::new();
        for (i, corners) in between {
            if gentle(&out.hard, &corners) {
                interpolate(out, i, &corners);
            } else {
                own.push(i);
            }
        }
        rays.cast(out, &own, &self.points)?;
        Ok(added)
    }

    /// The grid pixels whose values pixel `i` takes and their bilinear weights: `i` itself on
    /// the grid, else the 2 or 4 corners of its cell; `None` where the cell leaves the image.
    fn corners(&self, guide: &Guide, i: usize) -> Option<Vec<(usize, f64)>> {
        let (w, h, s) = (guide.width, guide.height, self.step);
        let axis = |v: usize| {
            let v0 = v - v % s;
            let t = (v % s) as f64 / s as f64;
            [(v0, 1.0 - t), (v0 + s, t)]
        };
        let (xs, ys) = (axis(i % w), axis(i / w));
        let mut out = Vec::with_capacity(4);
        for &(y, fy) in &ys {
            for &(x, fx) in &xs {
                if fx * fy > 0.0 {
                    if x >= w || y >= h {
                        return None;
                    }
                    out.push((y * w + x, fx * fy));
                }
            }
        }
        Some(out)
    }
}

/// Pixel `i`'s buffers as the weighted mean of `corners`' (weights summing to 1): the fraction
/// seen and Z_receiver over all of them, Z_occluder and the half-width over those blocked.
fn interpolate(out: &mut RtBuffers, i: usize, corners: &[(usize, f64)]) {
    let (mut seen, mut z_r) = (0.0, 0.0);
    let (mut blocked, mut z_o, mut radius) = (0.0, 0.0, 0.0);
    for &(j, wt) in corners {
        seen += wt * f64::from(out.hard[j]);
        z_r += wt * out.z_receiver[j];
        if out.z_occluder[j].is_finite() {
            blocked += wt;
            z_o += wt * out.z_occluder[j];
            // An occluder at the light (f64::MAX, capped by the blur) stays one.
            radius = if radius == f64::MAX || out.radius[j] == f64::MAX {
                f64::MAX
            } else {
                radius + wt * out.radius[j]
            };
        }
    }
    out.hard[i] = seen as f32;
    out.z_receiver[i] = z_r;
    (out.z_occluder[i], out.radius[i]) = match blocked > 0.0 {
        true if radius == f64::MAX => (z_o / blocked, f64::MAX),
        true => (z_o / blocked, (radius / blocked).min(f64::MAX)),
        false => (f64::NAN, 0.0),
    };
}

/// How far, in pixels, a round of [`split_light`]'s growth reaches from a seam pixel.
const GROW_BAND: isize = 4;

/// How many rounds the split region may grow past the one-ray blur's reach: together at most
/// [`Params::grow`] pixels.
fn grow_rounds(params: &Params) -> usize {
    let rounds = (params.grow / GROW_BAND as f64).ceil();
    if rounds.is_finite() && rounds > 0.0 {
        rounds.min(1e4) as usize
    } else {
        0
    }
}

/// The split region's seam: the pixels not yet split within [`GROW_BAND`] pixels (a square)
/// of a newly split pixel (`last`) that has a same-surface neighbour not split whose one ray's
/// 0 or 1 (`one_ray`) differs from its fraction; marked in `split` and returned in order.
/// Where the one ray's blur falls short of the area light's penumbra (its width capped at
/// [`Params::max_radius`], or a narrower occluder's distance), the split fractions would stop
/// at such a step; the bands take the region on until the fractions meet the one ray's values.
fn seam_band(
    last: &[usize],
    split: &mut [bool],
    hard: &[f32],
    one_ray: &[f32],
    guide: &Guide,
    params: &Params,
) -> Vec<usize> {
    let (w, h) = (guide.width as isize, guide.height as isize);
    let free = |split: &[bool], x: isize, y: isize| {
        (x >= 0 && y >= 0 && x < w && y < h)
            .then_some((y * w + x) as usize)
            .filter(|&j| !split[j] && guide.pixels[j].is_some())
    };
    // The seam against the region as it was before this round …
    let seams: Vec<(isize, isize)> = last
        .iter()
        .filter_map(|&i| {
            let p = guide.pixels[i].as_ref()?;
            let (x, y) = ((i as isize) % w, (i as isize) / w);
            [(-1, 0), (1, 0), (0, -1), (0, 1)]
                .iter()
                .filter_map(|&(dx, dy)| free(split, x + dx, y + dy))
                .any(|j| {
                    one_ray[j] != hard[i]
                        && guide.pixels[j]
                            .as_ref()
                            .is_some_and(|q| guide.same_surface(p, q, params))
                })
                .then_some((x, y))
        })
        .collect();
    // … then its bands, each pixel once.
    let mut out = Vec::new();
    for (x, y) in seams {
        for qy in y - GROW_BAND..=y + GROW_BAND {
            for qx in x - GROW_BAND..=x + GROW_BAND {
                if let Some(j) = free(split, qx, qy) {
                    split[j] = true;
                    out.push(j);
                }
            }
        }
    }
    out.sort_unstable();
    out
}

/// Casts the rays of `pixels` toward `points` (on `light`) and writes their buffers: the
/// weighted fraction of the points seen, and of the blocked ones the weighted mean Z_receiver,
/// Z_occluder and half-width for a part of width W_light / √(number of points).
fn cast(
    out: &mut RtBuffers,
    pixels: &[usize],
    guide: &Guide,
    light: &Light,
    points: &[DVec3],
    caster: &dyn ShadowCaster,
    epsilon: f64,
) -> Result<()> {
    let w_part = light_width(light) / (points.len().max(1) as f64).sqrt();
    // Every pixel with a surface's rays, `points.len()` each, in `pixels`' order.
    let rays: Vec<PixelRay> = pixels
        .par_iter()
        .flat_map_iter(|&i| {
            guide.pixels[i]
                .as_ref()
                .into_iter()
                .flat_map(|g| points.iter().map(|&p| pixel_ray(g, light, p, epsilon)))
        })
        .collect();
    let segments: Vec<Segment> = rays
        .iter()
        .filter_map(|(_, _, c)| c.map(|(s, _)| s))
        .collect();
    let hits = caster.first_hits(&segments)?;
    if hits.len() != segments.len() {
        anyhow::bail!(
            "the shadow rays came back {} answers for {} segments",
            hits.len(),
            segments.len()
        );
    }
    let mut hits = hits.into_iter();
    // Per point: Z_receiver, weight, and Z_occluder from the light (`None`: seen); reused.
    let mut answers: Vec<(f64, f64, Option<f64>)> = Vec::with_capacity(points.len());
    let mut blocked: Vec<(f64, f64, f64)> = Vec::with_capacity(points.len());
    let mut rays = rays.chunks_exact(points.len().max(1));
    for &i in pixels {
        if guide.pixels[i].is_none() {
            continue;
        }
        let Some(ray) = rays.next() else {
            break;
        };
        answers.clear();
        answers.extend(ray.iter().map(|&(z_r, weight, cast)| {
            let z_o = cast
                .and_then(|(_, len)| hits.next().flatten().map(|t| (len - f64::from(t)).max(0.0)));
            (z_r, weight, z_o)
        }));
        // Points count by their share of the unshadowed light; one point (paper 003's), or a
        // pixel that faces none of them, counts them alike.
        let weighted = answers.len() > 1 && answers.iter().any(|a| a.1 > 0.0);
        let share = |a: &(f64, f64, Option<f64>)| if weighted { a.1 } else { 1.0 };
        let total: f64 = answers.iter().map(share).sum();
        let seen: f64 = answers.iter().filter(|a| a.2.is_none()).map(share).sum();
        out.hard[i] = (seen / total) as f32;
        // The blocked points' means (alike if none of them has a share): Z_r, Z_o and half of
        // W = (Z_r − Z_o) / Z_o · W_part (f64::MAX for an occluder at the light: the blur caps it).
        blocked.clear();
        blocked.extend(
            answers
                .iter()
                .filter_map(|a| a.2.map(|z_o| (share(a), a.0, z_o))),
        );
        let alike = !blocked.iter().any(|b| b.0 > 0.0);
        let w = |b: &(f64, f64, f64)| if alike { 1.0 } else { b.0 };
        let sum_w: f64 = blocked.iter().map(w).sum();
        let mean = |f: &dyn Fn(&(f64, f64, f64)) -> f64| {
            blocked.iter().map(|b| w(b) * f(b)).sum::<f64>() / sum_w
        };
        (out.z_receiver[i], out.z_occluder[i], out.radius[i]) = match blocked.is_empty() {
            true => (
                answers.iter().map(|a| a.0).sum::<f64>() / answers.len().max(1) as f64,
                f64::NAN,
                0.0,
            ),
            false => (
                mean(&|b| b.1),
                mean(&|b| b.2),
                mean(&|b| 0.5 * penumbra_width(b.1, b.2, w_part)).min(f64::MAX),
            ),
        };
    }
    Ok(())
}

/// The shadow ray from `g`'s surface to the point `p` on `light`, with `p`'s weight in `g`'s
/// unshadowed light: cos θ_receiver · cos θ_light / d² (0 below either horizon).
fn pixel_ray(g: &GuidePixel, light: &Light, p: DVec3, epsilon: f64) -> PixelRay {
    let to_light = p - g.position;
    let z_r = to_light.length();
    if !(z_r > epsilon) || !z_r.is_finite() {
        // The receiver touches the point light: nothing can be in between.
        return (z_r, 0.0, None);
    }
    let dir = to_light / z_r;
    let cos_l = match light.two_sided {
        true => light.normal.dot(dir).abs(),
        false => (-light.normal.dot(dir)).max(0.0),
    };
    let weight = g.normal.dot(dir).max(0.0) * cos_l / (z_r * z_r);
    let side = if g.geometric.dot(dir) >= 0.0 {
        1.0
    } else {
        -1.0
    };
    let origin = g.position + g.geometric * (epsilon * side);
    let seg = p - origin;
    let len = seg.length();
    let t_max = len - epsilon;
    let cast = (t_max > 0.0 && len.is_finite()).then(|| {
        let s = Segment::new(origin.as_vec3(), (seg / len).as_vec3(), t_max as f32);
        (s, len)
    });
    (z_r, if weight.is_finite() { weight } else { 0.0 }, cast)
}

/// The soft shadow factor: the hard shadow blurred by the per-pixel radius spread from the
/// hard shadow's edge ([`blur::edge_radius`], [`blur::spread_radius`]; where the light is
/// split, within each blocked pixel's own width); by `caster`'s machine where it blurs
/// ([`ShadowCaster::blur`], the box kernel's tent).
pub(crate) fn soft_shadows(
    buffers: &RtBuffers,
    guide: &Guide,
    view: &View,
    light: &Light,
    params: &Params,
    caster: &dyn ShadowCaster,
) -> Result<Vec<f32>> {
    if params.kernel == Kernel::Box
        && let Some(soft) = caster.blur(buffers, guide, params)
    {
        return soft;
    }
    let edge = blur::edge_radius(&buffers.hard, &buffers.radius, guide, params);
    let own = blur::own_widths(&buffers.radius, params);
    let radius = blur::spread_radius(&edge, own, guide, params);
    Ok(match params.kernel {
        Kernel::Box => {
            let sharp = blur::sharp_pixels(&buffers.hard, own, guide, params);
            blur::blur(&buffers.hard, &radius, sharp.as_deref(), guide, params)
        }
        Kernel::Light(n) => blur::light_blur(
            &buffers.hard,
            &radius,
            guide,
            view,
            light.centroid(),
            &blur::light_offsets(light, n),
            light_width(light),
            params,
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn buffers(n: usize) -> RtBuffers {
        RtBuffers {
            hard: vec![1.0; n],
            z_receiver: vec![2.0; n],
            z_occluder: vec![f64::NAN; n],
            radius: vec![0.0; n],
        }
    }

    #[test]
    fn corners_are_the_cells_bilinear_weights() {
        let g = super::super::blur::tests::flat();
        let sparse = Sparse {
            points: Vec::new(),
            step: 3,
        };
        let w = g.width;
        // On the grid: itself.
        assert_eq!(sparse.corners(&g, 3 * w + 6), Some(vec![(3 * w + 6, 1.0)]));
        // On a grid row, between two columns: 2 ⁄ 3 and 1 ⁄ 3.
        let c = sparse.corners(&g, 3 * w + 7).expect("inside");
        assert_eq!(c.len(), 2);
        assert_eq!((c[0].0, c[1].0), (3 * w + 6, 3 * w + 9));
        assert!((c[0].1 - 2.0 / 3.0).abs() < 1e-12 && (c[1].1 - 1.0 / 3.0).abs() < 1e-12);
        // Inside a cell: four corners, weights summing to 1.
        let c = sparse.corners(&g, 4 * w + 8).expect("inside");
        assert_eq!(c.len(), 4);
        assert!((c.iter().map(|c| c.1).sum::<f64>() - 1.0).abs() < 1e-12);
        // A cell past the image's last column (31 = 30 + 1; 33 does not exist): the pixel is
        // not interpolated.
        assert_eq!(sparse.corners(&g, 3 * w + 31), None);
    }

    #[test]
    fn interpolation_means_the_blocked_corners_widths() {
        let mut b = buffers(4);
        // Corner 0 blocked (half the light seen, Z_o 1, half-width 0.3); corner 1 clear.
        b.hard[0] = 0.5;
        b.z_occluder[0] = 1.0;
        b.radius[0] = 0.3;
        interpolate(&mut b, 2, &[(0, 0.25), (1, 0.75)]);
        assert!((b.hard[2] - 0.875).abs() < 1e-7, "{}", b.hard[2]);
        // The width is the blocked corners' (a clear corner has none to average in).
        assert!((b.radius[2] - 0.3).abs() < 1e-12 && b.z_occluder[2] == 1.0);
        // None blocked: no occluder, no width.
        interpolate(&mut b, 3, &[(1, 1.0)]);
        assert!(b.z_occluder[3].is_nan() && b.radius[3] == 0.0 && b.hard[3] == 1.0);
        // An occluder at the light (width f64::MAX) stays the largest finite width.
        b.radius[1] = f64::MAX;
        b.z_occluder[1] = 0.0;
        b.radius[0] = f64::MAX;
        interpolate(&mut b, 3, &[(0, 0.3), (1, 0.7)]);
        assert_eq!(b.radius[3], f64::MAX);
    }
}
