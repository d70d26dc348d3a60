//! Errors for user-supplied data. Every variant names what is wrong in words a user can act on.

use thiserror::Error;

/// A mesh file that cannot be used.
#[derive(Debug, Error)]
pub enum MeshError {
    /// The file cannot be read.
    #[error("cannot read mesh file {path}: {source}")]
    Io {
        /// The file's path, as given.
        path: String,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// The file's extension names no format this crate reads.
    #[error("unsupported mesh format {0:?} (expected .glb, .gltf, .obj or .ply)")]
    UnsupportedFormat(String),
    /// The mesh has no triangle.
    #[error("mesh has no triangles")]
    NoTriangles,
    /// A position is NaN or infinite.
    #[error("vertex {vertex} has a NaN or infinite coordinate")]
    NonFinitePosition {
        /// Index of the vertex.
        vertex: usize,
    },
    /// A triangle refers to a vertex the mesh does not have.
    #[error("triangle {triangle} uses vertex index {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        /// Index of the triangle.
        triangle: usize,
        /// The vertex index it uses.
        index: u64,
        /// Number of vertices in the mesh.
        vertices: usize,
    },
    /// A declared count that the file's size rules out (checked before allocating).
    #[error("mesh declares {declared} {what}, which cannot fit in a file of {file_bytes} bytes")]
    AbsurdCount {
        /// What is counted (`vertices`, `accessor elements`, …).
        what: &'static str,
        /// The count the file declares.
        declared: u64,
        /// The file's size in bytes.
        file_bytes: u64,
    },
    /// A count over the caller's [`crate::import::Limits`].
    #[error("mesh is too large: {what} = {count} exceeds the limit of {limit}")]
    TooLarge {
        /// What is counted.
        what: &'static str,
        /// The count found.
        count: u64,
        /// The limit it exceeds.
        limit: u64,
    },
    /// The file does not follow its format.
    #[error("malformed {format} file: {message}")]
    Malformed {
        /// The format (`OBJ`, `PLY`, `glTF`, `GLB`).
        format: &'static str,
        /// What is wrong, in words.
        message: String,
    },
    /// The mesh was read but cannot be used (for instance, normals that do not match).
    #[error("invalid mesh: {0}")]
    Invalid(String),
}

/// A scene file that cannot be used.
#[derive(Debug, Error)]
pub enum SceneError {
    /// The file cannot be read.
    #[error("cannot read scene file {path}: {source}")]
    Io {
        /// The file's path, as given.
        path: String,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// The file is not JSON of the scene format (docs/scene-format.md).
    #[error("scene file is not valid JSON for the bspvt scene format: {0}")]
    Json(#[from] serde_json::Error),
    /// A mesh the scene names cannot be used.
    #[error("scene mesh: {0}")]
    Mesh(#[from] MeshError),
    /// The scene was read but a value is out of range or inconsistent.
    #[error("invalid scene: {0}")]
    Invalid(String),
}

/// Encoded trees that cannot be decoded. Decoding never trusts a length it has not checked.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum DecodeError {
    /// The data does not start with the bspvt magic.
    #[error("not a bspvt file (bad magic)")]
    BadMagic,
    /// A format version this build does not read.
    #[error("unsupported format version {found} (this build reads {supported})")]
    Version {
        /// The version in the data.
        found: u16,
        /// The version this build reads.
        supported: u16,
    },
    /// The data ends inside the named part.
    #[error("truncated data: {0}")]
    Truncated(&'static str),
    /// A frame's CRC-32 does not match its bytes.
    #[error("chunk checksum mismatch (stored {stored:#010x}, computed {computed:#010x})")]
    Checksum {
        /// The CRC-32 stored in the frame.
        stored: u32,
        /// The CRC-32 of the bytes read.
        computed: u32,
    },
    /// A declared size or count over the decoder's limits.
    #[error("limit exceeded: {what} = {value} > {limit}")]
    Limit {
        /// What is limited.
        what: &'static str,
        /// The value declared.
        value: u64,
        /// The limit.
        limit: u64,
    },
    /// The data is inconsistent (a bad node, an index out of range, …).
    #[error("corrupt data: {0}")]
    Corrupt(String),
}

/// One line for a user: the error and each cause whose text it does not already contain.
pub fn chain_message(err: &(dyn std::error::Error + 'static)) -> String {
    let mut msg = err.to_string();
    let mut cur = err.source();
    while let Some(e) = cur {
        let s = e.to_string();
        if !msg.contains(&s) {
            msg.push_str(": ");
            msg.push_str(&s);
        }
        cur = e.source();
    }
    msg
}

/// The exit status of a command-line tool, printing `error: …` (one line, see
/// [`chain_message`]) for a failure.
pub fn exit_code<E>(result: Result<(), E>) -> std::process::ExitCode
where
    E: AsRef<dyn std::error::Error + Send + Sync + 'static>,
{
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", chain_message(e.as_ref()));
            std::process::ExitCode::FAILURE
        }
    }
}
