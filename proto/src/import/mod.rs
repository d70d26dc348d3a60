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
//! - `material_ids` all 0 (files carry no materials bspvt reads; a scene assigns them);
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

use std::path::Path;

use glam::Vec3;

use crate::error::MeshError;
use crate::mesh::Mesh;

mod gltf;
mod obj;
mod ply;

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

/// Loads a mesh file with the default [`Limits`], choosing the format by extension. Relative
/// external glTF buffers are resolved next to the file.
pub fn load_mesh(path: &Path) -> Result<Mesh, MeshError> {
    load_mesh_with_limits(path, &Limits::default())
}

/// [`load_mesh`] with explicit limits.
pub(crate) fn load_mesh_with_limits(path: &Path, limits: &Limits) -> Result<Mesh, MeshError> {
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
    load(&bytes, format, limits, Some(&base_dir))
}

/// Loads a mesh from memory (an HTTP upload). glTF files must be self-contained: external
/// buffer and image URIs are rejected; only `data:` URIs and a GLB's BIN chunk are read.
pub fn load_mesh_bytes(bytes: &[u8], format: Format, limits: &Limits) -> Result<Mesh, MeshError> {
    load(bytes, format, limits, None)
}

fn load(
    bytes: &[u8],
    format: Format,
    limits: &Limits,
    base_dir: Option<&Path>,
) -> Result<Mesh, MeshError> {
    limits.check_bytes(bytes.len() as u64)?;
    if bytes.is_empty() {
        return Err(MeshError::Malformed {
            format: format.name(),
            message: "the file is empty".into(),
        });
    }
    match format {
        Format::Gltf | Format::Glb => gltf::parse(bytes, base_dir, limits),
        Format::Obj => obj::parse(bytes, limits),
        Format::Ply => ply::parse(bytes, limits),
    }
}

/// Shared last step of every importer: checks indices and coordinates, drops unused vertices,
/// settles the normals (the file's when complete and usable, else computed) and validates.
///
/// `mesh.normals` is either one per position (the file's normals) or empty.
pub(crate) fn finish(mut mesh: Mesh) -> Result<Mesh, MeshError> {
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
    if mesh.normals.len() != n {
        mesh.normals.clear();
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
