//! Crash safety: a server killed with SIGKILL in the middle of two bakes, restarted on the
//! same data directory, finishes both without baking any chunk that was durable before the
//! kill (counted from the database and from the restarted server), and the results are the
//! offline bakes byte for byte. A chunk file lost while the server was down is baked again;
//! stray files are removed.

#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use common::*;

/// (chunk index → (crc32, generation)) of a scene, read from the database of a stopped server.
fn durable_chunks(data: &Path, id: &str) -> BTreeMap<u32, (u32, i64)> {
    let db = rusqlite::Connection::open(data.join("bspvt.sqlite")).expect("open db");
    let mut st = db
        .prepare("SELECT idx, crc32, generation FROM chunks WHERE scene_id = ?1")
        .unwrap();
    st.query_map([id], |r| Ok((r.get(0)?, (r.get(1)?, r.get(2)?))))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap()
}

#[test]
fn sigkill_mid_bake_then_restart_resumes_without_recomputing() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let data = tmp.path().join("data");
    // Slow enough to kill midway: one worker, one thread, many small chunks.
    let json_a = plate_small_json(48, 32); // 81 chunks
    let json_b = plate_small_json(24, 100); // 26 chunks
    let total_a = 81;
    let total_b = 26;

    let mut srv = start(&data, &["--workers", "1", "--threads", "1"]);
    let a = agent();
    let id_a = submit_ok(&a, &srv, &[("scene", None, json_a.as_bytes())], None);
    let id_b = submit_ok(&a, &srv, &[("scene", None, json_b.as_bytes())], None);
    wait_status(&a, &srv, &id_a, Duration::from_secs(120), |s| {
        s["chunks_done"].as_u64() >= Some(12)
    });
    srv.kill();
    assert!(!srv.is_running());
    let before_a = durable_chunks(&data, &id_a);
    let before_b = durable_chunks(&data, &id_b);
    let (na, nb) = (before_a.len() as u64, before_b.len() as u64);
    eprintln!("durable before the kill: A {na}/{total_a}, B {nb}/{total_b}");
    assert!(na >= 12 && na < total_a, "A not killed midway ({na})");
    assert!(nb < total_b, "B finished before the kill");
    // One worker, two scenes: chunks alternate between them (round-robin), so B advanced
    // alongside A instead of waiting for it.
    assert!(nb >= na / 2, "B starved while A baked: A {na}, B {nb}");
    assert!(before_a.values().all(|&(_, g)| g == 1));

    // Damage the store while the server is down: a recorded chunk of B loses its file (it
    // must be baked again), stray files appear in A's directory (they must be ignored).
    let (&lost, _) = before_b.iter().next().expect("B has a durable chunk");
    let chunks_a = data.join("scenes").join(&id_a).join("chunks");
    std::fs::remove_file(data.join(format!("scenes/{id_b}/chunks/{lost}.bvck"))).unwrap();
    std::fs::write(chunks_a.join("80.bvck.tmp"), b"half-written").unwrap();
    std::fs::write(chunks_a.join("9999.bvck"), b"never recorded").unwrap();

    // Offline references while nothing else runs.
    let offline_a = offline_bake(tmp.path(), &json_a, "a");
    let offline_b = offline_bake(tmp.path(), &json_b, "b");

    let srv = start(&data, &["--workers", "2"]);
    let sa = wait_done(&a, &srv, &id_a);
    let sb = wait_done(&a, &srv, &id_b);
    assert_eq!(
        sa["chunks_baked_this_process"].as_u64(),
        Some(total_a - na),
        "{sa}"
    );
    assert_eq!(
        sb["chunks_baked_this_process"].as_u64(),
        Some(total_b - nb + 1),
        "{sb}"
    );
    assert_eq!(sb["chunks_corrupt"], 1, "{sb}");
    let text = get(&a, &srv.url("/metrics")).text();
    assert_eq!(
        metric(&text, "bspvt_chunks_baked_total") as u64,
        (total_a - na) + (total_b - nb + 1)
    );
    assert!(!chunks_a.join("80.bvck.tmp").exists() && !chunks_a.join("9999.bvck").exists());
    assert_eq!(metric(&text, "bspvt_generation"), 2.0);

    let ta = get(&a, &srv.url(&format!("/v1/scenes/{id_a}/trees")));
    let tb = get(&a, &srv.url(&format!("/v1/scenes/{id_b}/trees")));
    assert!(ta.body == offline_a, "A differs from the offline bake");
    assert!(tb.body == offline_b, "B differs from the offline bake");
    assert!(srv.log_text().contains("resuming scene"));

    // Every chunk durable before the kill is still the one baked then (generation 1).
    drop(srv);
    let after_a = durable_chunks(&data, &id_a);
    assert_eq!(after_a.len() as u64, total_a);
    for (c, v) in &before_a {
        assert_eq!(after_a.get(c), Some(v), "chunk {c} was baked again");
    }
    let regenerated = after_a.values().filter(|&&(_, g)| g == 2).count() as u64;
    assert_eq!(regenerated, total_a - na);
    let after_b = durable_chunks(&data, &id_b);
    for (c, v) in &before_b {
        if *c == lost {
            assert_eq!(after_b[c].1, 2, "lost chunk {c} not re-baked");
        } else {
            assert_eq!(after_b.get(c), Some(v), "chunk {c} of B was baked again");
        }
    }
}

/// Runs `bspvt-server serve` on `data` expecting it to refuse to start: returns its stderr.
/// Fails if it is still running after 30 s.
fn refused_start(data: &Path) -> String {
    let mut child = std::process::Command::new(BIN)
        .args(["serve", "--data-dir"])
        .arg(data)
        .args(["--addr", "127.0.0.1:0"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn bspvt-server");
    let t = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            assert!(!status.success(), "the server exited with success");
            let mut err = String::new();
            use std::io::Read as _;
            child
                .stderr
                .take()
                .expect("stderr")
                .read_to_string(&mut err)
                .expect("read stderr");
            return err;
        }
        if t.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            panic!("the server started on a data folder it should have refused");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Data safety at start: a `done` scene whose chunk rows were lost (a damaged chunk table) is
/// baked again where rows are missing, never served as `done` with chunks missing; a data
/// folder whose database is missing, or fails its integrity check, is refused with a clear
/// error and nothing in it is deleted.
#[test]
fn lost_chunk_rows_are_rebaked_and_a_missing_or_corrupt_database_is_refused() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let data = tmp.path().join("data");
    let json = plate_small_json(24, 100); // 26 chunks
    let total = 26;
    let a = agent();
    let mut srv = start(&data, &["--workers", "1"]);
    let id = submit_ok(&a, &srv, &[("scene", None, json.as_bytes())], None);
    wait_done(&a, &srv, &id);
    srv.kill();

    // Five chunk rows lost while the scene stays `done`.
    {
        let db = rusqlite::Connection::open(data.join("bspvt.sqlite")).expect("open db");
        let n = db
            .execute(
                "DELETE FROM chunks WHERE scene_id = ?1 AND idx IN (0, 3, 7, 11, 25)",
                [&id],
            )
            .expect("delete rows");
        assert_eq!(n, 5);
    }
    let offline = offline_bake(tmp.path(), &json, "lost-rows");
    let mut srv = start(&data, &["--workers", "1"]);
    let s = wait_done(&a, &srv, &id);
    assert_eq!(s["chunks_baked_this_process"].as_u64(), Some(5), "{s}");
    assert_eq!(s["chunks_done"].as_u64(), Some(total), "{s}");
    let trees = get(&a, &srv.url(&format!("/v1/scenes/{id}/trees")));
    assert!(
        trees.body == offline,
        "the trees differ from the offline bake"
    );
    assert!(srv.log_text().contains("chunks missing"));
    srv.kill();

    // The database moved away: refused, nothing deleted.
    let scene_dir = data.join("scenes").join(&id);
    let chunks_before = std::fs::read_dir(scene_dir.join("chunks")).unwrap().count();
    let moved = tmp.path().join("moved");
    std::fs::create_dir_all(&moved).unwrap();
    for f in ["bspvt.sqlite", "bspvt.sqlite-wal", "bspvt.sqlite-shm"] {
        if data.join(f).exists() {
            std::fs::rename(data.join(f), moved.join(f)).unwrap();
        }
    }
    let err = refused_start(&data);
    assert!(
        err.contains("no database") && err.contains("nothing was deleted"),
        "{err}"
    );
    assert!(
        !data.join("bspvt.sqlite").exists(),
        "a new database was created"
    );
    assert_eq!(
        std::fs::read_dir(scene_dir.join("chunks")).unwrap().count(),
        chunks_before
    );

    // A damaged database (its second half overwritten): refused, nothing deleted.
    for f in ["bspvt.sqlite", "bspvt.sqlite-wal", "bspvt.sqlite-shm"] {
        if moved.join(f).exists() {
            std::fs::rename(moved.join(f), data.join(f)).unwrap();
        }
    }
    {
        // Fold the WAL into the main file first, so the damage is not undone by it.
        let db = rusqlite::Connection::open(data.join("bspvt.sqlite")).expect("open db");
        db.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))
            .unwrap();
    }
    let mut bytes = std::fs::read(data.join("bspvt.sqlite")).unwrap();
    let page = 4096;
    assert!(bytes.len() >= 4 * page, "{} bytes", bytes.len());
    for b in &mut bytes[2 * page..] {
        *b = 0x5a;
    }
    std::fs::write(data.join("bspvt.sqlite"), &bytes).unwrap();
    let err = refused_start(&data);
    assert!(
        err.contains("refusing to start") || err.contains("malformed"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_dir(scene_dir.join("chunks")).unwrap().count(),
        chunks_before
    );
}
