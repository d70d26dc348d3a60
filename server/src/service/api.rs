//! HTTP handlers for scenes, meshes, health and metrics. They are thin:
//! they parse and check the request, call `input`, `jobs` or `store`, and shape the answer.
//!
//! Guarantees: writes (`POST`, `DELETE`) and the listing need the key when one is configured
//! (`Authorization: Bearer KEY` or `X-API-Key: KEY`, compared in constant time), checked
//! before any body byte is read; an
//! upload is refused before it is read when the queue is full, too many uploads are in
//! progress or its declared length is over the limit; blocking work (mesh parsing, file and
//! database I/O) runs on tokio's blocking pool, never on the executor; ids are 128 random bits.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use axum::extract::multipart::{Field, MultipartError, MultipartRejection};
use axum::extract::{FromRequestParts, Multipart, Path, RawQuery, State};
use axum::http::request::Parts;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use bspvt_proto::encoding::{BakeHeader, encode_header};
use serde::Serialize;
use utoipa::ToSchema;

use bspvt_proto::api::{JobState, Links, SceneStatus};

use super::clients::{Client, Kind};
use super::db::{SceneRow, now_ms};
use super::error::{ApiError, ApiResult, ErrorBody, gone};
use super::http::{not_modified, not_modified_response, query_pairs};
use super::input::{self, Upload};
use super::jobs::{Live, SubmitError};
use super::memory::Reservation;
use super::metrics::Gauges;
use super::state::{Shared, blocking, check_id, lookup, status_of};

/// Largest `scene` field (scene JSON).
pub(crate) const MAX_SCENE_JSON_BYTES: u64 = 1 << 20;
/// Most `file` fields (a mesh's material libraries, textures and buffers) in one submission.
pub(crate) const MAX_UPLOADED_FILES: usize = 256;
/// Largest `settings` field.
pub(crate) const MAX_SETTINGS_JSON_BYTES: u64 = 64 << 10;

/// Answer to a submission.
#[derive(Serialize, ToSchema)]
pub(crate) struct Submitted {
    /// The scene's id: 32 hex digits (128 random bits). Whoever knows it can read the scene.
    pub id: String,
    pub state: JobState,
    pub links: Links,
}

/// A new unguessable id: 128 bits from the operating system's generator.
fn new_id() -> ApiResult<String> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b).map_err(|e| ApiError::internal(format!("no randomness: {e}")))?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// Proof that a request carries the API key (when one is configured): writes and the listing
/// need it. The key is accepted as `Authorization: Bearer KEY` (scheme in any case) or as
/// `X-API-Key: KEY`; every key given must be right (one wrong key is 401 even beside a right
/// one). Each comparison takes the same time whatever bytes differ.
pub(crate) struct KeyAccess;

impl FromRequestParts<Shared> for KeyAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, st: &Shared) -> ApiResult<KeyAccess> {
        let Some(key) = &st.cfg.api_key else {
            return Ok(KeyAccess);
        };
        let unauthorized =
            |d: &str| ApiError::new(StatusCode::UNAUTHORIZED, "unauthorized", d.to_string());
        let mut given = Vec::new();
        for v in parts.headers.get_all(header::AUTHORIZATION) {
            let v = v
                .to_str()
                .map_err(|_| unauthorized("the Authorization header is not ASCII"))?;
            // The scheme is case-insensitive (RFC 9110 §11.1).
            let token = v
                .split_once(' ')
                .filter(|(scheme, _)| scheme.eq_ignore_ascii_case("bearer"))
                .map(|(_, token)| token.trim())
                .ok_or_else(|| unauthorized("the Authorization header must be `Bearer KEY`"))?;
            given.push(token);
        }
        for v in parts.headers.get_all("x-api-key") {
            let v = v
                .to_str()
                .map_err(|_| unauthorized("the X-API-Key header is not ASCII"))?;
            given.push(v.trim());
        }
        if given.is_empty() {
            return Err(unauthorized(
                "this server needs its API key for this request: send `Authorization: Bearer KEY` or `X-API-Key: KEY`",
            ));
        }
        // Every key is compared (no early exit on the first mismatch).
        let right = given.iter().fold(true, |ok, g| {
            ok & constant_time_eq(g.as_bytes(), key.as_bytes())
        });
        if right {
            Ok(KeyAccess)
        } else {
            Err(unauthorized("wrong API key"))
        }
    }
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

fn multipart_error(e: MultipartError) -> ApiError {
    let status = e.status();
    // axum answers 500 when the body stream itself fails: the connection closed (or reset)
    // before the body's end — the client's doing, not the server's.
    if status.is_server_error() {
        return ApiError::client_closed(format!(
            "the upload ended before its body did: {}",
            e.body_text()
        ));
    }
    let code = if status == StatusCode::PAYLOAD_TOO_LARGE {
        "body_too_large"
    } else {
        "invalid_multipart"
    };
    ApiError::new(status, code, e.body_text())
}

/// Awaits the next piece of an upload's body, or 408 when the client sends nothing for `idle`
/// (nginx's `client_body_timeout`: the time between two reads, not for the whole body).
/// How fast an upload must send: a read may wait at most `idle` (nginx's
/// `client_body_timeout`), and after that grace period the body must average `min_rate`
/// bytes/s (Apache's `RequestReadTimeout body=… MinRate=…`): each byte received buys
/// 1/min_rate s more, so a client trickling a byte a minute is cut off, not only a silent one.
#[derive(Clone, Copy)]
pub(super) struct Pace {
    start: Instant,
    /// When the last read completed.
    last: Instant,
    received: u64,
    idle: Duration,
    min_rate: u64,
}

impl Pace {
    pub(super) fn new(idle: Duration, min_rate: u64) -> Pace {
        let now = Instant::now();
        Pace {
            start: now,
            last: now,
            received: 0,
            idle,
            min_rate,
        }
    }

    /// How long the next read may take: `idle`, or less when the average rate would fall
    /// below `min_rate` sooner.
    fn budget(&self) -> Duration {
        if self.min_rate == 0 {
            return self.idle;
        }
        let earned =
            self.idle + Duration::from_secs_f64(self.received as f64 / self.min_rate as f64);
        earned.saturating_sub(self.start.elapsed()).min(self.idle)
    }

    /// Awaits `next` within [`Pace::budget`]; 408 when it runs out.
    async fn within<T>(&mut self, next: impl std::future::Future<Output = T>) -> ApiResult<T> {
        let budget = self.budget();
        let r = tokio::time::timeout(budget, next).await;
        if r.is_ok() {
            self.last = Instant::now();
        }
        r.map_err(|_| {
            let secs = self.start.elapsed().as_secs_f64();
            // Silent for the whole read timeout: `body_timeout`; else too slow on average.
            if self.last.elapsed() + Duration::from_millis(5) < self.idle {
                ApiError::new(
                    StatusCode::REQUEST_TIMEOUT,
                    "body_too_slow",
                    format!(
                        "the upload sent {} bytes in {secs:.0} s; after the first {} s an \
                         upload must average at least {} bytes/s",
                        self.received,
                        self.idle.as_secs(),
                        self.min_rate
                    ),
                )
            } else {
                ApiError::new(
                    StatusCode::REQUEST_TIMEOUT,
                    "body_timeout",
                    format!("the upload sent nothing for {} s", self.idle.as_secs()),
                )
            }
        })
    }
}

/// Reads one form field, refusing it past `max` bytes.
async fn read_field(
    mut field: Field<'_>,
    max: u64,
    what: &str,
    pace: &mut Pace,
) -> ApiResult<Vec<u8>> {
    let mut buf = Vec::new();
    while let Some(chunk) = pace.within(field.chunk()).await?.map_err(multipart_error)? {
        pace.received += chunk.len() as u64;
        if (buf.len() + chunk.len()) as u64 > max {
            return Err(ApiError::too_large(
                "field_too_large",
                format!("the `{what}` field is larger than the limit of {max} bytes"),
            ));
        }
        buf.extend_from_slice(&chunk);
    }
    Ok(buf)
}

/// Reads and discards a form, at most `max` bytes at the upload's pace (errors end it).
async fn drain(mut mp: Multipart, max: u64, mut pace: Pace) {
    while let Ok(Ok(Some(mut field))) = pace.within(mp.next_field()).await {
        while let Ok(Ok(Some(chunk))) = pace.within(field.chunk()).await {
            pace.received += chunk.len() as u64;
            if pace.received > max {
                return;
            }
        }
    }
}

pub(super) async fn read_upload(
    mut mp: Multipart,
    max_mesh: u64,
    mut pace: Pace,
) -> ApiResult<Upload> {
    let mut up = Upload {
        mesh: None,
        files: BTreeMap::new(),
        scene: None,
        settings: None,
    };
    // The mesh and its other files together stay within the mesh limit.
    let mut file_bytes = 0u64;
    let text = |b: Vec<u8>, what: &str| {
        String::from_utf8(b).map_err(|_| {
            ApiError::bad_request("invalid_field", format!("the `{what}` field is not UTF-8"))
        })
    };
    let duplicate = |what: &str| {
        ApiError::bad_request(
            "duplicate_field",
            format!("the form has more than one `{what}` field"),
        )
    };
    while let Some(field) = pace
        .within(mp.next_field())
        .await?
        .map_err(multipart_error)?
    {
        let name = field.name().unwrap_or_default().to_string();
        match name.as_str() {
            "mesh" => {
                if up.mesh.is_some() {
                    return Err(duplicate("mesh"));
                }
                let file_name = field.file_name().unwrap_or_default().to_string();
                if file_name.is_empty() {
                    return Err(ApiError::bad_request(
                        "missing_file_name",
                        "the `mesh` field must be a file with a name such as model.glb (the extension picks the format)",
                    ));
                }
                // The compressed size is bounded too: no upload is larger than the mesh limit.
                let bytes = read_field(field, max_mesh - file_bytes, "mesh", &mut pace).await?;
                file_bytes += bytes.len() as u64;
                up.mesh = Some((file_name, bytes));
            }
            "file" => {
                let given = field.file_name().unwrap_or_default().to_string();
                let Some(name) = bspvt_proto::import::sidecar_name(&given) else {
                    return Err(ApiError::bad_request(
                        "invalid_file_name",
                        format!(
                            "a `file` field is named {:?}: it must be the path the mesh names it by, \
                             relative and below the mesh (such as model.mtl or textures/wood.png)",
                            super::error::truncate(&given, 200)
                        ),
                    ));
                };
                if up.files.contains_key(&name) {
                    return Err(duplicate(&format!("file {name:?}")));
                }
                if up.files.len() >= MAX_UPLOADED_FILES {
                    return Err(ApiError::bad_request(
                        "too_many_files",
                        format!("more than {MAX_UPLOADED_FILES} `file` fields"),
                    ));
                }
                let bytes = read_field(field, max_mesh - file_bytes, "file", &mut pace).await?;
                file_bytes += bytes.len() as u64;
                up.files.insert(name, bytes);
            }
            "scene" => {
                if up.scene.is_some() {
                    return Err(duplicate("scene"));
                }
                up.scene = Some(text(
                    read_field(field, MAX_SCENE_JSON_BYTES, "scene", &mut pace).await?,
                    "scene",
                )?);
            }
            "settings" => {
                if up.settings.is_some() {
                    return Err(duplicate("settings"));
                }
                up.settings = Some(text(
                    read_field(field, MAX_SETTINGS_JSON_BYTES, "settings", &mut pace).await?,
                    "settings",
                )?);
            }
            other => {
                return Err(ApiError::bad_request(
                    "unknown_field",
                    format!(
                        "unknown form field {:?} (expected mesh, file, scene, settings)",
                        super::error::truncate(other, 100)
                    ),
                ));
            }
        }
    }
    Ok(up)
}

/// How long an `Idempotency-Key` is remembered after the submission it created: 24 hours.
pub(crate) const IDEMPOTENCY_TTL_MS: i64 = 24 * 3600 * 1000;

/// What a submission led to.
enum Submission {
    /// A new scene, queued.
    Accepted(Arc<Live>),
    /// The scene an earlier submission with the same `Idempotency-Key` and body created.
    Replayed(Arc<Live>),
}

/// The `Idempotency-Key` header, if any: 1 to 255 visible ASCII characters, optionally in
/// double quotes (the IETF draft sends it as a structured-field string).
fn idempotency_key(headers: &HeaderMap) -> ApiResult<Option<String>> {
    let mut values = headers.get_all("idempotency-key").iter();
    let Some(v) = values.next() else {
        return Ok(None);
    };
    let bad = |d: String| ApiError::bad_request("invalid_idempotency_key", d);
    if values.next().is_some() {
        return Err(bad("more than one Idempotency-Key header".into()));
    }
    let raw = v.as_bytes();
    let key = raw
        .strip_prefix(b"\"")
        .and_then(|k| k.strip_suffix(b"\""))
        .unwrap_or(raw);
    if key.is_empty() || key.len() > 255 || !key.iter().all(|b| (0x21..=0x7e).contains(b)) {
        return Err(bad(format!(
            "the Idempotency-Key must be 1 to 255 visible ASCII characters (e.g. a UUID); got {} bytes",
            raw.len()
        )));
    }
    Ok(Some(String::from_utf8_lossy(key).into_owned()))
}

/// An `Idempotency-Key` claimed by the request being handled; released when dropped.
struct KeyClaim {
    st: Shared,
    key: String,
}

impl KeyClaim {
    /// Claims `key`, or 409 when another request with it is still being handled.
    fn claim(st: &Shared, key: &str) -> ApiResult<KeyClaim> {
        let mut held = st
            .idempotency_in_flight
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        if !held.insert(key.to_string()) {
            return Err(ApiError {
                retry_after: Some(1),
                ..ApiError::new(
                    StatusCode::CONFLICT,
                    "idempotency_key_in_use",
                    "a request with this Idempotency-Key is still being handled; retry when it has been answered",
                )
            });
        }
        Ok(KeyClaim {
            st: st.clone(),
            key: key.to_string(),
        })
    }
}

impl Drop for KeyClaim {
    fn drop(&mut self) {
        self.st
            .idempotency_in_flight
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&self.key);
    }
}

/// Accepts an upload, or, when its `Idempotency-Key` already created a scene from the same
/// body, answers with that scene (blocking: runs on the blocking pool).
fn accept_or_replay(
    st: &Shared,
    up: Upload,
    key: Option<String>,
    mem: &mut Reservation,
) -> ApiResult<Submission> {
    let Some(key) = key else {
        return accept(st, up, None, mem).map(Submission::Accepted);
    };
    let fp = input::fingerprint(&up);
    let now = now_ms();
    let recorded = st
        .db
        .idempotent(&key, now - IDEMPOTENCY_TTL_MS)
        .map_err(|e| ApiError::internal(format!("cannot read the idempotency keys: {e:#}")))?;
    match recorded {
        Some(r) if r.fingerprint == fp => {
            let live = st
                .jobs
                .lookup(&r.scene_id)
                .map_err(|e| ApiError::internal(format!("cannot read the scene: {e:#}")))?
                .ok_or_else(|| {
                    ApiError::internal(format!("the key's scene {} is not recorded", r.scene_id))
                })?;
            tracing::info!(scene = %r.scene_id, "idempotent resubmission answered with its scene");
            Ok(Submission::Replayed(live))
        }
        Some(r) => Err(ApiError::unprocessable(
            "idempotency_key_reused",
            format!(
                "this Idempotency-Key was used {} s ago for a different request (another mesh, \
                 scene or settings); a new submission needs a new key (keys are kept {} h)",
                (now - r.created_ms).max(0) / 1000,
                IDEMPOTENCY_TTL_MS / 3_600_000
            ),
        )),
        None => {
            if !st.jobs.has_room() {
                return Err(queue_full(st.cfg.max_queued_scenes));
            }
            accept(st, up, Some((&key, &fp)), mem).map(Submission::Accepted)
        }
    }
}

/// Parses, stores and queues an upload (blocking: runs on the blocking pool), recording the
/// `Idempotency-Key` and request fingerprint with it.
fn accept(
    st: &Shared,
    up: Upload,
    key: Option<(&str, &str)>,
    mem: &mut Reservation,
) -> ApiResult<Arc<Live>> {
    let p = input::prepare(up, &st.input_limits(), mem)?;
    let scene = &p.scene;
    // A scene whose bake could never fit is refused now, not failed later.
    st.memory
        .check_fits(st.jobs.bake_estimate(
            scene.mesh.vertex_count() as u64,
            scene.mesh.triangles.len() as u64,
            scene.bake.face_res,
        ))
        .map_err(|r| ApiError::memory("baking this scene", r))?;
    let id = new_id()?;
    let vertex_count = scene.mesh.vertex_count() as u32;
    // The mesh's hash and its repeated triangles (a sort of every triangle) on a second thread
    // while the scene is encoded and stored: a tenth of a second of a big upload's answer.
    let (side, stored) = std::thread::scope(|s| {
        let side = s.spawn(|| {
            let repeats = bspvt_proto::import::repeats_warning(&scene.mesh);
            (scene.mesh.content_hash(), repeats)
        });
        let stored = st.store.create_scene(&id, &input::encode_scene(scene));
        (side.join(), stored)
    });
    stored.map_err(|e| {
        if super::error::is_storage_full(&e) {
            insufficient_storage()
        } else {
            ApiError::internal(format!("cannot store the scene: {}", e.kind()))
        }
    })?;
    let Ok((mesh_hash, repeats)) = side else {
        let _ = st.store.remove_scene(&id);
        return Err(ApiError::internal("the mesh's hash could not be computed"));
    };
    let header = BakeHeader::new(&scene.bake, vertex_count, mesh_hash);
    let mut warnings = scene.warnings.clone();
    warnings.extend(repeats);
    let row = SceneRow {
        id: id.clone(),
        seq: 0,
        state: JobState::Queued,
        reason: None,
        created_ms: now_ms(),
        started_ms: None,
        finished_ms: None,
        vertex_count,
        triangle_count: scene.mesh.triangles.len() as u64,
        chunk_count: header.chunk_count(),
        chunk_vertices: header.chunk_vertices,
        settings_json: serde_json::to_string(&scene.bake).unwrap_or_default(),
        mesh_hash: header.mesh_hash,
        header: encode_header(&header),
        upload_bytes: p.upload_bytes,
        source: p.source,
        chunks_baked: 0,
        chunks_corrupt: 0,
        warnings,
    };
    match st.jobs.submit(row, key) {
        Ok(live) => {
            tracing::info!(
                scene = %id,
                vertices = vertex_count,
                chunks = live.row.chunk_count,
                source = %live.row.source,
                "scene accepted"
            );
            Ok(live)
        }
        Err(e) => {
            let _ = st.store.remove_scene(&id);
            Err(match e {
                SubmitError::QueueFull(n) => queue_full(n),
                SubmitError::Db(e) if super::error::is_disk_full(&e) => insufficient_storage(),
                SubmitError::Db(e) => ApiError::internal(format!("cannot record the scene: {e}")),
            })
        }
    }
}

/// 507 with `Retry-After`: the data disk is full (RFC 4918 §11.5).
fn insufficient_storage() -> ApiError {
    tracing::warn!("an upload was refused: the data disk is full");
    ApiError {
        retry_after: Some(30),
        ..ApiError::new(
            StatusCode::INSUFFICIENT_STORAGE,
            "insufficient_storage",
            "the server's data disk is full; retry later",
        )
    }
}

fn queue_full(n: usize) -> ApiError {
    ApiError {
        retry_after: Some(10),
        ..ApiError::new(
            StatusCode::TOO_MANY_REQUESTS,
            "queue_full",
            format!("{n} scenes are queued or baking, the most this server accepts; retry later"),
        )
    }
}

/// Multipart form of a submission (for the OpenAPI document).
#[derive(ToSchema)]
#[allow(dead_code)]
pub(crate) struct SubmitForm {
    /// The mesh file (`.glb`, `.gltf`, `.obj`, `.ply`, each optionally compressed as `.zst`).
    /// Required unless the scene names only `builtin:` meshes.
    #[schema(value_type = Option<String>, format = Binary)]
    mesh: Option<Vec<u8>>,
    /// The mesh's other files, any number of fields named `file`, each with the file name the
    /// mesh refers to it by (relative, below the mesh: `room.mtl`, `textures/wood.png`,
    /// `scene.bin`): an OBJ's material libraries and their textures, a `.gltf`'s external
    /// buffers and images. Only these are read; a file the mesh names but that is not uploaded
    /// is a warning (material, texture) or an error (glTF buffer). Counted in the mesh limit.
    #[schema(value_type = Option<Vec<String>>, format = Binary)]
    file: Option<Vec<Vec<u8>>>,
    /// Scene JSON (docs/scene-format.md). Each non-builtin mesh path must end in the uploaded
    /// file's name (`../meshes/bunny.ply` names an upload `bunny.ply`): the server never reads
    /// a path. Without it the mesh gets the default scene (ground plane, quad light).
    scene: Option<String>,
    /// Bake settings JSON replacing the scene's `bake` (`face_res`, `epsilon`,
    /// `supersampling`, `split`, `chunk_vertices`).
    settings: Option<String>,
}

/// Submit a scene for baking.
#[utoipa::path(
    post,
    path = "/v1/scenes",
    tag = "scenes",
    params(
        ("Idempotency-Key" = Option<String>, Header, description = "1 to 255 visible ASCII characters (a UUID, say). A retry with the same key and the same form gets the first submission's scene (200, `Idempotent-Replayed: true`) instead of a second bake; the same key with another form is 422 `idempotency_key_reused`; while the first request is still being handled, 409. Keys are kept 24 hours, across restarts."),
    ),
    request_body(content = SubmitForm, content_type = "multipart/form-data"),
    responses(
        (status = 202, description = "Accepted and queued (`Location`: the status)", body = Submitted),
        (status = 200, description = "A retry with a known Idempotency-Key and the same form: the scene the first request created, in its current state (`Idempotent-Replayed: true`)", body = Submitted),
        (status = 400, description = "Malformed form, scene JSON or Idempotency-Key", body = ErrorBody),
        (status = 401, description = "Missing or wrong API key", body = ErrorBody),
        (status = 409, description = "A request with this Idempotency-Key is still being handled", body = ErrorBody),
        (status = 413, description = "Body, field, mesh or scene over a limit", body = ErrorBody),
        (status = 415, description = "Not a multipart form, or unsupported mesh format", body = ErrorBody),
        (status = 422, description = "Invalid mesh, scene or settings; or an Idempotency-Key reused for another form", body = ErrorBody),
        (status = 429, description = "Queue full or too many uploads at once", body = ErrorBody),
        (status = 507, description = "The server's data disk is full (with Retry-After)", body = ErrorBody),
    ),
    security(("api_key" = []), ("api_key_header" = []))
)]
pub(crate) async fn submit(
    State(st): State<Shared>,
    _auth: KeyAccess,
    headers: HeaderMap,
    client: Option<Extension<Client>>,
    mp: Result<Multipart, MultipartRejection>,
) -> ApiResult<Response> {
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if let Some(n) = declared
        && n > st.cfg.max_body_bytes
    {
        return Err(ApiError::too_large(
            "body_too_large",
            format!(
                "the request body is {n} bytes; the limit is {}",
                st.cfg.max_body_bytes
            ),
        ));
    }
    let key = idempotency_key(&headers)?;
    // A retry with a known key is answered even when the queue is full (checked again below).
    if key.is_none() && !st.jobs.has_room() {
        return Err(queue_full(st.cfg.max_queued_scenes));
    }
    // The client's slot first: one address cannot hold every upload slot.
    let _slot = st.clients.acquire(
        client.map(|Extension(c)| c),
        Kind::Upload,
        st.cfg.max_uploads_per_client,
    )?;
    let _permit = st
        .uploads
        .clone()
        .try_acquire_owned()
        .map_err(|_| ApiError::too_many("too many uploads in progress; retry shortly"))?;
    let _claim = key
        .as_deref()
        .map(|k| KeyClaim::claim(&st, k))
        .transpose()?;
    let mp = mp.map_err(|r| {
        let status = r.status();
        ApiError::new(
            if status == StatusCode::BAD_REQUEST {
                StatusCode::UNSUPPORTED_MEDIA_TYPE
            } else {
                status
            },
            "not_multipart",
            format!(
                "{} (send multipart/form-data with a `mesh` file and/or a `scene` field)",
                r.body_text()
            ),
        )
    })?;
    let pace = Pace::new(
        Duration::from_secs(st.cfg.body_read_timeout_s),
        st.cfg.min_upload_rate,
    );
    // The body, then the parse, are held against the memory budget (memory.rs).
    let mut mem = match st
        .memory
        .try_reserve(declared.unwrap_or(st.cfg.max_body_bytes))
    {
        Ok(r) => r,
        Err(refusal) => {
            // Read and drop the body first, as nginx's lingering close does: a client still
            // sending would otherwise meet a reset instead of the answer.
            drain(mp, st.cfg.max_body_bytes, pace).await;
            return Err(ApiError::memory("this upload", refusal));
        }
    };
    let up = read_upload(mp, st.cfg.max_mesh_bytes, pace).await?;
    let st2 = st.clone();
    let outcome =
        blocking(move || Ok::<_, anyhow::Error>(accept_or_replay(&st2, up, key, &mut mem)))
            .await??;
    // A new scene is answered as accepted (`queued`); a replay with its state now.
    let (status, live, state) = match outcome {
        Submission::Accepted(live) => (StatusCode::ACCEPTED, live, JobState::Queued),
        Submission::Replayed(live) => {
            let state = live.state();
            (StatusCode::OK, live, state)
        }
    };
    let id = live.row.id.clone();
    let mut r = (
        status,
        Json(Submitted {
            id: id.clone(),
            state,
            links: Links::of(&id),
        }),
    )
        .into_response();
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/scenes/{id}")) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    if status == StatusCode::OK {
        r.headers_mut()
            .insert("idempotent-replayed", HeaderValue::from_static("true"));
    }
    Ok(r)
}

/// Most scenes a listing page holds (`limit`), and how many when not asked.
pub(crate) const MAX_LIST_LIMIT: u32 = 100;
const DEFAULT_LIST_LIMIT: u32 = 20;

/// A scene in a listing (from the database: state, counts and times as last recorded).
#[derive(Serialize, ToSchema)]
pub(crate) struct SceneListItem {
    pub id: String,
    pub state: JobState,
    /// Why it failed (`failed`), or why it is paused, or who deleted it (`cancelled`).
    pub reason: Option<String>,
    pub created_ms: i64,
    pub finished_ms: Option<i64>,
    pub vertices_total: u32,
    pub chunks_done: u32,
    pub chunks_total: u32,
    /// How it was submitted, in words.
    pub source: String,
    pub links: Links,
}

/// A page of the listing, newest scene first.
#[derive(Serialize, ToSchema)]
pub(crate) struct SceneList {
    pub scenes: Vec<SceneListItem>,
    /// The next page's URL (also in the `Link: <…>; rel="next"` header); null on the last
    /// page.
    pub next: Option<String>,
    /// The next page's cursor (`after=`): the id of this page's last scene; null on the last
    /// page.
    pub next_cursor: Option<String>,
}

/// List scenes, newest first, a page at a time.
#[utoipa::path(
    get,
    path = "/v1/scenes",
    tag = "scenes",
    params(
        ("limit" = Option<u32>, Query, description = "Scenes per page, 1 to 100 (default 20)"),
        ("after" = Option<String>, Query, description = "Cursor: the last id of the previous page (its `next_cursor`); the page holds the scenes submitted before it"),
        ("state" = Option<String>, Query, description = "Only scenes in these states, comma-separated (`queued,baking,done,failed,cancelled`)"),
    ),
    responses(
        (status = 200, description = "A page of scenes; `next` and `Link: <…>; rel=\"next\"` name the next page", body = SceneList),
        (status = 400, description = "Bad `limit`, `after`, `state` or an unknown parameter", body = ErrorBody),
        (status = 401, description = "Missing or wrong API key", body = ErrorBody),
    ),
    security(("api_key" = []), ("api_key_header" = []))
)]
pub(crate) async fn list_scenes(
    State(st): State<Shared>,
    _auth: KeyAccess,
    RawQuery(q): RawQuery,
) -> ApiResult<Response> {
    let mut limit = DEFAULT_LIST_LIMIT;
    let mut after: Option<String> = None;
    let mut states: Option<Vec<JobState>> = None;
    for (k, v) in query_pairs(q.as_deref())? {
        match k.as_str() {
            "limit" => {
                limit = v
                    .parse::<u32>()
                    .ok()
                    .filter(|n| (1..=MAX_LIST_LIMIT).contains(n))
                    .ok_or_else(|| {
                        ApiError::bad_request(
                            "invalid_query",
                            format!(
                                "limit must be a whole number from 1 to {MAX_LIST_LIMIT}; got {:?}",
                                super::error::truncate(&v, 40)
                            ),
                        )
                    })?;
            }
            "after" => {
                check_id(&v).map_err(|_| {
                    ApiError::bad_request(
                        "invalid_cursor",
                        format!(
                            "after={:?} is not a scene id (use the `next_cursor` of the previous page)",
                            super::error::truncate(&v, 40)
                        ),
                    )
                })?;
                after = Some(v);
            }
            "state" => {
                let parsed = v
                    .split(',')
                    .map(|s| {
                        JobState::parse(s.trim()).ok_or_else(|| {
                            ApiError::bad_request(
                                "invalid_query",
                                format!(
                                    "state {:?} is not one of queued, baking, done, failed, cancelled",
                                    super::error::truncate(s, 40)
                                ),
                            )
                        })
                    })
                    .collect::<ApiResult<Vec<_>>>()?;
                states = Some(parsed);
            }
            other => {
                return Err(ApiError::bad_request(
                    "invalid_query",
                    format!(
                        "unknown query parameter {:?} (expected limit, after, state)",
                        super::error::truncate(other, 40)
                    ),
                ));
            }
        }
    }
    let db = st.db.clone();
    let (cursor, filter) = (after.clone(), states.clone());
    let rows = blocking(move || db.list_scenes(cursor.as_deref(), filter.as_deref(), limit + 1))
        .await?
        .ok_or_else(|| {
            ApiError::bad_request(
                "invalid_cursor",
                format!(
                    "after={:?} names no scene on this server",
                    after.as_deref().unwrap_or_default()
                ),
            )
        })?;
    let more = rows.len() > limit as usize;
    let scenes: Vec<SceneListItem> = rows
        .into_iter()
        .take(limit as usize)
        .map(|r| SceneListItem {
            links: Links::of(&r.id),
            id: r.id,
            state: r.state,
            reason: r.reason,
            created_ms: r.created_ms,
            finished_ms: r.finished_ms,
            vertices_total: r.vertex_count,
            chunks_done: r.chunks_done,
            chunks_total: r.chunk_count,
            source: r.source,
        })
        .collect();
    let next_cursor = more.then(|| scenes.last().map(|s| s.id.clone())).flatten();
    let next = next_cursor.as_ref().map(|c| {
        let mut url = format!("/v1/scenes?limit={limit}&after={c}");
        if let Some(s) = &states {
            let names: Vec<&str> = s.iter().map(|s| s.as_str()).collect();
            url.push_str(&format!("&state={}", names.join(",")));
        }
        url
    });
    let mut r = Json(SceneList {
        scenes,
        next: next.clone(),
        next_cursor,
    })
    .into_response();
    let h = r.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    if let Some(n) = next
        && let Ok(v) = HeaderValue::from_str(&format!("<{n}>; rel=\"next\""))
    {
        h.insert(header::LINK, v);
    }
    Ok(r)
}

/// A scene's status.
#[utoipa::path(
    get,
    path = "/v1/scenes/{id}",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    responses(
        (status = 200, description = "Status", body = SceneStatus),
        (status = 404, description = "Unknown id", body = ErrorBody),
    )
)]
pub(crate) async fn get_scene(
    State(st): State<Shared>,
    Path(id): Path<String>,
) -> ApiResult<Response> {
    let live = lookup(&st, &id).await?;
    let mut r = Json(status_of(&st, &live)).into_response();
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    Ok(r)
}

/// Cancel a scene's bake and delete its data (a `cancelled` tombstone remains).
#[utoipa::path(
    delete,
    path = "/v1/scenes/{id}",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    responses(
        (status = 200, description = "Cancelled and deleted; the final status", body = SceneStatus),
        (status = 401, description = "Missing or wrong API key", body = ErrorBody),
        (status = 404, description = "Unknown id", body = ErrorBody),
    ),
    security(("api_key" = []), ("api_key_header" = []))
)]
pub(crate) async fn delete_scene(
    State(st): State<Shared>,
    _auth: KeyAccess,
    Path(id): Path<String>,
) -> ApiResult<Response> {
    check_id(&id)?;
    let jobs = st.jobs.clone();
    let key = id.clone();
    blocking(move || jobs.delete(&key))
        .await?
        .ok_or_else(|| ApiError::not_found(&id))?;
    let live = lookup(&st, &id).await?;
    Ok(Json(status_of(&st, &live)).into_response())
}

/// The mesh as baked (vertex order = tree order).
#[utoipa::path(
    get,
    path = "/v1/scenes/{id}/mesh",
    tag = "scenes",
    params(
        ("id" = String, Path, description = "Scene id"),
        ("format" = Option<String>, Query, description = "`json` (default: the `Mesh` as JSON: positions, normals, triangles, material_ids) or `ply` (binary little-endian PLY, exact floats)"),
    ),
    responses(
        (status = 200, description = "The mesh", content_type = "application/json"),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 400, description = "Unknown format", body = ErrorBody),
        (status = 404, description = "Unknown id", body = ErrorBody),
        (status = 410, description = "Deleted", body = ErrorBody),
    )
)]
pub(crate) async fn get_mesh(
    State(st): State<Shared>,
    Path(id): Path<String>,
    RawQuery(q): RawQuery,
    headers: HeaderMap,
) -> ApiResult<Response> {
    let mut format = "json";
    for (k, v) in query_pairs(q.as_deref())? {
        match (k.as_str(), v.as_str()) {
            ("format", "json") => format = "json",
            ("format", "ply") => format = "ply",
            ("format", other) => {
                return Err(ApiError::bad_request(
                    "invalid_query",
                    format!("format {other:?} is neither json nor ply"),
                ));
            }
            (other, _) => {
                return Err(ApiError::bad_request(
                    "invalid_query",
                    format!("unknown query parameter {other:?} (expected format)"),
                ));
            }
        }
    }
    let content_type = if format == "ply" {
        "application/octet-stream"
    } else {
        "application/json"
    };
    scene_derived(
        &st,
        &id,
        &headers,
        |hash| format!("\"mesh-{hash:016x}-{format}\""),
        content_type,
        move |bytes| {
            let scene = input::decode_scene(&bytes).map_err(|e| anyhow::anyhow!(e))?;
            Ok(match format {
                "ply" => ply_bytes(&scene.mesh),
                _ => serde_json::to_vec(&scene.mesh)?,
            })
        },
    )
    .await
}

/// The scene exactly as baked (mesh, materials, lights, camera, bake settings), in the
/// service's stored encoding: postcard with exact floats, read back with
/// [`input::decode_scene`]. One request gives a client everything it needs to shade.
#[utoipa::path(
    get,
    path = "/v1/scenes/{id}/scene",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    responses(
        (status = 200, description = "The scene (postcard, version-tagged; `bspvt_server::service::input::decode_scene`)", content_type = "application/octet-stream"),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "Unknown id", body = ErrorBody),
        (status = 410, description = "Deleted", body = ErrorBody),
    )
)]
pub(crate) async fn get_scene_file(
    State(st): State<Shared>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    // A scene never changes after submission: its id and mesh hash name its bytes.
    scene_derived(
        &st,
        &id,
        &headers,
        |hash| format!("\"scene-{id}-{hash:016x}\""),
        "application/octet-stream",
        Ok,
    )
    .await
}

/// A body made from scene `id`'s stored bytes by `build`: named by `etag` (of the mesh hash),
/// built once per name and shared (`bodies`), 304 when the client has it, 410 for a deleted
/// scene; with `X-Bspvt-Mesh-Hash`. The scene, its mesh and its GPU bundle are such bodies.
pub(crate) async fn scene_derived(
    st: &Shared,
    id: &str,
    headers: &HeaderMap,
    etag: impl FnOnce(u64) -> String,
    content_type: &'static str,
    build: impl FnOnce(Vec<u8>) -> anyhow::Result<Vec<u8>> + Send + 'static,
) -> ApiResult<Response> {
    let live = lookup(st, id).await?;
    if live.state() == JobState::Cancelled {
        return Err(gone(id));
    }
    let etag = etag(live.row.mesh_hash);
    if not_modified(headers, &etag) {
        return Ok(not_modified_response(&etag));
    }
    let body = st
        .bodies
        .get_or_build(&etag, || read_stored_scene(st, id, build))
        .await?;
    let mut r = immutable_response(st, body, content_type, &etag);
    if let Ok(v) = HeaderValue::from_str(&format!("{:016x}", live.row.mesh_hash)) {
        r.headers_mut().insert("x-bspvt-mesh-hash", v);
    }
    Ok(r)
}

/// Reads scene `id`'s stored bytes off the async threads and maps them with `f`.
async fn read_stored_scene(
    st: &Shared,
    id: &str,
    f: impl FnOnce(Vec<u8>) -> anyhow::Result<Vec<u8>> + Send + 'static,
) -> ApiResult<Vec<u8>> {
    let store = st.store.clone();
    let key = id.to_string();
    blocking(move || {
        let bytes = store
            .read_scene(&key)
            .map_err(|e| anyhow::anyhow!("cannot read the stored scene: {e}"))?;
        f(bytes)
    })
    .await
}

/// A body that never changes for its ETag: counted as served, revalidated by the client.
fn immutable_response(
    st: &Shared,
    body: axum::body::Bytes,
    content_type: &'static str,
    etag: &str,
) -> Response {
    st.metrics
        .other_bytes_served
        .fetch_add(body.len() as u64, Ordering::Relaxed);
    let mut r = body.into_response();
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    if let Ok(v) = HeaderValue::from_str(etag) {
        h.insert(header::ETAG, v);
    }
    r
}

/// A binary little-endian PLY of the mesh: float x y z nx ny nz per vertex, then per triangle
/// a `uchar`-counted `uint` index list and its material id.
pub(crate) fn ply_bytes(m: &bspvt_proto::Mesh) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\ncomment bspvt baked mesh {:016x}; vertex order = tree order\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         element face {}\nproperty list uchar uint vertex_indices\nproperty uint material\nend_header\n",
        m.content_hash(),
        m.positions.len(),
        m.triangles.len()
    )
    .into_bytes();
    out.reserve(m.positions.len() * 24 + m.triangles.len() * 17);
    for (p, n) in m.positions.iter().zip(&m.normals) {
        for x in p.to_array().into_iter().chain(n.to_array()) {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    for (t, mat) in m.triangles.iter().zip(&m.material_ids) {
        out.push(3);
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
        out.extend_from_slice(&mat.to_le_bytes());
    }
    out
}

/// Health.
#[derive(Serialize, ToSchema)]
pub(crate) struct Health {
    /// `ok`.
    pub status: String,
    pub generation: i64,
    pub uptime_s: f64,
    pub scenes_queued: u64,
    pub scenes_baking: u64,
    /// The distributed shape: the bake workers the database knows (seen in the last hour).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub workers: Option<Vec<super::pg::WorkerInfo>>,
    /// The distributed shape: `ok`, or how the object store fails now (then `status` is
    /// `degraded`: reads and bakes wait and retry; the service needs no restart).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub store: Option<String>,
}

/// Liveness and readiness (the database answers).
#[utoipa::path(
    get,
    path = "/healthz",
    tag = "service",
    responses(
        (status = 200, description = "Healthy", body = Health),
        (status = 503, description = "The database does not answer", body = ErrorBody),
    )
)]
pub(crate) async fn healthz(State(st): State<Shared>) -> ApiResult<Json<Health>> {
    let db = st.db.clone();
    blocking(move || db.ping())
        .await
        .map_err(|e| ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "unhealthy", e.detail))?;
    let g = st.jobs.gauges();
    let store = st.store.probe_objects().await;
    let degraded = matches!(store, Some(Err(_)));
    if degraded {
        st.metrics
            .store_probe_failures
            .fetch_add(1, Ordering::Relaxed);
    }
    Ok(Json(Health {
        status: if degraded { "degraded" } else { "ok" }.into(),
        store: store.map(|r| r.err().unwrap_or_else(|| "ok".into())),
        generation: g.generation,
        uptime_s: st.started.elapsed().as_secs_f64(),
        scenes_queued: g.scenes_queued,
        scenes_baking: g.scenes_baking,
        workers: g.cluster.map(|c| c.workers),
    }))
}

/// Prometheus metrics (text exposition format 0.0.4).
#[utoipa::path(
    get,
    path = "/metrics",
    tag = "service",
    responses((status = 200, description = "Metrics", content_type = "text/plain"))
)]
pub(crate) async fn metrics(State(st): State<Shared>) -> Response {
    let text = st.metrics.render(&Gauges {
        memory_budget_bytes: st.memory.total(),
        memory_reserved_bytes: st.memory.used(),
        ..st.jobs.gauges()
    });
    let mut r = text.into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/plain; version=0.0.4; charset=utf-8"),
    );
    r
}

/// Unknown routes.
pub(crate) async fn not_found() -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        "not_found",
        "no such endpoint (see /v1/openapi.json)",
    )
}
