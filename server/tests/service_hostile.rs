//! Hostile input: a corpus of malformed, oversized, unauthorised and nonsensical requests
//! against a real server with an API key and small limits. Each gets the expected 4xx with a
//! JSON body naming the problem; afterwards the server is healthy, still bakes, and its
//! resident memory stayed bounded over repeated rounds of the corpus.

#![allow(clippy::unwrap_used)]

mod common;

use std::time::Duration;

use common::*;

const MAX_BODY: usize = 4 << 20;
const MAX_MESH: usize = 2 << 20;

type Send = Box<dyn Fn(&Server, &ureq::Agent) -> Resp>;

struct Case {
    name: &'static str,
    status: u16,
    /// Expected `error` code (None: any).
    code: Option<&'static str>,
    send: Send,
}

fn form(
    parts: Vec<(&'static str, Option<&'static str>, Vec<u8>)>,
    key: Option<&'static str>,
) -> Send {
    Box::new(move |srv, a| {
        let p: Vec<Part> = parts.iter().map(|(n, f, d)| (*n, *f, &d[..])).collect();
        submit(a, srv, &p, key)
    })
}

fn mesh(file: &'static str, data: impl Into<Vec<u8>>) -> Send {
    form(vec![("mesh", Some(file), data.into())], Some(API_KEY))
}

fn scene(json: impl Into<Vec<u8>>) -> Send {
    form(vec![("scene", None, json.into())], Some(API_KEY))
}

fn raw_post(headers: &'static str, body: Vec<u8>) -> Send {
    Box::new(move |srv, _| {
        let mut req = format!(
            "POST /v1/scenes HTTP/1.1\r\nHost: {}\r\nAuthorization: Bearer {API_KEY}\r\nConnection: close\r\n{headers}\r\n",
            srv.addr
        )
        .into_bytes();
        req.extend_from_slice(&body);
        raw(&srv.addr, &req)
    })
}

fn get_path(path: String) -> Send {
    Box::new(move |srv, a| try_get(a, &srv.url(&path), &[]).unwrap())
}

const GOOD_LIGHT: &str =
    r#"[{"vertices": [[-1,3,-1],[1,3,-1],[1,3,1],[-1,3,1]], "radiance": [1,1,1]}]"#;

fn builtin_scene_with(bake: &str, lights: &str) -> String {
    format!(
        r#"{{"meshes": [{{"path": "builtin:plate-small"}}], "materials": [{{}}, {{}}, {{}}],
            "lights": {lights}, "bake": {bake}}}"#
    )
}

fn corpus(done_id: &str) -> Vec<Case> {
    let bad_id = "0123456789abcdef0123456789abcdef";
    let tri = b"v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 3 2\n".to_vec();
    let mut ply_trunc =
        b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    ply_trunc.extend(std::iter::repeat_n(0u8, 120));
    let mut ply_absurd =
        b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    ply_absurd.extend(std::iter::repeat_n(0u8, 64));
    let mut ply_many =
        b"ply\nformat binary_little_endian 1.0\nelement vertex 30000\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    ply_many.extend(std::iter::repeat_n(0u8, 30_000 * 12));
    ply_many.extend([3, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0]);
    let mut big_obj = String::new();
    for i in 0..25_000 {
        big_obj += &format!("v {i} 0 {}\n", i % 7);
    }
    big_obj += "f 1 2 3\n";
    let bomb = zstd::bulk::compress(&vec![b' '; 64 << 20], 19).unwrap();
    let mut glb_trunc = b"glTF".to_vec();
    glb_trunc.extend(2u32.to_le_bytes());
    glb_trunc.extend(100_000u32.to_le_bytes());
    glb_trunc.extend(b"\x10\x00\x00\x00JSON{\"asset\"");
    let ext_gltf = br#"{"asset": {"version": "2.0"}, "buffers": [{"uri": "../../../etc/passwd", "byteLength": 36}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}]}"#
        .to_vec();
    let key_ok = Some(API_KEY);
    let c = |name, status, code, send| Case {
        name,
        status,
        code,
        send,
    };
    vec![
        // Access.
        c(
            "no API key",
            401,
            Some("unauthorized"),
            form(vec![("mesh", Some("t.obj"), tri.clone())], None),
        ),
        c(
            "wrong API key",
            401,
            Some("unauthorized"),
            form(vec![("mesh", Some("t.obj"), tri.clone())], Some("nope")),
        ),
        c(
            "basic auth instead of bearer",
            401,
            Some("unauthorized"),
            Box::new(|srv, a| {
                let r = a
                    .post(srv.url("/v1/scenes"))
                    .header("Authorization", "Basic dXNlcjpwYXNz")
                    .send(&b""[..])
                    .unwrap();
                resp(r)
            }),
        ),
        c(
            // The scheme is case-insensitive (RFC 9110 §11.1): auth passes, the body is refused.
            "lower-case bearer scheme",
            415,
            Some("not_multipart"),
            Box::new(|srv, a| {
                let r = a
                    .post(srv.url("/v1/scenes"))
                    .header("Authorization", format!("bearer {API_KEY}"))
                    .send(&b""[..])
                    .unwrap();
                resp(r)
            }),
        ),
        c(
            "delete without key",
            401,
            Some("unauthorized"),
            Box::new(move |srv, a| delete(a, &srv.url(&format!("/v1/scenes/{bad_id}")), None)),
        ),
        c(
            "delete with wrong key",
            401,
            Some("unauthorized"),
            Box::new(move |srv, a| delete(a, &srv.url(&format!("/v1/scenes/{bad_id}")), Some("x"))),
        ),
        // Forms.
        c(
            "JSON body instead of a form",
            415,
            Some("not_multipart"),
            raw_post(
                "Content-Type: application/json\r\nContent-Length: 2\r\n",
                b"{}".to_vec(),
            ),
        ),
        c(
            "multipart without boundary",
            415,
            Some("not_multipart"),
            raw_post(
                "Content-Type: multipart/form-data\r\nContent-Length: 4\r\n",
                b"junk".to_vec(),
            ),
        ),
        c(
            "garbage multipart body",
            400,
            Some("invalid_multipart"),
            raw_post(
                "Content-Type: multipart/form-data; boundary=XYZ\r\nContent-Length: 19\r\n",
                b"this is not a form\n".to_vec(),
            ),
        ),
        c(
            "empty form",
            400,
            Some("missing_field"),
            form(vec![], key_ok),
        ),
        c(
            "unknown field",
            400,
            Some("unknown_field"),
            form(vec![("meshh", Some("t.obj"), tri.clone())], key_ok),
        ),
        c(
            "two mesh fields",
            400,
            Some("duplicate_field"),
            form(
                vec![
                    ("mesh", Some("a.obj"), tri.clone()),
                    ("mesh", Some("b.obj"), tri.clone()),
                ],
                key_ok,
            ),
        ),
        c(
            "mesh without file name",
            400,
            Some("missing_file_name"),
            form(vec![("mesh", None, tri.clone())], key_ok),
        ),
        c(
            "a mesh's file named out of its folder",
            400,
            Some("invalid_file_name"),
            form(
                vec![
                    ("mesh", Some("t.obj"), tri.clone()),
                    ("file", Some("../t.mtl"), b"newmtl a".to_vec()),
                ],
                key_ok,
            ),
        ),
        c(
            "a mesh's file named twice",
            400,
            Some("duplicate_field"),
            form(
                vec![
                    ("mesh", Some("t.obj"), tri.clone()),
                    ("file", Some("t.mtl"), b"newmtl a".to_vec()),
                    ("file", Some("t.mtl"), b"newmtl b".to_vec()),
                ],
                key_ok,
            ),
        ),
        c(
            "a file but neither mesh nor scene",
            400,
            Some("missing_field"),
            form(vec![("file", Some("t.mtl"), b"newmtl a".to_vec())], key_ok),
        ),
        c(
            "unsupported mesh format",
            415,
            Some("unsupported_mesh_format"),
            mesh("model.stl", tri.clone()),
        ),
        // Meshes.
        c(
            "empty mesh",
            422,
            Some("invalid_mesh"),
            mesh("e.obj", Vec::new()),
        ),
        c(
            "truncated binary PLY",
            422,
            Some("invalid_mesh"),
            mesh("t.ply", ply_trunc),
        ),
        c(
            "corrupt PLY header",
            422,
            Some("invalid_mesh"),
            mesh(
                "c.ply",
                b"ply\nformat nonsense 9.0\nelement vertex 3\nend_header\n".to_vec(),
            ),
        ),
        c(
            "PLY declaring 4e9 vertices",
            422,
            Some("invalid_mesh"),
            mesh("a.ply", ply_absurd),
        ),
        c(
            "PLY with more vertices than allowed",
            413,
            Some("mesh_too_large"),
            mesh("many.ply", ply_many),
        ),
        c(
            "NaN coordinate",
            422,
            Some("invalid_mesh"),
            mesh("n.obj", b"v 0 0 0\nv nan 0 0\nv 0 0 1\nf 1 2 3\n".to_vec()),
        ),
        c(
            "zero triangles",
            422,
            Some("invalid_mesh"),
            mesh("z.obj", b"v 0 0 0\nv 1 0 0\nv 0 0 1\n".to_vec()),
        ),
        c(
            "index out of range",
            422,
            Some("invalid_mesh"),
            mesh("i.obj", b"v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 2 99\n".to_vec()),
        ),
        c(
            "truncated GLB",
            422,
            Some("invalid_mesh"),
            mesh("t.glb", glb_trunc),
        ),
        c(
            "GLB with bad magic",
            422,
            Some("invalid_mesh"),
            mesh("m.glb", b"GLTF\x02\x00\x00\x00\x0c\x00\x00\x00".to_vec()),
        ),
        c(
            "glTF with an external buffer",
            422,
            Some("invalid_mesh"),
            mesh("x.gltf", ext_gltf),
        ),
        c(
            "corrupt glTF JSON",
            422,
            Some("invalid_mesh"),
            mesh("x.gltf", b"{\"asset\": [1, 2".to_vec()),
        ),
        c(
            "mesh over the vertex limit",
            413,
            Some("mesh_too_large"),
            mesh("big.obj", big_obj),
        ),
        c(
            "zstd bomb",
            413,
            Some("mesh_too_large"),
            mesh("bomb.obj.zst", bomb),
        ),
        c(
            "corrupt zstd",
            422,
            Some("invalid_compression"),
            mesh(
                "c.obj.zst",
                b"\x28\xb5\x2f\xfd\x00\x58garbage-garbage".to_vec(),
            ),
        ),
        c(
            "mesh field over the mesh limit",
            413,
            Some("field_too_large"),
            mesh("huge.obj", vec![b'#'; MAX_MESH + 1]),
        ),
        c(
            "declared body over the limit",
            413,
            Some("body_too_large"),
            raw_post(
                "Content-Type: multipart/form-data; boundary=XYZ\r\nContent-Length: 104857600\r\n",
                Vec::new(),
            ),
        ),
        c(
            "chunked body over the limit",
            413,
            None,
            Box::new(|srv, _| {
                let mut req = format!(
                "POST /v1/scenes HTTP/1.1\r\nHost: {}\r\nAuthorization: Bearer {API_KEY}\r\nConnection: close\r\nContent-Type: multipart/form-data; boundary={BOUNDARY}\r\nTransfer-Encoding: chunked\r\n\r\n",
                srv.addr
            ).into_bytes();
                let head = format!(
                    "--{BOUNDARY}\r\nContent-Disposition: form-data; name=\"scene\"\r\n\r\n"
                );
                let mut body = head.into_bytes();
                body.resize(MAX_BODY + 1024, b' ');
                for piece in body.chunks(256 << 10) {
                    req.extend_from_slice(format!("{:x}\r\n", piece.len()).as_bytes());
                    req.extend_from_slice(piece);
                    req.extend_from_slice(b"\r\n");
                }
                req.extend_from_slice(b"0\r\n\r\n");
                raw(&srv.addr, &req)
            }),
        ),
        // Scenes and settings.
        c(
            "scene is not JSON",
            400,
            Some("invalid_scene_json"),
            scene("{{{"),
        ),
        c(
            "scene with a wrong type",
            422,
            Some("invalid_scene"),
            scene(builtin_scene_with(r#"{"face_res": "big"}"#, GOOD_LIGHT)),
        ),
        c(
            "scene with an unknown field",
            422,
            Some("invalid_scene"),
            scene(r#"{"meshes": [{"path": "builtin:plate-small"}], "lights": [], "colour": 1}"#),
        ),
        // (A scene without lights is valid: its bake is the sky's.)
        c(
            "scene with a light of zero area",
            422,
            Some("invalid_scene"),
            scene(builtin_scene_with(
                "{}",
                r#"[{"vertices": [[0, 1, 0], [1, 1, 0], [2, 1, 0]], "radiance": [1, 1, 1]}]"#,
            )),
        ),
        c(
            "scene naming a server path",
            422,
            Some("invalid_scene"),
            form(
                vec![
                    ("mesh", Some("t.obj"), tri.clone()),
                    (
                        "scene",
                        None,
                        br#"{"meshes": [{"path": "../../../etc/passwd"}], "lights": []}"#.to_vec(),
                    ),
                ],
                key_ok,
            ),
        ),
        c(
            "scene naming a mesh not uploaded",
            400,
            Some("missing_field"),
            scene(r#"{"meshes": [{"path": "model.glb"}], "lights": []}"#),
        ),
        c(
            "face_res out of range",
            422,
            Some("invalid_scene"),
            scene(builtin_scene_with(r#"{"face_res": 100000}"#, GOOD_LIGHT)),
        ),
        c(
            "face_res over the server's limit",
            422,
            Some("invalid_settings"),
            scene(builtin_scene_with(r#"{"face_res": 512}"#, GOOD_LIGHT)),
        ),
        c(
            "infinite light coordinate",
            422,
            Some("invalid_scene"),
            scene(builtin_scene_with(
                "{}",
                r#"[{"vertices": [[-1,3,-1],[1e39,3,-1],[1,3,1]], "radiance": [1,1,1]}]"#,
            )),
        ),
        c(
            "scene field over 1 MiB",
            413,
            Some("field_too_large"),
            scene(vec![b' '; (1 << 20) + 1]),
        ),
        c(
            "scene not UTF-8",
            400,
            Some("invalid_field"),
            scene(vec![0xff, 0xfe, b'{']),
        ),
        c(
            "settings: zero chunk size",
            422,
            Some("invalid_scene"),
            form(
                vec![
                    ("mesh", Some("t.obj"), tri.clone()),
                    ("settings", None, br#"{"chunk_vertices": 0}"#.to_vec()),
                ],
                key_ok,
            ),
        ),
        c(
            "settings not JSON",
            422,
            Some("invalid_settings"),
            form(
                vec![
                    ("mesh", Some("t.obj"), tri.clone()),
                    ("settings", None, b"face_res=8".to_vec()),
                ],
                key_ok,
            ),
        ),
        // Reads.
        c(
            "unknown scene id",
            404,
            Some("not_found"),
            get_path(format!("/v1/scenes/{bad_id}")),
        ),
        c(
            "malformed scene id",
            404,
            Some("not_found"),
            get_path("/v1/scenes/..%2F..%2Fetc".into()),
        ),
        c(
            "trees of an unknown id",
            404,
            Some("not_found"),
            get_path(format!("/v1/scenes/{bad_id}/trees")),
        ),
        c(
            "events of an unknown id",
            404,
            Some("not_found"),
            get_path(format!("/v1/scenes/{bad_id}/events")),
        ),
        c(
            "tree range syntax",
            400,
            Some("invalid_range"),
            get_path(format!("/v1/scenes/{done_id}/trees?vertices=ten..20")),
        ),
        c(
            "tree range outside the scene",
            416,
            Some("invalid_range"),
            get_path(format!("/v1/scenes/{done_id}/trees?vertices=0..999999")),
        ),
        c(
            "tree range empty",
            416,
            Some("invalid_range"),
            get_path(format!("/v1/scenes/{done_id}/trees?vertices=7..7")),
        ),
        c(
            "unknown face",
            400,
            Some("invalid_faces"),
            get_path(format!("/v1/scenes/{done_id}/trees?faces=7")),
        ),
        c(
            "unknown tree parameter",
            400,
            Some("invalid_query"),
            get_path(format!("/v1/scenes/{done_id}/trees?vertex=1..2")),
        ),
        c(
            "bad percent-encoding",
            400,
            Some("invalid_query"),
            get_path(format!("/v1/scenes/{done_id}/trees?faces=%G1")),
        ),
        c(
            "unknown mesh format",
            400,
            Some("invalid_query"),
            get_path(format!("/v1/scenes/{done_id}/mesh?format=stl")),
        ),
        c(
            "delete an unknown id",
            404,
            Some("not_found"),
            Box::new(move |srv, a| {
                delete(a, &srv.url(&format!("/v1/scenes/{bad_id}")), Some(API_KEY))
            }),
        ),
        c(
            "unknown route",
            404,
            Some("not_found"),
            get_path("/v2/everything".into()),
        ),
        c(
            "wrong method",
            405,
            Some("method_not_allowed"),
            Box::new(|srv, a| resp(a.put(srv.url("/v1/scenes")).send(&b"x"[..]).unwrap())),
        ),
    ]
}

fn resp(mut r: ureq::http::Response<ureq::Body>) -> Resp {
    let status = r.status().as_u16();
    let headers = r
        .headers()
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_str().unwrap_or("").to_string()))
        .collect();
    let body = r.body_mut().read_to_vec().unwrap_or_default();
    Resp {
        status,
        headers,
        body,
    }
}

#[test]
fn hostile_requests_get_json_4xx_and_the_server_stays_healthy_and_bounded() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(
        &tmp.path().join("data"),
        &[
            "--api-key",
            API_KEY,
            "--max-body-bytes",
            &MAX_BODY.to_string(),
            "--max-mesh-bytes",
            &MAX_MESH.to_string(),
            "--max-mesh-vertices",
            "20000",
            "--max-face-res",
            "128",
            "--workers",
            "1",
        ],
    );
    let a = agent();
    let good = plate_small_json(8, 512);
    let id = submit_ok(&a, &srv, &[("scene", None, good.as_bytes())], Some(API_KEY));
    wait_done(&a, &srv, &id);
    let cases = corpus(&id);
    assert!(cases.len() >= 30, "only {} cases", cases.len());
    let rss_start = srv.rss_kib();
    let mut rss_rounds = Vec::new();
    // Six rounds: the allocator's arenas fill during the first few, then RSS is flat (12
    // rounds were checked by hand: +0.9 MiB from round 4 to 12). BSPVT_HOSTILE_ROUNDS=N
    // runs more.
    let rounds: usize = std::env::var("BSPVT_HOSTILE_ROUNDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(6)
        .max(6);
    for round in 0..rounds {
        let mut failures = Vec::new();
        for case in &cases {
            let r = (case.send)(&srv, &a);
            let body: Option<serde_json::Value> = serde_json::from_slice(&r.body).ok();
            let code = body
                .as_ref()
                .and_then(|b| b["error"].as_str().map(str::to_string));
            let detail_ok = body
                .as_ref()
                .and_then(|b| b["detail"].as_str())
                .is_some_and(|d| !d.is_empty());
            let code_ok = match case.code {
                Some(c) => code.as_deref() == Some(c),
                None => code.is_some(),
            };
            if r.status != case.status || !code_ok || !detail_ok {
                failures.push(format!(
                    "{}: got {} {}",
                    case.name,
                    r.status,
                    String::from_utf8_lossy(&r.body[..r.body.len().min(300)])
                ));
            } else if round == 0 {
                eprintln!(
                    "{:>3} {:<24} {}",
                    r.status,
                    code.unwrap_or_default(),
                    case.name
                );
            }
        }
        assert!(
            failures.is_empty(),
            "round {round}:\n{}\nserver log tail:\n{}",
            failures.join("\n"),
            srv.log_text()
                .lines()
                .rev()
                .take(30)
                .collect::<Vec<_>>()
                .join("\n")
        );
        rss_rounds.push(srv.rss_kib());
    }
    eprintln!(
        "{} cases × {rounds} rounds; RSS before {} KiB, after each round {:?} KiB",
        cases.len(),
        rss_start,
        rss_rounds
    );
    // Memory stays bounded: far below what the rejected payloads would take if they were
    // buffered (a 64 MiB bomb, a 100 MiB declared body), and flat once the allocator is warm.
    let peak = *rss_rounds.iter().max().unwrap();
    assert!(peak < 256 * 1024, "RSS {peak} KiB");
    let last = *rss_rounds.last().unwrap();
    assert!(
        last < rss_rounds[3] + 16 * 1024,
        "RSS still grows after warm-up: {rss_rounds:?}"
    );

    // Still healthy, still baking, nothing failed server-side.
    let h = get(&a, &srv.url("/healthz"));
    assert_eq!(h.status, 200);
    let id2 = submit_ok(&a, &srv, &[("scene", None, good.as_bytes())], Some(API_KEY));
    wait_done(&a, &srv, &id2);
    let text = get(&a, &srv.url("/metrics")).text();
    assert_eq!(
        metric(&text, "bspvt_http_responses_total{class=\"5xx\"}"),
        0.0
    );
    assert!(
        metric(&text, "bspvt_http_responses_total{class=\"4xx\"}") >= (rounds * cases.len()) as f64
    );
}

#[test]
fn a_full_queue_answers_429_until_a_scene_leaves() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(
        &tmp.path().join("data"),
        &[
            "--max-queued-scenes",
            "1",
            "--workers",
            "1",
            "--threads",
            "1",
        ],
    );
    let a = agent();
    let slow = plate_small_json(64, 64);
    let id = submit_ok(&a, &srv, &[("scene", None, slow.as_bytes())], None);
    let r = submit(&a, &srv, &[("scene", None, slow.as_bytes())], None);
    assert_eq!(r.status, 429, "{}", r.text());
    assert_eq!(r.json()["error"], "queue_full");
    assert!(r.header("retry-after").is_some());
    assert_eq!(
        delete(&a, &srv.url(&format!("/v1/scenes/{id}")), None).status,
        200
    );
    let quick = plate_small_json(8, 1024);
    let id2 = submit_ok(&a, &srv, &[("scene", None, quick.as_bytes())], None);
    wait_status(&a, &srv, &id2, Duration::from_secs(60), |s| {
        s["state"] == "done"
    });
}

#[test]
fn slow_and_excess_connections_are_cut_off() {
    use std::io::{Read, Write};
    use std::net::TcpStream;
    use std::time::Instant;

    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(
        &tmp.path().join("data"),
        &["--header-read-timeout-s", "1", "--max-connections", "4"],
    );
    let open = |addr: &str| {
        let s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        s
    };
    // Eof or reset: the server closed the connection.
    let closed_within = |mut s: TcpStream, limit: Duration| {
        let t0 = Instant::now();
        let mut buf = [0u8; 256];
        let n = s.read(&mut buf).unwrap_or(0);
        assert_eq!(n, 0, "expected the server to close, got {:?}", &buf[..n]);
        assert!(t0.elapsed() < limit, "closed only after {:?}", t0.elapsed());
    };
    // Slowloris: headers never finish.
    let mut slow: Vec<TcpStream> = (0..4).map(|_| open(&srv.addr)).collect();
    for s in &mut slow {
        s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
            .unwrap();
    }
    // A fifth connection is over the limit: closed at once.
    std::thread::sleep(Duration::from_millis(200));
    closed_within(open(&srv.addr), Duration::from_millis(900));
    for s in slow {
        closed_within(s, Duration::from_secs(5));
    }
    // Once the slow ones are gone, service is normal.
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(get(&agent(), &srv.url("/healthz")).status, 200);
}

/// Per-client limits: 8 trickling uploads and 600 idle event streams from one address hold at
/// most `max_uploads_per_client` (2) and `max_streams_per_client` (64) slots, the rest get 429
/// at once; another address (127.0.0.2) still uploads and streams.
#[test]
fn one_address_cannot_hold_every_slot() {
    use std::io::{Read, Write};
    use std::net::{SocketAddr, TcpStream};

    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), &["--workers", "1"]);
    let a = agent();
    let json = plate_small_json(8, 4096);
    let id = submit_ok(&a, &srv, &[("scene", None, json.as_bytes())], None);
    wait_done(&a, &srv, &id);
    let slow = plate_small_json(64, 16);
    let baking = submit_ok(&a, &srv, &[("scene", None, slow.as_bytes())], None);
    let server: SocketAddr = srv.addr.parse().unwrap();

    // A connection from `from` (127.0.0.1: the test's default).
    let connect = |from: [u8; 4]| -> TcpStream {
        let sock = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None)
            .expect("socket");
        sock.bind(&SocketAddr::from((from, 0)).into())
            .expect("bind");
        sock.connect(&server.into()).expect("connect");
        let s: TcpStream = sock.into();
        s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
        s
    };
    // The status code of the response on `s` (reads the status line only).
    let status = |s: &mut TcpStream| -> u16 {
        let mut line = Vec::new();
        let mut b = [0u8; 1];
        while !line.ends_with(b"\r\n") {
            match s.read(&mut b) {
                Ok(1) => line.push(b[0]),
                _ => panic!("no status line: {:?}", String::from_utf8_lossy(&line)),
            }
        }
        let text = String::from_utf8_lossy(&line);
        text.split(' ')
            .nth(1)
            .and_then(|c| c.parse().ok())
            .unwrap_or(0)
    };
    // Headers and the first bytes of a 100 kB body, then nothing. One write: a refused
    // upload is answered (and closed) as soon as its headers are read.
    let trickle = |from: [u8; 4]| {
        let mut s = connect(from);
        let head = format!(
            "POST /v1/scenes HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; \
             boundary={BOUNDARY}\r\nContent-Length: 100000\r\n\r\n--{BOUNDARY}\r\n"
        );
        let _ = s.write_all(head.as_bytes());
        s
    };

    // Eight trickling uploads from 127.0.0.1: two hold their slots, six are refused at once.
    let mut uploads: Vec<TcpStream> = Vec::new();
    for _ in 0..2 {
        uploads.push(trickle([127, 0, 0, 1]));
    }
    std::thread::sleep(Duration::from_millis(300));
    for _ in 0..6 {
        let mut s = trickle([127, 0, 0, 1]);
        assert_eq!(status(&mut s), 429, "a third upload from one address");
    }
    // 600 idle event streams from 127.0.0.1 on a scene still baking (a finished scene's
    // event stream ends at once): 64 open, the rest refused.
    let mut events: Vec<TcpStream> = Vec::new();
    let (mut open, mut refused) = (0, 0);
    for _ in 0..600 {
        let mut s = connect([127, 0, 0, 1]);
        write!(
            s,
            "GET /v1/scenes/{baking}/events HTTP/1.1\r\nHost: x\r\n\r\n"
        )
        .unwrap();
        match status(&mut s) {
            200 => {
                open += 1;
                events.push(s);
            }
            429 => refused += 1,
            other => panic!("events: status {other}"),
        }
    }
    assert_eq!((open, refused), (64, 536));
    let st = get(&a, &srv.url(&format!("/v1/scenes/{baking}"))).json();
    assert_ne!(
        st["state"], "done",
        "the scene finished during the test: {st}"
    );

    // Another address uploads and streams as if nothing were going on.
    let body = multipart(&[("scene", None, plate_small_json(8, 4096).as_bytes())]);
    let mut up = connect([127, 0, 0, 2]);
    write!(
        up,
        "POST /v1/scenes HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; \
         boundary={BOUNDARY}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    )
    .unwrap();
    up.write_all(&body).unwrap();
    assert_eq!(status(&mut up), 202, "an upload from 127.0.0.2");
    let mut tr = connect([127, 0, 0, 2]);
    write!(
        tr,
        "GET /v1/scenes/{id}/trees HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    assert_eq!(status(&mut tr), 200, "a tree stream from 127.0.0.2");
    drop((uploads, events));
}

/// An upload that stops sending is cut off after `--body-read-timeout-s` of silence (408), and
/// its slot is free again at once.
#[test]
fn a_stalled_upload_times_out_and_frees_its_slot() {
    use std::io::{Read, Write};
    use std::net::TcpStream;
    use std::time::Instant;

    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(
        &tmp.path().join("data"),
        &[
            "--body-read-timeout-s",
            "1",
            "--max-uploads-per-client",
            "1",
        ],
    );
    let mut s = TcpStream::connect(&srv.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let head = format!(
        "POST /v1/scenes HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; \
         boundary={BOUNDARY}\r\nContent-Length: 100000\r\n\r\n--{BOUNDARY}\r\n"
    );
    s.write_all(head.as_bytes()).unwrap();
    let t0 = Instant::now();
    let mut reply = Vec::new();
    let mut buf = [0u8; 4096];
    while !String::from_utf8_lossy(&reply).contains("body_timeout") {
        match s.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => reply.extend_from_slice(&buf[..n]),
        }
    }
    let text = String::from_utf8_lossy(&reply);
    assert!(text.starts_with("HTTP/1.1 408"), "{text}");
    assert!(text.contains("body_timeout"), "{text}");
    let waited = t0.elapsed();
    assert!(
        waited >= Duration::from_millis(900) && waited < Duration::from_secs(10),
        "{waited:?}"
    );
    // The one upload slot of this address is free again.
    let json = plate_small_json(8, 4096);
    submit_ok(&agent(), &srv, &[("scene", None, json.as_bytes())], None);
}

/// A client that closes the connection in the middle of an upload is not a server error: the
/// request counts as 499 (nginx's "client closed request") in 4xx and in
/// `bspvt_http_client_aborts_total`, never in 5xx, and the service goes on.
#[test]
fn a_client_abort_is_counted_apart_from_server_errors() {
    use std::io::Write;
    use std::net::TcpStream;

    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), &[]);
    let metric = |name: &str| -> u64 {
        let text = get(&agent(), &srv.url("/metrics")).text();
        text.lines()
            .find_map(|l| l.strip_prefix(name)?.trim().parse().ok())
            .unwrap_or_else(|| panic!("no {name} in {text}"))
    };
    let before_5xx = metric("bspvt_http_responses_total{class=\"5xx\"}");
    let before_aborts = metric("bspvt_http_client_aborts_total");
    assert_eq!(before_aborts, 0);
    {
        let mut s = TcpStream::connect(&srv.addr).unwrap();
        let head = format!(
            "POST /v1/scenes HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; \
             boundary={BOUNDARY}\r\nContent-Length: 100000\r\n\r\n--{BOUNDARY}\r\n\
             Content-Disposition: form-data; name=\"mesh\"; filename=\"m.obj\"\r\n\r\nv 0 0 0\n"
        );
        s.write_all(head.as_bytes()).unwrap();
        s.flush().unwrap();
        std::thread::sleep(Duration::from_millis(200));
        // Dropped here: the body ends 99.9 KB early.
    }
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while metric("bspvt_http_client_aborts_total") == 0 {
        assert!(
            std::time::Instant::now() < deadline,
            "the abort was never counted"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(metric("bspvt_http_client_aborts_total"), 1);
    assert_eq!(
        metric("bspvt_http_responses_total{class=\"5xx\"}"),
        before_5xx
    );
    assert_eq!(get(&agent(), &srv.url("/healthz")).status, 200);
}

/// The coverage-guided fuzz targets' entry points (`fuzz/`): every input a fuzzer found
/// crashing, kept under `fuzz/regressions/<target>/`, now returns without a panic; and each entry
/// point accepts a valid input, so a target is not fuzzing a wall of early errors.
#[test]
fn fuzz_regressions_replay_and_the_targets_accept_valid_input() {
    use bspvt_proto::import::Format;
    use bspvt_server::service::fuzz;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let read = |rel: &str| std::fs::read(root.join(rel)).unwrap();
    // Valid inputs are accepted.
    let cornell = read("assets/rooms/cornell-box.obj");
    let mtl = read("assets/rooms/cornell-box.mtl");
    let b = fuzz::BOUNDARY;
    let settings = r#"{"face_res": 16, "epsilon": 0.001, "supersampling": 1, "split": "default", "chunk_vertices": 64}"#;
    let mut body = Vec::new();
    for (head, data) in [
        (
            "name=\"mesh\"; filename=\"cornell-box.obj\"",
            cornell.as_slice(),
        ),
        (
            "name=\"file\"; filename=\"cornell-box.mtl\"",
            mtl.as_slice(),
        ),
        // Without refinement (seconds for a room in a debug build).
        ("name=\"settings\"", settings.as_bytes()),
    ] {
        body.extend(format!("--{b}\r\nContent-Disposition: form-data; {head}\r\n\r\n").bytes());
        body.extend(data);
        body.extend(b"\r\n");
    }
    body.extend(format!("--{b}--\r\n").bytes());
    assert!(
        fuzz::upload(&body),
        "the upload target refuses a valid form"
    );
    assert!(!fuzz::upload(b"not a form"));
    let plate = read("assets/scenes/plate.json");
    assert!(
        fuzz::scene_json(&plate),
        "the scene target refuses plate.json"
    );
    assert!(!fuzz::scene_json(b"{\"meshes\": 3}"));
    assert!(bspvt_tests::fuzz::import(&cornell, Format::Obj));
    assert!(bspvt_tests::fuzz::import(
        &read("assets/rooms/room.gltf"),
        Format::Gltf
    ));
    // Every saved crash replays through its target.
    let mut replayed = 0;
    let dir = root.join("fuzz/regressions");
    for target in std::fs::read_dir(&dir).unwrap() {
        let target = target.unwrap().path();
        if !target.is_dir() {
            continue;
        }
        let name = target.file_name().unwrap().to_string_lossy().to_string();
        for case in std::fs::read_dir(&target).unwrap() {
            let case = case.unwrap().path();
            let data = std::fs::read(&case).unwrap();
            eprintln!("replaying {}", case.display());
            let _accepted = match name.as_str() {
                "gltf" => bspvt_tests::fuzz::import(&data, Format::Gltf),
                "glb" => bspvt_tests::fuzz::import(&data, Format::Glb),
                "obj" => bspvt_tests::fuzz::import(&data, Format::Obj),
                "ply" => bspvt_tests::fuzz::import(&data, Format::Ply),
                "bake" => bspvt_tests::fuzz::decode(&data),
                "scene_json" => fuzz::scene_json(&data),
                "upload" => fuzz::upload(&data),
                other => panic!("fuzz/regressions/{other}: no such fuzz target"),
            };
            replayed += 1;
        }
    }
    eprintln!("replayed {replayed} fuzz regressions");
}
