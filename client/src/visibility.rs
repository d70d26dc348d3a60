//! Per-vertex visibility of polygonal lights from baked trees.

use bspvt_proto::Scene;
use bspvt_proto::bspvt::{LineCodec, VertexTrees};
use bspvt_proto::sphere::clip;
use glam::DVec3;
use rayon::prelude::*;

/// The directions of a light polygon seen from `p`, clipped to the upper hemisphere of `n`.
/// Empty when the light is wholly below the horizon or `p` is behind a one-sided light.
pub(crate) fn light_directions(
    light: &[DVec3],
    light_normal: DVec3,
    two_sided: bool,
    p: DVec3,
    n: DVec3,
) -> Vec<DVec3> {
    if !two_sided && light_normal.dot(p - light[0]) <= 0.0 {
        return Vec::new();
    }
    let dirs: Vec<DVec3> = light.iter().map(|&q| q - p).collect();
    clip(&dirs, n).to_vec()
}

/// For every vertex, the fraction of the light's (upper-hemisphere) solid angle the trees say
/// is visible: Σ v̄ᵢ Ωᵢ / Ω. Vertices that cannot see the light at all get `None`.
pub fn visible_fractions(
    scene: &Scene,
    light: usize,
    codec: &LineCodec,
    trees: &[VertexTrees],
) -> Vec<Option<f64>> {
    let l = &scene.lights[light];
    let poly: Vec<DVec3> = l.points().iter().map(|p| p.as_dvec3()).collect();
    let ln = l.normal().as_dvec3();
    trees
        .par_iter()
        .enumerate()
        .map(|(v, t)| {
            let p = scene.mesh.positions[v].as_dvec3();
            let n = scene.mesh.normals[v].as_dvec3();
            let dirs = light_directions(&poly, ln, l.two_sided, p, n);
            (dirs.len() >= 3).then(|| t.visible_fraction(codec, &dirs))
        })
        .collect()
}
