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
    let points: Vec<DVec3> = blur::light_offsets(light, params.split)
        .into_iter()
        .map(|o| centre + o)
        .collect();
    if points.len() < 2 {
        return Ok(());
    }
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
    cast(buffers, &last, guide, light, &points, caster, epsilon)?;
    for _ in 0..grow_rounds(params) {
        last = seam_band(&last, &mut split, &buffers.hard, &one_ray, guide, params);
        if last.is_empty() {
            break;
        }
        cast(buffers, &last, guide, light, &points, caster, epsilon)?;
    }
    Ok(())
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
