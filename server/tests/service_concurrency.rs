//! Load: 50 clients stream a scene's trees while it bakes (whole streams and vertex ranges,
//! each connected before the bake ends); every client gets exactly the offline bake's bytes,
//! no request fails, and the server is healthy afterwards.

#![allow(clippy::unwrap_used)]

mod common;

use std::sync::{Arc, Barrier};
use std::time::{Duration, Instant};

use bspvt_proto::encoding::{decode_bake, decode_header, peek_chunk};
use common::*;

const CLIENTS: usize = 50;

#[test]
fn fifty_streaming_clients_during_a_bake_all_get_correct_data() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let json = plate_small_json(40, 64); // 41 chunks
    let offline = Arc::new(offline_bake(tmp.path(), &json, "ref"));
    let reference = decode_bake(&offline).expect("reference decodes");
    // One bake thread, so that the bake outlasts the clients' start on any machine.
    let srv = start(
        &tmp.path().join("data"),
        &["--workers", "2", "--threads", "1"],
    );
    let a = agent();
    let id = submit_ok(&a, &srv, &[("scene", None, json.as_bytes())], None);
    let submitted = Instant::now();

    // Header length and chunk offsets of the reference, for range checks.
    let (_, hlen) = decode_header(&offline).unwrap();
    let mut offsets = vec![hlen];
    while *offsets.last().unwrap() < offline.len() {
        let at = *offsets.last().unwrap();
        offsets.push(at + peek_chunk(&offline[at..]).unwrap().1);
    }

    let barrier = Arc::new(Barrier::new(CLIENTS));
    let clients: Vec<_> = (0..CLIENTS)
        .map(|i| {
            let base = srv.url(&format!("/v1/scenes/{id}/trees"));
            let offline = offline.clone();
            let offsets = offsets.clone();
            let barrier = barrier.clone();
            std::thread::spawn(move || {
                let a = agent();
                // Every other client asks for a vertex range (chunks c0..c1).
                let (url, c0, c1) = if i % 2 == 0 {
                    (base, 0, offsets.len() - 1)
                } else {
                    let c0 = i % 20;
                    let c1 = (c0 + 1 + i % 7).min(offsets.len() - 1);
                    (
                        format!("{base}?vertices={}..{}", c0 * 64 + 5, c1 * 64 - 3),
                        c0,
                        c1,
                    )
                };
                barrier.wait();
                let t0 = Instant::now();
                let r = try_get(&a, &url, &[]).unwrap_or_else(|e| panic!("client {i}: {e}"));
                assert_eq!(r.status, 200, "client {i}: {}", r.text());
                let want = [&offline[..offsets[0]], &offline[offsets[c0]..offsets[c1]]].concat();
                assert!(r.body == want, "client {i} got different bytes");
                (t0, r.body.len())
            })
        })
        .collect();
    // Clients are connected while the bake runs.
    let during = get(&a, &srv.url(&format!("/v1/scenes/{id}")));
    let results: Vec<_> = clients.into_iter().map(|c| c.join().unwrap()).collect();
    let s = wait_done(&a, &srv, &id);
    let finished = submitted.elapsed();
    eprintln!(
        "state when clients started: {}; bake + streams took {:.2} s; {} bytes streamed",
        during.json()["state"],
        finished.as_secs_f64(),
        results.iter().map(|r| r.1).sum::<usize>()
    );
    assert_ne!(
        during.json()["state"],
        "done",
        "the bake ended before the clients started"
    );
    assert_eq!(s["chunks_baked_this_process"], 41);

    // A full stream after the bake decodes to the reference trees.
    let whole = get(&a, &srv.url(&format!("/v1/scenes/{id}/trees")));
    assert_eq!(decode_bake(&whole.body).unwrap().trees, reference.trees);

    let text = get(&a, &srv.url("/metrics")).text();
    assert_eq!(
        metric(&text, "bspvt_http_responses_total{class=\"5xx\"}"),
        0.0
    );
    assert_eq!(
        metric(&text, "bspvt_http_responses_total{class=\"4xx\"}"),
        0.0
    );
    // Streams close as their clients finish.
    let t0 = Instant::now();
    while metric(&get(&a, &srv.url("/metrics")).text(), "bspvt_streams_open") != 0.0 {
        assert!(t0.elapsed() < Duration::from_secs(10), "streams left open");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(get(&a, &srv.url("/healthz")).json()["status"], "ok");
}
