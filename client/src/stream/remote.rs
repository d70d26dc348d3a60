//! The service's HTTP API as the client uses it (blocking, ureq): submit, status, the scene as
//! baked, and tree-stream requests.

use std::io::Read;
use std::path::Path;
use std::time::Duration;

use anyhow::{Context, Result};
use bspvt_proto::Scene;
use bspvt_proto::api::SceneStatus;
use bspvt_proto::api::decode_scene;
use bspvt_proto::scene::SceneFile;

use super::cache::Cache;
use super::error::StreamError;
use super::form::Form;

/// A bspvt service, e.g. `http://127.0.0.1:8080`.
#[derive(Clone)]
pub struct Remote {
    base: String,
    agent: ureq::Agent,
    api_key: Option<String>,
}

/// The answer to a tree-stream request.
pub(crate) struct TreesResponse {
    /// 200, or 304 when the validator matched.
    pub(crate) status: u16,
    pub(crate) body: Box<dyn Read + Send>,
}

const BOUNDARY: &str = "----bspvt-client-9f2c41";

impl Remote {
    /// A client of the service at `base` (`http://HOST:PORT`), sending `api_key` on writes.
    pub fn new(base: &str, api_key: Option<String>) -> Remote {
        let agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_connect(Some(Duration::from_secs(5)))
            // A tree stream waits for the bake: no global timeout, but a stalled socket fails.
            .timeout_recv_body(Some(Duration::from_secs(600)))
            .build()
            .into();
        Remote {
            base: base.trim_end_matches('/').to_string(),
            agent,
            api_key,
        }
    }

    /// The service's address.
    pub fn base(&self) -> &str {
        &self.base
    }

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    /// Reads a whole body, refusing more than `limit` bytes.
    fn body(
        what: &str,
        mut r: ureq::http::Response<ureq::Body>,
        limit: u64,
    ) -> Result<Vec<u8>, StreamError> {
        let mut out = Vec::new();
        r.body_mut()
            .as_reader()
            .take(limit)
            .read_to_end(&mut out)
            .map_err(|source| StreamError::Interrupted {
                what: what.to_string(),
                source,
            })?;
        Ok(out)
    }

    /// The typed error of a non-success answer (its `ErrorBody` read for the detail).
    fn error(what: &str, r: ureq::http::Response<ureq::Body>) -> StreamError {
        let status = r.status().as_u16();
        let retry_after = header(&r, "retry-after").and_then(|v| v.trim().parse().ok());
        let body = Self::body(what, r, 4096).unwrap_or_default();
        StreamError::from_status(what, status, &body, retry_after)
    }

    /// A transport failure (nothing answered).
    fn unreachable(&self, e: ureq::Error) -> StreamError {
        StreamError::Unreachable {
            base: self.base.clone(),
            source: Box::new(e),
        }
    }

    /// `GET /v1/scenes/{id}`: where the scene's bake stands.
    pub fn status(&self, id: &str) -> Result<SceneStatus, StreamError> {
        let what = format!("status of scene {id}");
        let r = self
            .agent
            .get(self.url(&format!("/v1/scenes/{id}")))
            .call()
            .map_err(|e| self.unreachable(e))?;
        if r.status() != 200 {
            return Err(Self::error(&what, r));
        }
        let bytes = Self::body(&what, r, 1 << 20)?;
        serde_json::from_slice(&bytes)
            .map_err(|e| StreamError::Invalid(format!("{what}: not the expected JSON: {e}")))
    }

    /// The scene as baked, from the cache when the server says it is current. Returns the
    /// scene and the bytes fetched.
    pub(crate) fn scene(&self, id: &str, cache: Option<&Cache>) -> Result<(Scene, u64)> {
        let what = format!("scene {id}");
        let cached = cache.and_then(Cache::scene);
        let mut req = self.agent.get(self.url(&format!("/v1/scenes/{id}/scene")));
        if let Some((_, etag)) = &cached {
            req = req.header("If-None-Match", etag.as_str());
        }
        let r = req.call().map_err(|e| self.unreachable(e))?;
        let (bytes, fetched) = match (r.status().as_u16(), cached) {
            (304, Some((bytes, _))) => (bytes, 0),
            (200, _) => {
                let etag = header(&r, "etag");
                let bytes = Self::body(&what, r, 4 << 30)?;
                if let (Some(c), Some(e)) = (cache, etag) {
                    c.put_scene(&bytes, &e)?;
                }
                let n = bytes.len() as u64;
                (bytes, n)
            }
            _ => return Err(Self::error(&what, r).into()),
        };
        let scene =
            decode_scene(&bytes).map_err(|e| StreamError::Invalid(format!("{what}: {e}")))?;
        Ok((scene, fetched))
    }

    /// `GET /v1/scenes/{id}/trees` for chunks `first..end` (all when `None`).
    pub(crate) fn trees(
        &self,
        id: &str,
        vertices: Option<(u32, u32)>,
        if_none_match: Option<&str>,
    ) -> Result<TreesResponse, StreamError> {
        let query = match vertices {
            Some((a, b)) => format!("?vertices={a}..{b}"),
            None => String::new(),
        };
        let mut req = self
            .agent
            .get(self.url(&format!("/v1/scenes/{id}/trees{query}")));
        if let Some(e) = if_none_match {
            req = req.header("If-None-Match", e);
        }
        let r = req.call().map_err(|e| self.unreachable(e))?;
        let status = r.status().as_u16();
        if status != 200 && status != 304 {
            return Err(Self::error(&format!("trees of scene {id}"), r));
        }
        Ok(TreesResponse {
            status,
            body: Box::new(r.into_body().into_reader()),
        })
    }

    /// The validator of the complete tree stream, when the bake is done (`HEAD`).
    pub(crate) fn trees_etag(&self, id: &str) -> Result<Option<String>, StreamError> {
        let r = self
            .agent
            .head(self.url(&format!("/v1/scenes/{id}/trees")))
            .call()
            .map_err(|e| self.unreachable(e))?;
        Ok((r.status() == 200).then(|| header(&r, "etag")).flatten())
    }

    /// Submits a scene: `builtin:NAME`, a scene file (its one mesh file is uploaded with it),
    /// or a bare mesh, each mesh with the other files it reads ([`Form::local`]). Returns the
    /// new scene's id.
    pub fn submit(&self, scene: Option<&str>, mesh: Option<&Path>) -> Result<String> {
        self.submit_form(&Form::local(scene, mesh)?)
    }

    /// Submits a form. Returns the new scene's id.
    pub(crate) fn submit_form(&self, form: &Form) -> Result<String> {
        let body = form.body(BOUNDARY);
        let mut req = self.agent.post(self.url("/v1/scenes")).header(
            "Content-Type",
            format!("multipart/form-data; boundary={BOUNDARY}"),
        );
        if let Some(k) = &self.api_key {
            req = req.header("Authorization", format!("Bearer {k}"));
        }
        let r = req.send(&body[..]).map_err(|e| self.unreachable(e))?;
        if r.status() != 202 {
            return Err(Self::error("submit", r).into());
        }
        let v: serde_json::Value = serde_json::from_slice(&Self::body("submit", r, 1 << 20)?)?;
        v["id"]
            .as_str()
            .map(str::to_string)
            .context("the submit answer has no id")
    }
}

fn header(r: &ureq::http::Response<ureq::Body>, name: &str) -> Option<String> {
    r.headers()
        .get(name)
        .and_then(|v| v.to_str().ok())
        .map(str::to_string)
}

/// A built-in scene as a scene file the service accepts (the same meshes, lights and camera).
pub(crate) fn builtin_scene_file(name: &str) -> Result<SceneFile> {
    bspvt_proto::builtin::scene_file(name).with_context(|| {
        format!(
            "unknown built-in scene {name:?} (known: {})",
            bspvt_proto::builtin::NAMES.join(", ")
        )
    })
}
