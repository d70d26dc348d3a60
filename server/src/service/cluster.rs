//! Bake workers of the distributed shape (`bspvt-server worker`, and `serve --workers N`
//! against PostgreSQL): lease a chunk, bake it ([`super::chunk`], as the embedded scheduler
//! does), write its object, record it under the lease; a heartbeat renews the leases.
//!
//! Guarantees:
//! - **object before record**: a chunk's object is written before the database records it,
//!   so a recorded chunk is always readable;
//! - a worker that dies loses its leases after the lease time and other workers bake exactly
//!   its unfinished chunks; a worker that was silent for longer than that (paused, cut off)
//!   is fenced by the database when it comes back (`PgDb::complete`): its object is the same
//!   content under the same name, its record is refused and counted as fenced;
//! - a scene deleted or failed while a worker bakes one of its chunks is seen at the next
//!   heartbeat: the worker drops the result and deletes an object it wrote for it;
//! - a chunk that fails (unreadable scene, storage error, panic) is given back with the
//!   reason; after `max_failures` different workers its scene fails with that reason;
//! - the worker stops cleanly on SIGINT/SIGTERM: it finishes the chunks it holds, then gives
//!   back its leases.

use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use bspvt_bake::Baker;

use super::db::Db;
use super::metrics::Metrics;
use super::pg::{Lease, PgDb, Recorded};
use super::pool::PoolSettings;
use super::store::Store;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Scenes whose baker a worker keeps (leases go round-robin over scenes).
const BAKERS_KEPT: usize = 8;

/// One worker process's (or one `serve`'s) workers: an id in the database, a heartbeat and
/// `loops` threads taking chunks.
pub(crate) struct Workers {
    db: Arc<Db>,
    store: Arc<Store>,
    metrics: Arc<Metrics>,
    pool: rayon::ThreadPool,
    id: String,
    max_failures: u32,
    stop: AtomicBool,
    /// Leases held now: token → lease.
    held: Mutex<HashMap<i64, Lease>>,
    /// Tokens the heartbeat found taken over or whose scene is gone.
    lost: Mutex<HashSet<i64>>,
    bakers: Mutex<Vec<(String, Arc<Baker>)>>,
    /// Chunks put back in a row for a failing store (`retry_later`'s backoff).
    setbacks: AtomicU32,
}

/// Why a chunk was not baked.
enum Failure {
    /// The chunk's own (a corrupt or missing scene, a bake that panicked): it counts towards
    /// failing the scene.
    Chunk(String),
    /// The object store's or the database's, for now: the chunk is tried again later.
    Transient(String),
}

impl Workers {
    /// Registers worker `id` and starts `loops` threads on a bake pool of `pool`'s settings.
    pub(crate) fn start(
        db: Arc<Db>,
        store: Arc<Store>,
        metrics: Arc<Metrics>,
        id: String,
        loops: usize,
        pool: PoolSettings,
        max_failures: u32,
    ) -> Result<(Arc<Workers>, Vec<std::thread::JoinHandle<()>>)> {
        let pool = pool.build()?;
        let w = Arc::new(Workers {
            db,
            store,
            metrics,
            id,
            max_failures,
            stop: AtomicBool::new(false),
            held: Mutex::new(HashMap::new()),
            lost: Mutex::new(HashSet::new()),
            setbacks: AtomicU32::new(0),
            bakers: Mutex::new(Vec::new()),
            pool,
        });
        let host = std::env::var("HOSTNAME").unwrap_or_else(|_| "localhost".into());
        w.pg()?
            .register_worker(&w.id, &host, w.pool.current_num_threads() as u32)?;
        tracing::info!(worker = %w.id, loops, threads = w.pool.current_num_threads(), "bake worker registered");
        let mut handles = Vec::new();
        let hb = w.clone();
        handles.push(
            std::thread::Builder::new()
                .name("heartbeat".into())
                .spawn(move || hb.heartbeat())
                .context("cannot start the heartbeat")?,
        );
        for i in 0..loops {
            let wl = w.clone();
            handles.push(
                std::thread::Builder::new()
                    .name(format!("bake-worker-{i}"))
                    .spawn(move || wl.work())
                    .context("cannot start a bake worker")?,
            );
        }
        Ok((w, handles))
    }

    fn pg(&self) -> Result<&PgDb> {
        self.db
            .pg()
            .context("bake workers of the distributed shape need a postgres:// database")
    }

    /// Asks the workers to stop after the chunks they hold.
    pub(crate) fn stop(&self) {
        self.stop.store(true, Ordering::Release);
    }

    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }

    /// Renews the leases held and reports this worker alive, every third of the lease time.
    fn heartbeat(&self) {
        let Ok(pg) = self.pg() else { return };
        let every = pg.lease_ttl / 3;
        while !self.stopping() {
            let tokens: Vec<i64> = lock(&self.held).keys().copied().collect();
            match pg.heartbeat(&self.id, &tokens) {
                Ok(kept) => {
                    let kept: HashSet<i64> = kept.into_iter().collect();
                    let mut lost = lock(&self.lost);
                    for t in tokens.into_iter().filter(|t| !kept.contains(t)) {
                        if lost.insert(t) {
                            tracing::warn!(worker = %self.id, token = t, "lease lost (taken over, or its scene deleted)");
                        }
                    }
                }
                Err(e) => {
                    tracing::warn!(worker = %self.id, error = %format!("{e:#}"), "heartbeat failed")
                }
            }
            let t0 = Instant::now();
            while t0.elapsed() < every && !self.stopping() {
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        // Leases still held are given back by the caller once the loops have finished.
    }

    /// Takes and bakes chunks until stopped.
    fn work(&self) {
        let Ok(pg) = self.pg() else { return };
        let mut idle = Duration::from_millis(20);
        while !self.stopping() {
            let lease = match pg.lease(&self.id) {
                Ok(Some(l)) => l,
                Ok(None) => {
                    std::thread::sleep(idle);
                    idle = (idle * 2).min(Duration::from_millis(250));
                    continue;
                }
                Err(e) => {
                    tracing::error!(worker = %self.id, error = %format!("{e:#}"), "cannot lease a chunk");
                    std::thread::sleep(Duration::from_secs(1));
                    continue;
                }
            };
            idle = Duration::from_millis(20);
            lock(&self.held).insert(lease.token, lease.clone());
            let span = tracing::info_span!("chunk", scene = %lease.scene_id, chunk = lease.idx);
            let _enter = span.enter();
            if let Err(e) = self.bake_one(pg, &lease) {
                tracing::error!(error = %format!("{e:#}"), "cannot record the chunk's outcome; its lease will expire");
            }
            lock(&self.held).remove(&lease.token);
            lock(&self.lost).remove(&lease.token);
        }
    }

    fn bake_one(&self, pg: &PgDb, lease: &Lease) -> Result<()> {
        let t0 = Instant::now();
        let baker = match self.baker(pg, &lease.scene_id) {
            Ok(Some(b)) => b,
            Ok(None) => return Ok(()), // deleted meanwhile
            Err(Failure::Chunk(reason)) => return self.failed(pg, lease, &reason),
            Err(Failure::Transient(reason)) => return self.retry_later(pg, lease, &reason),
        };
        let (frame, meta, vertices) = match super::chunk::bake(lease.idx, || {
            Ok(self.pool.install(|| baker.bake_chunk(lease.idx)))
        }) {
            Ok(r) => r,
            Err(reason) => return self.failed(pg, lease, &reason),
        };
        drop(baker);
        if lock(&self.lost).contains(&lease.token) && !self.scene_live(pg, &lease.scene_id)? {
            tracing::info!("scene deleted or failed while its chunk was baked; result dropped");
            return Ok(());
        }
        if let Err(e) = self.store.write_chunk(&lease.scene_id, lease.idx, &frame) {
            tracing::error!(error = %e, "cannot write a chunk object");
            return self.retry_later(
                pg,
                lease,
                &format!("storage error writing chunk {}: {e}", lease.idx),
            );
        }
        self.setbacks.store(0, Ordering::Relaxed);
        match pg.complete(&self.id, lease, meta)? {
            Recorded::Yes => {
                self.metrics.chunk_baked(vertices, t0.elapsed());
                tracing::debug!(
                    bytes = meta.bytes,
                    ms = t0.elapsed().as_secs_f64() * 1e3,
                    "chunk durable"
                );
            }
            Recorded::Fenced => {
                tracing::warn!(
                    "stale lease: another worker baked this chunk; result dropped (fenced)"
                );
            }
            Recorded::SceneGone => {
                tracing::info!("scene deleted or failed; chunk object removed");
                self.store.forget_chunk(&lease.scene_id, lease.idx, meta);
                lock(&self.bakers).retain(|(id, _)| id != &lease.scene_id);
            }
        }
        Ok(())
    }

    fn scene_live(&self, pg: &PgDb, id: &str) -> Result<bool> {
        Ok(pg.scene(id)?.is_some_and(|r| !r.state.is_terminal()))
    }

    /// A chunk that the object store or the database kept from being baked or stored (after
    /// their own retries) goes back without counting against it, not to be leased again for
    /// a while, and this worker waits as long before its next lease: exponential backoff
    /// (1 s, 2 s, … at most 32 s, while the failures last) with jitter (a random 50–100 % of
    /// it), so that workers neither spin on a store that is down nor come back in step. The
    /// scene waits rather than fails: its chunks are not at fault.
    fn retry_later(&self, pg: &PgDb, lease: &Lease, reason: &str) -> Result<()> {
        let n = self.setbacks.fetch_add(1, Ordering::Relaxed).min(5);
        let full = Duration::from_secs(1 << n);
        let jitter =
            0.5 + 0.5 * (getrandom::u32().unwrap_or(u32::MAX / 2) as f64 / u32::MAX as f64);
        let delay = full.mul_f64(jitter);
        tracing::warn!(%reason, retry_in_s = delay.as_secs_f64(), "chunk put back: the store failed; it is retried");
        pg.put_back(lease, reason, delay)?;
        lock(&self.bakers).retain(|(id, _)| id != &lease.scene_id);
        std::thread::sleep(delay);
        Ok(())
    }

    /// A failed chunk goes back with its reason (the scene fails after enough workers).
    fn failed(&self, pg: &PgDb, lease: &Lease, reason: &str) -> Result<()> {
        tracing::error!(%reason, "chunk failed on this worker");
        self.metrics.bake_errors.fetch_add(1, Ordering::Relaxed);
        if pg.fail_chunk(&self.id, lease, reason, self.max_failures)? {
            tracing::error!(scene = %lease.scene_id, "scene failed: its chunk failed on {} workers", self.max_failures);
            self.metrics.scenes_failed.fetch_add(1, Ordering::Relaxed);
        }
        lock(&self.bakers).retain(|(id, _)| id != &lease.scene_id);
        Ok(())
    }

    /// The baker of scene `id` (kept for the last few scenes). `Ok(None)`: the scene is gone.
    fn baker(&self, pg: &PgDb, id: &str) -> Result<Option<Arc<Baker>>, Failure> {
        let mut bakers = lock(&self.bakers);
        if let Some(i) = bakers.iter().position(|(s, _)| s == id) {
            let b = bakers.remove(i);
            let baker = b.1.clone();
            bakers.push(b);
            return Ok(Some(baker));
        }
        let row = match pg.scene(id) {
            Ok(Some(r)) => r,
            Ok(None) => return Ok(None),
            Err(e) => {
                return Err(Failure::Transient(format!(
                    "database error reading the scene: {e:#}"
                )));
            }
        };
        let bytes = self
            .store
            .read_scene_or_retry(id)
            .map_err(|(e, transient)| {
                if transient {
                    Failure::Transient(e)
                } else {
                    Failure::Chunk(e)
                }
            })?;
        let baker =
            Arc::new(super::chunk::baker_of(&bytes, &row, &self.pool).map_err(Failure::Chunk)?);
        if bakers.len() >= BAKERS_KEPT {
            bakers.remove(0);
        }
        bakers.push((id.to_string(), baker.clone()));
        Ok(Some(baker))
    }

    /// After the loops ended: the leases still held go back, the worker is marked stopped.
    pub(crate) fn finish(&self) {
        if let Ok(pg) = self.pg()
            && let Err(e) = pg.worker_stopped(&self.id)
        {
            tracing::warn!(error = %format!("{e:#}"), "cannot record the worker's stop");
        }
    }
}

/// A worker id unique across machines and restarts: host, process id, a random suffix.
pub(crate) fn new_worker_id() -> String {
    let host = std::env::var("HOSTNAME").unwrap_or_else(|_| "worker".into());
    let mut r = [0u8; 3];
    let _ = getrandom::fill(&mut r);
    format!(
        "{host}-{}-{:02x}{:02x}{:02x}",
        std::process::id(),
        r[0],
        r[1],
        r[2]
    )
}

/// `bspvt-server worker` flags.
#[derive(clap::Args, Debug, Clone)]
pub struct WorkerArgs {
    /// The PostgreSQL database the API instances use (`postgres://USER@HOST/DB`).
    #[arg(long, env = "BSPVT_DATABASE", hide_env_values = true)]
    pub database: String,
    /// The store the API instances use: `s3://BUCKET/PREFIX` or a shared folder.
    #[arg(long, env = "BSPVT_STORE")]
    pub store: String,
    /// Threads of the bake pool (0 = one per core).
    #[arg(long, env = "BSPVT_THREADS", default_value_t = 0)]
    pub threads: usize,
    /// Added to the bake threads' nice value (Linux; 0 = the process's priority): other work
    /// on the machine goes first.
    #[arg(long, env = "BSPVT_BAKE_NICE", default_value_t = super::pool::DEFAULT_NICE)]
    pub bake_nice: i32,
    /// Chunks baked at the same time (each on the whole pool).
    #[arg(long, env = "BSPVT_WORKER_CHUNKS", default_value_t = 2)]
    pub chunks: usize,
    /// Seconds a lease lasts without a heartbeat (the same for every process).
    #[arg(long, env = "BSPVT_LEASE_S", default_value_t = 30)]
    pub lease_s: u64,
    /// Different workers a chunk may fail on before its scene fails.
    #[arg(long, env = "BSPVT_MAX_CHUNK_FAILURES", default_value_t = 3)]
    pub max_chunk_failures: u32,
    /// This worker's name in the database (default: host, process id and a random suffix).
    #[arg(long, env = "BSPVT_WORKER_ID")]
    pub id: Option<String>,
    /// `text` or `json` log lines on stderr.
    #[arg(long, env = "BSPVT_LOG_FORMAT", default_value = "text")]
    pub log_format: String,
}
