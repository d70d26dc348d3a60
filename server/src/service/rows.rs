//! What both databases (`db`'s SQLite, `pg`'s PostgreSQL) hold, as the rest of the service
//! sees it: a scene's row, a durable chunk's record, the listing's summaries.

pub(crate) use bspvt_proto::api::JobState;

/// What the database records of a durable chunk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct ChunkMeta {
    /// Length of the chunk frame in bytes.
    pub bytes: u32,
    /// CRC-32 of the whole frame file.
    pub crc32: u32,
}

/// A scene's row.
#[derive(Clone, Debug)]
pub(crate) struct SceneRow {
    pub id: String,
    pub seq: i64,
    pub state: JobState,
    pub reason: Option<String>,
    pub created_ms: i64,
    pub started_ms: Option<i64>,
    pub finished_ms: Option<i64>,
    pub vertex_count: u32,
    pub triangle_count: u64,
    pub chunk_count: u32,
    pub chunk_vertices: u32,
    /// The bake settings as JSON (for display; the bake reads the stored scene).
    pub settings_json: String,
    pub mesh_hash: u64,
    /// The encoded bake header frame, sent first on every tree stream.
    pub header: Vec<u8>,
    pub upload_bytes: u64,
    /// How the scene was submitted, in words.
    pub source: String,
    /// Chunks baked for this scene over all runs (re-bakes included).
    pub chunks_baked: u64,
    /// Stored chunks found corrupt and re-baked.
    pub chunks_corrupt: u64,
    /// What the importer did not use or added (JSON list of sentences).
    pub warnings: Vec<String>,
}

/// A scene as the listing shows it (from its row and its chunk rows).
#[derive(Clone, Debug)]
pub(crate) struct SceneSummary {
    pub id: String,
    pub state: JobState,
    pub reason: Option<String>,
    pub created_ms: i64,
    pub finished_ms: Option<i64>,
    pub vertex_count: u32,
    pub chunk_count: u32,
    pub chunks_done: u32,
    pub source: String,
}

/// The scene an `Idempotency-Key` created, and the fingerprint of the request that did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct IdempotentRecord {
    pub fingerprint: String,
    pub scene_id: String,
    pub created_ms: i64,
}

/// Milliseconds since the Unix epoch.
pub(crate) fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}
