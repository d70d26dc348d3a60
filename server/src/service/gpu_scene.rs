//! `GET /v1/scenes/{id}/gpu-scene`: a scene as the GPU shaders read it, for the browser viewer
//! (`/view/{id}`): the buffers of `bspvt_shaders::gpu` built here, once per scene, with the
//! same code the native client fills its wgpu buffers with, so the page only uploads them.
//!
//! Body: `"BVGS"`, u32 LE length L, L bytes of JSON (padded with spaces to a multiple of 4),
//! then the sections the JSON's `sections` lists as `[offset, bytes]` from the end of the JSON:
//! `verts` (4 × vec4f per vertex: position, (normal, u), (albedo, α), (F0, v)), `tris`
//! (vec4u per triangle: corners and material), `materials` (vec4f records),
//! `surface_textures` (u32 words), `cut` (u32 words), `ltc` (vec4f, two per table node),
//! `frames` (vec4f: a normal-mapped scene's unbent normal and tangent per vertex; one zero vec4
//! otherwise), `light_texture_K` (vec4f: textured lamp K's prefiltered pyramid,
//! `LightTexture::gpu_words`). The
//! JSON also carries the camera, the lights (each its kind, its shader record of
//! `bspvt_shaders::gpu::lights` and count; a lamp also its corners and region), the bounds,
//! and `not_shown`: what of the scene the browser's GPU path leaves out, one sentence each.

use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use bspvt_proto::Scene;
use bspvt_shaders::gpu::{lights, materials, records};
use bspvt_shaders::light_texture::LightTexture;
use bspvt_shaders::ltc_table::LtcTable;
use bspvt_shaders::normal_map::NormalMaps;
use serde_json::json;

use super::api::scene_derived;
use super::error::{ApiResult, ErrorBody};
use super::input;
use super::state::Shared;

/// The bundle's format version (the JSON's `version`).
const VERSION: u32 = 1;

/// The scene as the GPU shaders read it (see the module documentation).
#[utoipa::path(
    get,
    path = "/v1/scenes/{id}/gpu-scene",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    responses(
        (status = 200, description = "\"BVGS\", u32 JSON length, JSON (camera, lights, sections), then the GPU buffers (docs/service.md, \"Viewer\")", content_type = "application/vnd.bspvt-gpu-scene"),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "Unknown id", body = ErrorBody),
        (status = 410, description = "Deleted", body = ErrorBody),
    )
)]
pub(crate) async fn get_gpu_scene(
    State(st): State<Shared>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    // A scene never changes after submission; the bundle's version is part of its name.
    scene_derived(
        &st,
        &id,
        &headers,
        |hash| format!("\"gpu-scene-{id}-{hash:016x}-v{VERSION}\""),
        "application/vnd.bspvt-gpu-scene",
        |bytes| {
            let scene = input::decode_scene(&bytes).map_err(|e| anyhow::anyhow!(e))?;
            bundle(&scene)
        },
    )
    .await
}

/// Little-endian bytes of 32-bit words.
fn le<T: Copy>(words: &[T], to: impl Fn(T) -> [u8; 4]) -> Vec<u8> {
    words.iter().flat_map(|&w| to(w)).collect()
}

/// The bundle of `scene` (see the module documentation).
pub(crate) fn bundle(scene: &Scene) -> anyhow::Result<Vec<u8>> {
    let mesh = &scene.mesh;
    let uvs = mesh.uvs.len() == mesh.vertex_count();
    // MikkTSpace once: the bent vertex normals and the per-pixel tangent frames.
    let maps = NormalMaps::of(mesh, &scene.materials);
    let verts: Vec<f32> = records::mesh_vertex_records(mesh, &scene.materials, maps.as_deref())
        .iter()
        .flatten()
        .flatten()
        .copied()
        .collect();
    let tris: Vec<u32> = records::triangles(mesh).into_iter().flatten().collect();
    let (material_records, textures) = materials::tables(&scene.materials, uvs, true);
    let cut = bspvt_raytrace::Cutouts::of(mesh, &scene.materials)
        .map_or(vec![0u32], |c| c.gpu_words_by_triangle());
    // A normal-mapped scene's unbent normals and tangents (one zero vec4 otherwise: the
    // resolve pass then bends nothing).
    let mut frames = records::tangent_frames(mesh, maps.as_deref());
    if frames.is_empty() {
        frames.push([0.0; 4]);
    }
    let table = LtcTable::builtin();
    let ltc = table.gpu_nodes();
    // Each textured lamp's prefiltered pyramid, as the native client uploads it.
    let light_textures: Vec<Option<(String, Vec<u8>)>> = scene
        .lights
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let image = l.image.as_ref()?;
            let t = LightTexture::from_texels(
                image.width as usize,
                image.height as usize,
                &image.texels,
            )
            .ok()?;
            let words: Vec<f32> = t.gpu_words().into_iter().flatten().collect();
            Some((format!("light_texture_{k}"), le(&words, f32::to_le_bytes)))
        })
        .collect();
    let mut sections: Vec<(String, Vec<u8>)> = vec![
        ("verts", le(&verts, f32::to_le_bytes)),
        ("tris", le(&tris, u32::to_le_bytes)),
        (
            "materials",
            le(
                &material_records
                    .iter()
                    .flatten()
                    .copied()
                    .collect::<Vec<_>>(),
                f32::to_le_bytes,
            ),
        ),
        ("surface_textures", le(&textures, u32::to_le_bytes)),
        ("cut", le(&cut, u32::to_le_bytes)),
        (
            "frames",
            le(
                &frames.iter().flatten().copied().collect::<Vec<_>>(),
                f32::to_le_bytes,
            ),
        ),
        (
            "ltc",
            le(
                &ltc.iter().flatten().copied().collect::<Vec<_>>(),
                f32::to_le_bytes,
            ),
        ),
    ]
    .into_iter()
    .map(|(name, bytes)| (name.to_string(), bytes))
    .collect();
    sections.extend(light_textures.iter().flatten().cloned());
    let mut offset = 0usize;
    let mut table_of_sections = serde_json::Map::new();
    for (name, bytes) in &sections {
        table_of_sections.insert(name.clone(), json!([offset, bytes.len()]));
        offset += bytes.len();
    }
    let textures: Vec<Option<&str>> = light_textures
        .iter()
        .map(|t| t.as_ref().map(|(name, _)| name.as_str()))
        .collect();
    let lights = light_docs(scene, &textures);
    let bounds = mesh.bounds();
    let doc = json!({
        "version": VERSION,
        "vertices": mesh.vertex_count(),
        "triangles": mesh.triangles.len(),
        "materials": scene.materials.len(),
        "uvs": uvs,
        "bounds": {"min": bounds.min.to_array(), "max": bounds.max.to_array()},
        "camera": scene.camera,
        "lights": lights,
        "ltc_size": table.size(),
        "chunk_vertices": scene.bake.chunk_vertices,
        "not_shown": not_shown(scene),
        "sections": table_of_sections,
    });
    let mut text = serde_json::to_string(&doc)?;
    while !text.len().is_multiple_of(4) {
        text.push(' ');
    }
    let len = u32::try_from(text.len())?;
    let mut out = Vec::with_capacity(8 + text.len() + offset);
    out.extend_from_slice(b"BVGS");
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(text.as_bytes());
    for (_, bytes) in sections {
        out.extend_from_slice(&bytes);
    }
    Ok(out)
}

/// Every light the GPU path shades, each with its shader record
/// (`bspvt_shaders::gpu::lights`: 10 × 4 floats, and the vertex count the shaders take) and
/// whether the streamed trees shadow it: the polygon lamps (their corners and region: the page
/// drags them; a textured one the section of its texture, `textures[k]`), then the point and
/// spot lights' spheres, then the suns.
fn light_docs(scene: &Scene, textures: &[Option<&str>]) -> Vec<serde_json::Value> {
    let doc =
        |kind: &str, (record, count): (lights::LightRecord, u32), extra: serde_json::Value| {
            let mut d = json!({"kind": kind, "record": record, "count": count, "shadowed": true});
            if let (Some(d), serde_json::Value::Object(extra)) = (d.as_object_mut(), extra) {
                d.extend(extra);
            }
            d
        };
    let polygons = scene.lights.iter().enumerate().map(|(k, l)| {
        let radiance = glam::Vec3::from(l.radiance);
        let texture = textures.get(k).copied().flatten();
        doc(
            "polygon",
            lights::polygon(
                &l.points(),
                l.normal(),
                radiance,
                l.two_sided,
                texture.is_some(),
            ),
            json!({
                "texture": texture,
                "vertices": l.points().iter().map(|p| p.to_array()).collect::<Vec<_>>(),
                "region": l.region.as_ref().map(|r| json!({"min": r.min, "max": r.max})),
                "moves_in_plane": l.moves_in_plane,
            }),
        )
    });
    let spheres = scene.punctual.iter().map(|l| {
        doc(
            "sphere",
            lights::scene_sphere(l),
            json!({"name": l.name, "vertices": [l.position]}),
        )
    });
    // A sun beside lamps is shadowed by the sky's bake, which is not streamed: drawn unshadowed.
    let sun_shadowed = !scene.suns_in_sky_bake();
    let suns = scene.suns.iter().map(|l| {
        doc(
            "sun",
            lights::scene_sun(l),
            json!({"name": l.name, "vertices": [], "shadowed": sun_shadowed}),
        )
    });
    polygons.chain(spheres).chain(suns).collect()
}

/// What of `scene` the browser's GPU path does not draw, one sentence each.
fn not_shown(scene: &Scene) -> Vec<String> {
    let mut out = Vec::new();
    if scene.suns_in_sky_bake() {
        out.push(format!(
            "the shadows of {} sun(s): a sun lit beside lamps is shadowed by the sky's bake, \
             which the page does not stream (drawn unshadowed)",
            scene.suns.len()
        ));
    }
    if scene.lights.iter().any(|l| l.vertices.len() > 8) {
        out.push("lights of more than 8 vertices".into());
    }
    out
}
