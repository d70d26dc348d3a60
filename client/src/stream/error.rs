//! What can go wrong while talking to the service, typed so that the fetcher knows what to
//! retry: a dropped connection, a timeout or a busy service ([`StreamError::is_final`] false)
//! is retried with backoff; a scene that is not there, gone, forbidden or refused is final.

use bspvt_proto::api::ErrorBody;

/// An error from the service or the connection to it.
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    /// 404: the service has no such scene.
    #[error("{what}: no such scene on the service (404): {detail}")]
    NotFound {
        /// The request.
        what: String,
        /// The service's explanation.
        detail: String,
    },
    /// 410: the scene was deleted.
    #[error("{what}: the scene is gone (410): {detail}")]
    Gone {
        /// The request.
        what: String,
        /// The service's explanation.
        detail: String,
    },
    /// 401 or 403: a key is missing or wrong.
    #[error("{what}: not authorised ({status}): {detail}")]
    Unauthorized {
        /// The request.
        what: String,
        /// 401 or 403.
        status: u16,
        /// The service's explanation.
        detail: String,
    },
    /// Another 4xx: the request itself is wrong; asking again does not help.
    #[error("{what}: the service refused the request ({status} {code}): {detail}")]
    Rejected {
        /// The request.
        what: String,
        /// The status code.
        status: u16,
        /// The service's machine-readable error code.
        code: String,
        /// The service's explanation.
        detail: String,
    },
    /// 5xx, 429 or 503: the service is busy or failing now; worth retrying (after
    /// `retry_after` seconds when it said so).
    #[error("{what}: the service answered {status}: {detail}")]
    Busy {
        /// The request.
        what: String,
        /// The status code.
        status: u16,
        /// The service's explanation.
        detail: String,
        /// `Retry-After`, seconds.
        retry_after: Option<u64>,
    },
    /// The service could not be reached, or the connection broke.
    #[error("cannot reach {base}: {source}")]
    Unreachable {
        /// The service's address.
        base: String,
        /// The transport error.
        #[source]
        source: Box<ureq::Error>,
    },
    /// Reading a response body failed part way (a dropped connection).
    #[error("{what}: {source}")]
    Interrupted {
        /// What was being read.
        what: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The bake of the scene failed on the service.
    #[error("the bake failed: {0}")]
    BakeFailed(String),
    /// The scene was deleted while it was being streamed.
    #[error("the scene was deleted")]
    Deleted,
    /// The service answered something this client cannot read.
    #[error("{0}")]
    Invalid(String),
}

impl StreamError {
    /// Whether asking again cannot help: the fetcher stops at once on these.
    pub fn is_final(&self) -> bool {
        !matches!(
            self,
            StreamError::Busy { .. }
                | StreamError::Unreachable { .. }
                | StreamError::Interrupted { .. }
        )
    }

    /// The error a non-success answer stands for, with the service's `ErrorBody` detail.
    pub(crate) fn from_status(
        what: &str,
        status: u16,
        body: &[u8],
        retry_after: Option<u64>,
    ) -> StreamError {
        let (code, detail) = match serde_json::from_slice::<ErrorBody>(body) {
            Ok(b) => (b.error, b.detail),
            Err(_) => (
                String::new(),
                String::from_utf8_lossy(&body[..body.len().min(512)]).into_owned(),
            ),
        };
        let what = what.to_string();
        match status {
            404 => StreamError::NotFound { what, detail },
            410 => StreamError::Gone { what, detail },
            401 | 403 => StreamError::Unauthorized {
                what,
                status,
                detail,
            },
            429 | 500..=599 => StreamError::Busy {
                what,
                status,
                detail,
                retry_after,
            },
            _ => StreamError::Rejected {
                what,
                status,
                code,
                detail,
            },
        }
    }

    /// The stream error at the root of `e`, if there is one.
    pub fn of(e: &anyhow::Error) -> Option<&StreamError> {
        e.chain().find_map(|c| c.downcast_ref::<StreamError>())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statuses_map_to_final_and_transient_errors() {
        let body = br#"{"error": "not_found", "detail": "no scene 0123"}"#;
        let e = StreamError::from_status("status", 404, body, None);
        assert!(e.is_final());
        assert!(e.to_string().contains("no scene 0123"), "{e}");
        for s in [401, 403, 410, 400, 413, 422] {
            assert!(
                StreamError::from_status("x", s, b"", None).is_final(),
                "{s}"
            );
        }
        for s in [429, 500, 502, 503] {
            assert!(
                !StreamError::from_status("x", s, b"oops", Some(2)).is_final(),
                "{s}"
            );
        }
        let busy = StreamError::from_status("x", 503, b"", Some(7));
        assert!(matches!(
            busy,
            StreamError::Busy {
                retry_after: Some(7),
                ..
            }
        ));
        let wrapped = anyhow::Error::from(StreamError::Deleted).context("fetching");
        assert!(StreamError::of(&wrapped).is_some_and(StreamError::is_final));
    }
}
