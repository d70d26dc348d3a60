//! Shadow-map baselines: a perspective depth map rendered from the light's centroid along the
//! light's normal (rasterised by [`GBuffer::rasterize`] through a light camera), then
//!
//! - **PCF**: the fraction of taps in a fixed (2k+1)² texel kernel whose depth is beyond the
//!   receiver's (Reeves, Salesin, Cook 1987);
//! - **VSM**: depth moments (z, z²) prefiltered with a box of the same size; Chebyshev's upper
//!   bound p = σ² / (σ² + (z − μ)²) for z > μ, with light bleeding reduced by
//!   p ↦ linstep(a, 1, p) (Donnelly, Lauritzen 2006; Lauritzen 2007);
//! - **PCSS**: mean depth of the blockers in the region of the map that the receiver→light
//!   frustum covers, then PCF with the similar-triangles width
//!   W = (Z_receiver − Z_blocker) / Z_blocker · W_light (Fernando 2005), capped.
//!
//! Depths are linear, along the light's normal. Receivers behind the light's plane or outside
//! the map are lit (the unshadowed LTC already removes light from behind). The depth bias is
//! slope-scaled: texel size at the receiver × (kernel radius + 1) × tan θ, plus two texels.

use bspvt_proto::Mesh;
use glam::DVec3;
use rayon::prelude::*;

use super::{Guide, GuidePixel, Params, light_width, penumbra_width};
use crate::frame::camera::View;
use crate::frame::gbuffer::GBuffer;
use crate::light::Light;

/// Largest half field of view of the light camera: tan 75°.
const MAX_TAN_HALF: f64 = 3.732;

/// Shadow-map filtering.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Filter {
    Pcf,
    Vsm,
    Pcss,
}

/// A depth map seen from the light.
#[derive(Clone, Debug)]
pub(crate) struct LightMap {
    pub(crate) view: View,
    pub(crate) res: usize,
    /// Depth along the light's normal per texel (row-major); `INFINITY`: nothing.
    pub(crate) depth: Vec<f64>,
    /// Nearest and farthest finite depth.
    pub(crate) z_min: f64,
    pub(crate) z_max: f64,
}

impl LightMap {
    /// Renders the depth of `mesh` from `light`'s centroid looking along its normal, with a
    /// square field of view that covers the mesh's bounds in front of the light (at most
    /// ±75°). `None` when nothing lies in front of the light.
    pub(crate) fn render(
        mesh: &Mesh,
        cut: Option<&bspvt_raytrace::Cutouts>,
        light: &Light,
        res: u32,
    ) -> Option<LightMap> {
        let eye = light.centroid();
        let forward = light.normal.normalize_or(DVec3::NEG_Y);
        if !eye.is_finite() || !forward.is_finite() {
            return None;
        }
        let (right, up) = forward.any_orthonormal_pair();
        let b = mesh.bounds();
        let (lo, hi) = (b.min.as_dvec3(), b.max.as_dvec3());
        let mut tan_half: f64 = 0.05;
        for k in 0..8 {
            let c = DVec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            let v = c - eye;
            let along = v.dot(forward);
            let t = if along > 1e-9 {
                v.dot(right).abs().max(v.dot(up).abs()) / along
            } else {
                MAX_TAN_HALF
            };
            tan_half = tan_half.max(t.min(MAX_TAN_HALF));
        }
        let res = res.clamp(16, 8192);
        let view = View {
            eye,
            forward,
            right,
            up,
            tan_half_fov: tan_half * 1.01,
            width: res,
            height: res,
        };
        let g = GBuffer::rasterize_cut(mesh, &view, cut);
        let depth: Vec<f64> = (0..g.tri.len())
            .into_par_iter()
            .map(|i| {
                g.surface(mesh, &view, i)
                    .map(|s| view.to_camera(s.position).z)
                    .filter(|z| z.is_finite() && *z > 0.0)
                    .unwrap_or(f64::INFINITY)
            })
            .collect();
        let finite = depth.iter().copied().filter(|z| z.is_finite());
        let z_min = finite.clone().fold(f64::INFINITY, f64::min);
        let z_max = finite.fold(0.0, f64::max);
        if !z_min.is_finite() {
            return None;
        }
        Some(LightMap {
            view,
            res: res as usize,
            depth,
            z_min,
            z_max,
        })
    }

    /// World size of one texel at depth `z`.
    fn texel(&self, z: f64) -> f64 {
        2.0 * z * self.view.tan_half_fov / self.res as f64
    }

    /// The receiver's texel (x, y), depth and slope-scaled bias for a kernel of `radius`
    /// texels; `None`: outside the map or behind the light.
    fn locate(&self, g: &GuidePixel, radius: f64) -> Option<(isize, isize, f64, f64)> {
        let c = self.view.to_camera(g.position);
        if !(c.z > 0.0) {
            return None;
        }
        let (x, y) = self.view.to_image(c);
        let r = self.res as f64;
        if !(x >= 0.0 && y >= 0.0 && x < r && y < r) {
            return None;
        }
        let l = (self.view.eye - g.position).normalize_or(self.view.forward);
        let cos = g.geometric.dot(l).abs().max(0.1);
        let tan = (1.0 - cos * cos).max(0.0).sqrt() / cos;
        let bias = self.texel(c.z) * ((radius + 1.0) * tan + 2.0);
        Some((x as isize, y as isize, c.z, bias))
    }

    /// Fraction of taps within `radius` texels of (x, y) whose depth is beyond `z`; at most
    /// 17² taps (strided for large radii).
    fn pcf(&self, x: isize, y: isize, z: f64, radius: f64) -> f64 {
        let r = radius.clamp(0.0, 4096.0).round() as isize;
        let step = ((2 * r + 1) as f64 / 17.0).ceil().max(1.0) as isize;
        let n = self.res as isize;
        let (mut lit, mut all) = (0u32, 0u32);
        let mut dy = -r;
        while dy <= r {
            let mut dx = -r;
            while dx <= r {
                let (qx, qy) = ((x + dx).clamp(0, n - 1), (y + dy).clamp(0, n - 1));
                all += 1;
                if self.depth[(qy * n + qx) as usize] >= z {
                    lit += 1;
                }
                dx += step;
            }
            dy += step;
        }
        f64::from(lit) / f64::from(all.max(1))
    }

    /// Mean depth of the blockers (depth < z) within `radius` texels, strided to ≤ 17² taps.
    fn blockers(&self, x: isize, y: isize, z: f64, radius: f64) -> Option<f64> {
        let r = radius.clamp(0.0, 4096.0).round() as isize;
        let step = ((2 * r + 1) as f64 / 17.0).ceil().max(1.0) as isize;
        let n = self.res as isize;
        let (mut sum, mut count) = (0.0, 0u32);
        let mut dy = -r;
        while dy <= r {
            let mut dx = -r;
            while dx <= r {
                let (qx, qy) = ((x + dx).clamp(0, n - 1), (y + dy).clamp(0, n - 1));
                let d = self.depth[(qy * n + qx) as usize];
                if d < z {
                    sum += d;
                    count += 1;
                }
                dx += step;
            }
            dy += step;
        }
        (count > 0).then(|| sum / f64::from(count))
    }

    /// Depth moments (μ, E[z²]) box-filtered over (2k+1)² texels; empty texels count as the
    /// far depth 2 z_max.
    pub(crate) fn moments(&self, k: u32) -> Vec<[f64; 2]> {
        let far = 2.0 * self.z_max.max(self.z_min);
        let m: Vec<[f64; 2]> = self
            .depth
            .iter()
            .map(|&d| {
                let z = if d.is_finite() { d } else { far };
                [z, z * z]
            })
            .collect();
        let h = box_pass(&m, self.res, k as isize, true);
        box_pass(&h, self.res, k as isize, false)
    }
}

fn box_pass(m: &[[f64; 2]], n: usize, k: isize, horizontal: bool) -> Vec<[f64; 2]> {
    let ni = n as isize;
    (0..m.len())
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % n) as isize, (i / n) as isize);
            let mut s = [0.0; 2];
            for d in -k..=k {
                let (qx, qy) = if horizontal { (x + d, y) } else { (x, y + d) };
                let j = (qy.clamp(0, ni - 1) * ni + qx.clamp(0, ni - 1)) as usize;
                s[0] += m[j][0];
                s[1] += m[j][1];
            }
            let c = (2 * k + 1) as f64;
            [s[0] / c, s[1] / c]
        })
        .collect()
}

/// linstep(a, b, x): 0 below a, 1 above b, linear between.
fn linstep(a: f64, b: f64, x: f64) -> f64 {
    if !(b > a) {
        return if x >= b { 1.0 } else { 0.0 };
    }
    ((x - a) / (b - a)).clamp(0.0, 1.0)
}

/// VSM visibility: Chebyshev's one-sided bound on P(depth ≥ z), with light-bleeding
/// reduction; `min_var` keeps σ² off 0 (flat, fully lit regions).
pub(crate) fn chebyshev(m: [f64; 2], z: f64, min_var: f64, bleed: f64) -> f64 {
    let [mu, m2] = m;
    if !(z > mu) {
        return 1.0;
    }
    let var = (m2 - mu * mu).max(min_var);
    let d = z - mu;
    let p = var / (var + d * d);
    let p = if p.is_finite() { p } else { 0.0 };
    linstep(bleed.clamp(0.0, 0.99), 1.0, p)
}

/// The shadow factor per pixel for `filter` (1 for background pixels and when nothing lies in
/// front of the light).
pub(crate) fn shadow_factor(
    guide: &Guide,
    mesh: &Mesh,
    cut: Option<&bspvt_raytrace::Cutouts>,
    light: &Light,
    filter: Filter,
    params: &Params,
) -> Vec<f32> {
    let Some(map) = LightMap::render(mesh, cut, light, params.map_res) else {
        return vec![1.0; guide.pixels.len()];
    };
    let k = f64::from(params.pcf_radius);
    let moments = (filter == Filter::Vsm).then(|| map.moments(params.pcf_radius));
    let w_light = light_width(light);
    let cap = params.max_radius.max(0.0);
    let n = map.res as isize;
    guide
        .pixels
        .par_iter()
        .map(|g| {
            let Some(g) = g else {
                return 1.0;
            };
            let s = match filter {
                Filter::Pcf => match map.locate(g, k) {
                    Some((x, y, z, bias)) => map.pcf(x, y, z - bias, k),
                    None => 1.0,
                },
                Filter::Vsm => match (map.locate(g, k), &moments) {
                    (Some((x, y, z, bias)), Some(m)) => {
                        let t = map.texel(z);
                        chebyshev(
                            m[(y.clamp(0, n - 1) * n + x.clamp(0, n - 1)) as usize],
                            z - bias,
                            0.01 * t * t,
                            params.vsm_bleed,
                        )
                    }
                    _ => 1.0,
                },
                Filter::Pcss => pcss(&map, g, w_light, cap),
            };
            s as f32
        })
        .collect()
}

/// PCSS at one receiver: blocker search over the region the receiver→light frustum covers at
/// the nearest depth in the map, then PCF of half-width W/2 (texels at the receiver's depth).
fn pcss(map: &LightMap, g: &GuidePixel, w_light: f64, cap: f64) -> f64 {
    let Some((x, y, z, _)) = map.locate(g, 0.0) else {
        return 1.0;
    };
    let zn = map.z_min.max(1e-9 * z);
    let search = 0.5 * w_light * ((z - zn) / z).max(0.0) / map.texel(zn);
    let search = if search.is_finite() {
        search.clamp(1.0, cap.max(1.0))
    } else {
        cap.max(1.0)
    };
    let Some((_, _, _, bias)) = map.locate(g, search) else {
        return 1.0;
    };
    let Some(zb) = map.blockers(x, y, z - bias, search) else {
        return 1.0;
    };
    let w = penumbra_width(z, zb, w_light);
    let r = 0.5 * w / map.texel(z);
    let r = if r.is_finite() {
        r.clamp(0.0, cap)
    } else {
        cap
    };
    let Some((_, _, _, bias)) = map.locate(g, r) else {
        return 1.0;
    };
    map.pcf(x, y, z - bias, r)
}
