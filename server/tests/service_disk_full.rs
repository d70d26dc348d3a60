//! A full data disk is a state, not a crash: on a size-limited filesystem (a tmpfs with
//! `size=`), a bake that runs out of space pauses with a reason and leaves no temporary
//! file; an upload gets 507 with `Retry-After`; `DELETE` of another scene works on the full
//! disk; once space is freed the bake resumes by itself and its trees are the offline bake's,
//! byte for byte. The server's log is on the same full disk (the test harness writes it
//! beside the data folder): a log line that cannot be written is dropped, not a crash.
//!
//! Mounting needs root (or passwordless sudo); where neither works the test says so and
//! skips.

#![allow(clippy::unwrap_used)]

mod common;
#[path = "common/tmpfs.rs"]
mod tmpfs;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use common::*;
use tmpfs::{Tmpfs, fill};

/// Files whose name ends in `.tmp` anywhere under `dir`.
fn temporaries(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p.clone());
            }
            if p.to_string_lossy().ends_with(".tmp") {
                out.push(p);
            }
        }
    }
    out
}

#[test]
fn a_full_disk_pauses_the_bake_and_freed_space_resumes_it_byte_identical() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let Some(fs) = Tmpfs::mount(&tmp.path().join("disk"), "24m") else {
        eprintln!("skipped: cannot mount a tmpfs here (needs root or passwordless sudo)");
        return;
    };
    let data = fs.0.join("data");
    let json_a = plate_small_json(48, 32); // 81 chunks
    let json_c = plate_small_json(24, 100);
    let offline_a = offline_bake(tmp.path(), &json_a, "a");

    let a = agent();
    let srv = start(&data, &["--workers", "1", "--threads", "1"]);
    assert!(data.join("reserve").is_file(), "no ballast file");
    let id_a = submit_ok(&a, &srv, &[("scene", None, json_a.as_bytes())], None);
    let id_c = submit_ok(&a, &srv, &[("scene", None, json_c.as_bytes())], None);
    wait_status(&a, &srv, &id_a, Duration::from_secs(120), |s| {
        s["chunks_done"].as_u64() >= Some(5)
    });

    // The disk fills up mid-bake: the scene pauses with a reason, nothing half-written stays.
    let filler = fs.0.join("filler");
    fill(&filler);
    let paused = wait_status(&a, &srv, &id_a, Duration::from_secs(60), |s| {
        s["reason"]
            .as_str()
            .is_some_and(|r| r.contains("disk is full"))
    });
    assert_eq!(paused["state"], "baking", "{paused}");
    let done_then = paused["chunks_done"].as_u64().unwrap();
    assert!(done_then < 81, "{paused}");
    std::thread::sleep(Duration::from_millis(1500));
    let later = get(&a, &srv.url(&format!("/v1/scenes/{id_a}"))).json();
    assert_eq!(later["chunks_done"].as_u64(), Some(done_then), "{later}");
    assert!(temporaries(&data).is_empty(), "{:?}", temporaries(&data));
    assert!(
        !data.join("reserve").exists(),
        "the ballast was not given back"
    );

    // Full to the last byte (the ballast's space too): an upload is refused with 507 …
    let filler2 = fs.0.join("filler2");
    fill(&filler2);
    let r = submit(
        &a,
        &srv,
        &[("scene", None, plate_small_json(16, 64).as_bytes())],
        None,
    );
    assert_eq!(r.status, 507, "{}", r.text());
    assert_eq!(r.json()["error"], "insufficient_storage");
    assert!(r.header("Retry-After").is_some());
    // … and DELETE of another scene still works, at once.
    let t = Instant::now();
    let d = delete(&a, &srv.url(&format!("/v1/scenes/{id_c}")), None);
    assert_eq!(d.status, 200, "{}", d.text());
    assert!(t.elapsed() < Duration::from_secs(5));
    assert!(!data.join("scenes").join(&id_c).exists());

    // Space freed: the bake resumes by itself; the trees are the offline bake's.
    std::fs::remove_file(&filler).unwrap();
    std::fs::remove_file(&filler2).unwrap();
    let done = wait_done(&a, &srv, &id_a);
    assert!(done["reason"].is_null(), "{done}");
    let trees = get(&a, &srv.url(&format!("/v1/scenes/{id_a}/trees")));
    assert!(
        trees.body == offline_a,
        "the trees differ from the offline bake"
    );
    assert!(temporaries(&data).is_empty(), "{:?}", temporaries(&data));
    assert!(
        data.join("reserve").is_file(),
        "the ballast was not put back"
    );
    assert!(srv.log_text().contains("waiting for space"));
    drop(srv);
}

/// A data folder on a read-only filesystem is refused at start with a message that says so
/// (SQLite alone reports "disk I/O error"), and nothing in it changes.
#[test]
fn a_read_only_data_folder_is_refused_with_a_clear_error() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let Some(fs) = Tmpfs::mount(&tmp.path().join("disk"), "8m") else {
        eprintln!("skipped: cannot mount a tmpfs here (needs root or passwordless sudo)");
        return;
    };
    let data = fs.0.join("data");
    drop(start(&data, &[]));
    let before: Vec<_> = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    let remount = |opts: &str| {
        let ok = Command::new("mount")
            .args(["-o", opts])
            .arg(&fs.0)
            .output()
            .is_ok_and(|o| o.status.success())
            || Command::new("sudo")
                .args(["-n", "mount", "-o", opts])
                .arg(&fs.0)
                .output()
                .is_ok_and(|o| o.status.success());
        assert!(ok, "cannot remount {opts}");
    };
    remount("remount,ro");
    let out = Command::new(BIN)
        .args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
        .arg(&data)
        .output()
        .unwrap();
    remount("remount,rw");
    let err = String::from_utf8_lossy(&out.stderr);
    eprintln!("{err}");
    assert!(!out.status.success());
    assert!(
        err.contains("is not writable") && err.contains(&data.display().to_string()),
        "{err}"
    );
    let after: Vec<_> = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(before, after);
}
