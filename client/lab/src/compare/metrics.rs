//! Image error metrics over the pixels that see a surface.
//!
//! Linear radiance, per channel, over covered pixels (N of them, 3N values):
//! - RMSE = √(Σ (x − r)² / 3N); MAE = Σ |x − r| / 3N;
//! - relative MSE = Σ (x − r)² / (r² + τ²) / 3N, with τ = 0.01 × the reference's mean, so
//!   black pixels (umbra) do not divide by zero and the metric does not depend on exposure;
//! - share over 8 %: pixels whose tone-mapped display value (the PNG the user sees, 0…1 per
//!   channel) differs by more than 0.08 in any channel — paper 000's threshold (fig. 8);
//! - FLIP: LDR-ꟻLIP (Andersson et al. 2020, NVIDIA's implementation through `nv-flip`) of the
//!   same tone-mapped images at the default 67 pixels per degree, averaged over covered pixels.

use serde::Serialize;

use bspvt_client::frame::gbuffer::{GBuffer, NONE};
use bspvt_client::frame::image::Image;

/// The display threshold of [`Metrics::share_over_8`].
pub const DISPLAY_THRESHOLD: f64 = 0.08;

/// τ / reference mean in the relative MSE.
pub(crate) const REL_MSE_FLOOR: f64 = 0.01;

/// The errors of one image against its reference.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Metrics {
    /// Root-mean-square error over covered pixels and channels.
    pub rmse: f64,
    /// Relative MSE: squared error over (reference² + 1e-2), averaged.
    pub rel_mse: f64,
    /// Mean absolute error over covered pixels and channels.
    pub mae: f64,
    /// Mean LDR-FLIP over covered pixels (0 = identical, 1 = maximally different).
    pub flip: f64,
    /// Share of covered pixels whose display value is off by more than 8 % (0…1).
    pub share_over_8: f64,
}

/// Below this share of the unshadowed light, a pixel of the reference is in an umbra.
pub const UMBRA_BELOW: f64 = 0.02;

/// How much light an image puts where the reference is in an umbra (issue 35: shadow error
/// where the shadows are, not over the whole image), as shares of the unshadowed level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct UmbraLeak {
    /// Umbra pixels.
    pub pixels: usize,
    /// Mean of image / unshadowed over them.
    pub mean: f64,
    /// Its 99th percentile.
    pub p99: f64,
}

/// The covered pixels where `reference` is below [`UMBRA_BELOW`] of `lit` (the unshadowed
/// image) and `lit` is not black.
pub fn umbra_pixels(reference: &Image, lit: &Image, covered: &[bool]) -> Vec<usize> {
    let lum = |p: &[f32; 3]| (f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2])) / 3.0;
    (0..reference.pixels.len())
        .filter(|&i| {
            let l = lum(&lit.pixels[i]);
            covered.get(i) == Some(&true) && l > 0.0 && lum(&reference.pixels[i]) < UMBRA_BELOW * l
        })
        .collect()
}

/// [`UmbraLeak`] of `img` over `umbra` ([`umbra_pixels`]); `None` without umbra pixels.
pub fn umbra_leak(img: &Image, lit: &Image, umbra: &[usize]) -> Option<UmbraLeak> {
    let lum = |p: &[f32; 3]| (f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2])) / 3.0;
    let mut share: Vec<f64> = umbra
        .iter()
        .map(|&i| lum(&img.pixels[i]) / lum(&lit.pixels[i]))
        .filter(|x| x.is_finite())
        .collect();
    if share.is_empty() {
        return None;
    }
    share.sort_by(f64::total_cmp);
    let n = share.len();
    Some(UmbraLeak {
        pixels: n,
        mean: share.iter().sum::<f64>() / n as f64,
        p99: share[(n * 99 / 100).min(n - 1)],
    })
}

/// The pixels that see a surface.
pub fn covered(gbuffer: &GBuffer) -> Vec<bool> {
    gbuffer.tri.iter().map(|&t| t != NONE).collect()
}

/// Every metric of `img` against `reference` over `covered` pixels; PNG-like tone mapping at
/// `exposure` for the display metrics.
pub(crate) fn measure(img: &Image, reference: &Image, covered: &[bool], exposure: f32) -> Metrics {
    let (rmse, mae) = rmse_mae(img, reference, covered);
    let a = img.to_srgb8(exposure);
    let b = reference.to_srgb8(exposure);
    let (mut over, mut n) = (0usize, 0usize);
    for ((p, q), &c) in a.pixels().zip(b.pixels()).zip(covered) {
        if c {
            n += 1;
            let worst = (0..3)
                .map(|k| (f64::from(p.0[k]) - f64::from(q.0[k])).abs() / 255.0)
                .fold(0.0, f64::max);
            if worst > DISPLAY_THRESHOLD {
                over += 1;
            }
        }
    }
    let flip_map = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(b.width(), b.height(), b.as_raw()),
        nv_flip::FlipImageRgb8::with_data(a.width(), a.height(), a.as_raw()),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    )
    .to_vec();
    let flip = masked_mean(&flip_map, covered);
    Metrics {
        rmse,
        rel_mse: rel_mse(img, reference, covered),
        mae,
        flip,
        share_over_8: over as f64 / n.max(1) as f64,
    }
}

/// RMSE and mean absolute error over covered pixels, per channel (see the module docs).
pub fn rmse_mae(a: &Image, b: &Image, covered: &[bool]) -> (f64, f64) {
    let (mut sq, mut abs, mut n) = (0.0, 0.0, 0usize);
    for ((x, y), &c) in a.pixels.iter().zip(&b.pixels).zip(covered) {
        if !c {
            continue;
        }
        for k in 0..3 {
            let d = f64::from(x[k]) - f64::from(y[k]);
            sq += d * d;
            abs += d.abs();
        }
        n += 3;
    }
    let n = n.max(1) as f64;
    ((sq / n).sqrt(), abs / n)
}

/// Relative MSE with the floor τ = [`REL_MSE_FLOOR`] × the reference's covered mean.
/// Undefined against a black reference (no floor to scale by): 0 for an equal image, +∞ for
/// any other.
pub(crate) fn rel_mse(img: &Image, reference: &Image, covered: &[bool]) -> f64 {
    let tau = REL_MSE_FLOOR * covered_mean(reference, covered);
    let tau2 = tau * tau;
    if !(tau2 > 0.0) {
        let equal = img
            .pixels
            .iter()
            .zip(&reference.pixels)
            .zip(covered)
            .all(|((x, r), &c)| !c || x == r);
        return if equal { 0.0 } else { f64::INFINITY };
    }
    let (mut s, mut n) = (0.0, 0usize);
    for ((x, r), &c) in img.pixels.iter().zip(&reference.pixels).zip(covered) {
        if c {
            for k in 0..3 {
                let (x, r) = (f64::from(x[k]), f64::from(r[k]));
                s += (x - r) * (x - r) / (r * r + tau2);
            }
            n += 3;
        }
    }
    s / n.max(1) as f64
}

/// Mean of the three channels over covered pixels.
pub fn covered_mean(img: &Image, covered: &[bool]) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (p, &c) in img.pixels.iter().zip(covered) {
        if c {
            s += p.iter().map(|&v| f64::from(v)).sum::<f64>() / 3.0;
            n += 1;
        }
    }
    s / n.max(1) as f64
}

/// √(mean σ²) over covered pixels and channels of a per-pixel standard-error image: a Monte
/// Carlo reference's own RMSE.
pub(crate) fn rmse_floor(stderr: &Image, covered: &[bool]) -> f64 {
    let (mut s2, mut n) = (0.0, 0usize);
    for (p, &c) in stderr.pixels.iter().zip(covered) {
        if c {
            s2 += p.iter().map(|&v| f64::from(v) * f64::from(v)).sum::<f64>();
            n += 3;
        }
    }
    (s2 / n.max(1) as f64).sqrt()
}

/// Per-pixel mean of two images (two independent estimates → one with half the variance).
pub(crate) fn mean_image(a: &Image, b: &Image) -> Image {
    let mut m = a.clone();
    for (p, q) in m.pixels.iter_mut().zip(&b.pixels) {
        for k in 0..3 {
            p[k] = 0.5 * (p[k] + q[k]);
        }
    }
    m
}

fn masked_mean(values: &[f32], covered: &[bool]) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (&v, &c) in values.iter().zip(covered) {
        if c && v.is_finite() {
            s += f64::from(v);
            n += 1;
        }
    }
    s / n.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(values: &[f32]) -> Image {
        let mut img = Image::new(values.len() as u32, 1);
        for (p, &v) in img.pixels.iter_mut().zip(values) {
            *p = [v; 3];
        }
        img
    }

    #[test]
    fn umbra_leak_is_light_over_the_unshadowed_level_where_the_reference_is_dark() {
        let lit = image(&[1.0, 2.0, 4.0, 1.0, 0.0]);
        let reference = image(&[0.01, 0.0, 3.0, 0.5, 0.0]);
        // Pixels 0 and 1 are below 2 % of the lit level; 2 and 3 are lit; 4 sees no light.
        let umbra = umbra_pixels(&reference, &lit, &[true; 5]);
        assert_eq!(umbra, vec![0, 1]);
        let img = image(&[0.1, 0.0, 3.0, 0.5, 0.0]);
        let u = umbra_leak(&img, &lit, &umbra).expect("an umbra");
        assert_eq!(u.pixels, 2);
        assert!(
            (u.mean - 0.05).abs() < 1e-6 && (u.p99 - 0.1).abs() < 1e-6,
            "{u:?}"
        );
        assert!(umbra_leak(&img, &lit, &[]).is_none());
    }

    #[test]
    fn identical_images_have_no_error() {
        let a = image(&[0.1, 0.5, 2.0, 0.0]);
        let m = measure(&a, &a, &[true; 4], 1.0);
        assert_eq!(m, Metrics::default());
    }

    #[test]
    fn relative_mse_against_black_is_zero_or_infinite() {
        let black = image(&[0.0; 4]);
        let dim = image(&[0.0, 1e-6, 0.0, 0.0]);
        assert_eq!(rel_mse(&black, &black, &[true; 4]), 0.0);
        assert_eq!(rel_mse(&dim, &black, &[true; 4]), f64::INFINITY);
        // Where the difference is not covered, the images are equal.
        assert_eq!(rel_mse(&dim, &black, &[true, false, true, true]), 0.0);
    }

    #[test]
    fn metrics_match_their_definitions() {
        let r = image(&[1.0, 1.0, 0.0, 5.0]);
        let x = image(&[0.25, 1.0, 0.0, 100.0]);
        let covered = [true, true, true, false];
        let (rmse, mae) = rmse_mae(&x, &r, &covered);
        assert!((rmse - (0.5625f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!((mae - 0.75 / 3.0).abs() < 1e-12);
        // τ = 0.01 · 2/3; only the first pixel differs: 0.75² / (1 + τ²) / 3.
        let tau = 0.01 * 2.0 / 3.0;
        assert!((rel_mse(&x, &r, &covered) - 0.5625 / (1.0 + tau * tau) / 3.0).abs() < 1e-9);
        let m = measure(&x, &r, &covered, 1.0);
        // 0.25 and 1.0 tone-map to display values more than 0.08 apart: 1 of 3 pixels.
        assert!((m.share_over_8 - 1.0 / 3.0).abs() < 1e-12);
        assert!(m.flip > 0.0 && m.flip < 1.0, "{}", m.flip);
    }

    #[test]
    fn small_display_differences_are_under_the_threshold() {
        let r = image(&[0.5; 16]);
        let x = image(&[0.51; 16]);
        let m = measure(&x, &r, &[true; 16], 1.0);
        assert_eq!(m.share_over_8, 0.0);
        assert!(m.rmse > 0.0);
    }
}
