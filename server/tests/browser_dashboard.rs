//! The dashboard (`GET /`) in a real browser: a real `bspvt-server serve` with an API key on
//! loopback, Debian's Chromium driven headless by playwright-core (`tests/browser/`), the page
//! served behind a path prefix. The script drops the Cornell box (OBJ + MTL) on the page, waits
//! on the page for `done`, checks the row against the API, deletes the scene; see
//! `tests/browser/dashboard.mjs`. Skipped with a message where Node.js, Chromium or the
//! script's packages are missing (`.ci/run` installs them: `apt-get install chromium`,
//! `npm ci --prefix tests/browser`). Also, without a browser: the pages and their files as
//! served (types, policy, validators; the viewer's shaders are the native client's).

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::process::Command;

use common::*;

#[test]
fn the_dashboard_submits_follows_and_deletes_a_scene_in_chromium() {
    let Some(chromium) = bspvt_tests::browser::chromium_or_skip("the dashboard in Chromium") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let srv = start(&tmp.path().join("data"), &["--api-key", API_KEY]);
    let rooms = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/rooms");
    let out = tmp.path().join("shots");
    std::fs::create_dir_all(&out).unwrap();
    let run = Command::new("node")
        .current_dir(bspvt_tests::browser::scripts())
        .arg("dashboard.mjs")
        .args(["--url", &srv.base, "--key", API_KEY])
        .arg("--mesh")
        .arg(rooms.join("cornell-box.obj"))
        .arg("--file")
        .arg(rooms.join("cornell-box.mtl"))
        .arg("--out")
        .arg(&out)
        .arg("--chromium")
        .arg(&chromium)
        .output()
        .expect("run node");
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        run.status.success(),
        "the browser script failed:\n{stderr}\n{stdout}\nserver log:\n{}",
        srv.log_text()
    );
    eprintln!("{stdout}");
    let seen: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap_or(""))
        .unwrap_or_else(|e| panic!("the script's last line is not JSON ({e}): {stdout}"));
    let id = seen["id"].as_str().expect("an id");
    assert_eq!(
        seen["states"].as_array().and_then(|s| s.last()),
        Some(&"done".into())
    );
    // What the page submitted is what the API holds: the OBJ with its material library read
    // (no warning about a missing .mtl), deleted at the end.
    let a = agent();
    let status = get(&a, &srv.url(&format!("/v1/scenes/{id}"))).json();
    assert_eq!(status["state"], "cancelled", "{status}");
    assert!(
        status["source"]
            .as_str()
            .unwrap_or("")
            .contains("cornell-box.obj"),
        "{status}"
    );
    assert!(
        status["warnings"]
            .as_array()
            .is_some_and(|w| w.iter().all(|w| !w.as_str().unwrap_or("").contains(".mtl"))),
        "{status}"
    );
    assert!(out.join("dashboard.png").exists());
}

#[test]
fn the_page_and_its_files_are_served_with_a_strict_policy() {
    let tmp = tempfile::tempdir().unwrap();
    let srv = start(&tmp.path().join("data"), &["--api-key", API_KEY]);
    let a = agent();
    // The page needs no key (it holds no data); the listing it calls does.
    let page = get(&a, &srv.url("/"));
    assert_eq!(page.status, 200);
    assert_eq!(
        page.header("content-type"),
        Some("text/html; charset=utf-8")
    );
    let csp = page.header("content-security-policy").expect("a CSP");
    for directive in [
        "default-src 'none'",
        "script-src 'self'",
        "frame-ancestors 'none'",
    ] {
        assert!(csp.contains(directive), "{csp}");
    }
    assert!(
        !csp.contains("unsafe-inline") && !csp.contains("unsafe-eval"),
        "{csp}"
    );
    assert_eq!(page.header("x-content-type-options"), Some("nosniff"));
    assert!(page.text().contains("ui/dashboard.js"));
    for (file, kind) in [
        ("dashboard.js", "text/javascript"),
        ("upload.js", "text/javascript"),
        ("cpu.js", "text/javascript"),
        ("style.css", "text/css"),
        ("icon.svg", "image/svg+xml"),
    ] {
        let r = get(&a, &srv.url(&format!("/ui/{file}")));
        assert_eq!(r.status, 200, "{file}");
        assert!(
            r.header("content-type").unwrap_or("").starts_with(kind),
            "{file}"
        );
        // Revalidated on every load, 304 when unchanged.
        let etag = r.header("etag").expect("an ETag").to_string();
        let again = try_get(
            &a,
            &srv.url(&format!("/ui/{file}")),
            &[("If-None-Match", &etag)],
        )
        .expect("GET");
        assert_eq!(again.status, 304, "{file}");
    }
    // The viewer's page, and the shaders exactly as the native client compiles them.
    let view = get(&a, &srv.url("/view/0123456789abcdef0123456789abcdef"));
    assert_eq!(view.status, 200);
    assert!(view.header("content-security-policy").is_some());
    assert!(view.text().contains("../ui/viewer.js"));
    use bspvt_shaders::gpu::wgsl;
    for (name, source) in [
        ("shade.wgsl", wgsl::shade()),
        ("visibility.wgsl", wgsl::visibility()),
        ("resolve.wgsl", wgsl::resolve(1)),
        ("present.wgsl", wgsl::present().to_string()),
        ("sides.wgsl", wgsl::sides()),
    ] {
        let r = get(&a, &srv.url(&format!("/ui/wgsl/{name}")));
        assert_eq!(r.status, 200, "{name}");
        assert_eq!(r.text(), source, "{name} is not the native client's source");
    }
    assert_eq!(get(&a, &srv.url("/ui/wgsl/other.wgsl")).status, 404);
    let missing = get(&a, &srv.url("/ui/secret.txt"));
    assert_eq!(missing.status, 404);
    assert_eq!(missing.json()["error"], "not_found");
    assert_eq!(get(&a, &srv.url("/v1/scenes")).status, 401);
}
