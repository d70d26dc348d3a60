//! Turning an upload (a mesh file, an optional scene JSON, optional bake settings) into the
//! [`Scene`] the service bakes, and storing that scene.
//!
//! Guarantees:
//! - the mesh is parsed from memory by `bspvt_proto::import` under the service's [`Limits`]
//!   (no panic, no allocation from an unchecked count); the files it refers to (an OBJ's
//!   material libraries and textures, a glTF's external buffers and images) are read only from
//!   the `file` fields uploaded with it, never from this machine's disk; a `.zst`
//!   mesh is decompressed to at most `max_mesh_bytes` with a bounded zstd window, so a
//!   decompression bomb is refused after reading at most that many bytes;
//! - a scene JSON may only name `builtin:` meshes and the uploaded file: a mesh path names the
//!   upload when its last component is the upload's file name (so the project's scene files,
//!   whose paths are relative to where they lie, are submitted as they are); the server never
//!   reads a path of the scene's choosing;
//! - the scene is composed exactly as [`Scene::from_file`] composes a scene file on disk
//!   (tested below), so the service bakes what the offline `bspvt-server bake` bakes;
//! - the stored form ([`encode_scene`]) round-trips every bit (postcard, no JSON floats).

use std::collections::BTreeMap;
use std::io::Read;

use bspvt_proto::import::{Asset, Format, Limits, parse_asset_uploaded};
use bspvt_proto::scene::SceneFile;
use bspvt_proto::texture::{LightImage, image_dimensions};
use bspvt_proto::{BakeSettings, Scene, SceneError};

use super::error::{ApiError, ApiResult};
use super::memory::{Reservation, parse_bytes};

/// What a submission may contain.
pub(crate) struct Upload {
    /// The `mesh` field: its file name and bytes as received.
    pub mesh: Option<(String, Vec<u8>)>,
    /// The `file` fields: the mesh's other files, by their
    /// [`bspvt_proto::import::sidecar_name`].
    pub files: BTreeMap<String, Vec<u8>>,
    /// The `scene` field (scene JSON).
    pub scene: Option<String>,
    /// The `settings` field (bake settings JSON, replaces the scene's `bake`).
    pub settings: Option<String>,
}

/// Limits applied while preparing a scene.
#[derive(Clone, Copy, Debug)]
pub(crate) struct InputLimits {
    pub mesh: Limits,
    pub max_face_res: u32,
    pub max_supersampling: u32,
}

/// A scene ready to be stored and baked.
pub(crate) struct Prepared {
    pub scene: Scene,
    /// How it was submitted, in words (for the status document).
    pub source: String,
    /// Bytes uploaded (mesh as received + scene + settings).
    pub upload_bytes: u64,
}

/// Longest zstd window accepted for a compressed mesh (2^24 = 16 MiB of decoder memory).
const ZSTD_WINDOW_LOG_MAX: u32 = 24;

/// A fingerprint of what was submitted (every field's name, file name and bytes): two requests
/// with the same `Idempotency-Key` are the same submission when their fingerprints are equal.
/// FNV-1a 64 and CRC-32 over length-prefixed fields, plus the length (96 bits: retries of one
/// client are told apart from its other requests, not an adversary's collisions).
pub(crate) fn fingerprint(up: &Upload) -> String {
    let mut fnv = bspvt_proto::hash::Fnv1a::default();
    let mut crc = crc32fast::Hasher::new();
    let mut total = 0u64;
    let mut put = |b: &[u8]| {
        let len = (b.len() as u64).to_le_bytes();
        for part in [&len[..], b] {
            fnv.write(part);
            crc.update(part);
        }
        total += b.len() as u64;
    };
    match &up.mesh {
        Some((name, bytes)) => {
            put(b"mesh");
            put(name.as_bytes());
            put(bytes);
        }
        None => put(b"no mesh"),
    }
    for (name, bytes) in &up.files {
        put(b"file");
        put(name.as_bytes());
        put(bytes);
    }
    for (field, v) in [("scene", &up.scene), ("settings", &up.settings)] {
        put(field.as_bytes());
        match v {
            Some(t) => put(t.as_bytes()),
            None => put(b"absent"),
        }
    }
    format!(
        "fnv1a64:{:016x}/crc32:{:08x}/bytes:{total}",
        fnv.finish(),
        crc.finalize()
    )
}

/// The last component of a path as a scene file or a client writes it (`/` or `\\`).
fn file_name(path: &str) -> &str {
    path.rsplit(['/', '\\']).next().unwrap_or_default()
}

/// Builds the scene of an upload, applying every limit; `mem` (holding the body's bytes)
/// grows to the decompressed file and the parse's estimated working set before they are
/// allocated.
pub(crate) fn prepare(up: Upload, lim: &InputLimits, mem: &mut Reservation) -> ApiResult<Prepared> {
    let upload_bytes = up.mesh.as_ref().map_or(0, |m| m.1.len() as u64)
        + up.files.values().map(|f| f.len() as u64).sum::<u64>()
        + up.scene.as_ref().map_or(0, |s| s.len() as u64)
        + up.settings.as_ref().map_or(0, |s| s.len() as u64);
    let mesh = match up.mesh {
        Some((name, bytes)) => Some(load_upload(&name, bytes, &up.files, &lim.mesh, mem)?),
        None => None,
    };
    // The uploaded files something reads: the mesh's, and the scene's light textures.
    let mut used: Vec<String> = mesh.as_ref().map_or(Vec::new(), |m| m.1.files.clone());
    let (mut scene, mut source) = match (up.scene, mesh) {
        (Some(json), mesh) => {
            let file: SceneFile = serde_json::from_str(&json).map_err(SceneError::from)?;
            used.extend(
                file.lights
                    .iter()
                    .filter_map(|l| l.texture.as_deref())
                    .map(|t| file_name(t).to_string()),
            );
            let source = match &mesh {
                Some((name, m)) => format!(
                    "scene JSON with mesh {name} ({} vertices)",
                    m.mesh.vertex_count()
                ),
                None => "scene JSON".to_string(),
            };
            (compose(file, mesh.as_ref(), &up.files, mem)?, source)
        }
        (None, Some((name, m))) => {
            let source = format!(
                "mesh {name} ({} vertices), {}",
                m.mesh.vertex_count(),
                if m.lights.is_empty() {
                    "default scene"
                } else {
                    "with its own lamps"
                }
            );
            (Scene::from_asset(m)?, source)
        }
        (None, None) => {
            return Err(ApiError::bad_request(
                "missing_field",
                "the form has neither a `mesh` file nor a `scene` field",
            ));
        }
    };
    for unused in up.files.keys().filter(|f| !used.contains(f)) {
        scene.warnings.push(format!(
            "the uploaded file {unused:?} was not used: neither the mesh nor a light refers to it"
        ));
    }
    if let Some(json) = up.settings {
        scene.bake = serde_json::from_str::<BakeSettings>(&json).map_err(|e| {
            ApiError::unprocessable("invalid_settings", format!("`settings` field: {e}"))
        })?;
        source.push_str(", settings overridden");
        scene.validate()?;
    }
    // Refinement where shadows cross large triangles (bounded by the scene's vertex budget);
    // the stored scene carries the refined mesh, so every client renders what was baked.
    if let Some(stats) = bspvt_bake::refine::refine_scene(&mut scene)
        .map_err(|e| ApiError::unprocessable("invalid_settings", e.to_string()))?
    {
        source.push_str(&format!(
            ", refined from {} to {} vertices",
            stats.vertices_before, stats.vertices_after
        ));
    }
    check_limits(&scene, lim)?;
    Ok(Prepared {
        scene,
        source,
        upload_bytes,
    })
}

/// Decompresses (`.zst`) and parses an uploaded mesh; returns its file name (without `.zst`)
/// and the mesh.
fn load_upload(
    name: &str,
    bytes: Vec<u8>,
    files: &BTreeMap<String, Vec<u8>>,
    lim: &Limits,
    mem: &mut Reservation,
) -> ApiResult<(String, Asset)> {
    // Only the last path component of a client-supplied file name means anything.
    let name = file_name(name).to_string();
    if name.is_empty() {
        return Err(ApiError::bad_request(
            "missing_file_name",
            "the `mesh` field needs a file name with an extension (.glb, .gltf, .obj, .ply, optionally + .zst)",
        ));
    }
    let lower = name.to_ascii_lowercase();
    let (inner, bytes) = match lower.strip_suffix(".zst") {
        Some(_) => {
            let inner = name[..name.len() - 4].to_string();
            (inner, decompress(&bytes, lim.max_bytes, mem)?)
        }
        None => (name.clone(), bytes),
    };
    let format = Format::from_name(&inner)?;
    // The mesh's uploaded images (textures) decode to far more than their compressed bytes:
    // 8 B per texel their headers declare (the decoder's RGB buffer and the RGBA8 texels),
    // at most the texels an asset may hold in all.
    let texels: u64 = files
        .values()
        .filter_map(|b| image_dimensions(b).ok())
        .map(|(w, h)| u64::from(w) * u64::from(h))
        .sum::<u64>()
        .min(bspvt_proto::texture::MAX_ASSET_TEXELS);
    mem.grow_to(mem.bytes() + parse_bytes(bytes.len() as u64) + 8 * texels)
        .map_err(|r| ApiError::memory("parsing this mesh", r))?;
    // The check for repeated triangles runs on the scene's mesh, beside its storing (`accept`).
    let asset = parse_asset_uploaded(&bytes, format, lim, files)?;
    Ok((inner, asset))
}

/// Bytes of decompressed output reserved at a time.
const DECOMPRESS_STEP: u64 = 8 << 20;

/// zstd decompression that stops at `max` bytes of output, reserving the output from `mem`
/// a step ahead of writing it.
fn decompress(data: &[u8], max: u64, mem: &mut Reservation) -> ApiResult<Vec<u8>> {
    let bad = |e: std::io::Error| {
        ApiError::unprocessable("invalid_compression", format!("bad zstd data: {e}"))
    };
    let mut dec = zstd::stream::read::Decoder::new(data).map_err(bad)?;
    dec.window_log_max(ZSTD_WINDOW_LOG_MAX).map_err(bad)?;
    let base = mem.bytes();
    let mut out = Vec::new();
    let mut dec = dec.take(max + 1);
    loop {
        // Room for the next step and for the Vec's doubling on growth.
        let next = (out.len() as u64 + DECOMPRESS_STEP).min(max + 1);
        mem.grow_to(base + 2 * next)
            .map_err(|r| ApiError::memory("decompressing this mesh", r))?;
        let before = out.len();
        (&mut dec)
            .take(next - before as u64)
            .read_to_end(&mut out)
            .map_err(bad)?;
        if out.len() == before || out.len() as u64 > max {
            break;
        }
    }
    if out.len() as u64 > max {
        return Err(ApiError::too_large(
            "mesh_too_large",
            format!("the decompressed mesh is larger than the limit of {max} bytes"),
        ));
    }
    Ok(out)
}

/// [`Scene::from_file`] for an upload: `builtin:` meshes and the uploaded mesh only, light
/// textures from the uploaded files (by the last component of their path, as meshes).
fn compose(
    mut file: SceneFile,
    upload: Option<&(String, Asset)>,
    files: &BTreeMap<String, Vec<u8>>,
    mem: &mut Reservation,
) -> ApiResult<Scene> {
    // Light textures are decoded to f32 texels that the stored scene keeps: their memory is
    // set aside first, from the sizes their headers declare (what cannot be read is refused
    // by the decode below, with the light named).
    for l in file.lights.iter().filter(|l| l.image.is_none()) {
        let Some(bytes) = l.texture.as_deref().and_then(|t| files.get(file_name(t))) else {
            continue;
        };
        if let Ok((w, h)) = image_dimensions(bytes)
            && u64::from(w) * u64::from(h) <= bspvt_proto::texture::MAX_TEXTURE_TEXELS
        {
            mem.grow_to(mem.bytes() + LightImage::decode_bytes(w, h))
                .map_err(|r| ApiError::memory("decoding this scene's light textures", r))?;
        }
    }
    file.load_light_textures(|path| {
        let name = file_name(path);
        files.get(name).map(|b| b.as_slice().into()).ok_or_else(|| {
            format!(
                "it was not uploaded (send it as a `file` field named {:?})",
                super::error::truncate(name, 200)
            )
        })
    })?;
    let mut parts = Vec::with_capacity(file.meshes.len());
    // The scene path that named the upload first.
    let mut named: Option<String> = None;
    for m in &file.meshes {
        if let Some(name) = m.path.strip_prefix("builtin:") {
            let part = bspvt_proto::builtin::mesh(name).ok_or_else(|| {
                ApiError::unprocessable(
                    "invalid_scene",
                    format!(
                        "unknown built-in mesh {name:?} (known: {})",
                        bspvt_proto::builtin::mesh_names().join(", ")
                    ),
                )
            })?;
            parts.push(Asset {
                mesh: part,
                ..Asset::default()
            });
        } else {
            // The file the path names, as `Scene::load` would read it (`.zst` or not).
            let wanted = file_name(&m.path);
            let plain = wanted
                .strip_suffix(".zst")
                .or_else(|| wanted.strip_suffix(".ZST"))
                .unwrap_or(wanted);
            match upload {
                Some((uploaded, part)) if *uploaded == plain => {
                    if let Some(other) = named.replace(m.path.clone())
                        && other != m.path
                    {
                        return Err(ApiError::unprocessable(
                            "invalid_scene",
                            format!(
                                "the scene names {:?} and {:?}: both end in the uploaded file's name {uploaded:?}, so which file each means is ambiguous",
                                super::error::truncate(&other, 200),
                                super::error::truncate(&m.path, 200)
                            ),
                        ));
                    }
                    parts.push(part.clone())
                }
                Some((uploaded, _)) => {
                    return Err(ApiError::unprocessable(
                        "invalid_scene",
                        format!(
                            "the scene names mesh {:?}, but the uploaded mesh is {uploaded:?}: upload that file under its name {:?} (a scene may name only `builtin:` meshes and the uploaded file, matched by file name)",
                            super::error::truncate(&m.path, 200),
                            super::error::truncate(wanted, 200)
                        ),
                    ));
                }
                None => {
                    return Err(ApiError::bad_request(
                        "missing_field",
                        format!(
                            "the scene names mesh {:?}, but no `mesh` file was uploaded (upload it as a `mesh` file named {:?})",
                            super::error::truncate(&m.path, 200),
                            super::error::truncate(wanted, 200)
                        ),
                    ));
                }
            }
        }
    }
    Ok(Scene::assemble(file, parts)?)
}

/// The service's own caps on top of [`Scene::validate`].
fn check_limits(scene: &Scene, lim: &InputLimits) -> ApiResult<()> {
    let too_large = |what: &str, n: u64, limit: u64| {
        Err(ApiError::too_large(
            "scene_too_large",
            format!("the scene has {n} {what}; this server accepts at most {limit}"),
        ))
    };
    let v = scene.mesh.vertex_count() as u64;
    if v > lim.mesh.max_vertices {
        return too_large("vertices", v, lim.mesh.max_vertices);
    }
    let t = scene.mesh.triangles.len() as u64;
    if t > lim.mesh.max_triangles {
        return too_large("triangles", t, lim.mesh.max_triangles);
    }
    let b = &scene.bake;
    if b.face_res > lim.max_face_res {
        return Err(ApiError::unprocessable(
            "invalid_settings",
            format!(
                "bake.face_res = {} is above this server's limit of {}",
                b.face_res, lim.max_face_res
            ),
        ));
    }
    if b.supersampling > lim.max_supersampling {
        return Err(ApiError::unprocessable(
            "invalid_settings",
            format!(
                "bake.supersampling = {} is above this server's limit of {}",
                b.supersampling, lim.max_supersampling
            ),
        ));
    }
    Ok(())
}

pub(crate) use bspvt_proto::api::{decode_scene, encode_scene};

#[cfg(test)]
mod tests {
    use super::*;

    /// A reservation that always grows (its budget is gone): these tests are not about memory.
    fn unbounded() -> crate::service::memory::Reservation {
        crate::service::memory::MemoryBudget::new(u64::MAX)
            .try_reserve(0)
            .expect("an empty reservation")
    }

    fn limits() -> InputLimits {
        InputLimits {
            mesh: Limits::default(),
            max_face_res: 512,
            max_supersampling: 8,
        }
    }

    const OBJ: &str = "v 0 0 0\nv 1 0 0\nv 0 0 1\nv 1 0.5 1\nf 1 3 2\nf 2 3 4\n";

    /// An uploaded mesh + scene JSON gives exactly the scene `Scene::load` reads from disk.
    #[test]
    fn upload_composes_like_a_scene_file_on_disk() {
        let dir = tempfile::tempdir().expect("temp dir");
        let json = r#"{
            "meshes": [{"path": "tri.obj"}, {"path": "builtin:plate-small", "material": 1},
                       {"path": "tri.obj", "material": 1}],
            "ground_plane": true, "ground_material": 1,
            "materials": [{"name": "a"}, {"name": "b", "roughness": 0.5}, {}, {}],
            "lights": [{"vertices": [[-1,3,-1],[1,3,-1],[1,3,1],[-1,3,1]],
                        "radiance": [1,1,1], "region": {"min": [-2,2,-2], "max": [2,4,2]}}],
            "bake": {"face_res": 16, "chunk_vertices": 100}
        }"#;
        std::fs::write(dir.path().join("tri.obj"), OBJ).expect("write obj");
        std::fs::write(dir.path().join("s.json"), json).expect("write scene");
        let disk = Scene::load(&dir.path().join("s.json")).expect("scene from disk");
        let up = prepare(
            Upload {
                mesh: Some(("some/dir/tri.obj".into(), OBJ.as_bytes().to_vec())),
                files: BTreeMap::new(),
                scene: Some(json.into()),
                settings: None,
            },
            &limits(),
            &mut unbounded(),
        )
        .unwrap_or_else(|e| panic!("prepare: {e:?}"));
        assert_eq!(up.scene, disk);
        assert_eq!(decode_scene(&encode_scene(&up.scene)), Ok(disk));
    }

    /// A moving scene keeps its motion through storage; a version-1 scene still reads, and a
    /// stored part that does not fit the mesh is refused.
    #[test]
    fn moving_scenes_survive_storage() {
        let s = bspvt_proto::builtin::scene("dynamic").expect("builtin");
        assert!(s.is_dynamic());
        // Uploaded as a scene file, it composes to the same moving scene.
        let up = prepare(
            Upload {
                mesh: None,
                files: BTreeMap::new(),
                scene: Some(bspvt_proto::builtin::DYNAMIC_JSON.into()),
                settings: None,
            },
            &limits(),
            &mut unbounded(),
        )
        .unwrap_or_else(|e| panic!("prepare: {e:?}"));
        assert_eq!(up.scene, s);
        let back = decode_scene(&encode_scene(&s)).expect("decodes");
        assert_eq!(back, s);
        assert_eq!(back.at(0.3), s.at(0.3));
        let mut broken = s.clone();
        broken.motion[0].first_vertex = u32::MAX - 10;
        let e = decode_scene(&encode_scene(&broken)).expect_err("refused");
        assert!(e.contains("moving part 0"), "{e}");
    }

    #[test]
    fn builtin_scene_survives_storage_and_bare_meshes_get_the_default_scene() {
        let s = bspvt_proto::builtin::scene("plate-small").expect("builtin");
        assert_eq!(decode_scene(&encode_scene(&s)).as_ref(), Ok(&s));
        let z = zstd::bulk::compress(OBJ.as_bytes(), 3).expect("compress");
        let up = prepare(
            Upload {
                mesh: Some(("tri.OBJ.zst".into(), z)),
                files: BTreeMap::new(),
                scene: None,
                settings: Some(r#"{"face_res": 8}"#.into()),
            },
            &limits(),
            &mut unbounded(),
        )
        .unwrap_or_else(|e| panic!("prepare: {e:?}"));
        let mut expect = Scene::from_mesh(
            bspvt_proto::import::load_mesh_bytes(OBJ.as_bytes(), Format::Obj, &Limits::default())
                .expect("mesh"),
        )
        .expect("scene");
        expect.bake.face_res = 8;
        assert_eq!(up.scene, expect);
    }

    /// A path names the upload by its last component (the project's scene files name meshes
    /// relative to themselves); two different paths ending in the same name are ambiguous.
    #[test]
    fn scene_paths_name_the_upload_by_file_name() {
        let up = |meshes: &str| {
            prepare(
                Upload {
                    mesh: Some(("tri.obj".into(), OBJ.as_bytes().to_vec())),
                    files: BTreeMap::new(),
                    scene: Some(format!(
                        r#"{{"meshes": {meshes}, "lights": [{{"vertices": [[-1,3,-1],[1,3,-1],[1,3,1],[-1,3,1]],
                            "radiance": [1,1,1], "region": {{"min": [-2,2,-2], "max": [2,4,2]}}}}]}}"#
                    )),
                    settings: None,
                },
                &limits(),
                &mut unbounded(),
            )
        };
        let ok = up(r#"[{"path": "../../meshes/tri.obj"}, {"path": "../../meshes/tri.obj"}]"#)
            .unwrap_or_else(|e| panic!("prepare: {e:?}"));
        assert_eq!(ok.scene.mesh.vertex_count(), 8, "two copies of the upload");
        let zst = up(r#"[{"path": "meshes/tri.obj.zst"}]"#).unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(zst.scene.mesh.vertex_count(), 4);
        let e = up(r#"[{"path": "a/tri.obj"}, {"path": "b/tri.obj"}]"#)
            .err()
            .expect("ambiguous paths accepted");
        assert_eq!(e.code, "invalid_scene");
        assert!(e.detail.contains("ambiguous"), "{}", e.detail);
        let e = up(r#"[{"path": "../meshes/other.obj"}]"#)
            .err()
            .expect("another file accepted");
        assert!(e.detail.contains("\"other.obj\""), "{}", e.detail);
        assert_eq!(
            fingerprint(&Upload {
                mesh: None,
                files: BTreeMap::new(),
                scene: Some("a".into()),
                settings: None,
            }),
            fingerprint(&Upload {
                mesh: None,
                files: BTreeMap::new(),
                scene: Some("a".into()),
                settings: None,
            })
        );
        // A mesh's other files are part of the submission.
        let with = |name: &str| Upload {
            mesh: None,
            files: BTreeMap::from([(name.to_string(), b"x".to_vec())]),
            scene: Some("a".into()),
            settings: None,
        };
        assert_ne!(fingerprint(&with("a.mtl")), fingerprint(&with("b.mtl")));
        assert_ne!(
            fingerprint(&with("a.mtl")),
            fingerprint(&Upload {
                mesh: None,
                files: BTreeMap::new(),
                scene: Some("a".into()),
                settings: None,
            })
        );
        assert_ne!(
            fingerprint(&Upload {
                mesh: None,
                files: BTreeMap::new(),
                scene: Some("ab".into()),
                settings: None,
            }),
            fingerprint(&Upload {
                mesh: None,
                files: BTreeMap::new(),
                scene: Some("a".into()),
                settings: Some("b".into()),
            })
        );
    }

    #[test]
    fn scenes_cannot_name_server_paths_and_bombs_stop_at_the_limit() {
        let err = prepare(
            Upload {
                mesh: None,
                files: BTreeMap::new(),
                scene: Some(r#"{"meshes": [{"path": "/etc/passwd.obj"}], "lights": []}"#.into()),
                settings: None,
            },
            &limits(),
            &mut unbounded(),
        )
        .err()
        .expect("refused");
        assert_eq!(err.code, "missing_field");
        let bomb = zstd::bulk::compress(&vec![b' '; 1 << 20], 3).expect("compress");
        let lim = InputLimits {
            mesh: Limits {
                max_bytes: 1000,
                ..Limits::default()
            },
            ..limits()
        };
        let err = prepare(
            Upload {
                mesh: Some(("x.obj.zst".into(), bomb)),
                files: BTreeMap::new(),
                scene: None,
                settings: None,
            },
            &lim,
            &mut unbounded(),
        )
        .err()
        .expect("refused");
        assert_eq!(err.status, axum::http::StatusCode::PAYLOAD_TOO_LARGE);
    }

    /// A light texture is decoded on the service (the stored scene carries its texels): its
    /// memory is set aside from its header's size first, so a budget too small for it refuses
    /// the scene instead of being exceeded.
    #[test]
    fn light_textures_reserve_their_memory() {
        // A flat (not run-length encoded) 128² Radiance HDR file, every texel (0.5, 0.5, 0.5).
        let mut hdr = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 128 +X 128\n".to_vec();
        for _ in 0..128 * 128 {
            hdr.extend_from_slice(&[128, 128, 128, 128]);
        }
        let mut json: serde_json::Value =
            serde_json::from_str(bspvt_proto::builtin::DYNAMIC_JSON).expect("json");
        json["lights"][0]["texture"] = "tex/sky.hdr".into();
        let up = || Upload {
            mesh: None,
            files: BTreeMap::from([("sky.hdr".to_string(), hdr.clone())]),
            scene: Some(json.to_string()),
            settings: None,
        };
        let ok = prepare(up(), &limits(), &mut unbounded()).unwrap_or_else(|e| panic!("{e:?}"));
        let image = ok.scene.lights[0].image.as_ref().expect("decoded");
        assert_eq!((image.width, image.height), (128, 128));
        assert!(
            (image.texels[0][0] - 0.5).abs() < 1e-6,
            "{:?}",
            image.texels[0]
        );
        let budget = crate::service::memory::MemoryBudget::new(100_000);
        let mut small = budget.try_reserve(0).expect("an empty reservation");
        let e = prepare(up(), &limits(), &mut small)
            .err()
            .expect("128² × 28 B is over a 100 kB budget");
        assert_eq!(e.code, "over_memory_budget", "{}", e.detail);
    }
}
