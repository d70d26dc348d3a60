//! The vertex records the shading passes read (`verts` of shade.wgsl, resolve.wgsl and
//! visibility.wgsl): four vec4 per vertex.

use bspvt_proto::Mesh;
use bspvt_proto::scene::Material;
use glam::{Vec2, Vec3};

use crate::normal_map::NormalMaps;

/// Per triangle: its three corners and its material (`tris` of visibility.wgsl and
/// resolve.wgsl).
pub fn triangles(mesh: &Mesh) -> Vec<[u32; 4]> {
    mesh.triangles
        .iter()
        .enumerate()
        .map(|(t, c)| {
            [
                c[0],
                c[1],
                c[2],
                mesh.material_ids.get(t).copied().unwrap_or(0),
            ]
        })
        .collect()
}

/// The material each vertex is shaded with per vertex: that of the first triangle that uses
/// it (material 0 where the mesh has no material ids; `u32::MAX` for a vertex no triangle
/// uses).
pub fn vertex_materials(mesh: &Mesh) -> Vec<u32> {
    let mut out = vec![u32::MAX; mesh.vertex_count()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for &v in tri {
            if let Some(m) = out.get_mut(v as usize)
                && *m == u32::MAX
            {
                *m = mesh.material_ids.get(t).copied().unwrap_or(0);
            }
        }
    }
    out
}

/// Position, (unit normal, u), (albedo, α), (F0, v): `material` is the one the vertex is
/// shaded with (a textured material already evaluated at its UV); the UV rides in the spare w
/// of the normal and F0 (0 without one) for the per-pixel pass's texture lookups.
pub fn vertex_record(p: Vec3, n: Vec3, m: &Material, uv: Option<Vec2>) -> [[f32; 4]; 4] {
    let uv = uv.unwrap_or(Vec2::ZERO);
    [
        p.extend(1.0).to_array(),
        n.extend(uv.x).to_array(),
        [m.albedo[0], m.albedo[1], m.albedo[2], m.roughness],
        [m.specular[0], m.specular[1], m.specular[2], uv.y],
    ]
}

/// `record`, whose normal is the one to shade with, for a vertex seen from behind or not
/// (the client's `Renderer::seen_from_behind`): behind, its normal is stored turned back to the
/// mesh's side (which resolve.wgsl interpolates per pixel) and its position's w is −1 (else
/// 1), and shade.wgsl turns the normal over again and shades the vertex unshadowed — its trees
/// are for its other side.
pub fn seen_from_behind(mut record: [[f32; 4]; 4], behind: bool) -> [[f32; 4]; 4] {
    record[0][3] = if behind { -1.0 } else { 1.0 };
    if behind {
        for x in &mut record[1][..3] {
            *x = -*x;
        }
    }
    record
}

/// The records of every vertex of a mesh at rest: the vertex's material (its first
/// triangle's, clamped to the list; textured ones evaluated at the vertex's UV) and its
/// normal — bent by its material's normal map at its UV where it has one, as seen from the
/// side the mesh normal faces (a viewer seeing a vertex from behind turns the frame over:
/// `Renderer::vertex_surface`, the browser's `Frames::vertexNormals`). No roughness override.
/// `maps`: the scene's [`NormalMaps::of`].
pub fn mesh_vertex_records(
    mesh: &Mesh,
    materials: &[Material],
    maps: Option<&NormalMaps>,
) -> Vec<[[f32; 4]; 4]> {
    let fallback = Material::default();
    let ids = vertex_materials(mesh);
    (0..mesh.vertex_count())
        .map(|v| {
            let id = ids[v] as usize;
            let m = materials
                .get(id.min(materials.len().saturating_sub(1)))
                .unwrap_or(&fallback);
            let uv = mesh.uvs.get(v).copied();
            let n = mesh.normals.get(v).copied().unwrap_or(Vec3::Y);
            let n = n.normalize_or(Vec3::Y);
            let n = maps.map_or(n, |maps| {
                maps.bend_vertex(mesh, v as u32, id as u32, n.as_dvec3())
                    .as_vec3()
            });
            vertex_record(mesh.positions[v], n, &m.at(uv), uv)
        })
        .collect()
}

/// The per-pixel pass's tangent frames: per vertex (unbent unit normal, 0) and (MikkTSpace
/// tangent, bitangent sign) where a material is normal-mapped (`maps`: the scene's
/// [`NormalMaps::of`]); empty (the pass then bends nothing) otherwise.
pub fn tangent_frames(mesh: &Mesh, maps: Option<&NormalMaps>) -> Vec<[f32; 4]> {
    let Some(maps) = maps else {
        return Vec::new();
    };
    mesh.normals
        .iter()
        .zip(maps.tangents())
        .flat_map(|(n, t)| [n.extend(0.0).to_array(), t.to_array()])
        .collect()
}
