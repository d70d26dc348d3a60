//! Mesh import: glTF 2.0 (`.gltf`, `.glb`), Wavefront OBJ and PLY into a validated [`Mesh`].
//!
//! Every importer treats its input as hostile: files come from users and, through the server's
//! upload endpoint, from the network. No importer panics on any input, and none allocates what a
//! header or a JSON count merely claims: counts are checked against the size of the file (and
//! against [`Limits`]) before anything is reserved.
//!
//! What every returned mesh looks like:
//!
//! - triangles only (polygons are fan-triangulated; points and lines are skipped), with
//!   degenerate triangles (a repeated vertex index) dropped;
//! - vertices that no triangle uses dropped, the rest kept in file order;
//! - `material_ids` index [`Asset::materials`] (all 0 when the file has no materials: PLY, an
//!   OBJ without `usemtl`);
//! - triangles whose material emits are not in the mesh: they are the asset's lamps
//!   ([`Asset::lights`], merged by `lamps.rs`), and a lamp is not an occluder;
//! - unit normals: the file's own when every vertex has a finite, non-zero one, otherwise
//!   [`Mesh::compute_normals`];
//! - [`Mesh::validate`] passes.
//!
//! A NaN or infinite coordinate anywhere in the file is an error ([`MeshError::NonFinitePosition`],
//! numbered as in the file), even on a vertex no triangle uses.
//!
//! Which parts are hand-written and why is explained in each format's module (`gltf.rs`,
//! `obj.rs`, `ply.rs`): glTF uses the `gltf` crate for JSON parsing and validation only and reads
//! the binary data itself; OBJ and PLY are read by small careful parsers.

use std::collections::BTreeMap;
use std::path::Path;

use glam::Vec3;

use crate::camera::Camera;
use crate::error::MeshError;
use crate::light::{PolygonLight, PunctualLight, SunLight};
use crate::material::Material;
use crate::mesh::Mesh;
use crate::texture::TextureRef;

mod gltf;
mod lamps;
mod mtl;
mod obj;
mod ply;
mod sidecar;

use sidecar::Sidecars;
pub use sidecar::sidecar_name;

/// An imported file: its geometry and what it says about materials, lamps and the camera.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Asset {
    /// The geometry without the emitting triangles; `material_ids` index `materials`.
    pub mesh: Mesh,
    /// The file's materials (empty when it has none; then every id is 0).
    pub materials: Vec<Material>,
    /// The lamps: emitting triangles merged into convex polygons, most powerful first.
    pub lights: Vec<PolygonLight>,
    /// `KHR_lights_punctual` point and spot lights, placed by their nodes.
    pub punctual: Vec<PunctualLight>,
    /// `KHR_lights_punctual` directional lights, turned by their nodes.
    pub suns: Vec<SunLight>,
    /// The file's first perspective camera, placed by its node.
    pub camera: Option<Camera>,
    /// What the file holds that was not used (textures, extensions, punctual lights, …), one
    /// sentence each.
    pub warnings: Vec<String>,
    /// The other files read (material libraries, textures, external buffers), relative to the
    /// asset, in the order first read: what an upload of the asset must carry with it.
    pub files: Vec<String>,
}

/// A material as read from a file, before the emitters are split out.
#[derive(Clone, Debug, Default)]
pub(crate) struct FileMaterial {
    pub material: Material,
    /// Emitted radiance, linear RGB (zero: not a lamp).
    pub emission: [f32; 3],
    /// Emits (and is seen) from both sides.
    pub two_sided: bool,
    /// glTF `emissiveTexture` (it becomes the lamp's texture).
    pub emissive_texture: Option<TextureRef>,
}

/// What a format's reader hands to [`finish_asset`].
#[derive(Default)]
pub(crate) struct Raw {
    /// Positions, triangles, optional per-position normals; `material_ids` one per triangle
    /// (indexing `materials`) or empty.
    pub mesh: Mesh,
    pub materials: Vec<FileMaterial>,
    pub camera: Option<Camera>,
    pub punctual: Vec<PunctualLight>,
    pub suns: Vec<SunLight>,
    pub warnings: Vec<String>,
}

/// Mesh file formats bspvt reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// glTF 2.0 JSON (`.gltf`), buffers embedded as `data:` URIs or in files next to it.
    Gltf,
    /// Binary glTF 2.0 (`.glb`).
    Glb,
    /// Wavefront OBJ (`.obj`).
    Obj,
    /// Stanford PLY (`.ply`): ASCII, binary little-endian or binary big-endian.
    Ply,
}

impl Format {
    /// The format of a file, chosen by its extension (case-insensitive).
    pub(crate) fn from_path(path: &Path) -> Result<Format, MeshError> {
        let unsupported = || MeshError::UnsupportedFormat(path.display().to_string());
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .ok_or_else(unsupported)?;
        Format::from_extension(ext).ok_or_else(unsupported)
    }

    /// The format of a file name (for example an upload's `filename`), by its extension.
    pub fn from_name(file_name: &str) -> Result<Format, MeshError> {
        let unsupported = || MeshError::UnsupportedFormat(file_name.to_string());
        let (_, ext) = file_name.rsplit_once('.').ok_or_else(unsupported)?;
        Format::from_extension(ext).ok_or_else(unsupported)
    }

    /// The format for an extension without its dot (`"glb"`, `"PLY"`), case-insensitive.
    pub(crate) fn from_extension(ext: &str) -> Option<Format> {
        match ext.to_ascii_lowercase().as_str() {
            "gltf" => Some(Format::Gltf),
            "glb" => Some(Format::Glb),
            "obj" => Some(Format::Obj),
            "ply" => Some(Format::Ply),
            _ => None,
        }
    }

    /// The format's name as used in error messages.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Format::Gltf => "glTF",
            Format::Glb => "GLB",
            Format::Obj => "OBJ",
            Format::Ply => "PLY",
        }
    }
}

/// Size limits an import enforces before it allocates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Most vertices a mesh may have (as declared by the file, and after import).
    pub max_vertices: u64,
    /// Most triangles a mesh may have (after triangulation).
    pub max_triangles: u64,
    /// Most bytes read: the file itself plus any external glTF buffers it names.
    pub max_bytes: u64,
}

impl Default for Limits {
    /// 20 M vertices, 40 M triangles, 2 GiB.
    fn default() -> Self {
        Limits {
            max_vertices: 20_000_000,
            max_triangles: 40_000_000,
            max_bytes: 2 << 30,
        }
    }
}

impl Limits {
    /// The vertex limit, also capped by what a `u32` index can address.
    pub(crate) fn vertex_cap(&self) -> u64 {
        self.max_vertices.min(u64::from(u32::MAX))
    }

    pub(crate) fn check_vertices(&self, count: u64) -> Result<(), MeshError> {
        if count > self.vertex_cap() {
            return Err(MeshError::TooLarge {
                what: "vertices",
                count,
                limit: self.vertex_cap(),
            });
        }
        Ok(())
    }

    pub(crate) fn check_triangles(&self, count: u64) -> Result<(), MeshError> {
        if count > self.max_triangles {
            return Err(MeshError::TooLarge {
                what: "triangles",
                count,
                limit: self.max_triangles,
            });
        }
        Ok(())
    }

    pub(crate) fn check_bytes(&self, count: u64) -> Result<(), MeshError> {
        if count > self.max_bytes {
            return Err(MeshError::TooLarge {
                what: "bytes",
                count,
                limit: self.max_bytes,
            });
        }
        Ok(())
    }
}

/// Loads a mesh file's geometry with the default [`Limits`] ([`load_asset`]'s mesh).
pub fn load_mesh(path: &Path) -> Result<Mesh, MeshError> {
    load_asset(path).map(|a| a.mesh)
}

/// Loads an asset file with the default [`Limits`], choosing the format by extension. Its other
/// files (OBJ material libraries and textures, external glTF buffers and images) are read
/// from beside it.
pub fn load_asset(path: &Path) -> Result<Asset, MeshError> {
    load_asset_with_limits(path, &Limits::default())
}

/// [`load_asset`] with explicit limits.
pub(crate) fn load_asset_with_limits(path: &Path, limits: &Limits) -> Result<Asset, MeshError> {
    let format = Format::from_path(path)?;
    let io = |source| MeshError::Io {
        path: path.display().to_string(),
        source,
    };
    // Check the size before reading so that a huge file is refused without being loaded.
    let len = std::fs::metadata(path).map_err(io)?.len();
    limits.check_bytes(len)?;
    let bytes = std::fs::read(path).map_err(io)?;
    limits.check_bytes(bytes.len() as u64)?;
    let base_dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    load(&bytes, format, limits, Sidecars::dir(&base_dir))
}

/// A mesh's geometry from memory ([`load_asset_bytes`]'s mesh).
pub fn load_mesh_bytes(bytes: &[u8], format: Format, limits: &Limits) -> Result<Mesh, MeshError> {
    load_asset_bytes(bytes, format, limits).map(|a| a.mesh)
}

/// Loads an asset from memory, alone: an external glTF buffer or image is an error, an OBJ's
/// material library a warning ([`load_asset_uploaded`] with no files).
pub fn load_asset_bytes(bytes: &[u8], format: Format, limits: &Limits) -> Result<Asset, MeshError> {
    load_asset_uploaded(bytes, format, limits, &BTreeMap::new())
}

/// Loads an asset from memory (an HTTP upload) with the other files uploaded with it, keyed by
/// [`sidecar_name`]; only those are read, never a file on this machine.
pub fn load_asset_uploaded(
    bytes: &[u8],
    format: Format,
    limits: &Limits,
    files: &BTreeMap<String, Vec<u8>>,
) -> Result<Asset, MeshError> {
    load(bytes, format, limits, Sidecars::uploaded(files))
}

/// [`load_asset_uploaded`] without the check for repeated triangles: for a caller that runs
/// [`repeats_warning`] on the mesh it bakes beside other work (the service, while it stores
/// the scene; on a scanned mesh of a million triangles the check is a tenth of a second).
pub fn parse_asset_uploaded(
    bytes: &[u8],
    format: Format,
    limits: &Limits,
    files: &BTreeMap<String, Vec<u8>>,
) -> Result<Asset, MeshError> {
    parse(bytes, format, limits, Sidecars::uploaded(files))
}

/// The warning for the triangles the ray casters leave out ([`Mesh::unique_triangles`]:
/// copies of another triangle and single points), if there are any.
pub fn repeats_warning(mesh: &Mesh) -> Option<String> {
    let left_out = mesh.triangles.len() - mesh.unique_triangles().len();
    (left_out > 0).then(|| {
        format!(
            "{left_out} triangles repeat another triangle's corners or are a single point: kept \
             for shading, left out of the rays' BVH (they change no ray's answer)"
        )
    })
}

/// [`parse`] and the warning for repeated triangles.
fn load(
    bytes: &[u8],
    format: Format,
    limits: &Limits,
    sidecars: Sidecars<'_>,
) -> Result<Asset, MeshError> {
    let mut asset = parse(bytes, format, limits, sidecars)?;
    asset.warnings.extend(repeats_warning(&asset.mesh));
    Ok(asset)
}

fn parse(
    bytes: &[u8],
    format: Format,
    limits: &Limits,
    sidecars: Sidecars<'_>,
) -> Result<Asset, MeshError> {
    limits.check_bytes(bytes.len() as u64)?;
    if bytes.is_empty() {
        return Err(MeshError::Malformed {
            format: format.name(),
            message: "the file is empty".into(),
        });
    }
    let mut asset = match format {
        Format::Gltf | Format::Glb => finish_asset(gltf::parse(bytes, &sidecars, limits)?)?,
        Format::Obj => finish_asset(obj::parse(bytes, &sidecars, limits)?)?,
        Format::Ply => Asset {
            mesh: ply::parse(bytes, limits)?,
            ..Asset::default()
        },
    };
    asset.files = sidecars.into_read();
    Ok(asset)
}

/// The last step of the glTF and OBJ readers: checks indices and coordinates, takes the
/// emitting triangles out as lamps, then settles the mesh as [`finish`] does (material ids
/// kept).
pub(crate) fn finish_asset(raw: Raw) -> Result<Asset, MeshError> {
    let Raw {
        mut mesh,
        materials,
        camera,
        punctual,
        suns,
        mut warnings,
    } = raw;
    check_indices(&mesh)?;
    if mesh.material_ids.len() != mesh.triangles.len() || materials.is_empty() {
        mesh.material_ids = vec![0; mesh.triangles.len()];
    }
    let file_normals = usable_normals(&mesh.normals, mesh.positions.len());
    let emits = |m: u32| {
        materials
            .get(m as usize)
            .is_some_and(|f| f.emission.iter().any(|&e| e > 0.0))
    };
    let mut emitters = Vec::new();
    let has_uvs = mesh.uvs.len() == mesh.positions.len();
    let mut kept = Mesh {
        positions: std::mem::take(&mut mesh.positions),
        normals: std::mem::take(&mut mesh.normals),
        uvs: std::mem::take(&mut mesh.uvs),
        ..Mesh::default()
    };
    for (t, &m) in mesh.triangles.iter().zip(&mesh.material_ids) {
        if !emits(m) {
            kept.triangles.push(*t);
            kept.material_ids.push(m);
            continue;
        }
        let corners = t.map(|i| kept.positions[i as usize]);
        let normal_hint = if file_normals {
            t.iter()
                .map(|&i| kept.normals[i as usize].normalize())
                .sum()
        } else {
            (corners[1] - corners[0]).cross(corners[2] - corners[0])
        };
        let f = &materials[m as usize];
        emitters.push(lamps::Emitter {
            corners,
            normal_hint,
            radiance: f.emission,
            two_sided: f.two_sided,
            texture: f
                .emissive_texture
                .clone()
                .filter(|_| has_uvs)
                .map(|tex| (tex, t.map(|i| kept.uvs[i as usize]))),
        });
    }
    let mut lamps = lamps::merge(&emitters);
    for (light, group) in lamps.lights.iter_mut().zip(&lamps.groups) {
        let Some((tex, _)) = group.first().and_then(|&e| emitters[e].texture.as_ref()) else {
            continue;
        };
        match lamps::lamp_image(light, group, &emitters) {
            Ok(image) => light.image = Some(std::sync::Arc::new(image)),
            Err(why) => {
                let mean = tex.texture.mean(true);
                for (r, m) in light.radiance.iter_mut().zip(mean) {
                    *r *= m;
                }
                warnings.push(format!(
                    "the lamp of emissive texture {:?}: {why}; its mean is used as a \
                     constant radiance",
                    tex.texture.name
                ));
            }
        }
    }
    if lamps.dropped > 0 {
        warnings.push(format!(
            "{} emitting polygons beyond the {} most powerful were not made lights",
            lamps.dropped,
            lamps::MAX_LAMPS
        ));
    }
    if lamps.degenerate > 0 {
        warnings.push(format!(
            "{} emitting triangles have no area and were skipped",
            lamps.degenerate
        ));
    }
    if kept.triangles.is_empty() {
        return Err(MeshError::Invalid(format!(
            "every one of the {} triangles emits light: nothing is left to light",
            mesh.triangles.len()
        )));
    }
    // UVs only where a kept triangle's material samples a texture.
    if !kept.material_ids.iter().any(|&m| {
        materials
            .get(m as usize)
            .is_some_and(|f| f.material.samples_uvs())
    }) {
        kept.uvs.clear();
    }
    let ids = std::mem::take(&mut kept.material_ids);
    let mut mesh = finish(kept)?;
    mesh.material_ids = ids;
    Ok(Asset {
        mesh,
        materials: materials.into_iter().map(|f| f.material).collect(),
        lights: lamps.lights,
        punctual,
        suns,
        camera,
        warnings,
        files: Vec::new(),
    })
}

/// Every triangle's indices in range and every position finite.
fn check_indices(mesh: &Mesh) -> Result<(), MeshError> {
    if mesh.triangles.is_empty() {
        return Err(MeshError::NoTriangles);
    }
    if let Some(i) = mesh.positions.iter().position(|p| !p.is_finite()) {
        return Err(MeshError::NonFinitePosition { vertex: i });
    }
    let n = mesh.positions.len();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if let Some(&i) = tri.iter().find(|&&i| i as usize >= n) {
            return Err(MeshError::IndexOutOfRange {
                triangle: t,
                index: u64::from(i),
                vertices: n,
            });
        }
    }
    Ok(())
}

/// Shared last step of every importer: checks indices and coordinates, drops unused vertices,
/// settles the normals (the file's when complete and usable, else computed) and validates.
///
/// `mesh.normals` is either one per position (the file's normals) or empty.
pub(crate) fn finish(mut mesh: Mesh) -> Result<Mesh, MeshError> {
    check_indices(&mesh)?;
    let n = mesh.positions.len();
    if mesh.normals.len() != n {
        mesh.normals.clear();
    }
    if mesh.uvs.len() != n {
        mesh.uvs.clear();
    }
    mesh.drop_unused_vertices();
    mesh.material_ids = vec![0; mesh.triangles.len()];
    if usable_normals(&mesh.normals, mesh.positions.len()) {
        for v in &mut mesh.normals {
            *v = v.normalize();
        }
    } else {
        mesh.compute_normals();
    }
    mesh.validate()?;
    Ok(mesh)
}

/// Whether `normals` has one finite, non-zero normal per vertex (normalisable without NaN).
pub(crate) fn usable_normals(normals: &[Vec3], vertices: usize) -> bool {
    normals.len() == vertices
        && normals.iter().all(|n| {
            let l = n.length_squared();
            n.is_finite() && l.is_finite() && l > 1e-30
        })
}

/// Whether a triangle repeats a vertex index.
pub(crate) fn is_degenerate(t: &[u32; 3]) -> bool {
    t[0] == t[1] || t[1] == t[2] || t[0] == t[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_by_extension() {
        assert_eq!(
            Format::from_path(Path::new("a/b/Model.GLB")).ok(),
            Some(Format::Glb)
        );
        assert_eq!(Format::from_name("x.tar.ply").ok(), Some(Format::Ply));
        assert_eq!(Format::from_name("scene.gltf").ok(), Some(Format::Gltf));
        assert_eq!(Format::from_name("teapot.Obj").ok(), Some(Format::Obj));
        assert!(matches!(
            Format::from_name("mesh.stl"),
            Err(MeshError::UnsupportedFormat(_))
        ));
        assert!(matches!(
            Format::from_name("noext"),
            Err(MeshError::UnsupportedFormat(_))
        ));
        assert!(Format::from_path(Path::new("")).is_err());
    }
}
