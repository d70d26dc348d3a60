//! glTF 2.0 reader (`.gltf` JSON and `.glb` binary).
//!
//! The `gltf` crate is used for what it does safely: deserialising the JSON (serde_json, with
//! its recursion limit) and validating it (every index refers to an existing object, every enum
//! value is known), which the typed accessors of `gltf::Document` rely on. Everything that
//! touches bytes is done here instead, because reading `gltf` 1.4.1's source showed:
//!
//! - `Glb::from_slice` computes `header.length - 12` unchecked: a GLB whose header length is
//!   below 12 panics (overflow check) or wraps;
//! - relative URIs are percent-decoded with `urlencoding::decode(uri).unwrap()`, which panics on
//!   `%FF` (invalid UTF-8), and `import_slice` also decodes every image (not needed here);
//! - the accessor iterators compute `stride * (count - 1)` unchecked (a `count` of 0 underflows,
//!   an absurd count overflows) and only `debug_assert!` that the accessor's element type
//!   matches the type they read (a `VEC2` `POSITION` is read past its element).
//!
//! So this module splits GLB containers itself, resolves buffers itself (`data:` base64 URIs,
//! the BIN chunk, and relative files beside the glTF through `sidecar.rs`), and reads
//! accessors with checked arithmetic against their buffer views, after checking the element
//! type and that `count` cannot exceed what the file's bytes could hold.
//!
//! Geometry taken: every primitive of every mesh instanced by the default scene (or, without
//! one, by all scenes; without scenes, every mesh once with the identity transform), with node
//! transforms composed down the hierarchy. Positions are transformed by the world matrix,
//! normals by its inverse transpose (renormalised), and a mirroring transform (negative
//! determinant) flips the winding. Modes `TRIANGLES`, `TRIANGLE_STRIP` and `TRIANGLE_FAN` are
//! read; points and lines are skipped. Positions may be `FLOAT` or (KHR_mesh_quantization)
//! integer `VEC3`; normals `FLOAT` or normalised `BYTE`/`SHORT`; sparse accessors are applied.
//! Skins and morph targets are ignored (the bind pose is used). A primitive whose normals are
//! missing or unusable gets computed normals.
//!
//! Materials (metallic-roughness, per primitive): GGX α = roughness², diffuse albedo =
//! baseColor · (1 − metallic), F0 = mix(0.04, baseColor, metallic) (the glTF 2.0
//! specification's appendix B BRDF), each factor times its texture (`baseColorTexture` RGB,
//! sRGB; `metallicRoughnessTexture` B = metallic, G = roughness) through the material's
//! texture coordinate set (its first texture's, usually `TEXCOORD_0`; one set per material),
//! which
//! is read only for primitives whose material is textured; a primitive without a material
//! gets the specification's default material. Images are decoded once each, when a material
//! first uses them (buffer view, `data:` URI, or a file beside the glTF), bounded by
//! `texture::MAX_*`; one that cannot be read is a warning and the factor is used alone. A
//! material whose `emissiveFactor` × `KHR_materials_emissive_strength` is non-zero makes its
//! triangles lamps (`lamps.rs`), two-sided when the material is `doubleSided`; its
//! `emissiveTexture` becomes the lamp's texture. `KHR_lights_punctual` point, spot and
//! directional lights of the instanced nodes are placed by the node's world transform (spots
//! and suns point down its −Z). The
//! first perspective camera instanced by the scene becomes the scene's camera (looking down its
//! node's −Z with +Y up). Every texture may carry `KHR_texture_transform`. `normalTexture`
//! becomes the material's [`NormalMap`] (tangents: MikkTSpace's, computed by the client from
//! the positions, normals and UVs; an asset's `TANGENT` attribute is not read). Occlusion
//! textures (no method has an ambient term: each computes its own shadowing), a texture on a
//! set other than its material's, other extensions and orthographic cameras are not used;
//! each kind is named in the warnings. Image and light JSON is read from the
//! document's JSON, not through the `gltf` crate's accessors that `unwrap` (an image with a
//! buffer view but no MIME type would panic there).

use super::sidecar::{SidecarError, Sidecars};
use std::borrow::Cow;
use std::collections::HashMap;
use std::rc::Rc;
use std::sync::Arc;

use ::gltf::Document;
use ::gltf::accessor::{Accessor, DataType, Dimensions};
use ::gltf::buffer::View;
use ::gltf::mesh::{Mode, Semantic};
use glam::{Mat3, Mat4, Vec2, Vec3};

use super::mtl::MIN_ALPHA;
use super::{FileMaterial, Limits, Raw, is_degenerate, usable_normals};
use crate::camera::Camera;
use crate::error::MeshError;
use crate::light::{PunctualLight, Spot, SunLight};
use crate::material::MaterialMaps;
use crate::material::{Cutout, Material, NormalMap};
use crate::mesh::Mesh;
use crate::texture::{MAX_ASSET_TEXELS, Texture, TextureRef, UvTransform, Wrap};

fn malformed(message: impl Into<String>) -> MeshError {
    MeshError::Malformed {
        format: "glTF",
        message: message.into(),
    }
}

pub(super) fn parse(
    bytes: &[u8],
    sidecars: &Sidecars<'_>,
    limits: &Limits,
) -> Result<Raw, MeshError> {
    let (json, bin) = if bytes.starts_with(b"glTF") {
        split_glb(bytes)?
    } else {
        (bytes, None)
    };
    let doc = parse_document(json)?;
    let (buffers, total_bytes) = load_buffers(&doc, bin, sidecars, limits, bytes.len() as u64)?;
    let mut reader = Builder {
        buffers,
        file_bytes: total_bytes,
        limits,
        mesh: Mesh::default(),
        vec3s: HashMap::new(),
        indices: HashMap::new(),
        primitives: HashMap::new(),
        work: 0,
        work_limit: limits
            .max_vertices
            .saturating_add(limits.max_triangles.saturating_mul(3))
            .saturating_mul(2),
        materials: Vec::new(),
        uv_sets: doc.materials().map(|m| uv_set(&m)).collect(),
        default_material: None,
        untextured: HashMap::new(),
        camera: None,
        punctual: Vec::new(),
        suns: Vec::new(),
        warnings: Vec::new(),
        sidecars,
        images: HashMap::new(),
        texels: 0,
    };
    reader.materials = doc.materials().map(|m| reader.material(&doc, &m)).collect();
    reader.read_scenes(&doc)?;
    let mut warnings = unused_features(&doc);
    warnings.append(&mut reader.warnings);
    Ok(Raw {
        mesh: reader.mesh,
        materials: reader.materials,
        camera: reader.camera,
        punctual: reader.punctual,
        suns: reader.suns,
        warnings,
    })
}

/// A texture reference's wrap modes (glTF 2.0 §5.26; the default sampler repeats).
fn wrap_modes(t: &::gltf::texture::Texture) -> [Wrap; 2] {
    use ::gltf::texture::WrappingMode as W;
    let json = &t.sampler();
    let w = |m: W| match m {
        W::ClampToEdge => Wrap::Clamp,
        W::MirroredRepeat => Wrap::Mirror,
        W::Repeat => Wrap::Repeat,
    };
    [w(json.wrap_s()), w(json.wrap_t())]
}

/// Warnings for what the file holds and bspvt does not use: extensions, textures, punctual
/// lights, non-opaque materials.
fn unused_features(doc: &Document) -> Vec<String> {
    const READ: &[&str] = &[
        "KHR_materials_emissive_strength",
        "KHR_texture_transform",
        "KHR_mesh_quantization",
        "KHR_lights_punctual",
    ];
    let mut w: Vec<String> = doc
        .extensions_used()
        .filter(|e| !READ.contains(e))
        .map(|e| format!("extension {e} is not supported and was ignored"))
        .collect();
    let count = |f: &dyn Fn(&::gltf::Material) -> bool| doc.materials().filter(|m| f(m)).count();
    let textures = [(
        count(&|m| m.occlusion_texture().is_some()),
        "occlusion textures (no method has an ambient term to darken: each computes its own \
             shadowing)",
    )];
    for (n, what) in textures {
        if n > 0 {
            w.push(format!("{n} materials have {what}: ignored"));
        }
    }
    let blend = count(&|m| m.alpha_mode() == ::gltf::material::AlphaMode::Blend);
    if blend > 0 {
        w.push(format!(
            "{blend} materials have alpha mode BLEND: shadows take them as a mask at alpha {} \
             (no partial transmission)",
            Cutout::BLEND_CUTOFF
        ));
    }
    w
}

/// The texture coordinate set a textureInfo reads (`KHR_texture_transform`'s `texCoord`
/// overrides its own).
fn info_set(info: &::gltf::texture::Info<'_>) -> u32 {
    info.texture_transform()
        .and_then(|x| x.tex_coord())
        .unwrap_or(info.tex_coord())
}

/// [`info_set`] of a `normalTexture` (its transform is raw JSON).
fn normal_set(n: &::gltf::material::NormalTexture<'_>) -> u32 {
    n.extension_value("KHR_texture_transform")
        .and_then(|v| texture_transform_json(v).1)
        .unwrap_or(n.tex_coord())
}

/// The one texture coordinate set a material's textures are read through: the set of its
/// first texture that bspvt reads (base colour, metallic-roughness, normal, then emissive when
/// it emits); 0 without one. A texture on another set is left out, with a warning
/// (`Builder::texture_of`); occlusion textures, which are not read, do not count.
fn uv_set(m: &::gltf::Material<'_>) -> u32 {
    let pbr = m.pbr_metallic_roughness();
    let emits = m.emissive_factor().iter().any(|&e| e > 0.0);
    pbr.base_color_texture()
        .map(|t| info_set(&t))
        .or_else(|| pbr.metallic_roughness_texture().map(|t| info_set(&t)))
        .or_else(|| m.normal_texture().map(|n| normal_set(&n)))
        .or_else(|| m.emissive_texture().filter(|_| emits).map(|t| info_set(&t)))
        .unwrap_or(0)
}

/// A `KHR_texture_transform` object read from its JSON (where the gltf crate offers no typed
/// accessor: a `normalTexture`'s), with its `texCoord` override; absent or malformed fields
/// take the extension's defaults.
fn texture_transform_json(v: &serde_json::Value) -> (Option<UvTransform>, Option<u32>) {
    let num = |x: &serde_json::Value| x.as_f64().map(|f| f as f32).filter(|f| f.is_finite());
    let pair = |key: &str, d: [f32; 2]| {
        v.get(key)
            .and_then(|a| a.as_array())
            .filter(|a| a.len() == 2)
            .and_then(|a| Some([num(&a[0])?, num(&a[1])?]))
            .unwrap_or(d)
    };
    let t = UvTransform {
        offset: pair("offset", [0.0, 0.0]),
        rotation: v.get("rotation").and_then(num).unwrap_or(0.0),
        scale: pair("scale", [1.0, 1.0]),
    };
    let set = v
        .get("texCoord")
        .and_then(|x| x.as_u64())
        .map(|x| u32::try_from(x).unwrap_or(u32::MAX));
    (Some(t), set)
}

/// The cut-out of material `m` (glTF 2.0 §3.9.4): MASK cuts at its `alphaCutoff`, BLEND at
/// [`Cutout::BLEND_CUTOFF`]; `alpha`: `baseColorFactor`'s alpha; the base-colour texture's
/// alpha modulates it when the texture has any texel below 255. `None` when nothing is cut
/// out.
fn cutout(m: &::gltf::Material<'_>, alpha: f32, texture: Option<&TextureRef>) -> Option<Cutout> {
    use ::gltf::material::AlphaMode;
    let (cutoff, blend) = match m.alpha_mode() {
        AlphaMode::Opaque => return None,
        AlphaMode::Mask => (
            m.alpha_cutoff()
                .filter(|c| c.is_finite())
                .map_or(Cutout::DEFAULT_CUTOFF, |c| c.clamp(0.0, 1.0)),
            false,
        ),
        AlphaMode::Blend => (Cutout::BLEND_CUTOFF, true),
    };
    let texture = texture
        .filter(|t| t.texture.rgba.chunks_exact(4).any(|p| p[3] < 255))
        .cloned();
    Some(Cutout {
        alpha,
        cutoff,
        texture,
        blend,
    })
    .filter(|c| !c.is_opaque())
}

/// The camera a node's world transform places: at its origin, looking down its −Z, +Y up.
fn node_camera(world: &Mat4, cam: &::gltf::Camera) -> Result<Camera, String> {
    let ::gltf::camera::Projection::Perspective(p) = cam.projection() else {
        return Err(
            "an orthographic camera was ignored (only perspective cameras are read)".into(),
        );
    };
    let eye = affine_point(world, Vec3::ZERO);
    let forward = Mat3::from_mat4(*world) * Vec3::NEG_Z;
    let up = Mat3::from_mat4(*world) * Vec3::Y;
    let fov_y_deg = p.yfov().to_degrees();
    let camera = Camera {
        position: eye.to_array(),
        target: (eye + forward.normalize_or_zero()).to_array(),
        up: up.normalize_or_zero().to_array(),
        fov_y_deg,
        aspect: p.aspect_ratio(),
    };
    camera
        .validate()
        .map(|()| camera)
        .map_err(|e| format!("camera {} was ignored: {e}", cam.index()))
}

fn short(s: &str) -> String {
    let mut t: String = s.chars().take(80).collect();
    if t.len() < s.len() {
        t.push('…');
    }
    t
}

/// Splits a GLB container into its JSON chunk and optional BIN chunk.
fn split_glb(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>), MeshError> {
    let bad = |m: String| MeshError::Malformed {
        format: "GLB",
        message: m,
    };
    let u32_at = |at: usize| -> Option<u32> {
        let b = bytes.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes(b.try_into().ok()?))
    };
    let (Some(version), Some(length)) = (u32_at(4), u32_at(8)) else {
        return Err(bad(format!(
            "truncated: {} bytes is shorter than the 12-byte GLB header",
            bytes.len()
        )));
    };
    if version != 2 {
        return Err(bad(format!(
            "unsupported GLB version {version} (only glTF 2.0 is read)"
        )));
    }
    let length = length as usize;
    if length > bytes.len() {
        return Err(bad(format!(
            "truncated: the header says the file has {length} bytes, but it has {}",
            bytes.len()
        )));
    }
    let data = &bytes[..length];
    let mut pos = 12usize;
    let mut json = None;
    let mut bin = None;
    let mut chunk = 0usize;
    while pos < data.len() {
        let (Some(len), Some(kind)) = (
            u32_at(pos).filter(|_| pos + 8 <= data.len()),
            u32_at(pos + 4).filter(|_| pos + 8 <= data.len()),
        ) else {
            return Err(bad(format!(
                "chunk {chunk} header is cut off at byte {pos} of {}",
                data.len()
            )));
        };
        let start = pos + 8;
        let end = start
            .checked_add(len as usize)
            .filter(|&e| e <= data.len())
            .ok_or_else(|| {
                bad(format!(
                    "chunk {chunk} declares {len} bytes, but only {} remain in the file",
                    data.len() - start
                ))
            })?;
        let body = &data[start..end];
        match (&kind.to_le_bytes(), chunk) {
            (b"JSON", 0) => json = Some(body),
            (_, 0) => return Err(bad("the first chunk is not the JSON chunk".into())),
            (b"BIN\0", _) if bin.is_none() => bin = Some(body),
            // Unknown chunks are skipped, as the specification asks.
            _ => {}
        }
        chunk += 1;
        pos = end;
    }
    let json = json.ok_or_else(|| bad("the file has no JSON chunk".into()))?;
    Ok((json, bin))
}

fn parse_document(json: &[u8]) -> Result<Document, MeshError> {
    use ::gltf::json::validation::{Error as VError, Validate};

    let json = json.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(json);
    let root: ::gltf::json::Root = ::gltf::json::deserialize::from_slice(json)
        .map_err(|e| malformed(format!("invalid JSON: {e}")))?;
    // gltf-json's primitive validation hook indexes `root.accessors[POSITION]` before anything
    // has checked that index: check it here first.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &prim.attributes {
                if index.value() >= root.accessors.len() {
                    return Err(malformed(format!(
                        "meshes[{m}].primitives[{p}].attributes[{semantic:?}] refers to \
                         accessor {}, but there are {}",
                        index.value(),
                        root.accessors.len()
                    )));
                }
            }
        }
    }
    // Last line of defence: the rest of the crate's validation is not ours to audit line by
    // line, so a panic inside it becomes an error rather than taking the server down.
    let errors = std::panic::catch_unwind(|| {
        let mut errors: Vec<(String, VError)> = Vec::new();
        root.validate(&root, ::gltf::json::Path::new, &mut |path, error| {
            let path = path().as_str().to_string();
            // Tolerated: POSITION min/max (required by the specification, read by nothing
            // here and omitted by some exporters), and required extensions that do not change
            // geometry (materials, textures, lights) or that this module implements.
            let ignored = path.ends_with("[\"POSITION\"].min")
                || path.ends_with("[\"POSITION\"].max")
                || (error == VError::Unsupported
                    && path
                        .rsplit_once("= \"")
                        .is_some_and(|(_, ext)| harmless_extension(ext.trim_end_matches('"'))));
            if !ignored && errors.len() < 8 {
                errors.push((path, error));
            }
        });
        errors
    })
    .map_err(|_| malformed("the glTF validator failed on this file"))?;
    if !errors.is_empty() {
        let list: Vec<String> = errors
            .iter()
            .map(|(path, e)| {
                let what = match e {
                    VError::IndexOutOfBounds => "index out of bounds",
                    VError::Invalid => "invalid value",
                    VError::Missing => "missing",
                    VError::Oversize => "too large",
                    VError::Unsupported => "an extension bspvt cannot read",
                };
                format!("{path}: {what}")
            })
            .collect();
        return Err(malformed(format!("invalid glTF: {}", list.join("; "))));
    }
    Ok(Document::from_json_without_validation(root))
}

/// Required extensions that can be ignored when only geometry is read.
fn harmless_extension(name: &str) -> bool {
    name == "KHR_mesh_quantization"
        || name == "KHR_lights_punctual"
        || ["KHR_materials_", "KHR_texture_", "EXT_texture_"]
            .iter()
            .any(|p| name.starts_with(p))
}

/// The bytes of every buffer, in order: borrowed from the input or decoded/read.
type Buffers<'a> = Vec<Cow<'a, [u8]>>;

/// Resolves every buffer's bytes. Returns them with the total bytes read (file + externals).
fn load_buffers<'a>(
    doc: &Document,
    mut bin: Option<&'a [u8]>,
    sidecars: &Sidecars<'_>,
    limits: &Limits,
    file_bytes: u64,
) -> Result<(Buffers<'a>, u64), MeshError> {
    let mut total = file_bytes;
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let i = buffer.index();
        let data: Cow<'a, [u8]> = match buffer.source() {
            ::gltf::buffer::Source::Bin => Cow::Borrowed(bin.take().ok_or_else(|| {
                malformed(format!(
                    "buffer {i} refers to the GLB BIN chunk, but the file has none"
                ))
            })?),
            ::gltf::buffer::Source::Uri(uri) => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    Cow::Owned(
                        decode_data_uri(rest).map_err(|m| malformed(format!("buffer {i}: {m}")))?,
                    )
                } else {
                    let bytes =
                        read_external(sidecars, uri, limits, total).map_err(|e| match e {
                            MeshError::Malformed { message, .. } => {
                                malformed(format!("buffer {i}: {message}"))
                            }
                            e => e,
                        })?;
                    total += bytes.len() as u64;
                    Cow::Owned(bytes)
                }
            }
        };
        if data.len() < buffer.length() {
            return Err(malformed(format!(
                "buffer {i} declares {} bytes but only {} are present",
                buffer.length(),
                data.len()
            )));
        }
        out.push(data);
    }
    Ok((out, total))
}

/// Reads a relative URI beside the glTF file, refusing what would exceed the byte limit.
fn read_external(
    sidecars: &Sidecars<'_>,
    uri: &str,
    limits: &Limits,
    read_so_far: u64,
) -> Result<Vec<u8>, MeshError> {
    let decoded = percent_decode(uri)
        .ok_or_else(|| malformed(format!("bad percent-encoding in URI {:?}", short(uri))))?;
    match sidecars.read(&decoded, limits.max_bytes.saturating_sub(read_so_far)) {
        Ok(bytes) => Ok(bytes),
        Err(SidecarError::TooLarge(len)) => {
            limits.check_bytes(read_so_far.saturating_add(len))?;
            Err(malformed(format!("{:?} is too large", short(uri))))
        }
        Err(SidecarError::Io(path, source)) => Err(MeshError::Io { path, source }),
        Err(e) => Err(malformed(format!(
            "cannot read the external file {:?}: {e}",
            short(uri)
        ))),
    }
}

fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// Decodes the part of a `data:` URI after `data:`; only base64 payloads are accepted.
fn decode_data_uri(rest: &str) -> Result<Vec<u8>, String> {
    let (meta, payload) = rest.split_once(',').ok_or("a data: URI without a comma")?;
    if !meta.ends_with(";base64") {
        return Err("only base64 data: URIs are supported".into());
    }
    base64_decode(payload.as_bytes()).ok_or_else(|| "invalid base64 in a data: URI".into())
}

/// Standard base64 (RFC 4648), padding optional, ASCII whitespace ignored.
fn base64_decode(input: &[u8]) -> Option<Vec<u8>> {
    fn value(c: u8) -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            _ => return None,
        } as u32)
    }
    let mut out = Vec::with_capacity(input.len() / 4 * 3 + 3);
    let mut acc = 0u32;
    let mut bits = 0u32;
    let mut padding = 0usize;
    for &c in input {
        if c.is_ascii_whitespace() {
            continue;
        }
        if c == b'=' {
            padding += 1;
            continue;
        }
        if padding > 0 {
            return None; // data after padding
        }
        acc = (acc << 6) | value(c)?;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    // Leftover bits must be zero padding of a partial group (2 or 4 bits).
    if bits >= 6 || acc != 0 || padding > 2 {
        return None;
    }
    Some(out)
}

struct Builder<'a> {
    buffers: Buffers<'a>,
    /// Bytes of input (file plus external buffers): no accessor can hold more elements.
    file_bytes: u64,
    limits: &'a Limits,
    mesh: Mesh,
    /// Decoded accessors (by index, and whether read as normals) and primitives (by mesh and
    /// primitive index), so that instancing and shared accessors cost no repeated decoding.
    vec3s: HashMap<(usize, bool), Rc<Vec<Vec3>>>,
    indices: HashMap<usize, Rc<Vec<u32>>>,
    primitives: HashMap<(usize, usize), Option<Rc<Primitive>>>,
    /// The file's materials, then (when a primitive has none) the default material, then
    /// untextured copies of textured materials for primitives without their UV set.
    materials: Vec<FileMaterial>,
    /// The texture coordinate set each glTF material's textures are read through
    /// ([`uv_set`]).
    uv_sets: Vec<u32>,
    default_material: Option<u32>,
    untextured: HashMap<u32, u32>,
    /// The first valid perspective camera met.
    camera: Option<Camera>,
    /// `KHR_lights_punctual` point and spot lights of the instanced nodes.
    punctual: Vec<PunctualLight>,
    /// `KHR_lights_punctual` directional lights of the instanced nodes.
    suns: Vec<SunLight>,
    warnings: Vec<String>,
    /// Where external image files are read from.
    sidecars: &'a Sidecars<'a>,
    /// Images decoded so far (`None`: could not be read; warned once), by image index.
    images: HashMap<usize, Option<Arc<Texture>>>,
    /// Texels decoded so far, against [`MAX_ASSET_TEXELS`].
    texels: u64,
    /// Accessor elements decoded and indices assembled so far, and the most allowed. Output is
    /// bounded by the limits; this bounds the work spent on input that yields no output (for
    /// example many primitives sharing one large accessor of degenerate triangles).
    work: u64,
    work_limit: u64,
}

/// A primitive's geometry in its own space.
struct Primitive {
    positions: Rc<Vec<Vec3>>,
    normals: Option<Rc<Vec<Vec3>>>,
    /// The material's UV set (`uv_set`), read only when the primitive's material is textured.
    uvs: Option<Rc<Vec<Vec2>>>,
    /// Checked against `positions`, degenerate ones removed; never empty.
    triangles: Vec<[u32; 3]>,
}

impl Builder<'_> {
    fn read_scenes(&mut self, doc: &Document) -> Result<(), MeshError> {
        let roots: Vec<usize> = match doc.default_scene() {
            Some(scene) => scene.nodes().map(|n| n.index()).collect(),
            None => doc
                .scenes()
                .flat_map(|s| s.nodes())
                .map(|n| n.index())
                .collect(),
        };
        if doc.scenes().len() == 0 {
            for mesh in doc.meshes() {
                self.add_mesh(&mesh, Mat4::IDENTITY)?;
            }
            return Ok(());
        }
        let nodes: Vec<::gltf::Node> = doc.nodes().collect();
        let mut visited = vec![false; nodes.len()];
        let mut stack: Vec<(usize, Mat4)> = Vec::new();
        for root in roots {
            // Scenes may share root nodes; each is instanced once.
            if visited.get(root).copied().unwrap_or(true) {
                continue;
            }
            visited[root] = true;
            stack.push((root, Mat4::IDENTITY));
            while let Some((i, parent)) = stack.pop() {
                let Some(node) = nodes.get(i) else { continue };
                let local = Mat4::from_cols_array_2d(&node.transform().matrix());
                let world = parent * local;
                if self.camera.is_none()
                    && let Some(cam) = node.camera()
                {
                    match node_camera(&world, &cam) {
                        Ok(c) => self.camera = Some(c),
                        Err(w) => self.warnings.push(w),
                    }
                }
                if let Some(light) = node.light() {
                    self.punctual_light(&world, &light);
                }
                if let Some(mesh) = node.mesh() {
                    self.add_mesh(&mesh, world)?;
                }
                let children: Vec<usize> = node.children().map(|c| c.index()).collect();
                // Reversed so that the first child is read first (depth-first, file order).
                for &c in children.iter().rev() {
                    match visited.get_mut(c) {
                        Some(v) if !*v => *v = true,
                        _ => {
                            return Err(malformed(format!(
                                "node {c} is reached twice (through node {i}); the node \
                                 hierarchy must be a tree"
                            )));
                        }
                    }
                    stack.push((c, world));
                }
            }
        }
        Ok(())
    }

    fn add_mesh(&mut self, mesh: &::gltf::Mesh, world: Mat4) -> Result<(), MeshError> {
        for prim in mesh.primitives() {
            let Some(p) = self.primitive(mesh, &prim)? else {
                continue;
            };
            let mut material = match prim.material().index() {
                Some(i) if i < self.materials.len() => i as u32,
                _ => self.default_material(),
            };
            if p.uvs.is_none() && self.textured(Some(material as usize)) {
                material = self.untextured_material(material);
            }
            let n = p.positions.len();
            self.limits
                .check_vertices(self.mesh.positions.len() as u64 + n as u64)?;
            self.limits
                .check_triangles(self.mesh.triangles.len() as u64 + p.triangles.len() as u64)?;
            let linear = Mat3::from_mat4(world);
            let det = linear.determinant();
            let mut triangles = p.triangles.clone();
            // A mirroring transform turns counter-clockwise into clockwise: flip the winding.
            if det < 0.0 {
                for t in &mut triangles {
                    t.swap(1, 2);
                }
            }
            // Normals transform by the inverse transpose, which is the cofactor matrix divided
            // by the determinant; only its direction matters (normals are renormalised), so the
            // cofactor matrix times the determinant's sign is used. It needs no division, and a
            // singular transform gives zero normals, which fall back to computed ones. (glam's
            // `inverse` and `transform_point3` assert on such input when `glam-assert` is on.)
            let sign = if det > 0.0 {
                1.0
            } else if det < 0.0 {
                -1.0
            } else {
                0.0
            };
            let normal_matrix = Mat3::from_cols(
                linear.y_axis.cross(linear.z_axis),
                linear.z_axis.cross(linear.x_axis),
                linear.x_axis.cross(linear.y_axis),
            ) * sign;
            let mut piece = Mesh {
                positions: p
                    .positions
                    .iter()
                    .map(|&v| affine_point(&world, v))
                    .collect(),
                normals: p
                    .normals
                    .as_ref()
                    .map(|ns| ns.iter().map(|&v| normal_matrix * v).collect())
                    .unwrap_or_default(),
                material_ids: vec![material; triangles.len()],
                triangles,
                uvs: p.uvs.as_ref().map(|u| u.to_vec()).unwrap_or_default(),
            };
            if usable_normals(&piece.normals, n) {
                piece.normals.iter_mut().for_each(|v| *v = v.normalize());
            } else {
                piece.compute_normals();
            }
            self.mesh.append(&piece, 0);
        }
        Ok(())
    }

    /// The index of glTF's default material (white, metallic 1, roughness 1), appended once
    /// when first needed. A file that defines no material at all is read as geometry only
    /// (no materials: the scene chooses, as for a PLY).
    fn default_material(&mut self) -> u32 {
        if self.materials.is_empty() {
            return 0;
        }
        *self.default_material.get_or_insert_with(|| {
            self.materials.push(FileMaterial {
                material: Material {
                    name: "glTF default material".into(),
                    roughness: 1.0,
                    albedo: [0.0; 3],
                    specular: [1.0; 3],
                    maps: None,
                    cutout: None,
                    normal_map: None,
                },
                emission: [0.0; 3],
                two_sided: false,
                emissive_texture: None,
            });
            self.materials.len() as u32 - 1
        })
    }

    /// Counts `n` units of decoding work against the budget.
    fn spend(&mut self, n: usize) -> Result<(), MeshError> {
        self.work = self.work.saturating_add(n as u64);
        if self.work > self.work_limit {
            return Err(MeshError::TooLarge {
                what: "accessor elements read",
                count: self.work,
                limit: self.work_limit,
            });
        }
        Ok(())
    }

    /// The decoded primitive, or `None` when it contributes no triangles.
    fn primitive(
        &mut self,
        mesh: &::gltf::Mesh,
        prim: &::gltf::Primitive,
    ) -> Result<Option<Rc<Primitive>>, MeshError> {
        let key = (mesh.index(), prim.index());
        if let Some(p) = self.primitives.get(&key) {
            return Ok(p.clone());
        }
        let p = self.decode_primitive(mesh, prim)?.map(Rc::new);
        self.primitives.insert(key, p.clone());
        Ok(p)
    }

    fn decode_primitive(
        &mut self,
        mesh: &::gltf::Mesh,
        prim: &::gltf::Primitive,
    ) -> Result<Option<Primitive>, MeshError> {
        let what = |attr: &str| format!("mesh {} primitive {} {attr}", mesh.index(), prim.index());
        if !matches!(
            prim.mode(),
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            return Ok(None);
        }
        let Some(pos_acc) = prim.get(&Semantic::Positions) else {
            return Ok(None);
        };
        let positions = self.read_vec3(&pos_acc, &what("POSITION"), false)?;
        let n = positions.len();
        if n == 0 {
            return Ok(None);
        }
        // Also guarantees that `n` fits in a u32 index.
        self.limits.check_vertices(n as u64)?;
        let normals = match prim.get(&Semantic::Normals) {
            Some(acc) => {
                let normals = self.read_vec3(&acc, &what("NORMAL"), true)?;
                if normals.len() != n {
                    return Err(malformed(format!(
                        "{} has {} elements but POSITION has {n}",
                        what("NORMAL"),
                        normals.len()
                    )));
                }
                Some(normals)
            }
            None => None,
        };
        // The set the material's textures are read through (usually 0).
        let set = self.uv_set_of(prim.material().index());
        let uvs = match prim.get(&Semantic::TexCoords(set)) {
            Some(acc) if self.textured(prim.material().index()) => {
                let name = format!("TEXCOORD_{set}");
                let uvs = self.read_uvs(&acc, &what(&name))?;
                if uvs.len() != n {
                    return Err(malformed(format!(
                        "{} has {} elements but POSITION has {n}",
                        what(&name),
                        uvs.len()
                    )));
                }
                Some(uvs)
            }
            _ => None,
        };
        let mut triangles = match prim.indices() {
            Some(acc) => {
                let indices = self.read_indices(&acc, &what("indices"))?;
                self.spend(indices.len())?;
                assemble(prim.mode(), &indices)
            }
            None => {
                self.spend(n)?;
                assemble(prim.mode(), &(0..n as u32).collect::<Vec<_>>())
            }
        };
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&i) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::IndexOutOfRange {
                    triangle: self.mesh.triangles.len() + t,
                    index: u64::from(i),
                    vertices: n,
                });
            }
        }
        triangles.retain(|t| !is_degenerate(t));
        if triangles.is_empty() {
            return Ok(None);
        }
        Ok(Some(Primitive {
            positions,
            normals,
            uvs,
            triangles,
        }))
    }

    fn read_vec3(
        &mut self,
        acc: &Accessor,
        what: &str,
        is_normal: bool,
    ) -> Result<Rc<Vec<Vec3>>, MeshError> {
        if let Some(v) = self.vec3s.get(&(acc.index(), is_normal)) {
            return Ok(v.clone());
        }
        let dt = acc.data_type();
        let normalized = acc.normalized();
        let type_ok = acc.dimensions() == Dimensions::Vec3
            && match dt {
                DataType::F32 => true,
                DataType::I8 | DataType::I16 => !is_normal || normalized,
                DataType::U8 | DataType::U16 => !is_normal,
                DataType::U32 => false,
            };
        if !type_ok {
            return Err(malformed(format!(
                "{what} has type {:?} {:?}{}, which is not a valid {}",
                acc.dimensions(),
                dt,
                if normalized { " (normalized)" } else { "" },
                if is_normal { "normal" } else { "position" }
            )));
        }
        let size = component_size(dt);
        let v = Rc::new(self.read_elements(acc, what, 3 * size, Vec3::ZERO, |b| {
            Vec3::new(
                component(b, 0, dt, normalized),
                component(b, size, dt, normalized),
                component(b, 2 * size, dt, normalized),
            )
        })?);
        self.vec3s.insert((acc.index(), is_normal), v.clone());
        Ok(v)
    }

    fn read_indices(&mut self, acc: &Accessor, what: &str) -> Result<Rc<Vec<u32>>, MeshError> {
        if let Some(v) = self.indices.get(&acc.index()) {
            return Ok(v.clone());
        }
        let dt = acc.data_type();
        if acc.dimensions() != Dimensions::Scalar
            || !matches!(dt, DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(malformed(format!(
                "{what} has type {:?} {dt:?}; indices must be unsigned integer scalars",
                acc.dimensions()
            )));
        }
        let v = Rc::new(self.read_elements(acc, what, component_size(dt), 0, |b| uint(b, 0, dt))?);
        self.indices.insert(acc.index(), v.clone());
        Ok(v)
    }

    /// Reads `acc.count()` elements of `elem` bytes each, decoded by `decode`, applying sparse
    /// substitution. Every offset is checked against its buffer view and buffer.
    fn read_elements<T: Copy>(
        &mut self,
        acc: &Accessor,
        what: &str,
        elem: usize,
        zero: T,
        decode: impl Fn(&[u8]) -> T,
    ) -> Result<Vec<T>, MeshError> {
        let count = acc.count();
        if (count as u64).saturating_mul(elem as u64) > self.file_bytes {
            return Err(MeshError::AbsurdCount {
                what: "accessor elements",
                declared: count as u64,
                file_bytes: self.file_bytes,
            });
        }
        self.spend(count)?;
        if let Some(sparse) = acc.sparse() {
            self.spend(sparse.count())?;
        }
        // Bounded by the input size (checked just above).
        let mut out = Vec::with_capacity(count);
        match acc.view() {
            Some(view) => {
                let stride = match view.stride() {
                    Some(s) if s < elem => {
                        return Err(malformed(format!(
                            "{what}: buffer view {} has byteStride {s}, smaller than the \
                             {elem}-byte element",
                            view.index()
                        )));
                    }
                    Some(s) => s,
                    None => elem,
                };
                let data = self.view_slice(&view, acc.offset(), count, elem, stride, what)?;
                for k in 0..count {
                    let e = data
                        .get(k * stride..k * stride + elem)
                        .ok_or_else(|| malformed(format!("{what}: element {k} out of bounds")))?;
                    out.push(decode(e));
                }
            }
            None => out.resize(count, zero),
        }
        if let Some(sparse) = acc.sparse() {
            let n = sparse.count();
            if n > count {
                return Err(malformed(format!(
                    "{what}: {n} sparse substitutions for {count} elements"
                )));
            }
            let idx = sparse.indices();
            let idx_dt = match idx.index_type() {
                ::gltf::accessor::sparse::IndexType::U8 => DataType::U8,
                ::gltf::accessor::sparse::IndexType::U16 => DataType::U16,
                ::gltf::accessor::sparse::IndexType::U32 => DataType::U32,
            };
            let isz = component_size(idx_dt);
            let idx_data = self.view_slice(&idx.view(), idx.offset(), n, isz, isz, what)?;
            let values = sparse.values();
            let val_data = self.view_slice(&values.view(), values.offset(), n, elem, elem, what)?;
            for k in 0..n {
                let (Some(ib), Some(vb)) = (
                    idx_data.get(k * isz..(k + 1) * isz),
                    val_data.get(k * elem..(k + 1) * elem),
                ) else {
                    return Err(malformed(format!("{what}: sparse entry {k} out of bounds")));
                };
                let i = uint(ib, 0, idx_dt) as usize;
                let slot = out.get_mut(i).ok_or_else(|| {
                    malformed(format!(
                        "{what}: sparse index {i} is outside the accessor's {count} elements"
                    ))
                })?;
                *slot = decode(vb);
            }
        }
        Ok(out)
    }

    /// The bytes of `count` elements of `elem` bytes, `stride` apart, starting `offset` bytes
    /// into `view`; checked against the view and its buffer.
    fn view_slice(
        &self,
        view: &View,
        offset: usize,
        count: usize,
        elem: usize,
        stride: usize,
        what: &str,
    ) -> Result<&[u8], MeshError> {
        if count == 0 {
            return Ok(&[]);
        }
        let b = view.buffer().index();
        let buffer = self
            .buffers
            .get(b)
            .ok_or_else(|| malformed(format!("{what}: buffer {b} is missing")))?;
        let vstart = view.offset();
        let vend = vstart
            .checked_add(view.length())
            .filter(|&e| e <= buffer.len())
            .ok_or_else(|| {
                malformed(format!(
                    "{what}: buffer view {} (offset {vstart}, length {}) lies outside buffer \
                     {b} ({} bytes)",
                    view.index(),
                    view.length(),
                    buffer.len()
                ))
            })?;
        let needed = stride
            .checked_mul(count - 1)
            .and_then(|x| x.checked_add(elem))
            .and_then(|x| x.checked_add(offset));
        match needed {
            Some(needed) if needed <= vend - vstart => {
                Ok(&buffer[vstart + offset..vstart + needed])
            }
            _ => Err(malformed(format!(
                "{what}: {count} elements of {elem} bytes (stride {stride}) from offset \
                 {offset} do not fit in buffer view {} ({} bytes)",
                view.index(),
                view.length()
            ))),
        }
    }
}

/// Materials, textures and punctual lights.
impl Builder<'_> {
    /// A glTF metallic-roughness material in bspvt's GGX model (see the module documentation),
    /// with its textures (decoded here; one that cannot be read is warned about and left out).
    fn material(&mut self, doc: &Document, m: &::gltf::Material<'_>) -> FileMaterial {
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, a] = pbr.base_color_factor();
        let fin = |x: f32, d: f32| if x.is_finite() { x.clamp(0.0, 1.0) } else { d };
        let base = [r, g, b].map(|x| fin(x, 0.0));
        let metallic = fin(pbr.metallic_factor(), 1.0);
        let roughness = fin(pbr.roughness_factor(), 1.0);
        let strength = m
            .emissive_strength()
            .filter(|s| s.is_finite() && *s >= 0.0)
            .unwrap_or(1.0);
        let emission = m.emissive_factor().map(|e| {
            if e.is_finite() {
                (e.max(0.0) * strength).min(1e30)
            } else {
                0.0
            }
        });
        let name = m.name().map_or_else(
            || format!("material {}", m.index().unwrap_or(0)),
            str::to_string,
        );
        let index = m.index().unwrap_or(usize::MAX);
        let base_color_texture = pbr
            .base_color_texture()
            .and_then(|t| self.texture(doc, (index, &name), "base-colour", &t));
        let metallic_roughness_texture = pbr
            .metallic_roughness_texture()
            .and_then(|t| self.texture(doc, (index, &name), "metallic-roughness", &t));
        let emissive_texture = if emission.iter().any(|&e| e > 0.0) {
            m.emissive_texture()
                .and_then(|t| self.texture(doc, (index, &name), "emissive", &t))
        } else {
            None
        };
        let cutout = cutout(m, fin(a, 1.0), base_color_texture.as_ref());
        let normal_map = m.normal_texture().and_then(|n| {
            // NormalTextureInfo carries KHR_texture_transform as raw JSON.
            let ext = n
                .extension_value("KHR_texture_transform")
                .map(texture_transform_json);
            let texture = self.texture_of(
                doc,
                (index, &name),
                "normal",
                normal_set(&n),
                ext.and_then(|e| e.0),
                &n.texture(),
            )?;
            Some(NormalMap {
                texture,
                scale: Some(n.scale()).filter(|s| s.is_finite()).unwrap_or(1.0),
            })
        });
        let maps = (base_color_texture.is_some() || metallic_roughness_texture.is_some())
            .then_some(MaterialMaps::MetallicRoughness {
                base_color: base,
                metallic,
                roughness,
                base_color_texture,
                metallic_roughness_texture,
            });
        let mut material = Material {
            name,
            roughness: (roughness * roughness).clamp(MIN_ALPHA, 1.0),
            albedo: base.map(|c| c * (1.0 - metallic)),
            specular: base.map(|c| 0.04 + (c - 0.04) * metallic),
            maps: None,
            cutout,
            normal_map,
        };
        if let Some(maps) = maps {
            // The constant fields: the material at the textures' means (module docs).
            let mean = maps.at_mean(&material);
            material.roughness = mean.roughness;
            material.albedo = mean.albedo;
            material.specular = mean.specular;
            material.maps = Some(maps);
        }
        FileMaterial {
            material,
            emission,
            two_sided: m.double_sided(),
            emissive_texture,
        }
    }

    /// The texture an `info` names, decoded; `None` (with a warning) when it cannot be used.
    fn texture(
        &mut self,
        doc: &Document,
        material: (usize, &str),
        what: &str,
        info: &::gltf::texture::Info<'_>,
    ) -> Option<TextureRef> {
        let ext = info.texture_transform();
        let set = info_set(info);
        let transform = ext.map(|x| UvTransform {
            offset: x.offset(),
            rotation: x.rotation(),
            scale: x.scale(),
        });
        self.texture_of(doc, material, what, set, transform, &info.texture())
    }

    /// Texture `t` read through texture coordinate set `set` and `transform`, decoded; `None`
    /// (with a warning) when it cannot be used.
    fn texture_of(
        &mut self,
        doc: &Document,
        material: (usize, &str),
        what: &str,
        set: u32,
        transform: Option<UvTransform>,
        t: &::gltf::texture::Texture<'_>,
    ) -> Option<TextureRef> {
        let (index, material) = material;
        let read = self.uv_set_of(Some(index));
        if set != read {
            self.warnings.push(format!(
                "material {material:?}: its {what} texture uses TEXCOORD_{set} but its others \
                 TEXCOORD_{read}; one set per material is read: using the factor alone"
            ));
            return None;
        }
        let transform = transform.filter(|t| *t != UvTransform::IDENTITY);
        let image = t.source().index();
        let texture = self.image(doc, image)?;
        Some(TextureRef {
            texture,
            wrap: wrap_modes(t),
            transform,
        })
    }

    /// Image `i` decoded (once); `None` when it cannot be read (warned once).
    fn image(&mut self, doc: &Document, i: usize) -> Option<Arc<Texture>> {
        if let Some(t) = self.images.get(&i) {
            return t.clone();
        }
        let json = doc.as_json().images.get(i);
        let name = json
            .and_then(|j| {
                j.name
                    .clone()
                    .or_else(|| j.uri.clone().filter(|u| !u.starts_with("data:")))
            })
            .map_or_else(|| format!("image {i}"), |n| short(&n));
        let decoded = self.image_bytes(doc, i).and_then(|bytes| {
            let t = Texture::decode(&bytes, &name)?;
            let texels = u64::from(t.width) * u64::from(t.height);
            if self.texels.saturating_add(texels) > MAX_ASSET_TEXELS {
                return Err(format!(
                    "the asset's textures would exceed {MAX_ASSET_TEXELS} texels in all"
                ));
            }
            self.texels += texels;
            Ok(Arc::new(t))
        });
        let t = match decoded {
            Ok(t) => Some(t),
            Err(e) => {
                self.warnings.push(format!(
                    "texture {name:?} could not be read: {e}; using the factor alone"
                ));
                None
            }
        };
        self.images.insert(i, t.clone());
        t
    }

    /// The encoded bytes of image `i`: a buffer view, a `data:` URI, or a file next to the
    /// glTF (counted against the byte limit).
    fn image_bytes(&mut self, doc: &Document, i: usize) -> Result<Vec<u8>, String> {
        let json = doc
            .as_json()
            .images
            .get(i)
            .ok_or_else(|| format!("there is no image {i}"))?;
        if let Some(v) = &json.buffer_view {
            let view = doc
                .views()
                .nth(v.value())
                .ok_or_else(|| format!("buffer view {} does not exist", v.value()))?;
            let buffer = self
                .buffers
                .get(view.buffer().index())
                .ok_or("its buffer is missing")?;
            return view
                .offset()
                .checked_add(view.length())
                .and_then(|end| buffer.get(view.offset()..end))
                .map(<[u8]>::to_vec)
                .ok_or_else(|| format!("buffer view {} lies outside its buffer", view.index()));
        }
        let uri = json
            .uri
            .as_deref()
            .ok_or("it has neither a buffer view nor a URI")?;
        if let Some(rest) = uri.strip_prefix("data:") {
            return decode_data_uri(rest);
        }
        let bytes = read_external(self.sidecars, uri, self.limits, self.file_bytes)
            .map_err(|e| e.to_string())?;
        self.file_bytes += bytes.len() as u64;
        Ok(bytes)
    }

    /// The material a primitive without its UV set uses instead of textured material `m`:
    /// a copy without its textures (the factors alone), made once, with a warning.
    fn untextured_material(&mut self, m: u32) -> u32 {
        if let Some(&u) = self.untextured.get(&m) {
            return u;
        }
        let Some(f) = self.materials.get(m as usize) else {
            return m;
        };
        let mut copy = f.clone();
        let name = copy.material.name.clone();
        if let Some(maps) = copy.material.maps.take()
            && let MaterialMaps::MetallicRoughness {
                base_color,
                metallic,
                roughness,
                ..
            } = maps
        {
            copy.material.roughness = (roughness * roughness).clamp(MIN_ALPHA, 1.0);
            copy.material.albedo = base_color.map(|c| c * (1.0 - metallic));
            copy.material.specular = base_color.map(|c| 0.04 + (c - 0.04) * metallic);
        }
        // Without UVs a cut-out's texture is read at its mean alpha (`Cutout::covers`), and
        // there is no tangent frame to bend a normal in.
        copy.emissive_texture = None;
        copy.material.normal_map = None;
        let set = self.uv_set_of(Some(m as usize));
        copy.material.name = format!("{name} (no TEXCOORD_{set})");
        self.warnings.push(format!(
            "material {name:?} is textured but a primitive using it has no TEXCOORD_{set}: the \
             factors alone are used there"
        ));
        self.materials.push(copy);
        let u = self.materials.len() as u32 - 1;
        self.untextured.insert(m, u);
        u
    }

    /// The texture coordinate set material `m` (a glTF material index) is read through.
    fn uv_set_of(&self, m: Option<usize>) -> u32 {
        m.and_then(|i| self.uv_sets.get(i)).copied().unwrap_or(0)
    }

    /// Whether material `m` samples a texture through the mesh's UVs.
    fn textured(&self, m: Option<usize>) -> bool {
        m.and_then(|i| self.materials.get(i))
            .is_some_and(|f| f.material.samples_uvs() || f.emissive_texture.is_some())
    }

    /// A `KHR_lights_punctual` light placed by its node's world transform (position: the
    /// node's origin; a spot points down the node's −Z).
    fn punctual_light(&mut self, world: &Mat4, light: &::gltf::khr_lights_punctual::Light) {
        use ::gltf::khr_lights_punctual::Kind;
        let name = light
            .name()
            .map_or_else(|| format!("light {}", light.index()), short);
        let spot = match light.kind() {
            Kind::Directional => {
                let dir = (Mat3::from_mat4(*world) * Vec3::NEG_Z).normalize_or_zero();
                let sun = SunLight {
                    name: name.clone(),
                    direction: dir.to_array(),
                    illuminance: light.color().map(|c| c * light.intensity()),
                    angular_diameter: None,
                };
                match sun.validate(self.suns.len()) {
                    Ok(()) => self.suns.push(sun),
                    Err(e) => self
                        .warnings
                        .push(format!("directional light {name:?} was ignored: {e}")),
                }
                return;
            }
            Kind::Point => None,
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                let dir = (Mat3::from_mat4(*world) * Vec3::NEG_Z).normalize_or_zero();
                Some(Spot {
                    direction: dir.to_array(),
                    inner_cone_angle,
                    outer_cone_angle,
                })
            }
        };
        let colour = light.color();
        let l = PunctualLight {
            name: name.clone(),
            position: affine_point(world, Vec3::ZERO).to_array(),
            intensity: colour.map(|c| c * light.intensity()),
            range: light.range(),
            spot,
            radius: None,
        };
        match l.validate(self.punctual.len()) {
            Ok(()) => self.punctual.push(l),
            Err(e) => self
                .warnings
                .push(format!("punctual light {name:?} was ignored: {e}")),
        }
    }

    fn read_uvs(&mut self, acc: &Accessor, what: &str) -> Result<Rc<Vec<Vec2>>, MeshError> {
        let dt = acc.data_type();
        let normalized = acc.normalized();
        let ok = acc.dimensions() == Dimensions::Vec2
            && match dt {
                DataType::F32 => true,
                DataType::U8 | DataType::U16 | DataType::I8 | DataType::I16 => normalized,
                DataType::U32 => false,
            };
        if !ok {
            return Err(malformed(format!(
                "{what} has type {:?} {dt:?}, which is not a valid TEXCOORD",
                acc.dimensions()
            )));
        }
        let size = component_size(dt);
        let uvs = self.read_elements(acc, what, 2 * size, Vec2::ZERO, |b| {
            Vec2::new(
                component(b, 0, dt, normalized),
                component(b, size, dt, normalized),
            )
        })?;
        if let Some(k) = uvs.iter().position(|v| !v.is_finite()) {
            return Err(malformed(format!("{what}: element {k} is not finite")));
        }
        Ok(Rc::new(uvs))
    }
}

/// `m` applied to the point `p`, as an affine transform (glTF node matrices are affine; a
/// projective last row is ignored rather than asserted on).
fn affine_point(m: &Mat4, p: Vec3) -> Vec3 {
    (m.x_axis * p.x + m.y_axis * p.y + m.z_axis * p.z + m.w_axis).truncate()
}

/// Triangles of a primitive from its index list (strip and fan as in the glTF specification).
fn assemble(mode: Mode, idx: &[u32]) -> Vec<[u32; 3]> {
    match mode {
        Mode::Triangles => idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        Mode::TriangleStrip => idx
            .windows(3)
            .enumerate()
            .map(|(i, w)| {
                if i % 2 == 0 {
                    [w[0], w[1], w[2]]
                } else {
                    [w[0], w[2], w[1]]
                }
            })
            .collect(),
        Mode::TriangleFan => match idx.split_first() {
            Some((&first, rest)) => rest.windows(2).map(|w| [w[0], w[1], first]).collect(),
            None => Vec::new(),
        },
        _ => Vec::new(),
    }
}

fn component_size(dt: DataType) -> usize {
    match dt {
        DataType::I8 | DataType::U8 => 1,
        DataType::I16 | DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
    }
}

fn bytes_at<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    b.get(at..at + N)
        .and_then(|s| s.try_into().ok())
        .unwrap_or([0; N])
}

/// An unsigned integer component (callers pass slices of the right size).
fn uint(b: &[u8], at: usize, dt: DataType) -> u32 {
    match dt {
        DataType::U8 => u32::from(bytes_at::<1>(b, at)[0]),
        DataType::U16 => u32::from(u16::from_le_bytes(bytes_at(b, at))),
        _ => u32::from_le_bytes(bytes_at(b, at)),
    }
}

/// A component as a float, applying glTF's normalisation rules when `normalized`.
fn component(b: &[u8], at: usize, dt: DataType, normalized: bool) -> f32 {
    match dt {
        DataType::F32 => f32::from_le_bytes(bytes_at(b, at)),
        DataType::I8 => {
            let v = f32::from(i8::from_le_bytes(bytes_at(b, at)));
            if normalized { (v / 127.0).max(-1.0) } else { v }
        }
        DataType::U8 => {
            let v = f32::from(bytes_at::<1>(b, at)[0]);
            if normalized { v / 255.0 } else { v }
        }
        DataType::I16 => {
            let v = f32::from(i16::from_le_bytes(bytes_at(b, at)));
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U16 => {
            let v = f32::from(u16::from_le_bytes(bytes_at(b, at)));
            if normalized { v / 65535.0 } else { v }
        }
        DataType::U32 => u32::from_le_bytes(bytes_at(b, at)) as f32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trip() {
        assert_eq!(base64_decode(b"").as_deref(), Some(&b""[..]));
        assert_eq!(base64_decode(b"TWFu").as_deref(), Some(&b"Man"[..]));
        assert_eq!(base64_decode(b"TWE=").as_deref(), Some(&b"Ma"[..]));
        assert_eq!(base64_decode(b"TWE").as_deref(), Some(&b"Ma"[..]));
        assert_eq!(base64_decode(b"TQ==").as_deref(), Some(&b"M"[..]));
        assert_eq!(base64_decode(b"AAAAAA==").as_deref(), Some(&[0u8; 4][..]));
        assert!(base64_decode(b"T").is_none());
        assert!(base64_decode(b"TQ==TQ").is_none());
        assert!(base64_decode(b"T*==").is_none());
    }

    #[test]
    fn percent() {
        assert_eq!(percent_decode("a%20b.bin").as_deref(), Some("a b.bin"));
        assert_eq!(percent_decode("%FF"), None);
        assert_eq!(percent_decode("%4"), None);
        assert_eq!(percent_decode("%zz"), None);
    }

    #[test]
    fn strips_and_fans() {
        assert_eq!(
            assemble(Mode::TriangleStrip, &[0, 1, 2, 3]),
            vec![[0, 1, 2], [1, 3, 2]]
        );
        assert_eq!(
            assemble(Mode::TriangleFan, &[0, 1, 2, 3]),
            vec![[1, 2, 0], [2, 3, 0]]
        );
        assert_eq!(assemble(Mode::Triangles, &[0, 1, 2, 3]), vec![[0, 1, 2]]);
    }
}
