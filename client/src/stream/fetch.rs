//! The background fetcher: fills a scene's trees from the cache, then from the service, in the
//! order the view needs them, and survives dropped connections.
//!
//! Order: chunks that hold the vertices the camera sees first (when the bake is done), then the
//! rest; while the bake runs, in bake order (a request for a chunk not yet baked waits for it).
//! A dropped connection is retried with back-off and asks only for the chunks still missing.
//! Every chunk received is written to the cache, so a later start fetches nothing already here;
//! a complete cache is validated with the full stream's ETag (`If-None-Match` → 304).

use std::io::Read;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{Result, bail};

use super::error::StreamError;
use bspvt_proto::api::JobState;
use bspvt_proto::api::SceneStatus;
use bspvt_proto::encoding::{BakeHeader, Chunk, decode_chunk, decode_header};

use super::cache::Cache;
use super::frames::{Frame, FrameReader};
use super::remote::Remote;

/// What the fetcher tells the renderer.
pub enum Update {
    /// The bake's header (first).
    Header(BakeHeader),
    /// Trees of one chunk.
    Chunk {
        /// The chunk's trees.
        chunk: Chunk,
        /// Read from the disk cache (not the network).
        cached: bool,
    },
    /// The bake's status, as the service reports it.
    Status(Box<SceneStatus>),
    /// Every chunk is here.
    Done,
    /// The fetcher gave up (the message says why); what arrived stays usable.
    Failed(String),
}

/// Counters shared with the caller (for overlays, tests and benchmarks).
#[derive(Default)]
pub struct Counters {
    /// Tree-stream bytes received from the network (frames; HTTP framing not counted).
    pub tree_bytes: AtomicU64,
    /// Chunks received from the network.
    pub chunks_fetched: AtomicU64,
    /// Chunks read from the disk cache.
    pub chunks_cached: AtomicU64,
    /// Tree-stream requests made.
    pub requests: AtomicU64,
    /// Requests made again after a transient failure (dropped connection, busy service).
    pub reconnects: AtomicU64,
    /// Set by the caller to stop the fetcher.
    pub(crate) stop: AtomicBool,
    /// Set by the fetcher when it has sent its last update (`Done` or `Failed`).
    pub(crate) finished: AtomicBool,
    /// Set by the fetcher once what the disk cache holds has been sent (before any request).
    pub(crate) cache_read: AtomicBool,
}

/// How the fetcher works.
pub struct FetchOptions {
    /// Vertices wanted first (the camera's).
    pub priority: Vec<u32>,
    /// The on-disk cache of this scene (`None`: none).
    pub cache: Option<Cache>,
    /// Give up after this many chunks from the network (tests: a connection that drops).
    pub max_chunks: Option<u64>,
    /// Consecutive failed attempts before giving up.
    pub max_retries: u32,
}

impl Default for FetchOptions {
    fn default() -> FetchOptions {
        FetchOptions {
            priority: Vec::new(),
            cache: None,
            max_chunks: None,
            max_retries: 8,
        }
    }
}

/// Starts fetching scene `id`'s trees on a background thread.
pub fn spawn(
    remote: Remote,
    id: String,
    opts: FetchOptions,
) -> (Receiver<Update>, Arc<Counters>, JoinHandle<()>) {
    let (tx, rx) = channel();
    let counters = Arc::new(Counters::default());
    spawn_status_relay(remote.clone(), id.clone(), tx.clone(), counters.clone());
    let c = counters.clone();
    let handle = std::thread::Builder::new()
        .name("bspvt-fetch".into())
        .spawn(move || {
            let mut f = Fetcher {
                remote,
                id,
                opts,
                tx,
                counters: c,
                header: None,
                have: Vec::new(),
            };
            let last = match f.run() {
                Ok(()) => Update::Done,
                Err(e) => Update::Failed(format!("{e:#}")),
            };
            f.counters.finished.store(true, Ordering::Relaxed);
            let _ = f.tx.send(last);
        })
        .expect("spawning a thread");
    (rx, counters, handle)
}

/// Relays the bake's status every half second while it is queued or baking (a tree request
/// waiting for chunks says nothing about progress), so overlays and progress bars move.
fn spawn_status_relay(remote: Remote, id: String, tx: Sender<Update>, counters: Arc<Counters>) {
    let relay = move || {
        while !counters.stop.load(Ordering::Relaxed) && !counters.finished.load(Ordering::Relaxed) {
            match remote.status(&id) {
                Ok(s) => {
                    let finished = !matches!(s.state, JobState::Queued | JobState::Baking);
                    if tx.send(Update::Status(Box::new(s))).is_err() || finished {
                        return;
                    }
                }
                Err(e) => tracing::debug!("status: {e:#}"),
            }
            std::thread::sleep(Duration::from_millis(500));
        }
    };
    if let Err(e) = std::thread::Builder::new()
        .name("bspvt-status".into())
        .spawn(relay)
    {
        tracing::warn!("no bake progress updates: {e}");
    }
}

struct Fetcher {
    remote: Remote,
    id: String,
    opts: FetchOptions,
    tx: Sender<Update>,
    counters: Arc<Counters>,
    header: Option<(BakeHeader, Vec<u8>)>,
    /// Chunks present, by index.
    have: Vec<bool>,
}

impl Fetcher {
    fn send(&self, u: Update) -> Result<()> {
        if self.tx.send(u).is_err() || self.counters.stop.load(Ordering::Relaxed) {
            bail!("stopped");
        }
        Ok(())
    }

    fn set_header(&mut self, h: BakeHeader, bytes: Vec<u8>) -> Result<()> {
        if let Some((_, old)) = &self.header {
            if *old != bytes {
                bail!("the server's tree header changed under the client");
            }
            return Ok(());
        }
        self.have = vec![false; h.chunk_count() as usize];
        self.header = Some((h.clone(), bytes));
        self.send(Update::Header(h))
    }

    fn accept(&mut self, chunk: Chunk, frame: &[u8], cached: bool) -> Result<()> {
        let Some((h, _)) = &self.header else {
            bail!("a chunk before the header");
        };
        let index = (chunk.first_vertex / h.chunk_vertices.max(1)) as usize;
        if index >= self.have.len() || self.have[index] {
            return Ok(()); // a repeat (e.g. a re-requested run): nothing new
        }
        self.have[index] = true;
        if cached {
            self.counters.chunks_cached.fetch_add(1, Ordering::Relaxed);
        } else {
            self.counters.chunks_fetched.fetch_add(1, Ordering::Relaxed);
            if let Some(c) = &self.opts.cache {
                c.put_chunk(index as u32, frame)?;
            }
        }
        self.send(Update::Chunk { chunk, cached })
    }

    fn complete(&self) -> bool {
        self.header.is_some() && self.have.iter().all(|&h| h)
    }

    /// Loads what the cache holds; corrupt entries are ignored (and fetched again).
    fn load_cache(&mut self) -> Result<()> {
        let Some(cache) = &self.opts.cache else {
            return Ok(());
        };
        let Some(hb) = cache.header() else {
            return Ok(());
        };
        let Ok((h, _)) = decode_header(&hb) else {
            cache.clear()?;
            return Ok(());
        };
        let chunks = cache.chunks();
        self.set_header(h.clone(), hb)?;
        for (_, frame) in chunks {
            if let Ok((chunk, _)) = decode_chunk(&frame, &h) {
                self.accept(chunk, &frame, true)?;
            }
        }
        Ok(())
    }

    fn run(&mut self) -> Result<()> {
        let loaded = self.load_cache();
        self.counters.cache_read.store(true, Ordering::Release);
        loaded?;
        // A complete cache: one conditional request validates it.
        if self.complete()
            && let Some(etag) = self.opts.cache.as_ref().and_then(Cache::etag)
        {
            match self.remote.trees(&self.id, None, Some(&etag)) {
                Ok(r) if r.status == 304 => return Ok(()),
                Ok(_) => {
                    // The server's stream is not what we cached: start over.
                    if let Some(c) = &self.opts.cache {
                        c.clear()?;
                    }
                    self.header = None;
                    self.have.clear();
                }
                Err(e) => {
                    // Offline: what is cached is a finished bake; use it.
                    tracing::warn!("cannot validate the cache ({e:#}); using it");
                    return Ok(());
                }
            }
        }
        let mut failures = 0;
        let mut status = self.remote.status(&self.id)?;
        loop {
            if !self.complete() {
                let before = self.counters.chunks_fetched.load(Ordering::Relaxed);
                match self.fetch_missing(&status) {
                    Ok(()) => failures = 0,
                    Err(e) => {
                        // Final answers (no such scene, gone, refused) end the stream at
                        // once; dropped connections and a busy service are retried.
                        if self.counters.stop.load(Ordering::Relaxed)
                            || StreamError::of(&e).is_some_and(StreamError::is_final)
                        {
                            return Err(e);
                        }
                        let progressed =
                            self.counters.chunks_fetched.load(Ordering::Relaxed) > before;
                        failures = if progressed { 1 } else { failures + 1 };
                        if failures > self.opts.max_retries {
                            return Err(e.context(format!("giving up after {failures} attempts")));
                        }
                        self.counters.reconnects.fetch_add(1, Ordering::Relaxed);
                        tracing::warn!("tree stream interrupted ({e:#}); retrying");
                        std::thread::sleep(Duration::from_millis(100 << failures.min(5)));
                    }
                }
            }
            match self.remote.status(&self.id) {
                Ok(s) => {
                    status = s;
                    self.send(Update::Status(Box::new(status.clone())))?;
                }
                Err(e) if !e.is_final() && failures < self.opts.max_retries => {
                    failures += 1;
                    tracing::warn!("status: {e:#}");
                    std::thread::sleep(Duration::from_millis(100 << failures.min(5)));
                    continue;
                }
                Err(e) => return Err(e.into()),
            }
            match status.state {
                JobState::Failed => {
                    return Err(StreamError::BakeFailed(
                        status
                            .reason
                            .clone()
                            .unwrap_or_else(|| "no reason given".into()),
                    )
                    .into());
                }
                JobState::Cancelled => return Err(StreamError::Deleted.into()),
                _ => {}
            }
            if self.complete() {
                if status.state == JobState::Done
                    && let Some(c) = &self.opts.cache
                    && let Ok(Some(etag)) = self.remote.trees_etag(&self.id)
                {
                    c.put_etag(&etag)?;
                }
                return Ok(());
            }
        }
    }

    /// Requests the missing chunks, run by run, in the order the view needs them.
    fn fetch_missing(&mut self, status: &SceneStatus) -> Result<()> {
        let Some((h, _)) = &self.header else {
            // No header yet: the first chunk's request brings it.
            return self.fetch_run(0, 1);
        };
        let cv = h.chunk_vertices.max(1);
        let n = self.have.len() as u32;
        let mut order: Vec<u32> = Vec::new();
        if status.state == JobState::Done {
            let mut wanted = vec![false; n as usize];
            for &v in &self.opts.priority {
                if let Some(w) = wanted.get_mut((v / cv) as usize) {
                    *w = true;
                }
            }
            order.extend((0..n).filter(|&c| wanted[c as usize]));
            order.extend((0..n).filter(|&c| !wanted[c as usize]));
        } else {
            order.extend(0..n);
        }
        order.retain(|&c| !self.have[c as usize]);
        // Contiguous runs, in order.
        let mut runs: Vec<(u32, u32)> = Vec::new();
        for c in order {
            match runs.last_mut() {
                Some((_, end)) if *end == c => *end += 1,
                _ => runs.push((c, c + 1)),
            }
        }
        for (a, b) in runs {
            self.fetch_run(a, b)?;
        }
        Ok(())
    }

    /// Streams chunks `a..b`.
    fn fetch_run(&mut self, a: u32, b: u32) -> Result<()> {
        let cv = self.header.as_ref().map_or(1, |(h, _)| h.chunk_vertices);
        let vcount = self
            .header
            .as_ref()
            .map_or(u32::MAX, |(h, _)| h.vertex_count);
        let range = (a.saturating_mul(cv), b.saturating_mul(cv).min(vcount));
        self.counters.requests.fetch_add(1, Ordering::Relaxed);
        let mut r = self.remote.trees(&self.id, Some(range), None)?;
        let mut reader = FrameReader::new();
        let mut buf = vec![0u8; 64 << 10];
        loop {
            let k = r
                .body
                .read(&mut buf)
                .map_err(|source| StreamError::Interrupted {
                    what: format!("trees of scene {}", self.id),
                    source,
                })?;
            if k == 0 {
                if reader.pending() > 0 {
                    bail!("the tree stream ended in the middle of a frame");
                }
                return Ok(());
            }
            self.counters
                .tree_bytes
                .fetch_add(k as u64, Ordering::Relaxed);
            reader.push(&buf[..k]);
            while let Some(frame) = reader.next_frame()? {
                match frame {
                    Frame::Header(h, bytes) => {
                        if let Some(c) = &self.opts.cache
                            && self.header.is_none()
                        {
                            c.put_header(&bytes)?;
                        }
                        self.set_header(h, bytes)?;
                    }
                    Frame::Chunk(chunk, bytes) => {
                        self.accept(chunk, &bytes, false)?;
                        if let Some(max) = self.opts.max_chunks
                            && self.counters.chunks_fetched.load(Ordering::Relaxed) >= max
                        {
                            self.counters.stop.store(true, Ordering::Relaxed);
                            bail!("stopped after {max} chunks (max_chunks)");
                        }
                    }
                }
            }
        }
    }
}
