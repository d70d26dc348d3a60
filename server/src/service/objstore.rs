//! Object storage for the distributed shape (`--store s3://BUCKET/PREFIX`, or a folder shared
//! by every machine): scenes and chunks as objects, through `object_store` (S3 and any
//! S3-compatible server: credentials, region and endpoint from the standard `AWS_*`
//! variables; `AWS_ALLOW_HTTP=true` for a plain-HTTP endpoint).
//!
//! ```text
//! PREFIX/scenes/<id>/scene.bin                          framed + CRC-32, as in a data folder
//! PREFIX/scenes/<id>/chunks/<n>-<crc32>-<bytes>.bvck    chunk n's frame
//! ```
//!
//! Guarantees:
//! - a chunk object is named by its content (CRC-32 and length), so the database row that
//!   records it names exactly one object, and a late worker cannot replace it with other
//!   bytes; it is written create-only where the store supports it (an existing object of that
//!   name is the same chunk and is kept);
//! - a chunk object is complete before the worker records it (a PUT is atomic);
//! - errors given to clients name no bucket, key or endpoint (the log has them).

use std::sync::Arc;

use anyhow::{Context, Result};
use futures_util::StreamExt;
use object_store::path::Path as Key;
use object_store::{ObjectStore, PutMode, PutOptions, PutPayload};

use super::db::ChunkMeta;
use super::io;

/// How long `/healthz` waits for the object store.
const PROBE_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(2);

/// An object store and the prefix under which this service keeps its objects.
pub(crate) struct ObjStore {
    inner: Arc<dyn ObjectStore>,
    /// The same store without retries and with a short timeout: `/healthz`'s probe answers
    /// now, while `inner` retries with backoff (object_store's `RetryConfig`: at most 10
    /// retries within 3 min, exponential backoff with decorrelated jitter).
    probe: Arc<dyn ObjectStore>,
    prefix: String,
    /// For messages: `s3://bucket/prefix` or the folder.
    pub url: String,
}

/// What `--store` names.
pub(crate) enum StoreUrl {
    /// A local folder.
    Folder(std::path::PathBuf),
    /// `s3://BUCKET[/PREFIX]`.
    S3 { bucket: String, prefix: String },
}

impl StoreUrl {
    pub(crate) fn parse(s: &str) -> Result<StoreUrl> {
        if let Some(rest) = s.strip_prefix("s3://") {
            let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
            if bucket.is_empty() {
                anyhow::bail!("--store {s:?}: no bucket (expected s3://BUCKET/PREFIX)");
            }
            return Ok(StoreUrl::S3 {
                bucket: bucket.to_string(),
                prefix: prefix.trim_matches('/').to_string(),
            });
        }
        if s.contains("://") {
            anyhow::bail!(
                "--store {s:?}: unsupported scheme (expected a folder or s3://BUCKET/PREFIX)"
            );
        }
        Ok(StoreUrl::Folder(s.into()))
    }
}

impl ObjStore {
    /// Opens `url`; a folder is created if missing.
    pub(crate) fn open(url: &StoreUrl) -> Result<ObjStore> {
        match url {
            StoreUrl::Folder(dir) => {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("cannot create store folder {}", dir.display()))?;
                let fs = object_store::local::LocalFileSystem::new_with_prefix(dir)
                    .with_context(|| format!("cannot open store folder {}", dir.display()))?;
                let fs = Arc::new(fs);
                Ok(ObjStore {
                    probe: fs.clone(),
                    inner: fs,
                    prefix: String::new(),
                    url: dir.display().to_string(),
                })
            }
            StoreUrl::S3 { bucket, prefix } => {
                let build = |b: object_store::aws::AmazonS3Builder| {
                    b.with_bucket_name(bucket)
                        .build()
                        .with_context(|| format!("cannot configure S3 bucket {bucket:?}"))
                };
                let s3 = build(object_store::aws::AmazonS3Builder::from_env())?;
                let probe = build(
                    object_store::aws::AmazonS3Builder::from_env()
                        .with_retry(object_store::RetryConfig {
                            max_retries: 0,
                            ..Default::default()
                        })
                        // On top of the environment's client options (`AWS_ALLOW_HTTP`, …).
                        .with_config(
                            object_store::aws::AmazonS3ConfigKey::Client(
                                object_store::ClientConfigKey::Timeout,
                            ),
                            format!("{}s", PROBE_TIMEOUT.as_secs()),
                        ),
                )?;
                Ok(ObjStore {
                    inner: Arc::new(s3),
                    probe: Arc::new(probe),
                    prefix: prefix.clone(),
                    url: format!("s3://{bucket}/{prefix}"),
                })
            }
        }
    }

    fn key(&self, rest: &str) -> Key {
        if self.prefix.is_empty() {
            Key::from(rest)
        } else {
            Key::from(format!("{}/{rest}", self.prefix))
        }
    }

    fn scene_key(&self, id: &str) -> Key {
        self.key(&format!("scenes/{id}/scene.bin"))
    }

    pub(crate) fn chunk_key(&self, id: &str, c: u32, m: ChunkMeta) -> Key {
        self.key(&format!(
            "scenes/{id}/chunks/{c}-{:08x}-{}.bvck",
            m.crc32, m.bytes
        ))
    }

    /// Checks that the store answers (a list of the prefix).
    pub(crate) fn check(&self) -> Result<()> {
        let (inner, prefix) = (self.inner.clone(), self.key("scenes"));
        io::block_on(async move {
            let mut l = inner.list(Some(&prefix));
            if let Some(r) = l.next().await {
                r?;
            }
            Ok(())
        })
    }

    /// Whether the store answers now, without retries (`/healthz`): `Err` says how it failed,
    /// naming no bucket, key or endpoint (the log has the detail).
    pub(crate) async fn probe(&self) -> Result<(), String> {
        let prefix = self.key("scenes");
        let mut l = self.probe.list(Some(&prefix));
        let r = tokio::time::timeout(PROBE_TIMEOUT, l.next()).await;
        let e = match r {
            Ok(None | Some(Ok(_))) => return Ok(()),
            Ok(Some(Err(e))) => e.to_string(),
            Err(_) => "timed out".to_string(),
        };
        tracing::warn!(store = %self.url, error = %e, "the object store's health probe failed");
        let status = (500..600)
            .map(|c: u16| c.to_string())
            .find(|c| e.contains(&format!("status {c}")) || e.contains(&format!("{c} ")));
        Err(match status {
            Some(c) => format!("the object store answers {c}; requests are retried"),
            None if e == "timed out" => format!(
                "the object store did not answer within {} s; requests are retried",
                PROBE_TIMEOUT.as_secs()
            ),
            None => "the object store cannot be reached; requests are retried".to_string(),
        })
    }

    /// Writes an object (whole; a PUT is atomic).
    pub(crate) fn put(&self, key: Key, body: Vec<u8>) -> Result<()> {
        let inner = self.inner.clone();
        io::block_on(async move {
            inner
                .put(&key, PutPayload::from(body))
                .await
                .with_context(|| format!("cannot write object {key}"))?;
            Ok(())
        })
    }

    /// Writes a chunk object create-only: an object already there under its content name is
    /// the same chunk (a late worker's or a retry's) and is kept.
    pub(crate) fn put_chunk(&self, id: &str, c: u32, m: ChunkMeta, frame: Vec<u8>) -> Result<()> {
        let inner = self.inner.clone();
        let key = self.chunk_key(id, c, m);
        io::block_on(async move {
            let opts = PutOptions {
                mode: PutMode::Create,
                ..Default::default()
            };
            match inner
                .put_opts(&key, PutPayload::from(frame.clone()), opts)
                .await
            {
                Ok(_) | Err(object_store::Error::AlreadyExists { .. }) => Ok(()),
                // A store without conditional writes: a plain PUT (same name, same bytes).
                Err(object_store::Error::NotImplemented) => {
                    inner
                        .put(&key, PutPayload::from(frame))
                        .await
                        .with_context(|| format!("cannot write object {key}"))?;
                    Ok(())
                }
                Err(e) => Err(anyhow::Error::new(e).context(format!("cannot write object {key}"))),
            }
        })
    }

    /// Reads an object; `None` when it does not exist.
    pub(crate) async fn get_async(&self, key: Key) -> Result<Option<Vec<u8>>> {
        let inner = self.inner.clone();
        io::spawn(async move {
            match inner.get(&key).await {
                Ok(r) => Ok(Some(r.bytes().await?.to_vec())),
                Err(object_store::Error::NotFound { .. }) => Ok(None),
                Err(e) => Err(anyhow::Error::new(e).context(format!("cannot read object {key}"))),
            }
        })
        .await
    }

    /// [`ObjStore::get_async`] from blocking code.
    pub(crate) fn get(&self, key: Key) -> Result<Option<Vec<u8>>> {
        let inner = self.inner.clone();
        io::block_on(async move {
            match inner.get(&key).await {
                Ok(r) => Ok(Some(r.bytes().await?.to_vec())),
                Err(object_store::Error::NotFound { .. }) => Ok(None),
                Err(e) => Err(anyhow::Error::new(e).context(format!("cannot read object {key}"))),
            }
        })
    }

    pub(crate) fn scene_object(&self, id: &str) -> Key {
        self.scene_key(id)
    }

    /// Deletes one object (a missing one is fine).
    pub(crate) fn delete(&self, key: Key) -> Result<()> {
        let inner = self.inner.clone();
        io::block_on(async move {
            match inner.delete(&key).await {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => Ok(()),
                Err(e) => Err(anyhow::Error::new(e).context(format!("cannot delete {key}"))),
            }
        })
    }

    /// Deletes every object of a scene.
    pub(crate) fn delete_scene(&self, id: &str) -> Result<()> {
        let inner = self.inner.clone();
        let prefix = self.key(&format!("scenes/{id}"));
        io::block_on(async move {
            let keys: Vec<Key> = inner
                .list(Some(&prefix))
                .filter_map(|m| async move { m.ok().map(|m| m.location) })
                .collect()
                .await;
            for k in keys {
                match inner.delete(&k).await {
                    Ok(()) | Err(object_store::Error::NotFound { .. }) => {}
                    Err(e) => {
                        return Err(anyhow::Error::new(e).context(format!("cannot delete {k}")));
                    }
                }
            }
            Ok(())
        })
    }
}
