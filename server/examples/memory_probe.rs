//! Peak memory of the service's two heavy steps, measured in a fresh process each, to
//! calibrate the estimates of `service/memory.rs` (docs/service.md, "Memory budget"):
//!
//!     cargo run --release -p bspvt-server --example memory_probe -- parse MESH[.zst]
//!     cargo run --release -p bspvt-server --example memory_probe -- bake MESH THREADS
//!     cargo run --release -p bspvt-server --example memory_probe -- grid-obj N OUT.obj
//!
//! `parse` reads the file and parses it as the upload path does (zstd included); `bake`
//! parses it, builds the baker and bakes one chunk on THREADS threads. Each prints the
//! process's peak resident memory (`VmHWM`) before and after, with the mesh's counts.
//! `grid-obj` writes an N×N-quad grid as OBJ text (2N² triangles), a mesh of any size.

#![allow(clippy::unwrap_used)]

use std::io::{Read, Write};

fn hwm_kib() -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    s.lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

fn load(path: &str) -> (usize, bspvt_proto::Scene) {
    let raw = std::fs::read(path).unwrap();
    let body = raw.len();
    let (name, bytes) = match path.strip_suffix(".zst") {
        Some(inner) => {
            let mut out = Vec::new();
            zstd::stream::read::Decoder::new(&raw[..])
                .unwrap()
                .read_to_end(&mut out)
                .unwrap();
            (inner.to_string(), out)
        }
        None => (path.to_string(), raw.clone()),
    };
    let format = bspvt_proto::import::Format::from_name(&name).unwrap();
    let lim = bspvt_proto::import::Limits::default();
    let asset = bspvt_proto::import::load_asset_bytes(&bytes, format, &lim).unwrap();
    println!(
        "body {body} B, decompressed {} B, parsed: hwm {} KiB",
        bytes.len(),
        hwm_kib()
    );
    drop(bytes);
    drop(raw);
    (body, bspvt_proto::Scene::from_asset(asset).unwrap())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let before = hwm_kib();
    println!("start: hwm {before} KiB");
    match args.first().map(String::as_str) {
        Some("parse") => {
            let (_, scene) = load(&args[1]);
            println!(
                "vertices {} triangles {} hwm {} KiB",
                scene.mesh.vertex_count(),
                scene.mesh.triangles.len(),
                hwm_kib()
            );
        }
        Some("bake") => {
            let (_, scene) = load(&args[1]);
            let threads: usize = args[2].parse().unwrap();
            let parsed = hwm_kib();
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let baker = pool.install(|| bspvt_bake::Baker::new(&scene));
            let built = hwm_kib();
            let (frame, _) = pool.install(|| baker.bake_chunk(0));
            println!(
                "vertices {} triangles {} parsed hwm {parsed} KiB, baker built hwm {built} KiB, \
                 chunk 0 ({} B) hwm {} KiB",
                scene.mesh.vertex_count(),
                scene.mesh.triangles.len(),
                frame.len(),
                hwm_kib()
            );
        }
        Some("grid-obj") => {
            let n: usize = args[1].parse().unwrap();
            let mut out = std::io::BufWriter::new(std::fs::File::create(&args[2]).unwrap());
            for j in 0..=n {
                for i in 0..=n {
                    writeln!(out, "v {} 0 {}", i as f32 / n as f32, j as f32 / n as f32).unwrap();
                }
            }
            let v = |i: usize, j: usize| j * (n + 1) + i + 1;
            for j in 0..n {
                for i in 0..n {
                    writeln!(out, "f {} {} {}", v(i, j), v(i + 1, j), v(i + 1, j + 1)).unwrap();
                    writeln!(out, "f {} {} {}", v(i, j), v(i + 1, j + 1), v(i, j + 1)).unwrap();
                }
            }
        }
        _ => eprintln!("usage: memory_probe parse|bake|grid-obj …"),
    }
}
