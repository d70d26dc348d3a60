//! Indexed triangle meshes: the geometry every other part of bspvt works on.
//!
//! Vertex order is tree order: the bake produces one set of visibility trees per vertex, in the
//! order of [`Mesh::positions`].

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

use crate::error::MeshError;

/// An indexed triangle mesh with per-vertex normals and a material per triangle.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Unit normals, one per position.
    pub normals: Vec<Vec3>,
    /// Vertex indices of each triangle.
    pub triangles: Vec<[u32; 3]>,
    /// Index into the scene's materials, one per triangle.
    pub material_ids: Vec<u32>,
    /// Texture coordinates (glTF's convention: (0, 0) the image's top-left), one per position,
    /// or empty: only a mesh whose materials are textured carries them. Not part of the
    /// postcard form of `Mesh` (nor of [`Mesh::content_hash`]: the bake does not depend on
    /// them); the stored scene carries them beside the mesh (`api`, version 5).
    #[serde(skip)]
    pub uvs: Vec<Vec2>,
}

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Vec3,
    /// Largest corner.
    pub max: Vec3,
}

impl Aabb {
    pub(crate) const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// The smallest box holding `points` (an empty, invalid box for none).
    pub fn from_points(points: &[Vec3]) -> Aabb {
        points.iter().fold(Aabb::EMPTY, |b, &p| b.grow(p))
    }

    pub(crate) fn grow(self, p: Vec3) -> Aabb {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The box's centre.
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Length of the box's diagonal.
    pub fn diagonal(&self) -> f32 {
        (self.max - self.min).length()
    }

    pub(crate) fn is_valid(&self) -> bool {
        self.min.is_finite() && self.max.is_finite() && self.min.cmple(self.max).all()
    }

    /// Whether the ray `origin + t·dir`, t ≥ 0, meets the box (slab test).
    pub fn hit_by_ray(&self, origin: Vec3, dir: Vec3) -> bool {
        let inv = dir.recip();
        let t0 = (self.min - origin) * inv;
        let t1 = (self.max - origin) * inv;
        // NaN (0 · ∞ when the origin lies on a slab plane) is treated as "inside the slab".
        let tmin = t0.min(t1);
        let tmax = t0.max(t1);
        let enter = tmin.x.max(tmin.y).max(tmin.z).max(0.0);
        let exit = tmax.x.min(tmax.y).min(tmax.z);
        enter <= exit
    }

    /// Where the ray `origin + t·dir` enters the box: `Some(t)` with t > 0 when it does from
    /// outside; `None` when it misses the box or starts inside it.
    pub fn ray_entry(&self, origin: Vec3, dir: Vec3) -> Option<f32> {
        let inv = dir.recip();
        let t0 = (self.min - origin) * inv;
        let t1 = (self.max - origin) * inv;
        let tmin = t0.min(t1);
        let tmax = t0.max(t1);
        let enter = tmin.x.max(tmin.y).max(tmin.z);
        let exit = tmax.x.min(tmax.y).min(tmax.z);
        (enter > 0.0 && enter <= exit).then_some(enter)
    }
}

impl Mesh {
    /// The texture coordinates at barycentric `weights` of triangle `tri` (`None`: no UVs).
    pub fn uv_at(&self, tri: usize, weights: [f64; 3]) -> Option<Vec2> {
        let t = self.triangles.get(tri)?;
        let mut uv = glam::DVec2::ZERO;
        for (k, &i) in t.iter().enumerate() {
            uv += self.uvs.get(i as usize)?.as_dvec2() * weights[k];
        }
        Some(uv.as_vec2())
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// The bounding box of the positions.
    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(&self.positions)
    }

    /// Checks the invariants every consumer relies on; importers call it before returning.
    pub fn validate(&self) -> Result<(), MeshError> {
        if self.triangles.is_empty() {
            return Err(MeshError::NoTriangles);
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinitePosition { vertex: i });
        }
        if self.normals.len() != self.positions.len() {
            return Err(MeshError::Invalid(format!(
                "{} normals for {} positions",
                self.normals.len(),
                self.positions.len()
            )));
        }
        if self.material_ids.len() != self.triangles.len() {
            return Err(MeshError::Invalid(format!(
                "{} material ids for {} triangles",
                self.material_ids.len(),
                self.triangles.len()
            )));
        }
        let n = self.positions.len();
        for (t, tri) in self.triangles.iter().enumerate() {
            if let Some(&i) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::IndexOutOfRange {
                    triangle: t,
                    index: i as u64,
                    vertices: n,
                });
            }
        }
        if let Some(i) = self.normals.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::Invalid(format!("normal {i} is not finite")));
        }
        if !self.uvs.is_empty() && self.uvs.len() != self.positions.len() {
            return Err(MeshError::Invalid(format!(
                "{} texture coordinates for {} positions",
                self.uvs.len(),
                self.positions.len()
            )));
        }
        if let Some(i) = self.uvs.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::Invalid(format!(
                "texture coordinate {i} is not finite"
            )));
        }
        Ok(())
    }

    /// Area-and-angle weighted vertex normals from the triangles (used when a file has none).
    /// Vertices with no usable neighbouring triangle get +Y.
    pub fn compute_normals(&mut self) {
        let mut acc = vec![Vec3::ZERO; self.positions.len()];
        for tri in &self.triangles {
            let p = tri.map(|i| self.positions[i as usize]);
            // Face normal with length = 2·area; weighting by it favours large triangles.
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            if !n.is_finite() {
                continue;
            }
            for &i in tri {
                acc[i as usize] += n;
            }
        }
        self.normals = acc
            .into_iter()
            .map(|n| n.try_normalize().unwrap_or(Vec3::Y))
            .collect();
    }

    /// Drops vertices no triangle uses, keeping the order of the rest.
    pub(crate) fn drop_unused_vertices(&mut self) {
        let mut used = vec![false; self.positions.len()];
        for tri in &self.triangles {
            for &i in tri {
                used[i as usize] = true;
            }
        }
        if used.iter().all(|&u| u) {
            return;
        }
        let mut remap = vec![u32::MAX; used.len()];
        let mut next = 0u32;
        for (i, &u) in used.iter().enumerate() {
            if u {
                remap[i] = next;
                next += 1;
            }
        }
        let keep = |v: &Vec<Vec3>| -> Vec<Vec3> {
            v.iter()
                .zip(&used)
                .filter(|(_, u)| **u)
                .map(|(p, _)| *p)
                .collect()
        };
        self.positions = keep(&self.positions);
        if self.normals.len() == used.len() {
            self.normals = keep(&self.normals);
        }
        if self.uvs.len() == used.len() {
            self.uvs = self
                .uvs
                .iter()
                .zip(&used)
                .filter(|(_, u)| **u)
                .map(|(p, _)| *p)
                .collect();
        } else {
            self.uvs.clear();
        }
        for tri in &mut self.triangles {
            *tri = tri.map(|i| remap[i as usize]);
        }
    }

    /// Appends `other`, offsetting its indices and material ids by `material_offset`.
    /// Moves every vertex by `m` (normals by its inverse transpose, renormalised).
    pub(crate) fn transform(&mut self, m: &glam::Affine3A) {
        let nm = glam::Mat3::from(m.matrix3).inverse().transpose();
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        for n in &mut self.normals {
            *n = (nm * *n).try_normalize().unwrap_or(*n);
        }
    }

    /// Appends `other`, shifting its indices and its material ids by `material_offset`.
    /// When either carries UVs the result does, (0, 0) for the vertices of the one without.
    pub fn append(&mut self, other: &Mesh, material_offset: u32) {
        let base = self.positions.len() as u32;
        if !self.uvs.is_empty() || !other.uvs.is_empty() {
            self.uvs.resize(self.positions.len(), Vec2::ZERO);
            if other.uvs.len() == other.positions.len() {
                self.uvs.extend_from_slice(&other.uvs);
            } else {
                self.uvs
                    .resize(self.positions.len() + other.positions.len(), Vec2::ZERO);
            }
        }
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
        self.material_ids
            .extend(other.material_ids.iter().map(|m| m + material_offset));
    }

    /// Indices of the triangles a ray can meet, in mesh order: of each set of coincident
    /// triangles (the same three positions, bit for bit, in any order or winding, whatever
    /// their vertex indices) the first, and no triangle whose three corners are one point.
    /// The others are left out of the ray casters' BVHs: a copy answers every ray as the first
    /// does — or, when it lies on other vertices (a doubled sheet), would only shadow the first
    /// one's vertices, which the vertices' own triangles never do —, a point is never hit (its
    /// edges are zero: the intersection's t is 0 · ∞ = NaN, which no ray accepts), and a
    /// million copies of one face, or of one point, kept a BVH build busy for hours.
    ///
    /// Two sorts of packed 128-bit keys: the positions by their bits (each distinct position
    /// an id), then the triangles by their sorted corner ids with the triangle's index in the
    /// low bits, so the first of each run is the first in mesh order — not the 36-byte keys of
    /// the corners' bits themselves (docs/benchmarks.md, "The first frame of an uploaded
    /// mesh").
    pub fn unique_triangles(&self) -> Vec<u32> {
        let pack = |k: [u32; 3], low: u32| {
            (u128::from(k[0]) << 96)
                | (u128::from(k[1]) << 64)
                | (u128::from(k[2]) << 32)
                | u128::from(low)
        };
        let mut by_bits: Vec<u128> = self
            .positions
            .iter()
            .enumerate()
            .map(|(i, p)| pack(p.to_array().map(f32::to_bits), i as u32))
            .collect();
        by_bits.sort_unstable();
        // Position ids: equal bits, equal id (an index out of range: u32::MAX, never an id).
        let mut id = vec![0u32; self.positions.len()];
        let mut next = 0u32;
        for (k, w) in by_bits.iter().enumerate() {
            if k > 0 && by_bits[k - 1] >> 32 != w >> 32 {
                next += 1;
            }
            id[*w as u32 as usize] = next;
        }
        let mut keyed: Vec<u128> = self
            .triangles
            .iter()
            .enumerate()
            .filter_map(|(i, t)| {
                let mut k = t.map(|v| id.get(v as usize).copied().unwrap_or(u32::MAX));
                k.sort_unstable();
                (k[0] != k[2]).then(|| pack(k, i as u32))
            })
            .collect();
        keyed.sort_unstable();
        keyed.dedup_by_key(|k| *k >> 32);
        let mut kept = vec![false; self.triangles.len()];
        for k in keyed {
            kept[k as u32 as usize] = true;
        }
        (0..self.triangles.len() as u32)
            .filter(|&t| kept[t as usize])
            .collect()
    }

    /// A stable 64-bit content hash (FNV-1a over the little-endian bytes), used to tie a bake
    /// file to the mesh it was baked from.
    pub fn content_hash(&self) -> u64 {
        let mut h = crate::hash::Fnv1a::default();
        for p in &self.positions {
            h.write_f32s(&p.to_array());
        }
        for n in &self.normals {
            h.write_f32s(&n.to_array());
        }
        for t in &self.triangles {
            for i in t {
                h.write(&i.to_le_bytes());
            }
        }
        h.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// [`Mesh::unique_triangles`] by its definition: the corners' bits sorted per triangle, the
    /// triangles sorted by them, the first (lowest index) of each equal run kept.
    fn unique_by_definition(mesh: &Mesh) -> Vec<u32> {
        let bits = |i: u32| {
            mesh.positions
                .get(i as usize)
                .map_or([u32::MAX; 3], |p| p.to_array().map(f32::to_bits))
        };
        let mut keyed: Vec<([[u32; 3]; 3], u32)> = mesh
            .triangles
            .iter()
            .enumerate()
            .filter_map(|(i, t)| {
                let mut k = t.map(bits);
                k.sort_unstable();
                (k[0] != k[2]).then_some((k, i as u32))
            })
            .collect();
        keyed.sort_unstable();
        keyed.dedup_by_key(|(k, _)| *k);
        let mut ids: Vec<u32> = keyed.into_iter().map(|(_, i)| i).collect();
        ids.sort_unstable();
        ids
    }

    proptest! {
        /// Meshes with repeated positions (a few distinct values, ±0 among them), doubled
        /// sheets, point triangles and any winding: the same triangles as the definition.
        #[test]
        fn unique_triangles_are_the_definitions(
            coords in prop::collection::vec(
                prop::sample::select(vec![0.0f32, -0.0, 1.0, 2.5, -3.0]), 6..60),
            corners in prop::collection::vec(0u32..20, 3..240),
        ) {
            let positions: Vec<Vec3> = coords
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2]))
                .collect();
            let n = positions.len() as u32;
            let triangles: Vec<[u32; 3]> = corners
                .chunks_exact(3)
                .map(|c| [c[0] % n, c[1] % n, c[2] % n])
                .collect();
            let mesh = Mesh { positions, triangles, ..Mesh::default() };
            prop_assert_eq!(mesh.unique_triangles(), unique_by_definition(&mesh));
        }
    }
}
