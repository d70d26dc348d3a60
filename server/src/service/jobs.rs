//! The bake scheduler: scenes split into chunks of vertices, baked by N worker threads on one
//! shared rayon pool, each chunk made durable before anyone hears of it.
//!
//! Guarantees:
//! - **durable before reported**: a chunk is written and synced (`store`), then recorded in
//!   the database (`db`), and only then marked done in memory and announced to streams, event
//!   subscribers and the status document;
//! - **resume without recomputation**: at start, every scene still `queued` or `baking` is
//!   re-queued with exactly the chunks the database does not record (a recorded chunk whose
//!   file is missing or has the wrong size is dropped and baked again); recorded chunks are
//!   never baked again, which `chunks_baked_this_process` makes visible;
//! - **fairness**: workers take one chunk at a time, round-robin over the scenes being baked
//!   (at most `max_active_scenes`, the others wait in submission order), so a big scene does
//!   not starve a small one;
//! - **no blocking of the async runtime**: baking and its file and database writes run on the
//!   worker threads and the rayon pool, never on tokio's executor;
//! - **determinism**: each chunk is [`Baker::bake_chunk`], so the stored frames are exactly the
//!   offline bake's, whatever the worker count, order or restarts;
//! - a corrupt stored chunk ([`Jobs::rebake`]) is forgotten and baked again, never served; a
//!   failing scene (unreadable stored scene, storage error, panic) becomes `failed` with a
//!   reason and does not stop the workers.
//!
//! In the distributed shape (a PostgreSQL database, [`Jobs::start_cluster`]) this process
//! schedules nothing: `cluster` workers (here with `--workers N`, or other processes) lease
//! the chunks from the database, and a mirror thread polls the database's changes into the
//! same [`Live`] scenes, so that status, events and tree streams work unchanged on any API
//! instance. The mirror also says why a scene stalls (no live worker; its chunks leased by
//! silent workers).

use std::collections::{BTreeSet, HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use tokio::sync::watch;

use super::cluster::Workers;
use super::config::Config;
use super::db::{ChunkMeta, Db, JobState, SceneRow, now_ms};
use super::memory::{MemoryBudget, Refusal, Reservation};
use super::metrics::{Gauges, Metrics};
use super::pg::{ClusterGauges, PgDb};
use super::pool::PoolSettings;
use super::rays::Rays;
use super::store::Store;
use bspvt_bake::Baker;

/// Locks a mutex, ignoring poisoning: every critical section here leaves its data consistent
/// at each step, and a panic is caught around the bake, not inside these sections.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// The scheduler and its workers.
pub(crate) struct Jobs {
    db: Arc<Db>,
    store: Arc<Store>,
    metrics: Arc<Metrics>,
    pool: rayon::ThreadPool,
    /// Where rays are cast (`--bake-backend`).
    rays: Rays,
    sched: Mutex<Sched>,
    work: Condvar,
    workers: usize,
    max_active: usize,
    max_queued: usize,
    handles: Mutex<Vec<JoinHandle<()>>>,
    /// Chunks baked by this process, per scene (the proof that a restart recomputes nothing
    /// that was durable; kept for the process's lifetime, a few bytes per scene).
    baked_here: Mutex<HashMap<String, u32>>,
    /// Set while the data disk is full: how long a worker waits before it tries again.
    space_wait: Mutex<Option<Duration>>,
    /// A scene starts baking only once its estimated peak memory is reserved here.
    memory: Arc<MemoryBudget>,
    /// Threads of the bake pool.
    threads: usize,
    /// The distributed shape: what the mirror last read, and this process's own workers.
    cluster: Option<Cluster>,
}

struct Cluster {
    gauges: Mutex<ClusterGauges>,
    workers: Option<Arc<Workers>>,
}

/// How often the mirror polls the database for changes (status, events and streams of an
/// API instance lag the workers by about this much).
const MIRROR_POLL: Duration = Duration::from_millis(100);
/// How often it reads the queue gauges and the workers, and checks for stalls.
const MIRROR_GAUGES: Duration = Duration::from_secs(1);

/// Reasons the mirror shows, and clears when they no longer hold.
const STALLED: &str = "stalled: ";
const WAITING: &str = "waiting: ";

/// The first wait after the disk filled up; it doubles up to [`SPACE_WAIT_MAX`].
const SPACE_WAIT_MIN: Duration = Duration::from_millis(500);
const SPACE_WAIT_MAX: Duration = Duration::from_secs(15);

/// The reason a scene shows while its bake waits for disk space.
const PAUSED_FOR_SPACE: &str = "paused: the data disk is full; the bake resumes by itself when \
                                space is freed (free space or delete scenes)";

#[derive(Default)]
struct Sched {
    /// Every scene queued or baking.
    live: HashMap<String, Arc<Live>>,
    /// Scenes waiting for a bake slot, in submission order.
    queue: VecDeque<Arc<Live>>,
    /// Scenes being baked, in round-robin order.
    active: VecDeque<Arc<Live>>,
    stop: bool,
}

/// A scene as the scheduler and the streams see it.
pub(crate) struct Live {
    /// Metadata (its `state` field is the state when loaded; see [`Live::snapshot`]).
    pub row: SceneRow,
    progress: Mutex<Progress>,
    /// Bumped on every change of `progress`.
    tx: watch::Sender<u64>,
    cancel: AtomicBool,
    baker: Mutex<Option<Arc<Baker>>>,
    /// The bake's memory, held from activation until the scene ends.
    memory: Mutex<Option<Reservation>>,
}

struct Progress {
    state: JobState,
    reason: Option<String>,
    chunks: Vec<Option<ChunkMeta>>,
    pending: BTreeSet<u32>,
    in_flight: BTreeSet<u32>,
    chunks_done: u32,
    vertices_done: u64,
    stored_bytes: u64,
    started_ms: Option<i64>,
    finished_ms: Option<i64>,
    chunks_baked_total: u64,
    chunks_corrupt: u64,
    vertices_this_process: u64,
    first_start: Option<Instant>,
}

/// A consistent copy of a scene's progress.
#[derive(Clone, Debug)]
pub(crate) struct Snapshot {
    pub state: JobState,
    pub reason: Option<String>,
    pub chunks_done: u32,
    pub vertices_done: u64,
    pub stored_bytes: u64,
    pub started_ms: Option<i64>,
    pub finished_ms: Option<i64>,
    pub chunks_baked_total: u64,
    pub chunks_corrupt: u64,
    /// Vertices per second baked by this process (while baking).
    pub rate: Option<f64>,
    pub eta_s: Option<f64>,
}

/// What a stream sees of one chunk.
pub(crate) enum ChunkState {
    Durable(ChunkMeta),
    /// Not baked yet; the scene is queued or baking.
    Waiting,
    /// It will never come: the scene failed or was deleted.
    Never(JobState, Option<String>),
}

/// Why a submission was not queued.
pub(crate) enum SubmitError {
    QueueFull(usize),
    Db(anyhow::Error),
}

/// Vertices of chunk `c`.
pub(crate) fn chunk_len(row: &SceneRow, c: u32) -> u64 {
    let start = c as u64 * row.chunk_vertices as u64;
    (row.vertex_count as u64)
        .saturating_sub(start)
        .min(row.chunk_vertices as u64)
}

impl Live {
    fn new(row: SceneRow, durable: Vec<(u32, ChunkMeta)>) -> Live {
        let n = row.chunk_count;
        let mut chunks = vec![None; n as usize];
        let (mut done, mut verts, mut bytes) = (0, 0, row.header.len() as u64);
        for (i, m) in durable {
            if let Some(slot) = chunks.get_mut(i as usize)
                && slot.is_none()
            {
                *slot = Some(m);
                done += 1;
                verts += chunk_len(&row, i);
                bytes += m.bytes as u64;
            }
        }
        let pending = if row.state.is_terminal() {
            BTreeSet::new()
        } else {
            (0..n).filter(|&i| chunks[i as usize].is_none()).collect()
        };
        let progress = Progress {
            state: row.state,
            reason: row.reason.clone(),
            chunks,
            pending,
            in_flight: BTreeSet::new(),
            chunks_done: done,
            vertices_done: verts,
            stored_bytes: bytes,
            started_ms: row.started_ms,
            finished_ms: row.finished_ms,
            chunks_baked_total: row.chunks_baked,
            chunks_corrupt: row.chunks_corrupt,
            vertices_this_process: 0,
            first_start: None,
        };
        Live {
            row,
            progress: Mutex::new(progress),
            tx: watch::channel(0).0,
            cancel: AtomicBool::new(false),
            baker: Mutex::new(None),
            memory: Mutex::new(None),
        }
    }

    pub(crate) fn id(&self) -> &str {
        &self.row.id
    }

    /// A chunk the database recorded (distributed shape: seen by the mirror).
    fn apply_chunk(&self, c: u32, m: ChunkMeta) {
        let len = chunk_len(&self.row, c);
        {
            let mut p = lock(&self.progress);
            let Some(slot) = p.chunks.get(c as usize).copied() else {
                return;
            };
            match slot {
                Some(old) if old == m => return,
                Some(old) => p.stored_bytes = p.stored_bytes - old.bytes as u64 + m.bytes as u64,
                None => {
                    p.chunks_done += 1;
                    p.vertices_done += len;
                    p.stored_bytes += m.bytes as u64;
                    p.vertices_this_process += len;
                    p.chunks_baked_total += 1;
                    if p.first_start.is_none() {
                        p.first_start = Some(Instant::now());
                    }
                }
            }
            p.chunks[c as usize] = Some(m);
            p.pending.remove(&c);
        }
        self.bump();
    }

    /// A scene row the database changed (distributed shape).
    fn apply_row(&self, r: &SceneRow) {
        {
            let mut p = lock(&self.progress);
            p.state = r.state;
            p.reason = r.reason.clone();
            p.started_ms = r.started_ms;
            p.finished_ms = r.finished_ms;
            p.chunks_baked_total = r.chunks_baked;
            p.chunks_corrupt = r.chunks_corrupt;
            if r.state.is_terminal() {
                p.pending.clear();
            }
        }
        if r.state == JobState::Cancelled {
            self.cancel.store(true, Ordering::Release);
        }
        self.bump();
    }

    /// Shows (or clears) why a scene of the distributed shape does not advance; a reason the
    /// database recorded wins.
    fn set_stall(&self, why: Option<String>) {
        let mut p = lock(&self.progress);
        if p.state.is_terminal() {
            return;
        }
        let ours = p
            .reason
            .as_deref()
            .is_none_or(|r| r.starts_with(STALLED) || r.starts_with(WAITING));
        if ours && p.reason != why {
            p.reason = why;
            drop(p);
            self.bump();
        }
    }

    /// A receiver that wakes on every change (subscribe before reading, to miss nothing).
    pub(crate) fn subscribe(&self) -> watch::Receiver<u64> {
        self.tx.subscribe()
    }

    fn bump(&self) {
        self.tx.send_modify(|v| *v = v.wrapping_add(1));
    }

    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Acquire)
    }

    /// Where chunk `c` stands.
    pub(crate) fn chunk(&self, c: u32) -> ChunkState {
        let p = lock(&self.progress);
        match p.chunks.get(c as usize).copied().flatten() {
            Some(m) => ChunkState::Durable(m),
            None if matches!(p.state, JobState::Failed | JobState::Cancelled) => {
                ChunkState::Never(p.state, p.reason.clone())
            }
            None => ChunkState::Waiting,
        }
    }

    /// The metadata of chunks `range` if every one of them is durable.
    pub(crate) fn durable(&self, range: std::ops::Range<u32>) -> Option<Vec<ChunkMeta>> {
        let p = lock(&self.progress);
        range
            .map(|c| p.chunks.get(c as usize).copied().flatten())
            .collect()
    }

    pub(crate) fn state(&self) -> JobState {
        lock(&self.progress).state
    }

    pub(crate) fn snapshot(&self) -> Snapshot {
        let p = lock(&self.progress);
        let rate = match (p.state, p.first_start) {
            (JobState::Baking, Some(t)) if p.vertices_this_process > 0 => {
                Some(p.vertices_this_process as f64 / t.elapsed().as_secs_f64().max(1e-3))
            }
            _ => None,
        };
        let remaining = (self.row.vertex_count as u64).saturating_sub(p.vertices_done);
        Snapshot {
            state: p.state,
            reason: p.reason.clone(),
            chunks_done: p.chunks_done,
            vertices_done: p.vertices_done,
            stored_bytes: p.stored_bytes,
            started_ms: p.started_ms,
            finished_ms: p.finished_ms,
            chunks_baked_total: p.chunks_baked_total,
            chunks_corrupt: p.chunks_corrupt,
            rate,
            eta_s: rate.map(|r| remaining as f64 / r.max(1e-9)),
        }
    }
}

impl Jobs {
    /// Resumes unfinished scenes from the database, cleans the store and starts the workers.
    pub(crate) fn start(
        db: Arc<Db>,
        store: Arc<Store>,
        metrics: Arc<Metrics>,
        memory: Arc<MemoryBudget>,
        rays: Rays,
        cfg: &Config,
    ) -> Result<Arc<Jobs>> {
        let (workers, threads) = (cfg.workers, cfg.threads);
        let (max_active, max_queued) = (cfg.max_active_scenes, cfg.max_queued_scenes);
        let pool = PoolSettings {
            threads,
            nice: cfg.bake_nice,
        }
        .build()?;
        let pool_threads = pool.current_num_threads();
        let jobs = Arc::new(Jobs {
            db,
            store,
            metrics,
            pool,
            rays,
            sched: Mutex::new(Sched::default()),
            work: Condvar::new(),
            workers,
            max_active,
            max_queued,
            handles: Mutex::new(Vec::new()),
            baked_here: Mutex::new(HashMap::new()),
            space_wait: Mutex::new(None),
            memory,
            threads: pool_threads,
            cluster: None,
        });
        // Memory given back may let a waiting scene start.
        let weak = Arc::downgrade(&jobs);
        jobs.memory.set_on_release(move || {
            if let Some(j) = weak.upgrade() {
                // Taking the lock orders the wake-up after a waiter's check.
                drop(lock(&j.sched));
                j.work.notify_all();
            }
        });
        jobs.collect_garbage()?;
        jobs.reopen_incomplete()?;
        jobs.resume()?;
        let mut handles = lock(&jobs.handles);
        for w in 0..workers {
            let j = jobs.clone();
            handles.push(
                std::thread::Builder::new()
                    .name(format!("bake-worker-{w}"))
                    .spawn(move || j.worker())
                    .context("cannot start a bake worker")?,
            );
        }
        drop(handles);
        Ok(jobs)
    }

    /// The distributed shape: loads the unfinished scenes (to answer for them), starts the
    /// mirror of the database's changes and, with `workers > 0`, this process's own bake
    /// workers (the same as `bspvt-server worker`'s).
    pub(crate) fn start_cluster(
        db: Arc<Db>,
        store: Arc<Store>,
        metrics: Arc<Metrics>,
        memory: Arc<MemoryBudget>,
        cfg: &Config,
    ) -> Result<Arc<Jobs>> {
        let (workers, threads) = (cfg.workers, cfg.threads);
        let (max_queued, max_failures) = (cfg.max_queued_scenes, cfg.max_chunk_failures);
        let pg = db.pg().context("the distributed shape needs PostgreSQL")?;
        // Read the position first: nothing committed after it is missed by the mirror.
        let since = pg.changes(i64::MAX)?.next;
        let local = if workers > 0 {
            let id = super::cluster::new_worker_id();
            let (w, handles) = Workers::start(
                db.clone(),
                store.clone(),
                metrics.clone(),
                id,
                workers,
                PoolSettings {
                    threads,
                    nice: cfg.bake_nice,
                },
                max_failures,
            )?;
            Some((w, handles))
        } else {
            None
        };
        let jobs = Arc::new(Jobs {
            db,
            store,
            metrics,
            pool: rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .thread_name(|i| format!("api-pool-{i}"))
                .build()
                .context("cannot start a thread pool")?,
            sched: Mutex::new(Sched::default()),
            work: Condvar::new(),
            workers,
            max_active: 0,
            max_queued,
            handles: Mutex::new(Vec::new()),
            baked_here: Mutex::new(HashMap::new()),
            space_wait: Mutex::new(None),
            memory,
            threads,
            // Its own workers (`cluster`) cast on the CPU.
            rays: Rays::open(bspvt_bake::Backend::Cpu)?,
            cluster: Some(Cluster {
                gauges: Mutex::new(ClusterGauges::default()),
                workers: local.as_ref().map(|(w, _)| w.clone()),
            }),
        });
        {
            let mut s = lock(&jobs.sched);
            let pg = jobs.pg()?;
            for row in pg.unfinished_scenes()? {
                let chunks = pg.chunks(&row.id)?;
                s.live
                    .insert(row.id.clone(), Arc::new(Live::new(row, chunks)));
            }
        }
        let mut handles = lock(&jobs.handles);
        if let Some((_, h)) = local {
            handles.extend(h);
        }
        let j = jobs.clone();
        handles.push(
            std::thread::Builder::new()
                .name("mirror".into())
                .spawn(move || j.mirror(since))
                .context("cannot start the database mirror")?,
        );
        drop(handles);
        Ok(jobs)
    }

    fn pg(&self) -> Result<&PgDb> {
        self.db.pg().context("not the distributed shape")
    }

    /// Polls the database's changes into the live scenes until shutdown (distributed shape).
    fn mirror(&self, mut since: i64) {
        let Ok(pg) = self.pg() else { return };
        let mut last_gauges: Option<Instant> = None;
        loop {
            if lock(&self.sched).stop {
                return;
            }
            match pg.changes(since) {
                Ok(ch) => {
                    since = ch.next;
                    self.apply_changes(pg, ch);
                }
                Err(e) => {
                    tracing::warn!(error = %format!("{e:#}"), "cannot read the database's changes");
                }
            }
            if last_gauges.is_none_or(|t| t.elapsed() >= MIRROR_GAUGES) {
                last_gauges = Some(Instant::now());
                if let Err(e) = pg.sweep_finished() {
                    tracing::warn!(error = %format!("{e:#}"), "cannot sweep finished scenes");
                }
                match pg.gauges() {
                    Ok(g) => {
                        self.check_stalls(pg, &g);
                        if let Some(c) = &self.cluster {
                            *lock(&c.gauges) = g;
                        }
                    }
                    Err(e) => {
                        tracing::warn!(error = %format!("{e:#}"), "cannot read the queue gauges");
                    }
                }
            }
            std::thread::sleep(MIRROR_POLL);
        }
    }

    fn apply_changes(&self, pg: &PgDb, ch: super::pg::Changes) {
        // Chunks first: a scene is `done` only once its chunks are visible.
        for (id, c, m) in ch.chunks {
            let live = lock(&self.sched).live.get(&id).cloned();
            if let Some(l) = live {
                l.apply_chunk(c, m);
            }
        }
        for row in ch.scenes {
            let live = lock(&self.sched).live.get(&row.id).cloned();
            match live {
                Some(l) => {
                    l.apply_row(&row);
                    if row.state.is_terminal() {
                        lock(&self.sched).live.remove(&row.id);
                        *lock(&l.baker) = None;
                    }
                }
                None if !row.state.is_terminal() => {
                    // Submitted through another API instance.
                    match pg.chunks(&row.id) {
                        Ok(chunks) => {
                            let id = row.id.clone();
                            lock(&self.sched)
                                .live
                                .insert(id, Arc::new(Live::new(row, chunks)));
                        }
                        Err(e) => {
                            tracing::warn!(scene = %row.id, error = %format!("{e:#}"), "cannot load a scene's chunks");
                        }
                    }
                }
                None => {}
            }
        }
    }

    /// Tells each unfinished scene why it does not advance, if it cannot.
    fn check_stalls(&self, pg: &PgDb, g: &ClusterGauges) {
        let live: Vec<Arc<Live>> = lock(&self.sched).live.values().cloned().collect();
        let workers = g.workers.iter().filter(|w| w.live).count();
        for l in live {
            if l.state().is_terminal() {
                continue;
            }
            let why = if workers == 0 {
                Some(format!(
                    "{STALLED}no live bake worker (none sent a heartbeat in the last {} s); \
                     start `bspvt-server worker` against this database and store",
                    pg.lease_ttl.as_secs()
                ))
            } else {
                match pg.held_by_silent(l.id()) {
                    Ok(Some(s)) => Some(format!(
                        "{WAITING}its remaining chunks are leased by workers that stopped \
                         answering; the first lease expires in {s:.0} s"
                    )),
                    Ok(None) => None,
                    Err(_) => continue,
                }
            };
            l.set_stall(why);
        }
    }

    /// Removes scene directories the database does not know (a crash between writing a new
    /// scene's files and recording it) or no longer owns (a crash while deleting).
    fn collect_garbage(&self) -> Result<()> {
        let keep = self.db.scene_ids_with_data()?;
        for id in self.store.scene_ids()? {
            if !keep.contains(&id) {
                tracing::info!(scene = %id, "removing files of an unrecorded or deleted scene");
                if let Err(e) = self.store.remove_scene(&id) {
                    tracing::warn!(scene = %id, error = %e, "cannot remove scene files");
                }
            }
        }
        Ok(())
    }

    /// A scene recorded `done` whose chunk rows are not all there (a damaged chunk table) is
    /// queued again: [`Jobs::resume`] keeps the chunks its files and rows prove and bakes the
    /// rest, so it is never served as `done` with chunks missing.
    fn reopen_incomplete(&self) -> Result<()> {
        for (id, recorded, total) in self.db.done_scenes_missing_chunks()? {
            tracing::warn!(
                scene = %id,
                recorded,
                total,
                "scene recorded done with chunks missing; baking the missing ones again"
            );
            self.db.set_state(&id, JobState::Queued, None)?;
        }
        Ok(())
    }

    /// Re-queues the scenes a previous run left queued or baking: baking ones first, the least
    /// recently advanced of them first (so that repeated restarts rotate, not starve).
    fn resume(&self) -> Result<()> {
        let rows = self.db.unfinished_scenes()?;
        let mut s = lock(&self.sched);
        for row in rows {
            let id = row.id.clone();
            let recorded = self.db.chunks(&id)?;
            let on_disk = match self.store.list_chunks(&id) {
                Ok(files) => {
                    for p in files.stray {
                        let _ = std::fs::remove_file(p);
                    }
                    files.chunks.into_iter().collect::<HashMap<u32, u64>>()
                }
                Err(e) => {
                    let reason = format!("the scene's files are missing: {e}");
                    tracing::error!(scene = %id, %reason, "cannot resume");
                    self.db.set_state(&id, JobState::Failed, Some(&reason))?;
                    continue;
                }
            };
            let mut kept = Vec::new();
            for (c, m) in recorded {
                if on_disk.get(&c) == Some(&(m.bytes as u64)) {
                    kept.push((c, m));
                } else {
                    tracing::warn!(scene = %id, chunk = c, "recorded chunk missing or truncated on disk; baking it again");
                    self.metrics.chunks_corrupt.fetch_add(1, Ordering::Relaxed);
                    self.db.drop_chunk(&id, c, m, true)?;
                    self.store.remove_chunk(&id, c);
                }
            }
            // Files without a record were never reported: bake them again.
            let recorded: std::collections::HashSet<u32> = kept.iter().map(|(c, _)| *c).collect();
            for &c in on_disk.keys() {
                if !recorded.contains(&c) {
                    self.store.remove_chunk(&id, c);
                }
            }
            // Re-read: dropping chunks above changed its counters.
            let row = self.db.scene(&id)?.unwrap_or(row);
            let live = Arc::new(Live::new(row, kept));
            let missing = lock(&live.progress).pending.len();
            tracing::info!(
                scene = %id,
                chunks_missing = missing,
                chunks_total = live.row.chunk_count,
                "resuming scene"
            );
            s.live.insert(id, live.clone());
            s.queue.push_back(live);
        }
        // Scenes with nothing left to bake are finished by the first worker that looks.
        drop(s);
        self.work.notify_all();
        Ok(())
    }

    /// Records and queues a new scene (its files are already durable), with the
    /// `Idempotency-Key` and request fingerprint that created it, if any.
    pub(crate) fn submit(
        &self,
        row: SceneRow,
        idempotency: Option<(&str, &str)>,
    ) -> Result<Arc<Live>, SubmitError> {
        let mut s = lock(&self.sched);
        if s.live.len() >= self.max_queued {
            return Err(SubmitError::QueueFull(self.max_queued));
        }
        let mut row = row;
        row.seq = self
            .db
            .insert_scene_with_key(&row, idempotency)
            .map_err(SubmitError::Db)?;
        let live = Arc::new(Live::new(row, Vec::new()));
        s.live.insert(live.row.id.clone(), live.clone());
        if self.cluster.is_none() {
            s.queue.push_back(live.clone());
        }
        drop(s);
        self.metrics
            .scenes_submitted
            .fetch_add(1, Ordering::Relaxed);
        self.work.notify_one();
        Ok(live)
    }

    /// The budget uploads and bakes reserve from.
    pub(crate) fn memory(&self) -> &Arc<MemoryBudget> {
        &self.memory
    }

    /// The estimated peak memory of baking a scene of these counts on this server's pool.
    pub(crate) fn bake_estimate(&self, vertices: u64, triangles: u64, face_res: u32) -> u64 {
        super::memory::bake_bytes(vertices, triangles, face_res, self.threads)
    }

    fn estimate(&self, row: &SceneRow) -> u64 {
        let face_res = serde_json::from_str::<bspvt_proto::BakeSettings>(&row.settings_json)
            .map_or(bspvt_proto::BakeSettings::MAX_FACE_RES, |b| b.face_res);
        self.bake_estimate(u64::from(row.vertex_count), row.triangle_count, face_res)
    }

    /// Whether a submission would be queued now.
    pub(crate) fn has_room(&self) -> bool {
        lock(&self.sched).live.len() < self.max_queued
    }

    /// The scene `id`: the live one if queued or baking, else loaded from the database.
    pub(crate) fn lookup(&self, id: &str) -> Result<Option<Arc<Live>>> {
        if let Some(l) = lock(&self.sched).live.get(id) {
            return Ok(Some(l.clone()));
        }
        let Some(row) = self.db.scene(id)? else {
            return Ok(None);
        };
        if !row.state.is_terminal() {
            // It became live (a re-bake) between the two looks.
            if let Some(l) = lock(&self.sched).live.get(id) {
                return Ok(Some(l.clone()));
            }
        }
        let chunks = match row.state {
            JobState::Cancelled => Vec::new(),
            _ => self.db.chunks(id)?,
        };
        let live = Arc::new(Live::new(row, chunks));
        if self.cluster.is_some() && !live.row.state.is_terminal() {
            return self.adopt(live).map(Some);
        }
        Ok(Some(live))
    }

    /// A scene still baking that another API instance accepted (distributed shape): it joins
    /// the live scenes, then its row and chunks are read again, so that nothing the mirror
    /// applied before it joined is missed.
    fn adopt(&self, live: Arc<Live>) -> Result<Arc<Live>> {
        let id = live.id().to_string();
        let live = lock(&self.sched)
            .live
            .entry(id.clone())
            .or_insert(live)
            .clone();
        if let Some(row) = self.db.scene(&id)? {
            for (c, m) in self.db.chunks(&id)? {
                live.apply_chunk(c, m);
            }
            live.apply_row(&row);
            if row.state.is_terminal() {
                lock(&self.sched).live.remove(&id);
            }
        }
        Ok(live)
    }

    /// Chunks of scene `id` baked by this process.
    pub(crate) fn baked_this_process(&self, id: &str) -> u32 {
        lock(&self.baked_here).get(id).copied().unwrap_or(0)
    }

    /// Position in the waiting queue (0 = next), if queued.
    pub(crate) fn queue_position(&self, id: &str) -> Option<usize> {
        lock(&self.sched).queue.iter().position(|l| l.id() == id)
    }

    /// Cancels a scene and deletes its data. Returns its previous state, `None` if unknown.
    pub(crate) fn delete(&self, id: &str) -> Result<Option<JobState>> {
        let mut s = lock(&self.sched);
        let live = s.live.remove(id);
        s.queue.retain(|l| l.id() != id);
        s.active.retain(|l| l.id() != id);
        let before = match self.db.cancel(id) {
            Ok(b) => b,
            Err(e) if super::error::is_disk_full(&e) => {
                // The disk is full to the last byte: free the scene's own space, then record
                // the deletion. (A crash in between leaves its row without files: it fails
                // with "files are missing" at the next start instead of reading "cancelled".)
                tracing::warn!(scene = %id, "the data disk is full: removing the scene's files before recording its deletion");
                if let Err(e) = self.store.remove_scene(id) {
                    tracing::warn!(scene = %id, error = %e, "cannot remove the files of a deleted scene");
                }
                self.db.cancel(id)?
            }
            Err(e) => return Err(e),
        };
        drop(s);
        if let Some(l) = &live {
            l.cancel.store(true, Ordering::Release);
            {
                let mut p = lock(&l.progress);
                p.state = JobState::Cancelled;
                p.reason = Some("deleted by a client".into());
                p.pending.clear();
                p.finished_ms = Some(now_ms());
            }
            // A worker building the scene's BVH holds this lock: never wait for it (the
            // worker sees the cancellation and the baker goes with the scene).
            if let Ok(mut b) = l.baker.try_lock() {
                *b = None;
                *lock(&l.memory) = None;
            }
            l.bump();
        }
        if matches!(before, Some(b) if b != JobState::Cancelled) {
            self.metrics
                .scenes_cancelled
                .fetch_add(1, Ordering::Relaxed);
            // Leftovers are removed at the next start (a cancelled scene owns no files).
            if let Err(e) = self.store.remove_scene(id) {
                tracing::warn!(scene = %id, error = %e, "cannot remove the files of a deleted scene");
            }
            tracing::info!(scene = %id, "scene cancelled and deleted");
        }
        Ok(before)
    }

    /// Chunk `c` of scene `id`, recorded as `seen`, failed verification on read: forget it,
    /// bake it again, and return the live scene to wait on (`None` if the scene is gone).
    pub(crate) fn rebake(
        &self,
        id: &str,
        c: u32,
        seen: ChunkMeta,
        why: &str,
    ) -> Result<Option<Arc<Live>>> {
        let mut s = lock(&self.sched);
        if let Some(live) = s.live.get(id).cloned() {
            let mut p = lock(&live.progress);
            if p.chunks.get(c as usize).copied().flatten() == Some(seen) {
                tracing::error!(scene = %id, chunk = c, %why, "stored chunk is corrupt; baking it again");
                self.metrics.chunks_corrupt.fetch_add(1, Ordering::Relaxed);
                self.db.drop_chunk(id, c, seen, true)?;
                self.store.forget_chunk(id, c, seen);
                p.chunks[c as usize] = None;
                p.chunks_done -= 1;
                p.vertices_done -= chunk_len(&live.row, c);
                p.stored_bytes -= seen.bytes as u64;
                p.chunks_corrupt += 1;
                p.pending.insert(c);
            }
            drop(p);
            drop(s);
            live.bump();
            self.work.notify_one();
            return Ok(Some(live));
        }
        // A finished scene: back to baking with this one chunk missing.
        let Some(row) = self.db.scene(id)? else {
            return Ok(None);
        };
        if row.state != JobState::Done {
            return Ok(None);
        }
        tracing::error!(scene = %id, chunk = c, %why, "stored chunk is corrupt; baking it again");
        self.metrics.chunks_corrupt.fetch_add(1, Ordering::Relaxed);
        self.db.drop_chunk(id, c, seen, true)?;
        self.store.forget_chunk(id, c, seen);
        let Some(row) = self.db.scene(id)? else {
            return Ok(None);
        };
        let live = Arc::new(Live::new(row, self.db.chunks(id)?));
        s.live.insert(id.to_string(), live.clone());
        if self.cluster.is_none() {
            s.queue.push_front(live.clone());
        }
        drop(s);
        self.work.notify_one();
        Ok(Some(live))
    }

    /// Queue and bake gauges.
    pub(crate) fn gauges(&self) -> Gauges {
        if let Some(c) = &self.cluster {
            let g = lock(&c.gauges);
            return Gauges {
                scenes_queued: g.scenes_queued,
                scenes_baking: g.scenes_baking,
                chunks_pending: g.chunks_pending,
                chunks_in_flight: g.chunks_leased,
                workers: self.workers as u64,
                generation: self.db.generation(),
                cluster: Some(g.clone()),
                gpu_busy_seconds: self.rays.gpu_busy_seconds(),
                ..Gauges::default()
            };
        }
        let s = lock(&self.sched);
        let mut g = Gauges {
            scenes_queued: s.queue.len() as u64,
            scenes_baking: s.active.len() as u64,
            workers: self.workers as u64,
            generation: self.db.generation(),
            gpu_busy_seconds: self.rays.gpu_busy_seconds(),
            ..Gauges::default()
        };
        for l in s.live.values() {
            let p = lock(&l.progress);
            g.chunks_pending += p.pending.len() as u64;
            g.chunks_in_flight += p.in_flight.len() as u64;
        }
        g
    }

    /// Stops handing out work and waits (up to `wait`) for chunks being baked to be stored.
    pub(crate) fn shutdown(&self, wait: Duration) {
        lock(&self.sched).stop = true;
        let local = self.cluster.as_ref().and_then(|c| c.workers.clone());
        if let Some(w) = &local {
            w.stop();
        }
        self.work.notify_all();
        let deadline = Instant::now() + wait;
        let handles = std::mem::take(&mut *lock(&self.handles));
        for h in handles {
            while !h.is_finished() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            if h.is_finished() {
                let _ = h.join();
            }
        }
        if let Some(w) = local {
            w.finish();
        }
    }

    // -----------------------------------------------------------------------------------------
    // Workers.

    fn worker(self: Arc<Self>) {
        while let Some((live, c)) = self.next_work() {
            {
                let span = tracing::info_span!("chunk", scene = %live.row.id, chunk = c);
                let _enter = span.enter();
                self.bake_one(&live, c);
            }
            self.wait_for_space();
        }
    }

    /// While the disk is full, waits (backing off) before the next chunk; returns at once
    /// when stopping.
    fn wait_for_space(&self) {
        let Some(delay) = *lock(&self.space_wait) else {
            return;
        };
        let s = lock(&self.sched);
        if !s.stop {
            drop(self.work.wait_timeout(s, delay));
        }
    }

    /// Chunk `c` could not be stored because the disk is full: it goes back to the scene's
    /// pending chunks, the scene shows why, the ballast is released (so that states and
    /// deletions can still be recorded), and workers back off.
    fn pause_for_space(&self, live: &Arc<Live>, c: u32, what: &str) {
        let delay = {
            let mut w = lock(&self.space_wait);
            let d = w.map_or(SPACE_WAIT_MIN, |d| (d * 2).min(SPACE_WAIT_MAX));
            *w = Some(d);
            d
        };
        {
            let mut p = lock(&live.progress);
            p.in_flight.remove(&c);
            if !p.state.is_terminal() {
                p.pending.insert(c);
                p.reason = Some(PAUSED_FOR_SPACE.to_string());
            }
        }
        let released = self.store.release_ballast();
        if released {
            self.metrics.bake_errors.fetch_add(1, Ordering::Relaxed);
        }
        tracing::warn!(
            scene = %live.id(),
            chunk = c,
            retry_ms = delay.as_millis() as u64,
            ballast_released = released,
            "{what}: the data disk is full, waiting for space"
        );
        live.bump();
    }

    /// While paused for space: true once the ballast could be written back (the disk has
    /// room for it and more), which ends the pause.
    fn room_again(&self) -> bool {
        let mut w = lock(&self.space_wait);
        if w.is_none() {
            return true;
        }
        if self.store.room_again() {
            *w = None;
            tracing::info!("the data disk has room again; baking resumes");
            return true;
        }
        false
    }

    /// A chunk was stored: the scene no longer shows the pause.
    fn space_is_back(&self, live: &Live) {
        let mut p = lock(&live.progress);
        if p.reason.as_deref() == Some(PAUSED_FOR_SPACE) {
            p.reason = None;
        }
    }

    /// The next (scene, chunk), round-robin over active scenes; blocks until there is one.
    fn next_work(&self) -> Option<(Arc<Live>, u32)> {
        let mut s = lock(&self.sched);
        loop {
            if s.stop {
                return None;
            }
            let mut refused = Vec::new();
            while s.active.len() < self.max_active {
                let Some(l) = s.queue.front().cloned() else {
                    break;
                };
                // In submission order: the head waits for memory rather than be overtaken.
                match self.memory.try_reserve(self.estimate(&l.row)) {
                    Ok(r) => *lock(&l.memory) = Some(r),
                    Err(Refusal::Busy { .. }) => break,
                    Err(never @ Refusal::Never { .. }) => {
                        s.queue.pop_front();
                        refused.push((l, never));
                        continue;
                    }
                }
                s.queue.pop_front();
                self.activate(&l);
                s.active.push_back(l);
            }
            if !refused.is_empty() {
                drop(s);
                for (l, why) in refused {
                    self.fail(&l, format!("baking this scene {why}"));
                }
                s = lock(&self.sched);
                continue;
            }
            let mut finished = Vec::new();
            let mut found = None;
            for (i, l) in s.active.iter().enumerate() {
                let mut p = lock(&l.progress);
                if let Some(c) = p.pending.pop_first() {
                    p.in_flight.insert(c);
                    if p.first_start.is_none() {
                        p.first_start = Some(Instant::now());
                    }
                    found = Some((i, c));
                    break;
                }
                if p.in_flight.is_empty() {
                    finished.push(l.clone());
                }
            }
            if let Some((i, c)) = found {
                let l = s.active.remove(i)?;
                s.active.push_back(l.clone());
                drop(s);
                for f in finished {
                    self.finish(&f);
                }
                return Some((l, c));
            }
            if !finished.is_empty() {
                // Scenes resumed with every chunk already durable.
                drop(s);
                for f in finished {
                    self.finish(&f);
                }
                s = lock(&self.sched);
                continue;
            }
            s = self.work.wait(s).unwrap_or_else(|p| p.into_inner());
        }
    }

    fn activate(&self, l: &Live) {
        let mut p = lock(&l.progress);
        if p.state == JobState::Queued {
            p.state = JobState::Baking;
            p.started_ms.get_or_insert_with(now_ms);
            drop(p);
            if let Err(e) = self.db.set_state(l.id(), JobState::Baking, None) {
                tracing::error!(scene = %l.id(), error = %e, "cannot record the start of a bake");
            }
            tracing::info!(scene = %l.id(), "bake started");
            l.bump();
        }
    }

    fn bake_one(&self, live: &Arc<Live>, c: u32) {
        if live.cancelled() {
            return;
        }
        if !self.room_again() {
            return self.pause_for_space(live, c, "still no room for a chunk");
        }
        let baker = match self.baker(live) {
            Ok(b) => b,
            Err(reason) => return self.fail(live, reason),
        };
        if live.cancelled() {
            // Deleted while its BVH was built: the baker and its memory go now.
            *lock(&live.baker) = None;
            *lock(&live.memory) = None;
            return;
        }
        let t0 = Instant::now();
        let result = super::chunk::bake(c, || self.rays.bake_chunk(&self.pool, &baker, c));
        drop(baker);
        let (frame, meta, vertices) = match result {
            Ok(r) => r,
            Err(reason) => return self.fail(live, reason),
        };
        if live.cancelled() {
            return;
        }
        if let Err(e) = self.store.write_chunk(live.id(), c, &frame) {
            if live.cancelled() {
                return;
            }
            if super::error::is_storage_full(&e) {
                return self.pause_for_space(live, c, "cannot write a chunk");
            }
            // The scene's reason is public: the error's kind, not the server's paths.
            tracing::error!(scene = %live.id(), chunk = c, error = %e, "cannot write a chunk");
            return self.fail(
                live,
                format!(
                    "storage error writing chunk {c}: {} (see the server's log)",
                    e.kind()
                ),
            );
        }
        match self.db.insert_chunk(live.id(), c, meta) {
            Ok(true) => {}
            Ok(false) => return, // deleted meanwhile
            Err(e) if super::error::is_disk_full(&e) => {
                // Not recorded, so never reported: the file goes, the chunk is baked again.
                self.store.remove_chunk(live.id(), c);
                return self.pause_for_space(live, c, "cannot record a chunk");
            }
            Err(e) => {
                return self.fail(live, format!("database error recording chunk {c}: {e}"));
            }
        }
        self.space_is_back(live);
        let took = t0.elapsed();
        tracing::debug!(
            vertices,
            bytes = meta.bytes,
            ms = took.as_secs_f64() * 1e3,
            "chunk durable"
        );
        let len = chunk_len(&live.row, c);
        self.metrics.chunk_baked(len, took);
        *lock(&self.baked_here)
            .entry(live.id().to_string())
            .or_default() += 1;
        let finished = {
            let mut p = lock(&live.progress);
            p.in_flight.remove(&c);
            if p.chunks[c as usize].is_none() {
                p.chunks_done += 1;
                p.vertices_done += len;
                p.stored_bytes += meta.bytes as u64;
            }
            p.chunks[c as usize] = Some(meta);
            p.chunks_baked_total += 1;
            p.vertices_this_process += len;
            p.pending.is_empty() && p.in_flight.is_empty()
        };
        live.bump();
        if finished {
            self.finish(live);
        }
    }

    /// The scene's baker, built (BVH and all) on first use from the stored scene.
    fn baker(&self, live: &Live) -> Result<Arc<Baker>, String> {
        let mut slot = lock(&live.baker);
        if let Some(b) = slot.as_ref() {
            return Ok(b.clone());
        }
        let baker = Arc::new(super::chunk::baker(&self.store, &live.row, &self.pool)?);
        *slot = Some(baker.clone());
        Ok(baker)
    }

    /// Marks a scene done if every chunk is durable (a scene with nothing left to bake but
    /// chunks missing would be a bug: it fails instead of waiting forever).
    fn finish(&self, live: &Arc<Live>) {
        let mut s = lock(&self.sched);
        {
            let mut p = lock(&live.progress);
            if p.state.is_terminal() || !p.pending.is_empty() || !p.in_flight.is_empty() {
                return;
            }
            if p.chunks_done != live.row.chunk_count {
                let missing = live.row.chunk_count - p.chunks_done;
                drop(p);
                drop(s);
                return self.fail(
                    live,
                    format!("internal error: nothing left to bake but {missing} chunks missing"),
                );
            }
            if let Err(e) = self.db.set_state(live.id(), JobState::Done, None) {
                tracing::error!(scene = %live.id(), error = %e, "cannot record a finished bake");
                return;
            }
            p.state = JobState::Done;
            p.finished_ms = Some(now_ms());
        }
        s.live.remove(live.id());
        s.active.retain(|l| !Arc::ptr_eq(l, live));
        s.queue.retain(|l| !Arc::ptr_eq(l, live));
        drop(s);
        *lock(&live.baker) = None;
        *lock(&live.memory) = None;
        live.bump();
        self.metrics.scenes_done.fetch_add(1, Ordering::Relaxed);
        tracing::info!(scene = %live.id(), "bake done");
        self.work.notify_all();
    }

    fn fail(&self, live: &Arc<Live>, reason: String) {
        let mut s = lock(&self.sched);
        {
            let mut p = lock(&live.progress);
            if p.state.is_terminal() {
                return;
            }
            p.state = JobState::Failed;
            p.reason = Some(reason.clone());
            p.pending.clear();
            p.finished_ms = Some(now_ms());
        }
        if let Err(e) = self
            .db
            .set_state(live.id(), JobState::Failed, Some(&reason))
        {
            tracing::error!(scene = %live.id(), error = %e, "cannot record a failed bake");
        }
        s.live.remove(live.id());
        s.active.retain(|l| !Arc::ptr_eq(l, live));
        s.queue.retain(|l| !Arc::ptr_eq(l, live));
        drop(s);
        *lock(&live.baker) = None;
        *lock(&live.memory) = None;
        live.bump();
        self.metrics.scenes_failed.fetch_add(1, Ordering::Relaxed);
        self.metrics.bake_errors.fetch_add(1, Ordering::Relaxed);
        tracing::error!(scene = %live.id(), %reason, "bake failed");
        self.work.notify_all();
    }
}
