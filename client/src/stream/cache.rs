//! The client's on-disk cache of a scene: `ROOT/<scene id>/` holds `scene.bin` (the scene as
//! baked, with its ETag), `header.bin` (the tree stream's header frame), `chunks/<n>.bvck`
//! (chunk frames exactly as received; each carries its own CRC-32, checked on load) and
//! `etag` (the validator of the complete tree stream, once the bake is done and every chunk is
//! here). Chunks are immutable: a bake is deterministic, so a chunk received while the bake was
//! running is the chunk of the finished bake.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// The on-disk cache of one scene: its scene bytes, bake header, chunks and the stream's
/// validator, each written atomically.
pub struct Cache {
    dir: PathBuf,
}

impl Cache {
    /// The cache of scene `id` under `root` (created on first write).
    pub fn new(root: &Path, id: &str) -> Result<Cache> {
        anyhow::ensure!(
            !id.is_empty() && id.chars().all(|c| c.is_ascii_alphanumeric() || c == '-'),
            "scene id {id:?} is not a valid id"
        );
        Ok(Cache { dir: root.join(id) })
    }

    fn read(&self, name: &str) -> Option<Vec<u8>> {
        fs::read(self.dir.join(name)).ok()
    }

    /// Writes atomically (temporary file, rename), so a killed client leaves no torn file.
    fn write(&self, name: &str, bytes: &[u8]) -> Result<()> {
        let path = self.dir.join(name);
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
        let tmp = path.with_extension("tmp");
        fs::write(&tmp, bytes).with_context(|| format!("cannot write {}", tmp.display()))?;
        fs::rename(&tmp, &path).with_context(|| format!("cannot write {}", path.display()))
    }

    pub(crate) fn scene(&self) -> Option<(Vec<u8>, String)> {
        let etag = String::from_utf8(self.read("scene.etag")?).ok()?;
        Some((self.read("scene.bin")?, etag))
    }

    pub(crate) fn put_scene(&self, bytes: &[u8], etag: &str) -> Result<()> {
        self.write("scene.bin", bytes)?;
        self.write("scene.etag", etag.as_bytes())
    }

    pub(crate) fn header(&self) -> Option<Vec<u8>> {
        self.read("header.bin")
    }

    pub(crate) fn put_header(&self, bytes: &[u8]) -> Result<()> {
        self.write("header.bin", bytes)
    }

    /// Chunk frames present, by index.
    pub(crate) fn chunks(&self) -> Vec<(u32, Vec<u8>)> {
        let Ok(dir) = fs::read_dir(self.dir.join("chunks")) else {
            return Vec::new();
        };
        let mut out: Vec<(u32, Vec<u8>)> = dir
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().into_string().ok()?;
                let n: u32 = name.strip_suffix(".bvck")?.parse().ok()?;
                Some((n, fs::read(e.path()).ok()?))
            })
            .collect();
        out.sort_by_key(|c| c.0);
        out
    }

    pub(crate) fn put_chunk(&self, index: u32, frame: &[u8]) -> Result<()> {
        self.write(&format!("chunks/{index}.bvck"), frame)
    }

    pub(crate) fn etag(&self) -> Option<String> {
        String::from_utf8(self.read("etag")?).ok()
    }

    pub(crate) fn put_etag(&self, etag: &str) -> Result<()> {
        self.write("etag", etag.as_bytes())
    }

    /// Forgets everything (the server no longer matches the cache).
    pub(crate) fn clear(&self) -> Result<()> {
        match fs::remove_dir_all(&self.dir) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                Err(e).with_context(|| format!("cannot clear {}", self.dir.display()))
            }
            _ => Ok(()),
        }
    }
}
