//! What the browser viewer reads, on a real `bspvt-server serve` over loopback: the trees as
//! GPU words (`trees?format=gpu`) hold, chunk by chunk, exactly the words of the trees the
//! encoded stream carries; a vertex range selects the same chunks; the two forms have their
//! own validators; they are gzipped for a client that accepts it. The scene bundle (`gpu-scene`) holds the mesh as baked, the camera, the
//! light with its region, and the LTC table.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use bspvt_proto::encoding::decode_bake;
use bspvt_shaders::gpu::trees;
use common::*;

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

/// The chunks of a `format=gpu` body: (first vertex, roots, node words), after checking the
/// header against `codec_header`.
fn gpu_chunks(body: &[u8], expect_header: &[u8]) -> Vec<(u32, Vec<u32>, Vec<u32>)> {
    assert!(body.starts_with(expect_header), "the BVGT header differs");
    let mut at = expect_header.len();
    let mut out = Vec::new();
    while at < body.len() {
        assert_eq!(&body[at..at + 4], b"BVGC");
        let (first, count, nodes) = (
            u32_at(body, at + 4),
            u32_at(body, at + 8) as usize,
            u32_at(body, at + 12) as usize,
        );
        let words = |from: usize, n: usize| (0..n).map(|k| u32_at(body, from + 4 * k)).collect();
        let roots: Vec<u32> = words(at + 16, count * 6);
        let node_words: Vec<u32> = words(at + 16 + count * 24, nodes * 2);
        at += 16 + count * 24 + nodes * 8;
        out.push((first, roots, node_words));
    }
    assert_eq!(at, body.len(), "the body ends inside a chunk");
    out
}

#[test]
fn gpu_words_stream_the_same_trees_and_the_scene_bundle_holds_the_baked_scene() {
    let tmp = tempfile::tempdir().unwrap();
    let srv = start(&tmp.path().join("data"), &[]);
    let a = agent();
    let scene = plate_small_json(16, 256);
    let id = submit_ok(
        &a,
        &srv,
        &[("scene", Some("p.json"), scene.as_bytes())],
        None,
    );
    wait_done(&a, &srv, &id);

    let encoded = get(&a, &srv.url(&format!("/v1/scenes/{id}/trees")));
    let bake = decode_bake(&encoded.body).expect("the encoded stream decodes");
    let h = &bake.header;
    let gpu = get(&a, &srv.url(&format!("/v1/scenes/{id}/trees?format=gpu")));
    assert_eq!(gpu.status, 200);
    assert_eq!(
        gpu.header("content-type"),
        Some("application/vnd.bspvt-gpu")
    );
    assert_ne!(
        gpu.header("etag"),
        encoded.header("etag"),
        "one validator per form"
    );
    assert!(
        gpu.header("etag").is_some(),
        "a finished stream has a validator"
    );

    // The header: version, counts, the codec's offsets, half step and normal table.
    let codec = h.codec();
    let (offsets, half_step) = trees::codec_params(&codec);
    let normals = trees::line_normals(&codec);
    let mut header = b"BVGT".to_vec();
    for x in [
        1,
        h.vertex_count,
        h.chunk_vertices,
        offsets,
        normals.len() as u32,
    ] {
        header.extend_from_slice(&x.to_le_bytes());
    }
    header.extend_from_slice(&half_step.to_le_bytes());
    for n in normals.iter().flatten() {
        header.extend_from_slice(&n.to_le_bytes());
    }
    let chunks = gpu_chunks(&gpu.body, &header);
    assert_eq!(
        chunks.len() as u32,
        h.vertex_count.div_ceil(h.chunk_vertices)
    );
    // Chunk by chunk, in order: the words of the decoded trees, roots relative to the chunk.
    let mut v = 0u32;
    for (first, roots, words) in &chunks {
        assert_eq!(*first, v);
        let count = roots.len() / 6;
        let mut expect_nodes = Vec::new();
        let mut expect_roots = Vec::new();
        for t in &bake.trees[v as usize..v as usize + count] {
            expect_roots.extend(trees::encode_vertex(t, 0, &mut expect_nodes));
        }
        assert_eq!(roots, &expect_roots, "roots of the chunk at {v}");
        let flat: Vec<u32> = expect_nodes.iter().flatten().copied().collect();
        assert_eq!(words, &flat, "nodes of the chunk at {v}");
        v += count as u32;
    }
    assert_eq!(v, h.vertex_count);

    // A vertex range: the chunks that intersect it, in the same words.
    let part = get(
        &a,
        &srv.url(&format!(
            "/v1/scenes/{id}/trees?format=gpu&vertices=300..520"
        )),
    );
    assert_eq!(part.header("x-bspvt-chunks"), Some("1..3"));
    assert_eq!(gpu_chunks(&part.body, &header), chunks[1..3].to_vec());
    let bad = try_get(
        &a,
        &srv.url(&format!("/v1/scenes/{id}/trees?format=png")),
        &[],
    )
    .unwrap();
    assert_eq!(bad.status, 400, "{}", bad.text());

    // gzip when asked for, on the GPU words only (the encoded stream is zstd inside).
    let gz = |path: &str| {
        raw(
            &srv.addr,
            format!(
                "GET {path} HTTP/1.1\r\nHost: x\r\nAccept-Encoding: gzip\r\nConnection: close\r\n\r\n"
            )
            .as_bytes(),
        )
    };
    let words = gz(&format!("/v1/scenes/{id}/trees?format=gpu"));
    assert_eq!(words.status, 200);
    assert_eq!(words.header("content-encoding"), Some("gzip"));
    assert!(
        words.body.len() * 2 < gpu.body.len(),
        "gzip saves: {}",
        words.body.len()
    );
    let plain = gz(&format!("/v1/scenes/{id}/trees"));
    assert_eq!(plain.header("content-encoding"), None);

    // The scene bundle.
    let bundle = get(&a, &srv.url(&format!("/v1/scenes/{id}/gpu-scene")));
    assert_eq!(bundle.status, 200);
    let b = &bundle.body;
    assert_eq!(&b[..4], b"BVGS");
    let len = u32_at(b, 4) as usize;
    assert_eq!(len % 4, 0);
    let doc: serde_json::Value = serde_json::from_slice(&b[8..8 + len]).unwrap();
    let mesh = get(&a, &srv.url(&format!("/v1/scenes/{id}/mesh"))).json();
    let n = mesh["positions"].as_array().unwrap().len();
    let t = mesh["triangles"].as_array().unwrap().len();
    assert_eq!(doc["vertices"], n);
    assert_eq!(doc["triangles"], t);
    assert_eq!(n as u32, h.vertex_count);
    let section = |name: &str| {
        let s = &doc["sections"][name];
        (
            s[0].as_u64().unwrap() as usize,
            s[1].as_u64().unwrap() as usize,
        )
    };
    assert_eq!(section("verts").1, 64 * n);
    assert_eq!(section("tris").1, 16 * t);
    let size = doc["ltc_size"].as_u64().unwrap() as usize;
    assert_eq!(section("ltc").1, size * size * 32);
    // The first vertex's record: its position as baked.
    let (off, _) = section("verts");
    let f = |k: usize| f32::from_le_bytes(b[8 + len + off + 4 * k..][..4].try_into().unwrap());
    let p0 = &mesh["positions"][0];
    for k in 0..3 {
        assert_eq!(f64::from(f(k)), p0[k].as_f64().unwrap());
    }
    // f32 values written as JSON: compared in f32.
    let f32s = |v: &serde_json::Value| -> Vec<f32> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap() as f32)
            .collect()
    };
    assert_eq!(f32s(&doc["camera"]["position"]), [3.2f32, 3.0, 4.2]);
    let light = &doc["lights"][0];
    assert_eq!(light["vertices"].as_array().unwrap().len(), 4);
    // Its shader record (bspvt_shaders::gpu::lights): a one-sided polygon, its corners.
    assert_eq!(light["kind"], "polygon");
    assert_eq!(light["count"], 4);
    let record = &light["record"];
    assert_eq!(record.as_array().unwrap().len(), 10);
    assert_eq!(record[0][3], 0.0);
    assert_eq!(f32s(&record[2])[..3], f32s(&light["vertices"][0])[..]);
    assert_eq!(f32s(&light["region"]["min"]), [-2.5f32, 2.0, -2.5]);
    assert_eq!(doc["not_shown"], serde_json::json!([]));
    let etag = bundle.header("etag").unwrap().to_string();
    let again = try_get(
        &a,
        &srv.url(&format!("/v1/scenes/{id}/gpu-scene")),
        &[("If-None-Match", &etag)],
    )
    .unwrap();
    assert_eq!(again.status, 304);
}

/// A glTF room lit by a point light, a spot and a sun (`assets/rooms/punctual-room.gltf`):
/// the bundle gives the page each as its shader record — the two spheres at their nodes with
/// the spot's cone, the sun's disk toward the sun — and says what the page leaves out (the
/// sun's shadows, which are the sky's bake).
#[test]
fn the_scene_bundle_holds_point_spot_and_sun_lights() {
    let tmp = tempfile::tempdir().unwrap();
    let srv = start(&tmp.path().join("data"), &[]);
    let a = agent();
    let gltf =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/rooms/punctual-room.gltf");
    let bytes = std::fs::read(&gltf).unwrap();
    let id = submit_ok(
        &a,
        &srv,
        &[("mesh", Some("punctual-room.gltf"), &bytes)],
        None,
    );
    let bundle = get(&a, &srv.url(&format!("/v1/scenes/{id}/gpu-scene")));
    assert_eq!(bundle.status, 200);
    let len = u32_at(&bundle.body, 4) as usize;
    let doc: serde_json::Value = serde_json::from_slice(&bundle.body[8..8 + len]).unwrap();
    let lights = doc["lights"].as_array().unwrap();
    let kinds: Vec<&str> = lights.iter().map(|l| l["kind"].as_str().unwrap()).collect();
    assert_eq!(kinds, ["sphere", "sphere", "sun"], "{doc}");
    let word = |l: &serde_json::Value, w: usize, k: usize| l["record"][w][k].as_f64().unwrap();
    for l in lights {
        // Twelve: the sides of the round polygon the shaders make of a sphere or a disk.
        assert_eq!(l["count"], 12);
        let kind = if l["kind"] == "sun" { 3.0 } else { 2.0 };
        assert_eq!(word(l, 0, 3), kind);
    }
    // The spheres sit at their nodes, of the default radius; the spot's cone is its own.
    for l in &lights[..2] {
        for k in 0..3 {
            assert_eq!(word(l, 2, k), l["vertices"][0][k].as_f64().unwrap());
        }
        assert_eq!(
            word(l, 2, 3) as f32,
            bspvt_proto::scene::DEFAULT_SPHERE_RADIUS
        );
    }
    assert_eq!(word(&lights[0], 4, 2), 0.0, "the bulb is not a spot");
    assert_eq!(word(&lights[1], 4, 2), 1.0, "the spot is a spot");
    assert!(
        word(&lights[1], 4, 0) > word(&lights[1], 4, 1),
        "cos inner > cos outer"
    );
    // The sun's direction is a unit vector, and its half angle the default's.
    let toward: f64 = (0..3).map(|k| word(&lights[2], 2, k).powi(2)).sum();
    assert!((toward - 1.0).abs() < 1e-6, "{toward}");
    // The sun beside the lamps is drawn unshadowed (its shadows are the sky's bake).
    let shadowed: Vec<bool> = lights
        .iter()
        .map(|l| l["shadowed"].as_bool().unwrap())
        .collect();
    assert_eq!(shadowed, [true, true, false]);
    let not_shown = doc["not_shown"].to_string();
    assert!(not_shown.contains("sun"), "{not_shown}");
    assert!(!not_shown.contains("point or spot"), "{not_shown}");
}
