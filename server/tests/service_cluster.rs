//! The distributed shape on real engines (PostgreSQL, an S3-compatible server; both started
//! on loopback by the test, skipped with a message where they are not installed):
//!
//! - one API instance (`serve --workers 0`) and three `worker` processes bake a real mesh
//!   byte-identical to the offline bake; a worker SIGKILLed mid-bake costs at most the chunks
//!   it held leased (counted from the database); the API instance SIGKILLed and another
//!   started on another port reports the progress and streams the trees;
//! - a stale worker (stopped while it held a lease, which expired and was taken over) cannot
//!   record or count its chunk again (fenced); PostgreSQL restarted mid-bake: workers and API
//!   reconnect, every chunk is recorded exactly once, the result is the offline bake's;
//! - the S3 server throttling for 10 s mid-bake (its connections cut, every request answered
//!   `503 SlowDown` by a proxy in front of it): the object-store clients retry with backoff and
//!   jitter, the bake finishes by itself as the offline bake, and the logs say what happened;
//! - a worker in its own network namespace cut off (packets dropped) while it holds a lease,
//!   then let back: not live on `/healthz` meanwhile, its chunk baked by another worker, its
//!   late work refused, and its connections heal without a restart;
//! - a worker whose own disk (folder, temporaries, log) is full bakes on.

#![allow(clippy::unwrap_used)]

#[path = "common/cluster.rs"]
mod cluster;
mod common;
#[path = "common/tmpfs.rs"]
mod tmpfs;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use cluster::*;
use common::*;

/// A scene file naming a real mesh (the Stanford bunny at its coarsest, 453 vertices, if the
/// shared assets are there; else the built-in plate), and the upload that sends it. At 256²
/// faces and 8 vertices per chunk the bunny is 57 chunks of about 0.2 s each on one thread:
/// slow enough to kill things mid-bake, quick enough for CI.
fn scene(dir: &Path, face_res: u32, chunk_vertices: u32) -> (String, Option<(String, Vec<u8>)>) {
    let bunny =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/assets/meshes/bunny_res4.ply");
    match std::fs::read(&bunny) {
        Ok(bytes) => {
            std::fs::write(dir.join("bunny_res4.ply"), &bytes).unwrap();
            let json = format!(
                r#"{{"meshes": [{{"path": "bunny_res4.ply"}}],
  "bake": {{"face_res": {face_res}, "chunk_vertices": {chunk_vertices}}}}}"#
            );
            (json, Some(("bunny_res4.ply".into(), bytes)))
        }
        Err(_) => {
            // As slow to bake as the bunny at 256² faces (service_restart's settings).
            eprintln!("shared assets absent: baking the built-in plate-small instead of the bunny");
            (plate_small_json(48, 32), None)
        }
    }
}

fn submit_scene(
    a: &ureq::Agent,
    srv: &Server,
    json: &str,
    mesh: &Option<(String, Vec<u8>)>,
) -> String {
    let mut parts: Vec<Part> = vec![("scene", None, json.as_bytes())];
    if let Some((name, bytes)) = mesh {
        parts.push(("mesh", Some(name.as_str()), bytes));
    }
    submit_ok(a, srv, &parts, None)
}

fn api(dir: &Path, name: &str, pg: &Postgres, s3: &S3, prefix: &str, extra: &[&str]) -> Server {
    let env = s3.env();
    let env: Vec<(&str, &str)> = env.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    let store = s3.url(prefix);
    let mut args = vec!["--database", &pg.url, "--store", &store];
    args.extend_from_slice(extra);
    Server::start_env(BIN, &dir.join(name), "127.0.0.1:0", &args, &env)
}

fn status(a: &ureq::Agent, srv: &Server, id: &str) -> serde_json::Value {
    get(a, &srv.url(&format!("/v1/scenes/{id}"))).json()
}

/// A bake of [`scene`] at 256² faces submitted to a new API instance (no workers of its own,
/// leases of `lease_s`) on `pg` and `s3` under `prefix`: the agent, the API, the scene's id,
/// its chunk count and the offline bake's bytes.
fn submit_bake(
    dir: &Path,
    pg: &Postgres,
    s3: &S3,
    prefix: &str,
    lease_s: &str,
) -> (ureq::Agent, Server, String, i64, Vec<u8>) {
    let (json, mesh) = scene(dir, 256, 8);
    let offline = offline_bake(dir, &json, "offline");
    let a = agent();
    let srv = api(
        dir,
        "api",
        pg,
        s3,
        prefix,
        &["--workers", "0", "--lease-s", lease_s],
    );
    let id = submit_scene(&a, &srv, &json, &mesh);
    let total = status(&a, &srv, &id)["chunks_total"].as_i64().unwrap();
    (a, srv, id, total, offline)
}

/// The scene ends `done` by itself, every chunk recorded once, its trees the offline bake's.
fn ends_like_offline(
    a: &ureq::Agent,
    srv: &Server,
    pg: &Postgres,
    id: &str,
    total: i64,
    offline: &[u8],
) {
    let s = wait_done(a, srv, id);
    assert_eq!(s["chunks_baked_total"].as_i64(), Some(total), "{s}");
    assert_eq!(
        pg.number(&format!(
            "SELECT count(*) FROM chunks WHERE scene_id = '{id}'"
        )),
        total
    );
    let served = get(a, &srv.url(&format!("/v1/scenes/{id}/trees"))).body;
    assert!(served == offline, "the trees differ from the offline bake");
}

fn tmp() -> (tempfile::TempDir, PathBuf) {
    let t = tempfile::tempdir().expect("temp dir");
    let p = t.path().to_path_buf();
    (t, p)
}

#[test]
fn three_workers_bake_like_offline_and_survive_a_killed_worker_and_api() {
    let (_t, dir) = tmp();
    let Some((pg, s3)) = engines(&dir, "three_workers_bake_like_offline…") else {
        return;
    };
    let (json, mesh) = scene(&dir, 256, 8);
    let offline = offline_bake(&dir, &json, "offline");
    let a = agent();
    let mut api1 = api(
        &dir,
        "api1",
        &pg,
        &s3,
        "t1",
        &["--workers", "0", "--lease-s", "4"],
    );
    let id = submit_scene(&a, &api1, &json, &mesh);
    let total = status(&a, &api1, &id)["chunks_total"].as_u64().unwrap();
    let w = ["--threads", "1", "--chunks", "1", "--lease-s", "4"];
    let mut w1 = Worker::start(&dir, "w1", &pg, &s3, "t1", &w);
    let _w2 = Worker::start(&dir, "w2", &pg, &s3, "t1", &w);
    let _w3 = Worker::start(&dir, "w3", &pg, &s3, "t1", &w);

    // The workers are listed with their heartbeats (status JSON and metrics).
    let t0 = Instant::now();
    loop {
        let h = get(&a, &api1.url("/healthz")).json();
        if h["workers"].as_array().is_some_and(|w| w.len() == 3) {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "workers not listed: {h}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    wait_status(&a, &api1, &id, Duration::from_secs(120), |s| {
        s["chunks_done"].as_u64() >= Some(total / 4)
    });
    // SIGKILL w1; what it held leased (unfinished) is what may be baked twice.
    w1.kill();
    let held = pg.number(&format!(
        "SELECT count(*) FROM tasks WHERE scene_id = '{id}' AND worker = 'w1'"
    ));
    let done_at_kill = pg.number(&format!(
        "SELECT count(*) FROM chunks WHERE scene_id = '{id}'"
    ));
    eprintln!("w1 killed holding {held} lease(s); {done_at_kill}/{total} chunks durable");
    assert!(
        (done_at_kill as u64) < total,
        "the bake finished before the kill"
    );
    let m = get(&a, &api1.url("/metrics")).text();
    assert!(
        m.contains("bspvt_worker_chunks_done_total{worker=\"w2\"}"),
        "{m}"
    );

    // SIGKILL the API instance too, and take over from another one on another port.
    wait_status(&a, &api1, &id, Duration::from_secs(120), |s| {
        s["chunks_done"].as_u64() >= Some(done_at_kill as u64 + 2)
    });
    let port1 = api1.addr.clone();
    api1.kill();
    let api2 = api(
        &dir,
        "api2",
        &pg,
        &s3,
        "t1",
        &["--workers", "0", "--lease-s", "4"],
    );
    assert_ne!(api2.addr, port1);
    let s = status(&a, &api2, &id);
    assert!(s["chunks_done"].as_u64() > Some(done_at_kill as u64), "{s}");
    // It streams the trees while the bake runs (the stream waits for the missing chunks).
    let served = get(&a, &api2.url(&format!("/v1/scenes/{id}/trees"))).body;
    let s = wait_done(&a, &api2, &id);
    assert!(
        served == offline,
        "the streamed trees differ from the offline bake"
    );
    let again = get(&a, &api2.url(&format!("/v1/scenes/{id}/trees"))).body;
    assert!(
        again == offline,
        "the finished trees differ from the offline bake"
    );

    // Counted: every chunk recorded once; leased more than once only for w1's leases.
    assert_eq!(s["chunks_baked_total"].as_u64(), Some(total), "{s}");
    let leased = pg.number(&format!(
        "SELECT sum(leases)::bigint FROM chunks WHERE scene_id = '{id}'"
    ));
    let twice = leased - total as i64;
    eprintln!("chunks leased {leased} for {total} chunks: {twice} baked twice (w1 held {held})");
    assert!(
        twice <= held,
        "{twice} chunks baked twice, w1 held only {held}"
    );
    // The killed worker stops being live once its last heartbeat is older than the lease time
    // (4 s); the bake may end sooner than that after the kill, so wait for it (bounded).
    let t0 = Instant::now();
    loop {
        let h = get(&a, &api2.url("/healthz")).json();
        let live: Vec<String> = h["workers"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|w| w["live"] == true)
            .map(|w| w["id"].as_str().unwrap().to_string())
            .collect();
        if !live.iter().any(|w| w == "w1") {
            assert_eq!(live.len(), 2, "{h}");
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "w1 still listed live 20 s after the bake ended: {h}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

#[test]
fn stale_worker_is_fenced_and_a_postgres_restart_loses_nothing() {
    let (_t, dir) = tmp();
    let Some((pg, s3)) = engines(&dir, "stale_worker_is_fenced…") else {
        return;
    };
    let (a, srv, id, total, offline) = submit_bake(&dir, &pg, &s3, "t2", "2");
    // No worker: the scene says why it does not advance.
    let s = wait_status(&a, &srv, &id, Duration::from_secs(30), |s| {
        s["reason"]
            .as_str()
            .is_some_and(|r| r.contains("no live bake worker"))
    });
    eprintln!("without workers: {}", s["reason"]);

    let w = ["--threads", "1", "--chunks", "1", "--lease-s", "2"];
    let wa = Worker::start(&dir, "stale", &pg, &s3, "t2", &w);
    // Freeze it while it holds a lease.
    let held_chunk = loop {
        wa.signal("STOP");
        let held = pg.sql(&format!(
            "SELECT idx FROM tasks WHERE scene_id = '{id}' AND worker = 'stale' LIMIT 1"
        ));
        if !held.is_empty() {
            break held.parse::<i64>().unwrap();
        }
        wa.signal("CONT");
        std::thread::sleep(Duration::from_millis(30));
    };
    let wb = Worker::start(&dir, "fresh", &pg, &s3, "t2", &w);
    // The frozen worker's lease expires and its chunk is baked and recorded by the other.
    let t0 = Instant::now();
    while pg.number(&format!(
        "SELECT count(*) FROM chunks WHERE scene_id = '{id}' AND idx = {held_chunk}"
    )) == 0
    {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "chunk {held_chunk} never taken over"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let recorded_by = pg.sql(&format!(
        "SELECT worker FROM chunks WHERE scene_id = '{id}' AND idx = {held_chunk}"
    ));
    assert_eq!(recorded_by, "fresh");
    let done_now = pg.number(&format!(
        "SELECT count(*) FROM chunks WHERE scene_id = '{id}'"
    ));
    assert!(
        done_now < total,
        "the bake finished before the stale worker came back"
    );
    // Back: it finishes its chunk and tries to record it; the database refuses (fenced).
    wa.signal("CONT");
    let t0 = Instant::now();
    while pg.number("SELECT chunks_fenced FROM workers WHERE id = 'stale'") == 0 {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the stale worker was not fenced; its log:\n{}",
            wa.log_text()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(
        recorded_by,
        pg.sql(&format!(
            "SELECT worker FROM chunks WHERE scene_id = '{id}' AND idx = {held_chunk}"
        )),
        "the stale worker overwrote the record"
    );

    // PostgreSQL restarted mid-bake (as after a crash): everyone reconnects.
    let before = pg.number(&format!(
        "SELECT count(*) FROM chunks WHERE scene_id = '{id}'"
    ));
    if before < total {
        pg.restart();
        eprintln!("PostgreSQL restarted with {before}/{total} chunks recorded");
    }
    ends_like_offline(&a, &srv, &pg, &id, total, &offline);
    let m = get(&a, &srv.url("/metrics")).text();
    assert!(
        metric(&m, "bspvt_cluster_chunks_fenced_total") >= 1.0,
        "{m}"
    );
    drop(wb);
    drop(wa);
}

/// A worker in its own network namespace, cut off (every packet dropped) while it holds a
/// lease, and let back after its lease was taken over: a zombie with a stale fencing token.
/// Meanwhile `/healthz` stops listing it live and another worker bakes its chunk; back, its
/// connections heal by themselves, its late record is refused (fenced, counted in
/// `/metrics`), and the bake ends as the offline bake. Needs root, iproute2 and iptables.
#[test]
fn a_worker_cut_off_from_the_network_loses_its_lease_and_heals() {
    let (_t, dir) = tmp();
    let ns = match Netns::create() {
        Ok(ns) => ns,
        Err(e) => {
            eprintln!("SKIPPED a_worker_cut_off…: no network namespace ({e})");
            return;
        }
    };
    let Some((pg, s3)) = engines(&dir, "a_worker_cut_off…") else {
        return;
    };
    let (a, srv, id, total, offline) = submit_bake(&dir, &pg, &s3, "t6", "3");
    let w = ["--threads", "1", "--chunks", "1", "--lease-s", "3"];
    let (pg_port, s3_port) = (ns.forward(pg.port), ns.forward(s3.port));
    let mut zombie = Worker::start_in(
        &ns,
        &dir,
        "zombie",
        (&pg, pg_port),
        (&s3, s3_port),
        "t6",
        &w,
    );
    let live = |who: &str| {
        let h = get(&a, &srv.url("/healthz")).json();
        h["workers"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w["id"] == who && w["live"] == true)
    };
    let t0 = Instant::now();
    while !live("zombie") {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "the worker in the namespace never listed live; its log:\n{}",
            zombie.log_text()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // Cut while it holds a lease.
    let held = |who: &str| {
        pg.sql(&format!(
            "SELECT idx FROM tasks WHERE scene_id = '{id}' AND worker = '{who}' LIMIT 1"
        ))
    };
    let t0 = Instant::now();
    let held_chunk = loop {
        ns.cut(true);
        if let Ok(i) = held("zombie").parse::<i64>() {
            break i;
        }
        ns.cut(false);
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the worker in the namespace never leased a chunk; its log:\n{}",
            zombie.log_text()
        );
        std::thread::sleep(Duration::from_millis(30));
    };
    let cut_at = Instant::now();
    let fresh = Worker::start(&dir, "fresh", &pg, &s3, "t6", &w);
    // While it is away: not live on /healthz, and its chunk baked and recorded by the other.
    let mut seen_not_live = None;
    while pg.number(&format!(
        "SELECT count(*) FROM chunks WHERE scene_id = '{id}' AND idx = {held_chunk}"
    )) == 0
        || seen_not_live.is_none()
    {
        if seen_not_live.is_none() && !live("zombie") {
            seen_not_live = Some(cut_at.elapsed());
        }
        assert!(
            cut_at.elapsed() < Duration::from_secs(90),
            "chunk {held_chunk} never taken over, or the cut-off worker still listed live"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let recorded_by = pg.sql(&format!(
        "SELECT worker FROM chunks WHERE scene_id = '{id}' AND idx = {held_chunk}"
    ));
    assert_eq!(recorded_by, "fresh");
    // Away for 15 s at least: past its lease, its heartbeats and its connections' timeouts.
    std::thread::sleep(Duration::from_secs(15).saturating_sub(cut_at.elapsed()));
    let away = cut_at.elapsed();
    let said_away = zombie.log_text();
    ns.cut(false);
    // Back: its late work is refused (fenced) or dropped (it learns its lease was lost).
    let back_at = Instant::now();
    let gave_up = || {
        pg.number("SELECT coalesce(max(chunks_fenced), 0) FROM workers WHERE id = 'zombie'") > 0
            || zombie.log_text().contains("lease lost")
    };
    while !gave_up() {
        assert!(
            back_at.elapsed() < Duration::from_secs(60),
            "the cut-off worker neither was fenced nor dropped its lease; its log:\n{}",
            zombie.log_text()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let learnt_after = back_at.elapsed();
    let fenced =
        pg.number("SELECT coalesce(max(chunks_fenced), 0) FROM workers WHERE id = 'zombie'");
    assert_eq!(
        recorded_by,
        pg.sql(&format!(
            "SELECT worker FROM chunks WHERE scene_id = '{id}' AND idx = {held_chunk}"
        )),
        "the cut-off worker overwrote the record"
    );
    ends_like_offline(&a, &srv, &pg, &id, total, &offline);
    if fenced > 0 {
        let m = get(&a, &srv.url("/metrics")).text();
        assert!(
            metric(&m, "bspvt_cluster_chunks_fenced_total") >= 1.0,
            "{m}"
        );
    }
    // While away it said so (the database did not answer), not nothing.
    assert!(
        said_away.contains("database unavailable"),
        "the cut-off worker's log does not say the database was unreachable:\n{said_away}"
    );
    // Its connections healed by themselves: alone, it bakes a second scene to the end.
    drop(fresh);
    let (json2, mesh2) = scene(&dir, 128, 8);
    let offline2 = offline_bake(&dir, &json2, "offline2");
    let id2 = submit_scene(&a, &srv, &json2, &mesh2);
    let t_second = Instant::now();
    let s2 = wait_done(&a, &srv, &id2);
    let by_zombie = pg.number(&format!(
        "SELECT count(*) FROM chunks WHERE scene_id = '{id2}' AND worker = 'zombie'"
    ));
    assert_eq!(Some(by_zombie), s2["chunks_total"].as_i64(), "{s2}");
    let served2 = get(&a, &srv.url(&format!("/v1/scenes/{id2}/trees"))).body;
    assert!(
        served2 == offline2,
        "the second scene's trees differ from the offline bake"
    );
    eprintln!(
        "cut off for {:.1} s holding chunk {held_chunk} (not live on /healthz after {:.1} s; \
         the chunk recorded by the other worker); back: {} {:.1} s later; a second scene of \
         {by_zombie} chunks baked by it alone in {:.1} s. What it logged while away:\n{}",
        away.as_secs_f64(),
        seen_not_live.unwrap_or_default().as_secs_f64(),
        if fenced > 0 {
            "fenced"
        } else {
            "dropped its lost lease"
        },
        learnt_after.as_secs_f64(),
        t_second.elapsed().as_secs_f64(),
        said_away
            .lines()
            .filter(|l| l.contains("WARN") || l.contains("ERROR"))
            .take(6)
            .collect::<Vec<_>>()
            .join("\n"),
    );
    zombie.kill();
}

/// A worker whose own disk is full: its working folder, its temporaries (`TMPDIR`) and its
/// log on a full tmpfs. A worker keeps nothing on local disk (chunks go to the object store,
/// state to PostgreSQL), so it bakes on; a log line that cannot be written is dropped, not a
/// crash. Needs root (or passwordless sudo) to mount.
#[test]
fn a_worker_on_a_full_disk_bakes_on() {
    let (_t, dir) = tmp();
    let disk = dir.join("disk");
    let Some(_fs) = tmpfs::Tmpfs::mount(&disk, "1m") else {
        eprintln!("SKIPPED a_worker_on_a_full_disk…: cannot mount a tmpfs (needs root or sudo)");
        return;
    };
    let Some((pg, s3)) = engines(&dir, "a_worker_on_a_full_disk…") else {
        return;
    };
    let (a, srv, id, total, offline) = submit_bake(&dir, &pg, &s3, "t7", "4");
    let filled = tmpfs::fill(&disk.join("ballast"));
    let w = ["--threads", "1", "--chunks", "1", "--lease-s", "4"];
    let mut worker = Worker::start(&disk, "full", &pg, &s3, "t7", &w);
    ends_like_offline(&a, &srv, &pg, &id, total, &offline);
    assert_eq!(
        pg.number(&format!(
            "SELECT count(*) FROM chunks WHERE scene_id = '{id}' AND worker = 'full'"
        )),
        total,
        "every chunk baked by the worker on the full disk"
    );
    assert!(
        matches!(worker.child.try_wait(), Ok(None)),
        "the worker on the full disk exited"
    );
    let logged = std::fs::metadata(disk.join("full.log")).map_or(0, |m| m.len());
    eprintln!(
        "a worker with its folder, TMPDIR and log on a full 1 MiB tmpfs ({filled} bytes of \
         ballast) baked {total} chunks, the offline bake's bytes; its log kept {logged} bytes"
    );
    worker.kill();
}

/// S3 throttling and cut connections for 10 s mid-bake (a [`FaultyProxy`] in front of the S3
/// server: `503 SlowDown` for 5 s, then `500 InternalError`). The object-store clients of the workers and the API retry with exponential backoff
/// and decorrelated jitter (`object_store`'s `RetryConfig`: at most 10 retries within 3 min, the
/// bound), so no chunk fails, no process is restarted by hand, and the bake ends `done`,
/// byte-identical to the offline bake; the logs name the 503s and 500s as they happen.
#[test]
fn s3_throttling_and_cut_connections_for_10_s_lose_nothing() {
    let (_t, dir) = tmp();
    let Some((pg, mut s3)) = engines(&dir, "s3_throttling_and_cut_connections…") else {
        return;
    };
    let proxy = FaultyProxy::start(s3.port);
    s3.endpoint = proxy.port;
    let (a, srv, id, total, offline) = submit_bake(&dir, &pg, &s3, "t5", "4");
    let w = ["--threads", "1", "--chunks", "1", "--lease-s", "4"];
    let w1 = Worker::start(&dir, "s1", &pg, &s3, "t5", &w);
    let w2 = Worker::start(&dir, "s2", &pg, &s3, "t5", &w);
    wait_status(&a, &srv, &id, Duration::from_secs(120), |s| {
        s["chunks_done"].as_i64() >= Some(total / 4)
    });
    let chunks = || {
        pg.number(&format!(
            "SELECT count(*) FROM chunks WHERE scene_id = '{id}'"
        ))
    };
    let before = chunks();
    proxy.fail(true);
    let t0 = Instant::now();
    let (mut said, mut said_500, mut health) = (false, false, None);
    while t0.elapsed() < Duration::from_secs(10) {
        // 503 SlowDown for 5 s, then 500 InternalError.
        if t0.elapsed() >= Duration::from_secs(5) {
            proxy.internal_errors();
        }
        let logs = w1.log_text() + &w2.log_text() + &srv.log_text();
        said |= logs.contains("status 503");
        said_500 |= logs.contains("status 500");
        if health.is_none() {
            let h = get(&a, &srv.url("/healthz"));
            let j = h.json();
            if j["status"] == "degraded" {
                assert_eq!(
                    h.status, 200,
                    "a degraded store is no reason to restart the API"
                );
                health = Some(j["store"].to_string());
            }
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    let during = chunks() - before;
    proxy.fail(false);
    let answered_500 = proxy.internal_answered();
    eprintln!(
        "S3 failing for 10 s: {} connections answered 503 then {answered_500} answered 500, \
         {during} chunks recorded meanwhile ({before}/{total} before); the logs named the 503s \
         during the fault: {said}, the 500s: {said_500}",
        proxy.refused() - answered_500
    );
    assert!(proxy.refused() > 0, "no request met the fault");
    assert!(
        answered_500 == 0 || said_500 || {
            std::thread::sleep(Duration::from_secs(1));
            (w1.log_text() + &w2.log_text() + &srv.log_text()).contains("status 500")
        },
        "{answered_500} requests answered 500 and no log says so"
    );
    let health = health.expect("/healthz never said the store was failing");
    eprintln!("/healthz during the fault: store {health}");
    assert!(
        health.contains("503") || health.contains("500"),
        "{health}; the API's log: {}",
        srv.log_text()
            .lines()
            .filter(|l| l.contains("probe"))
            .take(3)
            .collect::<Vec<_>>()
            .join("\n")
    );
    let m = get(&a, &srv.url("/metrics")).text();
    assert!(metric(&m, "bspvt_store_probe_failures_total") >= 1.0, "{m}");
    let h = get(&a, &srv.url("/healthz")).json();
    assert_eq!(h["store"], "ok", "after the fault: {h}");
    assert!(
        said,
        "the workers' logs did not say what happened while it happened:\n{}",
        w1.log_text()
    );
    ends_like_offline(&a, &srv, &pg, &id, total, &offline);
    // A store's fault is not the chunks': none counted as failed (with two workers, a chunk
    // failed on both used to be leased by neither, and the bake stalled).
    let put_back = (w1.log_text() + &w2.log_text())
        .matches("chunk put back")
        .count();
    eprintln!("chunks put back for a later try: {put_back}");
    assert_eq!(
        pg.number("SELECT coalesce(sum(chunks_failed), 0) FROM workers"),
        0
    );
}

#[test]
fn a_chunk_failing_on_three_workers_fails_its_scene_with_the_reason() {
    let (_t, dir) = tmp();
    let Some((pg, s3)) = engines(&dir, "a_chunk_failing_on_three_workers…") else {
        return;
    };
    let (json, mesh) = scene(&dir, 16, 64);
    let a = agent();
    let srv = api(&dir, "api", &pg, &s3, "t3", &["--workers", "0"]);
    let id = submit_scene(&a, &srv, &json, &mesh);
    // Workers pointed at another prefix of the bucket cannot read the stored scene.
    let w = ["--threads", "1", "--chunks", "1"];
    let _w: Vec<Worker> = (0..3)
        .map(|i| Worker::start(&dir, &format!("lost{i}"), &pg, &s3, "elsewhere", &w))
        .collect();
    let t0 = Instant::now();
    let s = loop {
        let s = status(&a, &srv, &id);
        if s["state"] == "failed" {
            break s;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "not failed: {s}");
        std::thread::sleep(Duration::from_millis(100));
    };
    let reason = s["reason"].as_str().unwrap();
    assert!(
        reason.contains("failed on 3 different workers") && reason.contains("stored scene"),
        "{reason}"
    );
    assert_eq!(
        pg.number("SELECT count(*) FROM tasks"),
        0,
        "a failed scene keeps no task"
    );
}

#[test]
fn deleting_a_scene_reaches_the_worker_baking_it() {
    let (_t, dir) = tmp();
    let Some((pg, s3)) = engines(&dir, "deleting_a_scene_reaches_the_worker…") else {
        return;
    };
    let (json, mesh) = scene(&dir, 256, 8);
    let a = agent();
    let srv = api(
        &dir,
        "api",
        &pg,
        &s3,
        "t4",
        &["--workers", "0", "--lease-s", "3"],
    );
    let id = submit_scene(&a, &srv, &json, &mesh);
    let w = Worker::start(
        &dir,
        "w",
        &pg,
        &s3,
        "t4",
        &["--threads", "1", "--chunks", "1"],
    );
    wait_status(&a, &srv, &id, Duration::from_secs(60), |s| {
        s["chunks_done"].as_u64() >= Some(3)
    });
    // Delete while it holds a lease (frozen for a moment, so that the deletion cannot fall
    // between two of its chunks).
    loop {
        w.signal("STOP");
        let held = pg.number(&format!(
            "SELECT count(*) FROM tasks WHERE scene_id = '{id}' AND worker = 'w'"
        ));
        if held > 0 {
            break;
        }
        w.signal("CONT");
        std::thread::sleep(Duration::from_millis(30));
    }
    let r = delete(&a, &srv.url(&format!("/v1/scenes/{id}")), None);
    w.signal("CONT");
    assert_eq!(r.status, 200, "{}", r.text());
    // The chunk it was baking is dropped (refused at record time, its object deleted), and
    // it takes no other chunk of the scene.
    let t0 = Instant::now();
    while !w.log_text().contains("scene deleted or failed") {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "worker not told:\n{}",
            w.log_text()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let done = pg.number("SELECT chunks_done FROM workers WHERE id = 'w'");
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(
        pg.number("SELECT chunks_done FROM workers WHERE id = 'w'"),
        done
    );
    assert_eq!(pg.number("SELECT count(*) FROM tasks"), 0);
    assert_eq!(pg.number("SELECT count(*) FROM chunks"), 0);
    assert_eq!(status(&a, &srv, &id)["state"], "cancelled");
}

/// Benchmark, not run by default:
/// `cargo test --release -p bspvt-server --test service_cluster -- --ignored --nocapture`.
/// The same scene baked by the embedded service (`--workers N --threads N`) and by one API
/// instance with N `worker` processes of one thread each, N = 1, 2, 4; the wall time is the
/// scene's own (`finished_ms - created_ms`, stamped by the processes), so it leaves out the
/// test's polling. `BSPVT_BENCH_MESH` (a .ply, default the bunny at its coarsest),
/// `BSPVT_BENCH_FACE_RES` (default 24), `BSPVT_BENCH_CHUNK` (vertices per chunk, default 32).
/// PostgreSQL runs with `fsync = on` here; the S3 server (moto) keeps objects in memory.
#[test]
#[ignore]
fn bench_distributed_against_embedded() {
    let (_t, dir) = tmp();
    let Some((mut pg, s3)) = engines(&dir, "bench_distributed_against_embedded") else {
        return;
    };
    // The test engines run with fsync off; the embedded service syncs every chunk, so the
    // comparison needs PostgreSQL's fsync back on (the S3 server keeps objects in memory).
    pg.fsync = true;
    pg.restart();
    assert_eq!(pg.sql("SHOW fsync"), "on");
    let var = |k: &str, d: u32| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let (face_res, chunk) = (
        var("BSPVT_BENCH_FACE_RES", 24),
        var("BSPVT_BENCH_CHUNK", 32),
    );
    let (json, mesh) = match std::env::var("BSPVT_BENCH_MESH") {
        Ok(p) => {
            let name = Path::new(&p)
                .file_name()
                .unwrap()
                .to_string_lossy()
                .into_owned();
            let json = format!(
                r#"{{"meshes": [{{"path": "{name}"}}],
  "bake": {{"face_res": {face_res}, "chunk_vertices": {chunk}}}}}"#
            );
            (json, Some((name, std::fs::read(&p).unwrap())))
        }
        Err(_) => scene(&dir, face_res, chunk),
    };
    let a = agent();
    let wall = |srv: &Server, id: &str| {
        let s = wait_status(&a, srv, id, Duration::from_secs(3600), |s| {
            s["state"] == "done"
        });
        let ms = s["finished_ms"].as_i64().unwrap() - s["created_ms"].as_i64().unwrap();
        (ms as f64 / 1e3, s)
    };
    println!(
        "| N | embedded: wall s, CPU s | distributed: wall s | API + workers CPU s | PostgreSQL CPU s | S3 (moto) CPU s | wall overhead | CPU overhead (API + workers + PostgreSQL) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    for n in [1usize, 2, 4] {
        let ns = n.to_string();
        let emb = start(
            &dir.join(format!("emb{n}")),
            &["--workers", &ns, "--threads", &ns],
        );
        let c0 = cpu_s(emb.child.id());
        let id = submit_scene(&a, &emb, &json, &mesh);
        let (te, s) = wall(&emb, &id);
        let ce = cpu_s(emb.child.id()) - c0;
        drop(emb);
        let prefix = format!("bench{n}");
        let (pg0, s30) = (pg.cpu_s(), cpu_s(s3.child.id()));
        let srv = api(
            &dir,
            &format!("api{n}"),
            &pg,
            &s3,
            &prefix,
            &["--workers", "0"],
        );
        let workers: Vec<Worker> = (0..n)
            .map(|i| {
                let w = ["--threads", "1", "--chunks", "1"];
                Worker::start(&dir, &format!("b{n}-{i}"), &pg, &s3, &prefix, &w)
            })
            .collect();
        let id = submit_scene(&a, &srv, &json, &mesh);
        let (td, _) = wall(&srv, &id);
        let cd = cpu_s(srv.child.id()) + workers.iter().map(|w| cpu_s(w.child.id())).sum::<f64>();
        drop(workers);
        drop(srv);
        // Their connections closed: the backends exit and are counted in the postmaster's.
        std::thread::sleep(Duration::from_secs(1));
        let (cpg, cs3) = (pg.cpu_s() - pg0, cpu_s(s3.child.id()) - s30);
        println!(
            "| {n} | {te:.2}, {ce:.2} | {td:.2} | {cd:.2} | {cpg:.2} | {cs3:.2} | {:+.1} % | {:+.1} % |   ({} vertices, {} chunks)",
            (td / te - 1.0) * 100.0,
            ((cd + cpg) / ce - 1.0) * 100.0,
            s["vertices_total"],
            s["chunks_total"]
        );
    }
}

/// Benchmark, not run by default: how long after a worker records a chunk (its row's
/// `baked_ms`) an API instance's SSE client hears of it (the event whose `chunks_done`
/// first counts it). Same machine, same clock.
/// `cargo test -p bspvt-server --test service_cluster bench_event -- --ignored --nocapture`.
#[test]
#[ignore]
fn bench_event_latency() {
    use std::io::BufRead;
    let (_t, dir) = tmp();
    let Some((pg, s3)) = engines(&dir, "bench_event_latency") else {
        return;
    };
    let (json, mesh) = scene(&dir, 256, 8);
    let a = agent();
    let srv = api(&dir, "api", &pg, &s3, "ev", &["--workers", "0"]);
    let id = submit_scene(&a, &srv, &json, &mesh);
    let url = srv.url(&format!("/v1/scenes/{id}/events"));
    let reader = std::thread::spawn(move || {
        let a = agent();
        let r = a.get(&url).call().unwrap();
        let mut seen: Vec<(u64, i64)> = Vec::new();
        let body = std::io::BufReader::new(r.into_body().into_reader());
        for line in body.lines() {
            let Ok(line) = line else { break };
            let Some(data) = line.strip_prefix("data:") else {
                continue;
            };
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_millis() as i64;
            let s: serde_json::Value = serde_json::from_str(data.trim()).unwrap();
            let done = s["chunks_done"].as_u64().unwrap();
            if seen.last().is_none_or(|&(d, _)| d < done) {
                seen.push((done, now));
            }
            if s["state"] == "done" {
                break;
            }
        }
        seen
    });
    let w = ["--threads", "1", "--chunks", "1"];
    let _w: Vec<Worker> = (0..2)
        .map(|i| Worker::start(&dir, &format!("ev{i}"), &pg, &s3, "ev", &w))
        .collect();
    let seen = reader.join().unwrap();
    let baked: Vec<i64> = pg
        .sql(&format!(
            "SELECT baked_ms FROM chunks WHERE scene_id = '{id}' ORDER BY baked_ms"
        ))
        .lines()
        .map(|l| l.parse().unwrap())
        .collect();
    let mut lat: Vec<i64> = seen
        .iter()
        .filter(|&&(d, _)| d > 0)
        .map(|&(d, t)| t - baked[d as usize - 1])
        .collect();
    lat.sort();
    let pct = |p: f64| lat[((lat.len() - 1) as f64 * p).round() as usize];
    println!(
        "SSE latency after a chunk's record, {} events for {} chunks: median {} ms, p90 {} ms, max {} ms",
        lat.len(),
        baked.len(),
        pct(0.5),
        pct(0.9),
        pct(1.0)
    );
}
