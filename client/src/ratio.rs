//! Stochastic shadows by the ratio estimator (Heitz, Hill and McGuire 2018, "Combining
//! analytic direct illumination and stochastic shadows", I3D): the analytic unshadowed
//! radiance (per-pixel LTC) times the ratio of two Monte Carlo estimates from the *same*
//! samples, with and without shadow rays (eq. 5):
//!
//! ```text
//! L ≈ L_ltc · Σᵢ f(ωᵢ) V(ωᵢ) / p(ωᵢ)  /  Σᵢ f(ωᵢ) / p(ωᵢ)
//! ```
//!
//! The two sums are correlated, so the ratio is exact (no noise) wherever nothing is occluded
//! and the BRDF's shape error of LTC never enters. The denoised variant filters the two sums
//! with the same edge-aware kernel before dividing (§4 of the paper: filtering numerator and
//! denominator separately keeps the ratio consistent); here the kernel is the screen-space,
//! depth- and normal-aware box of [`crate::penumbra::blur`] at a fixed radius in pixels.
//!
//! Samples are the ground truth's MIS samples ([`crate::groundtruth::McPoint`]): spherical-polygon light
//! sampling and VNDF BRDF sampling, one of each per sample.

use bspvt_raytrace::Occluder;
use rayon::prelude::*;

use crate::frame::image::Image;
use crate::groundtruth::{Ctx, McPoint, ShadingPoint, chan_mean, rng::Pcg32};
use crate::light::Light;
use crate::penumbra::{self, Guide, Params, compose};
use crate::render::renderer::Renderer;

/// The per-pixel Monte Carlo sums (channel means) with and without shadow rays.
#[derive(Clone, Debug)]
pub(crate) struct RatioSums {
    pub(crate) shadowed: Vec<f32>,
    pub(crate) unshadowed: Vec<f32>,
}

/// Both sums at every covered pixel of `r`'s G-buffer, `spp` MIS samples per pixel,
/// reproducible for a given `seed`. Background pixels: 0 and 0.
pub(crate) fn ratio_sums(
    r: &Renderer,
    light: &Light,
    occluder: &Occluder,
    spp: u32,
    seed: u64,
) -> RatioSums {
    let ctx = Ctx::new(r.scene, Some(occluder));
    let g = &r.gbuffer;
    let pairs: Vec<(f32, f32)> = (0..g.tri.len())
        .into_par_iter()
        .with_min_len(64)
        .map(|i| {
            let Some(s) = g.surface(&r.scene.mesh, &r.view, i) else {
                return (0.0, 0.0);
            };
            let sp = ShadingPoint::from_surface(&s, r.view.eye);
            let Some(pt) = McPoint::new(&sp, light) else {
                return (0.0, 0.0);
            };
            let brdf = &ctx.brdf(&s);
            let mut rng = Pcg32::for_key(seed, i as u64);
            let (mut sh, mut un) = (0.0, 0.0);
            for _ in 0..spp {
                let p = pt.sample_pair(brdf, light, Some(&ctx.shadows), &mut rng);
                sh += chan_mean(p.shadowed);
                un += chan_mean(p.unshadowed);
            }
            (sh as f32, un as f32)
        })
        .collect();
    let (shadowed, unshadowed) = pairs.into_iter().unzip();
    RatioSums {
        shadowed,
        unshadowed,
    }
}

/// The shadow factor Σ f V / Σ f per pixel, clamped to [0, 1]; 1 where the unshadowed sum
/// is 0 (no sample reached the light: the analytic term is 0 or nearly so, and nothing is
/// known about visibility).
pub(crate) fn ratio(sums: &RatioSums) -> Vec<f32> {
    sums.shadowed
        .iter()
        .zip(&sums.unshadowed)
        .map(|(&s, &u)| {
            let r = s / u;
            if u > 0.0 && r.is_finite() {
                r.clamp(0.0, 1.0)
            } else {
                1.0
            }
        })
        .collect()
}

/// Both sums filtered with the same edge-aware box of `radius_px` pixels (at each pixel's own
/// view depth: world half-width = radius × the pixel footprint), then divided.
pub(crate) fn denoised_ratio(sums: &RatioSums, guide: &Guide, radius_px: f64) -> Vec<f32> {
    let params = Params {
        max_radius: radius_px,
        ..Params::default()
    };
    let world: Vec<f64> = guide
        .pixels
        .iter()
        .map(|p| p.map_or(0.0, |p| radius_px * guide.footprint_per_depth * p.depth))
        .collect();
    let blurred = RatioSums {
        shadowed: penumbra::blur::blur(&sums.shadowed, &world, None, guide, &params),
        unshadowed: penumbra::blur::blur(&sums.unshadowed, &world, None, guide, &params),
    };
    ratio(&blurred)
}

/// One frame: unshadowed per-pixel LTC × the ratio estimate of `spp` samples; denoised with a
/// `denoise` pixel radius when given. `guide` is the camera's (computed once per camera).
pub fn render_ratio(
    r: &Renderer,
    guide: &Guide,
    light: &Light,
    occluder: &Occluder,
    spp: u32,
    seed: u64,
    denoise: Option<f64>,
) -> Image {
    let sums = ratio_sums(r, light, occluder, spp, seed);
    let factor = match denoise {
        Some(radius) => denoised_ratio(&sums, guide, radius),
        None => ratio(&sums),
    };
    compose(&r.shade_pixels(std::slice::from_ref(light), None), &factor)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratio_is_clamped_and_defined_everywhere() {
        let sums = RatioSums {
            shadowed: vec![0.5, 0.0, 2.0, 1.0, f32::NAN],
            unshadowed: vec![1.0, 0.0, 1.0, 0.0, 1.0],
        };
        assert_eq!(ratio(&sums), vec![0.5, 1.0, 1.0, 1.0, 1.0]);
    }
}
