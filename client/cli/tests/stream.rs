//! The streaming client against the real service (`bspvt serve` on loopback, real HTTP, real
//! on-disk store and cache): streamed frames equal offline frames, partial streams render and
//! converge, a dropped connection resumes, and a second start is served from the cache.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use bspvt_client::render::renderer::Mode;
use bspvt_client::session::connect::connect;
use bspvt_client::stream::cache::Cache;
use bspvt_client::stream::fetch::{self, FetchOptions};
use bspvt_client::stream::remote::Remote;
use bspvt_client::stream::trees::StreamedTrees;
use bspvt_proto::api::JobState;
use bspvt_proto::scene::open_scene;
use common::*;

const SIZE: u32 = 96;

#[test]
fn streamed_frames_equal_offline_frames_and_a_second_start_fetches_nothing() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), "127.0.0.1:0", &[]);
    let scene_path = plate_small(tmp.path(), "plate", 32, 256);
    let args = connect_args(&scene_path, &srv, tmp.path());

    // First start: submit, stream everything (the bake runs meanwhile), fill the cache.
    let c1 = connect(&args).expect("connect");
    assert!(c1.served.submitted);
    let mut s1 = c1.session(&args, SIZE, SIZE).expect("session");
    s1.wait_complete();
    assert!(s1.streamed.complete(), "{:?}", s1.streamed.failed);
    let k1 = s1.counters.clone().expect("counters");
    let n_chunks = k1.chunks_fetched.load(Ordering::Relaxed);
    assert_eq!(n_chunks, 11, "2587 vertices in chunks of 256");
    assert!(k1.tree_bytes.load(Ordering::Relaxed) > 0);

    // The offline bake of the same scene file, and the frames it gives.
    let bake = offline_bake(&scene_path);
    let scene = open_scene(Some(&scene_path.to_string_lossy()), None).expect("scene");
    assert_eq!(c1.scene.mesh.content_hash(), scene.mesh.content_hash());
    for (t, mode) in [(None, Mode::Vertex), (Some(0.37), Mode::Pixel)] {
        s1.path_t = t;
        s1.mode = mode;
        let streamed = s1.frame();
        let offline = offline_frame(
            &scene,
            &bake,
            &scene.camera,
            &s1.light().unwrap(),
            mode,
            SIZE,
        );
        assert!(all_finite(&streamed));
        assert!(
            streamed == offline,
            "a frame from streamed trees differs from the offline bake's ({mode:?}, t = {t:?})"
        );
        assert!(streamed.mean() > 0.0);
    }

    // Second start: same scene file, same cache: the service is asked nothing but validators.
    let c2 = connect(&args).expect("second connect");
    assert!(!c2.served.submitted, "the scene was submitted again");
    assert_eq!(c2.served.id, c1.served.id);
    assert_eq!(c2.scene_bytes_fetched, 0, "the scene was fetched again");
    let mut s2 = c2.session(&args, SIZE, SIZE).expect("session");
    // The cached trees are there before the first frame, not after a poll of the stream.
    assert!(
        s2.streamed.complete(),
        "a complete cache did not reach the first frame"
    );
    s2.wait_complete();
    assert!(s2.streamed.complete());
    let k2 = s2.counters.clone().expect("counters");
    assert_eq!(
        k2.tree_bytes.load(Ordering::Relaxed),
        0,
        "tree bytes fetched again"
    );
    assert_eq!(k2.chunks_fetched.load(Ordering::Relaxed), 0);
    assert_eq!(k2.chunks_cached.load(Ordering::Relaxed), n_chunks);
    s2.path_t = Some(0.37);
    s2.mode = Mode::Pixel;
    s1.path_t = Some(0.37);
    s1.mode = Mode::Pixel;
    assert!(
        s2.frame() == s1.frame(),
        "the cached trees draw another frame"
    );

    // A client that stops after 4 chunks, then a new one on the same cache: it fetches only
    // the 7 it lacks.
    let cache_root = tmp.path().join("cache-partial");
    let remote = Remote::new(&srv.base, None);
    let id = c1.served.id.clone();
    let run = |max_chunks| {
        let (rx, counters, handle) = fetch::spawn(
            remote.clone(),
            id.clone(),
            FetchOptions {
                cache: Some(Cache::new(&cache_root, &id).expect("cache")),
                max_chunks,
                ..FetchOptions::default()
            },
        );
        let mut trees = StreamedTrees::default();
        while let Ok(u) = rx.recv() {
            trees.apply(u);
        }
        handle.join().expect("fetcher");
        (trees, counters)
    };
    let (partial, k) = run(Some(4));
    assert!(partial.failed.is_some() && !partial.complete());
    assert_eq!(k.chunks_fetched.load(Ordering::Relaxed), 4);
    assert_eq!(partial.vertices_present, 4 * 256);
    let (full, k) = run(None);
    assert!(full.complete(), "{:?}", full.failed);
    assert_eq!(k.chunks_cached.load(Ordering::Relaxed), 4);
    assert_eq!(k.chunks_fetched.load(Ordering::Relaxed), n_chunks - 4);
}

#[test]
fn a_partial_stream_renders_survives_a_server_crash_and_converges() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let data = tmp.path().join("data");
    // One bake thread and small chunks: the bake lasts long enough to draw while it runs.
    let flags = ["--workers", "1", "--threads", "1"];
    let mut srv = start(&data, "127.0.0.1:0", &flags);
    let addr = srv.addr.clone();
    let scene_path = plate_small(tmp.path(), "plate", 48, 128);
    let mut args = connect_args(&scene_path, &srv, tmp.path());
    args.cache_dir = None;

    let c = connect(&args).expect("connect");
    let mut s = c.session(&args, SIZE, SIZE).expect("session");
    let mut fractions = Vec::new();
    let mut partial_frames = 0;
    let mut crashed = false;
    let deadline = Instant::now() + Duration::from_secs(600);
    while s.streaming() {
        assert!(Instant::now() < deadline, "the stream did not finish");
        s.poll();
        let img = s.frame();
        assert!(all_finite(&img), "NaN or Inf in a partial frame");
        let f = s.streamed.fraction();
        if f > 0.0 && f < 1.0 {
            partial_frames += 1;
        }
        fractions.push(f);
        // Once part of the trees is here, kill the service and start it again on the same
        // data folder and port: the client must resume, not start over.
        if !crashed && f > 0.2 {
            srv.kill();
            std::thread::sleep(Duration::from_millis(300));
            srv = start(&data, &addr, &flags);
            crashed = true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(s.streamed.complete(), "{:?}", s.streamed.failed);
    assert!(crashed, "the stream ended before the crash could be staged");
    assert!(
        partial_frames >= 3,
        "only {partial_frames} frames were drawn from a partial stream"
    );
    assert!(
        fractions.windows(2).all(|w| w[0] <= w[1]),
        "trees went missing"
    );
    let k = s.counters.clone().expect("counters");
    assert!(k.reconnects.load(Ordering::Relaxed) >= 1);
    // 2587 vertices in chunks of 128: each chunk fetched once, across the crash.
    assert_eq!(k.chunks_fetched.load(Ordering::Relaxed), 21);
    let status = Remote::new(&srv.base, None)
        .status(&c.served.id)
        .expect("status");
    assert_eq!(status.state, JobState::Done);

    // Converged: the frame equals the one from the offline bake.
    let bake = offline_bake(&scene_path);
    let scene = open_scene(Some(&scene_path.to_string_lossy()), None).expect("scene");
    s.path_t = Some(0.6);
    let img = s.frame();
    let offline = offline_frame(
        &scene,
        &bake,
        &scene.camera,
        &s.light().unwrap(),
        Mode::Vertex,
        SIZE,
    );
    assert!(
        img == offline,
        "the converged frame differs from the offline bake's"
    );
}

/// A final answer ends the stream at once: a scene the service does not know is not retried
/// (404 is not a dropped connection), and a scene deleted while it streams ends the stream
/// with the reason instead of reconnecting until the retries run out.
#[test]
fn not_found_and_deleted_scenes_end_the_stream_without_retries() {
    use bspvt_client::stream::fetch::Update;

    let tmp = tempfile::tempdir().expect("temp dir");
    let flags = ["--workers", "1", "--threads", "1"];
    let srv = start(&tmp.path().join("data"), "127.0.0.1:0", &flags);
    let remote = Remote::new(&srv.base, None);

    // An id nobody submitted.
    let t = Instant::now();
    let (rx, k, thread) = fetch::spawn(
        remote.clone(),
        "0123456789abcdef0123456789abcdef".into(),
        FetchOptions::default(),
    );
    thread.join().expect("fetcher");
    let last = rx.try_iter().last();
    match last {
        Some(Update::Failed(e)) => assert!(e.contains("404"), "{e}"),
        _ => panic!("an unknown scene did not fail"),
    }
    assert_eq!(k.reconnects.load(Ordering::Relaxed), 0);
    assert!(t.elapsed() < Duration::from_secs(5), "{:?}", t.elapsed());

    // A scene deleted while its trees stream (one slow bake thread, small chunks).
    let scene_path = plate_small(tmp.path(), "plate", 48, 64);
    let id = remote
        .submit(Some(&scene_path.to_string_lossy()), None)
        .expect("submit");
    let (rx, k, thread) = fetch::spawn(remote.clone(), id.clone(), FetchOptions::default());
    let deadline = Instant::now() + Duration::from_secs(120);
    while k.chunks_fetched.load(Ordering::Relaxed) < 1 {
        assert!(Instant::now() < deadline, "no chunk arrived");
        std::thread::sleep(Duration::from_millis(10));
    }
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let r = agent
        .delete(format!("{}/v1/scenes/{id}", srv.base))
        .call()
        .expect("delete");
    assert_eq!(r.status(), 200);
    let t = Instant::now();
    thread.join().expect("fetcher");
    let msgs: Vec<Update> = rx.try_iter().collect();
    match msgs.last() {
        Some(Update::Failed(e)) => assert!(
            e.contains("deleted") || e.contains("410") || e.contains("404"),
            "{e}"
        ),
        _ => panic!("the deleted scene's stream did not fail"),
    }
    // At most the one reconnect the cut connection itself causes; never a retry of a final
    // answer (the retry budget would take 8 attempts with backoff).
    assert!(k.reconnects.load(Ordering::Relaxed) <= 1);
    assert!(t.elapsed() < Duration::from_secs(5), "{:?}", t.elapsed());
}
