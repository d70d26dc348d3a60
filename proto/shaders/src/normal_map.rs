//! Tangent-space normal maps (glTF 2.0 §3.9.3 `normalTexture`): the shading normal bent by a
//! material's [`NormalMap`] in the mesh's MikkTSpace tangent frame [Mikkelsen08].
//!
//! Tangents are generated per vertex by MikkTSpace from the positions, normals and UVs, as
//! the glTF specification asks of a client when an asset has none (and as Blender bakes and
//! exports them). glTF's image v grows downwards while a normal texel's +y points up the
//! image, so the generator is given (u, 1 − v): its bitangent is then the texel's +y.

use std::sync::Arc;

use bevy_mikktspace::{Geometry, TangentSpace};
use bspvt_proto::Mesh;
use bspvt_proto::scene::{Material, NormalMap};
use glam::{DVec3, Vec3, Vec4};

/// A scene's normal maps and the tangent frames they are read in.
#[derive(Debug)]
pub struct NormalMaps {
    /// Per vertex: the unit tangent (xyz) and the sign of the bitangent B = w · N × T.
    tangents: Vec<Vec4>,
    /// Per material: its normal map, if any.
    maps: Vec<Option<NormalMap>>,
}

impl NormalMaps {
    /// The normal maps of `materials` over `mesh`, or `None` when no material has one or the
    /// mesh has no UVs (nothing is bent: the cost on such scenes is nil).
    pub fn of(mesh: &Mesh, materials: &[Material]) -> Option<Arc<NormalMaps>> {
        if mesh.uvs.len() != mesh.positions.len()
            || mesh.normals.len() != mesh.positions.len()
            || !materials.iter().any(|m| m.normal_map.is_some())
        {
            return None;
        }
        Some(Arc::new(NormalMaps {
            tangents: mikktspace(mesh),
            maps: materials.iter().map(|m| m.normal_map.clone()).collect(),
        }))
    }

    /// The per-vertex tangents (xyz, bitangent sign in w), for the GPU.
    pub fn tangents(&self) -> &[Vec4] {
        &self.tangents
    }

    /// Material `id`'s normal map.
    pub fn map(&self, id: u32) -> Option<&NormalMap> {
        self.maps.get(id as usize)?.as_ref()
    }

    /// The shading normal at the point of triangle `tri` with barycentric `weights`, whose
    /// interpolated unit normal is `n`: the triangle's material's map read at the point's UV
    /// in the interpolated tangent frame; `n` itself where there is no map.
    /// `duv`: the pixel's texture footprint (the map mipmapped), `None` for a point.
    pub fn bend(
        &self,
        mesh: &Mesh,
        tri: u32,
        weights: [f64; 3],
        n: DVec3,
        duv: Option<[glam::Vec2; 2]>,
    ) -> DVec3 {
        let id = mesh.material_ids.get(tri as usize).copied().unwrap_or(0);
        let (Some(map), Some(idx), Some(uv)) = (
            self.map(id),
            mesh.triangles.get(tri as usize),
            mesh.uv_at(tri as usize, weights),
        ) else {
            return n;
        };
        let mut t = DVec3::ZERO;
        let mut sign = 0.0;
        for (k, &v) in idx.iter().enumerate() {
            let tv = self.tangents.get(v as usize).copied().unwrap_or(Vec4::X);
            t += weights[k] * tv.truncate().as_dvec3();
            sign += weights[k] * f64::from(tv.w);
        }
        bend(
            n,
            t,
            if sign < 0.0 { -1.0 } else { 1.0 },
            map.at_footprint(uv, duv),
        )
    }

    /// `bent`, the bent normal of a surface whose unbent normal `n` faces the viewer along
    /// unit `wo`, brought back to just this side of the silhouette where the map's slope is
    /// steeper than the view is grazing: n′ ← normalize(n′ + (ε − n′·ω_o) ω_o), as real-time
    /// engines do, rather than a black pixel.
    pub fn facing(bent: DVec3, n: DVec3, wo: DVec3) -> DVec3 {
        /// n′·ω_o a bent normal keeps at least.
        const SILHOUETTE: f64 = 0.02;
        let d = bent.dot(wo);
        if d < SILHOUETTE && n.dot(wo) > SILHOUETTE {
            (bent + (SILHOUETTE - d) * wo).normalize_or(n)
        } else {
            bent
        }
    }

    /// The shading normal at vertex `v` (of material `id`, unit normal `n`): its map read at
    /// the vertex's UV, as per-vertex frames read a texture.
    pub fn bend_vertex(&self, mesh: &Mesh, v: u32, id: u32, n: DVec3) -> DVec3 {
        let (Some(map), Some(uv), Some(t)) = (
            self.map(id),
            mesh.uvs.get(v as usize),
            self.tangents.get(v as usize),
        ) else {
            return n;
        };
        let sign = if t.w < 0.0 { -1.0 } else { 1.0 };
        bend(n, t.truncate().as_dvec3(), sign, map.at(*uv))
    }
}

/// n′ = normalize(x·T + y·B + z·N), (x, y, z) the tangent-space normal `m`, T the tangent made
/// orthogonal to the unit normal `n` (Gram–Schmidt), B = sign · N × T (glTF 2.0 §3.7.2.1,
/// `TANGENT`). `n` where T is degenerate (parallel to N, zero or not finite) or the result is.
pub fn bend(n: DVec3, t: DVec3, sign: f64, m: Vec3) -> DVec3 {
    let t = t - n * n.dot(t);
    let Some(t) = t.try_normalize() else {
        return n;
    };
    let b = sign * n.cross(t);
    let m = m.as_dvec3();
    (m.x * t + m.y * b + m.z * n).try_normalize().unwrap_or(n)
}

/// Per-vertex MikkTSpace tangents of `mesh` (which has UVs), computed with (u, 1 − v); a
/// vertex the generator leaves without one (degenerate triangles only) gets +x, and a vertex
/// shared by triangles of opposite UV orientation keeps the last triangle's.
fn mikktspace(mesh: &Mesh) -> Vec<Vec4> {
    struct Frames<'a> {
        mesh: &'a Mesh,
        out: Vec<Vec4>,
    }
    fn finite(v: [f32; 3]) -> [f32; 3] {
        v.map(|x| if x.is_finite() { x } else { 0.0 })
    }
    impl Frames<'_> {
        fn vertex(&self, face: usize, vert: usize) -> usize {
            self.mesh.triangles[face][vert] as usize
        }
    }
    impl Geometry for Frames<'_> {
        fn num_faces(&self) -> usize {
            self.mesh.triangles.len()
        }
        fn num_vertices_of_face(&self, _face: usize) -> usize {
            3
        }
        fn position(&self, face: usize, vert: usize) -> [f32; 3] {
            finite(self.mesh.positions[self.vertex(face, vert)].to_array())
        }
        fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
            finite(self.mesh.normals[self.vertex(face, vert)].to_array())
        }
        fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
            let uv = self.mesh.uvs[self.vertex(face, vert)];
            let f = |x: f32| if x.is_finite() { x } else { 0.0 };
            [f(uv.x), f(1.0 - uv.y)]
        }
        fn set_tangent(&mut self, ts: Option<TangentSpace>, face: usize, vert: usize) {
            let Some(ts) = ts else {
                return;
            };
            let v = self.vertex(face, vert);
            let t = Vec4::from_array(ts.tangent_encoded());
            if t.is_finite() {
                self.out[v] = t;
            }
        }
    }
    let mut frames = Frames {
        mesh,
        out: vec![Vec4::X; mesh.positions.len()],
    };
    // An error means no face could be processed; every vertex keeps +x then.
    let _ = bevy_mikktspace::generate_tangents(&mut frames);
    frames.out
}

#[cfg(test)]
mod tests {
    use super::*;
    use bspvt_proto::texture::{Texture, TextureRef, Wrap};
    use glam::Vec2;

    /// A unit quad in the xz plane facing +y, u along +x and v along +z (so the image's up,
    /// decreasing v, is −z).
    fn quad() -> Mesh {
        Mesh {
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(0.0, 0.0, 1.0),
            ],
            normals: vec![Vec3::Y; 4],
            triangles: vec![[0, 2, 1], [0, 3, 2]],
            material_ids: vec![0, 0],
            uvs: vec![
                Vec2::new(0.0, 0.0),
                Vec2::new(1.0, 0.0),
                Vec2::new(1.0, 1.0),
                Vec2::new(0.0, 1.0),
            ],
        }
    }

    /// A material whose one-texel normal map is `rgb` (8-bit).
    fn mapped(rgb: [u8; 3], scale: f32) -> Material {
        let texture = Arc::new(Texture {
            name: "normal".into(),
            width: 1,
            height: 1,
            rgba: vec![rgb[0], rgb[1], rgb[2], 255],
            source: Vec::new(),
            mips: Default::default(),
        });
        Material {
            normal_map: Some(NormalMap {
                texture: TextureRef {
                    texture,
                    wrap: [Wrap::Repeat; 2],
                    transform: None,
                },
                scale,
            }),
            ..Material::default()
        }
    }

    #[test]
    fn mikktspace_tangent_follows_u_and_the_bitangent_points_up_the_image() {
        let mesh = quad();
        let t = mikktspace(&mesh);
        for tv in &t {
            assert!(
                (tv.truncate() - Vec3::X).length() < 1e-5,
                "T = +x (u): {tv}"
            );
        }
        // B = w · N × T = w · (y × x) = −w z must be −z (up the image, decreasing v): w = +1.
        assert!(t.iter().all(|tv| tv.w == 1.0), "{t:?}");
    }

    #[test]
    fn a_texel_leaning_right_and_up_bends_toward_plus_u_and_minus_v() {
        let mesh = quad();
        // (x, y, z) = (0.6, 0, 0.8) and (0, 0.6, 0.8), encoded as (n + 1) / 2.
        let enc = |x: f32| (((x + 1.0) * 0.5) * 255.0).round() as u8;
        let right =
            NormalMaps::of(&mesh, &[mapped([enc(0.6), enc(0.0), enc(0.8)], 1.0)]).expect("mapped");
        let up =
            NormalMaps::of(&mesh, &[mapped([enc(0.0), enc(0.6), enc(0.8)], 1.0)]).expect("mapped");
        let w = [1.0 / 3.0; 3];
        let n = right.bend(&mesh, 0, w, DVec3::Y, None);
        assert!(n.x > 0.55 && n.y > 0.75 && n.z.abs() < 0.02, "{n}");
        let n = up.bend(&mesh, 1, w, DVec3::Y, None);
        assert!(n.z < -0.55 && n.y > 0.75 && n.x.abs() < 0.02, "{n}");
        // The vertex path reads the same frame.
        let nv = up.bend_vertex(&mesh, 2, 0, DVec3::Y);
        assert!((nv - n).length() < 1e-6, "{nv} vs {n}");
    }

    #[test]
    fn flat_texels_and_zero_scale_leave_the_normal() {
        let mesh = quad();
        let flat = NormalMaps::of(&mesh, &[mapped([128, 128, 255], 1.0)]).expect("mapped");
        let n = flat.bend(&mesh, 0, [0.2, 0.3, 0.5], DVec3::Y, None);
        assert!((n - DVec3::Y).length() < 0.01, "{n}");
        let tilted = NormalMaps::of(&mesh, &[mapped([255, 128, 128], 0.0)]).expect("mapped");
        let n = tilted.bend(&mesh, 0, [0.2, 0.3, 0.5], DVec3::Y, None);
        assert!((n - DVec3::Y).length() < 0.01, "scale 0 bends nothing: {n}");
    }

    #[test]
    fn degenerate_input_never_gives_nan() {
        let n = DVec3::Y;
        for (t, m) in [
            (DVec3::Y, Vec3::X),
            (DVec3::ZERO, Vec3::X),
            (DVec3::NAN, Vec3::X),
            (DVec3::X, Vec3::ZERO),
            (DVec3::X, Vec3::NAN),
            (DVec3::X, Vec3::new(0.0, 0.0, -1.0)),
        ] {
            let b = bend(n, t, 1.0, m);
            assert!(
                b.is_finite() && (b.length() - 1.0).abs() < 1e-9,
                "{t} {m}: {b}"
            );
        }
        // A mesh of degenerate triangles and NaN UVs.
        let mut mesh = quad();
        mesh.positions = vec![Vec3::ZERO; 4];
        mesh.uvs[1] = Vec2::NAN;
        let t = mikktspace(&mesh);
        assert!(t.iter().all(|v| v.is_finite()), "{t:?}");
        let nm = NormalMaps::of(&mesh, &[mapped([255, 0, 128], 2.0)]).expect("mapped");
        let b = nm.bend(&mesh, 0, [0.5, 0.25, 0.25], DVec3::Y, None);
        assert!(b.is_finite(), "{b}");
    }

    #[test]
    fn scenes_without_normal_maps_build_nothing() {
        let mesh = quad();
        assert!(NormalMaps::of(&mesh, &[Material::default()]).is_none());
        let mut bare = quad();
        bare.uvs.clear();
        assert!(NormalMaps::of(&bare, &[mapped([128, 128, 255], 1.0)]).is_none());
    }
}
