//! Environment lighting with spherical Gaussians and a run-time spherical signed distance
//! function (paper 001; Wang et al. 2009 for the SG shading, Xu et al. 2013 for SSDF
//! visibility). Pure math lives in [`lobe`], [`halfspace`] and [`brdf`].

pub(crate) mod brdf;
pub(crate) mod diffuse;
pub mod fit;
pub mod halfspace;
pub(crate) mod lobe;
pub(crate) mod render;
pub(crate) mod ssdf;

pub use fit::{FitOptions, LightLobe, SgEnv, fit, fit_cached, fit_with};
pub use lobe::Sg;
pub use render::{SgCache, SgOptions, SgTimings, SsdfMode, render, render_cached};

#[cfg(test)]
pub(crate) mod testutil {
    use std::f64::consts::PI;

    use glam::DVec3;

    /// ∫ f over the sphere in polar coordinates about `axis`: midpoint rule in φ (256 cells)
    /// and, per φ, the tanh-sinh rule in θ over intervals [0, 1e-6, 2e-6, …, π] that resolve
    /// lobes up to λ ≈ 1e10 around `axis`.
    pub(crate) fn quad_about(axis: DVec3, f: &dyn Fn(DVec3) -> f64) -> f64 {
        let (t1, t2) = axis.any_orthonormal_pair();
        let n_phi = 256;
        let mut edges = vec![0.0];
        let mut e = 1e-6;
        while e < PI {
            edges.push(e);
            e *= 2.0;
        }
        edges.push(PI);
        let mut total = 0.0;
        for j in 0..n_phi {
            let phi = 2.0 * PI * (j as f64 + 0.5) / n_phi as f64;
            let (s, c) = phi.sin_cos();
            let dir_t = t1 * c + t2 * s;
            for w in edges.windows(2) {
                total += quadrature::double_exponential::integrate(
                    |th: f64| f(axis * th.cos() + dir_t * th.sin()) * th.sin(),
                    w[0],
                    w[1],
                    1e-14,
                )
                .integral;
            }
        }
        total * 2.0 * PI / n_phi as f64
    }
}
