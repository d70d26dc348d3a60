//! The service as API users meet it, on a real `bspvt-server serve` process over loopback HTTP
//! with its own data folder: the listing (pages, cursor, bad values, the key), CORS preflights
//! allowed and denied, the key as `X-API-Key`, `Idempotency-Key` (a retry gets the first scene
//! and bakes nothing; another body is refused; it survives a restart), the project's own
//! scene files submitted as they are, the request-latency histogram, and the OpenAPI document
//! against the routes the server really answers.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::collections::BTreeSet;
use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use common::*;

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

/// GET with extra headers.
fn get_with(a: &ureq::Agent, url: &str, headers: &[(&str, &str)]) -> Resp {
    try_get(a, url, headers).unwrap_or_else(|e| panic!("GET {url}: {e}"))
}

/// POST /v1/scenes: a multipart form with `boundary`, extra headers.
fn post_form(
    a: &ureq::Agent,
    srv: &Server,
    parts: &[Part],
    boundary: &str,
    headers: &[(&str, &str)],
) -> Resp {
    let body = String::from_utf8(multipart(parts))
        .expect("test forms are text")
        .replace(BOUNDARY, boundary);
    let mut req = a.post(srv.url("/v1/scenes")).header(
        "Content-Type",
        format!("multipart/form-data; boundary={boundary}"),
    );
    for (k, v) in headers {
        req = req.header(*k, *v);
    }
    resp(req.send(body.as_bytes()).expect("POST"))
}

/// A raw request with `method`, no body (answers read by Content-Length).
fn raw_request(srv: &Server, method: &str, path: &str, headers: &[(&str, &str)]) -> Resp {
    let mut req = format!("{method} {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n");
    for (k, v) in headers {
        req.push_str(&format!("{k}: {v}\r\n"));
    }
    req.push_str("Content-Length: 0\r\n\r\n");
    raw(&srv.addr, req.as_bytes())
}

fn bearer() -> String {
    format!("Bearer {API_KEY}")
}

fn list(a: &ureq::Agent, srv: &Server, query: &str) -> Resp {
    get_with(
        a,
        &srv.url(&format!("/v1/scenes{query}")),
        &[("X-API-Key", API_KEY)],
    )
}

#[test]
fn listing_pages_newest_first_and_needs_the_key_as_bearer_or_x_api_key() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(
        &tmp.path().join("data"),
        &["--api-key", API_KEY, "--workers", "1", "--threads", "1"],
    );
    let a = agent();
    let json = plate_small_json(8, 4096);
    let form = [("scene", None, json.as_bytes())];

    // X-API-Key works for writes as Bearer does; a wrong one is refused, even beside a right
    // Bearer.
    let mut ids = Vec::new();
    for i in 0..5 {
        let key = if i % 2 == 0 {
            ("X-API-Key", API_KEY.to_string())
        } else {
            ("Authorization", bearer())
        };
        let r = post_form(&a, &srv, &form, BOUNDARY, &[(key.0, &key.1)]);
        assert_eq!(r.status, 202, "{}", r.text());
        ids.push(r.json()["id"].as_str().unwrap().to_string());
    }
    let wrong = post_form(&a, &srv, &form, BOUNDARY, &[("X-API-Key", "nope")]);
    assert_eq!(
        (wrong.status, wrong.json()["error"].as_str()),
        (401, Some("unauthorized"))
    );
    let mixed = post_form(
        &a,
        &srv,
        &form,
        BOUNDARY,
        &[("Authorization", &bearer()), ("X-API-Key", "nope")],
    );
    assert_eq!(mixed.status, 401, "a wrong X-API-Key beside a right Bearer");

    // The listing needs the key.
    let none = get_with(&a, &srv.url("/v1/scenes"), &[]);
    assert_eq!(none.status, 401);
    assert!(
        none.json()["detail"]
            .as_str()
            .unwrap()
            .contains("X-API-Key")
    );
    assert_eq!(
        get_with(&a, &srv.url("/v1/scenes"), &[("X-API-Key", "wrong")]).status,
        401
    );
    let by_bearer = get_with(&a, &srv.url("/v1/scenes"), &[("Authorization", &bearer())]);
    assert_eq!(by_bearer.status, 200, "{}", by_bearer.text());

    // Pages of two, newest first, followed by their `next` links to the end.
    let mut seen = Vec::new();
    let mut url = "/v1/scenes?limit=2".to_string();
    let mut pages = 0;
    loop {
        let r = get_with(&a, &srv.url(&url), &[("X-API-Key", API_KEY)]);
        assert_eq!(r.status, 200, "{}", r.text());
        let page = r.json();
        let scenes = page["scenes"].as_array().unwrap();
        assert!(scenes.len() <= 2);
        for s in scenes {
            seen.push(s["id"].as_str().unwrap().to_string());
            let status = get(&a, &srv.url(s["links"]["self"].as_str().unwrap())).json();
            assert_eq!(s["vertices_total"], status["vertices_total"]);
            assert_eq!(s["chunks_total"], status["chunks_total"]);
            assert_eq!(s["created_ms"], status["created_ms"]);
            assert_eq!(
                s["links"]["self"],
                format!("/v1/scenes/{}", s["id"].as_str().unwrap())
            );
        }
        pages += 1;
        match page["next"].as_str() {
            Some(next) => {
                assert_eq!(
                    r.header("link"),
                    Some(format!("<{next}>; rel=\"next\"").as_str())
                );
                assert_eq!(
                    page["next_cursor"].as_str(),
                    scenes.last().and_then(|s| s["id"].as_str())
                );
                url = next.to_string();
            }
            None => {
                assert!(r.header("link").is_none());
                assert!(page["next_cursor"].is_null());
                break;
            }
        }
    }
    let newest_first: Vec<String> = ids.iter().rev().cloned().collect();
    assert_eq!(seen, newest_first);
    assert_eq!(pages, 3);

    // A scene submitted while paging does not shift the pages after the cursor.
    // Compared by id: the worker may move a listed scene from queued to baking meanwhile.
    let after_second = format!("?limit=2&after={}", ids[3]);
    let page_ids = |r: Resp| -> Vec<String> {
        r.json()["scenes"]
            .as_array()
            .map(|v| {
                v.iter()
                    .filter_map(|s| s["id"].as_str().map(String::from))
                    .collect()
            })
            .unwrap_or_default()
    };
    let before = page_ids(list(&a, &srv, &after_second));
    assert_eq!(before, [ids[2].clone(), ids[1].clone()]);
    let late = post_form(&a, &srv, &form, BOUNDARY, &[("X-API-Key", API_KEY)]);
    assert_eq!(late.status, 202);
    assert_eq!(page_ids(list(&a, &srv, &after_second)), before);

    // Filters: a deleted scene is listed as cancelled.
    let d = delete(
        &a,
        &srv.url(&format!("/v1/scenes/{}", ids[1])),
        Some(API_KEY),
    );
    assert_eq!(d.status, 200);
    let cancelled = list(&a, &srv, "?state=cancelled").json();
    let c: Vec<&str> = cancelled["scenes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["id"].as_str().unwrap())
        .collect();
    assert_eq!(c, [ids[1].as_str()]);

    // Bad values: a clear 400 each.
    for (q, code, says) in [
        ("?limit=0", "invalid_query", "from 1 to 100"),
        ("?limit=101", "invalid_query", "from 1 to 100"),
        ("?limit=abc", "invalid_query", "\"abc\""),
        ("?limit=-1", "invalid_query", "from 1 to 100"),
        ("?after=xyz", "invalid_cursor", "not a scene id"),
        (
            "?after=0123456789abcdef0123456789abcdef",
            "invalid_cursor",
            "names no scene",
        ),
        ("?state=finished", "invalid_query", "\"finished\""),
        ("?page=2", "invalid_query", "unknown query parameter"),
    ] {
        let r = list(&a, &srv, q);
        assert_eq!(r.status, 400, "{q}: {}", r.text());
        let e = r.json();
        assert_eq!(e["error"], code, "{q}");
        assert!(e["detail"].as_str().unwrap().contains(says), "{q}: {e}");
    }
    let max = list(&a, &srv, "?limit=100");
    assert_eq!(max.status, 200);
    assert_eq!(max.json()["scenes"].as_array().unwrap().len(), 6);
}

#[test]
fn cors_preflights_are_answered_for_allowed_origins_only() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(
        &tmp.path().join("data"),
        &[
            "--api-key",
            API_KEY,
            "--cors-origins",
            "https://app.example,http://localhost:5173",
        ],
    );
    let preflight = |origin: &str| {
        raw_request(
            &srv,
            "OPTIONS",
            "/v1/scenes",
            &[
                ("Origin", origin),
                ("Access-Control-Request-Method", "POST"),
                (
                    "Access-Control-Request-Headers",
                    "x-api-key,idempotency-key,content-type",
                ),
            ],
        )
    };
    for origin in ["https://app.example", "http://localhost:5173"] {
        let ok = preflight(origin);
        assert_eq!(ok.status, 200, "{}", ok.text());
        assert_eq!(ok.header("access-control-allow-origin"), Some(origin));
        let methods = ok.header("access-control-allow-methods").unwrap();
        assert!(
            methods.contains("POST") && methods.contains("DELETE"),
            "{methods}"
        );
        let allowed = ok.header("access-control-allow-headers").unwrap();
        for h in [
            "x-api-key",
            "idempotency-key",
            "authorization",
            "content-type",
        ] {
            assert!(allowed.contains(h), "{h} not in {allowed}");
        }
    }
    let denied = preflight("https://evil.example");
    assert!(
        denied.header("access-control-allow-origin").is_none(),
        "a denied origin was allowed: {:?}",
        denied.headers
    );

    // Real requests: allowed origins may read the answer, errors included, and the headers a
    // client needs; others get no CORS headers.
    let a = agent();
    let r = get_with(
        &a,
        &srv.url("/v1/scenes"),
        &[("Origin", "https://app.example"), ("X-API-Key", API_KEY)],
    );
    assert_eq!(r.status, 200);
    assert_eq!(
        r.header("access-control-allow-origin"),
        Some("https://app.example")
    );
    let exposed = r.header("access-control-expose-headers").unwrap();
    for h in ["location", "etag", "link", "idempotent-replayed"] {
        assert!(exposed.contains(h), "{h} not exposed: {exposed}");
    }
    let unauthorized = get_with(
        &a,
        &srv.url("/v1/scenes"),
        &[("Origin", "https://app.example")],
    );
    assert_eq!(unauthorized.status, 401);
    assert_eq!(
        unauthorized.header("access-control-allow-origin"),
        Some("https://app.example")
    );
    let other = get_with(
        &a,
        &srv.url("/healthz"),
        &[("Origin", "https://evil.example")],
    );
    assert_eq!(other.status, 200);
    assert!(other.header("access-control-allow-origin").is_none());

    // Off by default: no CORS headers, and a preflight is an ordinary OPTIONS (405).
    let plain = start(&tmp.path().join("plain"), &[]);
    let r = raw_request(
        &plain,
        "OPTIONS",
        "/v1/scenes",
        &[
            ("Origin", "https://app.example"),
            ("Access-Control-Request-Method", "POST"),
        ],
    );
    assert_eq!(r.status, 405, "{}", r.text());
    assert!(r.header("access-control-allow-origin").is_none());
}

#[test]
fn idempotency_key_returns_the_first_scene_refuses_another_body_and_survives_a_restart() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let data = tmp.path().join("data");
    let mut srv = start(&data, &["--workers", "1", "--threads", "1"]);
    let a = agent();
    let json = plate_small_json(8, 512);
    let other_json = plate_small_json(8, 1024);
    let form = [("scene", None, json.as_bytes())];
    let key = ("Idempotency-Key", "3f2c7a9e-5d41-4c0b-9e1f-1a2b3c4d5e6f");

    let first = post_form(&a, &srv, &form, BOUNDARY, &[key]);
    assert_eq!(first.status, 202, "{}", first.text());
    let id = first.json()["id"].as_str().unwrap().to_string();
    assert_eq!(first.json()["state"], "queued");
    assert!(first.header("idempotent-replayed").is_none());

    // A retry (as curl would send it: another multipart boundary) gets the same scene.
    let t0 = Instant::now();
    let again = post_form(&a, &srv, &form, "----another-boundary-91", &[key]);
    let replay_ms = t0.elapsed().as_secs_f64() * 1e3;
    assert_eq!(again.status, 200, "{}", again.text());
    assert_eq!(again.json()["id"], id.as_str());
    assert_eq!(again.header("idempotent-replayed"), Some("true"));
    assert_eq!(
        again.header("location"),
        Some(format!("/v1/scenes/{id}").as_str())
    );
    eprintln!("idempotent resubmit answered in {replay_ms:.1} ms");

    // The same key with another body: refused, nothing queued.
    let reused = post_form(
        &a,
        &srv,
        &[("scene", None, other_json.as_bytes())],
        BOUNDARY,
        &[key],
    );
    assert_eq!(reused.status, 422, "{}", reused.text());
    let e = reused.json();
    assert_eq!(e["error"], "idempotency_key_reused");
    assert!(
        e["detail"].as_str().unwrap().contains("different request"),
        "{e}"
    );

    // One bake job: one scene submitted, one listed, its chunks baked once.
    let metrics = get(&a, &srv.url("/metrics")).text();
    assert_eq!(
        metric(&metrics, "bspvt_scenes_total{event=\"submitted\"}"),
        1.0
    );
    let listed = get(&a, &srv.url("/v1/scenes")).json();
    assert_eq!(listed["scenes"].as_array().unwrap().len(), 1);
    let done = wait_done(&a, &srv, &id);
    let chunks = done["chunks_total"].as_u64().unwrap();
    assert_eq!(done["chunks_baked_total"].as_u64(), Some(chunks));

    // Bad keys are refused before anything is read.
    for bad in ["", "has space", &"k".repeat(256)] {
        let r = post_form(&a, &srv, &form, BOUNDARY, &[("Idempotency-Key", bad)]);
        assert_eq!(r.status, 400, "{bad:?}: {}", r.text());
        assert_eq!(r.json()["error"], "invalid_idempotency_key");
    }

    // While a request with a key is still being read, a second one with it gets 409; once the
    // first is gone, the key is free.
    let stalled_key = "stalled-upload-1";
    let mut s = std::net::TcpStream::connect(&srv.addr).unwrap();
    s.write_all(
        format!(
            "POST /v1/scenes HTTP/1.1\r\nHost: x\r\nIdempotency-Key: {stalled_key}\r\n\
             Content-Type: multipart/form-data; boundary={BOUNDARY}\r\n\
             Content-Length: 100000\r\n\r\n--{BOUNDARY}\r\n"
        )
        .as_bytes(),
    )
    .unwrap();
    // Let the stalled request reach its handler.
    std::thread::sleep(Duration::from_millis(500));
    let conflict = post_form(
        &a,
        &srv,
        &form,
        BOUNDARY,
        &[("Idempotency-Key", stalled_key)],
    );
    assert_eq!(conflict.status, 409, "{}", conflict.text());
    assert_eq!(conflict.json()["error"], "idempotency_key_in_use");
    drop(s);
    let t0 = Instant::now();
    let freed = loop {
        let r = post_form(
            &a,
            &srv,
            &form,
            BOUNDARY,
            &[("Idempotency-Key", stalled_key)],
        );
        if r.status != 409 || t0.elapsed() > Duration::from_secs(10) {
            break r;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(freed.status, 202, "{}", freed.text());
    let freed_id = freed.json()["id"].as_str().unwrap().to_string();
    wait_done(&a, &srv, &freed_id);

    // SIGKILL and restart on the same data folder: the key is still known.
    srv.kill();
    let srv = start(&data, &["--workers", "1", "--threads", "1"]);
    let after = post_form(&a, &srv, &form, "----after-restart", &[key]);
    assert_eq!(after.status, 200, "{}", after.text());
    assert_eq!(after.json()["id"], id.as_str());
    assert_eq!(after.json()["state"], "done");
    let reused = post_form(
        &a,
        &srv,
        &[("scene", None, other_json.as_bytes())],
        BOUNDARY,
        &[key],
    );
    assert_eq!(reused.status, 422);
    let metrics = get(&a, &srv.url("/metrics")).text();
    assert_eq!(
        metric(&metrics, "bspvt_scenes_total{event=\"submitted\"}"),
        0.0
    );
    assert_eq!(metric(&metrics, "bspvt_chunks_baked_total"), 0.0);
    // Without a key, or with a new one, the same body is a new scene.
    let new = post_form(
        &a,
        &srv,
        &form,
        BOUNDARY,
        &[("Idempotency-Key", "another-key")],
    );
    assert_eq!(new.status, 202);
    assert_ne!(new.json()["id"], id.as_str());
}

/// Mesh paths of a scene file that are not `builtin:`.
fn file_meshes(scene: &serde_json::Value) -> Vec<String> {
    scene["meshes"]
        .as_array()
        .map(|m| {
            m.iter()
                .filter_map(|m| m["path"].as_str())
                .filter(|p| !p.starts_with("builtin:"))
                .map(str::to_string)
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn the_projects_example_scenes_are_submittable_as_they_are() {
    let scenes_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/scenes");
    let mut files: Vec<_> = std::fs::read_dir(&scenes_dir)
        .expect("assets/scenes")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    files.sort();
    assert!(files.len() >= 4, "{files:?}");
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(
        &tmp.path().join("data"),
        &["--workers", "1", "--threads", "1"],
    );
    let a = agent();
    let mut submitted = Vec::new();
    for path in &files {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read(path).unwrap();
        let json: serde_json::Value = serde_json::from_slice(&text).unwrap();
        let meshes: BTreeSet<String> = file_meshes(&json).into_iter().collect();
        let dir = path.parent().unwrap();
        let missing: Vec<&String> = meshes.iter().filter(|m| !dir.join(m).exists()).collect();
        if !missing.is_empty() {
            eprintln!("skipping {name}: it needs {missing:?}, absent here (../shared/assets)");
            continue;
        }
        if meshes.len() > 1 {
            eprintln!(
                "skipping {name}: it names {} files; a submission uploads one",
                meshes.len()
            );
            continue;
        }
        let uploads: Vec<(String, Vec<u8>)> = meshes
            .iter()
            .map(|m| {
                let file = Path::new(m)
                    .file_name()
                    .unwrap()
                    .to_string_lossy()
                    .into_owned();
                (file, std::fs::read(dir.join(m)).unwrap())
            })
            .collect();
        let mut parts: Vec<Part> = vec![("scene", None, &text[..])];
        for (file, bytes) in &uploads {
            parts.push(("mesh", Some(file.as_str()), &bytes[..]));
        }
        let r = submit(&a, &srv, &parts, None);
        assert_eq!(r.status, 202, "{name}: {}", r.text());
        let id = r.json()["id"].as_str().unwrap().to_string();
        // The service composed exactly the scene `Scene::load` reads from the file on disk.
        let status = get(&a, &srv.url(&format!("/v1/scenes/{id}"))).json();
        let mut disk = bspvt_proto::Scene::load(path).expect("the scene loads from disk");
        bspvt_bake::refine::refine_scene(&mut disk).expect("refines");
        assert_eq!(
            status["mesh_hash"].as_str().unwrap(),
            format!("{:016x}", disk.mesh.content_hash()),
            "{name}"
        );
        assert_eq!(
            status["vertices_total"].as_u64(),
            Some(disk.mesh.vertex_count() as u64),
            "{name}"
        );
        // Stop the bake: this test is about submission.
        assert_eq!(
            delete(&a, &srv.url(&format!("/v1/scenes/{id}")), None).status,
            200
        );
        eprintln!(
            "{name}: 202, {} vertices, uploads {:?}",
            disk.mesh.vertex_count(),
            uploads.iter().map(|u| &u.0).collect::<Vec<_>>()
        );
        submitted.push(name);
    }
    // The built-in-only scenes are always here.
    for must in ["dynamic.json", "plate.json"] {
        assert!(submitted.iter().any(|s| s == must), "{must} not submitted");
    }
}

/// The histogram series of `route`, `method`, `class`: (cumulative buckets by bound, sum,
/// count).
fn histogram(text: &str, route: &str, method: &str, class: &str) -> (Vec<(String, f64)>, f64, f64) {
    let labels = format!("route=\"{route}\",method=\"{method}\",class=\"{class}\"");
    let name = "bspvt_http_request_duration_seconds";
    let mut buckets = Vec::new();
    let prefix = format!("{name}_bucket{{{labels},le=\"");
    for l in text.lines() {
        if let Some(rest) = l.strip_prefix(&prefix) {
            let (le, v) = rest.split_once("\"} ").unwrap();
            buckets.push((le.to_string(), v.parse().unwrap()));
        }
    }
    let sum = metric(text, &format!("{name}_sum{{{labels}}}"));
    let count = metric(text, &format!("{name}_count{{{labels}}}"));
    (buckets, sum, count)
}

#[test]
fn the_latency_histogram_counts_requests_by_route_template_and_class() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), &[]);
    let a = agent();
    let n = 50;
    for _ in 0..n {
        assert_eq!(get(&a, &srv.url("/healthz")).status, 200);
    }
    for i in 0..3 {
        let r = get(&a, &srv.url(&format!("/v1/scenes/{i:032x}")));
        assert_eq!(r.status, 404);
    }
    assert_eq!(get(&a, &srv.url("/no/such/route")).status, 404);
    let text = get(&a, &srv.url("/metrics")).text();
    assert!(text.contains("# TYPE bspvt_http_request_duration_seconds histogram"));

    let (buckets, sum, count) = histogram(&text, "/healthz", "GET", "2xx");
    assert_eq!(count, n as f64);
    assert_eq!(buckets.len(), 15, "14 bounds and +Inf: {buckets:?}");
    assert_eq!(buckets.last(), Some(&("+Inf".to_string(), n as f64)));
    assert!(
        buckets.windows(2).all(|w| w[0].1 <= w[1].1),
        "not cumulative: {buckets:?}"
    );
    assert!(sum > 0.0 && sum < n as f64, "sum {sum}");
    eprintln!("GET /healthz ×{n}: sum {sum:.6} s, buckets {buckets:?}");

    // Route templates, never raw paths: three ids make one series.
    let (_, _, c404) = histogram(&text, "/v1/scenes/{id}", "GET", "4xx");
    assert_eq!(c404, 3.0);
    let (_, _, unmatched) = histogram(&text, "unmatched", "GET", "4xx");
    assert_eq!(unmatched, 1.0);
    assert!(!text.contains("/no/such/route"));
    assert!(!text.contains(&format!("{:032x}", 1)));
}

#[test]
fn the_openapi_document_matches_the_routes_the_server_answers() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let srv = start(&tmp.path().join("data"), &["--api-key", API_KEY]);
    let a = agent();
    let doc = get(&a, &srv.url("/v1/openapi.json")).json();
    let paths = doc["paths"].as_object().unwrap();
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
        assert!(paths.contains_key(p), "{p} undocumented");
    }
    // Each documented path answers exactly its documented methods; the others are 405.
    let unknown = "0123456789abcdef0123456789abcdef";
    for (path, ops) in paths {
        let url = path.replace("{id}", unknown);
        for method in ["GET", "POST", "PUT", "PATCH", "DELETE"] {
            let documented = ops.get(method.to_ascii_lowercase()).is_some();
            let r = raw_request(&srv, method, &url, &[("X-API-Key", API_KEY)]);
            let routed = r.status != 405;
            assert_eq!(
                routed, documented,
                "{method} {path}: answered {} but documented {documented}",
                r.status
            );
            if routed {
                let body: serde_json::Value =
                    serde_json::from_slice(&r.body).unwrap_or(serde_json::Value::Null);
                assert_ne!(
                    body["detail"].as_str().unwrap_or_default(),
                    "no such endpoint (see /v1/openapi.json)",
                    "{method} {path} documented but not routed"
                );
            }
        }
    }
    // What the behaviour needs the document to say.
    let submit = &doc["paths"]["/v1/scenes"]["post"];
    let form = &doc["components"]["schemas"]["SubmitForm"];
    assert!(
        !form["required"]
            .as_array()
            .is_some_and(|r| r.iter().any(|f| f == "mesh")),
        "mesh documented as required: {form}"
    );
    let params: Vec<&str> = submit["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(params, ["Idempotency-Key"]);
    for status in ["200", "202", "409", "422"] {
        assert!(submit["responses"][status].is_object(), "submit {status}");
    }
    let list_params: Vec<&str> = doc["paths"]["/v1/scenes"]["get"]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(list_params, ["limit", "after", "state"]);
    let schemes = &doc["components"]["securitySchemes"];
    assert_eq!(schemes["api_key"]["scheme"], "bearer");
    assert_eq!(schemes["api_key_header"]["in"], "header");
    assert_eq!(schemes["api_key_header"]["name"], "X-API-Key");
    for (path, method) in [
        ("/v1/scenes", "post"),
        ("/v1/scenes", "get"),
        ("/v1/scenes/{id}", "delete"),
    ] {
        let sec = doc["paths"][path][method]["security"].to_string();
        assert!(
            sec.contains("api_key_header") && sec.contains("\"api_key\""),
            "{method} {path}: {sec}"
        );
    }
}
