//! `bspvt-server bench-cluster`: the coordination cost of the distributed shape on a real
//! PostgreSQL — what one chunk costs the database (lease, then record) and how many chunks per
//! second it hands out to many workers at once — on a trivial work item (no bake, no object
//! write), so that the coordinator's own limit shows.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use super::db::{ChunkMeta, JobState, SceneRow, now_ms};
use super::pg::PgDb;

/// `bspvt-server bench-cluster` flags.
#[derive(clap::Args, Debug, Clone)]
pub struct ClusterBenchArgs {
    /// A PostgreSQL database to use (scratch scenes are created and deleted in it).
    #[arg(long, env = "BSPVT_DATABASE", hide_env_values = true)]
    pub database: String,
    /// Chunks leased and recorded one after another by one worker (latency).
    #[arg(long, default_value_t = 1000)]
    pub serial: u32,
    /// Concurrent workers of the throughput run (each its own connection).
    #[arg(long, default_value_t = 64)]
    pub workers: usize,
    /// Chunks of the throughput run.
    #[arg(long, default_value_t = 10_000)]
    pub chunks: u32,
}

fn scratch_scene(pg: &PgDb, chunks: u32) -> Result<String> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b).map_err(|e| anyhow::anyhow!("no randomness: {e}"))?;
    let id: String = b.iter().map(|x| format!("{x:02x}")).collect();
    pg.insert_scene_with_key(
        &SceneRow {
            id: id.clone(),
            seq: 0,
            state: JobState::Queued,
            reason: None,
            created_ms: now_ms(),
            started_ms: None,
            finished_ms: None,
            vertex_count: chunks,
            triangle_count: 0,
            chunk_count: chunks,
            chunk_vertices: 1,
            settings_json: "{}".into(),
            mesh_hash: 0,
            header: Vec::new(),
            upload_bytes: 0,
            source: "bench-cluster (synthetic)".into(),
            chunks_baked: 0,
            chunks_corrupt: 0,
            warnings: Vec::new(),
        },
        None,
    )?;
    Ok(id)
}

fn pct(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// Runs the benchmark and prints its figures.
pub fn cluster_bench_command(a: &ClusterBenchArgs) -> Result<()> {
    let ttl = Duration::from_secs(30);
    let meta = ChunkMeta {
        bytes: 1000,
        crc32: 7,
    };
    let pg = PgDb::open(&a.database, ttl)?;
    pg.register_worker("bench-serial", "bench", 1)?;

    // Latency: one worker, one chunk after another.
    let id = scratch_scene(&pg, a.serial)?;
    let (mut lease_ms, mut record_ms) = (Vec::new(), Vec::new());
    let t0 = Instant::now();
    loop {
        let t = Instant::now();
        let Some(l) = pg.lease("bench-serial")? else {
            break;
        };
        lease_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        pg.complete("bench-serial", &l, meta)?;
        record_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let serial_s = t0.elapsed().as_secs_f64();
    anyhow::ensure!(!lease_ms.is_empty(), "--serial must be at least 1");
    pg.cancel(&id)?;
    for v in [&mut lease_ms, &mut record_ms] {
        v.sort_by(f64::total_cmp);
    }
    println!(
        "one worker, {} chunks: lease median {:.2} ms (p99 {:.2}), record median {:.2} ms (p99 {:.2}); {:.0} chunks/s",
        lease_ms.len(),
        pct(&lease_ms, 0.5),
        pct(&lease_ms, 0.99),
        pct(&record_ms, 0.5),
        pct(&record_ms, 0.99),
        lease_ms.len() as f64 / serial_s
    );

    // Throughput: many workers at once, each with its own connection.
    let id = scratch_scene(&pg, a.chunks)?;
    let dbs: Vec<Arc<PgDb>> = (0..a.workers)
        .map(|_| PgDb::open(&a.database, ttl).map(Arc::new))
        .collect::<Result<_>>()?;
    for (i, db) in dbs.iter().enumerate() {
        db.register_worker(&format!("bench-{i}"), "bench", 1)?;
    }
    let done = Arc::new(AtomicU64::new(0));
    let t0 = Instant::now();
    let handles: Vec<_> = dbs
        .iter()
        .enumerate()
        .map(|(i, db)| {
            let (db, done) = (db.clone(), done.clone());
            std::thread::spawn(move || -> Result<()> {
                let w = format!("bench-{i}");
                while let Some(l) = db.lease(&w)? {
                    db.complete(&w, &l, meta)?;
                    done.fetch_add(1, Ordering::Relaxed);
                }
                Ok(())
            })
        })
        .collect();
    for h in handles {
        h.join()
            .map_err(|_| anyhow::anyhow!("a bench worker panicked"))??;
    }
    let s = t0.elapsed().as_secs_f64();
    let n = done.load(Ordering::Relaxed);
    let state = pg.scene(&id)?.context("scratch scene")?;
    println!(
        "{} workers, {n} chunks: {:.2} s, {:.0} chunks/s (scene {}, {} recorded, {} leases)",
        a.workers,
        s,
        n as f64 / s,
        state.state.as_str(),
        state.chunks_baked,
        n
    );
    pg.cancel(&id)?;
    Ok(())
}
