//! Fitting K spherical Gaussians with RGB amplitudes to an environment map.
//!
//! Objective: the solid-angle-weighted squared error over the sphere,
//! E = Σ_i ω_i ‖Σ_k c_k G_k(d_i) − L_i‖², on a downsampled copy of the map
//! ([`FitOptions::map_width`] × half that), with G_k(d) = exp(λ_k(p_k·d − 1)).
//!
//! Optimiser: variable projection (Golub & Pereyra 1973; Kaufman 1975). For fixed axes and
//! sharpness the amplitudes c_k ∈ ℝ³ are a linear least-squares problem, solved exactly
//! (normal equations, Cholesky, a 1e-9 relative ridge); the remaining 3K parameters —
//! axes (on the sphere) and ln λ (clamped to [ln 1e-3, ln 1e5]) — follow Adam (Kingma & Ba
//! 2015) on the gradient of the projected objective (by the envelope theorem, the gradient with
//! the optimal amplitudes held fixed). Negative amplitudes are clamped to 0 after each solve
//! (light is non-negative), and the solve is repeated without the clamped lobes.
//!
//! Initialisation (from the brightest regions): matching pursuit — each new lobe sits on the
//! texel of largest remaining (residual) luminance, with the sharpness among {1, 4, …, 4⁷} that
//! best fits the residual there.
//!
//! Reported error: relative L2 over the sphere on the full-resolution map,
//! √(Σ ω ‖fit − L‖²) / √(Σ ω ‖L‖²).
//!
//! No crate: `argmin` would add a dependency tree for a 40-line Adam loop, and the variable
//! projection (the part that makes the fit fast) is problem-specific anyway.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::Sg;
use crate::envmap::EnvLight;

/// Sharpness bounds of the fit.
pub(crate) const LN_LAMBDA_MIN: f64 = -6.907_755_278_982_137; // ln 1e-3
pub(crate) const LN_LAMBDA_MAX: f64 = 11.512_925_464_970_229; // ln 1e5

/// One lighting lobe: an SG of unit amplitude times an RGB radiance.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LightLobe {
    pub(crate) axis: [f64; 3],
    pub(crate) lambda: f64,
    pub(crate) rgb: [f64; 3],
}

impl LightLobe {
    /// The lobe's shape (μ = 1).
    pub(crate) fn sg(&self) -> Sg {
        Sg::new(DVec3::from(self.axis), self.lambda, 1.0)
    }

    pub(crate) fn rgb(&self) -> DVec3 {
        DVec3::from(self.rgb)
    }
}

/// An environment map as a sum of SGs, with the fit's report.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SgEnv {
    pub(crate) lobes: Vec<LightLobe>,
    /// Relative L2 error over the sphere (full-resolution map).
    pub fit_error: f64,
    /// The same on the downsampled map the optimiser saw.
    pub(crate) fit_error_fitted_map: f64,
    pub(crate) iterations: usize,
    /// Time the fit took, s.
    pub seconds: f64,
}

/// Fit settings.
#[derive(Clone, Copy, Debug)]
pub struct FitOptions {
    /// Width of the downsampled map the optimiser sees (height = width / 2).
    pub(crate) map_width: u32,
    /// Adam iterations.
    pub(crate) iterations: usize,
    /// Adam step for the axes (radians) and for ln λ, decayed ×0.1 over the run.
    pub(crate) step_axis: f64,
    pub(crate) step_ln_lambda: f64,
}

impl Default for FitOptions {
    fn default() -> FitOptions {
        FitOptions {
            map_width: 128,
            iterations: 300,
            step_axis: 0.02,
            step_ln_lambda: 0.05,
        }
    }
}

/// Fits `k` lobes (clamped to 1..=256) with the default options.
pub fn fit(env: &EnvLight, k: usize) -> SgEnv {
    fit_with(env, k, &FitOptions::default())
}

/// [`fit`] through a cache folder: a fit of the same map content (FNV-1a hash of its size and
/// texels) and the same K is read back from `dir/sg-fit-HASH-kK.json`; otherwise it is fitted
/// and written there. A cache that cannot be read or written only costs the fit.
pub fn fit_cached(env: &EnvLight, k: usize, dir: &std::path::Path) -> SgEnv {
    let mut hash = bspvt_proto::hash::Fnv1a::default();
    hash.write(&env.width.to_le_bytes());
    hash.write(&env.height.to_le_bytes());
    for p in &env.pixels {
        hash.write_f32s(p);
    }
    let o = FitOptions::default();
    hash.write(
        format!(
            "{k}/{}/{}/{}/{}",
            o.map_width, o.iterations, o.step_axis, o.step_ln_lambda
        )
        .as_bytes(),
    );
    let h = hash.finish();
    let path = dir.join(format!("sg-fit-{h:016x}-k{k}.json"));
    if let Some(f) = std::fs::read(&path)
        .ok()
        .and_then(|b| serde_json::from_slice::<SgEnv>(&b).ok())
        .filter(|f| {
            f.lobes
                .iter()
                .all(|l| l.rgb().is_finite() && l.lambda.is_finite())
        })
    {
        return f;
    }
    let f = fit(env, k);
    let written = std::fs::create_dir_all(dir)
        .and_then(|()| std::fs::write(&path, serde_json::to_vec(&f).unwrap_or_default()));
    if let Err(e) = written {
        tracing::warn!("cannot cache the SG fit in {}: {e}", path.display());
    }
    f
}

/// The fitting samples: directions, solid angles, radiance.
struct Samples {
    dirs: Vec<DVec3>,
    weight: Vec<f64>,
    target: Vec<DVec3>,
}

impl Samples {
    fn of(env: &EnvLight) -> Samples {
        let (w, h) = (env.width as usize, env.height as usize);
        let mut s = Samples {
            dirs: Vec::with_capacity(w * h),
            weight: Vec::with_capacity(w * h),
            target: Vec::with_capacity(w * h),
        };
        for y in 0..h {
            let om = env.texel_solid_angle(y);
            for x in 0..w {
                s.dirs.push(EnvLight::direction(
                    (x as f64 + 0.5) / w as f64,
                    (y as f64 + 0.5) / h as f64,
                ));
                s.weight.push(om);
                let p = env.pixels[y * w + x];
                s.target.push(DVec3::new(
                    f64::from(p[0]),
                    f64::from(p[1]),
                    f64::from(p[2]),
                ));
            }
        }
        s
    }

    /// Relative L2 error of `lobes`.
    fn rel_error(&self, lobes: &[LightLobe]) -> f64 {
        let (num, den) = (0..self.dirs.len())
            .into_par_iter()
            .map(|i| {
                let f: DVec3 = lobes
                    .iter()
                    .map(|l| l.rgb() * l.sg().eval(self.dirs[i]))
                    .sum();
                let w = self.weight[i];
                (
                    w * (f - self.target[i]).length_squared(),
                    w * self.target[i].length_squared(),
                )
            })
            .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
        if den > 0.0 { (num / den).sqrt() } else { 0.0 }
    }
}

/// Luminance (Rec. 709).
fn luminance(c: DVec3) -> f64 {
    crate::frame::stats::luminance(c.x, c.y, c.z)
}

/// Basis values G_k(d_i) for all samples, sample-major (row i holds K values).
fn basis(s: &Samples, axes: &[DVec3], lnl: &[f64]) -> Vec<f64> {
    let k = axes.len();
    let mut a = vec![0.0; s.dirs.len() * k];
    a.par_chunks_mut(k).enumerate().for_each(|(i, row)| {
        let d = s.dirs[i];
        for j in 0..k {
            row[j] = (lnl[j].exp() * (axes[j].dot(d) - 1.0)).exp();
        }
    });
    a
}

/// Least-squares amplitudes for fixed shapes (non-negative by clamp-and-resolve).
fn solve_amplitudes(s: &Samples, a: &[f64], k: usize) -> Vec<DVec3> {
    let n = s.dirs.len();
    // Normal equations: M = Aᵀ W A (K×K), b = Aᵀ W y (K×3).
    let (m, b) = (0..n)
        .into_par_iter()
        .fold(
            || (vec![0.0; k * k], vec![DVec3::ZERO; k]),
            |(mut m, mut b), i| {
                let row = &a[i * k..(i + 1) * k];
                let w = s.weight[i];
                for p in 0..k {
                    let wp = w * row[p];
                    if wp == 0.0 {
                        continue;
                    }
                    b[p] += wp * s.target[i];
                    for q in p..k {
                        m[p * k + q] += wp * row[q];
                    }
                }
                (m, b)
            },
        )
        .reduce(
            || (vec![0.0; k * k], vec![DVec3::ZERO; k]),
            |(mut m, mut b), (m2, b2)| {
                m.iter_mut().zip(&m2).for_each(|(x, y)| *x += y);
                b.iter_mut().zip(&b2).for_each(|(x, y)| *x += *y);
                (m, b)
            },
        );
    // Per channel: solve on the active set, drop the lobes whose amplitude came out negative,
    // repeat (an active-set heuristic for the non-negative least squares; a dropped lobe stays
    // at 0 in that channel).
    let mut c = vec![DVec3::ZERO; k];
    for ch in 0..3 {
        let mut active = vec![true; k];
        for _ in 0..k {
            let idx: Vec<usize> = (0..k).filter(|&i| active[i]).collect();
            let na = idx.len();
            if na == 0 {
                break;
            }
            let mut sub = vec![0.0; na * na];
            let mut rhs = vec![0.0; na];
            let mut tr = 0.0;
            for (r, &p) in idx.iter().enumerate() {
                rhs[r] = b[p][ch];
                for (cc, &q) in idx.iter().enumerate() {
                    let (lo, hi) = if p <= q { (p, q) } else { (q, p) };
                    sub[r * na + cc] = m[lo * k + hi];
                }
                tr += m[p * k + p];
            }
            // A small ridge keeps nearly duplicate lobes from cancelling with huge amplitudes.
            let ridge = 1e-7 * tr / na as f64 + 1e-300;
            for r in 0..na {
                sub[r * na + r] += ridge;
            }
            let x = cholesky_solve(&mut sub, &rhs, na);
            let mut dropped = false;
            for (r, &p) in idx.iter().enumerate() {
                if x[r].is_finite() && x[r] >= 0.0 {
                    c[p][ch] = x[r];
                } else {
                    c[p][ch] = 0.0;
                    active[p] = false;
                    dropped = true;
                }
            }
            if !dropped {
                break;
            }
        }
    }
    c
}

/// Solves the SPD system `m` (n×n, overwritten by its Cholesky factor). A non-positive pivot
/// (numerically singular) becomes +∞, which zeroes that unknown.
fn cholesky_solve(m: &mut [f64], b: &[f64], n: usize) -> Vec<f64> {
    for j in 0..n {
        let mut d = m[j * n + j];
        for p in 0..j {
            d -= m[j * n + p] * m[j * n + p];
        }
        let d = if d > 0.0 { d.sqrt() } else { f64::INFINITY };
        m[j * n + j] = d;
        for i in j + 1..n {
            let mut s = m[i * n + j];
            for p in 0..j {
                s -= m[i * n + p] * m[j * n + p];
            }
            m[i * n + j] = s / d;
        }
    }
    let mut y = vec![0.0; n];
    for i in 0..n {
        let mut s = b[i];
        for p in 0..i {
            s -= m[i * n + p] * y[p];
        }
        y[i] = s / m[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = y[i];
        for p in i + 1..n {
            s -= m[p * n + i] * y[p];
        }
        y[i] = s / m[i * n + i];
    }
    y
}

/// Orthogonal matching pursuit on the residual: each new lobe sits on the texel of largest
/// residual luminance with the sharpness that removes the most residual energy there (scan of
/// 2^−2 … 2^14, then golden-section search on ln λ); then all amplitudes are re-solved and the
/// residual updated.
fn initialise(s: &Samples, k: usize) -> (Vec<DVec3>, Vec<f64>) {
    let n = s.dirs.len();
    let mut resid: Vec<DVec3> = s.target.clone();
    let mut axes = Vec::with_capacity(k);
    let mut lnl = Vec::with_capacity(k);
    for _ in 0..k {
        let best = (0..n)
            .max_by(|&a, &b| luminance(resid[a]).total_cmp(&luminance(resid[b])))
            .unwrap_or(0);
        let axis = s.dirs[best];
        // Energy removed by adding c·G(axis, λ) with the best non-negative c: 2c·gy − |c|² gg.
        let gain = |ll: f64| -> f64 {
            let l = ll.exp();
            let (gg, gy) = (0..n)
                .into_par_iter()
                .with_min_len(256)
                .map(|i| {
                    let g = (l * (axis.dot(s.dirs[i]) - 1.0)).exp();
                    (s.weight[i] * g * g, s.weight[i] * g * resid[i])
                })
                .reduce(|| (0.0, DVec3::ZERO), |a, b| (a.0 + b.0, a.1 + b.1));
            if !(gg > 0.0) {
                return f64::NEG_INFINITY;
            }
            let c = (gy / gg).max(DVec3::ZERO);
            2.0 * c.dot(gy) - c.length_squared() * gg
        };
        // Coarse scan of ln λ over powers of 2, then golden-section refinement around the best.
        let (mut lo, mut best_ll) = (0.0f64, 0.0f64);
        let mut best_g = f64::NEG_INFINITY;
        for e in -2..=14 {
            let ll = f64::from(e) * std::f64::consts::LN_2;
            let g = gain(ll);
            if g > best_g {
                best_g = g;
                best_ll = ll;
            }
        }
        lo = lo.max(best_ll - std::f64::consts::LN_2);
        let mut hi = best_ll + std::f64::consts::LN_2;
        if lo > best_ll {
            lo = best_ll - std::f64::consts::LN_2;
        }
        let phi = 0.618_033_988_749_895;
        let (mut x1, mut x2) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
        let (mut g1, mut g2) = (gain(x1), gain(x2));
        for _ in 0..20 {
            if g1 > g2 {
                hi = x2;
                x2 = x1;
                g2 = g1;
                x1 = hi - phi * (hi - lo);
                g1 = gain(x1);
            } else {
                lo = x1;
                x1 = x2;
                g1 = g2;
                x2 = lo + phi * (hi - lo);
                g2 = gain(x2);
            }
        }
        let choice = (
            0.0,
            if g1.max(g2) > best_g {
                0.5 * (lo + hi)
            } else {
                best_ll
            },
        );
        axes.push(axis);
        lnl.push(choice.1);
        let a = basis(s, &axes, &lnl);
        let kk = axes.len();
        let c = solve_amplitudes(s, &a, kk);
        for i in 0..n {
            let f: DVec3 = (0..kk).map(|j| c[j] * a[i * kk + j]).sum();
            resid[i] = s.target[i] - f;
        }
    }
    (axes, lnl)
}

/// Fits `k` lobes (clamped to 1..=256).
pub fn fit_with(env: &EnvLight, k: usize, o: &FitOptions) -> SgEnv {
    let start = Instant::now();
    let k = k.clamp(1, 256);
    let mw = o.map_width.clamp(4, env.width.max(4));
    let small = env.downsample(mw, (mw / 2).max(2));
    let s = Samples::of(&small);
    let n = s.dirs.len();
    let (mut axes, mut lnl) = initialise(&s, k);

    // Adam state: axes (3 each, tangent-projected) and ln λ.
    let (b1, b2, eps) = (0.9, 0.999, 1e-12);
    let mut m_ax = vec![DVec3::ZERO; k];
    let mut v_ax = vec![0.0f64; k];
    let mut m_l = vec![0.0; k];
    let mut v_l = vec![0.0; k];
    let iters = o.iterations;
    for it in 0..iters {
        let a = basis(&s, &axes, &lnl);
        let c = solve_amplitudes(&s, &a, k);
        // Gradient with the amplitudes fixed.
        let (g_ax, g_l) = (0..n)
            .into_par_iter()
            .fold(
                || (vec![DVec3::ZERO; k], vec![0.0; k]),
                |(mut gax, mut gl), i| {
                    let row = &a[i * k..(i + 1) * k];
                    let f: DVec3 = (0..k).map(|j| c[j] * row[j]).sum();
                    let r = f - s.target[i];
                    let w = 2.0 * s.weight[i];
                    let d = s.dirs[i];
                    for j in 0..k {
                        let cr = w * r.dot(c[j]) * row[j];
                        if cr == 0.0 {
                            continue;
                        }
                        let l = lnl[j].exp();
                        gax[j] += d * (cr * l);
                        gl[j] += cr * l * (axes[j].dot(d) - 1.0);
                    }
                    (gax, gl)
                },
            )
            .reduce(
                || (vec![DVec3::ZERO; k], vec![0.0; k]),
                |(mut a1, mut l1), (a2, l2)| {
                    a1.iter_mut().zip(&a2).for_each(|(x, y)| *x += *y);
                    l1.iter_mut().zip(&l2).for_each(|(x, y)| *x += y);
                    (a1, l1)
                },
            );
        let t = (it + 1) as i32;
        let decay = 0.1f64.powf(it as f64 / iters.max(1) as f64);
        for j in 0..k {
            // Axis: Riemannian gradient on the sphere, Adam with one second moment per lobe.
            let g = g_ax[j] - axes[j] * axes[j].dot(g_ax[j]);
            m_ax[j] = m_ax[j] * b1 + g * (1.0 - b1);
            v_ax[j] = v_ax[j] * b2 + g.length_squared() * (1.0 - b2);
            let mh = m_ax[j] / (1.0 - b1.powi(t));
            let vh = v_ax[j] / (1.0 - b2.powi(t));
            let step = mh / (vh.sqrt() + eps) * (o.step_axis * decay);
            let moved = axes[j] - step;
            if moved.is_finite() {
                axes[j] = moved.normalize_or(axes[j]);
            }
            let g = g_l[j];
            m_l[j] = m_l[j] * b1 + g * (1.0 - b1);
            v_l[j] = v_l[j] * b2 + g * g * (1.0 - b2);
            let mh = m_l[j] / (1.0 - b1.powi(t));
            let vh = v_l[j] / (1.0 - b2.powi(t));
            let nl = lnl[j] - mh / (vh.sqrt() + eps) * (o.step_ln_lambda * decay);
            if nl.is_finite() {
                lnl[j] = nl.clamp(LN_LAMBDA_MIN, LN_LAMBDA_MAX);
            }
        }
    }
    let a = basis(&s, &axes, &lnl);
    let c = solve_amplitudes(&s, &a, k);
    let lobes: Vec<LightLobe> = (0..k)
        .filter(|&j| c[j].max_element() > 0.0)
        .map(|j| LightLobe {
            axis: axes[j].to_array(),
            lambda: lnl[j].exp(),
            rgb: c[j].to_array(),
        })
        .collect();
    let fit_error_fitted_map = s.rel_error(&lobes);
    let fit_error = Samples::of(env).rel_error(&lobes);
    SgEnv {
        lobes,
        fit_error,
        fit_error_fitted_map,
        iterations: iters,
        seconds: start.elapsed().as_secs_f64(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A map made of known SGs is recovered (error small), and more lobes never fit worse on
    /// a real-looking map.
    #[test]
    fn recovers_a_synthetic_sg_map() {
        let truth = [
            (
                DVec3::new(0.3, 0.8, 0.2).normalize(),
                40.0,
                DVec3::new(5.0, 4.0, 3.0),
            ),
            (
                DVec3::new(-0.5, 0.1, -0.7).normalize(),
                3.0,
                DVec3::new(0.2, 0.4, 0.9),
            ),
        ];
        let (w, h) = (64u32, 32u32);
        let px = (0..w * h)
            .map(|i| {
                let d = EnvLight::direction(
                    ((i % w) as f64 + 0.5) / w as f64,
                    ((i / w) as f64 + 0.5) / h as f64,
                );
                let c: DVec3 = truth
                    .iter()
                    .map(|(p, l, c)| *c * Sg::new(*p, *l, 1.0).eval(d))
                    .sum();
                c.as_vec3().to_array()
            })
            .collect();
        let env = EnvLight::from_pixels(w, h, px).expect("map");
        let opts = FitOptions {
            map_width: 64,
            iterations: 150,
            ..FitOptions::default()
        };
        let f = fit_with(&env, 2, &opts);
        let f5 = fit_with(&env, 4, &opts);
        eprintln!(
            "synthetic: rel L2 K=2 {:.4} in {:.2} s, K=4 {:.4}",
            f.fit_error, f.seconds, f5.fit_error
        );
        {
            for (p, l, _) in &truth {
                let found = f5.lobes.iter().any(|x| {
                    DVec3::from(x.axis).angle_between(*p) < 0.1 && (x.lambda / l - 1.0).abs() < 0.25
                });
                assert!(found, "lobe {p} λ {l} not recovered: {:?}", f5.lobes);
            }
            assert!(f5.fit_error < 0.05, "{}", f5.fit_error);
        }
        assert!(
            f.lobes
                .iter()
                .all(|l| l.rgb().is_finite() && l.lambda.is_finite())
        );
        let f1 = fit_with(&env, 1, &opts);
        assert!(f1.fit_error > f.fit_error);
        assert!(f.fit_error >= f5.fit_error - 1e-3);
    }

    #[test]
    fn fits_the_test_map() {
        let p = crate::envmap::default_env_path();
        if !p.exists() {
            eprintln!("SKIP: {} not found (set BSPVT_ASSETS)", p.display());
            return;
        }
        let env = EnvLight::load(&p).expect("the test map loads");
        let opts = FitOptions {
            map_width: 64,
            iterations: 60,
            ..FitOptions::default()
        };
        let f8 = fit_with(&env, 8, &opts);
        let f16 = fit_with(&env, 16, &opts);
        eprintln!(
            "royal esplanade (64×32, 60 it): K=8 {:.4}, K=16 {:.4}",
            f8.fit_error, f16.fit_error
        );
        assert!(f16.fit_error < f8.fit_error && f8.fit_error < 1.0);
        assert!(f16.lobes.iter().all(|l| l.rgb().min_element() >= 0.0));
    }

    #[test]
    fn cached_fit_reads_back_the_same_lobes() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut px = vec![[0.05f32; 3]; 32 * 16];
        px[4 * 32 + 9] = [30.0, 20.0, 10.0];
        let env = EnvLight::from_pixels(32, 16, px).expect("map");
        let a = fit_cached(&env, 2, dir.path());
        let files = std::fs::read_dir(dir.path()).expect("dir").count();
        assert_eq!(files, 1);
        // (JSON round trip and parallel reductions: equal to rounding.)
        let close = |x: &SgEnv, y: &SgEnv| {
            x.lobes.len() == y.lobes.len()
                && x.lobes.iter().zip(&y.lobes).all(|(p, q)| {
                    (p.rgb() - q.rgb()).length() <= 1e-9 * p.rgb().length()
                        && (p.lambda - q.lambda).abs() <= 1e-9 * p.lambda
                        && (DVec3::from(p.axis) - DVec3::from(q.axis)).length() <= 1e-9
                })
        };
        let b = fit_cached(&env, 2, dir.path());
        assert!(close(&a, &b), "{:?} vs {:?}", a.lobes, b.lobes);
        // What is read is the file: an edited entry comes back edited.
        let entry = std::fs::read_dir(dir.path())
            .expect("dir")
            .flatten()
            .next()
            .expect("one entry")
            .path();
        let mut edited = a.clone();
        edited.lobes[0].lambda *= 2.0;
        std::fs::write(&entry, serde_json::to_vec(&edited).expect("json")).expect("write");
        let e = fit_cached(&env, 2, dir.path());
        assert!(close(&edited, &e));
        // A different K is a different entry; a corrupt file is refitted.
        let _ = fit_cached(&env, 3, dir.path());
        assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 2);
        for e in std::fs::read_dir(dir.path()).expect("dir").flatten() {
            std::fs::write(e.path(), b"not json").expect("write");
        }
        let c = fit_cached(&env, 2, dir.path());
        assert!(close(&a, &c), "{:?} vs {:?}", a.lobes, c.lobes);
    }

    #[test]
    fn degenerate_maps() {
        let black = EnvLight::constant([0.0; 3]);
        let f = fit(&black, 4);
        assert!(f.fit_error.is_finite());
        assert!(f.lobes.iter().all(|l| l.rgb().is_finite()));
        let white = EnvLight::constant([1.0; 3]);
        let f = fit_with(
            &white,
            2,
            &FitOptions {
                iterations: 50,
                ..FitOptions::default()
            },
        );
        assert!(f.fit_error < 0.2, "{}", f.fit_error);
    }
}
