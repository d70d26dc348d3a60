//! The one harness of the service tests (the service's own and the streaming client's): start
//! a real service process (`bspvt-server serve`, or `bspvt serve`) on a loopback port with a
//! data directory, talk HTTP to it (ureq, or raw TCP for malformed requests), and bake
//! offline for comparison. Test support: it panics on anything unexpected.

#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

pub const API_KEY: &str = "test-key-0123456789";

/// A running server process.
pub struct Server {
    pub child: Child,
    /// `http://127.0.0.1:PORT`
    pub base: String,
    pub addr: String,
    pub data_dir: PathBuf,
    pub log: PathBuf,
}

impl Server {
    /// Starts `BIN serve` (the service's binary, or the client's, which embeds it) on
    /// `data_dir` listening on `addr` (e.g. `127.0.0.1:0`) with extra flags; waits for its
    /// address.
    pub fn start(bin: &str, data_dir: &Path, addr: &str, extra: &[&str]) -> Server {
        Server::start_env(bin, data_dir, addr, extra, &[])
    }

    /// [`Server::start`] with extra environment variables.
    pub fn start_env(
        bin: &str,
        data_dir: &Path,
        addr: &str,
        extra: &[&str],
        env: &[(&str, &str)],
    ) -> Server {
        let n = std::fs::read_dir(data_dir.parent().unwrap_or(data_dir))
            .map(|d| d.count())
            .unwrap_or(0);
        let log = data_dir.with_extension(format!("log{n}"));
        let log_file = std::fs::File::create(&log).expect("create server log");
        let mut child = Command::new(bin)
            .arg("serve")
            .arg("--data-dir")
            .arg(data_dir)
            .args(["--addr", addr])
            .args(extra)
            .env("RUST_LOG", "info,bspvt_server::service::jobs=debug")
            .envs(env.iter().copied())
            .stdout(Stdio::piped())
            .stderr(Stdio::from(log_file))
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {bin}: {e}"));
        let stdout = child.stdout.take().expect("stdout");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            let _ = BufReader::new(stdout).read_line(&mut line);
            let _ = tx.send(line);
        });
        let line = match rx.recv_timeout(Duration::from_secs(60)) {
            Ok(l) => l,
            Err(_) => {
                let _ = child.kill();
                panic!(
                    "server did not start; log:\n{}",
                    std::fs::read_to_string(&log).unwrap_or_default()
                );
            }
        };
        let base = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| {
                panic!(
                    "unexpected first line {line:?}; log:\n{}",
                    std::fs::read_to_string(&log).unwrap_or_default()
                )
            })
            .to_string();
        let addr = base.trim_start_matches("http://").to_string();
        Server {
            child,
            base,
            addr,
            data_dir: data_dir.to_path_buf(),
            log,
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// SIGKILL (what `Child::kill` sends on Unix), then reap.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Resident set size in KiB.
    pub fn rss_kib(&self) -> u64 {
        let s = std::fs::read_to_string(format!("/proc/{}/status", self.child.id()))
            .expect("read /proc status");
        s.lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .expect("VmRSS")
    }

    /// Peak resident set size in KiB (`VmHWM`: the high-water mark since the start).
    pub fn hwm_kib(&self) -> u64 {
        let s = std::fs::read_to_string(format!("/proc/{}/status", self.child.id()))
            .expect("read /proc status");
        s.lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .expect("VmHWM")
    }

    /// SIGTERM (by `kill`, the test crates deny `unsafe`), then waits up to `limit` for the
    /// process to exit; returns how long it took, `None` if it was still running.
    pub fn terminate(&mut self, limit: Duration) -> Option<Duration> {
        let t0 = Instant::now();
        let st = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .expect("run kill");
        assert!(st.success(), "kill -TERM failed");
        while t0.elapsed() < limit {
            if let Ok(Some(_)) = self.child.try_wait() {
                return Some(t0.elapsed());
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        None
    }

    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.kill();
    }
}

pub fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(Duration::from_secs(120)))
        .build()
        .into()
}

/// A response: status, headers, body.
pub struct Resp {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Resp {
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }

    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "not JSON ({e}): {:?}",
                String::from_utf8_lossy(&self.body[..self.body.len().min(500)])
            )
        })
    }

    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

fn finish(mut r: ureq::http::Response<ureq::Body>) -> Result<Resp, String> {
    let status = r.status().as_u16();
    let headers = r
        .headers()
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_str().unwrap_or("").to_string()))
        .collect();
    let mut body = Vec::new();
    r.body_mut()
        .as_reader()
        .read_to_end(&mut body)
        .map_err(|e| format!("reading the body: {e}"))?;
    Ok(Resp {
        status,
        headers,
        body,
    })
}

/// GET; `Err` when the transfer fails (e.g. an aborted stream).
pub fn try_get(agent: &ureq::Agent, url: &str, headers: &[(&str, &str)]) -> Result<Resp, String> {
    let mut req = agent.get(url);
    for (k, v) in headers {
        req = req.header(*k, *v);
    }
    finish(req.call().map_err(|e| e.to_string())?)
}

pub fn get(agent: &ureq::Agent, url: &str) -> Resp {
    try_get(agent, url, &[]).unwrap_or_else(|e| panic!("GET {url}: {e}"))
}

pub fn delete(agent: &ureq::Agent, url: &str, key: Option<&str>) -> Resp {
    let mut req = agent.delete(url);
    if let Some(k) = key {
        req = req.header("Authorization", format!("Bearer {k}"));
    }
    finish(req.call().unwrap_or_else(|e| panic!("DELETE {url}: {e}"))).expect("body")
}

/// One multipart part: (field name, file name, bytes).
pub type Part<'a> = (&'a str, Option<&'a str>, &'a [u8]);

pub const BOUNDARY: &str = "----bspvt-test-boundary-7d1f";

pub fn multipart(parts: &[Part]) -> Vec<u8> {
    let mut b = Vec::new();
    for (name, file, data) in parts {
        b.extend_from_slice(format!("--{BOUNDARY}\r\n").as_bytes());
        match file {
            Some(f) => b.extend_from_slice(
                format!(
                    "Content-Disposition: form-data; name=\"{name}\"; filename=\"{f}\"\r\nContent-Type: application/octet-stream\r\n\r\n"
                )
                .as_bytes(),
            ),
            None => b.extend_from_slice(
                format!("Content-Disposition: form-data; name=\"{name}\"\r\n\r\n").as_bytes(),
            ),
        }
        b.extend_from_slice(data);
        b.extend_from_slice(b"\r\n");
    }
    b.extend_from_slice(format!("--{BOUNDARY}--\r\n").as_bytes());
    b
}

/// POST /v1/scenes with a multipart form.
pub fn submit(agent: &ureq::Agent, srv: &Server, parts: &[Part], key: Option<&str>) -> Resp {
    let mut req = agent.post(srv.url("/v1/scenes")).header(
        "Content-Type",
        format!("multipart/form-data; boundary={BOUNDARY}"),
    );
    if let Some(k) = key {
        req = req.header("Authorization", format!("Bearer {k}"));
    }
    finish(
        req.send(&multipart(parts)[..])
            .unwrap_or_else(|e| panic!("POST: {e}")),
    )
    .expect("body")
}

/// Submits and returns the new scene's id (asserting 202).
pub fn submit_ok(agent: &ureq::Agent, srv: &Server, parts: &[Part], key: Option<&str>) -> String {
    let r = submit(agent, srv, parts, key);
    assert_eq!(r.status, 202, "submit: {}", r.text());
    r.json()["id"].as_str().expect("id").to_string()
}

/// Polls the status until `pred` holds (panics after `timeout`).
pub fn wait_status(
    agent: &ureq::Agent,
    srv: &Server,
    id: &str,
    timeout: Duration,
    pred: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let t0 = Instant::now();
    loop {
        let s = get(agent, &srv.url(&format!("/v1/scenes/{id}"))).json();
        if pred(&s) {
            return s;
        }
        assert_ne!(s["state"], "failed", "bake failed: {s}");
        assert!(
            t0.elapsed() < timeout,
            "timed out waiting; last status {s}\nlog:\n{}",
            srv.log_text()
        );
        std::thread::sleep(Duration::from_millis(25));
    }
}

pub fn wait_done(agent: &ureq::Agent, srv: &Server, id: &str) -> serde_json::Value {
    wait_status(agent, srv, id, Duration::from_secs(120), |s| {
        s["state"] == "done"
    })
}

/// The built-in `plate-small` scene as a scene file, with the given bake settings.
pub fn plate_small_json(face_res: u32, chunk_vertices: u32) -> String {
    format!(
        r#"{{"meshes": [{{"path": "builtin:plate-small"}}],
  "materials": [{{"name": "floor", "roughness": 0.35, "albedo": [0.55, 0.55, 0.52]}},
                {{"name": "sphere", "roughness": 0.15, "albedo": [0.6, 0.15, 0.1]}},
                {{"name": "slab", "roughness": 0.5, "albedo": [0.2, 0.35, 0.6]}}],
  "lights": [{{"vertices": [[-0.5, 3, -0.5], [0.5, 3, -0.5], [0.5, 3, 0.5], [-0.5, 3, 0.5]],
              "radiance": [12, 11, 10],
              "region": {{"min": [-2.5, 2, -2.5], "max": [2.5, 4, 2.5]}}}}],
  "camera": {{"position": [3.2, 3.0, 4.2], "target": [0.0, 0.5, 0.0]}},
  "bake": {{"face_res": {face_res}, "chunk_vertices": {chunk_vertices}}}}}"#
    )
}

/// The offline bake (`BIN bake`, BIN = `bspvt-server`) of a scene file.
pub fn offline_bake(bin: &str, dir: &Path, scene_json: &str, name: &str) -> Vec<u8> {
    let scene = dir.join(format!("{name}.json"));
    let out = dir.join(format!("{name}.bspvt"));
    std::fs::write(&scene, scene_json).expect("write scene");
    let st = Command::new(bin)
        .arg("bake")
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .stderr(Stdio::null())
        .status()
        .expect("run offline bake");
    assert!(st.success(), "offline bake failed");
    std::fs::read(&out).expect("read offline bake")
}

/// A raw HTTP/1.1 exchange (for requests no client library would send). Returns the status,
/// the headers and the body (read to the end of the connection, or by Content-Length).
pub fn raw(addr: &str, request: &[u8]) -> Resp {
    let s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(30)))
        .expect("timeout");
    // The server may answer (and close) before the whole request is written: write from
    // another thread while this one reads.
    let mut w = s.try_clone().expect("clone socket");
    let request = request.to_vec();
    let writer = std::thread::spawn(move || {
        let _ = w.write_all(&request);
        let _ = w.flush();
    });
    let mut r = BufReader::new(s);
    let mut line = String::new();
    r.read_line(&mut line).expect("status line");
    let status: u16 = line
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("bad status line {line:?}"));
    let mut headers = Vec::new();
    loop {
        let mut h = String::new();
        r.read_line(&mut h).expect("header");
        let h = h.trim_end();
        if h.is_empty() {
            break;
        }
        if let Some((k, v)) = h.split_once(':') {
            headers.push((k.trim().to_string(), v.trim().to_string()));
        }
    }
    let len = headers
        .iter()
        .find(|(k, _)| k.eq_ignore_ascii_case("content-length"))
        .and_then(|(_, v)| v.parse::<usize>().ok());
    let mut body = Vec::new();
    match len {
        Some(n) => {
            body.resize(n, 0);
            r.read_exact(&mut body).expect("body");
        }
        None => {
            let _ = r.read_to_end(&mut body);
        }
    }
    let _ = writer.join();
    Resp {
        status,
        headers,
        body,
    }
}

/// The `bspvt_*` value of a metric line.
pub fn metric(text: &str, name: &str) -> f64 {
    text.lines()
        .find_map(|l| l.strip_prefix(name).and_then(|v| v.strip_prefix(' ')))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("metric {name} missing"))
}

/// [`plate_small_json`] written to `dir/NAME.json`; returns the path.
pub fn plate_small(dir: &Path, name: &str, face_res: u32, chunk_vertices: u32) -> PathBuf {
    let path = dir.join(format!("{name}.json"));
    std::fs::write(&path, plate_small_json(face_res, chunk_vertices)).expect("write scene");
    path
}
