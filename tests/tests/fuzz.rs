//! A mutation fuzzer for what reads untrusted bytes: the mesh importers (glTF, GLB, OBJ +
//! MTL, PLY ASCII and binary) and the bake decoders (header, chunk, whole file). Seeds are
//! valid files (the project's rooms, hand-made GLB and binary PLY, a real bake, and the shared
//! meshes when present); each case applies a few random mutations — bit flips, interesting
//! bytes and numbers, splices from another seed, duplicated ranges, truncation — and checks
//! that the reader returns instead of panicking, and that what it accepts is sane (finite
//! positions, indices in range).
//!
//! Not coverage-guided (the `cargo fuzz` targets in `fuzz/` are, on a nightly toolchain; both
//! check the same invariants, [`bspvt_tests::fuzz`]). It runs on the stable toolchain for a
//! bounded number of cases in CI (`BSPVT_FUZZ_CASES`, default 20,000 per target, about 5 s);
//! raise it for a longer run: `BSPVT_FUZZ_CASES=200000 cargo test --release -p bspvt-tests
//! --test fuzz`.

use bspvt_proto::import::{Format, Limits, load_asset_bytes};
use bspvt_tests::fuzz;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

fn cases() -> u32 {
    std::env::var("BSPVT_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20_000)
}

fn project_file(rel: &str) -> Vec<u8> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(rel);
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A binary glTF: one triangle, positions and u16 indices in the BIN chunk.
fn glb_seed() -> Vec<u8> {
    let mut bin = Vec::new();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
        for c in p {
            bin.extend(c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2] {
        bin.extend(i.to_le_bytes());
    }
    bin.extend([0, 0]); // 4-byte alignment
    let json = r#"{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],
"buffers":[{"byteLength":44}],
"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],
"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},
{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}]}"#;
    let mut j = json.as_bytes().to_vec();
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let total = 12 + 8 + j.len() + 8 + bin.len();
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(j);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

/// A binary little-endian PLY: a tetrahedron with normals.
fn ply_binary_seed() -> Vec<u8> {
    let mut out = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n\
property float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
element face 4\nproperty list uchar int vertex_indices\nend_header\n"
        .to_vec();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]] {
        for c in p.iter().chain(&[0., 1., 0.]) {
            out.extend(c.to_le_bytes());
        }
    }
    for f in [[0i32, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
        out.push(3);
        for i in f {
            out.extend(i.to_le_bytes());
        }
    }
    out
}

/// Every seed with its format.
fn mesh_seeds() -> Vec<(Format, Vec<u8>)> {
    let mut seeds = vec![
        (Format::Obj, project_file("assets/rooms/cornell-box.obj")),
        (Format::Gltf, project_file("assets/rooms/room.gltf")),
        (
            Format::Gltf,
            project_file("assets/rooms/textured-floor.gltf"),
        ),
        (Format::Glb, glb_seed()),
        (Format::Ply, ply_binary_seed()),
        (
            Format::Obj,
            b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n\
usemtl a\nf 1/1/1 2/2/1 3/3/1\nf -3 -2 -1\n"
                .to_vec(),
        ),
    ];
    let dir = bspvt_proto::paths::meshes_dir();
    for (f, name) in [(Format::Obj, "teapot.obj"), (Format::Ply, "bunny_res4.ply")] {
        match std::fs::read(dir.join(name)) {
            Ok(b) => seeds.push((f, b)),
            Err(_) => eprintln!(
                "fuzz: {name} not found in {}; skipped as a seed",
                dir.display()
            ),
        }
    }
    seeds
}

/// Bytes and numbers that break parsers.
const TOKENS: &[&[u8]] = &[
    b"nan",
    b"inf",
    b"-inf",
    b"1e39",
    b"-0",
    b"4294967295",
    b"4294967296",
    b"-2147483649",
    b"99999999999999999999",
    b"0x",
    b"\0",
    b"\xff\xff\xff\xff",
    b"\n",
    b"/",
    b"//",
    b"\"",
    b"{",
    b"]",
];

/// Applies 1–4 random mutations driven by `r` (a stream of random words).
fn mutate(seed: &[u8], other: &[u8], r: &[u64]) -> Vec<u8> {
    let mut b = seed.to_vec();
    let mut it = r.iter().copied();
    let mut next = move || it.next().unwrap_or(0x9e37_79b9_7f4a_7c15);
    let n = 1 + next() % 4;
    for _ in 0..n {
        let pos = |len: usize, x: u64| {
            if len == 0 {
                0
            } else {
                (x % len as u64) as usize
            }
        };
        match next() % 7 {
            0 => {
                let i = pos(b.len(), next());
                if let Some(v) = b.get_mut(i) {
                    *v ^= 1 << (next() % 8);
                }
            }
            1 => {
                let i = pos(b.len(), next());
                if let Some(v) = b.get_mut(i) {
                    *v = [0u8, 0xff, 0x7f, 0x80, b'-', b'9', b' '][(next() % 7) as usize];
                }
            }
            2 => {
                let t = TOKENS[(next() % TOKENS.len() as u64) as usize];
                let i = pos(b.len() + 1, next());
                let len = (next() % 8) as usize;
                let end = (i + len).min(b.len());
                b.splice(i..end, t.iter().copied());
            }
            3 => {
                let i = pos(b.len() + 1, next());
                let j = pos(other.len() + 1, next());
                let len = (next() % 64) as usize;
                let piece = &other[j.min(other.len())..(j + len).min(other.len())];
                b.splice(i..i, piece.iter().copied());
            }
            4 => {
                let i = pos(b.len(), next());
                let len = (next() % 256) as usize;
                let piece = b[i.min(b.len())..(i + len).min(b.len())].to_vec();
                b.splice(i..i, piece);
            }
            5 => {
                let i = pos(b.len() + 1, next());
                b.truncate(i);
            }
            _ => {
                // A little-endian u32 overwritten with an extreme value (counts, lengths).
                let i = pos(b.len().saturating_sub(3), next());
                let v = [0u32, 1, 0x7fff_ffff, 0xffff_ffff, 0x1000_0000][(next() % 5) as usize];
                if i + 4 <= b.len() {
                    b[i..i + 4].copy_from_slice(&v.to_le_bytes());
                }
            }
        }
    }
    b
}

fn runner() -> TestRunner {
    TestRunner::new(Config {
        cases: cases(),
        failure_persistence: None,
        ..Config::default()
    })
}

fn words() -> impl Strategy<Value = (usize, usize, Vec<u64>)> {
    (
        any::<usize>(),
        any::<usize>(),
        proptest::collection::vec(any::<u64>(), 16),
    )
}

#[test]
fn mesh_importers_never_panic_and_accept_only_sane_meshes() {
    let seeds = mesh_seeds();
    for (f, s) in &seeds {
        load_asset_bytes(s, *f, &Limits::default())
            .unwrap_or_else(|e| panic!("seed {f:?} does not load: {e}"));
    }
    let accepted = std::cell::Cell::new(0u32);
    runner()
        .run(&words(), |(a, b, r)| {
            let (format, seed) = &seeds[a % seeds.len()];
            let other = &seeds[b % seeds.len()].1;
            let bytes = mutate(seed, other, &r);
            if fuzz::import(&bytes, *format) {
                accepted.set(accepted.get() + 1);
            }
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    eprintln!("fuzz: {} mesh cases, {} accepted", cases(), accepted.get());
}

#[test]
fn bake_decoders_never_panic() {
    let (header, chunk) = fuzz::small_bake();
    let header = bspvt_proto::encoding::encode_header(header);
    let mut file = header.clone();
    file.extend(chunk);
    let seeds = [header, chunk.clone(), file];
    runner()
        .run(&words(), |(a, b, r)| {
            let seed = &seeds[a % seeds.len()];
            fuzz::decode(&mutate(seed, &seeds[b % seeds.len()], &r));
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    eprintln!("fuzz: {} decoder cases", cases());
}
