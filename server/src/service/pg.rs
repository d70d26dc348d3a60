//! The distributed database: PostgreSQL (tokio-postgres, pooled by deadpool) holds what the
//! embedded SQLite database holds — scenes, durable chunks, idempotency keys — and what only
//! several machines need: one `tasks` row per chunk still to bake (its lease), and the bake
//! workers with their heartbeats.
//!
//! Guarantees:
//! - **leases**: a worker takes one chunk at a time with `FOR UPDATE SKIP LOCKED` (no two
//!   workers wait on or take the same row), in order of chunk index across scenes (chunk 0 of
//!   every scene, then chunk 1, …: scenes advance side by side and a small one is not starved
//!   by a big one); a lease lasts `ttl` from the database's clock and is renewed by the
//!   worker's heartbeat; an expired lease is taken by the next worker that asks. Neither a
//!   lease nor a record writes the scene's row (it is not a point of contention), except
//!   the first lease (`queued` → `baking`) and the last record (`done`);
//! - **fencing**: every lease has a fresh token; a chunk is recorded only by the holder of the
//!   task's current token, in the same transaction that deletes the task, so a stale worker
//!   (its lease expired and taken over) can neither record nor count a chunk twice; its
//!   attempt is counted on its worker row (`chunks_fenced`);
//! - a scene becomes `done` right after its last chunk is recorded: each record checks, after
//!   its commit, whether tasks remain, so of two last chunks finishing together the later
//!   check sees both (and the API's mirror sweeps for a recorder that died in between);
//! - a chunk that fails on `max_failures` different workers fails its scene with the reason;
//! - every operation is retried while the database is unreachable or restarting (up to
//!   [`RETRY_FOR`]), so workers and API instances ride out a PostgreSQL restart; a retried
//!   completion whose first commit did succeed is recognised by its token;
//! - an attempt not answered within a lease (5 s at least) is abandoned with its connection
//!   and retried on a new one: across a network partition packets are dropped, not refused,
//!   and a query would otherwise wait for TCP's own retransmission timers (minutes) — while
//!   the process said nothing, and after the network came back;
//! - changes are read by transaction id (`xid` columns, `pg_current_snapshot()`), so an API
//!   instance polling them misses no commit, whatever order concurrent commits land in.

use std::future::Future;
use std::pin::Pin;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use deadpool_postgres::{Manager, ManagerConfig, Object, Pool, RecyclingMethod};
use tokio_postgres::NoTls;
use tokio_postgres::error::SqlState;

use super::io;
use super::rows::{ChunkMeta, IdempotentRecord, JobState, SceneRow, SceneSummary, now_ms};

/// How long an operation is retried while the database cannot be reached.
pub(crate) const RETRY_FOR: Duration = Duration::from_secs(90);

const SCHEMA: &str = "
CREATE SEQUENCE IF NOT EXISTS bspvt_lease_token;
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value BIGINT NOT NULL);
CREATE TABLE IF NOT EXISTS scenes (
    seq BIGSERIAL UNIQUE,
    id TEXT PRIMARY KEY,
    state TEXT NOT NULL,
    reason TEXT,
    created_ms BIGINT NOT NULL,
    started_ms BIGINT,
    finished_ms BIGINT,
    vertex_count BIGINT NOT NULL,
    triangle_count BIGINT NOT NULL,
    chunk_count BIGINT NOT NULL,
    chunk_vertices BIGINT NOT NULL,
    settings TEXT NOT NULL,
    mesh_hash BIGINT NOT NULL,
    header BYTEA NOT NULL,
    upload_bytes BIGINT NOT NULL,
    source TEXT NOT NULL,
    chunks_baked BIGINT NOT NULL DEFAULT 0,
    chunks_corrupt BIGINT NOT NULL DEFAULT 0,
    warnings TEXT NOT NULL DEFAULT '[]',
    xid BIGINT NOT NULL DEFAULT (pg_current_xact_id()::text::bigint)
);
CREATE INDEX IF NOT EXISTS scenes_state ON scenes(state);
CREATE INDEX IF NOT EXISTS scenes_xid ON scenes(xid);
CREATE TABLE IF NOT EXISTS chunks (
    scene_id TEXT NOT NULL REFERENCES scenes(id) ON DELETE CASCADE,
    idx INTEGER NOT NULL,
    bytes BIGINT NOT NULL,
    crc32 BIGINT NOT NULL,
    worker TEXT NOT NULL,
    token BIGINT NOT NULL,
    leases INTEGER NOT NULL,
    baked_ms BIGINT NOT NULL,
    xid BIGINT NOT NULL DEFAULT (pg_current_xact_id()::text::bigint),
    PRIMARY KEY (scene_id, idx)
);
CREATE INDEX IF NOT EXISTS chunks_xid ON chunks(xid);
CREATE TABLE IF NOT EXISTS tasks (
    scene_id TEXT NOT NULL REFERENCES scenes(id) ON DELETE CASCADE,
    idx INTEGER NOT NULL,
    worker TEXT,
    token BIGINT,
    lease_until TIMESTAMPTZ,
    failed_on TEXT[] NOT NULL DEFAULT '{}',
    last_error TEXT,
    leases INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (scene_id, idx)
);
CREATE INDEX IF NOT EXISTS tasks_worker ON tasks(worker);
CREATE INDEX IF NOT EXISTS tasks_order ON tasks(idx, scene_id);
CREATE TABLE IF NOT EXISTS workers (
    id TEXT PRIMARY KEY,
    host TEXT NOT NULL,
    threads INTEGER NOT NULL,
    started_ms BIGINT NOT NULL,
    last_seen TIMESTAMPTZ NOT NULL,
    chunks_done BIGINT NOT NULL DEFAULT 0,
    chunks_fenced BIGINT NOT NULL DEFAULT 0,
    chunks_failed BIGINT NOT NULL DEFAULT 0,
    stopped BOOLEAN NOT NULL DEFAULT false
);
CREATE TABLE IF NOT EXISTS idempotency_keys (
    key TEXT PRIMARY KEY,
    fingerprint TEXT NOT NULL,
    scene_id TEXT NOT NULL REFERENCES scenes(id) ON DELETE CASCADE,
    created_ms BIGINT NOT NULL
);
";

/// `chunks_baked` is counted, not stored: recording a chunk writes no scene row.
const SCENE_COLUMNS: &str = "id, seq, state, reason, created_ms, started_ms, finished_ms, \
    vertex_count, triangle_count, chunk_count, chunk_vertices, settings, mesh_hash, header, \
    upload_bytes, source, \
    (SELECT count(*) FROM chunks c WHERE c.scene_id = scenes.id) + chunks_corrupt, \
    chunks_corrupt, warnings";

/// `xid` of the current transaction, as a column value.
const XID: &str = "pg_current_xact_id()::text::bigint";

/// A chunk leased by a worker.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Lease {
    pub scene_id: String,
    pub idx: u32,
    pub token: i64,
}

/// What became of a worker's attempt to record a chunk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Recorded {
    Yes,
    /// The lease was taken over: another worker's chunk counts, this one is dropped.
    Fenced,
    /// The scene is gone (deleted, failed) or not baking.
    SceneGone,
}

/// A worker as the database knows it.
#[derive(Clone, Debug, serde::Serialize, utoipa::ToSchema)]
pub(crate) struct WorkerInfo {
    pub id: String,
    pub host: String,
    pub threads: u32,
    /// Seconds since its last heartbeat.
    pub last_seen_s: f64,
    /// Whether it sent a heartbeat within the lease time.
    pub live: bool,
    /// Chunks it holds a lease on now.
    pub chunks_leased: u64,
    pub chunks_done: u64,
    /// Stale results refused (its lease had been taken over).
    pub chunks_fenced: u64,
    pub chunks_failed: u64,
}

/// Queue depth and workers, from the database.
#[derive(Clone, Debug, Default)]
pub(crate) struct ClusterGauges {
    pub scenes_queued: u64,
    pub scenes_baking: u64,
    pub chunks_pending: u64,
    pub chunks_leased: u64,
    pub chunks_fenced: u64,
    pub workers: Vec<WorkerInfo>,
}

/// Changes committed since a poll.
pub(crate) struct Changes {
    pub scenes: Vec<SceneRow>,
    pub chunks: Vec<(String, u32, ChunkMeta)>,
    /// Pass this to the next poll.
    pub next: i64,
}

type Fut<'a, T> = Pin<Box<dyn Future<Output = Result<T, tokio_postgres::Error>> + Send + 'a>>;

/// The PostgreSQL database.
pub(crate) struct PgDb {
    pool: Pool,
    pub generation: i64,
    /// A worker is live while its last heartbeat is younger than this.
    pub lease_ttl: Duration,
}

/// Whether an error is worth retrying: the connection, a restart, a serialization failure.
fn transient(e: &tokio_postgres::Error) -> bool {
    if e.is_closed() {
        return true;
    }
    match e.code() {
        None => e.as_db_error().is_none(),
        Some(c) => {
            *c == SqlState::T_R_DEADLOCK_DETECTED
                || *c == SqlState::T_R_SERIALIZATION_FAILURE
                || *c == SqlState::ADMIN_SHUTDOWN
                || *c == SqlState::CRASH_SHUTDOWN
                || *c == SqlState::CANNOT_CONNECT_NOW
                || c.code().starts_with("08")
        }
    }
}

/// Runs `f` on a pooled connection, retrying transient failures for up to [`RETRY_FOR`].
async fn retry<T, F>(pool: Pool, what: &'static str, attempt: Duration, f: F) -> Result<T>
where
    F: for<'a> Fn(&'a mut Object) -> Fut<'a, T> + Sync,
{
    let t0 = Instant::now();
    let mut delay = Duration::from_millis(50);
    loop {
        let err = match pool.get().await {
            Ok(mut c) => match tokio::time::timeout(attempt, f(&mut c)).await {
                Ok(Ok(v)) => return Ok(v),
                Ok(Err(e)) if transient(&e) => {
                    // The connection may be dead: do not give it back.
                    let _ = Object::take(c);
                    format!("{e}")
                }
                Ok(Err(e)) => {
                    return Err(anyhow::Error::new(e).context(format!("database error ({what})")));
                }
                Err(_) => {
                    let _ = Object::take(c);
                    format!("no answer within {:.0} s", attempt.as_secs_f64())
                }
            },
            Err(e) => format!("{e}"),
        };
        if t0.elapsed() > RETRY_FOR {
            anyhow::bail!(
                "the database is unreachable ({what}): {err}; gave up after {} s",
                RETRY_FOR.as_secs()
            );
        }
        tracing::warn!(what, error = %err, retry_ms = delay.as_millis() as u64, "database unavailable; retrying");
        tokio::time::sleep(delay).await;
        delay = (delay * 2).min(Duration::from_secs(2));
    }
}

fn scene_row(r: &tokio_postgres::Row) -> Result<SceneRow> {
    let state: String = r.try_get(2)?;
    Ok(SceneRow {
        id: r.try_get(0)?,
        seq: r.try_get(1)?,
        state: JobState::parse(&state)
            .with_context(|| format!("unknown scene state {state:?} in the database"))?,
        reason: r.try_get(3)?,
        created_ms: r.try_get(4)?,
        started_ms: r.try_get(5)?,
        finished_ms: r.try_get(6)?,
        vertex_count: r.try_get::<_, i64>(7)? as u32,
        triangle_count: r.try_get::<_, i64>(8)? as u64,
        chunk_count: r.try_get::<_, i64>(9)? as u32,
        chunk_vertices: r.try_get::<_, i64>(10)? as u32,
        settings_json: r.try_get(11)?,
        mesh_hash: r.try_get::<_, i64>(12)? as u64,
        header: r.try_get(13)?,
        upload_bytes: r.try_get::<_, i64>(14)? as u64,
        source: r.try_get(15)?,
        chunks_baked: r.try_get::<_, i64>(16)? as u64,
        chunks_corrupt: r.try_get::<_, i64>(17)? as u64,
        warnings: serde_json::from_str(&r.try_get::<_, String>(18)?).unwrap_or_default(),
    })
}

/// Marks scene `id` done if no task is left (run after a record's commit: of two records
/// committing together, the later check sees both).
async fn finish_if_complete(c: &Object, id: &str, now: i64) -> Result<(), tokio_postgres::Error> {
    c.execute(
        &format!(
            "UPDATE scenes SET state = 'done', reason = NULL, finished_ms = $2, xid = {XID}
             WHERE id = $1 AND state IN ('queued', 'baking')
               AND NOT EXISTS(SELECT 1 FROM tasks WHERE scene_id = $1)"
        ),
        &[&id, &now],
    )
    .await?;
    Ok(())
}

fn chunk_meta(bytes: i64, crc32: i64) -> ChunkMeta {
    ChunkMeta {
        bytes: bytes as u32,
        crc32: crc32 as u32,
    }
}

impl PgDb {
    /// Connects (retrying while the server starts), creates the schema if missing (under an
    /// advisory lock: several processes may start at once) and starts a new generation.
    pub(crate) fn open(url: &str, lease_ttl: Duration) -> Result<PgDb> {
        let mut pg: tokio_postgres::Config = url
            .parse()
            .with_context(|| "--database: not a valid postgres:// URL".to_string())?;
        // A process frozen inside a transaction (paused, cut off) must not hold its row locks
        // for longer than a lease: the server aborts the transaction, and the process's retry
        // finds itself fenced.
        let idle_ms = lease_ttl.as_millis().max(1000);
        pg.options(format!("-c idle_in_transaction_session_timeout={idle_ms}"));
        let mgr = Manager::from_config(
            pg,
            NoTls,
            ManagerConfig {
                recycling_method: RecyclingMethod::Fast,
            },
        );
        let pool = Pool::builder(mgr)
            .max_size(16)
            .runtime(deadpool_postgres::Runtime::Tokio1)
            .create_timeout(Some(Duration::from_secs(5)))
            .wait_timeout(Some(Duration::from_secs(10)))
            .recycle_timeout(Some(Duration::from_secs(5)))
            .build()
            .context("cannot create the database pool")?;
        let p = pool.clone();
        // Creating the schema waits for the other processes' advisory lock: a minute per try.
        let generation = io::block_on(retry(p, "schema", Duration::from_secs(60), |c| {
            Box::pin(async move {
                let tx = c.transaction().await?;
                tx.execute("SELECT pg_advisory_xact_lock(2020)", &[])
                    .await?;
                tx.batch_execute(SCHEMA).await?;
                let g: i64 = tx
                    .query_one(
                        "INSERT INTO meta(key, value) VALUES('generation', 1)
                         ON CONFLICT(key) DO UPDATE SET value = meta.value + 1 RETURNING value",
                        &[],
                    )
                    .await?
                    .get(0);
                tx.commit().await?;
                Ok(g)
            })
        }))
        .context("cannot open the PostgreSQL database")?;
        Ok(PgDb {
            pool,
            generation,
            lease_ttl,
        })
    }

    fn run<T, F>(&self, what: &'static str, f: F) -> Result<T>
    where
        T: Send + 'static,
        F: for<'a> Fn(&'a mut Object) -> Fut<'a, T> + Send + Sync + 'static,
    {
        let attempt = self.lease_ttl.max(Duration::from_secs(5));
        io::block_on(retry(self.pool.clone(), what, attempt, f))
    }

    pub(crate) fn ping(&self) -> Result<()> {
        // One try: health must answer now, not in 90 s.
        let pool = self.pool.clone();
        io::block_on(async move {
            let c = tokio::time::timeout(Duration::from_secs(3), pool.get())
                .await
                .context("the database does not answer")??;
            tokio::time::timeout(Duration::from_secs(3), c.query_one("SELECT 1", &[]))
                .await
                .context("the database does not answer")??;
            Ok(())
        })
    }

    pub(crate) fn insert_scene_with_key(
        &self,
        r: &SceneRow,
        key: Option<(&str, &str)>,
    ) -> Result<i64> {
        let r = r.clone();
        let key = key.map(|(k, f)| (k.to_string(), f.to_string()));
        self.run("insert scene", move |c| {
            let (r, key) = (r.clone(), key.clone());
            Box::pin(async move {
                let tx = c.transaction().await?;
                let warnings = serde_json::to_string(&r.warnings).unwrap_or_else(|_| "[]".into());
                let seq: i64 = tx
                    .query_one(
                        "INSERT INTO scenes(id, state, created_ms, vertex_count, triangle_count,
                             chunk_count, chunk_vertices, settings, mesh_hash, header,
                             upload_bytes, source, warnings)
                         VALUES($1, 'queued', $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12)
                         RETURNING seq",
                        &[
                            &r.id,
                            &r.created_ms,
                            &(r.vertex_count as i64),
                            &(r.triangle_count as i64),
                            &(r.chunk_count as i64),
                            &(r.chunk_vertices as i64),
                            &r.settings_json,
                            &(r.mesh_hash as i64),
                            &r.header,
                            &(r.upload_bytes as i64),
                            &r.source,
                            &warnings,
                        ],
                    )
                    .await?
                    .get(0);
                tx.execute(
                    "INSERT INTO tasks(scene_id, idx)
                     SELECT $1, g FROM generate_series(0, $2::int - 1) g",
                    &[&r.id, &(r.chunk_count as i32)],
                )
                .await?;
                if let Some((k, f)) = &key {
                    tx.execute(
                        "INSERT INTO idempotency_keys(key, fingerprint, scene_id, created_ms)
                         VALUES($1, $2, $3, $4)",
                        &[k, f, &r.id, &r.created_ms],
                    )
                    .await?;
                }
                tx.commit().await?;
                Ok(seq)
            })
        })
    }

    pub(crate) fn idempotent(
        &self,
        key: &str,
        not_before_ms: i64,
    ) -> Result<Option<IdempotentRecord>> {
        let key = key.to_string();
        self.run("idempotency key", move |c| {
            let key = key.clone();
            Box::pin(async move {
                c.execute(
                    "DELETE FROM idempotency_keys WHERE created_ms < $1",
                    &[&not_before_ms],
                )
                .await?;
                let r = c
                    .query_opt(
                        "SELECT fingerprint, scene_id, created_ms FROM idempotency_keys
                         WHERE key = $1",
                        &[&key],
                    )
                    .await?;
                Ok(r.map(|r| IdempotentRecord {
                    fingerprint: r.get(0),
                    scene_id: r.get(1),
                    created_ms: r.get(2),
                }))
            })
        })
    }

    pub(crate) fn list_scenes(
        &self,
        before: Option<&str>,
        states: Option<&[JobState]>,
        limit: u32,
    ) -> Result<Option<Vec<SceneSummary>>> {
        let before = before.map(str::to_string);
        let states: Option<Vec<String>> =
            states.map(|s| s.iter().map(|s| s.as_str().to_string()).collect());
        let rows = self.run("list scenes", move |c| {
            let (before, states) = (before.clone(), states.clone());
            Box::pin(async move {
                let below = match &before {
                    None => i64::MAX,
                    Some(id) => {
                        match c
                            .query_opt("SELECT seq FROM scenes WHERE id = $1", &[id])
                            .await?
                        {
                            Some(r) => r.get(0),
                            None => return Ok(None),
                        }
                    }
                };
                let rows = c
                    .query(
                        "SELECT s.id, s.state, s.reason, s.created_ms, s.finished_ms,
                             s.vertex_count, s.chunk_count, s.source,
                             (SELECT COUNT(*) FROM chunks c WHERE c.scene_id = s.id)
                         FROM scenes s
                         WHERE s.seq < $1 AND ($2::text[] IS NULL OR s.state = ANY($2))
                         ORDER BY s.seq DESC LIMIT $3",
                        &[&below, &states, &(limit as i64)],
                    )
                    .await?;
                Ok(Some(rows))
            })
        })?;
        let Some(rows) = rows else { return Ok(None) };
        rows.into_iter()
            .map(|r| {
                let state: String = r.try_get(1)?;
                Ok(SceneSummary {
                    id: r.try_get(0)?,
                    state: JobState::parse(&state)
                        .with_context(|| format!("unknown scene state {state:?}"))?,
                    reason: r.try_get(2)?,
                    created_ms: r.try_get(3)?,
                    finished_ms: r.try_get(4)?,
                    vertex_count: r.try_get::<_, i64>(5)? as u32,
                    chunk_count: r.try_get::<_, i64>(6)? as u32,
                    source: r.try_get(7)?,
                    chunks_done: r.try_get::<_, i64>(8)? as u32,
                })
            })
            .collect::<Result<Vec<_>>>()
            .map(Some)
    }

    pub(crate) fn scene(&self, id: &str) -> Result<Option<SceneRow>> {
        let id = id.to_string();
        let r = self.run("scene", move |c| {
            let id = id.clone();
            Box::pin(async move {
                c.query_opt(
                    &format!("SELECT {SCENE_COLUMNS} FROM scenes WHERE id = $1"),
                    &[&id],
                )
                .await
            })
        })?;
        r.as_ref().map(scene_row).transpose()
    }

    /// Scenes queued or baking, in submission order.
    pub(crate) fn unfinished_scenes(&self) -> Result<Vec<SceneRow>> {
        let rows = self.run("unfinished scenes", |c| {
            Box::pin(async move {
                c.query(
                    &format!(
                        "SELECT {SCENE_COLUMNS} FROM scenes WHERE state IN ('queued', 'baking')
                         ORDER BY seq"
                    ),
                    &[],
                )
                .await
            })
        })?;
        rows.iter().map(scene_row).collect()
    }

    pub(crate) fn chunks(&self, id: &str) -> Result<Vec<(u32, ChunkMeta)>> {
        let id = id.to_string();
        let rows = self.run("chunks", move |c| {
            let id = id.clone();
            Box::pin(async move {
                c.query(
                    "SELECT idx, bytes, crc32 FROM chunks WHERE scene_id = $1 ORDER BY idx",
                    &[&id],
                )
                .await
            })
        })?;
        Ok(rows
            .iter()
            .map(|r| (r.get::<_, i32>(0) as u32, chunk_meta(r.get(1), r.get(2))))
            .collect())
    }

    /// Forgets a chunk found corrupt and queues it again.
    pub(crate) fn drop_chunk(
        &self,
        id: &str,
        idx: u32,
        seen: ChunkMeta,
        corrupt: bool,
    ) -> Result<bool> {
        let id = id.to_string();
        self.run("drop chunk", move |c| {
            let id = id.clone();
            Box::pin(async move {
                let tx = c.transaction().await?;
                let n = tx
                    .execute(
                        "DELETE FROM chunks WHERE scene_id = $1 AND idx = $2 AND bytes = $3
                             AND crc32 = $4",
                        &[
                            &id,
                            &(idx as i32),
                            &(seen.bytes as i64),
                            &(seen.crc32 as i64),
                        ],
                    )
                    .await?;
                if n == 1 {
                    tx.execute(
                        "INSERT INTO tasks(scene_id, idx) VALUES($1, $2) ON CONFLICT DO NOTHING",
                        &[&id, &(idx as i32)],
                    )
                    .await?;
                    tx.execute(
                        &format!(
                            "UPDATE scenes SET chunks_corrupt = chunks_corrupt + $2,
                                 state = CASE WHEN state = 'done' THEN 'baking' ELSE state END,
                                 finished_ms = CASE WHEN state = 'done' THEN NULL
                                     ELSE finished_ms END,
                                 xid = {XID}
                             WHERE id = $1"
                        ),
                        &[&id, &(corrupt as i64)],
                    )
                    .await?;
                }
                tx.commit().await?;
                Ok(n == 1)
            })
        })
    }

    pub(crate) fn set_state(&self, id: &str, state: JobState, reason: Option<&str>) -> Result<()> {
        let (id, reason) = (id.to_string(), reason.map(str::to_string));
        let now = now_ms();
        self.run("set state", move |c| {
            let (id, reason) = (id.clone(), reason.clone());
            Box::pin(async move {
                c.execute(
                    &format!(
                        "UPDATE scenes SET state = $2, reason = $3,
                             started_ms = CASE WHEN $2 = 'baking' THEN COALESCE(started_ms, $4)
                                 ELSE started_ms END,
                             finished_ms = CASE WHEN $2 IN ('done', 'failed', 'cancelled')
                                 THEN $4 ELSE NULL END,
                             xid = {XID}
                         WHERE id = $1"
                    ),
                    &[&id, &state.as_str(), &reason, &now],
                )
                .await?;
                Ok(())
            })
        })
    }

    /// Cancels a scene: its tasks (so that no worker takes or records its chunks) and chunk
    /// rows go, a `cancelled` tombstone stays.
    pub(crate) fn cancel(&self, id: &str) -> Result<Option<JobState>> {
        let id = id.to_string();
        let now = now_ms();
        let before = self.run("cancel", move |c| {
            let id = id.clone();
            Box::pin(async move {
                let tx = c.transaction().await?;
                // Tasks first: the lock order of leases (task, then scene).
                tx.execute("DELETE FROM tasks WHERE scene_id = $1", &[&id])
                    .await?;
                let before = tx
                    .query_opt("SELECT state FROM scenes WHERE id = $1 FOR UPDATE", &[&id])
                    .await?
                    .map(|r| r.get::<_, String>(0));
                if before.is_some() {
                    tx.execute("DELETE FROM chunks WHERE scene_id = $1", &[&id])
                        .await?;
                    tx.execute(
                        &format!(
                            "UPDATE scenes SET state = 'cancelled', reason = 'deleted by a client',
                                 finished_ms = COALESCE(finished_ms, $2), xid = {XID}
                             WHERE id = $1"
                        ),
                        &[&id, &now],
                    )
                    .await?;
                }
                tx.commit().await?;
                Ok(before)
            })
        })?;
        before
            .map(|s| JobState::parse(&s).with_context(|| format!("unknown scene state {s:?}")))
            .transpose()
    }

    // -----------------------------------------------------------------------------------------
    // Workers and leases.

    /// Records a worker (again, if it restarts under the same id) as live.
    pub(crate) fn register_worker(&self, id: &str, host: &str, threads: u32) -> Result<()> {
        let (id, host) = (id.to_string(), host.to_string());
        let now = now_ms();
        self.run("register worker", move |c| {
            let (id, host) = (id.clone(), host.clone());
            Box::pin(async move {
                c.execute(
                    "INSERT INTO workers(id, host, threads, started_ms, last_seen)
                     VALUES($1, $2, $3, $4, clock_timestamp())
                     ON CONFLICT(id) DO UPDATE SET host = $2, threads = $3, started_ms = $4,
                         last_seen = clock_timestamp(), stopped = false",
                    &[&id, &host, &(threads as i32), &now],
                )
                .await?;
                Ok(())
            })
        })
    }

    /// A worker that stops cleanly: its leases are given back at once.
    pub(crate) fn worker_stopped(&self, id: &str) -> Result<()> {
        let id = id.to_string();
        self.run("worker stopped", move |c| {
            let id = id.clone();
            Box::pin(async move {
                c.execute(
                    "UPDATE tasks SET worker = NULL, token = NULL, lease_until = NULL
                     WHERE worker = $1",
                    &[&id],
                )
                .await?;
                c.execute("UPDATE workers SET stopped = true WHERE id = $1", &[&id])
                    .await?;
                Ok(())
            })
        })
    }

    /// Leases the next chunk for `worker`: the lowest chunk index of any scene being baked
    /// whose lease is free or expired, skipping chunks that failed on this worker before.
    /// `None` when there is nothing to do.
    pub(crate) fn lease(&self, worker: &str) -> Result<Option<Lease>> {
        let worker = worker.to_string();
        let ttl = self.lease_ttl.as_secs_f64();
        let now = now_ms();
        self.run("lease", move |c| {
            let worker = worker.clone();
            Box::pin(async move {
                let Some(r) = c
                    .query_opt(
                        "WITH pick AS (
                             SELECT t.scene_id, t.idx FROM tasks t
                             JOIN scenes s ON s.id = t.scene_id
                             WHERE s.state IN ('queued', 'baking')
                               AND (t.lease_until IS NULL OR t.lease_until < clock_timestamp())
                               AND NOT ($1 = ANY(t.failed_on))
                             ORDER BY t.idx, t.scene_id
                             LIMIT 1
                             FOR UPDATE OF t SKIP LOCKED
                         )
                         UPDATE tasks t SET worker = $1, token = nextval('bspvt_lease_token'),
                             lease_until = clock_timestamp() + make_interval(secs => $2),
                             leases = t.leases + 1
                         FROM pick WHERE t.scene_id = pick.scene_id AND t.idx = pick.idx
                         RETURNING t.scene_id, t.idx, t.token,
                             (SELECT state FROM scenes WHERE id = t.scene_id)",
                        &[&worker, &ttl],
                    )
                    .await?
                else {
                    return Ok(None);
                };
                let lease = Lease {
                    scene_id: r.get(0),
                    idx: r.get::<_, i32>(1) as u32,
                    token: r.get(2),
                };
                if r.get::<_, Option<String>>(3).as_deref() == Some("queued") {
                    c.execute(
                        &format!(
                            "UPDATE scenes SET state = 'baking', xid = {XID},
                                 started_ms = COALESCE(started_ms, $2)
                             WHERE id = $1 AND state = 'queued'"
                        ),
                        &[&lease.scene_id, &now],
                    )
                    .await?;
                }
                Ok(Some(lease))
            })
        })
    }

    /// Heartbeat: renews `worker`'s leases on `tokens` and returns those it still holds (a
    /// token missing from the answer was taken over, or its scene deleted).
    pub(crate) fn heartbeat(&self, worker: &str, tokens: &[i64]) -> Result<Vec<i64>> {
        let worker = worker.to_string();
        let tokens = tokens.to_vec();
        let ttl = self.lease_ttl.as_secs_f64();
        self.run("heartbeat", move |c| {
            let (worker, tokens) = (worker.clone(), tokens.clone());
            Box::pin(async move {
                c.execute(
                    "UPDATE workers SET last_seen = clock_timestamp(), stopped = false
                     WHERE id = $1",
                    &[&worker],
                )
                .await?;
                if tokens.is_empty() {
                    return Ok(Vec::new());
                }
                let rows = c
                    .query(
                        "UPDATE tasks SET lease_until = clock_timestamp() + make_interval(secs => $3)
                         WHERE worker = $1 AND token = ANY($2) RETURNING token",
                        &[&worker, &tokens, &ttl],
                    )
                    .await?;
                Ok(rows.iter().map(|r| r.get(0)).collect())
            })
        })
    }

    /// Records chunk `l` (its object is already stored) if `worker` still holds its lease;
    /// the scene is `done` when it was the last.
    pub(crate) fn complete(&self, worker: &str, l: &Lease, m: ChunkMeta) -> Result<Recorded> {
        let (worker, l) = (worker.to_string(), l.clone());
        let now = now_ms();
        self.run("record chunk", move |c| {
            let (worker, l) = (worker.clone(), l.clone());
            Box::pin(async move {
                let tx = c.transaction().await?;
                let idx = l.idx as i32;
                let deleted = tx
                    .query_opt(
                        "DELETE FROM tasks WHERE scene_id = $1 AND idx = $2 AND token = $3
                         RETURNING leases",
                        &[&l.scene_id, &idx, &l.token],
                    )
                    .await?;
                let outcome = match deleted {
                    Some(r) => {
                        let leases: i32 = r.get(0);
                        tx.execute(
                            "INSERT INTO chunks(scene_id, idx, bytes, crc32, worker, token,
                                 leases, baked_ms)
                             VALUES($1, $2, $3, $4, $5, $6, $7, $8)
                             ON CONFLICT(scene_id, idx) DO UPDATE SET bytes = $3, crc32 = $4,
                                 worker = $5, token = $6, leases = chunks.leases + $7,
                                 baked_ms = $8, xid = pg_current_xact_id()::text::bigint",
                            &[
                                &l.scene_id,
                                &idx,
                                &(m.bytes as i64),
                                &(m.crc32 as i64),
                                &worker,
                                &l.token,
                                &leases,
                                &now,
                            ],
                        )
                        .await?;
                        tx.execute(
                            "UPDATE workers SET chunks_done = chunks_done + 1,
                                 last_seen = clock_timestamp()
                             WHERE id = $1",
                            &[&worker],
                        )
                        .await?;
                        Recorded::Yes
                    }
                    None => {
                        // A retry whose first commit landed finds its own chunk row.
                        let mine = tx
                            .query_opt(
                                "SELECT 1 FROM chunks WHERE scene_id = $1 AND idx = $2
                                     AND token = $3",
                                &[&l.scene_id, &idx, &l.token],
                            )
                            .await?
                            .is_some();
                        let live = tx
                            .query_opt(
                                "SELECT 1 FROM scenes WHERE id = $1
                                     AND state IN ('queued', 'baking')",
                                &[&l.scene_id],
                            )
                            .await?
                            .is_some();
                        if mine {
                            Recorded::Yes
                        } else if !live {
                            Recorded::SceneGone
                        } else {
                            tx.execute(
                                "UPDATE workers SET chunks_fenced = chunks_fenced + 1
                                 WHERE id = $1",
                                &[&worker],
                            )
                            .await?;
                            Recorded::Fenced
                        }
                    }
                };
                tx.commit().await?;
                if outcome == Recorded::Yes {
                    finish_if_complete(c, &l.scene_id, now).await?;
                }
                Ok(outcome)
            })
        })
    }

    /// Marks `done` every scene being baked with all its chunks recorded and no task left (a
    /// recorder that died between its commit and its check leaves one).
    pub(crate) fn sweep_finished(&self) -> Result<u64> {
        let now = now_ms();
        self.run("sweep finished scenes", move |c| {
            Box::pin(async move {
                c.execute(
                    &format!(
                        "UPDATE scenes SET state = 'done', reason = NULL, finished_ms = $1,
                             xid = {XID}
                         WHERE state IN ('queued', 'baking')
                           AND NOT EXISTS(SELECT 1 FROM tasks t WHERE t.scene_id = scenes.id)
                           AND chunk_count = (SELECT count(*) FROM chunks c
                               WHERE c.scene_id = scenes.id)"
                    ),
                    &[&now],
                )
                .await
            })
        })
    }

    /// Gives chunk `l` back without counting a failure, not to be leased for `delay` (the
    /// store failed for now: `cluster`'s backoff). Nothing happens when the lease was lost.
    pub(crate) fn put_back(&self, l: &Lease, reason: &str, delay: Duration) -> Result<()> {
        let (l, reason) = (l.clone(), reason.to_string());
        let secs = delay.as_secs_f64();
        self.run("put a chunk back", move |c| {
            let (l, reason) = (l.clone(), reason.clone());
            Box::pin(async move {
                c.execute(
                    "UPDATE tasks SET worker = NULL, token = NULL, last_error = $3,
                         lease_until = clock_timestamp() + make_interval(secs => $5)
                     WHERE scene_id = $1 AND idx = $2 AND token = $4",
                    &[&l.scene_id, &(l.idx as i32), &reason, &l.token, &secs],
                )
                .await?;
                Ok(())
            })
        })
    }

    /// Chunk `l` failed on `worker`: its lease is given back for another worker; after
    /// `max_failures` different workers the scene fails with `reason`. Returns whether the
    /// scene failed.
    pub(crate) fn fail_chunk(
        &self,
        worker: &str,
        l: &Lease,
        reason: &str,
        max_failures: u32,
    ) -> Result<bool> {
        let (worker, l, reason) = (worker.to_string(), l.clone(), reason.to_string());
        let now = now_ms();
        self.run("record a failure", move |c| {
            let (worker, l, reason) = (worker.clone(), l.clone(), reason.clone());
            Box::pin(async move {
                let tx = c.transaction().await?;
                let r = tx
                    .query_opt(
                        "UPDATE tasks SET worker = NULL, token = NULL, lease_until = NULL,
                             last_error = $4,
                             failed_on = CASE WHEN $3 = ANY(failed_on) THEN failed_on
                                 ELSE array_append(failed_on, $3) END
                         WHERE scene_id = $1 AND idx = $2 AND token = $5
                         RETURNING cardinality(failed_on)",
                        &[&l.scene_id, &(l.idx as i32), &worker, &reason, &l.token],
                    )
                    .await?;
                tx.execute(
                    "UPDATE workers SET chunks_failed = chunks_failed + 1 WHERE id = $1",
                    &[&worker],
                )
                .await?;
                let failures = r.map_or(0, |r| r.get::<_, i32>(0));
                let failed = failures as u32 >= max_failures;
                if failed {
                    let why = format!(
                        "chunk {} failed on {failures} different workers; last error: {reason}",
                        l.idx
                    );
                    tx.execute("DELETE FROM tasks WHERE scene_id = $1", &[&l.scene_id])
                        .await?;
                    tx.execute(
                        &format!(
                            "UPDATE scenes SET state = 'failed', reason = $2, finished_ms = $3,
                                 xid = {XID}
                             WHERE id = $1 AND state IN ('queued', 'baking')"
                        ),
                        &[&l.scene_id, &why, &now],
                    )
                    .await?;
                }
                tx.commit().await?;
                Ok(failed)
            })
        })
    }

    /// Scenes and chunks committed since `since` (0: everything); see the module's notes.
    pub(crate) fn changes(&self, since: i64) -> Result<Changes> {
        let (next, scenes, chunks) = self.run("changes", move |c| {
            Box::pin(async move {
                let tx = c
                    .build_transaction()
                    .isolation_level(tokio_postgres::IsolationLevel::RepeatableRead)
                    .read_only(true)
                    .start()
                    .await?;
                let next: i64 = tx
                    .query_one(
                        "SELECT pg_snapshot_xmin(pg_current_snapshot())::text::bigint",
                        &[],
                    )
                    .await?
                    .get(0);
                let scenes = tx
                    .query(
                        &format!("SELECT {SCENE_COLUMNS} FROM scenes WHERE xid >= $1"),
                        &[&since],
                    )
                    .await?;
                let chunks = tx
                    .query(
                        "SELECT scene_id, idx, bytes, crc32 FROM chunks WHERE xid >= $1",
                        &[&since],
                    )
                    .await?;
                tx.commit().await?;
                Ok((next, scenes, chunks))
            })
        })?;
        Ok(Changes {
            scenes: scenes.iter().map(scene_row).collect::<Result<_>>()?,
            chunks: chunks
                .iter()
                .map(|r| {
                    (
                        r.get(0),
                        r.get::<_, i32>(1) as u32,
                        chunk_meta(r.get(2), r.get(3)),
                    )
                })
                .collect(),
            next,
        })
    }

    /// Queue depth and the workers seen in the last hour.
    pub(crate) fn gauges(&self) -> Result<ClusterGauges> {
        let ttl = self.lease_ttl.as_secs_f64();
        let (counts, workers) = self.run("gauges", move |c| {
            Box::pin(async move {
                let counts = c
                    .query_one(
                        "SELECT (SELECT count(*) FROM scenes WHERE state = 'queued'),
                             (SELECT count(*) FROM scenes WHERE state = 'baking'),
                             (SELECT count(*) FROM tasks WHERE lease_until IS NULL
                                 OR lease_until < clock_timestamp()),
                             (SELECT count(*) FROM tasks WHERE lease_until >= clock_timestamp()),
                             (SELECT COALESCE(sum(chunks_fenced), 0)::bigint FROM workers)",
                        &[],
                    )
                    .await?;
                let workers = c
                    .query(
                        "SELECT w.id, w.host, w.threads,
                             EXTRACT(EPOCH FROM clock_timestamp() - w.last_seen)::float8,
                             (SELECT count(*) FROM tasks t WHERE t.worker = w.id
                                 AND t.lease_until >= clock_timestamp()),
                             w.chunks_done, w.chunks_fenced, w.chunks_failed
                         FROM workers w
                         WHERE NOT w.stopped
                           AND w.last_seen > clock_timestamp() - interval '1 hour'
                         ORDER BY w.id",
                        &[],
                    )
                    .await?;
                Ok((counts, workers))
            })
        })?;
        let n = |i: usize| counts.get::<_, i64>(i) as u64;
        Ok(ClusterGauges {
            scenes_queued: n(0),
            scenes_baking: n(1),
            chunks_pending: n(2),
            chunks_leased: n(3),
            chunks_fenced: n(4),
            workers: workers
                .iter()
                .map(|r| {
                    let age: f64 = r.get(3);
                    WorkerInfo {
                        id: r.get(0),
                        host: r.get(1),
                        threads: r.get::<_, i32>(2) as u32,
                        last_seen_s: age,
                        live: age < ttl,
                        chunks_leased: r.get::<_, i64>(4) as u64,
                        chunks_done: r.get::<_, i64>(5) as u64,
                        chunks_fenced: r.get::<_, i64>(6) as u64,
                        chunks_failed: r.get::<_, i64>(7) as u64,
                    }
                })
                .collect(),
        })
    }

    /// Seconds until the first lease held on scene `id`'s chunks by a silent worker (no
    /// heartbeat within the lease time) expires, if every leased chunk of it is held by one.
    pub(crate) fn held_by_silent(&self, id: &str) -> Result<Option<f64>> {
        let id = id.to_string();
        let ttl = self.lease_ttl.as_secs_f64();
        self.run("silent leases", move |c| {
            let id = id.clone();
            Box::pin(async move {
                let r = c
                    .query_one(
                        "SELECT count(*) FILTER (WHERE t.lease_until >= clock_timestamp()
                                 AND (w.last_seen IS NULL OR w.last_seen
                                     < clock_timestamp() - make_interval(secs => $2))),
                             count(*) FILTER (WHERE t.lease_until IS NULL
                                 OR t.lease_until < clock_timestamp()
                                 OR w.last_seen >= clock_timestamp() - make_interval(secs => $2)),
                             EXTRACT(EPOCH FROM min(t.lease_until) - clock_timestamp())::float8
                         FROM tasks t LEFT JOIN workers w ON w.id = t.worker
                         WHERE t.scene_id = $1",
                        &[&id, &ttl],
                    )
                    .await?;
                let (silent, other): (i64, i64) = (r.get(0), r.get(1));
                let expires: Option<f64> = r.get(2);
                Ok((silent > 0 && other == 0).then(|| expires.unwrap_or(0.0).max(0.0)))
            })
        })
    }
}
