//! The encoded forms of trees: vertex records, chunks of vertices, bake files.
//!
//! **Vertex record** (byte-aligned, so a vertex that sees everything is one byte). A header
//! byte: bits 0–5 = mask of faces that have a tree, bits 6–7 = mode (0: trees follow; 1: every
//! present face is one leaf of value 255; 2: … of value 0). In mode 0, the present faces' trees
//! follow in face order as one MSB-first bit stream, padded to a byte: per node in pre-order a
//! 2-bit tag — `00` split (then `angle_bits` + `offset_bits` of [`QLine`]), `01` leaf 0,
//! `10` leaf 255, `11` leaf with an 8-bit value.
//!
//! **Chunk frame**: `"BVCK"`, u32 LE body length, body = postcard [`ChunkHeader`] + zstd payload
//! (the concatenated vertex records), u32 LE CRC-32 of the body. Frames are self-delimiting, so
//! a file or an HTTP stream is a [`BakeHeader`] frame followed by chunk frames.
//!
//! **Mesh frame** (bake files of refined scenes only): `"BVMS"`, u32 LE body length, body =
//! u32 LE raw length + zstd of the postcard [`Mesh`], CRC-32. It ends the file of a scene whose
//! mesh was refined at bake time (`bake.refine`), so the file carries the very mesh its trees
//! belong to (vertex order = tree order; its content hash is the header's `mesh_hash`). Files of
//! unrefined scenes have none and are byte for byte what they were.
//!
//! **Encoding choice**: headers use postcard (serde, maintained, compact varints, a stable
//! documented wire format); bincode is not used (unmaintained, RUSTSEC-2025-0141). Trees use
//! the hand-written bit stream above because they are the product's core and dominate size.
//!
//! Decoding trusts no length it has not checked: every count is bounded before anything is
//! allocated, zstd output is capped at the declared (and bounded) raw length, and tree depth
//! and node counts are limited.

use serde::{Deserialize, Serialize};

use crate::bspvt::{FaceTree, LineCodec, MAX_DEPTH, Node, QLine, VertexTrees};
use crate::cubemap::FACES;
use crate::error::DecodeError;
use crate::mesh::Mesh;
use crate::scene::{BakeSettings, SplitMethod};

/// Format version written by this build.
pub const FORMAT_VERSION: u16 = 1;
const FILE_MAGIC: &[u8; 6] = b"BSPVT\0";
const CHUNK_MAGIC: &[u8; 4] = b"BVCK";
const MESH_MAGIC: &[u8; 4] = b"BVMS";
/// zstd level for chunks: trees are compressed once at bake time and served many times.
pub(crate) const ZSTD_LEVEL: i32 = 19;

/// Bounds the decoder enforces.
pub const MAX_HEADER_BYTES: u32 = 4096;
/// Largest compressed chunk body the decoder accepts.
pub const MAX_CHUNK_BODY_BYTES: u32 = 64 << 20;
/// Largest uncompressed chunk body the decoder accepts.
pub const MAX_CHUNK_RAW_BYTES: u32 = 256 << 20;
/// Largest compressed mesh frame body the decoder accepts.
pub const MAX_MESH_BODY_BYTES: u32 = 1 << 30;
/// Largest uncompressed mesh the decoder accepts.
pub const MAX_MESH_RAW_BYTES: u32 = 2 << 30;

/// What a reader needs to decode a bake's chunks, and what produced them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BakeHeader {
    /// Cube-map face resolution (pixels per side).
    pub face_res: u32,
    /// Bits of a split line's angle index.
    pub angle_bits: u8,
    /// Bits of a split line's offset index.
    pub offset_bits: u8,
    /// Leaf tolerance ε of the bake ([`BakeSettings::epsilon`]).
    pub epsilon: f32,
    /// Rays per pixel side.
    pub supersampling: u32,
    /// How split lines were chosen.
    pub split: SplitMethod,
    /// Vertices of the mesh (one tree set each).
    pub vertex_count: u32,
    /// Vertices per chunk (the last chunk may hold fewer).
    pub chunk_vertices: u32,
    /// [`crate::Mesh::content_hash`] of the mesh baked.
    pub mesh_hash: u64,
}

impl BakeHeader {
    /// The header of a bake of `vertex_count` vertices with `settings` (the line codec follows from
    /// the face resolution).
    pub fn new(settings: &BakeSettings, vertex_count: u32, mesh_hash: u64) -> BakeHeader {
        let codec = LineCodec::for_resolution(settings.face_res);
        BakeHeader {
            face_res: settings.face_res,
            angle_bits: codec.angle_bits,
            offset_bits: codec.offset_bits,
            epsilon: settings.epsilon,
            supersampling: settings.supersampling,
            split: settings.split,
            vertex_count,
            chunk_vertices: settings.chunk_vertices,
            mesh_hash,
        }
    }

    /// The line codec the trees were quantised with.
    pub fn codec(&self) -> LineCodec {
        LineCodec::new(self.angle_bits, self.offset_bits)
    }

    /// Number of chunks of the bake.
    pub fn chunk_count(&self) -> u32 {
        self.vertex_count.div_ceil(self.chunk_vertices.max(1))
    }

    /// Most nodes a face tree may have: a full tree over every pixel.
    pub fn max_nodes_per_face(&self) -> usize {
        2 * (self.face_res as usize).pow(2) + 1
    }

    fn check(&self) -> Result<(), DecodeError> {
        let lim = |what, value: u64, limit: u64| {
            if value > limit {
                Err(DecodeError::Limit { what, value, limit })
            } else {
                Ok(())
            }
        };
        lim(
            "face_res",
            self.face_res as u64,
            BakeSettings::MAX_FACE_RES as u64,
        )?;
        lim(
            "chunk_vertices",
            self.chunk_vertices as u64,
            BakeSettings::MAX_CHUNK_VERTICES as u64,
        )?;
        if self.face_res < 4 || self.chunk_vertices == 0 {
            return Err(DecodeError::Corrupt(
                "face_res or chunk_vertices is zero".into(),
            ));
        }
        for bits in [self.angle_bits, self.offset_bits] {
            if !(2..=14).contains(&bits) {
                return Err(DecodeError::Corrupt(format!(
                    "line precision of {bits} bits"
                )));
            }
        }
        Ok(())
    }
}

/// The header of a chunk frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChunkHeader {
    /// First vertex of the chunk.
    pub first_vertex: u32,
    /// Vertices in the chunk.
    pub vertex_count: u32,
    /// Length of the uncompressed vertex records.
    pub raw_len: u32,
}

/// A decoded chunk.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Chunk {
    /// First vertex of the chunk.
    pub first_vertex: u32,
    /// One entry per vertex, in vertex order.
    pub trees: Vec<VertexTrees>,
}

// ---------------------------------------------------------------------------------------------
// Bit streams.

struct BitWriter<'a> {
    out: &'a mut Vec<u8>,
    acc: u64,
    bits: u32,
}

impl<'a> BitWriter<'a> {
    fn new(out: &'a mut Vec<u8>) -> Self {
        BitWriter {
            out,
            acc: 0,
            bits: 0,
        }
    }

    fn put(&mut self, value: u32, n: u32) {
        debug_assert!(n <= 32 && (n == 32 || value < (1 << n)));
        self.acc = (self.acc << n) | value as u64;
        self.bits += n;
        while self.bits >= 8 {
            self.bits -= 8;
            self.out.push((self.acc >> self.bits) as u8);
        }
    }

    fn finish(mut self) {
        if self.bits > 0 {
            let pad = 8 - self.bits;
            self.put(0, pad);
        }
    }
}

struct BitReader<'a> {
    data: &'a [u8],
    pos: usize,
    acc: u64,
    bits: u32,
}

impl<'a> BitReader<'a> {
    fn new(data: &'a [u8], pos: usize) -> Self {
        BitReader {
            data,
            pos,
            acc: 0,
            bits: 0,
        }
    }

    fn get(&mut self, n: u32) -> Result<u32, DecodeError> {
        while self.bits < n {
            let b = *self
                .data
                .get(self.pos)
                .ok_or(DecodeError::Truncated("tree bit stream"))?;
            self.pos += 1;
            self.acc = (self.acc << 8) | b as u64;
            self.bits += 8;
        }
        self.bits -= n;
        Ok(((self.acc >> self.bits) & ((1u64 << n) - 1)) as u32)
    }

    /// Byte position after the (padded) stream.
    fn end(&self) -> usize {
        self.pos
    }
}

// ---------------------------------------------------------------------------------------------
// Vertex records.

const MODE_TREES: u8 = 0;
const MODE_ALL_VISIBLE: u8 = 1;
const MODE_ALL_OCCLUDED: u8 = 2;

/// Appends the record of one vertex to `out`.
pub fn encode_vertex(trees: &VertexTrees, codec: &LineCodec, out: &mut Vec<u8>) {
    let mut mask = 0u8;
    for (f, t) in trees.faces.iter().enumerate() {
        if t.is_some() {
            mask |= 1 << f;
        }
    }
    let uniform: Vec<Option<u8>> = trees
        .faces
        .iter()
        .flatten()
        .map(FaceTree::uniform_value)
        .collect();
    let all = |v: u8| uniform.iter().all(|&u| u == Some(v));
    if all(255) {
        out.push(mask | (MODE_ALL_VISIBLE << 6));
        return;
    }
    if all(0) {
        out.push(mask | (MODE_ALL_OCCLUDED << 6));
        return;
    }
    out.push(mask | (MODE_TREES << 6));
    let mut w = BitWriter::new(out);
    for t in trees.faces.iter().flatten() {
        for node in &t.nodes {
            match *node {
                Node::Split { line, .. } => {
                    w.put(0, 2);
                    w.put(line.angle as u32, codec.angle_bits as u32);
                    w.put(line.offset as u32, codec.offset_bits as u32);
                }
                Node::Leaf { value: 0 } => w.put(1, 2),
                Node::Leaf { value: 255 } => w.put(2, 2),
                Node::Leaf { value } => {
                    w.put(3, 2);
                    w.put(value as u32, 8);
                }
            }
        }
    }
    w.finish();
}

/// Decodes the record of one vertex starting at `*pos`, advancing `*pos` past it.
pub fn decode_vertex(
    data: &[u8],
    pos: &mut usize,
    header: &BakeHeader,
    codec: &LineCodec,
) -> Result<VertexTrees, DecodeError> {
    let h = *data
        .get(*pos)
        .ok_or(DecodeError::Truncated("vertex header"))?;
    *pos += 1;
    let mask = h & 0x3f;
    let mode = h >> 6;
    let mut trees = VertexTrees::default();
    let present = (0..FACES).filter(|f| mask & (1 << f) != 0);
    match mode {
        MODE_ALL_VISIBLE | MODE_ALL_OCCLUDED => {
            let v = if mode == MODE_ALL_VISIBLE { 255 } else { 0 };
            for f in present {
                trees.faces[f] = Some(FaceTree::leaf(v));
            }
        }
        MODE_TREES => {
            let mut r = BitReader::new(data, *pos);
            let max_nodes = header.max_nodes_per_face();
            for f in present {
                let mut nodes = Vec::new();
                decode_node(&mut r, codec, &mut nodes, 0, max_nodes)?;
                trees.faces[f] = Some(FaceTree { nodes });
            }
            *pos = r.end();
        }
        _ => return Err(DecodeError::Corrupt(format!("vertex record mode {mode}"))),
    }
    Ok(trees)
}

fn decode_node(
    r: &mut BitReader,
    codec: &LineCodec,
    nodes: &mut Vec<Node>,
    depth: usize,
    max_nodes: usize,
) -> Result<(), DecodeError> {
    if nodes.len() >= max_nodes {
        return Err(DecodeError::Limit {
            what: "nodes per face tree",
            value: nodes.len() as u64 + 1,
            limit: max_nodes as u64,
        });
    }
    let node = match r.get(2)? {
        0 => {
            if depth >= MAX_DEPTH {
                return Err(DecodeError::Limit {
                    what: "tree depth",
                    value: depth as u64 + 1,
                    limit: MAX_DEPTH as u64,
                });
            }
            let angle = r.get(codec.angle_bits as u32)? as u16;
            let offset = r.get(codec.offset_bits as u32)? as u16;
            let at = nodes.len();
            nodes.push(Node::Split {
                line: QLine { angle, offset },
                right: 0,
            });
            decode_node(r, codec, nodes, depth + 1, max_nodes)?;
            let right = nodes.len() as u32;
            nodes[at] = Node::Split {
                line: QLine { angle, offset },
                right,
            };
            decode_node(r, codec, nodes, depth + 1, max_nodes)?;
            return Ok(());
        }
        1 => Node::Leaf { value: 0 },
        2 => Node::Leaf { value: 255 },
        _ => Node::Leaf {
            value: r.get(8)? as u8,
        },
    };
    nodes.push(node);
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Chunk frames.

/// Encodes vertices `first_vertex ..` into one chunk frame.
pub fn encode_chunk(first_vertex: u32, trees: &[VertexTrees], codec: &LineCodec) -> Vec<u8> {
    let mut raw = Vec::new();
    for t in trees {
        encode_vertex(t, codec, &mut raw);
    }
    let payload = zstd::bulk::compress(&raw, ZSTD_LEVEL).unwrap_or_else(|e| {
        // Compressing an in-memory buffer fails only on allocation failure.
        panic!("zstd compression of a {} byte chunk failed: {e}", raw.len())
    });
    let header = ChunkHeader {
        first_vertex,
        vertex_count: trees.len() as u32,
        raw_len: raw.len() as u32,
    };
    let mut body = postcard::to_stdvec(&header).unwrap_or_default();
    body.extend_from_slice(&payload);
    frame(CHUNK_MAGIC, &body)
}

fn frame(magic: &[u8], body: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(body.len() + magic.len() + 8);
    out.extend_from_slice(magic);
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(body);
    out.extend_from_slice(&crc32fast::hash(body).to_le_bytes());
    out
}

/// Reads one frame: returns (body, bytes consumed) after checking magic, bounds and CRC.
fn read_frame<'a>(
    data: &'a [u8],
    magic: &[u8],
    max_body: u32,
) -> Result<(&'a [u8], usize), DecodeError> {
    let m = magic.len();
    if data.len() < m + 4 {
        return Err(DecodeError::Truncated("frame header"));
    }
    if &data[..m] != magic {
        return Err(DecodeError::BadMagic);
    }
    let len = u32::from_le_bytes([data[m], data[m + 1], data[m + 2], data[m + 3]]);
    if len > max_body {
        return Err(DecodeError::Limit {
            what: "frame body bytes",
            value: len as u64,
            limit: max_body as u64,
        });
    }
    let end = m + 4 + len as usize;
    if data.len() < end + 4 {
        return Err(DecodeError::Truncated("frame body"));
    }
    let body = &data[m + 4..end];
    let stored = u32::from_le_bytes([data[end], data[end + 1], data[end + 2], data[end + 3]]);
    let computed = crc32fast::hash(body);
    // Under `cargo fuzz` (cfg `fuzzing`) a wrong checksum is let through, or mutated frames
    // would never reach the decoders behind it.
    if stored != computed && !cfg!(fuzzing) {
        return Err(DecodeError::Checksum { stored, computed });
    }
    Ok((body, end + 4))
}

/// Checks a chunk frame at the start of `data` (magic, bounds, checksum) and returns its header
/// and length without decompressing it.
pub fn peek_chunk(data: &[u8]) -> Result<(ChunkHeader, usize), DecodeError> {
    let (body, used) = read_frame(data, CHUNK_MAGIC, MAX_CHUNK_BODY_BYTES)?;
    let (h, _) = postcard::take_from_bytes::<ChunkHeader>(body)
        .map_err(|e| DecodeError::Corrupt(format!("chunk header: {e}")))?;
    Ok((h, used))
}

/// Decodes the chunk frame at the start of `data`; returns it and the bytes consumed.
pub fn decode_chunk(data: &[u8], header: &BakeHeader) -> Result<(Chunk, usize), DecodeError> {
    header.check()?;
    let (body, used) = read_frame(data, CHUNK_MAGIC, MAX_CHUNK_BODY_BYTES)?;
    let (h, payload) = postcard::take_from_bytes::<ChunkHeader>(body)
        .map_err(|e| DecodeError::Corrupt(format!("chunk header: {e}")))?;
    if h.vertex_count > header.chunk_vertices {
        return Err(DecodeError::Limit {
            what: "vertices per chunk",
            value: h.vertex_count as u64,
            limit: header.chunk_vertices as u64,
        });
    }
    let end = h.first_vertex as u64 + h.vertex_count as u64;
    if end > header.vertex_count as u64 {
        return Err(DecodeError::Corrupt(format!(
            "chunk covers vertices {}..{end} of a {}-vertex bake",
            h.first_vertex, header.vertex_count
        )));
    }
    if h.raw_len > MAX_CHUNK_RAW_BYTES {
        return Err(DecodeError::Limit {
            what: "chunk raw bytes",
            value: h.raw_len as u64,
            limit: MAX_CHUNK_RAW_BYTES as u64,
        });
    }
    if (h.raw_len as u64) < h.vertex_count as u64 {
        return Err(DecodeError::Corrupt(
            "raw length shorter than one byte per vertex".into(),
        ));
    }
    // zstd refuses to write more than `raw_len` bytes: a decompression bomb fails here.
    let raw = zstd::bulk::decompress(payload, h.raw_len as usize)
        .map_err(|e| DecodeError::Corrupt(format!("chunk payload: {e}")))?;
    if raw.len() != h.raw_len as usize {
        return Err(DecodeError::Corrupt(format!(
            "chunk payload is {} bytes, header says {}",
            raw.len(),
            h.raw_len
        )));
    }
    let codec = header.codec();
    // raw_len ≥ vertex_count was checked, so this reservation is bounded by real data.
    let mut trees = Vec::with_capacity(h.vertex_count as usize);
    let mut pos = 0;
    for _ in 0..h.vertex_count {
        trees.push(decode_vertex(&raw, &mut pos, header, &codec)?);
    }
    if pos != raw.len() {
        return Err(DecodeError::Corrupt(format!(
            "{} trailing bytes after the last vertex",
            raw.len() - pos
        )));
    }
    Ok((
        Chunk {
            first_vertex: h.first_vertex,
            trees,
        },
        used,
    ))
}

// ---------------------------------------------------------------------------------------------
// Bake files.

/// The header frame of a bake file or tree stream.
pub fn encode_header(header: &BakeHeader) -> Vec<u8> {
    let mut body = FORMAT_VERSION.to_le_bytes().to_vec();
    body.extend(postcard::to_stdvec(header).unwrap_or_default());
    frame(FILE_MAGIC, &body)
}

/// Decodes a header frame; returns it and the bytes consumed.
pub fn decode_header(data: &[u8]) -> Result<(BakeHeader, usize), DecodeError> {
    let (body, used) = read_frame(data, FILE_MAGIC, MAX_HEADER_BYTES)?;
    if body.len() < 2 {
        return Err(DecodeError::Truncated("format version"));
    }
    let version = u16::from_le_bytes([body[0], body[1]]);
    if version != FORMAT_VERSION {
        return Err(DecodeError::Version {
            found: version,
            supported: FORMAT_VERSION,
        });
    }
    let (header, rest) = postcard::take_from_bytes::<BakeHeader>(&body[2..])
        .map_err(|e| DecodeError::Corrupt(format!("bake header: {e}")))?;
    if !rest.is_empty() {
        return Err(DecodeError::Corrupt(format!(
            "{} trailing bytes after the bake header",
            rest.len()
        )));
    }
    header.check()?;
    Ok((header, used))
}

/// A whole decoded bake.
#[derive(Clone, Debug, PartialEq)]
pub struct Bake {
    /// The bake's header.
    pub header: BakeHeader,
    /// One entry per vertex, in vertex order.
    pub trees: Vec<VertexTrees>,
    /// The mesh the trees belong to, when the file carries it (a refined scene's bake).
    pub mesh: Option<Mesh>,
}

/// The mesh frame that ends the bake file of a refined scene (see the module docs).
pub fn encode_mesh(mesh: &Mesh) -> Vec<u8> {
    let raw = postcard::to_stdvec(mesh).unwrap_or_default();
    let mut body = (raw.len() as u32).to_le_bytes().to_vec();
    body.extend(zstd::bulk::compress(&raw, 3).unwrap_or_default());
    frame(MESH_MAGIC, &body)
}

/// Decodes a mesh frame at the start of `data`; returns it and the bytes consumed.
pub fn decode_mesh(data: &[u8]) -> Result<(Mesh, usize), DecodeError> {
    let (body, used) = read_frame(data, MESH_MAGIC, MAX_MESH_BODY_BYTES)?;
    if body.len() < 4 {
        return Err(DecodeError::Truncated("mesh raw length"));
    }
    let raw_len = u32::from_le_bytes([body[0], body[1], body[2], body[3]]);
    if raw_len > MAX_MESH_RAW_BYTES {
        return Err(DecodeError::Limit {
            what: "mesh raw bytes",
            value: raw_len as u64,
            limit: MAX_MESH_RAW_BYTES as u64,
        });
    }
    // zstd refuses to write more than `raw_len` bytes: a decompression bomb fails here.
    let raw = zstd::bulk::decompress(&body[4..], raw_len as usize)
        .map_err(|e| DecodeError::Corrupt(format!("mesh payload: {e}")))?;
    let mesh: Mesh =
        postcard::from_bytes(&raw).map_err(|e| DecodeError::Corrupt(format!("mesh: {e}")))?;
    mesh.validate()
        .map_err(|e| DecodeError::Corrupt(format!("mesh: {e}")))?;
    Ok((mesh, used))
}

/// Decodes a bake file: a header frame followed by chunk frames covering every vertex once,
/// and for a refined scene a mesh frame last.
pub fn decode_bake(data: &[u8]) -> Result<Bake, DecodeError> {
    let (header, mut pos) = decode_header(data)?;
    let n = header.vertex_count as usize;
    let mut slots: Vec<Option<VertexTrees>> = Vec::new();
    let mut mesh = None;
    // Grow with the data instead of trusting vertex_count for the allocation.
    while pos < data.len() {
        if data[pos..].starts_with(MESH_MAGIC) {
            let (m, used) = decode_mesh(&data[pos..])?;
            if pos + used != data.len() {
                return Err(DecodeError::Corrupt("data after the mesh frame".into()));
            }
            if m.content_hash() != header.mesh_hash || m.vertex_count() != n {
                return Err(DecodeError::Corrupt(
                    "the mesh frame is not the mesh the header names".into(),
                ));
            }
            mesh = Some(m);
            break;
        }
        let (chunk, used) = decode_chunk(&data[pos..], &header)?;
        pos += used;
        let first = chunk.first_vertex as usize;
        let need = first + chunk.trees.len();
        if slots.len() < need {
            slots.resize(need, None);
        }
        for (i, t) in chunk.trees.into_iter().enumerate() {
            if slots[first + i].replace(t).is_some() {
                return Err(DecodeError::Corrupt(format!(
                    "vertex {} appears twice",
                    first + i
                )));
            }
        }
    }
    if slots.len() != n {
        return Err(DecodeError::Truncated("bake ends before its last vertex"));
    }
    let trees = slots
        .into_iter()
        .enumerate()
        .map(|(i, t)| t.ok_or_else(|| DecodeError::Corrupt(format!("vertex {i} is missing"))))
        .collect::<Result<_, _>>()?;
    Ok(Bake {
        header,
        trees,
        mesh,
    })
}
