//! The application state every handler reaches, and what the handler modules share on it:
//! scene lookup and the status document, stream accounting, and the bridge to tokio's
//! blocking pool.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::Result;
use bspvt_proto::api::{JobState, Links, SceneStatus, Sizes};
use bspvt_proto::import::Limits;
use tokio::sync::{OwnedSemaphorePermit, Semaphore, watch};

use super::clients::{Client, ClientSlot, Kind};
use super::config::Config;
use super::db::Db;
use super::error::{ApiError, ApiResult};
use super::input::InputLimits;
use super::jobs::{Jobs, Live};
use super::metrics::Metrics;
use super::store::Store;

/// Everything a handler can reach.
pub(crate) struct AppState {
    pub cfg: Config,
    pub db: Arc<Db>,
    pub store: Arc<Store>,
    pub jobs: Arc<Jobs>,
    pub metrics: Arc<Metrics>,
    /// Memory reserved by uploads being parsed and scenes being baked.
    pub memory: Arc<super::memory::MemoryBudget>,
    /// Uploads being read or parsed.
    pub uploads: Arc<Semaphore>,
    /// Open tree and event streams.
    pub streams: Arc<Semaphore>,
    /// Event streams, the idlest of which is shed when stream slots run out.
    pub idle_streams: Arc<super::idle::IdleStreams>,
    /// Uploads and streams held per remote address.
    pub clients: Arc<super::clients::ClientSlots>,
    /// Requests being handled (streams count until their headers are sent).
    pub requests: Arc<Semaphore>,
    /// Face-filter re-encodes running at once.
    pub reencode: Semaphore,
    /// Scene and mesh bodies, built once per ETag.
    pub bodies: super::bodies::Bodies,
    /// Becomes true when the server shuts down.
    pub shutdown: watch::Receiver<bool>,
    pub started: Instant,
    /// Number of the next request (its tracing span id).
    pub next_request: AtomicU64,
    /// `Idempotency-Key`s of submissions being handled now (a concurrent retry gets 409).
    pub idempotency_in_flight: std::sync::Mutex<std::collections::HashSet<String>>,
}

pub(crate) type Shared = Arc<AppState>;

impl AppState {
    pub(crate) fn input_limits(&self) -> InputLimits {
        InputLimits {
            mesh: Limits {
                max_vertices: self.cfg.max_mesh_vertices,
                max_triangles: self.cfg.max_mesh_triangles,
                max_bytes: self.cfg.max_mesh_bytes,
            },
            max_face_res: self.cfg.max_face_res,
            max_supersampling: self.cfg.max_supersampling,
        }
    }
}

/// Runs blocking work (database, files, parsing) on tokio's blocking pool.
pub(crate) async fn blocking<T, F>(f: F) -> ApiResult<T>
where
    F: FnOnce() -> Result<T> + Send + 'static,
    T: Send + 'static,
{
    match tokio::task::spawn_blocking(f).await {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(ApiError::internal(format!("{e:#}"))),
        Err(e) => Err(ApiError::internal(format!("background task failed: {e}"))),
    }
}

/// Builds a scene's status document.
pub(crate) fn status_of(st: &Shared, live: &Live) -> SceneStatus {
    let s = live.snapshot();
    let r = &live.row;
    SceneStatus {
        id: r.id.clone(),
        state: s.state,
        reason: s.reason,
        vertices_done: s.vertices_done,
        vertices_total: r.vertex_count,
        chunks_done: s.chunks_done,
        chunks_total: r.chunk_count,
        progress: s.vertices_done as f64 / (r.vertex_count.max(1)) as f64,
        rate_vertices_per_s: s.rate,
        eta_s: s.eta_s,
        queue_position: match s.state {
            JobState::Queued => st.jobs.queue_position(&r.id),
            _ => None,
        },
        settings: serde_json::from_str(&r.settings_json).unwrap_or(serde_json::Value::Null),
        sizes: Sizes {
            mesh_vertices: r.vertex_count,
            mesh_triangles: r.triangle_count,
            upload_bytes: r.upload_bytes,
            stored_bytes: s.stored_bytes,
        },
        mesh_hash: format!("{:016x}", r.mesh_hash),
        source: r.source.clone(),
        warnings: r.warnings.clone(),
        created_ms: r.created_ms,
        started_ms: s.started_ms,
        finished_ms: s.finished_ms,
        chunks_baked_this_process: st.jobs.baked_this_process(&r.id),
        chunks_baked_total: s.chunks_baked_total,
        chunks_corrupt: s.chunks_corrupt,
        links: Links::of(&r.id),
    }
}

/// Scene ids are 32 lowercase hex digits; anything else is unknown without a lookup.
pub(crate) fn check_id(id: &str) -> ApiResult<()> {
    if id.len() == 32
        && id
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
    {
        Ok(())
    } else {
        Err(ApiError::not_found(id))
    }
}

/// The scene `id` (live or from the database), or 404.
pub(crate) async fn lookup(st: &Shared, id: &str) -> ApiResult<Arc<Live>> {
    check_id(id)?;
    let jobs = st.jobs.clone();
    let key = id.to_string();
    blocking(move || jobs.lookup(&key))
        .await?
        .ok_or_else(|| ApiError::not_found(id))
}

/// Counts an open stream and holds its permits (the client's and the server's) while it
/// lives.
pub(crate) struct StreamGuard {
    st: Shared,
    _permit: OwnedSemaphorePermit,
    _client: Option<ClientSlot>,
}

impl StreamGuard {
    /// A stream slot for `client` (at most `max_streams_per_client` per address) and one of
    /// the server's `max_streams`; when those are all taken, the event stream idle the
    /// longest (at least `shed_idle_streams_after_s`) is asked to end and its slot is taken;
    /// 429 when the client holds its most or no stream can be shed.
    pub(crate) async fn open(st: &Shared, client: Option<Client>) -> ApiResult<StreamGuard> {
        let slot = st
            .clients
            .acquire(client, Kind::Stream, st.cfg.max_streams_per_client)?;
        let busy = || ApiError::too_many("too many open streams; retry shortly");
        let permit = match st.streams.clone().try_acquire_owned() {
            Ok(p) => p,
            Err(_) => {
                let min_idle = Duration::from_secs(st.cfg.shed_idle_streams_after_s);
                if !st.idle_streams.shed_one(min_idle) {
                    return Err(busy());
                }
                st.metrics.streams_shed.fetch_add(1, Ordering::Relaxed);
                // The shed stream sends its last event and ends, giving its permit back.
                tokio::time::timeout(Duration::from_secs(2), st.streams.clone().acquire_owned())
                    .await
                    .ok()
                    .and_then(Result::ok)
                    .ok_or_else(busy)?
            }
        };
        st.metrics.streams_open.fetch_add(1, Ordering::Relaxed);
        Ok(StreamGuard {
            st: st.clone(),
            _permit: permit,
            _client: slot,
        })
    }
}

impl Drop for StreamGuard {
    fn drop(&mut self) {
        self.st.metrics.streams_open.fetch_sub(1, Ordering::Relaxed);
    }
}
