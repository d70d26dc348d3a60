//! The embedded database (SQLite through rusqlite, bundled, WAL, `synchronous = FULL`): one row
//! per scene (state, sizes, settings, the bake header) and one row per durable chunk (length,
//! CRC-32, the process generation that baked it).
//!
//! Guarantees:
//! - a chunk row is only inserted after its file is durable (see `store`), and only while its
//!   scene is queued or baking — a chunk finishing after its scene was deleted is refused;
//! - every commit is synced (`synchronous = FULL`), so what a response reported survives a
//!   crash or a power cut;
//! - each process start bumps `generation`, so a chunk row tells which run baked it;
//! - foreign keys are enforced: chunk rows never outlive their scene row;
//! - an `Idempotency-Key` is recorded in the same transaction as the scene it created, so a
//!   key never names a scene that was not recorded, nor a recorded scene lack its key.

use std::path::Path;
use std::sync::{Mutex, MutexGuard};

use anyhow::{Context, Result};
use rusqlite::{Connection, OptionalExtension, params};

pub(crate) use super::rows::{
    ChunkMeta, IdempotentRecord, JobState, SceneRow, SceneSummary, now_ms,
};

/// A state column's text as a [`JobState`].
fn parse_state(s: &str) -> Result<JobState> {
    JobState::parse(s).with_context(|| format!("unknown scene state {s:?} in the database"))
}

/// 2: adds `scenes.warnings` (a version-1 database gains the column on open). The
/// `idempotency_keys` table is created on open when missing (an older build ignores it).
const SCHEMA_VERSION: i64 = 2;

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS meta (
    key TEXT PRIMARY KEY,
    value INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS scenes (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    id TEXT NOT NULL UNIQUE,
    state TEXT NOT NULL,
    reason TEXT,
    created_ms INTEGER NOT NULL,
    started_ms INTEGER,
    finished_ms INTEGER,
    vertex_count INTEGER NOT NULL,
    triangle_count INTEGER NOT NULL,
    chunk_count INTEGER NOT NULL,
    chunk_vertices INTEGER NOT NULL,
    settings TEXT NOT NULL,
    mesh_hash INTEGER NOT NULL,
    header BLOB NOT NULL,
    upload_bytes INTEGER NOT NULL,
    source TEXT NOT NULL,
    chunks_baked INTEGER NOT NULL DEFAULT 0,
    chunks_corrupt INTEGER NOT NULL DEFAULT 0,
    warnings TEXT NOT NULL DEFAULT '[]'
);
CREATE INDEX IF NOT EXISTS scenes_state ON scenes(state);
CREATE TABLE IF NOT EXISTS chunks (
    scene_id TEXT NOT NULL REFERENCES scenes(id) ON DELETE CASCADE,
    idx INTEGER NOT NULL,
    bytes INTEGER NOT NULL,
    crc32 INTEGER NOT NULL,
    generation INTEGER NOT NULL,
    baked_ms INTEGER NOT NULL,
    PRIMARY KEY (scene_id, idx)
) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS idempotency_keys (
    key TEXT PRIMARY KEY,
    fingerprint TEXT NOT NULL,
    scene_id TEXT NOT NULL REFERENCES scenes(id) ON DELETE CASCADE,
    created_ms INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS idempotency_keys_created ON idempotency_keys(created_ms);
";

const SCENE_COLUMNS: &str = "id, seq, state, reason, created_ms, started_ms, finished_ms, \
    vertex_count, triangle_count, chunk_count, chunk_vertices, settings, mesh_hash, header, \
    upload_bytes, source, chunks_baked, chunks_corrupt, warnings";

/// The service's database: the embedded SQLite one, or PostgreSQL for the distributed shape
/// (`pg`). Both keep the same scenes, chunks and idempotency keys with the same guarantees;
/// chunk leases and workers exist only in PostgreSQL.
pub(crate) enum Db {
    Sqlite(Sqlite),
    Pg(super::pg::PgDb),
}

/// Calls the same method on whichever database this is.
macro_rules! dispatch {
    ($self:ident.$m:ident($($a:expr),*)) => {
        match $self {
            Db::Sqlite(d) => d.$m($($a),*),
            Db::Pg(d) => d.$m($($a),*),
        }
    };
}

impl Db {
    /// Opens (creating if needed) the embedded database and starts a new generation.
    pub(crate) fn open(path: &Path) -> Result<Db> {
        Sqlite::open(path).map(Db::Sqlite)
    }

    /// This process's generation (bumped by every start against the database).
    pub(crate) fn generation(&self) -> i64 {
        match self {
            Db::Sqlite(d) => d.generation,
            Db::Pg(d) => d.generation,
        }
    }

    /// The PostgreSQL database, in the distributed shape.
    pub(crate) fn pg(&self) -> Option<&super::pg::PgDb> {
        match self {
            Db::Sqlite(_) => None,
            Db::Pg(d) => Some(d),
        }
    }

    pub(crate) fn ping(&self) -> Result<()> {
        dispatch!(self.ping())
    }

    #[cfg(test)]
    pub(crate) fn insert_scene(&self, r: &SceneRow) -> Result<i64> {
        self.insert_scene_with_key(r, None)
    }

    pub(crate) fn insert_scene_with_key(
        &self,
        r: &SceneRow,
        key: Option<(&str, &str)>,
    ) -> Result<i64> {
        dispatch!(self.insert_scene_with_key(r, key))
    }

    pub(crate) fn idempotent(
        &self,
        key: &str,
        not_before_ms: i64,
    ) -> Result<Option<IdempotentRecord>> {
        dispatch!(self.idempotent(key, not_before_ms))
    }

    pub(crate) fn list_scenes(
        &self,
        before: Option<&str>,
        states: Option<&[JobState]>,
        limit: u32,
    ) -> Result<Option<Vec<SceneSummary>>> {
        dispatch!(self.list_scenes(before, states, limit))
    }

    pub(crate) fn scene(&self, id: &str) -> Result<Option<SceneRow>> {
        dispatch!(self.scene(id))
    }

    pub(crate) fn unfinished_scenes(&self) -> Result<Vec<SceneRow>> {
        dispatch!(self.unfinished_scenes())
    }

    /// Scenes recorded `done` with chunk rows missing (the embedded database only: in
    /// PostgreSQL the last chunk's transaction is what makes a scene done).
    pub(crate) fn done_scenes_missing_chunks(&self) -> Result<Vec<(String, u32, u32)>> {
        match self {
            Db::Sqlite(d) => d.done_scenes_missing_chunks(),
            Db::Pg(_) => Ok(Vec::new()),
        }
    }

    pub(crate) fn scene_ids_with_data(&self) -> Result<std::collections::HashSet<String>> {
        match self {
            Db::Sqlite(d) => d.scene_ids_with_data(),
            Db::Pg(_) => anyhow::bail!("the distributed store is not swept for leftovers"),
        }
    }

    pub(crate) fn chunks(&self, id: &str) -> Result<Vec<(u32, ChunkMeta)>> {
        dispatch!(self.chunks(id))
    }

    /// Records a durable chunk baked by this process (the embedded scheduler; workers of the
    /// distributed shape record theirs with a lease, `PgDb::complete`).
    pub(crate) fn insert_chunk(&self, id: &str, idx: u32, m: ChunkMeta) -> Result<bool> {
        match self {
            Db::Sqlite(d) => d.insert_chunk(id, idx, m),
            Db::Pg(_) => anyhow::bail!("a chunk is recorded with its lease in PostgreSQL"),
        }
    }

    pub(crate) fn drop_chunk(
        &self,
        id: &str,
        idx: u32,
        seen: ChunkMeta,
        corrupt: bool,
    ) -> Result<bool> {
        dispatch!(self.drop_chunk(id, idx, seen, corrupt))
    }

    pub(crate) fn set_state(&self, id: &str, state: JobState, reason: Option<&str>) -> Result<()> {
        dispatch!(self.set_state(id, state, reason))
    }

    pub(crate) fn cancel(&self, id: &str) -> Result<Option<JobState>> {
        dispatch!(self.cancel(id))
    }
}

/// The embedded database: one connection behind a mutex (every statement is short).
pub(crate) struct Sqlite {
    conn: Mutex<Connection>,
    /// This process's generation (1 for the first start of a data directory).
    pub generation: i64,
}

impl Sqlite {
    /// Opens (creating if needed) the database and starts a new generation.
    pub(crate) fn open(path: &Path) -> Result<Sqlite> {
        let conn = Connection::open(path)
            .with_context(|| format!("cannot open database {}", path.display()))?;
        // One process per data directory: the exclusive lock is taken by the first write below
        // and held until the process ends (the OS drops it on a crash).
        conn.busy_timeout(std::time::Duration::from_secs(2))?;
        conn.pragma_update(None, "locking_mode", "EXCLUSIVE")?;
        conn.pragma_update(None, "journal_mode", "WAL")?;
        conn.pragma_update(None, "synchronous", "FULL")?;
        conn.pragma_update(None, "foreign_keys", true)?;
        // Corruption found now stops the start, before anything trusts (or deletes by) it.
        let check: Vec<String> = {
            let mut st = conn.prepare("PRAGMA quick_check")?;
            st.query_map([], |r| r.get(0))?
                .collect::<rusqlite::Result<_>>()
                .with_context(|| format!("cannot check database {}", path.display()))?
        };
        if check.first().map(String::as_str) != Some("ok") {
            anyhow::bail!(
                "database {} fails its integrity check (PRAGMA quick_check: {}); refusing to \
                 start, nothing was changed. Restore it from a backup, or move the data folder \
                 away to start empty",
                path.display(),
                check.iter().take(3).cloned().collect::<Vec<_>>().join("; ")
            );
        }
        let version: i64 = conn.pragma_query_value(None, "user_version", |r| r.get(0))?;
        if version > SCHEMA_VERSION {
            anyhow::bail!(
                "database {} has schema version {version}; this build knows {SCHEMA_VERSION}",
                path.display()
            );
        }
        conn.execute_batch(SCHEMA).with_context(|| {
            format!(
                "cannot use database {} (is another bspvt-server using this data directory?)",
                path.display()
            )
        })?;
        if version == 1 {
            conn.execute(
                "ALTER TABLE scenes ADD COLUMN warnings TEXT NOT NULL DEFAULT '[]'",
                [],
            )
            .with_context(|| format!("cannot upgrade database {}", path.display()))?;
        }
        conn.pragma_update(None, "user_version", SCHEMA_VERSION)?;
        conn.execute(
            "INSERT INTO meta(key, value) VALUES('generation', 1)
             ON CONFLICT(key) DO UPDATE SET value = value + 1",
            [],
        )?;
        let generation =
            conn.query_row("SELECT value FROM meta WHERE key = 'generation'", [], |r| {
                r.get(0)
            })?;
        Ok(Sqlite {
            conn: Mutex::new(conn),
            generation,
        })
    }

    fn conn(&self) -> MutexGuard<'_, Connection> {
        // A panic while holding the connection leaves SQLite consistent (each statement is
        // atomic), so a poisoned lock is still usable.
        self.conn.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Checks that the database answers.
    pub(crate) fn ping(&self) -> Result<()> {
        self.conn().query_row("SELECT 1", [], |_| Ok(()))?;
        Ok(())
    }

    /// [`Db::insert_scene`], recording in the same transaction the `Idempotency-Key` (and
    /// the request's fingerprint) that created it.
    pub(crate) fn insert_scene_with_key(
        &self,
        r: &SceneRow,
        key: Option<(&str, &str)>,
    ) -> Result<i64> {
        let mut c = self.conn();
        let tx = c.transaction()?;
        tx.execute(
            "INSERT INTO scenes(id, state, reason, created_ms, vertex_count, triangle_count,
                 chunk_count, chunk_vertices, settings, mesh_hash, header, upload_bytes, source,
                 warnings)
             VALUES(?1, ?2, NULL, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13)",
            params![
                r.id,
                JobState::Queued.as_str(),
                r.created_ms,
                r.vertex_count,
                r.triangle_count as i64,
                r.chunk_count,
                r.chunk_vertices,
                r.settings_json,
                r.mesh_hash as i64,
                r.header,
                r.upload_bytes as i64,
                r.source,
                serde_json::to_string(&r.warnings).unwrap_or_else(|_| "[]".into()),
            ],
        )?;
        let seq = tx.last_insert_rowid();
        if let Some((key, fingerprint)) = key {
            tx.execute(
                "INSERT INTO idempotency_keys(key, fingerprint, scene_id, created_ms)
                 VALUES(?1, ?2, ?3, ?4)",
                params![key, fingerprint, r.id, r.created_ms],
            )?;
        }
        tx.commit()?;
        Ok(seq)
    }

    /// The scene `key` created, if it was recorded at or after `not_before_ms`; older keys
    /// have expired and are deleted here.
    pub(crate) fn idempotent(
        &self,
        key: &str,
        not_before_ms: i64,
    ) -> Result<Option<IdempotentRecord>> {
        let c = self.conn();
        c.execute(
            "DELETE FROM idempotency_keys WHERE created_ms < ?1",
            [not_before_ms],
        )?;
        Ok(c.query_row(
            "SELECT fingerprint, scene_id, created_ms FROM idempotency_keys WHERE key = ?1",
            [key],
            |r| {
                Ok(IdempotentRecord {
                    fingerprint: r.get(0)?,
                    scene_id: r.get(1)?,
                    created_ms: r.get(2)?,
                })
            },
        )
        .optional()?)
    }

    /// Up to `limit` scenes, newest first, submitted before the scene `before` (a cursor:
    /// the last id of the previous page), whose state is one of `states` (all when `None`).
    /// `None` when the cursor names no scene.
    pub(crate) fn list_scenes(
        &self,
        before: Option<&str>,
        states: Option<&[JobState]>,
        limit: u32,
    ) -> Result<Option<Vec<SceneSummary>>> {
        let c = self.conn();
        let below = match before {
            None => i64::MAX,
            Some(id) => {
                let seq: Option<i64> = c
                    .query_row("SELECT seq FROM scenes WHERE id = ?1", [id], |r| r.get(0))
                    .optional()?;
                match seq {
                    Some(s) => s,
                    None => return Ok(None),
                }
            }
        };
        // ",done,failed," matches a state by `instr`: one statement, no SQL built from input.
        let filter: Option<String> = states.map(|s| {
            let names: Vec<&str> = s.iter().map(|s| s.as_str()).collect();
            format!(",{},", names.join(","))
        });
        let mut st = c.prepare(
            "SELECT s.id, s.state, s.reason, s.created_ms, s.finished_ms, s.vertex_count,
                 s.chunk_count, s.source,
                 (SELECT COUNT(*) FROM chunks c WHERE c.scene_id = s.id)
             FROM scenes s
             WHERE s.seq < ?1 AND (?2 IS NULL OR instr(?2, ',' || s.state || ',') > 0)
             ORDER BY s.seq DESC LIMIT ?3",
        )?;
        let rows = st
            .query_map(params![below, filter, limit], |r| {
                Ok((
                    SceneSummary {
                        id: r.get(0)?,
                        state: JobState::Queued,
                        reason: r.get(2)?,
                        created_ms: r.get(3)?,
                        finished_ms: r.get(4)?,
                        vertex_count: r.get(5)?,
                        chunk_count: r.get(6)?,
                        source: r.get(7)?,
                        chunks_done: r.get(8)?,
                    },
                    r.get::<_, String>(1)?,
                ))
            })?
            .collect::<rusqlite::Result<Vec<_>>>()?;
        rows.into_iter()
            .map(|(mut s, state)| {
                s.state = parse_state(&state)?;
                Ok(s)
            })
            .collect::<Result<Vec<_>>>()
            .map(Some)
    }

    fn row(r: &rusqlite::Row<'_>) -> rusqlite::Result<(SceneRow, String)> {
        let state: String = r.get(2)?;
        Ok((
            SceneRow {
                id: r.get(0)?,
                seq: r.get(1)?,
                state: JobState::Queued,
                reason: r.get(3)?,
                created_ms: r.get(4)?,
                started_ms: r.get(5)?,
                finished_ms: r.get(6)?,
                vertex_count: r.get(7)?,
                triangle_count: r.get::<_, i64>(8)? as u64,
                chunk_count: r.get(9)?,
                chunk_vertices: r.get(10)?,
                settings_json: r.get(11)?,
                mesh_hash: r.get::<_, i64>(12)? as u64,
                header: r.get(13)?,
                upload_bytes: r.get::<_, i64>(14)? as u64,
                source: r.get(15)?,
                chunks_baked: r.get::<_, i64>(16)? as u64,
                chunks_corrupt: r.get::<_, i64>(17)? as u64,
                // Written by this module as a JSON list; anything else reads as none.
                warnings: serde_json::from_str(&r.get::<_, String>(18)?).unwrap_or_default(),
            },
            state,
        ))
    }

    fn finish_row((mut row, state): (SceneRow, String)) -> Result<SceneRow> {
        row.state = parse_state(&state)?;
        Ok(row)
    }

    /// A scene's row.
    pub(crate) fn scene(&self, id: &str) -> Result<Option<SceneRow>> {
        let c = self.conn();
        let r = c
            .query_row(
                &format!("SELECT {SCENE_COLUMNS} FROM scenes WHERE id = ?1"),
                [id],
                Sqlite::row,
            )
            .optional()?;
        r.map(Sqlite::finish_row).transpose()
    }

    /// Scenes still to bake, those already baking first, then in submission order.
    pub(crate) fn unfinished_scenes(&self) -> Result<Vec<SceneRow>> {
        let c = self.conn();
        let mut st = c.prepare(&format!(
            "SELECT {SCENE_COLUMNS} FROM scenes WHERE state IN ('queued', 'baking')
             ORDER BY state = 'queued',
                 (SELECT MAX(c.baked_ms) FROM chunks c WHERE c.scene_id = scenes.id),
                 seq"
        ))?;
        let rows = st
            .query_map([], Sqlite::row)?
            .collect::<rusqlite::Result<Vec<_>>>()?;
        rows.into_iter().map(Sqlite::finish_row).collect()
    }

    /// Scenes recorded `done` with fewer chunk rows than they have chunks: (id, recorded,
    /// total). Never true after a clean run; a damaged chunk table can leave it.
    pub(crate) fn done_scenes_missing_chunks(&self) -> Result<Vec<(String, u32, u32)>> {
        let c = self.conn();
        let mut st = c.prepare(
            "SELECT s.id, (SELECT COUNT(*) FROM chunks c WHERE c.scene_id = s.id), s.chunk_count
             FROM scenes s WHERE s.state = 'done'",
        )?;
        let rows = st
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))?
            .collect::<rusqlite::Result<Vec<(String, u32, u32)>>>()?;
        Ok(rows.into_iter().filter(|(_, n, total)| n < total).collect())
    }

    /// Ids of every scene that still owns files (not cancelled).
    pub(crate) fn scene_ids_with_data(&self) -> Result<std::collections::HashSet<String>> {
        let c = self.conn();
        let mut st = c.prepare("SELECT id FROM scenes WHERE state != 'cancelled'")?;
        let ids = st
            .query_map([], |r| r.get(0))?
            .collect::<rusqlite::Result<_>>()?;
        Ok(ids)
    }

    /// The durable chunks of a scene, by index.
    pub(crate) fn chunks(&self, id: &str) -> Result<Vec<(u32, ChunkMeta)>> {
        let c = self.conn();
        let mut st =
            c.prepare("SELECT idx, bytes, crc32 FROM chunks WHERE scene_id = ?1 ORDER BY idx")?;
        let rows = st
            .query_map([id], |r| {
                Ok((
                    r.get::<_, u32>(0)?,
                    ChunkMeta {
                        bytes: r.get(1)?,
                        crc32: r.get(2)?,
                    },
                ))
            })?
            .collect::<rusqlite::Result<_>>()?;
        Ok(rows)
    }

    /// Records a durable chunk, if its scene is still queued or baking; returns whether it was
    /// recorded.
    pub(crate) fn insert_chunk(&self, id: &str, idx: u32, m: ChunkMeta) -> Result<bool> {
        let mut c = self.conn();
        let tx = c.transaction()?;
        let n = tx.execute(
            "INSERT OR REPLACE INTO chunks(scene_id, idx, bytes, crc32, generation, baked_ms)
             SELECT ?1, ?2, ?3, ?4, ?5, ?6 FROM scenes
             WHERE id = ?1 AND state IN ('queued', 'baking')",
            params![id, idx, m.bytes, m.crc32, self.generation, now_ms()],
        )?;
        if n == 1 {
            tx.execute(
                "UPDATE scenes SET chunks_baked = chunks_baked + 1 WHERE id = ?1",
                [id],
            )?;
        }
        tx.commit()?;
        Ok(n == 1)
    }

    /// Forgets a chunk (its file is missing or corrupt) so that it is baked again; a finished
    /// scene goes back to `baking`. Returns false when the row was already gone or differed.
    pub(crate) fn drop_chunk(
        &self,
        id: &str,
        idx: u32,
        seen: ChunkMeta,
        corrupt: bool,
    ) -> Result<bool> {
        let mut c = self.conn();
        let tx = c.transaction()?;
        let n = tx.execute(
            "DELETE FROM chunks WHERE scene_id = ?1 AND idx = ?2 AND bytes = ?3 AND crc32 = ?4",
            params![id, idx, seen.bytes, seen.crc32],
        )?;
        if n == 1 {
            tx.execute(
                "UPDATE scenes SET chunks_corrupt = chunks_corrupt + ?2,
                     state = CASE WHEN state = 'done' THEN 'baking' ELSE state END,
                     finished_ms = CASE WHEN state = 'done' THEN NULL ELSE finished_ms END
                 WHERE id = ?1",
                params![id, corrupt as i64],
            )?;
        }
        tx.commit()?;
        Ok(n == 1)
    }

    /// Moves a scene to `state` (with a reason for `failed`); stamps start and finish times.
    pub(crate) fn set_state(&self, id: &str, state: JobState, reason: Option<&str>) -> Result<()> {
        let now = now_ms();
        self.conn().execute(
            "UPDATE scenes SET state = ?2, reason = ?3,
                 started_ms = CASE WHEN ?2 = 'baking' THEN COALESCE(started_ms, ?4) ELSE started_ms END,
                 finished_ms = CASE WHEN ?2 IN ('done', 'failed', 'cancelled') THEN ?4 ELSE NULL END
             WHERE id = ?1",
            params![id, state.as_str(), reason, now],
        )?;
        Ok(())
    }

    /// Cancels a scene: drops its chunk rows and keeps a `cancelled` tombstone. Returns the
    /// state it had, or `None` for an unknown id.
    pub(crate) fn cancel(&self, id: &str) -> Result<Option<JobState>> {
        let mut c = self.conn();
        let tx = c.transaction()?;
        let before: Option<String> = tx
            .query_row("SELECT state FROM scenes WHERE id = ?1", [id], |r| r.get(0))
            .optional()?;
        let Some(before) = before else {
            return Ok(None);
        };
        tx.execute("DELETE FROM chunks WHERE scene_id = ?1", [id])?;
        tx.execute(
            "UPDATE scenes SET state = 'cancelled', reason = 'deleted by a client',
                 finished_ms = COALESCE(finished_ms, ?2) WHERE id = ?1",
            params![id, now_ms()],
        )?;
        tx.commit()?;
        Ok(Some(parse_state(&before)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(id: &str) -> SceneRow {
        SceneRow {
            id: id.into(),
            seq: 0,
            state: JobState::Queued,
            reason: None,
            created_ms: now_ms(),
            started_ms: None,
            finished_ms: None,
            vertex_count: 100,
            triangle_count: 150,
            chunk_count: 4,
            chunk_vertices: 32,
            settings_json: "{}".into(),
            mesh_hash: u64::MAX - 3,
            header: vec![1, 2, 3],
            upload_bytes: 10,
            source: "test".into(),
            warnings: Vec::new(),
            chunks_baked: 0,
            chunks_corrupt: 0,
        }
    }

    /// Scenes resume least recently advanced first (one with no chunk yet before all), so that
    /// repeated restarts do not always favour the same scenes.
    #[test]
    fn unfinished_scenes_resume_least_recently_advanced_first() {
        let dir = tempfile::tempdir().expect("temp dir");
        let db = Db::open(&dir.path().join("db.sqlite")).expect("open");
        let m = ChunkMeta { bytes: 1, crc32: 0 };
        for id in ["a", "b", "c", "q"] {
            db.insert_scene(&row(id)).expect("insert");
        }
        for id in ["a", "b", "c"] {
            db.set_state(id, JobState::Baking, None).expect("baking");
        }
        assert!(db.insert_chunk("a", 0, m).expect("chunk"));
        std::thread::sleep(std::time::Duration::from_millis(5));
        assert!(db.insert_chunk("c", 0, m).expect("chunk"));
        std::thread::sleep(std::time::Duration::from_millis(5));
        assert!(db.insert_chunk("a", 1, m).expect("chunk"));
        let order: Vec<String> = db
            .unfinished_scenes()
            .expect("query")
            .into_iter()
            .map(|r| r.id)
            .collect();
        assert_eq!(order, ["b", "c", "a", "q"]);
    }

    #[test]
    fn chunks_only_for_live_scenes_and_generations_grow() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("db.sqlite");
        let db = Db::open(&path).expect("open");
        assert_eq!(db.generation(), 1);
        db.insert_scene(&row("a")).expect("insert");
        let m = ChunkMeta {
            bytes: 10,
            crc32: u32::MAX,
        };
        assert!(db.insert_chunk("a", 0, m).expect("chunk"));
        assert!(
            !db.insert_chunk("nope", 0, m)
                .expect("chunk of unknown scene")
        );
        let r = db.scene("a").expect("query").expect("row");
        assert_eq!(r.mesh_hash, u64::MAX - 3);
        assert_eq!(r.chunks_baked, 1);
        assert_eq!(db.chunks("a").expect("chunks"), vec![(0, m)]);
        db.set_state("a", JobState::Done, None).expect("done");
        assert!(db.drop_chunk("a", 0, m, true).expect("drop"));
        let r = db.scene("a").expect("query").expect("row");
        assert_eq!((r.state, r.chunks_corrupt), (JobState::Baking, 1));
        assert_eq!(db.cancel("a").expect("cancel"), Some(JobState::Baking));
        assert!(!db.insert_chunk("a", 1, m).expect("chunk after cancel"));
        assert_eq!(db.cancel("zzz").expect("cancel unknown"), None);
        drop(db);
        assert_eq!(Db::open(&path).expect("reopen").generation(), 2);
    }

    /// Pages newest first with the last id as cursor; a state filter; an unknown cursor is
    /// `None`. Idempotency keys come back with their scene and expire.
    #[test]
    fn listing_pages_and_idempotency_keys_expire() {
        let dir = tempfile::tempdir().expect("temp dir");
        let db = Db::open(&dir.path().join("db.sqlite")).expect("open");
        for id in ["a", "b", "c", "d", "e"] {
            db.insert_scene(&row(id)).expect("insert");
        }
        db.set_state("b", JobState::Done, None).expect("done");
        let ids = |v: Vec<SceneSummary>| v.into_iter().map(|s| s.id).collect::<Vec<_>>();
        let p1 = db.list_scenes(None, None, 2).expect("list").expect("page");
        assert_eq!(ids(p1), ["e", "d"]);
        let p2 = db
            .list_scenes(Some("d"), None, 2)
            .expect("list")
            .expect("page");
        assert_eq!(ids(p2), ["c", "b"]);
        let p3 = db
            .list_scenes(Some("b"), None, 2)
            .expect("list")
            .expect("page");
        assert_eq!(ids(p3), ["a"]);
        let done = db
            .list_scenes(None, Some(&[JobState::Done]), 10)
            .expect("list")
            .expect("page");
        assert_eq!(ids(done.clone()), ["b"]);
        assert_eq!(done[0].state, JobState::Done);
        assert!(db.list_scenes(Some("zz"), None, 2).expect("list").is_none());

        let mut r = row("k");
        r.created_ms = 1_000;
        db.insert_scene_with_key(&r, Some(("key-1", "fp")))
            .expect("insert");
        let rec = db
            .idempotent("key-1", 500)
            .expect("query")
            .expect("recorded");
        assert_eq!(
            (rec.scene_id.as_str(), rec.fingerprint.as_str()),
            ("k", "fp")
        );
        assert_eq!(
            db.idempotent("key-1", 1_001).expect("query"),
            None,
            "not expired"
        );
        assert_eq!(
            db.idempotent("key-1", 0).expect("query"),
            None,
            "not deleted"
        );
    }
}
