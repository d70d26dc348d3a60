//! The service's HTTP API as the client uses it (blocking, ureq): submit, status, the scene as
//! baked, and tree-stream requests.

use std::io::Read;
use std::path::Path;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use bspvt_proto::Scene;
use bspvt_proto::api::SceneStatus;
use bspvt_proto::api::decode_scene;
use bspvt_proto::scene::{MeshRef, SceneFile};

use super::cache::Cache;

/// A bspvt service, e.g. `http://127.0.0.1:8080`.
#[derive(Clone)]
pub struct Remote {
    base: String,
    agent: ureq::Agent,
    api_key: Option<String>,
}

/// The answer to a tree-stream request.
pub struct TreesResponse {
    /// 200, or 304 when the validator matched.
    pub status: u16,
    pub etag: Option<String>,
    pub body: Box<dyn Read + Send>,
}

const BOUNDARY: &str = "----bspvt-client-9f2c41";

impl Remote {
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

    pub fn base(&self) -> &str {
        &self.base
    }

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    /// Reads a whole body, refusing more than `limit` bytes.
    fn body(mut r: ureq::http::Response<ureq::Body>, limit: u64) -> Result<Vec<u8>> {
        let mut out = Vec::new();
        r.body_mut()
            .as_reader()
            .take(limit)
            .read_to_end(&mut out)
            .context("reading the response")?;
        Ok(out)
    }

    fn error(what: &str, r: ureq::http::Response<ureq::Body>) -> anyhow::Error {
        let status = r.status();
        let text = Self::body(r, 4096)
            .map(|b| String::from_utf8_lossy(&b).into_owned())
            .unwrap_or_default();
        anyhow::anyhow!("{what}: the server answered {status}: {text}")
    }

    pub fn status(&self, id: &str) -> Result<SceneStatus> {
        let r = self
            .agent
            .get(self.url(&format!("/v1/scenes/{id}")))
            .call()
            .with_context(|| format!("cannot reach {}", self.base))?;
        if r.status() != 200 {
            return Err(Self::error(&format!("status of scene {id}"), r));
        }
        let bytes = Self::body(r, 1 << 20)?;
        serde_json::from_slice(&bytes).context("the status is not the expected JSON")
    }

    /// The scene as baked, from the cache when the server says it is current. Returns the
    /// scene and the bytes fetched.
    pub fn scene(&self, id: &str, cache: Option<&Cache>) -> Result<(Scene, u64)> {
        let cached = cache.and_then(Cache::scene);
        let mut req = self.agent.get(self.url(&format!("/v1/scenes/{id}/scene")));
        if let Some((_, etag)) = &cached {
            req = req.header("If-None-Match", etag.as_str());
        }
        let r = req
            .call()
            .with_context(|| format!("cannot reach {}", self.base))?;
        let (bytes, fetched) = match (r.status().as_u16(), cached) {
            (304, Some((bytes, _))) => (bytes, 0),
            (200, _) => {
                let etag = header(&r, "etag");
                let bytes = Self::body(r, 4 << 30)?;
                if let (Some(c), Some(e)) = (cache, etag) {
                    c.put_scene(&bytes, &e)?;
                }
                let n = bytes.len() as u64;
                (bytes, n)
            }
            _ => return Err(Self::error(&format!("scene {id}"), r)),
        };
        let scene = decode_scene(&bytes).map_err(|e| anyhow::anyhow!("scene {id}: {e}"))?;
        Ok((scene, fetched))
    }

    /// `GET /v1/scenes/{id}/trees` for chunks `first..end` (all when `None`).
    pub fn trees(
        &self,
        id: &str,
        vertices: Option<(u32, u32)>,
        if_none_match: Option<&str>,
    ) -> Result<TreesResponse> {
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
        let r = req
            .call()
            .with_context(|| format!("cannot reach {}", self.base))?;
        let status = r.status().as_u16();
        if status != 200 && status != 304 {
            return Err(Self::error(&format!("trees of scene {id}"), r));
        }
        let etag = header(&r, "etag");
        Ok(TreesResponse {
            status,
            etag,
            body: Box::new(r.into_body().into_reader()),
        })
    }

    /// The validator of the complete tree stream, when the bake is done (`HEAD`).
    pub fn trees_etag(&self, id: &str) -> Result<Option<String>> {
        let r = self
            .agent
            .head(self.url(&format!("/v1/scenes/{id}/trees")))
            .call()
            .with_context(|| format!("cannot reach {}", self.base))?;
        Ok((r.status() == 200).then(|| header(&r, "etag")).flatten())
    }

    /// Submits a scene: `builtin:NAME`, a scene file (its one mesh file is uploaded with it), or
    /// a bare mesh. Returns the new scene's id.
    pub fn submit(&self, scene: Option<&str>, mesh: Option<&Path>) -> Result<String> {
        let mut parts: Vec<(&str, Option<String>, Vec<u8>)> = Vec::new();
        match (scene, mesh) {
            (Some(s), None) => {
                let file = match s.strip_prefix("builtin:") {
                    Some(name) => builtin_scene_file(name)?,
                    None => {
                        let path = Path::new(s);
                        let text = std::fs::read_to_string(path)
                            .with_context(|| format!("cannot read {s}"))?;
                        let mut file: SceneFile = serde_json::from_str(&text)
                            .with_context(|| format!("{s} is not a valid scene file"))?;
                        let files: Vec<&mut MeshRef> = file
                            .meshes
                            .iter_mut()
                            .filter(|m| !m.path.starts_with("builtin:"))
                            .collect();
                        if files.len() > 1 {
                            bail!(
                                "{s} names {} mesh files; the service takes one upload per scene",
                                files.len()
                            );
                        }
                        if let Some(m) = files.into_iter().next() {
                            let mesh_path = path.parent().unwrap_or(Path::new(".")).join(&m.path);
                            let name = mesh_path
                                .file_name()
                                .and_then(|n| n.to_str())
                                .context("mesh file name")?
                                .to_string();
                            let bytes = std::fs::read(&mesh_path)
                                .with_context(|| format!("cannot read {}", mesh_path.display()))?;
                            m.path = name.clone();
                            parts.push(("mesh", Some(name), bytes));
                        }
                        file
                    }
                };
                parts.push(("scene", None, serde_json::to_vec(&file)?));
            }
            (None, Some(m)) => {
                let name = m
                    .file_name()
                    .and_then(|n| n.to_str())
                    .with_context(|| format!("{} has no file name", m.display()))?;
                let bytes =
                    std::fs::read(m).with_context(|| format!("cannot read {}", m.display()))?;
                parts.push(("mesh", Some(name.to_string()), bytes));
            }
            _ => bail!("give a scene (file or builtin:NAME) or --mesh PATH"),
        }
        let mut body = Vec::new();
        for (name, file, data) in &parts {
            body.extend_from_slice(format!("--{BOUNDARY}\r\n").as_bytes());
            let disposition = match file {
                Some(f) => format!(
                    "Content-Disposition: form-data; name=\"{name}\"; filename=\"{f}\"\r\nContent-Type: application/octet-stream\r\n\r\n"
                ),
                None => format!("Content-Disposition: form-data; name=\"{name}\"\r\n\r\n"),
            };
            body.extend_from_slice(disposition.as_bytes());
            body.extend_from_slice(data);
            body.extend_from_slice(b"\r\n");
        }
        body.extend_from_slice(format!("--{BOUNDARY}--\r\n").as_bytes());
        let mut req = self.agent.post(self.url("/v1/scenes")).header(
            "Content-Type",
            format!("multipart/form-data; boundary={BOUNDARY}"),
        );
        if let Some(k) = &self.api_key {
            req = req.header("Authorization", format!("Bearer {k}"));
        }
        let r = req
            .send(&body[..])
            .with_context(|| format!("cannot reach {}", self.base))?;
        if r.status() != 202 {
            return Err(Self::error("submit", r));
        }
        let v: serde_json::Value = serde_json::from_slice(&Self::body(r, 1 << 20)?)?;
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
pub fn builtin_scene_file(name: &str) -> Result<SceneFile> {
    bspvt_proto::builtin::scene_file(name).with_context(|| {
        format!(
            "unknown built-in scene {name:?} (known: {})",
            bspvt_proto::builtin::NAMES.join(", ")
        )
    })
}
