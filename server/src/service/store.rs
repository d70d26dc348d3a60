//! On-disk storage of scenes and tree chunks under the data directory:
//!
//! ```text
//! DIR/bspvt.sqlite                 the database (see `db`)
//! DIR/scenes/<id>/scene.bin        the scene as baked (mesh, lights, settings), framed + CRC-32
//! DIR/scenes/<id>/chunks/<n>.bvck  chunk n's frame, exactly as in a bake file
//! DIR/trash/                       scene directories being deleted
//! DIR/reserve                      ballast: 4 MiB given back when the disk fills up
//! ```
//!
//! In the distributed shape (`--database postgres://…`) the same operations go to an object
//! store instead (`objstore`: S3 or a shared folder); the ballast and free-space checks are
//! the local disk's and do nothing there.
//!
//! Guarantees:
//! - **durable before visible**: a file is written to a temporary name, synced, renamed into
//!   place and its directory synced; only then does the caller record it in the database;
//! - **verified on read**: a chunk is served only if its length and whole-file CRC-32 match the
//!   database and its frame parses (magic, frame CRC, the expected first vertex);
//!   anything else is [`ChunkRead::Corrupt`] and is never served;
//! - deleting a scene renames its directory into `trash/` first, so a half-deleted scene never
//!   looks like a live one;
//! - **a full disk is a state, not a crash**: a write that fails leaves no temporary file, and
//!   the ballast file (`reserve`, as CockroachDB's ballast) is removed when the disk fills so
//!   that the database can still record states and deletions; it is put back once the disk
//!   has room for it and as much again (`statvfs`), which ends the pause.

use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use bspvt_proto::encoding::peek_chunk;

use super::db::ChunkMeta;
use super::objstore::ObjStore;

/// The store rooted at the data directory, or an object store.
pub(crate) struct Store {
    root: PathBuf,
    object: Option<ObjStore>,
}

/// Size of the ballast file kept in the data directory.
const BALLAST_BYTES: usize = 4 << 20;

/// The result of reading a stored chunk.
pub(crate) enum ChunkRead {
    Ok(Vec<u8>),
    /// The file is missing.
    Missing,
    /// The file is there but is not the chunk the database describes.
    Corrupt(String),
}

/// What [`Store::list_chunks`] finds.
pub(crate) struct ChunkFiles {
    /// (chunk index, file length).
    pub chunks: Vec<(u32, u64)>,
    pub stray: Vec<PathBuf>,
}

const SCENE_MAGIC: &[u8; 4] = b"BSCN";

impl Store {
    /// Opens the store, creating its directories, and empties the trash.
    pub(crate) fn open(root: &Path) -> io::Result<Store> {
        fs::create_dir_all(root.join("scenes"))?;
        fs::create_dir_all(root.join("trash"))?;
        let s = Store {
            root: root.to_path_buf(),
            object: None,
        };
        s.empty_trash();
        s.restore_ballast();
        Ok(s)
    }

    /// A store of objects (the distributed shape).
    pub(crate) fn object(o: ObjStore) -> Store {
        Store {
            root: PathBuf::new(),
            object: Some(o),
        }
    }

    /// Whether the object store answers now (`ObjStore::probe`); `None` for a data folder.
    pub(crate) async fn probe_objects(&self) -> Option<Result<(), String>> {
        match &self.object {
            Some(o) => Some(o.probe().await),
            None => None,
        }
    }

    fn ballast(&self) -> PathBuf {
        self.root.join("reserve")
    }

    /// Bytes available to this process on the data disk (`None` where it cannot be read).
    pub(crate) fn free_bytes(&self) -> Option<u64> {
        if self.object.is_some() {
            return None;
        }
        #[cfg(unix)]
        {
            let s = rustix::fs::statvfs(&self.root).ok()?;
            Some(s.f_bavail.saturating_mul(s.f_frsize))
        }
        #[cfg(not(unix))]
        {
            None
        }
    }

    /// After the disk filled up: whether it has room again — for the ballast and as much again
    /// (so that the bake does not stop and start on the edge) — with the ballast put back.
    pub(crate) fn room_again(&self) -> bool {
        if self.object.is_some() {
            return true;
        }
        let margin = 2 * BALLAST_BYTES as u64;
        let extra = if self.ballast().exists() {
            0
        } else {
            BALLAST_BYTES as u64
        };
        if self.free_bytes().is_some_and(|f| f < margin + extra) {
            return false;
        }
        self.restore_ballast()
    }

    /// Gives the ballast's space back (the disk is full). True if there was one.
    pub(crate) fn release_ballast(&self) -> bool {
        if self.object.is_some() {
            return false;
        }
        fs::remove_file(self.ballast()).is_ok()
    }

    /// Writes the ballast if it is missing. False when the disk has no room for it (it is
    /// then left out): the bake waits rather than eat the database's reserve.
    pub(crate) fn restore_ballast(&self) -> bool {
        if self.object.is_some() {
            return true;
        }
        let path = self.ballast();
        if path.exists() {
            return true;
        }
        let tmp = self.root.join("reserve.tmp");
        let ok =
            write_synced(&tmp, &vec![0u8; BALLAST_BYTES]).and_then(|()| fs::rename(&tmp, &path));
        if ok.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        ok.is_ok()
    }

    pub(crate) fn scene_dir(&self, id: &str) -> PathBuf {
        self.root.join("scenes").join(id)
    }

    pub(crate) fn chunk_path(&self, id: &str, chunk: u32) -> PathBuf {
        self.scene_dir(id)
            .join("chunks")
            .join(format!("{chunk}.bvck"))
    }

    /// Writes a new scene's directory (its `scene.bin` and an empty `chunks/`) atomically:
    /// built under a temporary name, synced, then renamed into place.
    pub(crate) fn create_scene(&self, id: &str, scene_bin: &[u8]) -> io::Result<()> {
        if let Some(o) = &self.object {
            return o
                .put(o.scene_object(id), frame_scene(scene_bin))
                .map_err(io::Error::other);
        }
        let scenes = self.root.join("scenes");
        let tmp = scenes.join(format!("{id}.tmp"));
        if tmp.exists() {
            fs::remove_dir_all(&tmp)?;
        }
        let written = self.write_scene_dir(&tmp, scene_bin);
        if written.is_err() {
            let _ = fs::remove_dir_all(&tmp);
        }
        written?;
        fs::rename(&tmp, scenes.join(id))?;
        sync_dir(&scenes)
    }

    fn write_scene_dir(&self, tmp: &Path, scene_bin: &[u8]) -> io::Result<()> {
        fs::create_dir_all(tmp.join("chunks"))?;
        write_synced(&tmp.join("scene.bin"), &frame_scene(scene_bin))?;
        sync_dir(&tmp.join("chunks"))?;
        sync_dir(tmp)
    }

    /// Reads a scene's `scene.bin` payload, checking its frame and CRC. The error is public
    /// (a scene's `reason`): it names no server path; the log has the path.
    pub(crate) fn read_scene(&self, id: &str) -> Result<Vec<u8>, String> {
        self.read_scene_or_retry(id).map_err(|(e, _)| e)
    }

    /// [`Store::read_scene`], the error saying whether a later try may succeed (the object
    /// store failed, after its own retries) or not (missing, corrupt).
    pub(crate) fn read_scene_or_retry(&self, id: &str) -> Result<Vec<u8>, (String, bool)> {
        if let Some(o) = &self.object {
            let data = match o.get(o.scene_object(id)) {
                Ok(Some(d)) => d,
                Ok(None) => return Err(("the stored scene is missing".into(), false)),
                Err(e) => {
                    tracing::error!(scene = %id, error = %format!("{e:#}"), "cannot read the stored scene");
                    return Err((
                        "cannot read the stored scene from the object store".into(),
                        true,
                    ));
                }
            };
            return unframe_scene(&data).map(<[u8]>::to_vec).map_err(|what| {
                tracing::error!(scene = %id, what, "the stored scene is corrupt");
                (format!("the stored scene is corrupt: {what}"), false)
            });
        }
        let path = self.scene_dir(id).join("scene.bin");
        let data = fs::read(&path).map_err(|e| {
            tracing::error!(scene = %id, path = %path.display(), error = %e, "cannot read the stored scene");
            (format!("cannot read the stored scene: {}", e.kind()), false)
        })?;
        unframe_scene(&data).map(<[u8]>::to_vec).map_err(|what| {
            tracing::error!(scene = %id, path = %path.display(), what, "the stored scene is corrupt");
            (format!("the stored scene is corrupt: {what}"), false)
        })
    }

    /// Makes chunk `chunk`'s frame durable at its final path (temp file, fsync, rename, fsync
    /// of the directory). Fails, writing nothing, when the scene directory is gone (deleted).
    pub(crate) fn write_chunk(&self, id: &str, chunk: u32, frame: &[u8]) -> io::Result<()> {
        if let Some(o) = &self.object {
            let meta = ChunkMeta {
                bytes: frame.len() as u32,
                crc32: crc32fast::hash(frame),
            };
            return o
                .put_chunk(id, chunk, meta, frame.to_vec())
                // The whole chain (the object, the client's error, its cause: a timeout, a
                // status), which the log and the put-back reason then name.
                .map_err(|e| io::Error::other(format!("{e:#}")));
        }
        let path = self.chunk_path(id, chunk);
        let dir = path
            .parent()
            .ok_or_else(|| io::Error::other("chunk path has no directory"))?;
        let tmp = dir.join(format!("{chunk}.bvck.tmp"));
        let written = write_synced(&tmp, frame).and_then(|()| fs::rename(&tmp, &path));
        if written.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        written?;
        sync_dir(dir)
    }

    /// Reads and verifies chunk `chunk` against what the database recorded.
    pub(crate) async fn read_chunk(
        &self,
        id: &str,
        chunk: u32,
        meta: ChunkMeta,
        first_vertex: u32,
    ) -> ChunkRead {
        if let Some(o) = &self.object {
            return match o.get_async(o.chunk_key(id, chunk, meta)).await {
                Ok(Some(data)) => match verify_chunk(&data, meta, first_vertex) {
                    Ok(()) => ChunkRead::Ok(data),
                    Err(why) => ChunkRead::Corrupt(why),
                },
                Ok(None) => ChunkRead::Missing,
                Err(e) => ChunkRead::Corrupt(format!("{e:#}")),
            };
        }
        let path = self.chunk_path(id, chunk);
        match tokio::fs::read(&path).await {
            Ok(data) => match verify_chunk(&data, meta, first_vertex) {
                Ok(()) => ChunkRead::Ok(data),
                Err(why) => ChunkRead::Corrupt(why),
            },
            Err(e) if e.kind() == io::ErrorKind::NotFound => ChunkRead::Missing,
            Err(e) => ChunkRead::Corrupt(format!("cannot read {}: {e}", path.display())),
        }
    }

    /// Removes a chunk file (after it was found corrupt); a missing file is fine.
    pub(crate) fn remove_chunk(&self, id: &str, chunk: u32) {
        let _ = fs::remove_file(self.chunk_path(id, chunk));
    }

    /// Removes the stored chunk that `meta` describes (found corrupt); a missing one is fine.
    pub(crate) fn forget_chunk(&self, id: &str, chunk: u32, meta: ChunkMeta) {
        match &self.object {
            Some(o) => {
                if let Err(e) = o.delete(o.chunk_key(id, chunk, meta)) {
                    tracing::warn!(scene = %id, chunk, error = %format!("{e:#}"), "cannot delete a corrupt chunk object");
                }
            }
            None => self.remove_chunk(id, chunk),
        }
    }

    /// The chunk files present for a scene and stray files (temporary or unknown names) that
    /// no reader will ever use.
    pub(crate) fn list_chunks(&self, id: &str) -> io::Result<ChunkFiles> {
        let mut chunks = Vec::new();
        let mut stray = Vec::new();
        for e in fs::read_dir(self.scene_dir(id).join("chunks"))? {
            let e = e?;
            let name = e.file_name();
            let idx = name
                .to_str()
                .and_then(|n| n.strip_suffix(".bvck"))
                .and_then(|n| n.parse::<u32>().ok());
            match idx {
                Some(i) => chunks.push((i, e.metadata()?.len())),
                None => stray.push(e.path()),
            }
        }
        Ok(ChunkFiles { chunks, stray })
    }

    /// How many scene folders `root` holds (temporary ones not counted), without opening or
    /// changing anything: 0 when there is no `scenes` folder.
    pub(crate) fn scene_folders(root: &Path) -> io::Result<usize> {
        match fs::read_dir(root.join("scenes")) {
            Ok(rd) => {
                let mut n = 0;
                for e in rd {
                    let e = e?;
                    let name = e.file_name();
                    if e.file_type()?.is_dir() && !name.to_string_lossy().ends_with(".tmp") {
                        n += 1;
                    }
                }
                Ok(n)
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(0),
            Err(e) => Err(e),
        }
    }

    /// Ids of the scene directories present (temporary ones are removed).
    pub(crate) fn scene_ids(&self) -> io::Result<Vec<String>> {
        let mut ids = Vec::new();
        for e in fs::read_dir(self.root.join("scenes"))? {
            let e = e?;
            let Some(name) = e.file_name().to_str().map(str::to_string) else {
                continue;
            };
            if name.ends_with(".tmp") {
                let _ = fs::remove_dir_all(e.path());
            } else {
                ids.push(name);
            }
        }
        Ok(ids)
    }

    /// Deletes a scene's directory: renamed into the trash (atomic), then removed.
    pub(crate) fn remove_scene(&self, id: &str) -> io::Result<()> {
        if let Some(o) = &self.object {
            return o.delete_scene(id).map_err(io::Error::other);
        }
        let dir = self.scene_dir(id);
        if !dir.exists() {
            return Ok(());
        }
        let trash = self
            .root
            .join("trash")
            .join(format!("{id}-{}", super::db::now_ms()));
        fs::rename(&dir, &trash)?;
        sync_dir(&self.root.join("scenes"))?;
        fs::remove_dir_all(&trash)
    }

    fn empty_trash(&self) {
        if let Ok(rd) = fs::read_dir(self.root.join("trash")) {
            for e in rd.flatten() {
                let _ = fs::remove_dir_all(e.path());
            }
        }
    }
}

/// A scene's stored form: magic, length, the payload, its CRC-32.
fn frame_scene(scene_bin: &[u8]) -> Vec<u8> {
    let mut body = Vec::with_capacity(scene_bin.len() + 16);
    body.extend_from_slice(SCENE_MAGIC);
    body.extend_from_slice(&(scene_bin.len() as u64).to_le_bytes());
    body.extend_from_slice(scene_bin);
    body.extend_from_slice(&crc32fast::hash(scene_bin).to_le_bytes());
    body
}

/// The payload of a stored scene, or what is wrong with it.
fn unframe_scene(data: &[u8]) -> Result<&[u8], &'static str> {
    if data.len() < 16 || &data[..4] != SCENE_MAGIC {
        return Err("bad header");
    }
    let mut len = [0u8; 8];
    len.copy_from_slice(&data[4..12]);
    if u64::from_le_bytes(len) != (data.len() - 16) as u64 {
        return Err("length mismatch");
    }
    let body = &data[12..data.len() - 4];
    let mut crc = [0u8; 4];
    crc.copy_from_slice(&data[data.len() - 4..]);
    if u32::from_le_bytes(crc) != crc32fast::hash(body) {
        return Err("checksum mismatch");
    }
    Ok(body)
}

/// Checks a chunk file against its database record and its own framing.
pub(crate) fn verify_chunk(data: &[u8], meta: ChunkMeta, first_vertex: u32) -> Result<(), String> {
    if data.len() as u64 != meta.bytes as u64 {
        return Err(format!(
            "chunk file is {} bytes, the database says {}",
            data.len(),
            meta.bytes
        ));
    }
    let crc = crc32fast::hash(data);
    if crc != meta.crc32 {
        return Err(format!(
            "chunk file CRC-32 {crc:#010x}, the database says {:#010x}",
            meta.crc32
        ));
    }
    let (h, used) = peek_chunk(data).map_err(|e| format!("chunk frame: {e}"))?;
    if used != data.len() || h.first_vertex != first_vertex {
        return Err(format!(
            "chunk frame covers vertex {} and {used} bytes; expected vertex {first_vertex} and {} bytes",
            h.first_vertex,
            data.len()
        ));
    }
    Ok(())
}

fn write_synced(path: &Path, data: &[u8]) -> io::Result<()> {
    let mut f = File::create(path)?;
    f.write_all(data)?;
    f.sync_all()
}

fn sync_dir(dir: &Path) -> io::Result<()> {
    File::open(dir)?.sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scenes_and_chunks_round_trip_and_corruption_is_caught() {
        let dir = tempfile::tempdir().expect("temp dir");
        let s = Store::open(dir.path()).expect("open");
        s.create_scene("abc", b"scene bytes").expect("create");
        assert_eq!(s.read_scene("abc").expect("read"), b"scene bytes");
        let frame = bspvt_proto::encoding::encode_chunk(
            64,
            &[bspvt_proto::bspvt::VertexTrees::default()],
            &bspvt_proto::bspvt::LineCodec::for_resolution(16),
        );
        s.write_chunk("abc", 2, &frame).expect("write chunk");
        let meta = ChunkMeta {
            bytes: frame.len() as u32,
            crc32: crc32fast::hash(&frame),
        };
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .expect("runtime");
        assert!(matches!(
            rt.block_on(s.read_chunk("abc", 2, meta, 64)),
            ChunkRead::Ok(d) if d == frame
        ));
        assert!(matches!(
            rt.block_on(s.read_chunk("abc", 2, meta, 0)),
            ChunkRead::Corrupt(_)
        ));
        assert!(matches!(
            rt.block_on(s.read_chunk("abc", 3, meta, 64)),
            ChunkRead::Missing
        ));
        let mut bad = frame.clone();
        let last = bad.len() - 5;
        bad[last] ^= 1;
        std::fs::write(s.chunk_path("abc", 2), &bad).expect("corrupt");
        assert!(matches!(
            rt.block_on(s.read_chunk("abc", 2, meta, 64)),
            ChunkRead::Corrupt(_)
        ));
        let files = s.list_chunks("abc").expect("list");
        assert_eq!(files.chunks, vec![(2, frame.len() as u64)]);
        assert!(files.stray.is_empty());
        std::fs::write(
            s.scene_dir("abc").join("scene.bin"),
            b"BSCNxxxxxxxxxxxxxxxx",
        )
        .expect("corrupt scene");
        assert!(s.read_scene("abc").is_err());
        s.remove_scene("abc").expect("remove");
        assert!(!s.scene_dir("abc").exists());
        assert_eq!(s.scene_ids().expect("ids"), Vec::<String>::new());
    }
}
