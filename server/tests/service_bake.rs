//! The baking service end to end, on a real `bspvt-server serve` process over loopback HTTP:
//! a submitted scene bakes to exactly the offline `bspvt-server bake` bytes, streams (whole,
//! ranges, face subsets, before the bake ends) are correct, validators work, a corrupt stored
//! chunk is re-baked instead of served, and deletion cancels a bake.

#![allow(clippy::unwrap_used)]

mod common;

use std::io::Read;
use std::time::{Duration, Instant};

use bspvt_proto::encoding::{decode_bake, decode_header, peek_chunk};
use common::*;

/// Splits a bake file into its header frame and chunk frames.
fn frames(bake: &[u8]) -> (Vec<u8>, Vec<Vec<u8>>) {
    let (_, mut pos) = decode_header(bake).expect("header");
    let header = bake[..pos].to_vec();
    let mut chunks = Vec::new();
    while pos < bake.len() {
        let (_, used) = peek_chunk(&bake[pos..]).expect("chunk");
        chunks.push(bake[pos..pos + used].to_vec());
        pos += used;
    }
    (header, chunks)
}

#[test]
fn builtin_scene_bakes_streams_and_matches_the_offline_bake() {
    let tmp = tempfile::tempdir().expect("temp dir");
    // One bake thread: the bake lasts long enough on any machine for the early clients below
    // to connect while it runs.
    let srv = start(
        &tmp.path().join("data"),
        &["--workers", "2", "--threads", "1"],
    );
    let a = agent();
    let json = plate_small_json(32, 256);

    let id = submit_ok(&a, &srv, &[("scene", None, json.as_bytes())], None);
    assert_eq!(id.len(), 32);
    // A client that connects right away: header at once, chunks as they become durable.
    let early = {
        let url = srv.url(&format!("/v1/scenes/{id}/trees"));
        std::thread::spawn(move || {
            let a = agent();
            let t0 = Instant::now();
            let r = try_get(&a, &url, &[]).expect("early stream");
            (r, t0.elapsed())
        })
    };
    let events = {
        let url = srv.url(&format!("/v1/scenes/{id}/events"));
        std::thread::spawn(move || get(&agent(), &url).text())
    };
    let offline = offline_bake(tmp.path(), &json, "plate-small-32");
    let status = wait_done(&a, &srv, &id);
    assert_eq!(status["vertices_done"], 2587);
    assert_eq!(status["vertices_total"], 2587);
    assert_eq!(status["chunks_total"], 11);
    assert_eq!(status["settings"]["face_res"], 32);
    assert_eq!(status["sizes"]["stored_bytes"], offline.len() as u64);
    assert_eq!(status["chunks_baked_this_process"], 11);
    assert!(status["finished_ms"].as_i64().unwrap() >= status["started_ms"].as_i64().unwrap());

    // The whole stream is the offline bake, byte for byte.
    let r = get(&a, &srv.url(&format!("/v1/scenes/{id}/trees")));
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-type"), Some("application/vnd.bspvt"));
    assert!(r.body == offline, "stream differs from the offline bake");
    let bake = decode_bake(&r.body).expect("decodes");
    assert_eq!(bake.trees.len(), 2587);
    let (early, _) = early.join().expect("early client");
    assert_eq!(early.status, 200);
    assert!(early.body == offline, "early stream differs");
    assert_eq!(
        early.header("etag"),
        None,
        "no validator before the data is final"
    );

    // The same trees as the offline bake of the built-in scene itself (other chunking).
    let builtin_out = tmp.path().join("builtin.bspvt");
    let st = std::process::Command::new(BIN)
        .args(["bake", "builtin:plate-small", "--face-res", "32", "--out"])
        .arg(&builtin_out)
        .stderr(std::process::Stdio::null())
        .status()
        .expect("offline bake");
    assert!(st.success());
    let builtin = decode_bake(&std::fs::read(&builtin_out).expect("read")).expect("decode");
    assert_eq!(builtin.header.mesh_hash, bake.header.mesh_hash);
    assert!(
        builtin.trees == bake.trees,
        "trees differ from builtin:plate-small's"
    );

    // Events: progress only grows, the last one is `done`.
    let events = events.join().expect("events client");
    let states: Vec<serde_json::Value> = events
        .lines()
        .filter_map(|l| l.strip_prefix("data:"))
        .map(|d| serde_json::from_str(d.trim()).expect("event JSON"))
        .collect();
    assert!(!states.is_empty());
    assert_eq!(states.last().unwrap()["state"], "done");
    let done: Vec<u64> = states
        .iter()
        .map(|s| s["vertices_done"].as_u64().unwrap())
        .collect();
    assert!(done.windows(2).all(|w| w[0] <= w[1]), "{done:?}");

    // Validators: a final stream has a strong ETag; If-None-Match gives 304.
    let etag = r.header("etag").expect("etag").to_string();
    assert!(etag.starts_with('"'));
    assert_eq!(
        r.header("content-length"),
        Some(&*offline.len().to_string())
    );
    let nm = try_get(
        &a,
        &srv.url(&format!("/v1/scenes/{id}/trees")),
        &[("If-None-Match", &etag)],
    )
    .unwrap();
    assert_eq!(nm.status, 304);
    assert!(nm.body.is_empty());

    // Ranges: the chunks covering the vertices, after the header.
    let (header, chunks) = frames(&offline);
    let part = get(
        &a,
        &srv.url(&format!("/v1/scenes/{id}/trees?vertices=300..600")),
    );
    assert_eq!(part.status, 200);
    assert_eq!(part.header("x-bspvt-vertices"), Some("256..768"));
    assert!(part.body == [header.clone(), chunks[1].clone(), chunks[2].clone()].concat());
    assert_ne!(part.header("etag"), Some(etag.as_str()));
    let tail = get(
        &a,
        &srv.url(&format!("/v1/scenes/{id}/trees?vertices=2560..")),
    );
    assert!(tail.body == [header.clone(), chunks[10].clone()].concat());
    let tail = get(
        &a,
        &srv.url(&format!("/v1/scenes/{id}/trees?vertices=2559..")),
    );
    assert_eq!(tail.header("x-bspvt-chunks"), Some("9..11"));

    // Face subsets: the same trees with the other faces removed.
    let sub = get(
        &a,
        &srv.url(&format!("/v1/scenes/{id}/trees?faces=py,0,%2Bz")),
    );
    assert_eq!(sub.status, 200);
    let sub = decode_bake(&sub.body).expect("subset decodes");
    for (v, (s, full)) in sub.trees.iter().zip(&bake.trees).enumerate() {
        for f in 0..6 {
            let keep = [0, 2, 4].contains(&f);
            let want = if keep { full.faces[f].clone() } else { None };
            assert_eq!(s.faces[f], want, "vertex {v} face {f}");
        }
    }

    // The mesh, as baked: vertex order = tree order.
    let m = get(&a, &srv.url(&format!("/v1/scenes/{id}/mesh")));
    assert_eq!(m.status, 200);
    let mesh: bspvt_proto::Mesh = serde_json::from_slice(&m.body).expect("mesh JSON");
    assert_eq!(mesh.content_hash(), bake.header.mesh_hash);
    let builtin_mesh = bspvt_proto::builtin::mesh("plate-small").unwrap();
    assert_eq!(mesh, builtin_mesh);
    let metag = m.header("etag").unwrap().to_string();
    let m304 = try_get(
        &a,
        &srv.url(&format!("/v1/scenes/{id}/mesh")),
        &[("If-None-Match", &metag)],
    )
    .unwrap();
    assert_eq!(m304.status, 304);
    let ply = get(&a, &srv.url(&format!("/v1/scenes/{id}/mesh?format=ply")));
    assert_eq!(ply.status, 200);
    let back = bspvt_proto::import::load_mesh_bytes(
        &ply.body,
        bspvt_proto::import::Format::Ply,
        &bspvt_proto::import::Limits::default(),
    )
    .expect("PLY imports");
    assert_eq!(back.positions, builtin_mesh.positions);
    assert_eq!(back.triangles, builtin_mesh.triangles);

    // The OpenAPI document lists every route.
    let doc = get(&a, &srv.url("/v1/openapi.json")).json();
    assert!(doc["openapi"].as_str().unwrap().starts_with("3."));
    for p in [
        "/v1/scenes",
        "/v1/scenes/{id}",
        "/v1/scenes/{id}/events",
        "/v1/scenes/{id}/mesh",
        "/v1/scenes/{id}/scene",
        "/v1/scenes/{id}/trees",
        "/v1/openapi.json",
        "/healthz",
        "/metrics",
    ] {
        assert!(doc["paths"][p].is_object(), "{p} undocumented");
    }
    assert!(doc["components"]["securitySchemes"]["api_key"].is_object());

    // Metrics.
    let text = get(&a, &srv.url("/metrics")).text();
    assert_eq!(metric(&text, "bspvt_chunks_baked_total"), 11.0);
    assert!(metric(&text, "bspvt_chunks_served_total") >= 22.0);
    assert_eq!(metric(&text, "bspvt_streams_open"), 0.0);
    assert!(text.contains("bspvt_bytes_served_total{kind=\"trees\"}"));
    let log = srv.log_text();
    assert!(
        log.contains("chunk durable"),
        "per-chunk spans/logs missing"
    );
}

#[test]
fn corrupt_or_missing_chunks_are_rebaked_never_served() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let data = tmp.path().join("data");
    let srv = start(&data, &["--workers", "1"]);
    let a = agent();
    let json = plate_small_json(16, 512);
    let id = submit_ok(&a, &srv, &[("scene", None, json.as_bytes())], None);
    wait_done(&a, &srv, &id);
    let url = srv.url(&format!("/v1/scenes/{id}/trees"));
    let good = get(&a, &url).body;
    let etag = get(&a, &url).header("etag").unwrap().to_string();

    // Flip one byte in chunk 2's stored payload, delete chunk 4's file.
    let chunk = |n: u32| data.join(format!("scenes/{id}/chunks/{n}.bvck"));
    let mut bytes = std::fs::read(chunk(2)).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x40;
    std::fs::write(chunk(2), &bytes).unwrap();
    std::fs::remove_file(chunk(4)).unwrap();

    let again = get(&a, &url);
    assert_eq!(again.status, 200);
    assert!(again.body == good, "served bytes changed after corruption");
    let s = wait_done(&a, &srv, &id);
    assert_eq!(s["chunks_corrupt"], 2, "{s}");
    assert_eq!(s["chunks_baked_this_process"], 8);
    assert_ne!(
        std::fs::read(chunk(2)).unwrap(),
        bytes,
        "chunk 2 not re-baked"
    );
    // The re-baked data is the same, so the validator still holds.
    let nm = try_get(&a, &url, &[("If-None-Match", &etag)]).unwrap();
    assert_eq!(nm.status, 304);
    let text = get(&a, &srv.url("/metrics")).text();
    assert_eq!(metric(&text, "bspvt_chunks_corrupt_total"), 2.0);
    assert!(srv.log_text().contains("stored chunk is corrupt"));

    // A corrupt stored scene: the re-bake a missing chunk needs fails the scene, the stream
    // ends, and the public reason names no server path (the log has it).
    let scene_bin = data.join(format!("scenes/{id}/scene.bin"));
    let mut sb = std::fs::read(&scene_bin).unwrap();
    let k = sb.len() / 2;
    sb[k] ^= 0x01;
    std::fs::write(&scene_bin, &sb).unwrap();
    std::fs::remove_file(chunk(1)).unwrap();
    let _ = try_get(&a, &url, &[]);
    let s = wait_status(&a, &srv, &id, std::time::Duration::from_secs(60), |s| {
        s["state"] == "failed"
    });
    let reason = s["reason"].as_str().unwrap_or_default();
    assert!(reason.contains("the stored scene is corrupt"), "{s}");
    let root = tmp.path().to_string_lossy().to_string();
    assert!(
        !reason.contains(&root) && !reason.contains("scene.bin"),
        "{reason}"
    );
    assert!(srv.log_text().contains(&root), "the log names the path");
}

#[test]
fn bare_mesh_upload_with_settings_matches_offline_mesh_bake() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), &[]);
    let a = agent();
    // A bumpy 12×12 grid with a box on it, as OBJ, sent zstd-compressed.
    let mut obj = String::new();
    for j in 0..12 {
        for i in 0..12 {
            let h = if (4..8).contains(&i) && (4..8).contains(&j) {
                0.8
            } else {
                0.0
            };
            obj += &format!("v {} {h} {}\n", i as f32 * 0.1, j as f32 * 0.1);
        }
    }
    for j in 0..11 {
        for i in 0..11 {
            let v = |i: usize, j: usize| j * 12 + i + 1;
            obj += &format!("f {} {} {}\n", v(i, j), v(i, j + 1), v(i + 1, j));
            obj += &format!("f {} {} {}\n", v(i + 1, j), v(i, j + 1), v(i + 1, j + 1));
        }
    }
    let path = tmp.path().join("bumps.obj");
    std::fs::write(&path, &obj).unwrap();
    let z = zstd::bulk::compress(obj.as_bytes(), 19).unwrap();
    let id = submit_ok(
        &a,
        &srv,
        &[
            ("mesh", Some("bumps.obj.zst"), &z),
            (
                "settings",
                None,
                br#"{"face_res": 8, "chunk_vertices": 1024}"#,
            ),
        ],
        None,
    );
    let s = wait_done(&a, &srv, &id);
    assert!(s["source"].as_str().unwrap().contains("bumps.obj"));
    let served = get(&a, &srv.url(&format!("/v1/scenes/{id}/trees"))).body;
    let out = tmp.path().join("bumps.bspvt");
    let st = std::process::Command::new(BIN)
        .args(["bake", "--face-res", "8", "--mesh"])
        .arg(&path)
        .arg("--out")
        .arg(&out)
        .stderr(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(st.success());
    assert!(
        served == std::fs::read(&out).unwrap(),
        "differs from the offline --mesh bake"
    );
}

#[test]
fn delete_cancels_a_bake_and_aborts_its_streams() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let data = tmp.path().join("data");
    let srv = start(
        &data,
        &["--workers", "1", "--threads", "1", "--api-key", API_KEY],
    );
    let a = agent();
    let json = plate_small_json(48, 32);
    let id = submit_ok(&a, &srv, &[("scene", None, json.as_bytes())], Some(API_KEY));
    wait_status(&a, &srv, &id, Duration::from_secs(60), |s| {
        s["chunks_done"].as_u64() >= Some(2)
    });
    let url = srv.url(&format!("/v1/scenes/{id}/trees"));
    let reader = std::thread::spawn(move || {
        let a = agent();
        let mut r = a.get(&url).call().expect("stream starts");
        assert_eq!(r.status().as_u16(), 200);
        let mut body = Vec::new();
        r.body_mut()
            .as_reader()
            .read_to_end(&mut body)
            .map(|_| body.len())
    });
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(
        delete(&a, &srv.url(&format!("/v1/scenes/{id}")), None).status,
        401
    );
    let d = delete(&a, &srv.url(&format!("/v1/scenes/{id}")), Some(API_KEY));
    assert_eq!(d.status, 200, "{}", d.text());
    assert_eq!(d.json()["state"], "cancelled");
    let outcome = reader.join().unwrap();
    assert!(
        outcome.is_err(),
        "a stream of a deleted bake ended cleanly: {outcome:?}"
    );
    assert_eq!(
        get(&a, &srv.url(&format!("/v1/scenes/{id}"))).json()["state"],
        "cancelled"
    );
    let gone = get(&a, &srv.url(&format!("/v1/scenes/{id}/trees")));
    assert_eq!(gone.status, 410);
    assert_eq!(gone.json()["error"], "deleted");
    assert!(!data.join("scenes").join(&id).exists(), "files not removed");
    // Deleting twice is harmless.
    let d2 = delete(&a, &srv.url(&format!("/v1/scenes/{id}")), Some(API_KEY));
    assert_eq!(d2.status, 200);
    let text = get(&a, &srv.url("/metrics")).text();
    assert_eq!(metric(&text, "bspvt_queue_depth_chunks"), 0.0);
}

/// A 6.7 KB-style attack: a million copies of one triangle, zstd-compressed. Accepted with a
/// warning that names the copies, and baked in seconds (the copies are left out of the BVHs;
/// before, the BVH build of this upload ran for hours).
#[test]
fn a_million_coincident_triangles_bake_in_seconds() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), &["--workers", "1"]);
    let a = agent();
    let obj = String::from("v 0 0 0\nv 1 0 0\nv 0 0 1\n") + &"f 1 3 2\n".repeat(1_000_000);
    let z = zstd::bulk::compress(obj.as_bytes(), 19).unwrap();
    eprintln!("{} bytes compressed to {}", obj.len(), z.len());
    let t = std::time::Instant::now();
    let id = submit_ok(
        &a,
        &srv,
        &[
            ("mesh", Some("coincident.obj.zst"), &z),
            ("settings", None, br#"{"face_res": 8}"#),
        ],
        None,
    );
    let s = wait_status(&a, &srv, &id, std::time::Duration::from_secs(60), |s| {
        s["state"] == "done"
    });
    eprintln!("accepted and baked in {:.1} s", t.elapsed().as_secs_f64());
    let warnings = s["warnings"].to_string();
    assert!(warnings.contains("999999 triangles repeat"), "{s}");
}

/// The same attack on other vertices: 200,000 copies of one face, each on its own three
/// vertices, and 200,000 triangles that are one point. Before, the BVH build of such a mesh
/// never ended (`bspvt-server bake` was still building after 120 s with 300,000 of each kind,
/// in PLOC's search for the best pair); now the copies and the points are left out of the
/// BVH with a warning, the first chunk is durable in seconds, and `DELETE` answers at once.
#[test]
fn coincident_faces_on_their_own_vertices_and_point_triangles_do_not_stall() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), &["--workers", "1"]);
    let a = agent();
    let obj = "v 0 0 0\nv 1 0 0\nv 0 0 1\nf -3 -1 -2\n".repeat(200_000)
        + &"v 0.5 0 0.5\nv 0.5 0 0.5\nv 0.5 0 0.5\nf -3 -2 -1\n".repeat(200_000);
    let z = zstd::bulk::compress(obj.as_bytes(), 19).unwrap();
    let t = std::time::Instant::now();
    let id = submit_ok(
        &a,
        &srv,
        &[
            ("mesh", Some("coincident.obj.zst"), &z),
            (
                "settings",
                None,
                br#"{"face_res": 8, "chunk_vertices": 1024}"#,
            ),
        ],
        None,
    );
    let s = wait_status(&a, &srv, &id, std::time::Duration::from_secs(60), |s| {
        s["chunks_done"].as_u64().unwrap_or(0) >= 1
    });
    eprintln!(
        "first chunk durable {:.1} s after the upload",
        t.elapsed().as_secs_f64()
    );
    let warnings = s["warnings"].to_string();
    assert!(warnings.contains("399999 triangles repeat"), "{s}");
    let t = std::time::Instant::now();
    let d = delete(&a, &srv.url(&format!("/v1/scenes/{id}")), None);
    assert_eq!(d.status, 200);
    assert!(
        t.elapsed() < std::time::Duration::from_secs(1),
        "{:?}",
        t.elapsed()
    );
}
