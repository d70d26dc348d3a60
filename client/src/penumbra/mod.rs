//! Soft shadows from a point light by blurring a hard shadow (paper 003), and the shadow-map
//! baselines it is compared with (PCF, VSM, PCSS).
//!
//! All methods produce a per-pixel shadow factor s ∈ [0, 1]; the shadowed image is the
//! unshadowed per-pixel LTC shading × s ([`compose`]). The point light is the light polygon's
//! centroid; its width is W_light = √area.
//!
//! The penumbra width at a receiver follows from similar triangles (paper 003, as in PCSS),
//! with Z measured from the light:
//!
//! ```text
//! W = (Z_receiver − Z_occluder) / Z_occluder · W_light
//! ```
//!
//! - [`rt`]: one hard shadow ray per pixel gives s_hard and the occluder distance; W is
//!   projected to screen pixels and s_hard is blurred by a spatially varying, edge-aware
//!   ([`blur`]) kernel of that width.
//! - [`shadowmap`]: a depth map rendered from the light; PCF (fixed kernel), VSM (moments,
//!   Chebyshev bound, light-bleeding reduction) and PCSS (blocker search, then PCF of width W).

pub(crate) mod blur;
pub mod rt;
pub(crate) mod shadowmap;

use anyhow::{Result, bail};
use glam::DVec3;
use rayon::prelude::*;

use crate::frame::brdf::Shadows;
use crate::frame::image::Image;
use crate::light::Light;
use crate::render::renderer::Renderer;

/// A shadow technique of this module.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Technique {
    /// Paper 003: ray-traced hard shadow blurred by the similar-triangles width.
    RtPenumbra,
    /// The same hard shadow, unblurred.
    RtHard,
    /// Shadow map with percentage-closer filtering [Reeves87].
    Pcf,
    /// Variance shadow map [Donnelly06].
    Vsm,
    /// Percentage-closer soft shadows [Fernando05].
    Pcss,
}

impl Technique {
    /// True when the technique traces rays (needs a [`rt::ShadowCaster`]).
    pub(crate) fn needs_rays(self) -> bool {
        matches!(self, Technique::RtPenumbra | Technique::RtHard)
    }
}

/// The shadow factor per pixel of `r`'s G-buffer for `light`.
pub fn shadow_factor(
    r: &Renderer,
    guide: &Guide,
    light: &Light,
    technique: Technique,
    occluder: Option<&dyn rt::ShadowCaster>,
    params: &Params,
) -> Result<Vec<f32>> {
    let filter = match technique {
        Technique::RtPenumbra | Technique::RtHard => {
            let Some(occ) = occluder else {
                bail!("{technique:?} needs an occluder (ray tracing)");
            };
            let eps = Shadows::for_scene(r.scene, None).epsilon;
            let mut b = rt::hard_shadows(guide, light, occ, eps)?;
            if technique == Technique::RtHard {
                return Ok(b.hard);
            }
            rt::split_light(&mut b, guide, light, params, occ, eps)?;
            return rt::soft_shadows(&b, guide, &r.view, light, params, occ);
        }
        Technique::Pcf => shadowmap::Filter::Pcf,
        Technique::Vsm => shadowmap::Filter::Vsm,
        Technique::Pcss => shadowmap::Filter::Pcss,
    };
    Ok(shadowmap::shadow_factor(
        guide,
        &r.scene.mesh,
        r.cut.as_deref(),
        light,
        filter,
        params,
    ))
}

/// One frame: the unshadowed per-pixel LTC shading × the technique's shadow factor. When the
/// scene has punctual lights (glTF `KHR_lights_punctual`), they are the point lights instead
/// of the polygon's centroid ([`render_punctual`]). `guide`: `r`'s [`Guide`] (per camera, like
/// the G-buffer it is read from: [`GuideCache`]).
pub fn render(
    r: &Renderer,
    guide: &Guide,
    light: &Light,
    technique: Technique,
    occluder: Option<&dyn rt::ShadowCaster>,
    params: &Params,
) -> Result<Image> {
    if !r.scene.punctual.is_empty() {
        return render_punctual(r, guide, technique, occluder, params);
    }
    let unshadowed = r.shade_pixels(std::slice::from_ref(light), None);
    render_over(r, guide, light, technique, occluder, params, &unshadowed)
}

/// [`render`] of a polygon light over its unshadowed per-pixel frame drawn elsewhere (the
/// GPU's frames): `unshadowed` × the technique's shadow factor.
pub(crate) fn render_over(
    r: &Renderer,
    guide: &Guide,
    light: &Light,
    technique: Technique,
    occluder: Option<&dyn rt::ShadowCaster>,
    params: &Params,
    unshadowed: &Image,
) -> Result<Image> {
    let s = shadow_factor(r, guide, light, technique, occluder, params)?;
    Ok(compose(unshadowed, &s))
}

/// The scene's punctual lights: Σ over the lights of the unshadowed punctual shading
/// ([`Renderer::shade_pixels_punctual`]) × the technique's shadow factor for that light. A
/// punctual light has no size: its shadow is cast from a point ([`point_caster`]), so the
/// similar-triangles width W is 0 and rt-penumbra and PCSS give hard shadows; PCF and VSM keep
/// their fixed filters.
pub fn render_punctual(
    r: &Renderer,
    guide: &Guide,
    technique: Technique,
    occluder: Option<&dyn rt::ShadowCaster>,
    params: &Params,
) -> Result<Image> {
    let mut out = Image::new(r.gbuffer.width, r.gbuffer.height);
    for p in &r.scene.punctual {
        let caster = point_caster(r.scene, p);
        let s = shadow_factor(r, guide, &caster, technique, occluder, params)?;
        let lit = compose(&r.shade_pixels_punctual(p), &s);
        for (o, l) in out.pixels.iter_mut().zip(&lit.pixels) {
            for k in 0..3 {
                o[k] += l[k];
            }
        }
    }
    Ok(out)
}

/// The light the shadow techniques cast a punctual light's shadow from: a square of side
/// 10⁻⁶ × the scene's diagonal (a point for every purpose: W_light ≈ 0) at its position,
/// facing along a spot's axis, or for a point light toward the centre of the mesh's bounds
/// (the shadow map's view; −Y when the light sits at the centre).
pub(crate) fn point_caster(
    scene: &bspvt_proto::Scene,
    p: &bspvt_proto::scene::PunctualLight,
) -> Light {
    let pos = glam::Vec3::from(p.position).as_dvec3();
    let bounds = scene.mesh.bounds();
    let normal = match &p.spot {
        Some(s) => glam::Vec3::from(s.direction).as_dvec3(),
        None => bounds.center().as_dvec3() - pos,
    }
    .normalize_or(DVec3::NEG_Y);
    let side = 1e-6 * f64::from(bounds.diagonal()).max(1e-6);
    let u = normal.any_orthonormal_vector() * (0.5 * side);
    let v = normal.cross(u);
    Light {
        // Counter-clockwise about `normal`: (v1 − v0) × (v2 − v0) ∥ normal.
        vertices: vec![pos - u - v, pos + u - v, pos + u + v, pos - u + v],
        normal,
        radiance: DVec3::ZERO,
        two_sided: false,
        texture: None,
        shape: crate::light::Shape::Polygon,
    }
}

/// rt-penumbra's default light split ([`Params::split`]): 2 × 2 parts where the blur reaches.
pub const DEFAULT_SPLIT: usize = 2;

/// rt-penumbra's default split where the penumbra is wide ([`Params::wide_split`]): 4 × 4
/// parts, cast on every [`DEFAULT_SPARSE_STEP`]-th pixel.
pub const DEFAULT_WIDE_SPLIT: usize = 4;

/// rt-penumbra's default grid spacing, in pixels, of the wide split's rays
/// ([`Params::sparse_step`]).
pub const DEFAULT_SPARSE_STEP: usize = 3;

/// Settings shared by the methods.
#[derive(Clone, Copy, Debug)]
pub struct Params {
    /// Cap on the blur radius in screen pixels (rt-penumbra) and on the PCF/PCSS radius in
    /// shadow-map texels. W grows without bound as Z_occluder → 0 (occluder at the light);
    /// the cap bounds both the cost (taps ∝ radius) and the width.
    pub max_radius: f64,
    /// Bilateral weights: a tap counts when its distance to the centre's tangent plane is
    /// below `plane_tolerance` × the centre's view depth …
    pub plane_tolerance: f64,
    /// … and its normal is within acos(`normal_cos`) of the centre's.
    pub normal_cos: f64,
    /// Shadow-map resolution (square).
    pub map_res: u32,
    /// PCF kernel radius in texels (also VSM's moment prefilter radius).
    pub pcf_radius: u32,
    /// VSM light-bleeding reduction: p ↦ linstep(amount, 1, p).
    pub vsm_bleed: f64,
    /// rt-penumbra's blur kernel.
    pub kernel: Kernel,
    /// rt-penumbra's light split: where the point light's shadow is soft, `split` × `split`
    /// shadow rays per pixel toward the light's parts ([`rt::split_light`]); 1: paper 003's
    /// one ray toward the centroid everywhere.
    pub split: usize,
    /// How far, in pixels, the split region may grow past the one ray's blur where the split
    /// fractions still differ from the one ray's 0 or 1 at its edge ([`rt::split_light`]); 0:
    /// the region is the one ray's blur's reach.
    pub grow: f64,
    /// Where the penumbra is wide (the one ray's blur reaches `wide_reach` pixels or more
    /// along both axes, and where the split region grows), `wide_split` × `wide_split` rays
    /// toward the light's parts, cast on a grid of every `sparse_step`-th pixel and
    /// interpolated between ([`rt::split_light`]); `wide_split` ≤ `split`: `split`
    /// everywhere, every pixel cast.
    pub wide_split: usize,
    /// The wide split's grid spacing in pixels (1: every pixel casts).
    pub sparse_step: usize,
    /// The one ray's blur reach, in pixels, from which the wide split is cast.
    pub wide_reach: f64,
}

/// The shape of rt-penumbra's blur.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// Separable screen-space box of half-width W/2 per axis ([`blur::blur`]).
    Box,
    /// The light's shape scaled by W / W_light on the receiver's tangent plane, `n` × `n`
    /// taps ([`blur::light_blur`]).
    Light(usize),
}

impl Default for Params {
    fn default() -> Params {
        Params {
            max_radius: 32.0,
            plane_tolerance: 0.01,
            normal_cos: 0.9,
            map_res: 1024,
            pcf_radius: 2,
            vsm_bleed: 0.3,
            kernel: Kernel::Box,
            split: DEFAULT_SPLIT,
            grow: 32.0,
            wide_split: DEFAULT_WIDE_SPLIT,
            sparse_step: DEFAULT_SPARSE_STEP,
            wide_reach: 8.0,
        }
    }
}

/// Penumbra width at the receiver by similar triangles (paper 003):
/// W = (Z_receiver − Z_occluder) / Z_occluder · W_light, Z measured from the light.
/// Always finite and ≥ 0: an occluder at (or behind) the light gives `f64::MAX`, to be capped
/// by the caller; Z_occluder ≥ Z_receiver (no occluder in between) gives 0.
pub(crate) fn penumbra_width(z_receiver: f64, z_occluder: f64, w_light: f64) -> f64 {
    let d = z_receiver - z_occluder;
    if !(d > 0.0) || !(w_light > 0.0) {
        return 0.0;
    }
    if !(z_occluder > 1e-12 * z_receiver.abs().max(1e-300)) {
        return f64::MAX;
    }
    let w = d / z_occluder * w_light;
    if w.is_finite() { w } else { f64::MAX }
}

/// The light's width W_light: the side of the square of the same area.
pub(crate) fn light_width(light: &Light) -> f64 {
    let a = light.area();
    if a.is_finite() && a > 0.0 {
        a.sqrt()
    } else {
        0.0
    }
}

/// What each pixel sees, for edge-aware filtering: world position, shading normal and view
/// depth (along the camera's forward axis). `None`: background.
#[derive(Clone, Debug)]
pub struct Guide {
    pub(crate) width: usize,
    pub(crate) height: usize,
    /// Per pixel, row by row: the visible surface (`None`: background).
    pub pixels: Vec<Option<GuidePixel>>,
    /// World size of one pixel at view depth 1: 2 tan(fov_y / 2) / height.
    pub footprint_per_depth: f64,
    /// Which guide this is ([`Guide::next_id`]): the GPU's copy is kept while it stays the
    /// same (a guide is not changed after it is made).
    pub(crate) id: u64,
}

/// The [`Guide`] of the last camera a method drew for: a frame whose camera (and materials)
/// did not change reuses it, as it reuses the G-buffer.
#[derive(Default)]
pub struct GuideCache(Option<(u64, Guide)>);

impl GuideCache {
    /// `r`'s guide, built when `r`'s camera differs from the cached one.
    pub fn get(&mut self, r: &Renderer) -> &Guide {
        let key = r.shading_key();
        if self.0.as_ref().is_some_and(|(k, _)| *k != key) {
            self.0 = None;
        }
        &self.0.get_or_insert_with(|| (key, Guide::new(r))).1
    }
}

/// One pixel's visible surface, as the edge-aware filters see it.
#[derive(Clone, Copy, Debug)]
pub struct GuidePixel {
    /// World position.
    pub position: DVec3,
    /// Unit shading normal on the viewer's side.
    pub normal: DVec3,
    /// Unit geometric normal on the viewer's side (shadow-ray offsets).
    pub geometric: DVec3,
    pub(crate) depth: f64,
    /// World length on the tangent plane covered by one pixel along x and along y: the
    /// footprint grown by the receiver's slope (`f64::MAX` at grazing incidence).
    pub(crate) step: [f64; 2],
}

impl GuidePixel {
    /// A world half-width in pixels along x (`horizontal`) or y, capped at `cap`.
    #[inline]
    pub fn pixels(&self, half_width: f64, horizontal: bool, cap: f64) -> f64 {
        let r = half_width / self.step[usize::from(!horizontal)];
        if r.is_finite() {
            r.clamp(0.0, cap.max(0.0))
        } else if r > 0.0 {
            cap.max(0.0)
        } else {
            0.0
        }
    }
}

impl Guide {
    /// The guide of `r`'s G-buffer (once per camera).
    pub fn new(r: &Renderer) -> Guide {
        let g = &r.gbuffer;
        let w = g.width.max(1) as usize;
        let footprint_per_depth = 2.0 * r.view.tan_half_fov / f64::from(g.height.max(1));
        let pixels = (0..g.tri.len())
            .into_par_iter()
            .map(|i| {
                let s = g.surface(&r.scene.mesh, &r.view, i)?;
                let depth = r.view.to_camera(s.position).z;
                let iso = footprint_per_depth * depth;
                let (x, y) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
                // World distance between the tangent-plane hits of the rays through the
                // pixel's two edges, along x and along y (≥ the perpendicular footprint).
                let hit = |x: f64, y: f64| {
                    let d = r.view.ray_dir(x, y);
                    let t = s.geometric.dot(s.position - r.view.eye) / s.geometric.dot(d);
                    r.view.eye + d * t
                };
                let step = |a: DVec3, b: DVec3| {
                    let l = (a - b).length();
                    if l.is_finite() { l.max(iso) } else { f64::MAX }
                };
                let step = [
                    step(hit(x - 0.5, y), hit(x + 0.5, y)),
                    step(hit(x, y - 0.5), hit(x, y + 0.5)),
                ];
                (depth.is_finite() && depth > 0.0 && s.position.is_finite()).then_some(GuidePixel {
                    position: s.position,
                    normal: s.normal,
                    geometric: s.geometric,
                    depth,
                    step,
                })
            })
            .collect();
        Guide {
            width: g.width as usize,
            height: g.height as usize,
            pixels,
            footprint_per_depth,
            id: Guide::next_id(),
        }
    }

    /// A number no other guide of this process has.
    pub(crate) fn next_id() -> u64 {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    }

    /// True when pixel `q` lies on the same surface as `c`: near c's tangent plane (relative
    /// to c's view depth) and with a similar normal. Rejects taps across depth and normal
    /// discontinuities.
    #[inline]
    pub(crate) fn same_surface(&self, c: &GuidePixel, q: &GuidePixel, p: &Params) -> bool {
        let plane = c.normal.dot(q.position - c.position).abs();
        plane <= p.plane_tolerance * c.depth && c.normal.dot(q.normal) >= p.normal_cos
    }
}

/// The shadowed image: unshadowed × shadow factor, per pixel (factors are clamped to [0, 1];
/// a non-finite factor counts as lit).
pub(crate) fn compose(unshadowed: &Image, factor: &[f32]) -> Image {
    let mut out = unshadowed.clone();
    out.pixels
        .par_iter_mut()
        .zip(factor.par_iter())
        .for_each(|(px, &s)| {
            let s = if s.is_finite() {
                s.clamp(0.0, 1.0)
            } else {
                1.0
            };
            for c in px.iter_mut() {
                *c *= s;
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn width_formula_and_limits() {
        // Occluder halfway: W = W_light.
        assert!((penumbra_width(2.0, 1.0, 0.5) - 0.5).abs() < 1e-15);
        // Contact: 0. Occluder beyond the receiver: 0.
        assert_eq!(penumbra_width(2.0, 2.0, 1.0), 0.0);
        assert_eq!(penumbra_width(2.0, 3.0, 1.0), 0.0);
        // Occluder at the light: finite, huge.
        assert_eq!(penumbra_width(2.0, 0.0, 1.0), f64::MAX);
        assert_eq!(penumbra_width(2.0, -1.0, 1.0), f64::MAX);
        assert_eq!(penumbra_width(f64::NAN, 1.0, 1.0), 0.0);
    }
}
