//! Soak of one API instance: many viewers streaming trees at once while scenes are submitted,
//! for minutes, from a load generator on loopback; prints the latency per route (p50, p99,
//! max), the errors, and the server's peak resident memory against its budget.
//!
//!     cargo build --release -p bspvt-server --bins --examples
//!     target/release/examples/soak [--viewers 200] [--submissions 20] [--seconds 120]
//!         [--memory-budget-mib 320] [--scene assets/scenes/plate.json] [--no-trim]
//!
//! The server is `bspvt-server serve` beside this binary (its own process, so its memory is
//! its own), on a fresh data folder. Before the load, the viewers' scene (a scene JSON naming
//! a `builtin:` mesh) is submitted and baked. Each viewer is a thread with its own connections from one of eight loopback
//! addresses (127.0.0.2–9: 25 viewers each for 200, within the per-address stream limit, as
//! viewers behind different addresses would be) and loops over what `bspvt view` does: the
//! status, the scene, the mesh, then the trees view-first — a random quarter of the vertices
//! (`vertices=A..B`), then the rest (`..A`, `B..`); one stream in four is dropped halfway and
//! requested again (a reconnect). Submissions (the built-in small plate, each with its own
//! settings so none is a duplicate) are spread over the run from 127.0.0.1 and must all reach
//! `done`. `--no-trim` runs the server with `BSPVT_MALLOC_TRIM=0` (service/memory.rs): the
//! resident set without glibc's `malloc_trim`.

#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use bspvt_tests::Rng;
use bspvt_tests::service::{Server, agent, plate_small_json, submit_ok, wait_done};

struct Args {
    viewers: usize,
    submissions: usize,
    secs: f64,
    budget_mib: u64,
    scene: String,
    trim: bool,
}

fn args() -> Result<Args> {
    let mut a = Args {
        viewers: 200,
        submissions: 20,
        secs: 120.0,
        budget_mib: 320,
        scene: concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/scenes/plate.json").into(),
        trim: true,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut v = || it.next().with_context(|| format!("{k} needs a value"));
        match k.as_str() {
            "--viewers" => a.viewers = v()?.parse()?,
            "--submissions" => a.submissions = v()?.parse()?,
            "--seconds" => a.secs = v()?.parse()?,
            "--memory-budget-mib" => a.budget_mib = v()?.parse()?,
            "--scene" => a.scene = v()?,
            "--no-trim" => a.trim = false,
            _ => bail!("unknown argument {k} (see the doc comment of server/examples/soak.rs)"),
        }
    }
    Ok(a)
}

/// One request's outcome: route, latency, whether it failed, body bytes.
type Sample = (&'static str, Duration, bool, u64);

/// `GET path` on a new connection from `from`; reads the whole body, or `keep` bytes of it
/// (then drops the connection: a viewer going away). Returns (status, body bytes read).
fn get(from: [u8; 4], server: SocketAddr, path: &str, keep: Option<u64>) -> Result<(u16, u64)> {
    let sock = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None)?;
    sock.bind(&SocketAddr::from((from, 0)).into())?;
    sock.connect(&server.into())?;
    let mut s: TcpStream = sock.into();
    s.set_read_timeout(Some(Duration::from_secs(60)))?;
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {server}\r\nConnection: close\r\n\r\n"
    )?;
    let mut r = BufReader::new(s);
    let mut line = String::new();
    r.read_line(&mut line)?;
    let status: u16 = line
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .with_context(|| format!("bad status line {line:?}"))?;
    loop {
        let mut h = String::new();
        if r.read_line(&mut h)? == 0 || h.trim_end().is_empty() {
            break;
        }
    }
    // Connection: close, so the body (chunked or not) ends at EOF; framing bytes are counted.
    let mut buf = [0u8; 64 << 10];
    let mut n = 0u64;
    loop {
        let got = r.read(&mut buf)?;
        if got == 0 {
            break;
        }
        n += got as u64;
        if keep.is_some_and(|k| n >= k) {
            break;
        }
    }
    Ok((status, n))
}

fn viewer(
    i: usize,
    server: SocketAddr,
    id: &str,
    vertices: u64,
    stop: &AtomicBool,
    out: &Mutex<Vec<Sample>>,
) {
    let from = [127, 0, 0, 2 + (i % 8) as u8];
    let mut rng = Rng(i as u64 * 7919 + 1);
    let mut local = Vec::new();
    let mut one = |route: &'static str, path: String, keep: Option<u64>| {
        let t = Instant::now();
        let r = get(from, server, &path, keep);
        let failed = !matches!(r, Ok((200 | 206 | 304, _)));
        if failed {
            eprintln!("viewer {i}: {route} {path}: {r:?}");
        }
        local.push((route, t.elapsed(), failed, r.map_or(0, |(_, n)| n)));
    };
    while !stop.load(Ordering::Relaxed) {
        one("status", format!("/v1/scenes/{id}"), None);
        one("scene", format!("/v1/scenes/{id}/scene"), None);
        one("mesh", format!("/v1/scenes/{id}/mesh?format=ply"), None);
        let a = rng.below(vertices * 3 / 4);
        let b = a + vertices / 4;
        for range in [format!("{a}..{b}"), format!("..{a}"), format!("{b}..")] {
            if range == "..0" || range == format!("{vertices}..") {
                continue;
            }
            let path = format!("/v1/scenes/{id}/trees?vertices={range}");
            if rng.below(4) == 0 {
                // A reconnect: the stream dropped after a few kilobytes, then requested again.
                one("trees (dropped)", path.clone(), Some(4096));
            }
            one("trees", path, None);
        }
    }
    out.lock().unwrap().extend(local);
}

fn percentile(sorted: &[Duration], p: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i.min(sorted.len() - 1)].as_secs_f64() * 1e3
}

fn main() -> Result<()> {
    let a = args()?;
    let exe = std::env::current_exe()?;
    let bin = exe
        .parent()
        .and_then(|d| d.parent())
        .map(|d| d.join("bspvt-server"))
        .context("where is this binary?")?;
    if !bin.exists() {
        bail!(
            "{} not found: build it first (cargo build --release -p bspvt-server --bins --examples)",
            bin.display()
        );
    }
    let dir = tempfile::tempdir()?;
    let data = dir.path().join("data");
    let budget = a.budget_mib.to_string();
    let flags = ["--memory-budget-mib", budget.as_str(), "--workers", "2"];
    let trim = if a.trim { "1" } else { "0" };
    let mut srv = Server::start_env(
        bin.to_str().context("path")?,
        &data,
        "127.0.0.1:0",
        &flags,
        &[("BSPVT_MALLOC_TRIM", trim), ("RUST_LOG", "warn")],
    );
    let server: SocketAddr = srv.addr.parse()?;
    let ag = agent();

    // The viewers' scene, baked before the load.
    let t = Instant::now();
    let scene_json =
        std::fs::read(&a.scene).with_context(|| format!("reading the scene {}", a.scene))?;
    let id = submit_ok(&ag, &srv, &[("scene", None, &scene_json)], None);
    let status = wait_done(&ag, &srv, &id);
    let vertices = status["vertices_total"].as_u64().context("vertices")?;
    println!(
        "scene {} ({vertices} vertices) baked in {:.1} s; {} viewers and {} submissions for {:.0} s, \
         budget {} MiB, malloc_trim {}",
        a.scene,
        t.elapsed().as_secs_f64(),
        a.viewers,
        a.submissions,
        a.secs,
        a.budget_mib,
        if a.trim { "on" } else { "off" }
    );
    let rss_before = srv.rss_kib();

    let stop = Arc::new(AtomicBool::new(false));
    let out = Arc::new(Mutex::new(Vec::<Sample>::new()));
    let peak = Arc::new(AtomicU64::new(0));
    let pid = srv.child.id();
    let sampler = {
        let (stop, peak) = (stop.clone(), peak.clone());
        std::thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                let status = std::fs::read_to_string(format!("/proc/{pid}/status"));
                if let Some(kib) = status.ok().and_then(|s| {
                    s.lines()
                        .find_map(|l| l.strip_prefix("VmRSS:"))
                        .and_then(|v| v.trim().trim_end_matches(" kB").trim().parse().ok())
                }) {
                    peak.fetch_max(kib, Ordering::Relaxed);
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        })
    };
    let t0 = Instant::now();
    let threads: Vec<_> = (0..a.viewers)
        .map(|i| {
            let (stop, out, id) = (stop.clone(), out.clone(), id.clone());
            std::thread::Builder::new()
                .stack_size(256 << 10)
                .spawn(move || viewer(i, server, &id, vertices, &stop, &out))
                .unwrap()
        })
        .collect();
    // Submissions spread over the run.
    let mut submitted = Vec::new();
    for k in 0..a.submissions {
        let due = Duration::from_secs_f64(a.secs * k as f64 / a.submissions.max(1) as f64);
        std::thread::sleep(due.saturating_sub(t0.elapsed()));
        let json = plate_small_json(16 + k as u32, 256);
        let t = Instant::now();
        let sid = submit_ok(&ag, &srv, &[("scene", None, json.as_bytes())], None);
        out.lock().unwrap().push(("submit", t.elapsed(), false, 0));
        submitted.push(sid);
    }
    std::thread::sleep(Duration::from_secs_f64(a.secs).saturating_sub(t0.elapsed()));
    stop.store(true, Ordering::Relaxed);
    for t in threads {
        t.join().unwrap();
    }
    let elapsed = t0.elapsed().as_secs_f64();
    for sid in &submitted {
        wait_done(&ag, &srv, sid);
    }
    sampler.join().unwrap();
    let hwm = srv.hwm_kib();

    let samples = out.lock().unwrap();
    let mut routes: BTreeMap<&str, (Vec<Duration>, u64, u64)> = BTreeMap::new();
    for (route, d, failed, bytes) in samples.iter() {
        let e = routes.entry(route).or_default();
        e.0.push(*d);
        e.1 += *failed as u64;
        e.2 += bytes;
    }
    println!(
        "\n{:<16} {:>9} {:>7} {:>9} {:>9} {:>9} {:>10}",
        "route", "requests", "errors", "p50 ms", "p99 ms", "max ms", "MB read"
    );
    let mut errors = 0;
    for (route, (mut d, e, bytes)) in routes {
        d.sort();
        errors += e;
        println!(
            "{route:<16} {:>9} {e:>7} {:>9.1} {:>9.1} {:>9.1} {:>10.1}",
            d.len(),
            percentile(&d, 0.5),
            percentile(&d, 0.99),
            percentile(&d, 1.0),
            bytes as f64 / 1e6
        );
    }
    println!(
        "\n{} requests in {elapsed:.0} s ({:.0}/s), {errors} errors; {} submissions, all done",
        samples.len(),
        samples.len() as f64 / elapsed,
        submitted.len()
    );
    println!(
        "server resident memory: {:.0} MiB before the load, peak {:.0} MiB sampled every 50 ms \
         (VmHWM {:.0} MiB), budget {} MiB",
        rss_before as f64 / 1024.0,
        peak.load(Ordering::Relaxed) as f64 / 1024.0,
        hwm as f64 / 1024.0,
        a.budget_mib
    );
    srv.kill();
    if errors > 0 {
        bail!("{errors} requests failed");
    }
    Ok(())
}
