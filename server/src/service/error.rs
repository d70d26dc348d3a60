//! API errors: every rejected request gets a status code and a JSON body
//! `{"error": CODE, "detail": TEXT}` that says what is wrong.
//!
//! Guarantees: user mistakes map to 4xx with a stable machine-readable `error` code and a
//! human-readable `detail` (the full cause chain of the underlying error); only the service's
//! own failures are 5xx, and those are logged. [`json_errors`] rewrites any non-JSON error
//! response produced outside the handlers (unknown route, wrong method, body-limit rejections)
//! into the same shape.

use axum::Json;
use axum::body::Body;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use bspvt_proto::error::{MeshError, SceneError, chain_message};

/// True for the errors of a full disk or an exhausted quota (transient: the bake waits).
pub(crate) fn is_storage_full(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded
    )
}

/// True when `e` (a database or storage error) says the disk is full: SQLite's "database or
/// disk is full", or [`is_storage_full`] anywhere in its chain.
pub(crate) fn is_disk_full(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        matches!(
            c.downcast_ref::<rusqlite::Error>(),
            Some(rusqlite::Error::SqliteFailure(f, _)) if f.code == rusqlite::ErrorCode::DiskFull
        ) || c
            .downcast_ref::<std::io::Error>()
            .is_some_and(is_storage_full)
    })
}

pub(crate) use bspvt_proto::api::ErrorBody;

/// 499, nginx's "client closed request": the client went away before its request's body
/// ended. Not a server error: counted as 4xx and apart (`bspvt_http_client_aborts_total`).
pub(crate) const CLIENT_CLOSED_REQUEST: u16 = 499;

/// An error answered to a client.
#[derive(Debug)]
pub(crate) struct ApiError {
    pub status: StatusCode,
    pub code: &'static str,
    pub detail: String,
    /// Seconds for a `Retry-After` header (429).
    pub retry_after: Option<u64>,
}

pub(crate) type ApiResult<T> = Result<T, ApiError>;

impl ApiError {
    pub(crate) fn new(
        status: StatusCode,
        code: &'static str,
        detail: impl Into<String>,
    ) -> ApiError {
        ApiError {
            status,
            code,
            detail: detail.into(),
            retry_after: None,
        }
    }

    pub(crate) fn bad_request(code: &'static str, detail: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::BAD_REQUEST, code, detail)
    }

    pub(crate) fn unprocessable(code: &'static str, detail: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, code, detail)
    }

    pub(crate) fn too_large(code: &'static str, detail: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, code, detail)
    }

    pub(crate) fn not_found(id: &str) -> ApiError {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "not_found",
            format!("no scene with id {:?}", truncate(id, 80)),
        )
    }

    pub(crate) fn too_many(detail: impl Into<String>) -> ApiError {
        ApiError {
            retry_after: Some(1),
            ..ApiError::new(StatusCode::TOO_MANY_REQUESTS, "too_many_requests", detail)
        }
    }

    /// The client closed the connection before its body ended ([`CLIENT_CLOSED_REQUEST`]; the
    /// answer reaches no one, the metrics count it).
    pub(crate) fn client_closed(detail: impl Into<String>) -> ApiError {
        let status = StatusCode::from_u16(CLIENT_CLOSED_REQUEST).unwrap_or(StatusCode::BAD_REQUEST);
        ApiError::new(status, "client_closed_request", detail)
    }

    /// The memory budget refused `what`: 413 when it can never fit, 503 with `Retry-After`
    /// while other uploads and bakes hold the budget.
    pub(crate) fn memory(what: &str, r: super::memory::Refusal) -> ApiError {
        match r {
            super::memory::Refusal::Never { .. } => {
                ApiError::too_large("over_memory_budget", format!("{what} {r}"))
            }
            super::memory::Refusal::Busy { .. } => ApiError {
                retry_after: Some(5),
                ..ApiError::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    "memory_busy",
                    format!("{what} {r}; retry shortly"),
                )
            },
        }
    }

    /// A failure of the service itself (storage, database): logged, answered with 500.
    pub(crate) fn internal(detail: impl Into<String>) -> ApiError {
        let detail = detail.into();
        tracing::error!(%detail, "internal error");
        ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", detail)
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut r = (
            self.status,
            Json(ErrorBody {
                error: self.code.to_string(),
                detail: self.detail,
            }),
        )
            .into_response();
        if let Some(s) = self.retry_after {
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        if self.status == StatusCode::UNAUTHORIZED {
            r.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Bearer realm=\"bspvt\""),
            );
        }
        r
    }
}

impl From<MeshError> for ApiError {
    fn from(e: MeshError) -> ApiError {
        let detail = chain_message(&e);
        match e {
            MeshError::TooLarge { .. } => ApiError::too_large("mesh_too_large", detail),
            MeshError::UnsupportedFormat(_) => ApiError::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported_mesh_format",
                detail,
            ),
            _ => ApiError::unprocessable("invalid_mesh", detail),
        }
    }
}

impl From<SceneError> for ApiError {
    fn from(e: SceneError) -> ApiError {
        match e {
            SceneError::Mesh(m) => m.into(),
            SceneError::Json(ref j) => {
                let detail = chain_message(&e);
                if j.classify() == serde_json::error::Category::Data {
                    ApiError::unprocessable("invalid_scene", detail)
                } else {
                    ApiError::bad_request("invalid_scene_json", detail)
                }
            }
            _ => ApiError::unprocessable("invalid_scene", chain_message(&e)),
        }
    }
}

/// At most `n` characters of `s`.
pub(crate) fn truncate(s: &str, n: usize) -> String {
    match s.char_indices().nth(n) {
        Some((i, _)) => format!("{}…", &s[..i]),
        None => s.to_string(),
    }
}

/// Middleware: gives every error response that is not JSON yet (axum's own rejections: unknown
/// route, wrong method, body limits, timeouts) the [`ErrorBody`] shape.
pub(crate) async fn json_errors(response: Response) -> Response {
    let status = response.status();
    let is_json = response
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with("application/json"));
    if status.as_u16() < 400 || is_json {
        return response;
    }
    let (mut parts, body) = response.into_parts();
    let text = axum::body::to_bytes(body, 4096)
        .await
        .ok()
        .and_then(|b| String::from_utf8(b.to_vec()).ok())
        .filter(|t| !t.trim().is_empty())
        .unwrap_or_else(|| status.canonical_reason().unwrap_or("error").to_string());
    let code = match status {
        StatusCode::NOT_FOUND => "not_found",
        StatusCode::METHOD_NOT_ALLOWED => "method_not_allowed",
        StatusCode::PAYLOAD_TOO_LARGE => "body_too_large",
        StatusCode::REQUEST_TIMEOUT => "timeout",
        StatusCode::UNSUPPORTED_MEDIA_TYPE => "unsupported_media_type",
        s if s.is_server_error() => "internal",
        _ => "bad_request",
    };
    let body = serde_json::to_vec(&ErrorBody {
        error: code.to_string(),
        detail: truncate(text.trim(), 1000),
    })
    .unwrap_or_default();
    parts.headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    parts.headers.remove(header::CONTENT_LENGTH);
    Response::from_parts(parts, Body::from(body))
}

/// The answer about a deleted scene (410).
pub(crate) fn gone(id: &str) -> ApiError {
    ApiError::new(
        StatusCode::GONE,
        "deleted",
        format!("scene {id} was deleted"),
    )
}
