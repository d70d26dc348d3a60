//! Wavefront OBJ reader, written by hand.
//!
//! Why not `tobj` (which the workspace declares)? Reading tobj 4.0.5's source showed:
//!
//! - relative indices are computed as `pos_count as isize + index` and texture/normal bounds as
//!   `vt * 2 + 1`: a face index such as `-9223372036854775808`, or a far out-of-range relative
//!   texture index, overflows, which panics in builds with overflow checks (our test and dev
//!   profiles) and silently wraps otherwise;
//! - with `single_index` it splits the file into one model per `o`/`g` group and de-duplicates
//!   vertices per model, so a vertex shared by two groups becomes two vertices (a seam in the
//!   computed normals, and an extra visibility sample) when the groups are merged back;
//! - a file where only some faces name normals produces a normals array shorter than the
//!   positions, which callers must detect.
//!
//! OBJ is a simple line format, so this module reads it directly: `v` (x y z, any further
//! numbers ignored), `vn`, and `f` with corners `v`, `v/vt`, `v//vn` or `v/vt/vn`, 1-based or
//! negative (relative to the elements defined so far). Polygons are fan-triangulated. `usemtl`
//! gives the faces after it their material, read from the `mtllib` files beside the OBJ
//! (`mtl.rs`; a material with `Ke` makes its faces lamps; `map_Kd` textures it). Groups,
//! objects, smoothing groups, lines and points are ignored, so every group lands in one mesh.
//! `vt` (u v, flipped to glTF's convention: v' = 1 − v) is read when a material has a
//! `map_Kd` that could be read; otherwise texture coordinates are ignored. Lines may end in `\n` or `\r\n`, a trailing `\` continues a
//! line, and `#` starts a comment.
//!
//! Vertices: without complete normals (some face corner names none) and without textures, a
//! mesh vertex is an OBJ `v`, in file order. When every corner names a `vn`, or a material is
//! textured, a mesh vertex is a distinct (`v`, `vn`, `vt`) corner (a missing index counting as
//! one value), ordered by `v`, then `vn`, then `vt`, so hard edges keep their normals and UV
//! seams their texture coordinates.

use glam::{Vec2, Vec3};

use std::collections::HashMap;

use super::mtl::Library;
use super::sidecar::Sidecars;
use super::{FileMaterial, Limits, Raw, is_degenerate};
use crate::error::MeshError;
use crate::material::Material;
use crate::mesh::Mesh;

fn malformed(line: usize, message: impl std::fmt::Display) -> MeshError {
    MeshError::Malformed {
        format: "OBJ",
        message: format!("line {line}: {message}"),
    }
}

/// "No normal" in a corner.
const NONE: u32 = u32::MAX;

pub(super) fn parse(
    bytes: &[u8],
    sidecars: &Sidecars<'_>,
    limits: &Limits,
) -> Result<Raw, MeshError> {
    let mut positions: Vec<Vec3> = Vec::new();
    // Material names in order of first `usemtl`, the current one, and each triangle's.
    let mut material_names: Vec<String> = Vec::new();
    let mut material_index: HashMap<String, u32> = HashMap::new();
    let mut current_material: Option<u32> = None;
    let mut triangle_materials: Vec<u32> = Vec::new();
    let mut libraries: Vec<String> = Vec::new();
    let mut normals: Vec<Vec3> = Vec::new();
    let mut texcoords: Vec<Vec2> = Vec::new();
    // Triangles as (v, vn, vt) corners; positive indices are checked once the file is read (OBJ
    // readers conventionally accept forward references), relative ones when met.
    let mut corners: Vec<[(u32, u32, u32); 3]> = Vec::new();
    let mut all_have_normals = true;

    let mut poly: Vec<(u32, u32, u32)> = Vec::new();
    let mut joined: Vec<u8> = Vec::new();
    let mut line_no = 0usize;
    let mut rest = bytes;
    while !rest.is_empty() {
        // One logical line: physical lines joined while they end in a backslash.
        let first_line_no = line_no + 1;
        joined.clear();
        let mut continued = false;
        let line: &[u8] = loop {
            let (raw, next) = match rest.iter().position(|&b| b == b'\n') {
                Some(i) => (&rest[..i], &rest[i + 1..]),
                None => (rest, &rest[rest.len()..]),
            };
            rest = next;
            line_no += 1;
            let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
            match raw.trim_ascii_end().strip_suffix(b"\\") {
                Some(head) if !rest.is_empty() => {
                    joined.extend_from_slice(head);
                    joined.push(b' ');
                    continued = true;
                }
                _ if continued => {
                    joined.extend_from_slice(raw);
                    break &joined;
                }
                _ => break raw,
            }
        };
        let line = match line.iter().position(|&b| b == b'#') {
            Some(i) => &line[..i],
            None => line,
        };
        let mut words = line
            .split(|b| b.is_ascii_whitespace())
            .filter(|w| !w.is_empty());
        let Some(keyword) = words.next() else {
            continue;
        };
        let n = first_line_no;
        match keyword {
            b"v" => {
                let p = read_vec3(&mut words)
                    .ok_or_else(|| malformed(n, "a vertex needs three numbers (`v x y z`)"))?;
                if !p.is_finite() {
                    return Err(MeshError::NonFinitePosition {
                        vertex: positions.len(),
                    });
                }
                limits.check_vertices(positions.len() as u64 + 1)?;
                positions.push(p);
            }
            b"vn" => {
                let p = read_vec3(&mut words)
                    .ok_or_else(|| malformed(n, "a normal needs three numbers (`vn x y z`)"))?;
                limits.check_vertices(normals.len() as u64 + 1)?;
                normals.push(p);
            }
            b"vt" => {
                let mut uv = [0f32; 2];
                for x in &mut uv {
                    *x = words
                        .next()
                        .and_then(|w| std::str::from_utf8(w).ok()?.parse().ok())
                        .filter(|x: &f32| x.is_finite())
                        .ok_or_else(|| {
                            malformed(
                                n,
                                "a texture coordinate needs two finite numbers (`vt u v`)",
                            )
                        })?;
                }
                limits.check_vertices(texcoords.len() as u64 + 1)?;
                texcoords.push(Vec2::new(uv[0], 1.0 - uv[1]));
            }
            b"f" | b"fo" => {
                poly.clear();
                for w in words {
                    let c = match parse_corner(w, positions.len(), normals.len(), texcoords.len()) {
                        Ok(c) => c,
                        Err(CornerError::OutOfRange(index)) => {
                            return Err(MeshError::IndexOutOfRange {
                                triangle: corners.len(),
                                index,
                                vertices: positions.len(),
                            });
                        }
                        Err(CornerError::Bad(m)) => return Err(malformed(n, m)),
                    };
                    if c.1 == NONE {
                        all_have_normals = false;
                    }
                    poly.push(c);
                }
                if poly.len() < 3 {
                    return Err(malformed(
                        n,
                        format!(
                            "a face needs at least 3 vertices, this one has {}",
                            poly.len()
                        ),
                    ));
                }
                // Fan triangulation; a triangle repeating a position is dropped.
                let first = poly[0];
                for w in poly.windows(2).skip(1) {
                    let t = [first, w[0], w[1]];
                    if !is_degenerate(&t.map(|c| c.0)) {
                        limits.check_triangles(corners.len() as u64 + 1)?;
                        corners.push(t);
                        triangle_materials.push(current_material.unwrap_or(0));
                    }
                }
            }
            b"usemtl" | b"mtllib" => {
                let name = words
                    .map(String::from_utf8_lossy)
                    .collect::<Vec<_>>()
                    .join(" ");
                if keyword == b"mtllib" {
                    libraries.push(name);
                    continue;
                }
                // Faces before the first `usemtl` (if any) use material 0, the default.
                if material_names.is_empty() && !corners.is_empty() {
                    material_names.push(String::new());
                    material_index.insert(String::new(), 0);
                }
                let next = material_names.len() as u32;
                current_material = Some(*material_index.entry(name.clone()).or_insert_with(|| {
                    material_names.push(name);
                    next
                }));
            }
            _ => {}
        }
    }

    let n = positions.len();
    for (t, tri) in corners.iter().enumerate() {
        for &(v, vn, _) in tri {
            if v as usize >= n {
                return Err(MeshError::IndexOutOfRange {
                    triangle: t,
                    index: u64::from(v),
                    vertices: n,
                });
            }
            if vn != NONE && vn as usize >= normals.len() {
                return Err(MeshError::Malformed {
                    format: "OBJ",
                    message: format!(
                        "triangle {t} uses normal index {} (1-based), but the file has {} normals",
                        u64::from(vn) + 1,
                        normals.len()
                    ),
                });
            }
        }
    }
    if corners.is_empty() {
        return Err(MeshError::NoTriangles);
    }

    for c in corners.iter_mut().flatten() {
        if c.2 != NONE && c.2 as usize >= texcoords.len() {
            c.2 = NONE;
        }
    }
    let mut warnings = Vec::new();
    let mut materials = if material_names.is_empty() {
        Vec::new()
    } else {
        resolve_materials(&material_names, &libraries, sidecars, &mut warnings)
    };
    if material_names.is_empty() && !libraries.is_empty() {
        warnings.push(format!(
            "mtllib {} is named but no face uses a material (no `usemtl`)",
            libraries.join(", ")
        ));
    }
    // Texture coordinates only when a material samples a texture.
    let is_textured: Vec<bool> = materials
        .iter()
        .map(|f| f.material.maps.is_some())
        .collect();
    let textured = |m: u32| is_textured.get(m as usize).copied().unwrap_or(false);
    let use_uvs = triangle_materials.iter().any(|&m| textured(m));
    if use_uvs {
        let missing = corners
            .iter()
            .zip(&triangle_materials)
            .filter(|(t, m)| textured(**m) && t.iter().any(|c| c.2 == NONE))
            .count();
        if missing > 0 {
            // Those faces get the factor alone: their material without its texture.
            let mut plain: HashMap<u32, u32> = HashMap::new();
            for (t, m) in corners.iter().zip(triangle_materials.iter_mut()) {
                if textured(*m) && t.iter().any(|c| c.2 == NONE) {
                    *m = *plain.entry(*m).or_insert_with(|| {
                        let mut copy = materials[*m as usize].clone();
                        if let Some(crate::material::MaterialMaps::Diffuse { kd, .. }) =
                            copy.material.maps.take()
                        {
                            copy.material.albedo = kd;
                        }
                        copy.material.name.push_str(" (no vt)");
                        materials.push(copy);
                        materials.len() as u32 - 1
                    });
                }
            }
            warnings.push(format!(
                "{missing} faces with a map_Kd material name no texture coordinate (`vt`): the \
                 Kd alone is used there"
            ));
        }
    }
    let mut mesh = if all_have_normals || use_uvs {
        // One vertex per distinct corner, ordered by v, then vn, then vt.
        let key = |c: &(u32, u32, u32)| {
            (
                c.0,
                if all_have_normals { c.1 } else { NONE },
                if use_uvs { c.2 } else { NONE },
            )
        };
        let mut keys: Vec<(u32, u32, u32)> = corners.iter().flatten().map(key).collect();
        keys.sort_unstable();
        keys.dedup();
        let index = |c: &(u32, u32, u32)| keys.binary_search(&key(c)).map_or(0, |i| i as u32);
        let triangles = corners.iter().map(|t| t.map(|c| index(&c))).collect();
        Mesh {
            positions: keys
                .iter()
                .map(|&(v, _, _)| positions[v as usize])
                .collect(),
            normals: if all_have_normals {
                keys.iter()
                    .map(|&(_, vn, _)| normals[vn as usize])
                    .collect()
            } else {
                Vec::new()
            },
            triangles,
            material_ids: Vec::new(),
            uvs: if use_uvs {
                keys.iter()
                    .map(|&(_, _, vt)| texcoords.get(vt as usize).copied().unwrap_or(Vec2::ZERO))
                    .collect()
            } else {
                Vec::new()
            },
        }
    } else {
        Mesh {
            positions,
            normals: Vec::new(),
            triangles: corners.iter().map(|t| t.map(|c| c.0)).collect(),
            material_ids: Vec::new(),
            uvs: Vec::new(),
        }
    };
    if !material_names.is_empty() {
        mesh.material_ids = triangle_materials;
    }
    Ok(Raw {
        mesh,
        materials,
        camera: None,
        punctual: Vec::new(),
        suns: Vec::new(),
        warnings,
    })
}

/// The materials of `names` (index 0: faces before any `usemtl`), from the libraries next to
/// the file. Whatever cannot be found gets the default material and a warning.
fn resolve_materials(
    names: &[String],
    libraries: &[String],
    sidecars: &Sidecars<'_>,
    warnings: &mut Vec<String>,
) -> Vec<FileMaterial> {
    let mut libs: Vec<Library> = Vec::new();
    for name in libraries {
        // A material library is small; a huge one is refused rather than read.
        match sidecars.read(name, 16 << 20) {
            Ok(bytes) => {
                let lib = Library::parse(&bytes);
                for what in &lib.ignored {
                    warnings.push(format!("{name}: {what} ignored"));
                }
                libs.push(lib);
            }
            Err(e) => warnings.push(format!(
                "mtllib {name:?} could not be read: {e}; its materials get default values"
            )),
        }
    }
    let mut textures: HashMap<String, Option<std::sync::Arc<crate::texture::Texture>>> =
        HashMap::new();
    let mut texels = 0u64;
    let mut map_kd = |file: &str, warnings: &mut Vec<String>| {
        if let Some(t) = textures.get(file) {
            return t.clone();
        }
        // A PNG or JPEG of the largest texture allowed is far below 256 MiB.
        let read = sidecars
            .read(file, 256 << 20)
            .map_err(|e| e.to_string())
            .and_then(|b| crate::texture::Texture::decode(&b, file))
            .and_then(|t| {
                let n = u64::from(t.width) * u64::from(t.height);
                texels = texels.saturating_add(n);
                if texels > crate::texture::MAX_ASSET_TEXELS {
                    Err(format!(
                        "the asset's textures would exceed {} texels in all",
                        crate::texture::MAX_ASSET_TEXELS
                    ))
                } else {
                    Ok(std::sync::Arc::new(t))
                }
            });
        let t = match read {
            Ok(t) => Some(t),
            Err(e) => {
                warnings.push(format!(
                    "texture {file:?} could not be read: {e}; using the factor alone"
                ));
                None
            }
        };
        textures.insert(file.to_string(), t.clone());
        t
    };
    names
        .iter()
        .enumerate()
        .map(|(i, name)| {
            if let Some((lib, mut m)) = libs.iter().find_map(|l| Some((l, l.material(name)?)))
                && let Some(file) = lib.map_kd(name)
                && let Some(texture) = map_kd(file, warnings)
            {
                let maps = crate::material::MaterialMaps::Diffuse {
                    kd: m.material.albedo,
                    texture: crate::texture::TextureRef {
                        texture,
                        wrap: [crate::texture::Wrap::Repeat; 2],
                        transform: None,
                    },
                };
                m.material.albedo = maps.at_mean(&m.material).albedo;
                m.material.maps = Some(maps);
                return m;
            }
            if i == 0 && name.is_empty() {
                return FileMaterial {
                    material: Material {
                        name: "(no usemtl)".into(),
                        ..Material::default()
                    },
                    ..FileMaterial::default()
                };
            }
            libs.iter()
                .find_map(|l| l.material(name))
                .unwrap_or_else(|| {
                    if !libs.is_empty() {
                        warnings.push(format!(
                            "usemtl {name:?}: no such material in the material libraries;                              default values used"
                        ));
                    }
                    FileMaterial {
                        material: Material {
                            name: name.clone(),
                            ..Material::default()
                        },
                        ..FileMaterial::default()
                    }
                })
        })
        .collect()
}

fn read_vec3<'a>(words: &mut impl Iterator<Item = &'a [u8]>) -> Option<Vec3> {
    let mut v = [0f32; 3];
    for x in &mut v {
        *x = std::str::from_utf8(words.next()?).ok()?.parse().ok()?;
    }
    Some(Vec3::from(v))
}

enum CornerError {
    /// A positive position index too large for any mesh (0-based).
    OutOfRange(u64),
    Bad(String),
}

/// One face corner `v[/vt[/vn]]` as 0-based (position, normal or [`NONE`], texture
/// coordinate or [`NONE`]).
fn parse_corner(
    word: &[u8],
    positions: usize,
    normals: usize,
    texcoords: usize,
) -> Result<(u32, u32, u32), CornerError> {
    let text = std::str::from_utf8(word)
        .map_err(|_| CornerError::Bad("a face corner is not text".into()))?;
    let mut parts = text.split('/');
    let v = parts.next().unwrap_or("");
    let vt = parts.next();
    let vn = parts.next();
    if parts.next().is_some() {
        return Err(CornerError::Bad(format!(
            "bad face corner {:?} (expected v, v/vt, v//vn or v/vt/vn)",
            truncate(text)
        )));
    }
    let v = resolve(v, positions, "vertex")?;
    let vn = match vn {
        None | Some("") => NONE,
        Some(s) => resolve(s, normals, "normal")?,
    };
    // Texture coordinates are read only for textured materials: an unreadable `vt` index is
    // "none" (such a face then gets its material's factor alone), never an error.
    let vt = match vt {
        None | Some("") => NONE,
        Some(s) => resolve(s, texcoords, "texture coordinate").unwrap_or(NONE),
    };
    Ok((v, vn, vt))
}

/// A 1-based or negative (relative) OBJ index as a 0-based index.
fn resolve(s: &str, defined: usize, what: &str) -> Result<u32, CornerError> {
    let i: i64 = s
        .parse()
        .map_err(|_| CornerError::Bad(format!("bad {what} index {:?} in a face", truncate(s))))?;
    let zero_based = if i > 0 {
        i - 1
    } else if i < 0 {
        let r = (defined as i64).saturating_add(i);
        if r < 0 {
            return Err(CornerError::Bad(format!(
                "relative {what} index {i} reaches before the first {what} ({defined} defined so far)"
            )));
        }
        r
    } else {
        return Err(CornerError::Bad(format!(
            "{what} index 0 (OBJ indices start at 1)"
        )));
    };
    // NONE (u32::MAX) is reserved; no mesh can have that many vertices anyway.
    match u32::try_from(zero_based) {
        Ok(x) if x != NONE => Ok(x),
        _ if what == "vertex" => Err(CornerError::OutOfRange(zero_based as u64)),
        _ => Err(CornerError::Bad(format!(
            "{what} index {i} is out of range"
        ))),
    }
}

fn truncate(s: &str) -> String {
    s.chars().take(40).collect()
}
