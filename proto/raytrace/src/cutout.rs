//! Alpha cut-outs in the rays: a triangle whose material is cut out ([`Cutout`]: glTF
//! `alphaMode` MASK, BLEND as a mask at 0.5) blocks a ray only where its alpha at the hit's
//! texture coordinates reaches the cut-off — an any-hit filter, as a rasteriser's alpha test.
//! Triangles of opaque materials take no texture look-up and no extra memory beyond one word
//! per primitive, and only when the scene has a cut-out at all.

use std::sync::Arc;

use bspvt_proto::{Mesh, scene::Cutout, scene::Material};
use glam::Vec2;

/// A mesh's cut-out triangles: for each, its material's [`Cutout`] and the texture
/// coordinates of its corners. Built once per scene ([`Cutouts::of`]) and handed to the
/// occluders that shoot at it ([`crate::Occluder::cut_out`]).
#[derive(Debug)]
pub struct Cutouts {
    /// The cut-out materials' masks.
    masks: Vec<Cutout>,
    /// Per mesh triangle: 0 when opaque, else 1 + the index of its entry in `corners`.
    slot: Vec<u32>,
    /// Per cut-out triangle: its mask and its corners' UVs (`None`: a mesh without UVs, the
    /// texture's mean alpha).
    corners: Vec<(u32, Option<[Vec2; 3]>)>,
}

impl Cutouts {
    /// The cut-out triangles of `mesh` with these materials, or `None` when every surface is
    /// opaque (then rays take no alpha test at all).
    pub fn of(mesh: &Mesh, materials: &[Material]) -> Option<Arc<Cutouts>> {
        let mut masks = Vec::new();
        let mut of_material = vec![u32::MAX; materials.len()];
        for (m, material) in materials.iter().enumerate() {
            if let Some(c) = &material.cutout
                && !c.is_opaque()
            {
                of_material[m] = masks.len() as u32;
                masks.push(c.clone());
            }
        }
        if masks.is_empty() {
            return None;
        }
        let mut slot = vec![0u32; mesh.triangles.len()];
        let mut corners = Vec::new();
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let Some(&mask) = mesh
                .material_ids
                .get(t)
                .and_then(|&m| of_material.get(m as usize))
                .filter(|&&k| k != u32::MAX)
            else {
                continue;
            };
            let uv = tri
                .iter()
                .map(|&i| mesh.uvs.get(i as usize).copied())
                .collect::<Option<Vec<Vec2>>>()
                .map(|v| [v[0], v[1], v[2]]);
            corners.push((mask, uv));
            slot[t] = corners.len() as u32;
        }
        if corners.is_empty() {
            return None;
        }
        Some(Arc::new(Cutouts {
            masks,
            slot,
            corners,
        }))
    }

    /// How many triangles are cut out.
    pub fn triangles(&self) -> usize {
        self.corners.len()
    }

    /// A content hash of what the rays see (the masks, their texels and the cut-out
    /// triangles' UVs): part of a bake's identity, as the mesh's own content hash is.
    pub fn content_hash(&self) -> u64 {
        let mut h = bspvt_proto::hash::Fnv1a::default();
        for m in &self.masks {
            h.write_f32s(&[m.alpha, m.cutoff]);
            if let Some(t) = &m.texture {
                h.write(format!("{:?}", t.wrap).as_bytes());
                h.write(&t.texture.width.to_le_bytes());
                h.write(&t.texture.height.to_le_bytes());
                h.write(&t.texture.rgba);
            }
        }
        for (t, &s) in self.slot.iter().enumerate() {
            if s == 0 {
                continue;
            }
            h.write(&(t as u32).to_le_bytes());
            let (mask, uv) = &self.corners[s as usize - 1];
            h.write(&mask.to_le_bytes());
            for p in uv.iter().flatten() {
                h.write_f32s(&p.to_array());
            }
        }
        h.finish()
    }

    /// The cut-outs as `occlusion.wgsl`'s `cut` buffer, for primitives whose entries are
    /// `slots` (in BVH order): a header (1, where the entries start, where the masks start, 0),
    /// the slot of each primitive, 8 words per entry (mask, has UVs, the corners' UVs as f32
    /// bits), 16 words per mask (width, height — 0 without a texture —, the word its alpha
    /// bytes start at, the wrap modes along u and v — 0 repeat, 1 clamp, 2 mirror —, alpha,
    /// cut-off, the texture's mean alpha, its UV transform's a, b, c, d, tx, ty, two unused),
    /// then the masks' alpha bytes, four to a word.
    pub(crate) fn gpu_words(&self, slots: &[u32]) -> Vec<u32> {
        use bspvt_proto::texture::Wrap;
        let entries = 4 + slots.len();
        let masks = entries + 8 * self.corners.len();
        let mut w = vec![1, entries as u32, masks as u32, 0];
        w.extend_from_slice(slots);
        for (mask, uv) in &self.corners {
            w.push(*mask);
            w.push(u32::from(uv.is_some()));
            for p in uv.unwrap_or([Vec2::ZERO; 3]) {
                w.extend([p.x.to_bits(), p.y.to_bits()]);
            }
        }
        let mut texels = masks + 16 * self.masks.len();
        let mut bytes: Vec<&[u8]> = Vec::new();
        let wrap = |m: Wrap| match m {
            Wrap::Repeat => 0,
            Wrap::Clamp => 1,
            Wrap::Mirror => 2,
        };
        for m in &self.masks {
            let (size, wraps, mean) = match &m.texture {
                Some(t) => (
                    [t.texture.width, t.texture.height],
                    [wrap(t.wrap[0]), wrap(t.wrap[1])],
                    t.texture.mean(false)[3],
                ),
                None => ([0, 0], [0, 0], 1.0),
            };
            w.extend(size);
            w.push(texels as u32);
            w.extend(wraps);
            w.extend([m.alpha.to_bits(), m.cutoff.to_bits(), mean.to_bits()]);
            let uv = m
                .texture
                .as_ref()
                .and_then(|t| t.transform)
                .unwrap_or(bspvt_proto::texture::UvTransform::IDENTITY)
                .matrix();
            w.extend(uv.map(f32::to_bits));
            w.extend([0, 0]);
            if let Some(t) = &m.texture {
                let n = (t.texture.width * t.texture.height) as usize;
                texels += n.div_ceil(4);
                bytes.push(&t.texture.rgba);
            }
        }
        for rgba in bytes {
            let alpha: Vec<u8> = rgba.chunks_exact(4).map(|p| p[3]).collect();
            w.extend(alpha.chunks(4).map(|c| {
                c.iter()
                    .enumerate()
                    .fold(0u32, |acc, (k, &a)| acc | u32::from(a) << (8 * k))
            }));
        }
        w
    }

    /// [`Cutouts::gpu_words`] with each mesh triangle's entry in mesh order (a raster pass's
    /// triangle index).
    pub fn gpu_words_by_triangle(&self) -> Vec<u32> {
        self.gpu_words(&self.slot)
    }

    /// Whether mesh triangle `t` is present at barycentric `weights` of its corners (an
    /// opaque triangle always is): the test for closest-hit tracers built on their own BVH.
    pub fn covers_triangle(&self, t: u32, weights: [f32; 3]) -> bool {
        match self.slot(t) {
            0 => true,
            s => self.covers(s, weights),
        }
    }

    /// Entry of mesh triangle `t` (0: opaque).
    pub(crate) fn slot(&self, t: u32) -> u32 {
        self.slot.get(t as usize).copied().unwrap_or(0)
    }

    /// Whether the cut-out triangle in `slot` (≥ 1) is present at barycentric `weights` of its
    /// corners.
    pub(crate) fn covers(&self, slot: u32, weights: [f32; 3]) -> bool {
        let Some((mask, uv)) = self.corners.get(slot as usize - 1) else {
            return true;
        };
        let uv = uv.map(|c| c[0] * weights[0] + c[1] * weights[1] + c[2] * weights[2]);
        self.masks[*mask as usize].covers(uv)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Occluder, intersect, mesh_triangles};
    use bspvt_proto::scene::Cutout;
    use bspvt_proto::texture::{Texture, TextureRef, Wrap};
    use glam::{DVec3, Vec3};
    use obvhs::{ray::Ray, rt_triangle::RtTriangle, triangle::Triangle};

    /// The weights `intersect` returns are the hit's barycentrics of (v0, v1, v2): they
    /// rebuild the hit point (checked in f64).
    #[test]
    fn intersect_weights_rebuild_the_hit_point() {
        let p = [
            Vec3::new(0.3, -1.0, 2.0),
            Vec3::new(2.0, 0.5, 1.5),
            Vec3::new(-0.5, 1.5, 2.5),
        ];
        let tri = RtTriangle::from(&Triangle {
            v0: p[0].into(),
            v1: p[1].into(),
            v2: p[2].into(),
        });
        for (a, b) in [(0.2, 0.3), (0.6, 0.1), (0.05, 0.9), (1.0 / 3.0, 1.0 / 3.0)] {
            let target = p[0] * (1.0 - a - b) + p[1] * a + p[2] * b;
            let o = Vec3::new(0.1, 0.2, -1.0);
            let d = (target - o).normalize();
            let (t, w) =
                intersect(&tri, &Ray::new(o.into(), d.into(), 0.0, f32::INFINITY)).expect("a hit");
            let hit = o.as_dvec3() + d.as_dvec3() * f64::from(t);
            let rebuilt: DVec3 = (0..3).map(|k| p[k].as_dvec3() * f64::from(w[k])).sum();
            assert!((hit - rebuilt).length() < 1e-5, "{hit} vs {rebuilt}");
            assert!((f64::from(w[1]) - a as f64).abs() < 1e-5, "{w:?}");
            assert!((f64::from(w[2]) - b as f64).abs() < 1e-5, "{w:?}");
        }
    }

    /// A unit quad cut out by a 2 × 2 alpha checker: rays through its open quarters pass, rays
    /// through its solid quarters are blocked, and the same quad opaque blocks them all.
    #[test]
    fn rays_pass_through_the_holes_only() {
        let mut mesh = bspvt_proto::Mesh {
            positions: vec![
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(1.0, 1.0, 1.0),
                Vec3::new(0.0, 1.0, 1.0),
            ],
            normals: vec![Vec3::Y; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            material_ids: vec![0, 0],
            uvs: vec![
                Vec2::new(0.0, 0.0),
                Vec2::new(1.0, 0.0),
                Vec2::new(1.0, 1.0),
                Vec2::new(0.0, 1.0),
            ],
        };
        // Texel (x, y) open when x + y is odd.
        let rgba = (0..4)
            .flat_map(|i| {
                [
                    255,
                    255,
                    255,
                    if (i % 2 + i / 2) % 2 == 0 { 255 } else { 0 },
                ]
            })
            .collect();
        let texture = TextureRef {
            texture: std::sync::Arc::new(Texture {
                name: "checker".into(),
                width: 2,
                height: 2,
                rgba,
                source: Vec::new(),
                mips: Default::default(),
            }),
            wrap: [Wrap::Clamp; 2],
            transform: None,
        };
        let material = Material {
            cutout: Some(Cutout {
                alpha: 1.0,
                cutoff: 0.5,
                texture: Some(texture),
                blend: false,
            }),
            ..Material::default()
        };
        let cut = Cutouts::of(&mesh, std::slice::from_ref(&material)).expect("cut out");
        assert_eq!(cut.triangles(), 2);
        let occ = Occluder::new(&mesh, &mesh_triangles(&mesh)).cut_out(Some(cut));
        let opaque = Occluder::new(&mesh, &mesh_triangles(&mesh));
        for (x, z, open) in [
            (0.25, 0.25, false),
            (0.75, 0.25, true),
            (0.25, 0.75, true),
            (0.75, 0.75, false),
        ] {
            let o = Vec3::new(x, 0.0, z);
            assert_eq!(occ.occluded(o, Vec3::Y, u32::MAX), !open, "({x}, {z})");
            assert_eq!(occ.first_hit(o, Vec3::Y, 10.0).is_some(), !open);
            assert!(opaque.occluded(o, Vec3::Y, u32::MAX));
        }
        // Without UVs the texture's mean alpha (0.5) decides: present everywhere.
        mesh.uvs.clear();
        let cut = Cutouts::of(&mesh, std::slice::from_ref(&material)).expect("cut out");
        let occ = Occluder::new(&mesh, &mesh_triangles(&mesh)).cut_out(Some(cut));
        assert!(occ.occluded(Vec3::new(0.75, 0.0, 0.25), Vec3::Y, u32::MAX));
        // An opaque material makes no cut-outs at all.
        assert!(Cutouts::of(&mesh, &[Material::default()]).is_none());
    }
}
