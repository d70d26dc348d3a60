//! Errors for user-supplied data. Every variant names what is wrong in words a user can act on.

use thiserror::Error;

/// A mesh file that cannot be used.
#[derive(Debug, Error)]
pub enum MeshError {
    #[error("cannot read mesh file {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("unsupported mesh format {0:?} (expected .glb, .gltf, .obj or .ply)")]
    UnsupportedFormat(String),
    #[error("mesh has no triangles")]
    NoTriangles,
    #[error("vertex {vertex} has a NaN or infinite coordinate")]
    NonFinitePosition { vertex: usize },
    #[error("triangle {triangle} uses vertex index {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        triangle: usize,
        index: u64,
        vertices: usize,
    },
    #[error("mesh declares {declared} {what}, which cannot fit in a file of {file_bytes} bytes")]
    AbsurdCount {
        what: &'static str,
        declared: u64,
        file_bytes: u64,
    },
    #[error("mesh is too large: {what} = {count} exceeds the limit of {limit}")]
    TooLarge {
        what: &'static str,
        count: u64,
        limit: u64,
    },
    #[error("malformed {format} file: {message}")]
    Malformed {
        format: &'static str,
        message: String,
    },
    #[error("invalid mesh: {0}")]
    Invalid(String),
}

/// A scene file that cannot be used.
#[derive(Debug, Error)]
pub enum SceneError {
    #[error("cannot read scene file {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("scene file is not valid JSON for the bspvt scene format: {0}")]
    Json(#[from] serde_json::Error),
    #[error("scene mesh: {0}")]
    Mesh(#[from] MeshError),
    #[error("invalid scene: {0}")]
    Invalid(String),
}

/// Encoded trees that cannot be decoded. Decoding never trusts a length it has not checked.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum DecodeError {
    #[error("not a bspvt file (bad magic)")]
    BadMagic,
    #[error("unsupported format version {found} (this build reads {supported})")]
    Version { found: u16, supported: u16 },
    #[error("truncated data: {0}")]
    Truncated(&'static str),
    #[error("chunk checksum mismatch (stored {stored:#010x}, computed {computed:#010x})")]
    Checksum { stored: u32, computed: u32 },
    #[error("limit exceeded: {what} = {value} > {limit}")]
    Limit {
        what: &'static str,
        value: u64,
        limit: u64,
    },
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
