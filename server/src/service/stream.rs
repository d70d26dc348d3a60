//! `GET /v1/scenes/{id}/trees`: the encoded trees, streamed chunk by chunk as they become
//! durable.
//!
//! The body is a bake file: the header frame, then the chunk frames covering the requested
//! vertices, in order (`vertices=A..B` selects the chunks that intersect `A..B`, so a stream
//! may start before `A` and end after `B`; the `X-Bspvt-Vertices` header says what it covers).
//! `faces=` keeps only the listed cube faces: each chunk is decoded, the other faces dropped,
//! and the chunk re-encoded (same encoder, deterministic), so the result is what a bake that
//! had no pixels on those faces would hold.
//!
//! Guarantees:
//! - a chunk is sent only after its file was read back and verified (length, CRC-32 against
//!   the database, frame CRC and position); a corrupt or missing chunk is re-baked and the
//!   stream waits for the new one — corrupt bytes are never sent;
//! - a client may connect before the bake ends: it gets the header at once and each chunk as
//!   soon as it is durable; if the bake fails or the scene is deleted meanwhile, the response
//!   is aborted (no clean end), so a client cannot mistake a partial stream for a whole one;
//! - the `ETag` (strong) is only given when every requested chunk is durable: it is derived
//!   from the header and each chunk's length and CRC-32, so equal tags mean equal bytes;
//!   `If-None-Match` then answers 304;
//! - memory per stream is one chunk; open streams are limited (`max_streams`, else 429).

use std::sync::Arc;
use std::sync::atomic::Ordering;

use axum::Extension;
use axum::body::{Body, Bytes};
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use bspvt_proto::bspvt::VertexTrees;
use bspvt_proto::cubemap::FACES;
use bspvt_proto::encoding::{BakeHeader, decode_chunk, decode_header, encode_chunk};
use bspvt_shaders::gpu::trees;
use tokio::sync::watch;

use super::clients::Client;
use super::db::{ChunkMeta, JobState, SceneRow};
use super::error::{ApiError, ApiResult, ErrorBody, gone};
use super::http::{not_modified, not_modified_response, query_pairs};
use super::jobs::{ChunkState, Live};
use super::state::{Shared, StreamGuard, blocking, lookup};
use super::store::ChunkRead;

/// All six faces.
pub(crate) const ALL_FACES: u8 = (1 << FACES) - 1;

/// Face names accepted by `faces=` (index = face).
const FACE_NAMES: [[&str; 2]; FACES] = [
    ["px", "+x"],
    ["nx", "-x"],
    ["py", "+y"],
    ["ny", "-y"],
    ["pz", "+z"],
    ["nz", "-z"],
];

/// What a tree request asks for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Selection {
    /// Chunk indices.
    pub chunks: std::ops::Range<u32>,
    /// Bit f set = face f kept.
    pub faces: u8,
    /// The encoding of the body.
    pub format: Format,
}

/// The body's encoding: the bake file's frames (`encoded`, the default), or the trees as the
/// GPU shaders read them (`gpu`, for the browser viewer: [`gpu_header`], [`gpu_chunk`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Format {
    Encoded,
    Gpu,
}

impl Selection {
    /// Parses `vertices=A..B` (also `A..`, `..B`) and `faces=LIST` against a scene.
    pub(crate) fn parse(q: Option<&str>, row: &SceneRow) -> ApiResult<Selection> {
        let n = row.vertex_count;
        let (mut range, mut faces, mut format) = (None, None, None);
        for (k, v) in query_pairs(q)? {
            match k.as_str() {
                "vertices" if range.is_none() => range = Some(parse_range(&v, n)?),
                "faces" if faces.is_none() => faces = Some(parse_faces(&v)?),
                "format" if format.is_none() => {
                    format = Some(match v.as_str() {
                        "encoded" => Format::Encoded,
                        "gpu" => Format::Gpu,
                        other => {
                            return Err(ApiError::bad_request(
                                "invalid_query",
                                format!(
                                    "format {:?} is neither encoded nor gpu",
                                    super::error::truncate(other, 40)
                                ),
                            ));
                        }
                    })
                }
                "vertices" | "faces" | "format" => {
                    return Err(ApiError::bad_request(
                        "invalid_query",
                        format!("`{k}` is given twice"),
                    ));
                }
                other => {
                    return Err(ApiError::bad_request(
                        "invalid_query",
                        format!(
                            "unknown query parameter {:?} (expected vertices, faces, format)",
                            super::error::truncate(other, 100)
                        ),
                    ));
                }
            }
        }
        let (a, b) = range.unwrap_or((0, n));
        let cv = row.chunk_vertices.max(1);
        Ok(Selection {
            chunks: a / cv..b.div_ceil(cv),
            faces: faces.unwrap_or(ALL_FACES),
            format: format.unwrap_or(Format::Encoded),
        })
    }
}

fn parse_range(v: &str, n: u32) -> ApiResult<(u32, u32)> {
    let bad = || {
        ApiError::bad_request(
            "invalid_range",
            format!(
                "vertices={:?} is not A..B, A.. or ..B",
                super::error::truncate(v, 60)
            ),
        )
    };
    let (a, b) = v.split_once("..").ok_or_else(bad)?;
    let num = |s: &str, default: u32| -> ApiResult<u32> {
        if s.is_empty() {
            Ok(default)
        } else {
            s.parse::<u32>().map_err(|_| bad())
        }
    };
    let (a, b) = (num(a, 0)?, num(b, n)?);
    if a >= b || b > n {
        return Err(ApiError::new(
            StatusCode::RANGE_NOT_SATISFIABLE,
            "invalid_range",
            format!("vertices {a}..{b} is empty or outside the scene's 0..{n}"),
        ));
    }
    Ok((a, b))
}

fn parse_faces(v: &str) -> ApiResult<u8> {
    if v == "all" {
        return Ok(ALL_FACES);
    }
    let mut mask = 0u8;
    for t in v.split(',').map(str::trim) {
        let f = t
            .parse::<usize>()
            .ok()
            .filter(|&f| f < FACES)
            .or_else(|| FACE_NAMES.iter().position(|names| names.contains(&t)))
            .ok_or_else(|| {
                ApiError::bad_request(
                    "invalid_faces",
                    format!(
                        "face {:?} is not 0-5 or one of px, nx, py, ny, pz, nz",
                        super::error::truncate(t, 20)
                    ),
                )
            })?;
        mask |= 1 << f;
    }
    Ok(mask)
}

/// Strong validator of a finished selection: FNV-1a over the header, the selection and each
/// chunk's length and CRC-32.
fn etag(row: &SceneRow, sel: &Selection, chunks: &[ChunkMeta]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for &b in bytes {
            h ^= b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    eat(&row.header);
    eat(&sel.chunks.start.to_le_bytes());
    eat(&sel.chunks.end.to_le_bytes());
    eat(&[sel.faces, sel.format as u8]);
    for m in chunks {
        eat(&m.bytes.to_le_bytes());
        eat(&m.crc32.to_le_bytes());
    }
    format!("\"t-{h:016x}\"")
}

/// The encoded trees of a scene, streamed as chunks become durable.
#[utoipa::path(
    get,
    path = "/v1/scenes/{id}/trees",
    tag = "scenes",
    params(
        ("id" = String, Path, description = "Scene id"),
        ("vertices" = Option<String>, Query, description = "`A..B` (end exclusive), `A..` or `..B`: the chunks intersecting this range are sent (default: all)"),
        ("faces" = Option<String>, Query, description = "Comma-separated faces to keep: 0-5 or px,nx,py,ny,pz,nz (default: all). Chunks are re-encoded without the other faces."),
        ("format" = Option<String>, Query, description = "`encoded` (default: the bake file's frames) or `gpu` (the node words and roots the GPU shaders read, for the browser viewer; docs/service.md)"),
    ),
    responses(
        (status = 200, description = "Header frame then chunk frames (docs/encoding.md). Headers: X-Bspvt-Vertices (covered range), X-Bspvt-Chunks, ETag when final.", content_type = "application/vnd.bspvt"),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 400, description = "Bad query", body = ErrorBody),
        (status = 404, description = "Unknown id", body = ErrorBody),
        (status = 409, description = "The bake failed", body = ErrorBody),
        (status = 410, description = "Deleted", body = ErrorBody),
        (status = 416, description = "Vertex range outside the scene", body = ErrorBody),
        (status = 429, description = "Too many open streams", body = ErrorBody),
    )
)]
pub(crate) async fn get_trees(
    State(st): State<Shared>,
    Path(id): Path<String>,
    RawQuery(q): RawQuery,
    headers: HeaderMap,
    client: Option<Extension<Client>>,
) -> ApiResult<Response> {
    let live = lookup(&st, &id).await?;
    let snap = live.snapshot();
    match snap.state {
        JobState::Cancelled => return Err(gone(&id)),
        JobState::Failed => {
            return Err(ApiError::new(
                StatusCode::CONFLICT,
                "bake_failed",
                format!(
                    "the bake failed: {}",
                    snap.reason.unwrap_or_else(|| "unknown reason".into())
                ),
            ));
        }
        _ => {}
    }
    let sel = Selection::parse(q.as_deref(), &live.row)?;
    let header = decode_header(&live.row.header)
        .map_err(|e| ApiError::internal(format!("stored bake header: {e}")))?
        .0;
    let durable = live.durable(sel.chunks.clone());
    let etag = durable.as_ref().map(|m| etag(&live.row, &sel, m));
    if let Some(e) = &etag
        && not_modified(&headers, e)
    {
        return Ok(not_modified_response(e));
    }
    let guard = StreamGuard::open(&st, client.map(|Extension(c)| c)).await?;
    let cv = live.row.chunk_vertices;
    let covered = format!(
        "{}..{}",
        sel.chunks.start * cv,
        (sel.chunks.end as u64 * cv as u64).min(live.row.vertex_count as u64)
    );
    let length = match &durable {
        Some(m) if sel.faces == ALL_FACES && sel.format == Format::Encoded => {
            Some(live.row.header.len() as u64 + m.iter().map(|c| c.bytes as u64).sum::<u64>())
        }
        _ => None,
    };
    let stream = TreeStream {
        st: st.clone(),
        rx: live.subscribe(),
        header_frame: Some(Bytes::from(match sel.format {
            Format::Encoded => live.row.header.clone(),
            Format::Gpu => gpu_header(&header),
        })),
        live,
        header,
        format: sel.format,
        next: sel.chunks.start,
        end: sel.chunks.end,
        faces: sel.faces,
        shutdown: st.shutdown.clone(),
        done: false,
        _guard: guard,
    };
    // Fused: a layer that polls again after the end (gzip's encoder does) gets `None`, not
    // `unfold`'s panic.
    let body = Body::from_stream(futures_util::StreamExt::fuse(futures_util::stream::unfold(
        stream,
        TreeStream::step,
    )));
    let mut r = body.into_response();
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(match sel.format {
            Format::Encoded => "application/vnd.bspvt",
            Format::Gpu => "application/vnd.bspvt-gpu",
        }),
    );
    if let Ok(v) = HeaderValue::from_str(&covered) {
        h.insert("x-bspvt-vertices", v);
    }
    if let Ok(v) = HeaderValue::from_str(&format!("{}..{}", sel.chunks.start, sel.chunks.end)) {
        h.insert("x-bspvt-chunks", v);
    }
    match &etag {
        Some(e) => {
            if let Ok(v) = HeaderValue::from_str(e) {
                h.insert(header::ETAG, v);
            }
            h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
        }
        None => {
            h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
        }
    }
    if let Some(n) = length {
        h.insert(header::CONTENT_LENGTH, HeaderValue::from(n));
    }
    Ok(r)
}

struct TreeStream {
    st: Shared,
    live: Arc<Live>,
    rx: watch::Receiver<u64>,
    header: BakeHeader,
    header_frame: Option<Bytes>,
    next: u32,
    end: u32,
    faces: u8,
    format: Format,
    shutdown: watch::Receiver<bool>,
    done: bool,
    _guard: StreamGuard,
}

type Item = Result<Bytes, std::io::Error>;

impl TreeStream {
    fn sent(&self, n: usize) {
        self.st
            .metrics
            .tree_bytes_served
            .fetch_add(n as u64, Ordering::Relaxed);
    }

    /// Ends the response without a clean end, so the client sees an incomplete body.
    fn abort(mut self, why: String) -> Option<(Item, TreeStream)> {
        tracing::info!(scene = %self.live.id(), chunk = self.next, %why, "tree stream aborted");
        self.done = true;
        Some((Err(std::io::Error::other(why)), self))
    }

    async fn step(mut self) -> Option<(Item, TreeStream)> {
        if self.done {
            return None;
        }
        if let Some(h) = self.header_frame.take() {
            self.sent(h.len());
            return Some((Ok(h), self));
        }
        if self.next >= self.end {
            return None;
        }
        let c = self.next;
        loop {
            self.rx.borrow_and_update();
            match self.live.chunk(c) {
                ChunkState::Durable(meta) => {
                    let first = c * self.live.row.chunk_vertices;
                    match self
                        .st
                        .store
                        .read_chunk(self.live.id(), c, meta, first)
                        .await
                    {
                        ChunkRead::Ok(frame) => {
                            let frame = match self.filter(frame).await {
                                Ok(f) => f,
                                Err(e) => return self.abort(e),
                            };
                            self.next += 1;
                            self.sent(frame.len());
                            self.st
                                .metrics
                                .chunks_served
                                .fetch_add(1, Ordering::Relaxed);
                            return Some((Ok(Bytes::from(frame)), self));
                        }
                        ChunkRead::Missing => {
                            if let Err(e) = self.rebake(c, meta, "chunk file missing").await {
                                return self.abort(e);
                            }
                        }
                        ChunkRead::Corrupt(why) => {
                            if let Err(e) = self.rebake(c, meta, &why).await {
                                return self.abort(e);
                            }
                        }
                    }
                }
                ChunkState::Never(state, reason) => {
                    return self.abort(format!(
                        "the scene is {}: {}",
                        state.as_str(),
                        reason.unwrap_or_default()
                    ));
                }
                ChunkState::Waiting => {
                    tokio::select! {
                        r = self.rx.changed() => {
                            if r.is_err() {
                                return self.abort("the scene went away".into());
                            }
                        }
                        _ = self.shutdown.changed() => {
                            return self.abort("the server is shutting down".into());
                        }
                    }
                }
            }
        }
    }

    /// Asks for chunk `c` to be baked again and switches to the scene to wait on.
    async fn rebake(&mut self, c: u32, meta: ChunkMeta, why: &str) -> Result<(), String> {
        let jobs = self.st.jobs.clone();
        let id = self.live.id().to_string();
        let why = why.to_string();
        match blocking(move || jobs.rebake(&id, c, meta, &why)).await {
            Ok(Some(live)) => {
                self.rx = live.subscribe();
                self.live = live;
                Ok(())
            }
            Ok(None) => Err("the scene was deleted".into()),
            Err(e) => Err(e.detail),
        }
    }

    /// Drops the faces not asked for (re-encoding the chunk) or turns the chunk into GPU
    /// words, on the blocking pool; a whole-face encoded chunk is sent as stored.
    async fn filter(&self, frame: Vec<u8>) -> Result<Vec<u8>, String> {
        if self.faces == ALL_FACES && self.format == Format::Encoded {
            return Ok(frame);
        }
        let _permit = self
            .st
            .reencode
            .acquire()
            .await
            .map_err(|e| e.to_string())?;
        let header = self.header.clone();
        let (faces, format) = (self.faces, self.format);
        blocking(move || {
            let (mut chunk, _) = decode_chunk(&frame, &header)?;
            for t in &mut chunk.trees {
                for (f, tree) in t.faces.iter_mut().enumerate() {
                    if faces & (1 << f) == 0 {
                        *tree = None;
                    }
                }
            }
            Ok(match format {
                Format::Encoded => encode_chunk(chunk.first_vertex, &chunk.trees, &header.codec()),
                Format::Gpu => gpu_chunk(chunk.first_vertex, &chunk.trees),
            })
        })
        .await
        .map_err(|e| e.detail)
    }
}

/// The `format=gpu` stream's header: `"BVGT"`, then u32 LE version (1), vertex count, chunk
/// vertices, the line codec's offsets O and angle count A, f32 LE half step √2 / O, and the A
/// line normals (2 × f32 each): what `shade.wgsl` needs besides the nodes
/// (`bspvt_shaders::gpu::trees`).
pub(crate) fn gpu_header(h: &BakeHeader) -> Vec<u8> {
    let codec = h.codec();
    let normals = trees::line_normals(&codec);
    let (offsets, half_step) = trees::codec_params(&codec);
    let mut out = b"BVGT".to_vec();
    for x in [
        1,
        h.vertex_count,
        h.chunk_vertices,
        offsets,
        normals.len() as u32,
    ] {
        out.extend_from_slice(&x.to_le_bytes());
    }
    out.extend_from_slice(&half_step.to_le_bytes());
    for n in normals.iter().flatten() {
        out.extend_from_slice(&n.to_le_bytes());
    }
    out
}

/// One chunk of the `format=gpu` stream: `"BVGC"`, u32 LE first vertex, vertex count V and
/// node count N, then 6·V root indices relative to the chunk's first node ([`trees::ABSENT`]
/// for a face without a tree), then N nodes of two u32 (`shade.wgsl`'s `nodes`).
pub(crate) fn gpu_chunk(first_vertex: u32, vertex_trees: &[VertexTrees]) -> Vec<u8> {
    let mut nodes = Vec::new();
    let roots: Vec<[u32; FACES]> = vertex_trees
        .iter()
        .map(|t| trees::encode_vertex(t, 0, &mut nodes))
        .collect();
    let mut out = Vec::with_capacity(16 + roots.len() * 24 + nodes.len() * 8);
    out.extend_from_slice(b"BVGC");
    for x in [first_vertex, roots.len() as u32, nodes.len() as u32] {
        out.extend_from_slice(&x.to_le_bytes());
    }
    for w in roots.iter().flatten().chain(nodes.iter().flatten()) {
        out.extend_from_slice(&w.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row() -> SceneRow {
        SceneRow {
            id: "x".into(),
            seq: 1,
            state: JobState::Done,
            reason: None,
            created_ms: 0,
            started_ms: None,
            finished_ms: None,
            vertex_count: 1000,
            triangle_count: 1,
            chunk_count: 10,
            chunk_vertices: 100,
            settings_json: "{}".into(),
            mesh_hash: 0,
            header: vec![],
            upload_bytes: 0,
            source: String::new(),
            warnings: Vec::new(),
            chunks_baked: 0,
            chunks_corrupt: 0,
        }
    }

    #[test]
    fn selections() {
        let r = row();
        let s = |q: &str| Selection::parse(Some(q), &r);
        assert_eq!(s("").ok().map(|s| s.chunks), Some(0..10));
        assert_eq!(s("vertices=150..250").ok().map(|s| s.chunks), Some(1..3));
        assert_eq!(s("vertices=100..200").ok().map(|s| s.chunks), Some(1..2));
        assert_eq!(s("vertices=..1").ok().map(|s| s.chunks), Some(0..1));
        assert_eq!(s("vertices=999..").ok().map(|s| s.chunks), Some(9..10));
        assert_eq!(s("faces=0,%2Bz,ny").ok().map(|s| s.faces), Some(0b011001));
        assert_eq!(s("faces=+x").ok().map(|s| s.faces), Some(1));
        for bad in [
            "vertices=5..5",
            "vertices=5..1001",
            "vertices=a..b",
            "vertices=-1..3",
            "faces=6",
            "faces=",
            "x=1",
            "vertices=1..2&vertices=1..2",
            "faces=%zz",
        ] {
            let e = s(bad).err().unwrap_or_else(|| panic!("{bad} accepted"));
            assert!(e.status.is_client_error(), "{bad}");
        }
    }
}
