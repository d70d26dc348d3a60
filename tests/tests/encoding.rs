//! The encoded forms of trees: vertex records, chunk frames and bake files.
//!
//! - Round trips of random [`VertexTrees`] (random faces present, random trees with every leaf
//!   kind and random lines, up to `MAX_DEPTH` and up to the node limit) through
//!   `encode_vertex`/`decode_vertex`, `encode_chunk`/`decode_chunk`/`peek_chunk` and whole files
//!   (`encode_header` + chunks → `decode_bake`).
//! - A vertex that sees everything is one byte.
//! - Corruption: every single-byte change and every truncation of a small chunk frame and of a
//!   small bake file is an error.
//! - Hostile frames with a valid CRC and absurd fields each give their specific [`DecodeError`].
//! - Random bytes (raw, and behind valid framing) never make a decoder panic.

use bspvt_proto::bspvt::{FaceTree, LineCodec, MAX_DEPTH, Node, QLine, VertexTrees};
use bspvt_proto::cubemap::FACES;
use bspvt_proto::encoding::{
    Bake, BakeHeader, ChunkHeader, FORMAT_VERSION, MAX_CHUNK_BODY_BYTES, MAX_CHUNK_RAW_BYTES,
    MAX_HEADER_BYTES, decode_bake, decode_chunk, decode_header, decode_vertex, encode_chunk,
    encode_header, encode_mesh, encode_vertex, peek_chunk,
};
use bspvt_proto::{BakeSettings, DecodeError, SplitMethod};
use bspvt_tests::{Rng, random_value};
use proptest::prelude::*;

// ---------------------------------------------------------------------------------------------
// Random trees.
// ---------------------------------------------------------------------------------------------

/// A random pre-order tree: depth ≤ `max_depth`, at most `max_nodes` nodes (odd, ≥ 1), lines
/// anywhere in the codec's range; sometimes a comb straight down to `max_depth`.
fn random_tree(rng: &mut Rng, codec: &LineCodec, max_depth: usize, max_nodes: usize) -> FaceTree {
    fn go(
        rng: &mut Rng,
        codec: &LineCodec,
        depth: usize,
        max_depth: usize,
        budget: &mut usize,
        comb: bool,
        nodes: &mut Vec<Node>,
    ) {
        // A split costs 2 more nodes than a leaf (its two children replace it).
        let split = depth < max_depth
            && *budget >= 2
            && (comb || rng.chance(if depth == 0 { 0.9 } else { 0.55 }));
        if !split {
            nodes.push(Node::Leaf {
                value: random_value(rng),
            });
            return;
        }
        *budget -= 2;
        let line = QLine {
            angle: rng.below(codec.angles() as u64) as u16,
            offset: rng.below(codec.offsets() as u64) as u16,
        };
        let at = nodes.len();
        nodes.push(Node::Split { line, right: 0 });
        go(rng, codec, depth + 1, max_depth, budget, false, nodes);
        let right = nodes.len() as u32;
        nodes[at] = Node::Split { line, right };
        go(rng, codec, depth + 1, max_depth, budget, comb, nodes);
    }
    let mut nodes = Vec::new();
    let mut budget = max_nodes.saturating_sub(1);
    let comb = rng.chance(0.1);
    go(rng, codec, 0, max_depth, &mut budget, comb, &mut nodes);
    FaceTree { nodes }
}

fn random_vertex(rng: &mut Rng, header: &BakeHeader, codec: &LineCodec) -> VertexTrees {
    let mut t = VertexTrees::default();
    let kind = rng.below(10);
    for f in 0..FACES {
        if !rng.chance(0.7) {
            continue;
        }
        t.faces[f] = Some(match kind {
            // Uniform vertices (the one-byte modes), and mixed uniform faces.
            0 => FaceTree::leaf(255),
            1 => FaceTree::leaf(0),
            2 => FaceTree::leaf(random_value(rng)),
            _ => {
                let depth = if rng.chance(0.2) {
                    MAX_DEPTH
                } else {
                    rng.below(14) as usize
                };
                let cap =
                    header
                        .max_nodes_per_face()
                        .min(if rng.chance(0.1) { usize::MAX } else { 400 });
                random_tree(rng, codec, depth, cap)
            }
        });
    }
    t
}

fn random_header(rng: &mut Rng, vertex_count: u32) -> BakeHeader {
    let face_res = [4u32, 5, 8, 16, 33, 64, 128, 512][rng.below(8) as usize];
    let settings = BakeSettings {
        face_res,
        epsilon: 1e-3,
        supersampling: 1 + rng.below(4) as u32,
        split: [
            SplitMethod::Default,
            SplitMethod::Exhaustive,
            SplitMethod::NelderMead,
        ][rng.below(3) as usize],
        chunk_vertices: 1 + rng.below(8) as u32,
        refine: None,
    };
    BakeHeader::new(&settings, vertex_count, rng.next_u64())
}

fn header_for(face_res: u32, chunk_vertices: u32, vertex_count: u32) -> BakeHeader {
    let settings = BakeSettings {
        face_res,
        chunk_vertices,
        ..BakeSettings::default()
    };
    BakeHeader::new(&settings, vertex_count, 0x1234)
}

/// A whole bake file: header frame, then chunks of `chunk_vertices`.
fn encode_file(header: &BakeHeader, trees: &[VertexTrees]) -> Vec<u8> {
    let codec = header.codec();
    let mut out = encode_header(header);
    for (c, chunk) in trees.chunks(header.chunk_vertices as usize).enumerate() {
        out.extend(encode_chunk(
            c as u32 * header.chunk_vertices,
            chunk,
            &codec,
        ));
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Hand-built frames (valid CRC, chosen contents).
// ---------------------------------------------------------------------------------------------

fn frame(magic: &[u8], body: &[u8]) -> Vec<u8> {
    let mut out = magic.to_vec();
    out.extend((body.len() as u32).to_le_bytes());
    out.extend(body);
    out.extend(crc32fast::hash(body).to_le_bytes());
    out
}

fn chunk_frame(h: ChunkHeader, payload: &[u8]) -> Vec<u8> {
    let mut body = postcard::to_stdvec(&h).expect("postcard");
    body.extend(payload);
    frame(b"BVCK", &body)
}

/// A chunk frame around the raw vertex records `raw` (zstd-compressed), header fields honest.
fn raw_chunk(first_vertex: u32, vertex_count: u32, raw: &[u8]) -> Vec<u8> {
    let payload = zstd::bulk::compress(raw, 3).expect("zstd");
    chunk_frame(
        ChunkHeader {
            first_vertex,
            vertex_count,
            raw_len: raw.len() as u32,
        },
        &payload,
    )
}

fn header_frame(version: u16, h: &BakeHeader) -> Vec<u8> {
    let mut body = version.to_le_bytes().to_vec();
    body.extend(postcard::to_stdvec(h).expect("postcard"));
    frame(b"BSPVT\0", &body)
}

/// MSB-first bit writer, as the format specifies.
#[derive(Default)]
struct Bits {
    out: Vec<u8>,
    acc: u64,
    n: u32,
}

impl Bits {
    fn put(&mut self, v: u32, n: u32) {
        self.acc = (self.acc << n) | v as u64;
        self.n += n;
        while self.n >= 8 {
            self.n -= 8;
            self.out.push((self.acc >> self.n) as u8);
        }
    }
    fn finish(mut self) -> Vec<u8> {
        if self.n > 0 {
            let pad = 8 - self.n;
            self.put(0, pad);
        }
        self.out
    }
}

/// A mode-0 vertex record for face 0 holding a comb: `splits` splits, each with a leaf on the
/// left, and two leaves at the bottom (depth `splits`, 2·splits + 1 nodes).
fn comb_record(codec: &LineCodec, splits: usize) -> Vec<u8> {
    let mut b = Bits::default();
    for i in 0..splits {
        b.put(0, 2);
        b.put(i as u32 % codec.angles(), codec.angle_bits as u32);
        b.put(7 % codec.offsets(), codec.offset_bits as u32);
        b.put(1, 2); // left: leaf 0
    }
    b.put(2, 2); // last right: leaf 255
    let mut rec = vec![0b0000_0001];
    rec.extend(b.finish());
    rec
}

// ---------------------------------------------------------------------------------------------
// Round trips.
// ---------------------------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn chunk_and_file_round_trip(seed in any::<u64>(), n in 0u32..24) {
        let mut rng = Rng(seed);
        let header = random_header(&mut rng, n);
        let codec = header.codec();
        let trees: Vec<VertexTrees> = (0..n).map(|_| random_vertex(&mut rng, &header, &codec)).collect();

        // Vertex records: each decodes to itself and ends exactly where the next begins.
        let mut raw = Vec::new();
        let mut ends = Vec::new();
        for t in &trees {
            encode_vertex(t, &codec, &mut raw);
            ends.push(raw.len());
        }
        let mut pos = 0;
        for (t, &end) in trees.iter().zip(&ends) {
            let back = decode_vertex(&raw, &mut pos, &header, &codec);
            prop_assert_eq!(back.as_ref(), Ok(t));
            prop_assert_eq!(pos, end);
        }

        // One chunk (first vertex anywhere it fits), with peek.
        let wide = BakeHeader { vertex_count: n + 100, chunk_vertices: n.max(1), ..header.clone() };
        {
            let first = rng.below(101) as u32;
            let mut frame = encode_chunk(first, &trees, &codec);
            let len = frame.len();
            frame.extend([0xAB, 0xCD]); // following data is not part of the frame
            let (chunk, used) = decode_chunk(&frame, &wide).map_err(|e| TestCaseError::fail(e.to_string()))?;
            prop_assert_eq!(used, len);
            prop_assert_eq!(chunk.first_vertex, first);
            prop_assert_eq!(&chunk.trees, &trees);
            let (ph, pused) = peek_chunk(&frame).map_err(|e| TestCaseError::fail(e.to_string()))?;
            prop_assert_eq!(pused, len);
            prop_assert_eq!(ph.first_vertex, first);
            prop_assert_eq!(ph.vertex_count, n);
            prop_assert_eq!(ph.raw_len as usize, raw.len());
        }

        // The whole file.
        let file = encode_file(&header, &trees);
        let bake = decode_bake(&file).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(bake, Bake { header: header.clone(), trees, mesh: None });
        let (h, used) = decode_header(&file).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(h, header.clone());
        prop_assert_eq!(used, encode_header(&header).len());
    }
}

/// Chunks may come in any order in a file; every vertex must appear exactly once.
#[test]
fn file_with_chunks_out_of_order_decodes() {
    let mut rng = Rng(3);
    let header = header_for(16, 3, 10);
    let codec = header.codec();
    let trees: Vec<VertexTrees> = (0..10)
        .map(|_| random_vertex(&mut rng, &header, &codec))
        .collect();
    let mut file = encode_header(&header);
    for c in [3u32, 1, 0, 2] {
        let s = (c * 3) as usize;
        file.extend(encode_chunk(c * 3, &trees[s..(s + 3).min(10)], &codec));
    }
    assert_eq!(decode_bake(&file).expect("decodes").trees, trees);
}

/// A refined scene's bake file ends with its mesh: it decodes back; a mesh that is not the one
/// the header names, anything after it, a hostile raw length and every truncation are errors.
#[test]
fn mesh_frame_round_trips_and_is_checked() {
    let mesh = bspvt_proto::builtin::mesh("cube").expect("built-in cube");
    let n = mesh.vertex_count() as u32;
    let settings = BakeSettings {
        face_res: 16,
        chunk_vertices: 256,
        ..BakeSettings::default()
    };
    let header = BakeHeader::new(&settings, n, mesh.content_hash());
    let mut rng = Rng(11);
    let codec = header.codec();
    let trees: Vec<VertexTrees> = (0..n)
        .map(|_| random_vertex(&mut rng, &header, &codec))
        .collect();
    let mut file = encode_file(&header, &trees);
    let plain = decode_bake(&file).expect("decodes");
    assert_eq!(plain.mesh, None);
    let body_end = file.len();
    file.extend(encode_mesh(&mesh));
    let bake = decode_bake(&file).expect("decodes with its mesh");
    assert_eq!(bake.trees, trees);
    assert_eq!(bake.mesh.as_ref(), Some(&mesh));

    let mut after = file.clone();
    after.extend(encode_chunk(0, &trees[..1], &codec));
    assert!(matches!(decode_bake(&after), Err(DecodeError::Corrupt(_))));
    let mut other = mesh.clone();
    other.positions[0].x += 1.0;
    let mut wrong = file[..body_end].to_vec();
    wrong.extend(encode_mesh(&other));
    assert!(matches!(decode_bake(&wrong), Err(DecodeError::Corrupt(_))));
    let mut bomb = file[..body_end].to_vec();
    bomb.extend(frame(b"BVMS", &u32::MAX.to_le_bytes()));
    assert!(matches!(decode_bake(&bomb), Err(DecodeError::Limit { .. })));
    for cut in body_end + 1..file.len() {
        assert!(decode_bake(&file[..cut]).is_err(), "cut at {cut}");
    }
}

/// A vertex that sees everything is one byte, whichever faces are present; so is one that
/// sees nothing.
#[test]
fn uniform_vertices_are_one_byte() {
    let codec = LineCodec::for_resolution(64);
    let header = header_for(64, 16, 16);
    for mask in 0u32..64 {
        for v in [255u8, 0] {
            let mut t = VertexTrees::default();
            for f in 0..FACES {
                if mask & (1 << f) != 0 {
                    t.faces[f] = Some(FaceTree::leaf(v));
                }
            }
            let mut out = Vec::new();
            encode_vertex(&t, &codec, &mut out);
            if v == 255 || mask != 0 {
                assert_eq!(out.len(), 1, "mask {mask:#b}, value {v}: {out:?}");
            }
            let mut pos = 0;
            assert_eq!(decode_vertex(&out, &mut pos, &header, &codec), Ok(t));
            assert_eq!(pos, out.len());
        }
    }
    // The fully visible vertex, all six faces present.
    let all = VertexTrees {
        faces: std::array::from_fn(|_| Some(FaceTree::leaf(255))),
    };
    let mut out = Vec::new();
    encode_vertex(&all, &codec, &mut out);
    assert_eq!(out, vec![0b0111_1111]);
    eprintln!("fully visible vertex record: {out:?} (1 byte)");
}

// ---------------------------------------------------------------------------------------------
// Corruption.
// ---------------------------------------------------------------------------------------------

fn small_trees(rng: &mut Rng, header: &BakeHeader) -> Vec<VertexTrees> {
    let codec = header.codec();
    loop {
        let t: Vec<VertexTrees> = (0..2).map(|_| random_vertex(rng, header, &codec)).collect();
        // Make sure there is a tree stream to corrupt.
        if t.iter().any(|v| v.leaf_count() > 3) {
            return t;
        }
    }
}

/// Every change of a single byte (all 255 other values, at every position) and every
/// truncation of a small chunk frame is an error — the CRC-32 catches every change inside
/// the body and the checksum, the framing catches the rest.
#[test]
fn every_byte_change_and_truncation_of_a_chunk_fails() {
    let mut rng = Rng(21);
    let header = header_for(16, 4, 8);
    let trees = small_trees(&mut rng, &header);
    let frame = encode_chunk(2, &trees, &header.codec());
    assert!(decode_chunk(&frame, &header).is_ok());
    let mut kinds = std::collections::BTreeMap::<&str, usize>::new();
    for i in 0..frame.len() {
        for x in 1..=255u8 {
            let mut bad = frame.clone();
            bad[i] ^= x;
            let r = decode_chunk(&bad, &header);
            let p = peek_chunk(&bad);
            let kind = match &r {
                Ok(_) => panic!("byte {i} ^ {x:#04x}: decoded Ok"),
                Err(DecodeError::BadMagic) => "bad magic",
                Err(DecodeError::Checksum { .. }) => "checksum",
                Err(DecodeError::Truncated(_)) => "truncated",
                Err(DecodeError::Limit { .. }) => "limit",
                Err(e) => panic!("byte {i} ^ {x:#04x}: unexpected {e:?}"),
            };
            assert!(p.is_err(), "byte {i} ^ {x:#04x}: peek Ok");
            *kinds.entry(kind).or_default() += 1;
        }
    }
    for cut in 0..frame.len() {
        match decode_chunk(&frame[..cut], &header) {
            Err(DecodeError::Truncated(_)) => {}
            other => panic!("truncated to {cut} of {}: {other:?}", frame.len()),
        }
        assert!(peek_chunk(&frame[..cut]).is_err());
    }
    eprintln!(
        "chunk frame of {} bytes: {} single-byte changes all rejected {kinds:?}; {} truncations all Truncated",
        frame.len(),
        frame.len() * 255,
        frame.len()
    );
}

/// The same for a small bake file (header frame + two chunks): every single-bit flip and every
/// truncation is an error.
#[test]
fn every_bit_flip_and_truncation_of_a_file_fails() {
    let mut rng = Rng(22);
    let header = header_for(8, 2, 4);
    let codec = header.codec();
    let trees: Vec<VertexTrees> = (0..4)
        .map(|_| random_vertex(&mut rng, &header, &codec))
        .collect();
    let file = encode_file(&header, &trees);
    assert_eq!(decode_bake(&file).expect("valid").trees, trees);
    for i in 0..file.len() {
        for bit in 0..8 {
            let mut bad = file.clone();
            bad[i] ^= 1 << bit;
            assert!(decode_bake(&bad).is_err(), "byte {i} bit {bit}: decoded Ok");
        }
    }
    for cut in 0..file.len() {
        assert!(
            decode_bake(&file[..cut]).is_err(),
            "truncated to {cut}: decoded Ok"
        );
    }
    // Trailing garbage after the last chunk is not a chunk.
    let mut tail = file.clone();
    tail.push(0);
    assert_eq!(
        decode_bake(&tail),
        Err(DecodeError::Truncated("frame header"))
    );
    eprintln!(
        "bake file of {} bytes: {} bit flips and {} truncations all rejected",
        file.len(),
        file.len() * 8,
        file.len()
    );
}

// ---------------------------------------------------------------------------------------------
// Hostile frames: valid CRC, absurd contents.
// ---------------------------------------------------------------------------------------------

#[test]
fn hostile_chunk_headers() {
    let header = header_for(8, 16, 64);
    let ok_raw = [0b0111_1111u8]; // one fully visible vertex
    let payload = zstd::bulk::compress(&ok_raw, 3).expect("zstd");
    let chunk = |first_vertex, vertex_count, raw_len| {
        chunk_frame(
            ChunkHeader {
                first_vertex,
                vertex_count,
                raw_len,
            },
            &payload,
        )
    };
    // The honest frame decodes.
    assert!(decode_chunk(&chunk(0, 1, 1), &header).is_ok());
    // vertex_count 4e9.
    assert_eq!(
        decode_chunk(&chunk(0, 4_000_000_000, 1), &header).map(|_| ()),
        Err(DecodeError::Limit {
            what: "vertices per chunk",
            value: 4_000_000_000,
            limit: 16
        })
    );
    // raw_len 4e9.
    assert_eq!(
        decode_chunk(&chunk(0, 1, 4_000_000_000), &header).map(|_| ()),
        Err(DecodeError::Limit {
            what: "chunk raw bytes",
            value: 4_000_000_000,
            limit: MAX_CHUNK_RAW_BYTES as u64
        })
    );
    // first_vertex beyond the bake, and a chunk running past its end.
    for (first, count) in [(64, 1), (4_000_000_000, 1), (u32::MAX, 16), (60, 5)] {
        match decode_chunk(&chunk(first, count, count.max(1)), &header) {
            Err(DecodeError::Corrupt(m)) => assert!(m.contains("chunk covers vertices"), "{m}"),
            other => panic!("first {first}, count {count}: {other:?}"),
        }
    }
    // raw_len shorter than one byte per vertex.
    match decode_chunk(&chunk(0, 2, 1), &header) {
        Err(DecodeError::Corrupt(m)) => {
            assert!(m.contains("shorter than one byte per vertex"), "{m}")
        }
        other => panic!("{other:?}"),
    }
    // A payload that decompresses to less than raw_len.
    match decode_chunk(&chunk(0, 1, 2), &header) {
        Err(DecodeError::Corrupt(m)) => assert!(m.contains("header says 2"), "{m}"),
        other => panic!("{other:?}"),
    }
    // A payload that is not zstd.
    match decode_chunk(
        &chunk_frame(
            ChunkHeader {
                first_vertex: 0,
                vertex_count: 1,
                raw_len: 1,
            },
            b"not zstd",
        ),
        &header,
    ) {
        Err(DecodeError::Corrupt(m)) => assert!(m.starts_with("chunk payload"), "{m}"),
        other => panic!("{other:?}"),
    }
    // A chunk header postcard cannot read.
    match decode_chunk(&frame(b"BVCK", &[0xFF; 3]), &header) {
        Err(DecodeError::Corrupt(m)) => assert!(m.starts_with("chunk header"), "{m}"),
        other => panic!("{other:?}"),
    }
    // A frame body longer than the limit (checked before reading or hashing it).
    let mut big = b"BVCK".to_vec();
    big.extend((MAX_CHUNK_BODY_BYTES + 1).to_le_bytes());
    big.extend([0; 16]);
    assert_eq!(
        decode_chunk(&big, &header).map(|_| ()),
        Err(DecodeError::Limit {
            what: "frame body bytes",
            value: MAX_CHUNK_BODY_BYTES as u64 + 1,
            limit: MAX_CHUNK_BODY_BYTES as u64
        })
    );
    // Wrong magic.
    let mut bad = chunk(0, 1, 1);
    bad[0] = b'X';
    assert_eq!(
        decode_chunk(&bad, &header).map(|_| ()),
        Err(DecodeError::BadMagic)
    );
}

#[test]
fn zstd_bombs_are_refused() {
    let header = header_for(8, 16, 64);
    // 64 MiB of 0x7F (each a valid one-byte record) compresses to a few KiB; the header claims
    // 16 raw bytes.
    let huge = vec![0b0111_1111u8; 64 << 20];
    let t = std::time::Instant::now();
    for payload in [
        zstd::bulk::compress(&huge, 3).expect("zstd"),
        // Without a declared content size (streaming encoder), too.
        {
            let mut enc = zstd::stream::Encoder::new(Vec::new(), 3).expect("zstd");
            std::io::Write::write_all(&mut enc, &huge).expect("write");
            enc.finish().expect("zstd")
        },
    ] {
        let f = chunk_frame(
            ChunkHeader {
                first_vertex: 0,
                vertex_count: 16,
                raw_len: 16,
            },
            &payload,
        );
        match decode_chunk(&f, &header) {
            Err(DecodeError::Corrupt(m)) => assert!(m.starts_with("chunk payload"), "{m}"),
            other => panic!(
                "bomb of {} payload bytes: {:?}",
                payload.len(),
                other.map(|c| c.0.trees.len())
            ),
        }
    }
    // The largest raw_len allowed with a tiny payload: refused without decompressing much.
    let f = chunk_frame(
        ChunkHeader {
            first_vertex: 0,
            vertex_count: 16,
            raw_len: MAX_CHUNK_RAW_BYTES,
        },
        &zstd::bulk::compress(&[0x7F; 16], 3).expect("zstd"),
    );
    assert!(matches!(
        decode_chunk(&f, &header),
        Err(DecodeError::Corrupt(_))
    ));
    let secs = t.elapsed().as_secs_f64();
    eprintln!("zstd bombs refused in {secs:.3} s");
    assert!(secs < 5.0, "{secs}");
}

#[test]
fn hostile_tree_streams() {
    // face_res 8: 6-bit lines, at most 2·8² + 1 = 129 nodes per face.
    let header = header_for(8, 16, 64);
    let codec = header.codec();
    assert_eq!((codec.angle_bits, codec.offset_bits), (6, 6));
    let decode_raw =
        |raw: &[u8]| decode_chunk(&raw_chunk(0, 1, raw), &header).map(|(c, _)| c.trees);

    // Exactly MAX_DEPTH deep decodes; one deeper is refused.
    let ok = decode_raw(&comb_record(&codec, MAX_DEPTH)).expect("depth MAX_DEPTH is allowed");
    assert_eq!(
        ok[0].faces[0].as_ref().map(|t| t.nodes.len()),
        Some(2 * MAX_DEPTH + 1)
    );
    assert_eq!(
        decode_raw(&comb_record(&codec, MAX_DEPTH + 1)),
        Err(DecodeError::Limit {
            what: "tree depth",
            value: MAX_DEPTH as u64 + 1,
            limit: MAX_DEPTH as u64
        })
    );
    // A split tag forever (all-zero bits): refused at the depth limit, not by running out.
    let mut zeros = vec![0b0000_0001u8];
    zeros.extend([0u8; 400]);
    assert!(matches!(
        decode_raw(&zeros),
        Err(DecodeError::Limit {
            what: "tree depth",
            ..
        })
    ));

    // face_res 4: at most 2·4² + 1 = 33 nodes per face; a 16-split comb (33 nodes) decodes,
    // a 17-split comb (35 nodes) is refused when the 34th node would be added.
    let h4 = header_for(4, 16, 64);
    let c4 = h4.codec();
    assert_eq!(h4.max_nodes_per_face(), 33);
    let decode4 = |raw: &[u8]| decode_chunk(&raw_chunk(0, 1, raw), &h4).map(|(c, _)| c.trees);
    assert!(decode4(&comb_record(&c4, 16)).is_ok());
    assert_eq!(
        decode4(&comb_record(&c4, 17)),
        Err(DecodeError::Limit {
            what: "nodes per face tree",
            value: 34,
            limit: 33
        })
    );

    // The bit stream ends inside a tree.
    let full = comb_record(&codec, 3);
    assert_eq!(
        decode_raw(&full[..full.len() - 1]),
        Err(DecodeError::Truncated("tree bit stream"))
    );
    // A record with mode 3.
    match decode_raw(&[0b1100_0001]) {
        Err(DecodeError::Corrupt(m)) => assert!(m.contains("mode 3"), "{m}"),
        other => panic!("{other:?}"),
    }
    // Trailing bytes after the last vertex.
    let mut trailing = comb_record(&codec, 3);
    trailing.push(0);
    match decode_raw(&trailing) {
        Err(DecodeError::Corrupt(m)) => assert!(m.contains("1 trailing bytes"), "{m}"),
        other => panic!("{other:?}"),
    }
    // Fewer records than vertex_count.
    assert_eq!(
        decode_chunk(&raw_chunk(0, 2, &[0x7F]), &header).map(|_| ()),
        Err(DecodeError::Corrupt(
            "raw length shorter than one byte per vertex".into()
        ))
    );
    assert_eq!(
        decode_chunk(&raw_chunk(0, 2, &[0b0000_0001, 0b0100_0000]), &header).map(|_| ()),
        Err(DecodeError::Truncated("vertex header"))
    );
}

#[test]
fn hostile_bake_headers() {
    let good = header_for(16, 8, 10);
    assert_eq!(
        decode_header(&header_frame(FORMAT_VERSION, &good)).map(|h| h.0),
        Ok(good.clone())
    );
    // face_res 0 (in the file's header, and given to decode_chunk directly).
    let zero = BakeHeader {
        face_res: 0,
        ..good.clone()
    };
    let want = Err(DecodeError::Corrupt(
        "face_res or chunk_vertices is zero".into(),
    ));
    assert_eq!(
        decode_header(&header_frame(FORMAT_VERSION, &zero)).map(|_| ()),
        want
    );
    let chunk = encode_chunk(0, &[VertexTrees::default()], &good.codec());
    assert_eq!(decode_chunk(&chunk, &zero).map(|_| ()), want);
    assert_eq!(
        decode_header(&header_frame(
            FORMAT_VERSION,
            &BakeHeader {
                chunk_vertices: 0,
                ..good.clone()
            }
        ))
        .map(|_| ()),
        want
    );
    // face_res and chunk_vertices beyond their limits.
    assert_eq!(
        decode_header(&header_frame(
            FORMAT_VERSION,
            &BakeHeader {
                face_res: 100_000,
                ..good.clone()
            }
        ))
        .map(|_| ()),
        Err(DecodeError::Limit {
            what: "face_res",
            value: 100_000,
            limit: BakeSettings::MAX_FACE_RES as u64
        })
    );
    assert_eq!(
        decode_header(&header_frame(
            FORMAT_VERSION,
            &BakeHeader {
                chunk_vertices: u32::MAX,
                ..good.clone()
            }
        ))
        .map(|_| ()),
        Err(DecodeError::Limit {
            what: "chunk_vertices",
            value: u32::MAX as u64,
            limit: BakeSettings::MAX_CHUNK_VERTICES as u64
        })
    );
    // Line precision outside 2..=14 bits.
    for bits in [0u8, 1, 15, 255] {
        let h = BakeHeader {
            angle_bits: bits,
            ..good.clone()
        };
        match decode_header(&header_frame(FORMAT_VERSION, &h)) {
            Err(DecodeError::Corrupt(m)) => assert!(m.contains("line precision"), "{m}"),
            other => panic!("{bits} bits: {other:?}"),
        }
    }
    // Another format version.
    assert_eq!(
        decode_header(&header_frame(FORMAT_VERSION + 1, &good)).map(|_| ()),
        Err(DecodeError::Version {
            found: FORMAT_VERSION + 1,
            supported: FORMAT_VERSION
        })
    );
    // A header body beyond its limit.
    let mut big = b"BSPVT\0".to_vec();
    big.extend((MAX_HEADER_BYTES + 1).to_le_bytes());
    assert!(matches!(
        decode_header(&big),
        Err(DecodeError::Limit { .. })
    ));
    // A chunk frame where a header frame is expected.
    assert_eq!(
        decode_header(&chunk).map(|_| ()),
        Err(DecodeError::BadMagic)
    );

    // vertex_count 4e9 with no chunks: refused as truncated, without allocating for 4e9.
    let huge = BakeHeader {
        vertex_count: 4_000_000_000,
        ..good.clone()
    };
    assert_eq!(
        decode_bake(&header_frame(FORMAT_VERSION, &huge)).map(|_| ()),
        Err(DecodeError::Truncated("bake ends before its last vertex"))
    );
}

/// A header frame whose body has bytes after the postcard-encoded header should be refused,
/// as a chunk with bytes after its last vertex record is ("N trailing bytes after the last
/// vertex").
#[test]
fn header_frame_with_trailing_bytes_is_refused() {
    let good = header_for(16, 8, 10);
    let mut body = FORMAT_VERSION.to_le_bytes().to_vec();
    body.extend(postcard::to_stdvec(&good).expect("postcard"));
    body.push(0);
    let r = decode_header(&frame(b"BSPVT\0", &body));
    assert!(matches!(r, Err(DecodeError::Corrupt(_))), "{r:?}");
}

#[test]
fn hostile_bake_files() {
    let header = header_for(8, 2, 4);
    let codec = header.codec();
    let v = [VertexTrees::default(), VertexTrees::default()];
    let file = |chunks: &[(u32, usize)]| {
        let mut f = encode_header(&header);
        for &(first, n) in chunks {
            f.extend(encode_chunk(first, &v[..n], &codec));
        }
        f
    };
    assert!(decode_bake(&file(&[(0, 2), (2, 2)])).is_ok());
    // A vertex twice.
    match decode_bake(&file(&[(0, 2), (1, 2), (3, 1)])) {
        Err(DecodeError::Corrupt(m)) => assert_eq!(m, "vertex 1 appears twice"),
        other => panic!("{other:?}"),
    }
    // A hole.
    match decode_bake(&file(&[(0, 1), (2, 2)])) {
        Err(DecodeError::Corrupt(m)) => assert_eq!(m, "vertex 1 is missing"),
        other => panic!("{other:?}"),
    }
    // Missing the end.
    assert_eq!(
        decode_bake(&file(&[(0, 2)])).map(|_| ()),
        Err(DecodeError::Truncated("bake ends before its last vertex"))
    );
    // A chunk beyond the end.
    match decode_bake(&file(&[(0, 2), (2, 2), (4, 1)])) {
        Err(DecodeError::Corrupt(m)) => assert!(m.contains("chunk covers vertices 4..5"), "{m}"),
        other => panic!("{other:?}"),
    }
}

// ---------------------------------------------------------------------------------------------
// Fuzzing: no panics.
// ---------------------------------------------------------------------------------------------

fn fixed_header() -> BakeHeader {
    header_for(8, 16, 64)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2048))]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let h = fixed_header();
        let _ = decode_bake(&bytes);
        let _ = decode_chunk(&bytes, &h);
        let _ = decode_header(&bytes);
        let _ = peek_chunk(&bytes);
        let mut pos = 0;
        let _ = decode_vertex(&bytes, &mut pos, &h, &h.codec());
    }

    /// Random bytes behind valid framing: random chunk headers and bodies with a valid CRC,
    /// and random vertex records in an honest chunk. Whatever decodes must re-encode to
    /// something that decodes to the same trees.
    #[test]
    fn random_framed_bytes_never_panic(
        first in prop_oneof![Just(0u32), 0u32..80, any::<u32>()],
        count in prop_oneof![0u32..20, any::<u32>()],
        raw_len in prop_oneof![0u32..300, any::<u32>()],
        body in proptest::collection::vec(any::<u8>(), 0..200),
        raw in proptest::collection::vec(any::<u8>(), 0..200),
        n in 1u32..8,
    ) {
        let h = fixed_header();
        let _ = decode_chunk(&chunk_frame(ChunkHeader { first_vertex: first, vertex_count: count, raw_len }, &body), &h);
        let mut file = encode_header(&h);
        file.extend(chunk_frame(ChunkHeader { first_vertex: first, vertex_count: count, raw_len }, &body));
        let _ = decode_bake(&file);
        let _ = decode_header(&frame(b"BSPVT\0", &body));
        if let Ok((c, _)) = decode_chunk(&raw_chunk(0, n, &raw), &h) {
            let again = encode_chunk(0, &c.trees, &h.codec());
            let back = decode_chunk(&again, &h).map_err(|e| TestCaseError::fail(e.to_string()))?;
            prop_assert_eq!(back.0.trees, c.trees);
        }
    }
}
