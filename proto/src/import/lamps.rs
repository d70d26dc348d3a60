//! The asset's lamps: emitting triangles merged into the polygon lights the shading kernels take.
//!
//! A triangle emits when its material has a non-zero emission (glTF `emissiveFactor` ×
//! `KHR_materials_emissive_strength`, OBJ/MTL `Ke`). Emitting triangles are taken out of the
//! mesh (a lamp does not shadow its own light) and grouped:
//!
//! - each is oriented by its vertex normals (wound so that `(b − a) × (c − a)` points where
//!   the normals do), so an exporter's winding does not decide which way a lamp shines;
//! - triangles of the same radiance and sidedness that share an edge (by exact position, since
//!   exporters split vertices at seams) and lie in one plane are merged greedily into one
//!   convex polygon of at most 8 vertices (collinear vertices dropped); what cannot be merged
//!   stays a separate light;
//! - at most [`MAX_LAMPS`] lights are kept, the most powerful (radiance × area) first.

use std::collections::HashMap;

use glam::{DVec2, DVec3, Vec2, Vec3};

use crate::light::PolygonLight;
use crate::texture::{LightImage, TextureRef};

/// Most lights taken from one asset: shading costs one polygon integral per light and pixel.
pub(crate) const MAX_LAMPS: usize = 64;

/// Most vertices of a light polygon ([`PolygonLight`] takes 3 to 8).
const MAX_VERTICES: usize = 8;

/// One emitting triangle.
pub(crate) struct Emitter {
    /// Corners, in file winding.
    pub corners: [Vec3; 3],
    /// Sum of the corners' vertex normals (the side the lamp shines to).
    pub normal_hint: Vec3,
    /// Emitted radiance, linear RGB.
    pub radiance: [f32; 3],
    /// Emits from both sides.
    pub two_sided: bool,
    /// The emissive texture (glTF `emissiveTexture`) and the corners' UVs.
    pub texture: Option<(TextureRef, [Vec2; 3])>,
}

/// What [`merge`] made of the emitters.
pub(crate) struct Lamps {
    /// The lights, most powerful first.
    pub lights: Vec<PolygonLight>,
    /// For each light, the emitters of the coplanar group it was cut from.
    pub groups: Vec<Vec<usize>>,
    /// Emitting polygons left out by [`MAX_LAMPS`].
    pub dropped: usize,
    /// Emitting triangles with no area (skipped).
    pub degenerate: usize,
}

/// Merges emitting triangles into convex polygon lights (see the module documentation).
pub(crate) fn merge(emitters: &[Emitter]) -> Lamps {
    let mut degenerate = 0;
    // Oriented triangles with their unit normal; degenerate ones skipped.
    let mut tris: Vec<([Vec3; 3], Vec3, usize)> = Vec::with_capacity(emitters.len());
    for (i, e) in emitters.iter().enumerate() {
        let [a, b, c] = e.corners;
        let n = (b - a).cross(c - a);
        let Some(unit) = n.try_normalize() else {
            degenerate += 1;
            continue;
        };
        if unit.dot(e.normal_hint) < 0.0 {
            tris.push(([a, c, b], -unit, i));
        } else {
            tris.push(([a, b, c], unit, i));
        }
    }
    // Directed edge (by exact positions) → triangle, for finding neighbours.
    let key = |p: Vec3| p.to_array().map(f32::to_bits);
    let mut by_edge: HashMap<([u32; 3], [u32; 3]), usize> = HashMap::new();
    for (t, (c, _, _)) in tris.iter().enumerate() {
        for k in 0..3 {
            by_edge.entry((key(c[k]), key(c[(k + 1) % 3]))).or_insert(t);
        }
    }
    let compatible = |t: usize, u: usize| {
        let (e, f) = (&emitters[tris[t].2], &emitters[tris[u].2]);
        e.radiance == f.radiance
            && e.two_sided == f.two_sided
            && match (&e.texture, &f.texture) {
                (None, None) => true,
                (Some((a, _)), Some((b, _))) => {
                    std::sync::Arc::ptr_eq(&a.texture, &b.texture)
                        && a.wrap == b.wrap
                        && a.transform == b.transform
                }
                _ => false,
            }
            && tris[t].1.dot(tris[u].1) >= 1.0 - 1e-5
    };
    // The neighbour of `t` across its edge k, when compatible.
    let neighbour = |t: usize, k: usize| -> Option<usize> {
        let c = tris[t].0;
        let &u = by_edge.get(&(key(c[(k + 1) % 3]), key(c[k])))?;
        (u != t && compatible(t, u)).then_some(u)
    };
    let mut used = vec![false; tris.len()];
    let mut polygons: Vec<(Vec<Vec3>, usize, f32, usize)> = Vec::new();
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for start in 0..tris.len() {
        if used[start] {
            continue;
        }
        // The connected, compatible, coplanar group of `start` (flood fill in index order).
        let normal = tris[start].1;
        let c0 = tris[start].0[0];
        let size = (tris[start].0[1] - c0)
            .length()
            .max((tris[start].0[2] - c0).length());
        let mut group = vec![start];
        used[start] = true;
        let mut i = 0;
        while i < group.len() {
            for k in 0..3 {
                if let Some(u) = neighbour(group[i], k)
                    && !used[u]
                    && tris[u]
                        .0
                        .iter()
                        .all(|p| (*p - c0).dot(normal).abs() <= 1e-5 * size)
                {
                    used[u] = true;
                    group.push(u);
                }
            }
            i += 1;
        }
        for poly in polygons_of(&group, &tris, normal, &neighbour) {
            let src = tris[start].2;
            let e = &emitters[src];
            let area = 0.5 * crate::light::newell_normal(&poly).length();
            let power = area * (e.radiance[0] + e.radiance[1] + e.radiance[2]);
            polygons.push((poly, src, power, groups.len()));
        }
        groups.push(group.iter().map(|&t| tris[t].2).collect());
    }
    // Most powerful first; ties keep file order (the sort is stable).
    polygons.sort_by(|a, b| b.2.total_cmp(&a.2));
    let dropped = polygons.len().saturating_sub(MAX_LAMPS);
    polygons.truncate(MAX_LAMPS);
    let light_groups = polygons
        .iter()
        .map(|(_, _, _, g)| groups[*g].clone())
        .collect();
    let lights = polygons
        .into_iter()
        .map(|(poly, src, _, _)| PolygonLight {
            vertices: poly.iter().map(|p| p.to_array()).collect(),
            radiance: emitters[src].radiance,
            two_sided: emitters[src].two_sided,
            texture: None,
            // An asset's lamp is where the asset put it.
            region: None,
            moves_in_plane: false,
            image: None,
        })
        .collect();
    Lamps {
        lights,
        groups: light_groups,
        dropped,
        degenerate,
    }
}

/// Most texels per side of a lamp's resampled emissive texture.
pub(crate) const MAX_LAMP_TEXELS_PER_SIDE: usize = 256;

/// The emissive texture of a lamp cut from the emitters `group`, resampled onto the light's
/// parametrisation ((u, v) in the basis (p₁ − p₀, pₙ₋₁ − p₀), v down the rows: what
/// `bspvt_client::texture` reads). The group's UVs must be one affine map of its plane —
/// checked at every corner to 10⁻³ of the UVs' extent — else `Err` says why (the caller then
/// uses the texture's mean). Each axis gets as many texels as the texture has across the
/// polygon's extent along it, between 1 and [`MAX_LAMP_TEXELS_PER_SIDE`]; each texel is the
/// bilinear, linearised (sRGB) emissive texture at its centre's UV.
pub(crate) fn lamp_image(
    light: &PolygonLight,
    group: &[usize],
    emitters: &[Emitter],
) -> Result<LightImage, String> {
    let corners: Vec<(DVec3, DVec2, &TextureRef)> = group
        .iter()
        .filter_map(|&i| emitters.get(i))
        .filter_map(|e| {
            let (t, uv) = e.texture.as_ref()?;
            Some((0..3).map(move |k| (e.corners[k].as_dvec3(), uv[k].as_dvec2(), t)))
        })
        .flatten()
        .collect();
    let Some(&(_, _, tex)) = corners.first() else {
        return Err("it has no texture coordinates".into());
    };
    // The affine map from the first triangle with area: p = a + s e₁ + t e₂ ↦ uv_a + s d₁ + t d₂.
    let map = corners
        .chunks_exact(3)
        .find_map(|c| {
            let (a, e1, e2) = (c[0].0, c[1].0 - c[0].0, c[2].0 - c[0].0);
            let (g11, g12, g22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
            let det = g11 * g22 - g12 * g12;
            (det > 1e-12 * g11 * g22 && det.is_finite()).then_some((
                a,
                e1,
                e2,
                [g11, g12, g22, det],
                c[0].1,
                c[1].1 - c[0].1,
                c[2].1 - c[0].1,
            ))
        })
        .ok_or("its triangles have no area")?;
    let (a, e1, e2, [g11, g12, g22, det], uva, d1, d2) = map;
    let uv_of = |p: DVec3| {
        let r = p - a;
        let (x, y) = (r.dot(e1), r.dot(e2));
        let s = (g22 * x - g12 * y) / det;
        let t = (g11 * y - g12 * x) / det;
        uva + s * d1 + t * d2
    };
    let (lo, hi) = corners.iter().fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), c| (lo.min(c.1), hi.max(c.1)),
    );
    let tol = 1e-3 * (hi - lo).max_element().max(1e-6);
    if let Some(c) = corners
        .iter()
        .find(|c| (uv_of(c.0) - c.1).abs().max_element() > tol)
    {
        return Err(format!(
            "its texture coordinates are not an affine map of the lamp's plane (a corner at \
             UV ({:.4}, {:.4}) where the map gives ({:.4}, {:.4}))",
            c.1.x,
            c.1.y,
            uv_of(c.0).x,
            uv_of(c.0).y
        ));
    }
    let p = light.points();
    let n = p.len();
    let (p0, l1, l2) = (
        p[0].as_dvec3(),
        (p[1 % n] - p[0]).as_dvec3(),
        (p[n - 1] - p[0]).as_dvec3(),
    );
    let size = DVec2::new(f64::from(tex.texture.width), f64::from(tex.texture.height));
    let texels_along = |l: DVec3| {
        let span = ((uv_of(p0 + l) - uv_of(p0)) * size).length();
        if span.is_finite() {
            (span.ceil() as usize).clamp(1, MAX_LAMP_TEXELS_PER_SIDE)
        } else {
            1
        }
    };
    let (w, h) = (texels_along(l1), texels_along(l2));
    let mut texels = Vec::with_capacity(w * h);
    for j in 0..h {
        for i in 0..w {
            let (u, v) = ((i as f64 + 0.5) / w as f64, (j as f64 + 0.5) / h as f64);
            let uv = uv_of(p0 + u * l1 + v * l2).as_vec2();
            let t = tex.sample(uv, true);
            texels.push([t[0], t[1], t[2]].map(|x| if x.is_finite() { x.max(0.0) } else { 0.0 }));
        }
    }
    Ok(LightImage {
        width: w as u32,
        height: h as u32,
        texels,
    })
}

/// Convex polygons of at most 8 vertices covering a connected coplanar `group`: its outline
/// when that is one convex loop (a quad, a disc fan), else greedy merges of neighbours.
fn polygons_of(
    group: &[usize],
    tris: &[([Vec3; 3], Vec3, usize)],
    normal: Vec3,
    neighbour: &dyn Fn(usize, usize) -> Option<usize>,
) -> Vec<Vec<Vec3>> {
    let key = |p: Vec3| p.to_array().map(f32::to_bits);
    let in_group: std::collections::HashSet<usize> = group.iter().copied().collect();
    // Outline: the edges whose neighbour is not in the group, as a next-vertex map.
    let mut next: HashMap<[u32; 3], Vec3> = HashMap::new();
    let mut loop_ok = true;
    for &t in group {
        for k in 0..3 {
            if neighbour(t, k).is_some_and(|u| in_group.contains(&u)) {
                continue;
            }
            let c = tris[t].0;
            loop_ok &= next.insert(key(c[k]), c[(k + 1) % 3]).is_none();
        }
    }
    if loop_ok && let Some(first) = next.keys().min() {
        let start = next[first];
        let mut outline = vec![start];
        let mut p = start;
        while let Some(&q) = next.get(&key(p)) {
            if key(q) == key(start) || outline.len() > next.len() {
                break;
            }
            outline.push(q);
            p = q;
        }
        if outline.len() == next.len() {
            let outline = drop_collinear(&outline, normal);
            if outline.len() <= MAX_VERTICES && is_convex(&outline, normal) {
                return vec![outline];
            }
        }
    }
    // Greedy: grow a polygon from each unused triangle while a neighbour across one of its
    // edges keeps it convex and within 8 vertices.
    let mut used: std::collections::HashSet<usize> = std::collections::HashSet::new();
    let mut out = Vec::new();
    for &start in group {
        if !used.insert(start) {
            continue;
        }
        let mut poly: Vec<Vec3> = tris[start].0.to_vec();
        let mut grown = true;
        while grown {
            grown = false;
            'edges: for &t in group {
                if used.contains(&t) {
                    continue;
                }
                let c = tris[t].0;
                for k in 0..3 {
                    // Triangle edge a→b glued to polygon edge b→a; its third corner w goes
                    // between b and a.
                    let (a, b, w) = (c[k], c[(k + 1) % 3], c[(k + 2) % 3]);
                    let n = poly.len();
                    let Some(j) = (0..n)
                        .find(|&j| key(poly[j]) == key(b) && key(poly[(j + 1) % n]) == key(a))
                    else {
                        continue;
                    };
                    let mut candidate = poly.clone();
                    candidate.insert(j + 1, w);
                    let candidate = drop_collinear(&candidate, normal);
                    if candidate.len() <= MAX_VERTICES && is_convex(&candidate, normal) {
                        poly = candidate;
                        used.insert(t);
                        grown = true;
                        break 'edges;
                    }
                }
            }
        }
        out.push(poly);
    }
    out
}

/// `poly` without vertices that lie on the segment between their neighbours.
fn drop_collinear(poly: &[Vec3], normal: Vec3) -> Vec<Vec3> {
    let n = poly.len();
    let scale = poly
        .iter()
        .map(|p| (*p - poly[0]).length_squared())
        .fold(0.0, f32::max);
    (0..n)
        .filter(|&i| {
            let (a, b, c) = (poly[(i + n - 1) % n], poly[i], poly[(i + 1) % n]);
            (b - a).cross(c - b).dot(normal).abs() > 1e-6 * scale
        })
        .map(|i| poly[i])
        .collect()
}

/// Whether `poly` turns the same way (counter-clockwise about `normal`) at every vertex.
fn is_convex(poly: &[Vec3], normal: Vec3) -> bool {
    let n = poly.len();
    n >= 3
        && (0..n).all(|i| {
            let (a, b, c) = (poly[i], poly[(i + 1) % n], poly[(i + 2) % n]);
            (b - a).cross(c - b).dot(normal) > 0.0
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn emitter(corners: [Vec3; 3], hint: Vec3) -> Emitter {
        Emitter {
            corners,
            normal_hint: hint,
            radiance: [5.0, 4.0, 3.0],
            two_sided: false,
            texture: None,
        }
    }

    /// A quad of two triangles (with split seam vertices) becomes one 4-vertex light facing
    /// down, whatever the file's winding, since the normals say down.
    #[test]
    fn a_quad_lamp_is_one_light_oriented_by_its_normals() {
        let (a, b, c, d) = (
            Vec3::new(-0.5, 2.0, -0.5),
            Vec3::new(0.5, 2.0, -0.5),
            Vec3::new(0.5, 2.0, 0.5),
            Vec3::new(-0.5, 2.0, 0.5),
        );
        // Wound counter-clockwise seen from above (normal +Y), normals pointing down.
        let l = merge(&[
            emitter([a, d, c], Vec3::NEG_Y),
            emitter([a, c, b], Vec3::NEG_Y),
        ]);
        assert_eq!(l.lights.len(), 1);
        let light = &l.lights[0];
        assert_eq!(light.vertices.len(), 4);
        assert!(
            light.normal().dot(Vec3::NEG_Y) > 0.999,
            "{:?}",
            light.normal()
        );
        assert!(light.validate(0).is_ok());
        let area = 0.5 * crate::light::newell_normal(&light.points()).length();
        assert!((area - 1.0).abs() < 1e-6, "{area}");
    }

    /// A fan of 8 triangles around a centre (an octagonal lamp with its centre vertex) merges
    /// into one octagon; a 16-gon cannot (over 8 vertices) and stays several lights.
    #[test]
    fn fans_merge_up_to_eight_vertices() {
        for (sides, lights) in [(8, 1), (16, 3)] {
            let rim: Vec<Vec3> = (0..sides)
                .map(|i| {
                    let t = std::f32::consts::TAU * i as f32 / sides as f32;
                    Vec3::new(t.cos(), 1.0, -t.sin())
                })
                .collect();
            let centre = Vec3::new(0.0, 1.0, 0.0);
            let e: Vec<Emitter> = (0..sides)
                .map(|i| emitter([centre, rim[i], rim[(i + 1) % sides]], Vec3::Y))
                .collect();
            let l = merge(&e);
            assert!(l.lights.len() <= lights, "{sides}: {}", l.lights.len());
            assert!(l.lights.len() > 1 || sides == 8);
            let area: f32 = l
                .lights
                .iter()
                .map(|x| 0.5 * crate::light::newell_normal(&x.points()).length())
                .sum();
            let expect = 0.5 * sides as f32 * (std::f32::consts::TAU / sides as f32).sin();
            assert!((area - expect).abs() < 1e-5, "{sides}: {area} vs {expect}");
            for x in &l.lights {
                assert!(x.validate(0).is_ok(), "{sides}");
            }
        }
    }

    /// Different radiance, a fold (not coplanar) and a zero-area triangle are not merged.
    #[test]
    fn unlike_or_folded_neighbours_stay_apart() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, -1.0));
        let mut hot = emitter([a, c, Vec3::new(0.0, 0.0, -1.0)], Vec3::Y);
        hot.radiance = [9.0; 3];
        let folded = emitter([a, Vec3::new(0.5, 0.5, 0.5), b], Vec3::Y);
        let flat = emitter([a, b, c], Vec3::Y);
        let zero = emitter([a, b, Vec3::new(2.0, 0.0, 0.0)], Vec3::Y);
        let l = merge(&[flat, hot, folded, zero]);
        assert_eq!(l.lights.len(), 3);
        assert_eq!(l.degenerate, 1);
    }
}
