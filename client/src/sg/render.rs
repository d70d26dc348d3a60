//! The SG renderer (paper 001): per pixel of the G-buffer,
//!
//! ```text
//! L_o = Σ_k rgb_k ⊙ [ albedo/π · ∫ G_k C V_k  +  F · ∫ G_k S V_k ]
//! ```
//!
//! G_k the lighting lobes ([`super::fit`]), C the clamped cosine and S the warped GGX lobe
//! ([`super::brdf`]). Each product G_k C, G_k S is one SG (axis p, sharpness λ); its visible
//! integral is S(λ) F(λ, d) ([`super::halfspace`]) with d the signed distance of p to the
//! visibility boundary: the smaller of the horizon's asin(p·n) and the occluder boundary's
//! asin(p·m_k), m_k the half-space of lobe k's SSDF at this point ([`super::ssdf`]).
//!
//! Nothing is precomputed: the screen-space depth maps are rendered from the mesh as it is
//! in this frame, so moving geometry needs nothing but a new call.

use std::f64::consts::PI;
use std::time::Instant;

use anyhow::{Result, bail};
use bspvt_proto::Scene;
use bspvt_proto::scene::Material;
use bspvt_server::bake::raycast::Occluder;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::Sg;
use super::brdf::{cosine_lobe, ggx_lobe};
use super::fit::SgEnv;
use super::halfspace;
use super::lobe::sphere_integral;
use super::ssdf::{Boundary, DepthMap, Point, exact_boundary};
use crate::groundtruth::{Brdf, Shadows};
use crate::render::camera::View;
use crate::render::gbuffer::GBuffer;
use crate::render::image::Image;

/// How the SSDF is found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SsdfMode {
    /// The paper's: a depth map per lighting lobe with a MIN/MAX pyramid, coarse-to-fine.
    Screen,
    /// Ray-cast search around each lobe axis with the BVH (reference; slow).
    Exact,
    /// No occluders (horizon only): unshadowed SG shading.
    None,
}

/// Renderer settings.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct SgOptions {
    pub ssdf: SsdfMode,
    /// Side of the screen-space depth maps (rounded up to a power of two; paper: 256).
    pub depth_res: u32,
}

impl Default for SgOptions {
    fn default() -> SgOptions {
        SgOptions {
            ssdf: SsdfMode::Screen,
            depth_res: 128,
        }
    }
}

/// Where a frame's time went.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct SgTimings {
    /// Rendering the depth maps and their pyramids (screen mode).
    pub maps_ms: f64,
    /// The per-pixel pass (SSDF search + shading).
    pub pixels_ms: f64,
    pub pixels_shaded: usize,
    pub lobes: usize,
}

/// The visible integral of `g` given the horizon `n` and the lobe's boundary.
#[inline]
fn visible_integral(g: &Sg, n: DVec3, b: &Boundary) -> f64 {
    if !(g.mu > 0.0) {
        return 0.0;
    }
    let p = g.axis.as_vec3();
    let d = p
        .dot(n.as_vec3())
        .clamp(-1.0, 1.0)
        .asin()
        .min(b.distance(p));
    if d == f32::NEG_INFINITY {
        return 0.0;
    }
    g.mu * sphere_integral(g.lambda) * f64::from(halfspace::fraction(g.lambda as f32, d))
}

/// Renders one SG frame of `scene` at the G-buffer's pixels. `occluder` is required for
/// [`SsdfMode::Exact`]. Pixels without a surface are black.
pub fn render(
    scene: &Scene,
    view: &View,
    gbuffer: &GBuffer,
    env: &SgEnv,
    occluder: Option<&Occluder>,
    opts: &SgOptions,
) -> Result<(Image, SgTimings)> {
    if opts.ssdf == SsdfMode::Exact && occluder.is_none() {
        bail!("the exact SSDF needs the ray-tracing BVH (an occluder)");
    }
    halfspace::warm_up();
    let mesh = &scene.mesh;
    let t0 = Instant::now();
    let maps: Vec<DepthMap> = if opts.ssdf == SsdfMode::Screen {
        let b = mesh.bounds();
        let centre = b.center();
        let radius = 0.5 * b.diagonal();
        env.lobes
            .par_iter()
            .map(|l| {
                let xi = DVec3::from(l.axis).normalize_or(DVec3::Y).as_vec3();
                DepthMap::render(mesh, centre, radius, xi, opts.depth_res as usize)
            })
            .collect()
    } else {
        Vec::new()
    };
    let maps_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t1 = Instant::now();
    let brdfs: Vec<Brdf> = scene.materials.iter().map(Brdf::from_material).collect();
    let fallback = Brdf::from_material(&Material::default());
    let eps = Shadows::for_scene(scene, None).epsilon as f32;
    let bias_abs = 1e-3 * mesh.bounds().diagonal();
    let lobes: Vec<(Sg, DVec3, Vec3)> = env
        .lobes
        .iter()
        .map(|l| {
            let sg = l.sg();
            (sg, l.rgb(), sg.axis.as_vec3())
        })
        .collect();
    let mut img = Image::new(gbuffer.width, gbuffer.height);
    img.pixels
        .par_iter_mut()
        .enumerate()
        .with_min_len(32)
        .for_each(|(i, px)| {
            let Some(s) = gbuffer.surface(mesh, view, i) else {
                return;
            };
            let brdf = mesh
                .material_ids
                .get(s.tri as usize)
                .and_then(|&m| brdfs.get(m as usize))
                .unwrap_or(&fallback);
            let n = s.normal;
            let wo = (view.eye - s.position).normalize_or(n);
            let point = Point {
                position: s.position.as_vec3(),
                geometric: s.geometric.as_vec3(),
            };
            let cos = cosine_lobe(n);
            let spec = ggx_lobe(brdf.alpha, n, wo);
            let diffuse = brdf.albedo / PI;
            let fresnel = spec.map(|s| brdf.f0 + (DVec3::ONE - brdf.f0) * s.fresnel_weight);
            let mut acc = DVec3::ZERO;
            for (k, (g, rgb, xi)) in lobes.iter().enumerate() {
                let b = match opts.ssdf {
                    SsdfMode::None => Boundary::Visible,
                    SsdfMode::Screen => maps[k].boundary(&point, bias_abs),
                    SsdfMode::Exact => match occluder {
                        Some(occ) => exact_boundary(occ, &point, *xi, eps),
                        None => Boundary::Visible,
                    },
                };
                if b == Boundary::Occluded {
                    continue;
                }
                let mut c = diffuse * visible_integral(&g.product(&cos), n, &b);
                if let (Some(sp), Some(f)) = (spec, fresnel) {
                    c += f * visible_integral(&g.product(&sp.sg), n, &b);
                }
                acc += *rgb * c;
            }
            if acc.is_finite() {
                *px = acc.as_vec3().to_array();
            }
        });
    let timings = SgTimings {
        maps_ms,
        pixels_ms: t1.elapsed().as_secs_f64() * 1e3,
        pixels_shaded: gbuffer.covered(),
        lobes: env.lobes.len(),
    };
    Ok((img, timings))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sg::fit::LightLobe;
    use bspvt_proto::builtin;

    fn one_lobe(axis: [f64; 3], lambda: f64) -> SgEnv {
        SgEnv {
            lobes: vec![LightLobe {
                axis,
                lambda,
                rgb: [1.0, 0.5, 0.25],
            }],
            fit_error: 0.0,
            fit_error_fitted_map: 0.0,
            iterations: 0,
            seconds: 0.0,
        }
    }

    /// Every mode renders finite, non-negative images; shadows only darken (screen and exact
    /// ≤ unshadowed, up to the half-space model's smoothing), and the exact SSDF needs rays.
    #[test]
    fn modes_render_finite_images() {
        let scene = builtin::scene("plate-small").expect("built-in scene");
        let view = View::new(&scene.camera, 48, 32);
        let g = GBuffer::rasterize(&scene.mesh, &view);
        let tris = bspvt_server::bake::raycast::mesh_triangles(&scene.mesh);
        let occ = Occluder::new(&scene.mesh, &tris);
        let env = one_lobe([0.2, 1.0, 0.1], 20.0);
        let mut means = Vec::new();
        for ssdf in [SsdfMode::None, SsdfMode::Screen, SsdfMode::Exact] {
            let opts = SgOptions {
                ssdf,
                depth_res: 64,
            };
            let (img, t) = render(&scene, &view, &g, &env, Some(&occ), &opts).expect("render");
            assert!(
                img.pixels
                    .iter()
                    .flatten()
                    .all(|c| c.is_finite() && *c >= 0.0),
                "{ssdf:?}"
            );
            assert_eq!(t.pixels_shaded, g.covered());
            means.push(img.mean());
        }
        eprintln!("means none/screen/exact: {means:?}");
        assert!(means[0] > 0.0);
        assert!(means[1] < means[0] && means[2] < means[0], "{means:?}");
        let opts = SgOptions {
            ssdf: SsdfMode::Exact,
            depth_res: 64,
        };
        assert!(render(&scene, &view, &g, &env, None, &opts).is_err());
    }
}
