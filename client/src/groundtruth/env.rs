//! Monte Carlo ground truth under an environment map: the exact BRDF ([`Brdf`]), ray-traced
//! visibility (rays to infinity), and multiple importance sampling (power heuristic) of
//!
//! - **the map**: a 2D piecewise-constant distribution over texels proportional to luminance ×
//!   solid angle (marginal CDF over rows, conditional CDF per row; Pharr, Jakob, Humphreys,
//!   PBRT 3rd ed., §13.6.7 and §14.2.4), then uniform in solid angle inside the texel, so the
//!   density per solid angle is exactly P(texel)/Ω(texel) — the map is piecewise constant
//!   ([`EnvLight::eval`]), and so is this density;
//! - **the BRDF**: [`Brdf::sample`] (VNDF for the specular lobe, cosine for the diffuse).
//!
//! One sample = one map direction + one BRDF direction, each with a shadow ray.

use std::f64::consts::PI;

use bspvt_proto::Scene;
use bspvt_raytrace::Occluder;
use glam::DVec3;
use rayon::prelude::*;

use super::{Ctx, Estimate, NoiseReport, Pcg32, ShadingPoint, Shadows, finish, power_heuristic};
use crate::envmap::EnvLight;
use crate::frame::camera::View;
use crate::frame::gbuffer::GBuffer;
use crate::frame::image::Image;
use crate::frame::shading::ShadingFrame;

/// Importance sampling of an environment map by texel luminance × solid angle.
#[derive(Clone, Debug)]
pub struct EnvSampler {
    width: usize,
    height: usize,
    /// Row CDF (len height + 1, last = 1).
    marginal: Vec<f64>,
    /// Per-row CDFs (height × (width + 1)).
    conditional: Vec<f64>,
    /// Probability of each texel.
    prob: Vec<f64>,
    /// Solid angle of a texel per row.
    omega: Vec<f64>,
}

fn luminance(p: [f32; 3]) -> f64 {
    crate::frame::stats::luminance(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
}

impl EnvSampler {
    /// `None` when the map is black (nothing to sample; the BRDF strategy alone is exact then:
    /// the radiance is zero).
    pub(crate) fn new(env: &EnvLight) -> Option<EnvSampler> {
        let (w, h) = (env.width as usize, env.height as usize);
        let omega: Vec<f64> = (0..h).map(|y| env.texel_solid_angle(y)).collect();
        let mut conditional = vec![0.0; h * (w + 1)];
        let mut row_sum = vec![0.0; h];
        for y in 0..h {
            let c = &mut conditional[y * (w + 1)..(y + 1) * (w + 1)];
            for x in 0..w {
                c[x + 1] = c[x] + luminance(env.pixels[y * w + x]).max(0.0) * omega[y];
            }
            row_sum[y] = c[w];
            if c[w] > 0.0 {
                let s = c[w];
                c.iter_mut().for_each(|v| *v /= s);
            }
        }
        let total: f64 = row_sum.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let mut marginal = vec![0.0; h + 1];
        for y in 0..h {
            marginal[y + 1] = marginal[y] + row_sum[y] / total;
        }
        marginal[h] = 1.0;
        let mut prob = vec![0.0; w * h];
        for y in 0..h {
            for x in 0..w {
                prob[y * w + x] = luminance(env.pixels[y * w + x]).max(0.0) * omega[y] / total;
            }
        }
        Some(EnvSampler {
            width: w,
            height: h,
            marginal,
            conditional,
            prob,
            omega,
        })
    }

    /// Index i with cdf[i] ≤ u < cdf[i + 1], skipping empty intervals.
    fn pick(cdf: &[f64], u: f64) -> usize {
        let n = cdf.len() - 1;
        let i = cdf
            .partition_point(|&c| c <= u)
            .saturating_sub(1)
            .min(n - 1);
        // Never return an interval of zero probability (u exactly on a plateau).
        let mut i = i;
        while i + 1 < n && !(cdf[i + 1] > cdf[i]) {
            i += 1;
        }
        i
    }

    /// A direction and its density per solid angle from four uniform numbers.
    pub(crate) fn sample(&self, u: [f64; 4]) -> Option<(DVec3, f64)> {
        let y = Self::pick(&self.marginal, u[0]);
        let row = &self.conditional[y * (self.width + 1)..(y + 1) * (self.width + 1)];
        let x = Self::pick(row, u[1]);
        let p = self.prob[y * self.width + x];
        if !(p > 0.0) {
            return None;
        }
        let (w, h) = (self.width as f64, self.height as f64);
        // Uniform in solid angle inside the texel: φ uniform, cos θ uniform.
        let (t0, t1) = (PI * y as f64 / h, PI * (y + 1) as f64 / h);
        let ct = t0.cos() + u[2] * (t1.cos() - t0.cos());
        let u_img = (x as f64 + u[3]) / w;
        let phi = 2.0 * PI * u_img - PI;
        let st = (1.0 - ct * ct).max(0.0).sqrt();
        let d = DVec3::new(st * phi.cos(), ct, st * phi.sin());
        Some((d, p / self.omega[y]))
    }

    /// Density per solid angle of [`EnvSampler::sample`] producing `d`.
    pub(crate) fn pdf(&self, env: &EnvLight, d: DVec3) -> f64 {
        let (x, y) = env.texel_of(d);
        self.prob[y * self.width + x] / self.omega[y]
    }
}

/// `spp` MIS samples at one point.
#[allow(clippy::too_many_arguments)]
fn shade_point(
    sp: &ShadingPoint,
    brdf: &super::Brdf,
    env: &EnvLight,
    sampler: Option<&EnvSampler>,
    shadows: &Shadows,
    spp: u64,
    rng: &mut Pcg32,
) -> Estimate {
    let mut est = Estimate::default();
    let ok = |v: DVec3| v.is_finite() && v.length_squared() > 0.0;
    if !(sp.position.is_finite() && ok(sp.normal) && ok(sp.geometric) && ok(sp.wo)) {
        est.push_zeros(spp);
        return est;
    }
    let frame = ShadingFrame::new(sp.normal.normalize(), sp.wo.normalize());
    let wo = frame.to_local(sp.wo.normalize());
    if !(wo.z > 0.0) {
        est.push_zeros(spp);
        return est;
    }
    let ng = sp.geometric.normalize();
    // "Infinitely far": 1e4 scene diagonals (ε is 1e-4 diagonals; the segment test needs an
    // end point).
    let far = 1e8 * shadows.epsilon.max(1e-12);
    for _ in 0..spp {
        let mut v = DVec3::ZERO;
        let u_env = [
            rng.next_f64(),
            rng.next_f64(),
            rng.next_f64(),
            rng.next_f64(),
        ];
        let u_lobe = rng.next_f64();
        let u_brdf = rng.next_2d();
        if let Some((dir, pl)) = sampler.and_then(|s| s.sample(u_env)) {
            let wi = frame.to_local(dir);
            let f = brdf.eval_cos(wo, wi);
            if f != DVec3::ZERO {
                let w = power_heuristic(pl, brdf.pdf(wo, wi));
                if w > 0.0 && shadows.visible(sp.position, ng, dir, far) {
                    v += env.eval(dir) * f * (w / pl);
                }
            }
        }
        let wi = brdf.sample(wo, u_lobe, u_brdf);
        if wi.z > 0.0 && wi.is_finite() {
            let dir = frame.to_world(wi).normalize();
            let pb = brdf.pdf(wo, wi);
            let f = brdf.eval_cos(wo, wi);
            if pb > 0.0 && f != DVec3::ZERO {
                let pl = sampler.map_or(0.0, |s| s.pdf(env, dir));
                let w = power_heuristic(pb, pl);
                if w > 0.0 && shadows.visible(sp.position, ng, dir, far) {
                    v += env.eval(dir) * f * (w / pb);
                }
            }
        }
        est.push(if v.is_finite() { v } else { DVec3::ZERO });
    }
    est
}

/// Monte Carlo reference under `env` at the G-buffer's pixel centres (the points the SG
/// renderer shades), `spp` MIS samples per pixel, reproducible for `seed`. Pixels without a
/// surface are black.
pub fn render_mc_env(
    scene: &Scene,
    view: &View,
    gbuffer: &GBuffer,
    env: &EnvLight,
    occluder: &Occluder,
    spp: u32,
    seed: u64,
) -> (Image, NoiseReport) {
    let ctx = Ctx::new(scene, Some(occluder));
    let sampler = EnvSampler::new(env);
    let n = gbuffer.width as usize * gbuffer.height as usize;
    let est: Vec<Option<Estimate>> = (0..n)
        .into_par_iter()
        .with_min_len(16)
        .map(|i| {
            let s = gbuffer.surface(&ctx.scene.mesh, view, i)?;
            let sp = ShadingPoint::from_surface(&s, view.eye);
            let mut rng = Pcg32::for_key(seed, i as u64);
            Some(shade_point(
                &sp,
                &ctx.brdf(&s),
                env,
                sampler.as_ref(),
                &ctx.shadows,
                u64::from(spp.max(1)),
                &mut rng,
            ))
        })
        .collect();
    finish(gbuffer.width, gbuffer.height, &est)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::brdf::Brdf;

    /// The sampler's density integrates to 1 and matches the histogram of its samples.
    #[test]
    fn sampler_density_is_consistent() {
        let mut px = vec![[0.01f32; 3]; 32 * 16];
        px[3 * 32 + 5] = [50.0, 40.0, 30.0];
        px[10 * 32 + 20] = [0.0; 3];
        let env = EnvLight::from_pixels(32, 16, px).expect("map");
        let s = EnvSampler::new(&env).expect("not black");
        let total: f64 = (0..16)
            .map(|y| {
                (0..32)
                    .map(|x| {
                        let d =
                            EnvLight::direction((x as f64 + 0.5) / 32.0, (y as f64 + 0.5) / 16.0);
                        s.pdf(&env, d) * env.texel_solid_angle(y)
                    })
                    .sum::<f64>()
            })
            .sum();
        assert!((total - 1.0).abs() < 1e-9, "{total}");
        let mut rng = Pcg32::new(7, 1);
        let mut hits = vec![0u32; 32 * 16];
        let n = 200_000;
        for _ in 0..n {
            let u = [
                rng.next_f64(),
                rng.next_f64(),
                rng.next_f64(),
                rng.next_f64(),
            ];
            let (d, p) = s.sample(u).expect("sample");
            assert!((p - s.pdf(&env, d)).abs() <= 1e-9 * p, "pdf mismatch");
            let (x, y) = env.texel_of(d);
            hits[y * 32 + x] += 1;
        }
        assert_eq!(hits[10 * 32 + 20], 0, "black texel sampled");
        let k = 3 * 32 + 5;
        let want = s.prob[k];
        let got = f64::from(hits[k]) / n as f64;
        assert!((got - want).abs() < 0.01, "{got} vs {want}");
        assert!(EnvSampler::new(&EnvLight::constant([0.0; 3])).is_none());
    }

    /// Furnace test: a white diffuse plane (nothing above it) under a constant map L reflects
    /// albedo × L; the estimate is unbiased within its standard error.
    #[test]
    fn furnace_diffuse() {
        let env = EnvLight::constant([1.0, 1.0, 1.0]);
        let sampler = EnvSampler::new(&env);
        let brdf = Brdf::new(0.5, DVec3::splat(0.8), DVec3::ZERO);
        let sp = ShadingPoint {
            position: DVec3::ZERO,
            normal: DVec3::Y,
            geometric: DVec3::Y,
            wo: DVec3::new(0.3, 0.9, 0.1).normalize(),
        };
        let shadows = Shadows {
            occluder: None,
            epsilon: 1e-4,
            lamps: Vec::new(),
        };
        let mut rng = Pcg32::new(3, 9);
        let e = shade_point(&sp, &brdf, &env, sampler.as_ref(), &shadows, 4000, &mut rng);
        let se = e.std_error();
        assert!(
            (e.mean.x - 0.8).abs() < 4.0 * se.x + 1e-3,
            "{} ± {}",
            e.mean.x,
            se.x
        );
    }
}
