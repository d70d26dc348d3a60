//! Ground-truth renderers: what the LTC + BSPVT shading is measured against.
//!
//! # Monte Carlo with the exact BRDF ([`shade_mc`], [`render_mc`], [`render_mc_box`],
//! [`render_mc_until`])
//!
//! Direct lighting from one polygonal light, L_o(ωo) = ∫_P L_e(ωi) f(ωo, ωi) cos θi V(ωi) dωi,
//! with the project's BRDF ([`crate::ggx`]): f = albedo/π + F·D·G₁(ωo)G₁(ωi)/(4 cos θo cos θi),
//! GGX D, separable Smith G, Schlick F = F0 + (1 − F0)(1 − ωi·h)⁵, per RGB channel, and V from
//! shadow rays against the mesh. Each sample combines two strategies with multiple importance
//! sampling (Veach & Guibas 1995, "Optimally Combining Sampling Techniques for Monte Carlo
//! Rendering"; Veach's thesis 1997, §9.2), power heuristic β = 2:
//!
//! - **light**: uniform in solid angle over the light polygon clipped to the shading
//!   hemisphere (fan of spherical triangles, Arvo 1995), or uniform in area when it subtends
//!   less than [`sampling::AREA_SAMPLING_BELOW_SR`] ([`sampling`]);
//! - **BRDF**: a one-sample mixture of the visible-normal distribution for the specular lobe
//!   (Heitz 2018, "Sampling the GGX Distribution of Visible Normals", [`crate::ggx::sample_vndf`])
//!   and the cosine for the diffuse lobe, chosen with probability by lobe weight; its pdf is
//!   the mixture's.
//!
//! One sample = one light direction + one BRDF direction, each with a shadow ray:
//! X = Σ_s L_e f cos V w_s / p_s with w_s = p_s² / (p_light² + p_brdf²). The per-sample values
//! are independent, so their sample variance gives the standard error of each pixel
//! ([`Estimate`]); [`NoiseReport`] states the image's noise level.
//!
//! Random numbers: one PCG32 per pixel seeded from (seed, pixel index[, round]) — images are
//! reproducible bit for bit whatever the thread count.
//!
//! # LTC with exact visibility ([`render_ltc_exact_visibility`])
//!
//! The LTC BRDF (Heitz et al. 2016) with the visibility of many shadow rays instead of the
//! BSPVT's: ∫_P D V ≈ (∫_P D) · Σ wⱼ Vⱼ / Σ wⱼ, see [`ltcvis`]. Against it, the BSPVT shading
//! shows visibility error alone; against [`render_mc`], it shows the BRDF-fit error alone
//! (the split of the paper's figure 8).
//!
//! # Robustness
//!
//! No input makes NaN or Inf: α is clamped to [1e-4, 1]; a light behind a one-sided light's
//! plane, in its plane, or below the horizon contributes 0; pdf ratios are formed before
//! squaring; numerically failed samples contribute 0. `client/tests/groundtruth.rs` checks
//! random α, views to 89.99°, lights from 1e-8 sr to nearly 2π and scales 1e-4…1e4.

pub(crate) mod env;
pub mod ltcvis;
pub(crate) mod primary;
pub(crate) mod rng;
pub(crate) mod sampling;

use std::fmt;

use bspvt_proto::Scene;
use bspvt_proto::scene::Material;
use bspvt_raytrace::Occluder;
use glam::DVec3;
use rayon::prelude::*;

use crate::frame::brdf::{Brdf, Shadows, cosine_hemisphere};
use crate::frame::camera::View;
use crate::frame::gbuffer::{GBuffer, Surface};
use crate::frame::image::Image;
use crate::frame::shading::ShadingFrame;
use crate::light::{Light, Shape};

pub use env::{EnvSampler, render_mc_env};
pub use ltcvis::{
    LtcLobe, builtin_lookup, render_ltc_exact_visibility, shade_ltc_exact_visibility,
};
pub use primary::Tracer;
pub use rng::Pcg32;
use sampling::{ConeSampler, LightSampler, PolygonSampler};

/// A point to shade.
#[derive(Clone, Copy, Debug)]
pub struct ShadingPoint {
    /// World position.
    pub position: DVec3,
    /// Unit shading normal (the BRDF's z), on the viewer's side.
    pub normal: DVec3,
    /// Unit geometric normal, on the viewer's side (shadow-ray offsets).
    pub geometric: DVec3,
    /// Unit direction toward the viewer.
    pub wo: DVec3,
}

impl ShadingPoint {
    pub(crate) fn from_surface(s: &Surface, eye: DVec3) -> ShadingPoint {
        ShadingPoint {
            position: s.position,
            normal: s.normal,
            geometric: s.geometric,
            wo: (eye - s.position).normalize_or(s.normal),
        }
    }
}

/// Running mean and variance of i.i.d. per-sample values (Welford; Chan et al. to merge).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Estimate {
    pub(crate) n: u64,
    /// The running mean per channel.
    pub mean: DVec3,
    m2: DVec3,
}

impl Estimate {
    #[inline]
    pub(crate) fn push(&mut self, x: DVec3) {
        self.n += 1;
        let d = x - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (x - self.mean);
    }

    /// `k` samples of value zero.
    pub(crate) fn push_zeros(&mut self, k: u64) {
        self.merge(&Estimate {
            n: k,
            mean: DVec3::ZERO,
            m2: DVec3::ZERO,
        });
    }

    pub(crate) fn merge(&mut self, o: &Estimate) {
        if o.n == 0 {
            return;
        }
        if self.n == 0 {
            *self = *o;
            return;
        }
        let n = self.n + o.n;
        let d = o.mean - self.mean;
        let f = o.n as f64 / n as f64;
        self.mean += d * f;
        self.m2 += o.m2 + d * d * (self.n as f64 * f);
        self.n = n;
    }

    /// Sample variance of one sample (per channel).
    pub(crate) fn variance(&self) -> DVec3 {
        if self.n < 2 {
            return DVec3::ZERO;
        }
        (self.m2 / (self.n - 1) as f64).max(DVec3::ZERO)
    }

    /// Standard error of the mean (per channel).
    pub fn std_error(&self) -> DVec3 {
        if self.n == 0 {
            return DVec3::ZERO;
        }
        (self.variance() / self.n as f64).map(f64::sqrt)
    }
}

/// A shading point with its light sampler, reused by every sample of the point.
pub(crate) struct McPoint {
    position: DVec3,
    geometric: DVec3,
    frame: ShadingFrame,
    wo: DVec3,
    sampler: LightSampler,
    /// A spot's cone and a range's window toward this point (1 for the others).
    emission: f64,
}

impl McPoint {
    pub(crate) fn new(sp: &ShadingPoint, light: &Light) -> Option<McPoint> {
        let ok = |v: DVec3| v.is_finite() && v.length_squared() > 0.0;
        if !(sp.position.is_finite() && ok(sp.normal) && ok(sp.geometric) && ok(sp.wo)) {
            return None;
        }
        let n = sp.normal.normalize();
        let frame = ShadingFrame::new(n, sp.wo.normalize());
        let wo = frame.to_local(sp.wo.normalize());
        if wo.z.is_nan() || wo.z <= 0.0 || !light.faces(sp.position) {
            return None;
        }
        let sampler = match &light.shape {
            Shape::Polygon => {
                if light.vertices.len() < 3 {
                    return None;
                }
                let offsets: Vec<DVec3> = light.vertices.iter().map(|&q| q - sp.position).collect();
                LightSampler::Polygon(PolygonSampler::new(&offsets, light.normal, Some(n))?)
            }
            Shape::Sphere(l) => LightSampler::Cone(ConeSampler::sphere(
                glam::Vec3::from(l.position).as_dvec3() - sp.position,
                f64::from(l.sphere_radius()),
            )?),
            Shape::Distant { toward, half_angle } => {
                LightSampler::Cone(ConeSampler::distant(*toward, *half_angle)?)
            }
        };
        let emission = match &light.shape {
            Shape::Sphere(l) => f64::from(l.falloff(sp.position.as_vec3())),
            _ => 1.0,
        };
        Some(McPoint {
            position: sp.position,
            geometric: sp.geometric.normalize(),
            frame,
            wo,
            sampler,
            emission,
        })
    }

    /// The radiance `light` sends back along `dir` from distance `dist`.
    fn emitted(&self, light: &Light, dir: DVec3, dist: f64) -> DVec3 {
        match light.shape {
            Shape::Polygon => light.radiance_at(self.position + dir * dist) * self.emission,
            _ => light.radiance * self.emission,
        }
    }

    /// One MIS sample: a light direction and a BRDF direction.
    fn sample(&self, brdf: &Brdf, light: &Light, shadows: &Shadows, rng: &mut Pcg32) -> DVec3 {
        self.sample_pair(brdf, light, Some(shadows), rng).shadowed
    }

    /// One MIS sample, with and without its shadow rays (the same directions): what the ratio
    /// estimator needs. `shadows: None` skips the rays (`shadowed` is then 0).
    pub(crate) fn sample_pair(
        &self,
        brdf: &Brdf,
        light: &Light,
        shadows: Option<&Shadows>,
        rng: &mut Pcg32,
    ) -> SamplePair {
        let mut pair = SamplePair::default();
        let u_light = rng.next_2d();
        let u_lobe = rng.next_f64();
        let u_brdf = rng.next_2d();
        let mut add = |dir: DVec3, dist: f64, value: DVec3| {
            if !value.is_finite() {
                return;
            }
            pair.unshadowed += value;
            if shadows.is_some_and(|s| s.visible(self.position, self.geometric, dir, dist)) {
                pair.shadowed += value;
            }
        };

        if let Some(ls) = self.sampler.sample(u_light) {
            let wi = self.frame.to_local(ls.dir);
            let f = brdf.eval_cos(self.wo, wi);
            if f != DVec3::ZERO {
                let w = power_heuristic(ls.pdf, brdf.pdf(self.wo, wi));
                if w > 0.0 {
                    let le = self.emitted(light, ls.dir, ls.dist);
                    add(ls.dir, ls.dist, le * f * (w / ls.pdf));
                }
            }
        }

        let wi = brdf.sample(self.wo, u_lobe, u_brdf);
        if wi.z > 0.0 && wi.is_finite() {
            let dir = self.frame.to_world(wi).normalize();
            if let Some((dist, pl)) = self.sampler.pdf(dir) {
                let pb = brdf.pdf(self.wo, wi);
                let f = brdf.eval_cos(self.wo, wi);
                if pb > 0.0 && f != DVec3::ZERO {
                    let w = power_heuristic(pb, pl);
                    if w > 0.0 {
                        let le = self.emitted(light, dir, dist);
                        add(dir, dist, le * f * (w / pb));
                    }
                }
            }
        }
        pair
    }
}

/// One Monte Carlo sample's contribution with visibility (shadow rays) and without.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct SamplePair {
    pub(crate) shadowed: DVec3,
    pub(crate) unshadowed: DVec3,
}

/// Veach's power heuristic (β = 2) for the strategy with density `pa` against `pb`.
#[inline]
fn power_heuristic(pa: f64, pb: f64) -> f64 {
    if pa.is_nan() || pa <= 0.0 {
        return 0.0;
    }
    let r = pb / pa;
    let w = 1.0 / (1.0 + r * r);
    if w.is_finite() { w } else { 0.0 }
}

/// `spp` MIS samples of the reflected radiance at one point (linear RGB): the estimate is
/// `result.mean`, its standard error `result.std_error()`.
pub fn shade_mc(
    sp: &ShadingPoint,
    brdf: &Brdf,
    light: &Light,
    shadows: &Shadows,
    spp: u32,
    rng: &mut Pcg32,
) -> Estimate {
    let mut est = Estimate::default();
    match McPoint::new(sp, light) {
        None => est.push_zeros(u64::from(spp)),
        Some(pt) => {
            for _ in 0..spp {
                est.push(pt.sample(brdf, light, shadows, rng));
            }
        }
    }
    est
}

/// One shading point's samplers for several lights: a sample is the sum of one MIS sample of
/// each light the point can see (direct light is linear in the lights; a light behind the
/// point or below its horizon costs nothing).
struct McLights<'a> {
    points: Vec<(McPoint, &'a Light)>,
}

impl<'a> McLights<'a> {
    fn new(sp: &ShadingPoint, lights: &'a [Light]) -> McLights<'a> {
        McLights {
            points: lights
                .iter()
                .filter_map(|l| McPoint::new(sp, l).map(|p| (p, l)))
                .collect(),
        }
    }

    /// `k` samples into `est`.
    fn sample_into(
        &self,
        est: &mut Estimate,
        brdf: &Brdf,
        shadows: &Shadows,
        k: u64,
        rng: &mut Pcg32,
    ) {
        if self.points.is_empty() {
            est.push_zeros(k);
            return;
        }
        for _ in 0..k {
            est.push(self.sample(brdf, shadows, rng));
        }
    }

    fn sample(&self, brdf: &Brdf, shadows: &Shadows, rng: &mut Pcg32) -> DVec3 {
        self.points
            .iter()
            .map(|(pt, l)| pt.sample(brdf, l, shadows, rng))
            .sum()
    }
}

/// The noise level of a Monte Carlo image.
///
/// Per covered pixel: m = mean of the three channels' estimates, s = mean of their standard
/// errors, and the relative standard error r = s / max(m, τ) with τ = [`REL_FLOOR`] × the
/// image's mean m (so pixels in umbra or nearly black do not divide by ~0). The report gives
/// the mean, 95th percentile and maximum of r over covered pixels.
#[derive(Clone, Debug)]
pub struct NoiseReport {
    /// Pixels that see a surface (box-filtered images: any sample did).
    pub covered: usize,
    pub(crate) spp_min: u64,
    /// Most samples any pixel took.
    pub spp_max: u64,
    /// Mean samples per covered pixel.
    pub spp_mean: f64,
    /// Mean relative standard error r over covered pixels.
    pub mean_rel_stderr: f64,
    pub(crate) p95_rel_stderr: f64,
    pub(crate) max_rel_stderr: f64,
    /// τ: the floor of the relative error's denominator.
    pub(crate) rel_floor: f64,
    /// Mean over covered pixels of s (absolute standard error, same units as the image).
    pub(crate) mean_stderr: f64,
    /// [`render_mc_until`] only: pixels still above the target relative error (they reached
    /// `max_spp`).
    pub(crate) unconverged: Option<usize>,
    /// Standard error of each pixel, per channel.
    pub stderr: Image,
}

/// τ / image mean in [`NoiseReport`].
pub(crate) const REL_FLOOR: f64 = 0.01;

impl fmt::Display for NoiseReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} px, {}–{} spp (mean {:.0}): relative standard error mean {:.3} %, p95 {:.3} %, \
             max {:.3} % (floor {:.3e}); mean absolute {:.3e}",
            self.covered,
            self.spp_min,
            self.spp_max,
            self.spp_mean,
            100.0 * self.mean_rel_stderr,
            100.0 * self.p95_rel_stderr,
            100.0 * self.max_rel_stderr,
            self.rel_floor,
            self.mean_stderr
        )?;
        if let Some(u) = self.unconverged {
            write!(f, "; {u} px above the target at the maximum spp")?;
        }
        Ok(())
    }
}

pub(crate) fn chan_mean(v: DVec3) -> f64 {
    (v.x + v.y + v.z) / 3.0
}

fn rel_floor(est: &[Option<Estimate>]) -> f64 {
    let (s, k) = est
        .iter()
        .flatten()
        .fold((0.0, 0usize), |(s, k), e| (s + chan_mean(e.mean), k + 1));
    REL_FLOOR * s / k.max(1) as f64
}

fn rel_stderr(e: &Estimate, floor: f64) -> f64 {
    let s = chan_mean(e.std_error());
    if s == 0.0 {
        return 0.0;
    }
    s / chan_mean(e.mean).max(floor).max(f64::MIN_POSITIVE)
}

/// The image and its noise report from per-pixel estimates (`None`: no surface).
pub(crate) fn finish(width: u32, height: u32, est: &[Option<Estimate>]) -> (Image, NoiseReport) {
    let mut img = Image::new(width, height);
    let mut se = Image::new(width, height);
    let floor = rel_floor(est);
    let mut rel = Vec::new();
    let (mut smin, mut smax, mut ssum, mut abs_sum) = (u64::MAX, 0, 0u64, 0.0);
    for (i, e) in est.iter().enumerate() {
        let Some(e) = e else { continue };
        let m = e.mean.as_vec3().to_array();
        let s = e.std_error();
        img.pixels[i] = m;
        se.pixels[i] = s.as_vec3().to_array();
        rel.push(rel_stderr(e, floor));
        smin = smin.min(e.n);
        smax = smax.max(e.n);
        ssum += e.n;
        abs_sum += chan_mean(s);
    }
    let covered = rel.len();
    rel.sort_by(f64::total_cmp);
    let pct = |q: f64| {
        if rel.is_empty() {
            0.0
        } else {
            rel[((rel.len() - 1) as f64 * q).round() as usize]
        }
    };
    let report = NoiseReport {
        covered,
        spp_min: if covered == 0 { 0 } else { smin },
        spp_max: smax,
        spp_mean: ssum as f64 / covered.max(1) as f64,
        mean_rel_stderr: rel.iter().sum::<f64>() / covered.max(1) as f64,
        p95_rel_stderr: pct(0.95),
        max_rel_stderr: pct(1.0),
        rel_floor: floor,
        mean_stderr: abs_sum / covered.max(1) as f64,
        unconverged: None,
        stderr: se,
    };
    (img, report)
}

/// Per-scene shading state shared by the renderers.
pub(crate) struct Ctx<'a> {
    scene: &'a Scene,
    brdfs: Vec<Brdf>,
    fallback: Brdf,
    pub(crate) shadows: Shadows<'a>,
}

impl<'a> Ctx<'a> {
    pub(crate) fn new(scene: &'a Scene, occluder: Option<&'a Occluder>) -> Ctx<'a> {
        Ctx {
            scene,
            brdfs: scene.materials.iter().map(Brdf::from_material).collect(),
            fallback: Brdf::from_material(&Material::default()),
            shadows: Shadows::for_scene(scene, occluder),
        }
    }

    /// Shadow rays also stopped by `lamps` (each a surface in the way of the others).
    pub(crate) fn with_lamps(mut self, lamps: &[Light]) -> Ctx<'a> {
        self.shadows.lamps = lamps.iter().filter_map(Light::surface).collect();
        self
    }

    /// The BRDF at a shading point: its triangle's material, evaluated through the mesh's
    /// UVs where the material is textured (the same texels, mipmapped alike, the per-pixel
    /// LTC shades with).
    pub(crate) fn brdf(&self, s: &crate::frame::gbuffer::Surface) -> Brdf {
        let mesh = &self.scene.mesh;
        let id = mesh.material_ids.get(s.tri as usize).copied();
        let textured = id
            .and_then(|m| self.scene.materials.get(m as usize))
            .filter(|m| m.maps.is_some());
        if let Some(m) = textured
            && let Some(uv) = mesh.uv_at(s.tri as usize, s.weights)
        {
            return Brdf::from_material(&m.at_footprint(Some(uv), s.duv));
        }
        id.and_then(|m| self.brdfs.get(m as usize))
            .copied()
            .unwrap_or(self.fallback)
    }
}

/// Monte Carlo ground truth of `lights` (their sum) at the G-buffer's shading points (pixel
/// centres — the same points the LTC and BSPVT renderers shade), `spp` samples per pixel,
/// reproducible for a given `seed`. Pixels without a surface are black.
pub fn render_mc(
    scene: &Scene,
    view: &View,
    gbuffer: &GBuffer,
    lights: &[Light],
    occluder: &Occluder,
    spp: u32,
    seed: u64,
) -> (Image, NoiseReport) {
    let ctx = Ctx::new(scene, Some(occluder)).with_lamps(lights);
    let est = centre_pass(&ctx, view, gbuffer, lights, seed, &|_| u64::from(spp));
    finish(gbuffer.width, gbuffer.height, &est)
}

/// Stopping rule of [`render_mc_until`].
#[derive(Clone, Copy, Debug)]
pub struct Convergence {
    /// Stop sampling a pixel once its relative standard error (as in [`NoiseReport`]) is at
    /// most this.
    pub target_rel_stderr: f64,
    /// Samples of the first round (every pixel).
    pub min_spp: u32,
    /// No pixel gets more.
    pub max_spp: u32,
}

/// [`render_mc`] until converged: rounds of sampling in which every pixel whose relative
/// standard error still exceeds the target doubles its sample count (at most `max_spp`).
/// Pixels that reach `max_spp` unconverged show in the report's maximum and p95.
pub fn render_mc_until(
    scene: &Scene,
    view: &View,
    gbuffer: &GBuffer,
    lights: &[Light],
    occluder: &Occluder,
    conv: &Convergence,
    seed: u64,
) -> (Image, NoiseReport) {
    let ctx = Ctx::new(scene, Some(occluder)).with_lamps(lights);
    let min = u64::from(conv.min_spp.max(2));
    let max = u64::from(conv.max_spp).max(min);
    let mut est = centre_pass(&ctx, view, gbuffer, lights, seed, &|_| min);
    for round in 1..64u64 {
        let floor = rel_floor(&est);
        let more: Vec<u64> = est
            .iter()
            .map(|e| match e {
                Some(e) if e.n < max && rel_stderr(e, floor) > conv.target_rel_stderr => {
                    e.n.min(max - e.n)
                }
                _ => 0,
            })
            .collect();
        if more.iter().all(|&k| k == 0) {
            break;
        }
        let round_seed = rng::splitmix64(seed ^ round.wrapping_mul(0xA24B_AED4_963E_E407));
        let add = centre_pass(&ctx, view, gbuffer, lights, round_seed, &|i| more[i]);
        for (e, a) in est.iter_mut().zip(&add) {
            if let (Some(e), Some(a)) = (e.as_mut(), a) {
                e.merge(a);
            }
        }
    }
    let (img, mut report) = finish(gbuffer.width, gbuffer.height, &est);
    let floor = report.rel_floor;
    report.unconverged = Some(
        est.iter()
            .flatten()
            .filter(|e| rel_stderr(e, floor) > conv.target_rel_stderr)
            .count(),
    );
    (img, report)
}

/// One pass over the G-buffer's pixels with `spp(i)` samples at pixel `i` (pixels given 0
/// return an empty estimate).
fn centre_pass(
    ctx: &Ctx,
    view: &View,
    gbuffer: &GBuffer,
    lights: &[Light],
    seed: u64,
    spp: &(dyn Fn(usize) -> u64 + Sync),
) -> Vec<Option<Estimate>> {
    let n = gbuffer.width as usize * gbuffer.height as usize;
    (0..n)
        .into_par_iter()
        .with_min_len(64)
        .map(|i| {
            let s = gbuffer.surface(&ctx.scene.mesh, view, i)?;
            let k = spp(i);
            if k == 0 {
                return Some(Estimate::default());
            }
            let sp = ShadingPoint::from_surface(&s, view.eye);
            let brdf = &ctx.brdf(&s);
            let mut rng = Pcg32::for_key(seed, i as u64);
            let mut est = Estimate::default();
            McLights::new(&sp, lights).sample_into(&mut est, brdf, &ctx.shadows, k, &mut rng);
            Some(est)
        })
        .collect()
}

/// Monte Carlo ground truth with box-filtered pixels: every sample follows its own camera ray
/// through a uniformly jittered point of the pixel (closest hit by `tracer`), then one MIS
/// sample is shaded there. This is what an independent renderer with a box reconstruction
/// filter computes (the Mitsuba cross-check); rays that miss the mesh count as black.
pub fn render_mc_box(
    scene: &Scene,
    view: &View,
    tracer: &Tracer,
    lights: &[Light],
    occluder: &Occluder,
    spp: u32,
    seed: u64,
) -> (Image, NoiseReport) {
    let ctx = Ctx::new(scene, Some(occluder)).with_lamps(lights);
    let (w, h) = (view.width as usize, view.height as usize);
    let est: Vec<Option<Estimate>> = (0..w * h)
        .into_par_iter()
        .with_min_len(16)
        .map(|i| {
            let mut rng = Pcg32::for_key(seed, i as u64);
            let (px, py) = ((i % w) as f64, (i / w) as f64);
            let mut est = Estimate::default();
            let mut hit = false;
            for _ in 0..spp {
                let [jx, jy] = rng.next_2d();
                let dir = view.ray_dir(px + jx, py + jy);
                let v = match tracer.surface(&ctx.scene.mesh, view.eye, dir) {
                    None => DVec3::ZERO,
                    Some(s) => {
                        hit = true;
                        let sp = ShadingPoint::from_surface(&s, view.eye);
                        McLights::new(&sp, lights).sample(&ctx.brdf(&s), &ctx.shadows, &mut rng)
                    }
                };
                est.push(v);
            }
            hit.then_some(est)
        })
        .collect();
    finish(view.width, view.height, &est)
}
