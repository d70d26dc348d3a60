//! rt-penumbra (paper 003): one hard shadow ray per pixel toward the point light (the light
//! polygon's centroid), the occluder's distance from its closest hit, and a blur of the hard
//! shadow only, of width W = (Z_receiver − Z_occluder) / Z_occluder · W_light projected to
//! screen pixels (W / the pixel's footprint on the receiver's tangent plane), capped at
//! [`Params::max_radius`] pixels ([`super::blur`]).

use anyhow::Result;
use bspvt_raytrace::{Occluder, Segment};
use rayon::prelude::*;

use super::{Guide, Kernel, Params, blur, light_width, penumbra_width};
use crate::frame::camera::View;
use crate::light::Light;

/// Per-pixel buffers of the hard shadow pass (row-major; background pixels: lit, no width).
#[derive(Clone, Debug)]
pub struct RtBuffers {
    /// Hard shadow: 1 when the ray to the light's centroid is clear, else 0.
    pub(crate) hard: Vec<f32>,
    /// Distance from the light's centroid to the receiver, Z_receiver.
    pub(crate) z_receiver: Vec<f64>,
    /// Distance from the light's centroid to the occluder hit, Z_occluder (`NAN`: none).
    pub(crate) z_occluder: Vec<f64>,
    /// Half the penumbra width, W / 2, in world units (0 where unoccluded; `f64::MAX` for an
    /// occluder at the light — the blur caps it in pixels).
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

/// A pixel's shadow ray: its receiver's distance to the light Z_receiver, and the segment
/// cast with its length before the stop short of the light (`None`: nothing to cast).
type PixelRay = (f64, Option<(Segment, f64)>);

/// The hard shadow pass. `epsilon`: the shadow-ray offset (origins move by ε along the
/// geometric normal toward the light's side, segments stop ε short of the light).
pub fn hard_shadows(
    guide: &Guide,
    light: &Light,
    caster: &dyn ShadowCaster,
    epsilon: f64,
) -> Result<RtBuffers> {
    let centre = light.centroid();
    let w_light = light_width(light);
    let rays: Vec<Option<PixelRay>> = guide
        .pixels
        .par_iter()
        .map(|g| {
            let g = g.as_ref()?;
            let to_light = centre - g.position;
            let z_r = to_light.length();
            if !(z_r > epsilon) || !z_r.is_finite() {
                // The receiver touches the point light: nothing can be in between.
                return Some((z_r, None));
            }
            let dir = to_light / z_r;
            let side = if g.geometric.dot(dir) >= 0.0 {
                1.0
            } else {
                -1.0
            };
            let origin = g.position + g.geometric * (epsilon * side);
            let seg = centre - origin;
            let len = seg.length();
            let t_max = len - epsilon;
            let cast = (t_max > 0.0 && len.is_finite()).then(|| {
                let s = Segment::new(origin.as_vec3(), (seg / len).as_vec3(), t_max as f32);
                (s, len)
            });
            Some((z_r, cast))
        })
        .collect();
    let segments: Vec<Segment> = rays
        .iter()
        .filter_map(|r| r.and_then(|(_, c)| c).map(|(s, _)| s))
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
    let mut out = RtBuffers {
        hard: Vec::with_capacity(rays.len()),
        z_receiver: Vec::with_capacity(rays.len()),
        z_occluder: Vec::with_capacity(rays.len()),
        radius: Vec::with_capacity(rays.len()),
    };
    for ray in rays {
        let (h, zr, zo, r) = match ray {
            None => (1.0, f64::NAN, f64::NAN, 0.0),
            Some((z_r, None)) => (1.0, z_r, f64::NAN, 0.0),
            Some((z_r, Some((_, len)))) => match hits.next().flatten() {
                None => (1.0, z_r, f64::NAN, 0.0),
                Some(t) => {
                    // Z from the light: the hit lies len − t from the centroid.
                    let z_o = (len - f64::from(t)).max(0.0);
                    let w = penumbra_width(z_r, z_o, w_light);
                    (0.0, z_r, z_o, 0.5 * w)
                }
            },
        };
        out.hard.push(h);
        out.z_receiver.push(zr);
        out.z_occluder.push(zo);
        out.radius.push(r);
    }
    Ok(out)
}

/// The soft shadow factor: the hard shadow blurred by the per-pixel radius spread from the
/// hard shadow's edge ([`blur::edge_radius`], [`blur::spread_radius`]); by `caster`'s machine
/// where it blurs ([`ShadowCaster::blur`], the box kernel's tent).
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
    let radius = blur::spread_radius(&edge, guide, params);
    Ok(match params.kernel {
        Kernel::Box => blur::blur(&buffers.hard, &radius, guide, params),
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
