//! The service's bounds on what clients can make it hold: memory (the budget of
//! `service/memory.rs`), time (the minimum upload rate) and the shutdown deadline. Each test
//! runs the real `bspvt-server serve` binary on a real data folder over loopback.

mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use common::*;

/// An OBJ grid of n×n quads (2n² triangles) on the plane y = 0, about 61 bytes per vertex.
fn grid_obj(n: usize) -> Vec<u8> {
    let mut s = String::with_capacity(64 * (n + 1) * (n + 1));
    for j in 0..=n {
        for i in 0..=n {
            s.push_str(&format!(
                "v {} 0 {}\n",
                i as f32 / n as f32,
                j as f32 / n as f32
            ));
        }
    }
    let v = |i: usize, j: usize| j * (n + 1) + i + 1;
    for j in 0..n {
        for i in 0..n {
            s.push_str(&format!(
                "f {} {} {}\n",
                v(i, j),
                v(i + 1, j),
                v(i + 1, j + 1)
            ));
            s.push_str(&format!(
                "f {} {} {}\n",
                v(i, j),
                v(i + 1, j + 1),
                v(i, j + 1)
            ));
        }
    }
    s.into_bytes()
}

fn metric_of(srv: &Server, name: &str) -> f64 {
    metric(&get(&agent(), &srv.url("/metrics")).text(), name)
}

/// Four uploads near the mesh-size cap at once, each of which expands several times while it
/// is parsed, and then their bakes: the process's peak resident memory stays under the
/// configured budget. Uploads the budget cannot take now get 503 with `Retry-After` and
/// succeed when retried; scenes wait in the queue while a bake holds the budget; a mesh whose
/// bake could never fit is refused with 413 and the figures.
#[test]
fn four_near_cap_uploads_stay_under_the_memory_budget() {
    const BUDGET_MIB: u64 = 320;
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(
        &tmp.path().join("data"),
        &[
            "--memory-budget-mib",
            &BUDGET_MIB.to_string(),
            "--max-mesh-bytes",
            &(12u64 << 20).to_string(),
            "--max-body-bytes",
            &(13u64 << 20).to_string(),
            "--max-uploads",
            "4",
            "--max-uploads-per-client",
            "4",
            "--workers",
            "1",
            "--threads",
            "2",
        ],
    );
    let obj = grid_obj(430);
    assert!(
        obj.len() > 11 << 20 && obj.len() < 12 << 20,
        "{}",
        obj.len()
    );
    let ids: Vec<String> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..4)
            .map(|_| {
                let (srv, obj) = (&srv, &obj);
                s.spawn(move || {
                    let t0 = Instant::now();
                    let mut busy = 0;
                    loop {
                        let r = submit(&agent(), srv, &[("mesh", Some("grid.obj"), obj)], None);
                        if r.status == 202 {
                            return (r.json()["id"].as_str().expect("id").to_string(), busy);
                        }
                        assert_eq!(r.status, 503, "{}", r.text());
                        assert_eq!(r.json()["error"], "memory_busy", "{}", r.text());
                        assert!(r.header("retry-after").is_some());
                        busy += 1;
                        assert!(t0.elapsed() < Duration::from_secs(120), "never admitted");
                        std::thread::sleep(Duration::from_millis(200));
                    }
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                let (id, busy) = h.join().expect("uploader");
                eprintln!("scene {id}: admitted after {busy} memory_busy answer(s)");
                id
            })
            .collect()
    });
    eprintln!(
        "peak RSS after the uploads: {} MiB",
        srv.hwm_kib().div_ceil(1024)
    );
    // One bake fits the budget, two do not: one scene bakes, the others wait their turn.
    let a = agent();
    let state = |id: &str| get(&a, &srv.url(&format!("/v1/scenes/{id}"))).json()["state"].clone();
    let baking = || {
        ids.iter()
            .filter(|id| state(id) == "baking")
            .cloned()
            .collect::<Vec<_>>()
    };
    let t0 = Instant::now();
    while baking().is_empty() {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no scene started baking"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(4) {
        assert_eq!(metric_of(&srv, "bspvt_scenes_baking"), 1.0);
        let reserved = metric_of(&srv, "bspvt_memory_reserved_bytes");
        assert!(reserved <= (BUDGET_MIB << 20) as f64, "{reserved}");
        std::thread::sleep(Duration::from_millis(250));
    }
    assert_eq!(
        metric_of(&srv, "bspvt_queue_depth_scenes"),
        (ids.len() - 1) as f64
    );
    let hwm = srv.hwm_kib();
    eprintln!(
        "peak RSS {} MiB with a budget of {BUDGET_MIB} MiB",
        hwm.div_ceil(1024)
    );
    assert!(
        hwm <= BUDGET_MIB * 1024,
        "peak RSS {hwm} KiB over the budget of {BUDGET_MIB} MiB"
    );
    // Deleting the baking scene gives its memory to the next one.
    let first = baking();
    assert_eq!(first.len(), 1);
    assert_eq!(
        delete(&a, &srv.url(&format!("/v1/scenes/{}", first[0])), None).status,
        200
    );
    let t0 = Instant::now();
    while baking().is_empty() {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the next scene never started"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(baking().len(), 1);
    for id in &ids {
        delete(&a, &srv.url(&format!("/v1/scenes/{id}")), None);
    }
    assert!(srv.hwm_kib() <= BUDGET_MIB * 1024);
}

/// A mesh whose bake could never fit the budget is refused at submission with 413 and the
/// figures, and nothing is stored.
#[test]
fn a_mesh_that_can_never_fit_gets_413_with_the_figures() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), &["--memory-budget-mib", "100"]);
    let obj = grid_obj(300);
    let r = submit(&agent(), &srv, &[("mesh", Some("grid.obj"), &obj)], None);
    assert_eq!(r.status, 413, "{}", r.text());
    let body = r.json();
    assert_eq!(body["error"], "over_memory_budget");
    let detail = body["detail"].as_str().expect("detail");
    assert!(
        detail.contains("MiB") && detail.contains("100 MiB"),
        "{detail}"
    );
    let list = get(&agent(), &srv.url("/v1/scenes")).json();
    assert_eq!(list["scenes"].as_array().map(Vec::len), Some(0), "{list}");
    // A small scene still fits.
    let json = plate_small_json(8, 4096);
    submit_ok(&agent(), &srv, &[("scene", None, json.as_bytes())], None);
}

/// An upload that never falls silent for `--body-read-timeout-s` but trickles a few bytes at
/// a time is cut off once its average rate falls below `--min-upload-rate` (Apache's
/// `MinRate`), not after `request_timeout_s`.
#[test]
fn a_trickling_upload_is_cut_off_at_the_minimum_rate() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(
        &tmp.path().join("data"),
        &[
            "--body-read-timeout-s",
            "2",
            "--min-upload-rate",
            "1000",
            "--max-uploads-per-client",
            "1",
        ],
    );
    let mut s = TcpStream::connect(&srv.addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_millis(300)))
        .expect("timeout");
    let head = format!(
        "POST /v1/scenes HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; \
         boundary={BOUNDARY}\r\nContent-Length: 100000\r\n\r\n--{BOUNDARY}\r\n\
         Content-Disposition: form-data; name=\"mesh\"; filename=\"m.obj\"\r\n\r\n"
    );
    s.write_all(head.as_bytes()).expect("write");
    let t0 = Instant::now();
    let mut reply = Vec::new();
    let mut buf = [0u8; 4096];
    // 20 bytes every 0.3 s: never silent, about 67 bytes/s.
    while t0.elapsed() < Duration::from_secs(20) && !reply.ends_with(b"}") {
        let _ = s.write_all(b"v 0 0 0\nv 1 0 0\nv 0 1\n");
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => reply.extend_from_slice(&buf[..n]),
            Err(_) => {}
        }
    }
    let waited = t0.elapsed();
    eprintln!("cut off {waited:?} after the body began (grace 2 s)");
    let text = String::from_utf8_lossy(&reply);
    assert!(text.starts_with("HTTP/1.1 408"), "{text}");
    assert!(text.contains("body_too_slow"), "{text}");
    // Cut off at about the grace period plus what the bytes bought (2 s + ~0.1 s), well
    // before the request timeout.
    assert!(
        waited >= Duration::from_millis(1900) && waited < Duration::from_secs(8),
        "{waited:?}"
    );
    // Its slot is free again.
    let json = plate_small_json(8, 4096);
    submit_ok(&agent(), &srv, &[("scene", None, json.as_bytes())], None);
}

/// SIGTERM while a chunk is being baked (and, with this mesh, while its BVH may still be
/// built): the process exits within `--shutdown-timeout-s` and a little more, and the next
/// start resumes the scene.
#[test]
fn sigterm_exits_within_the_deadline_and_the_bake_resumes() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let data = tmp.path().join("data");
    let flags = ["--shutdown-timeout-s", "2", "--workers", "1"];
    let mut srv = start(&data, &flags);
    let obj = grid_obj(300);
    let settings = r#"{"face_res": 64, "chunk_vertices": 60000}"#;
    let id = submit_ok(
        &agent(),
        &srv,
        &[
            ("mesh", Some("grid.obj"), &obj),
            ("settings", None, settings.as_bytes()),
        ],
        None,
    );
    wait_status(&agent(), &srv, &id, Duration::from_secs(60), |s| {
        s["state"] == "baking"
    });
    std::thread::sleep(Duration::from_millis(300));
    let took = srv
        .terminate(Duration::from_secs(15))
        .unwrap_or_else(|| panic!("still running 15 s after SIGTERM\n{}", srv.log_text()));
    eprintln!("exited {took:?} after SIGTERM (deadline 2 s)");
    assert!(took < Duration::from_millis(3500), "{took:?}");
    let srv = start(&data, &flags);
    let s = get(&agent(), &srv.url(&format!("/v1/scenes/{id}"))).json();
    assert!(
        s["state"] == "baking" || s["state"] == "queued",
        "not resumed: {s}"
    );
    assert_eq!(
        delete(&agent(), &srv.url(&format!("/v1/scenes/{id}")), None).status,
        200
    );
}

/// Opens `GET path` as an event stream on a new connection and reads until `until` appears
/// (or 10 s pass); returns the connection and what it read.
fn open_events(addr: &str, path: &str, until: &str) -> (TcpStream, String) {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    s.write_all(
        format!("GET {path} HTTP/1.1\r\nHost: x\r\nAccept: text/event-stream\r\n\r\n").as_bytes(),
    )
    .expect("write");
    let text = read_until(&mut s, until, Duration::from_secs(10));
    (s, text)
}

fn read_until(s: &mut TcpStream, until: &str, limit: Duration) -> String {
    let t0 = Instant::now();
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    while t0.elapsed() < limit && !String::from_utf8_lossy(&got).contains(until) {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(_) => {}
        }
    }
    String::from_utf8_lossy(&got).into_owned()
}

/// Every stream slot held by idle event streams: a new stream is refused (429) while they are
/// younger than `--shed-idle-streams-after-s`; after that, the stream idle the longest is
/// ended with a `shed` event (and a `retry:` hint) and the new stream gets its slot.
#[test]
fn the_idlest_event_stream_is_shed_for_a_new_stream() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(
        &tmp.path().join("data"),
        &[
            "--max-streams",
            "4",
            "--max-streams-per-client",
            "8",
            "--shed-idle-streams-after-s",
            "2",
            "--workers",
            "1",
        ],
    );
    // A slow bake (one big chunk at 256² faces, 16× the work of 64²): its event streams stay
    // open and quiet. (At 64² the flat grid's one chunk came to take under 3 s once the cast's
    // per-face work was cut, and the bake was done before the streams could idle.)
    let obj = grid_obj(200);
    let settings = r#"{"face_res": 256, "chunk_vertices": 60000}"#;
    let id = submit_ok(
        &agent(),
        &srv,
        &[
            ("mesh", Some("grid.obj"), &obj),
            ("settings", None, settings.as_bytes()),
        ],
        None,
    );
    let path = format!("/v1/scenes/{id}/events");
    let mut held: Vec<TcpStream> = (0..4)
        .map(|_| {
            let (s, text) = open_events(&srv.addr, &path, "event: status");
            assert!(text.starts_with("HTTP/1.1 200"), "{text}");
            s
        })
        .collect();
    // Too young to shed: refused.
    let (_, text) = open_events(&srv.addr, &path, "\r\n\r\n");
    assert!(text.starts_with("HTTP/1.1 429"), "{text}");
    std::thread::sleep(Duration::from_millis(2500));
    let (_new, text) = open_events(&srv.addr, &path, "event: status");
    assert!(text.starts_with("HTTP/1.1 200"), "{text}");
    assert!(text.contains("event: status"), "{text}");
    // Exactly one of the old streams was told and ended.
    let mut shed = 0;
    for s in &mut held {
        let rest = read_until(s, "event: shed", Duration::from_millis(600));
        if rest.contains("event: shed") {
            assert!(rest.contains("retry: 30000"), "{rest}");
            shed += 1;
        }
    }
    assert_eq!(shed, 1);
    assert_eq!(metric_of(&srv, "bspvt_streams_shed_total"), 1.0);
    delete(&agent(), &srv.url(&format!("/v1/scenes/{id}")), None);
}
