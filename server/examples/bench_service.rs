//! Benchmark of the baking service on loopback: bake throughput alone and with streaming
//! clients, time to first chunk, streaming throughput with and without decoding.
//!
//!     cargo run --release -p bspvt-server --example bench_service -- [--clients 50]
//!         [--seconds 10] [--workers 2] [--scene builtin:plate] [--json out.json]
//!
//! The service runs in this process (`service::Background`, its own tokio runtime and bake
//! workers); the clients are threads with their own HTTP connections (ureq). Clients and
//! server share the machine's cores, so client-side work (reading, decoding) competes with
//! the bake — that is part of what is measured. Each bake phase also reports the cores used
//! by the bake threads, the service's HTTP runtime and the clients (from /proc/self/task),
//! which separates the cost of serving from other load on the machine; "bake alone" runs
//! before, between and after the loaded phases to show how much that other load drifted.

#![allow(clippy::unwrap_used)]

use std::collections::HashMap;
use std::io::Read;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Barrier};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use bspvt_proto::encoding::{decode_bake, decode_header, peek_chunk};
use bspvt_server::service::{Background, Config};
use serde_json::{Value, json};

struct Args {
    clients: usize,
    secs: f64,
    workers: usize,
    scene: String,
    json: Option<String>,
}

fn args() -> Result<Args> {
    let mut a = Args {
        clients: 50,
        secs: 10.0,
        workers: 2,
        scene: "builtin:plate".into(),
        json: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut v = || it.next().with_context(|| format!("{k} needs a value"));
        match k.as_str() {
            "--clients" => a.clients = v()?.parse()?,
            "--seconds" => a.secs = v()?.parse()?,
            "--workers" => a.workers = v()?.parse()?,
            "--scene" => a.scene = v()?,
            "--json" => a.json = Some(v()?),
            _ => bail!("unknown argument {k}"),
        }
    }
    Ok(a)
}

/// The scene file for a built-in scene (same mesh, lights and default bake settings).
fn scene_json(name: &str) -> Result<String> {
    let s = bspvt_proto::builtin::scene(name).with_context(|| format!("no built-in {name}"))?;
    Ok(json!({
        "meshes": [{"path": format!("builtin:{name}")}],
        "materials": s.materials,
        "lights": s.lights,
        "camera": s.camera,
        "bake": s.bake,
    })
    .to_string())
}

fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .timeout_global(Some(Duration::from_secs(600)))
        .build()
        .into()
}

fn submit(base: &str, scene: &str) -> Result<String> {
    let boundary = "----bench-boundary";
    let body = format!(
        "--{boundary}\r\nContent-Disposition: form-data; name=\"scene\"\r\n\r\n{scene}\r\n--{boundary}--\r\n"
    );
    let mut r = agent()
        .post(format!("{base}/v1/scenes"))
        .header(
            "Content-Type",
            format!("multipart/form-data; boundary={boundary}"),
        )
        .send(body.as_bytes())?;
    let v: Value = serde_json::from_str(&r.body_mut().read_to_string()?)?;
    Ok(v["id"].as_str().context("no id")?.to_string())
}

fn status(a: &ureq::Agent, base: &str, id: &str) -> Result<Value> {
    let mut r = a.get(format!("{base}/v1/scenes/{id}")).call()?;
    Ok(serde_json::from_str(&r.body_mut().read_to_string()?)?)
}

fn wait_done(base: &str, id: &str) -> Result<Value> {
    let a = agent();
    loop {
        let s = status(&a, base, id)?;
        match s["state"].as_str() {
            Some("done") => return Ok(s),
            Some("failed") | Some("cancelled") => bail!("bake ended: {s}"),
            _ => std::thread::sleep(Duration::from_millis(50)),
        }
    }
}

/// Streams the trees; returns the bytes, the time to the first complete chunk frame and the
/// total time.
fn stream(a: &ureq::Agent, url: &str) -> Result<(Vec<u8>, Duration, Duration)> {
    let t0 = Instant::now();
    let mut r = a.get(url).call()?;
    let mut reader = r.body_mut().as_reader();
    let mut buf = Vec::with_capacity(1 << 20);
    let mut chunk = vec![0u8; 256 << 10];
    let mut first = None;
    loop {
        let n = reader.read(&mut chunk)?;
        if n == 0 {
            break;
        }
        buf.extend_from_slice(&chunk[..n]);
        if first.is_none()
            && let Ok((_, h)) = decode_header(&buf)
            && peek_chunk(&buf[h..]).is_ok()
        {
            first = Some(t0.elapsed());
        }
    }
    let total = t0.elapsed();
    Ok((buf, first.unwrap_or(total), total))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// `clients` threads each streaming the bake again and again for `secs` seconds (at least
/// once; optionally decoding each copy): (MB/s, trees/s, median time to first chunk in ms).
fn streaming(url: &str, clients: usize, secs: f64, decode: bool) -> Result<(f64, f64, f64)> {
    let barrier = Arc::new(Barrier::new(clients + 1));
    let handles: Vec<_> = (0..clients)
        .map(|_| {
            let url = url.to_string();
            let barrier = barrier.clone();
            std::thread::spawn(move || -> Result<(u64, u64, Vec<f64>)> {
                let a = agent();
                barrier.wait();
                let t0 = Instant::now();
                let (mut bytes, mut trees, mut ttfc) = (0, 0, Vec::new());
                while ttfc.is_empty() || t0.elapsed().as_secs_f64() < secs {
                    let (b, first, _) = stream(&a, &url)?;
                    bytes += b.len() as u64;
                    if decode {
                        trees += decode_bake(&b)?.trees.len() as u64;
                    }
                    ttfc.push(first.as_secs_f64() * 1e3);
                }
                Ok((bytes, trees, ttfc))
            })
        })
        .collect();
    barrier.wait();
    let t0 = Instant::now();
    let (mut bytes, mut trees, mut ttfc) = (0, 0, Vec::new());
    for h in handles {
        let (b, t, f) = h.join().map_err(|_| anyhow::anyhow!("client panicked"))??;
        bytes += b;
        trees += t;
        ttfc.extend(f);
    }
    let s = t0.elapsed().as_secs_f64();
    Ok((bytes as f64 / s / 1e6, trees as f64 / s, median(ttfc)))
}

/// CPU seconds used so far by each live thread of this process (tid → group, seconds). Groups:
/// 0 bake workers and pool (`bake-*`), 1 the service's runtime (`bspvt-http`), 2 the rest
/// (the clients).
fn cpu_by_thread() -> HashMap<u64, (usize, f64)> {
    let mut out = HashMap::new();
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return out;
    };
    for t in tasks.flatten() {
        let Some(tid) = t.file_name().to_str().and_then(|n| n.parse::<u64>().ok()) else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(t.path().join("stat")) else {
            continue;
        };
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        let name = &stat[open + 1..close];
        let fields: Vec<&str> = stat[close + 2..].split(' ').collect();
        // utime and stime are fields 14 and 15 of stat (11 and 12 after the name and state).
        let ticks: f64 = fields
            .get(11..13)
            .map(|f| f.iter().filter_map(|x| x.parse::<f64>().ok()).sum())
            .unwrap_or(0.0);
        let g = if name.starts_with("bake-") {
            0
        } else if name.starts_with("bspvt-http") {
            1
        } else {
            2
        };
        out.insert(tid, (g, ticks / 100.0));
    }
    out
}

/// CPU seconds per group between two snapshots (threads that ended in between are missed).
fn cpu_delta(before: &HashMap<u64, (usize, f64)>, after: &HashMap<u64, (usize, f64)>) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (tid, &(g, secs)) in after {
        out[g] += secs - before.get(tid).map_or(0.0, |b| b.1);
    }
    out
}

/// Vertices per second of a finished bake, by the server's own start and finish stamps.
fn bake_rate(s: &Value) -> f64 {
    let ms = s["finished_ms"].as_i64().unwrap_or(0) - s["started_ms"].as_i64().unwrap_or(0);
    s["vertices_total"].as_f64().unwrap_or(0.0) / (ms.max(1) as f64 / 1e3)
}

/// A bake phase: vertices per second (server stamps) and the cores each thread group used.
struct Phase {
    rate: f64,
    cores: [f64; 3],
}

impl Phase {
    fn json(&self) -> Value {
        json!({"vertices_per_s": self.rate, "cores_bake": self.cores[0],
               "cores_http": self.cores[1], "cores_clients": self.cores[2],
               "vertices_per_s_per_bake_core": self.per_core()})
    }

    /// Throughput per core the bake threads actually got: insensitive to other processes
    /// taking cores, sensitive to the bake's own work getting slower.
    fn per_core(&self) -> f64 {
        self.rate / self.cores[0].max(1e-6)
    }

    fn line(&self, label: &str) {
        eprintln!(
            "{label}: {:.0} vertices/s ({:.0} per bake core); cores used: bake {:.2}, service HTTP {:.2}, clients {:.2}",
            self.rate,
            self.per_core(),
            self.cores[0],
            self.cores[1],
            self.cores[2]
        );
    }
}

/// Submits the scene, runs `during` (clients) while it bakes, waits for the end.
fn bake_phase<T>(
    base: &str,
    scene: &str,
    during: impl FnOnce(&str) -> Result<T>,
) -> Result<(Phase, String, T)> {
    let cpu0 = cpu_by_thread();
    let t0 = Instant::now();
    let id = submit(base, scene)?;
    let extra = during(&id)?;
    let s = wait_done(base, &id)?;
    let secs = t0.elapsed().as_secs_f64();
    let used = cpu_delta(&cpu0, &cpu_by_thread());
    let cores = used.map(|c| c / secs);
    Ok((
        Phase {
            rate: bake_rate(&s),
            cores,
        },
        id,
        extra,
    ))
}

fn main() -> Result<()> {
    let a = args()?;
    let name = a.scene.strip_prefix("builtin:").unwrap_or(&a.scene);
    let scene = scene_json(name)?;
    let dir = tempfile::tempdir()?;
    let mut cfg = Config::with_data_dir(dir.path());
    cfg.addr = "127.0.0.1:0".parse()?;
    cfg.workers = a.workers;
    cfg.check()?;
    let svc = Background::start(cfg)?;
    let base = format!("http://{}", svc.addr);
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    eprintln!("service on {base}; {cores} cores; scene {}", a.scene);

    // 1. Bake alone; one client streams it from the submission on (time to first chunk).
    let (alone1, id, (bytes, ttfc_baking)) = bake_phase(&base, &scene, |id| {
        let (b, first, _) = stream(&agent(), &format!("{base}/v1/scenes/{id}/trees"))?;
        Ok((b, first.as_secs_f64() * 1e3))
    })?;
    let url = format!("{base}/v1/scenes/{id}/trees");
    let vertices = decode_bake(&bytes)?.trees.len();
    eprintln!(
        "{vertices} vertices, {} bytes; first chunk {ttfc_baking:.0} ms after the request (made right after submission)",
        bytes.len()
    );
    alone1.line("bake alone");

    // 2. Streaming a finished bake.
    let (mb1, tr1, ttfc1) = streaming(&url, 1, a.secs, true)?;
    eprintln!("1 client, decode: {mb1:.1} MB/s, {tr1:.0} trees/s, first chunk {ttfc1:.2} ms");
    let (mbn, trn, ttfcn) = streaming(&url, a.clients, a.secs, true)?;
    eprintln!(
        "{} clients, decode: {mbn:.1} MB/s, {trn:.0} trees/s, first chunk {ttfcn:.1} ms (median)",
        a.clients
    );
    let (mbr, _, ttfcr) = streaming(&url, a.clients, a.secs, false)?;
    eprintln!(
        "{} clients, transfer only: {mbr:.1} MB/s, first chunk {ttfcr:.1} ms (median)",
        a.clients
    );

    // 3. The bake followed by the clients: each streams it once from submission (chunks
    // arrive as they are stored), the way a viewer would.
    let (follow, _, followers) = bake_phase(&base, &scene, |id| {
        Ok((0..a.clients)
            .map(|_| {
                let url = format!("{base}/v1/scenes/{id}/trees");
                std::thread::spawn(move || stream(&agent(), &url))
            })
            .collect::<Vec<_>>())
    })?;
    let mut follow_ttfc = Vec::new();
    for h in followers {
        let (b, first, _) = h.join().map_err(|_| anyhow::anyhow!("client panicked"))??;
        assert!(b == bytes, "a following client got different bytes");
        follow_ttfc.push(first.as_secs_f64() * 1e3);
    }
    let follow_ttfc = median(follow_ttfc);
    follow.line(&format!(
        "bake followed by {} clients (all copies identical; first chunk {follow_ttfc:.0} ms median)",
        a.clients
    ));
    let (alone2, _, ()) = bake_phase(&base, &scene, |_| Ok(()))?;
    alone2.line("bake alone");

    // 4. The bake while the clients re-download the finished one without pause.
    let stop = Arc::new(AtomicBool::new(false));
    let served = Arc::new(AtomicU64::new(0));
    let load: Vec<_> = (0..a.clients)
        .map(|_| {
            let (url, stop, served) = (url.clone(), stop.clone(), served.clone());
            std::thread::spawn(move || -> Result<()> {
                let a = agent();
                while !stop.load(Ordering::Relaxed) {
                    let (b, _, _) = stream(&a, &url)?;
                    served.fetch_add(b.len() as u64, Ordering::Relaxed);
                }
                Ok(())
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let t_load = Instant::now();
    let served0 = served.load(Ordering::Relaxed);
    let (saturated, id_s, ()) = bake_phase(&base, &scene, |_| Ok(()))?;
    let load_mb =
        (served.load(Ordering::Relaxed) - served0) as f64 / t_load.elapsed().as_secs_f64() / 1e6;
    stop.store(true, Ordering::Relaxed);
    for h in load {
        h.join().map_err(|_| anyhow::anyhow!("client panicked"))??;
    }
    let (b2, _, _) = stream(&agent(), &format!("{base}/v1/scenes/{id_s}/trees"))?;
    assert!(b2 == bytes, "the loaded bake differs");
    saturated.line(&format!(
        "bake while {} clients re-download ({load_mb:.0} MB/s)",
        a.clients
    ));
    let (alone3, _, ()) = bake_phase(&base, &scene, |_| Ok(()))?;
    alone3.line("bake alone");

    let out = json!({
        "scene": a.scene,
        "vertices": vertices,
        "bake_bytes": bytes.len(),
        "workers": a.workers,
        "clients": a.clients,
        "cores": cores,
        "seconds_per_streaming_phase": a.secs,
        "time_to_first_chunk_after_submit_ms": ttfc_baking,
        "bake_alone": [alone1.json(), alone2.json(), alone3.json()],
        "bake_followed_by_clients": follow.json(),
        "followers_first_chunk_ms_median": follow_ttfc,
        "bake_with_saturating_clients": saturated.json(),
        "saturating_clients_mb_per_s": load_mb,
        "stream_1_client_decode": {"mb_per_s": mb1, "trees_per_s": tr1, "first_chunk_ms": ttfc1},
        "stream_n_clients_decode": {"mb_per_s": mbn, "trees_per_s": trn, "first_chunk_ms_median": ttfcn},
        "stream_n_clients_transfer_only": {"mb_per_s": mbr, "first_chunk_ms_median": ttfcr},
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    if let Some(p) = &a.json {
        std::fs::write(p, serde_json::to_string_pretty(&out)? + "\n")?;
    }
    svc.stop()
}
