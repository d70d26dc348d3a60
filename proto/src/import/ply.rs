//! PLY (Stanford polygon file format) reader, written by hand.
//!
//! Why not `ply-rs-bw` (which the workspace declares)? Version 4 is careful about allocation, but:
//!
//! - its ASCII grammar only accepts numbers of the form `[-+]?digits(.digits)?(e[-+]?digits)?`,
//!   so `nan`, `inf`, `-nan` (what C's `printf` writes), `.5` and `5.` are parse errors: a NaN
//!   coordinate could not be reported as [`MeshError::NonFinitePosition`], and valid files with
//!   `5.` would be refused;
//! - it reads ASCII payloads strictly one element per line, where the format is a token stream;
//! - it stores every element as a map from property name to value (one allocation per vertex);
//! - the declared element counts must be checked against the file size before the payload is
//!   read anyway, which needs the header parsed first.
//!
//! The format is small: a text header, then the elements in header order, either as a
//! whitespace-separated token stream (ASCII) or as packed little- or big-endian records. This
//! reader checks every count against the bytes that remain before reserving memory, and reads
//! through a bounds-checked cursor, so a truncated or lying file is an error, never a panic or a
//! huge allocation.
//!
//! Read: vertex `x`, `y`, `z` (any scalar type), optional `nx`, `ny`, `nz`; face
//! `vertex_indices` or `vertex_index` (a list of any integer type), fan-triangulated. Other
//! elements and properties are skipped.

use glam::Vec3;

use super::{Limits, finish, is_degenerate};
use crate::error::MeshError;
use crate::mesh::Mesh;

fn malformed(message: impl Into<String>) -> MeshError {
    MeshError::Malformed {
        format: "PLY",
        message: message.into(),
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_int(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Clone, Copy, Debug)]
enum PropType {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

impl PropType {
    /// The fewest bytes a binary record of this property takes (an empty list: its count only).
    fn min_binary_size(self) -> u64 {
        match self {
            PropType::Scalar(s) => s.size() as u64,
            PropType::List { count, .. } => count.size() as u64,
        }
    }
}

#[derive(Debug)]
struct Property {
    name: String,
    ty: PropType,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

impl Element {
    fn what(&self) -> &'static str {
        match self.name.as_str() {
            "vertex" => "vertices",
            "face" => "faces",
            _ => "elements",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Ascii,
    LittleEndian,
    BigEndian,
}

#[derive(Debug)]
struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Byte offset of the payload (just after `end_header` and its line break).
    payload_start: usize,
}

fn parse_header(bytes: &[u8]) -> Result<Header, MeshError> {
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        if pos >= bytes.len() {
            return Err(malformed(
                "the header has no `end_header` line (truncated file?)",
            ));
        }
        let rest = &bytes[pos..];
        let (raw, next) = match rest.iter().position(|&b| b == b'\n') {
            Some(i) => (&rest[..i], pos + i + 1),
            None => (rest, bytes.len()),
        };
        line_no += 1;
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        let text = std::str::from_utf8(raw).map_err(|_| {
            if line_no == 1 {
                malformed("not a PLY file (the first line is not `ply`)")
            } else {
                malformed(format!("header line {line_no} is not text"))
            }
        })?;
        let mut words = text.split_ascii_whitespace();
        let keyword = words.next().unwrap_or("");
        if line_no == 1 {
            if keyword != "ply" || words.next().is_some() {
                return Err(malformed("not a PLY file (the first line is not `ply`)"));
            }
            pos = next;
            continue;
        }
        let bad = |what: &str| malformed(format!("header line {line_no} ({text:?}): {what}"));
        match keyword {
            "format" => {
                let enc = match words.next() {
                    Some("ascii") => Encoding::Ascii,
                    Some("binary_little_endian") => Encoding::LittleEndian,
                    Some("binary_big_endian") => Encoding::BigEndian,
                    _ => return Err(bad("unknown format")),
                };
                if words.next() != Some("1.0") {
                    return Err(bad("only PLY version 1.0 is supported"));
                }
                if encoding.replace(enc).is_some() {
                    return Err(bad("a second `format` line"));
                }
            }
            "comment" | "obj_info" | "" => {}
            "element" => {
                let (Some(name), Some(count), None) = (words.next(), words.next(), words.next())
                else {
                    return Err(bad("expected `element NAME COUNT`"));
                };
                let count: u64 = count
                    .parse()
                    .map_err(|_| bad("the element count is not a non-negative integer"))?;
                if elements.iter().any(|e| e.name == name) {
                    return Err(bad("the element is declared twice"));
                }
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            "property" => {
                let ty = match words.next() {
                    Some("list") => {
                        let count = words.next().and_then(Scalar::parse);
                        let item = words.next().and_then(Scalar::parse);
                        match (count, item) {
                            (Some(count), Some(item)) if count.is_int() => {
                                PropType::List { count, item }
                            }
                            _ => return Err(bad("expected `property list INTTYPE TYPE NAME`")),
                        }
                    }
                    Some(t) => {
                        PropType::Scalar(Scalar::parse(t).ok_or_else(|| bad("unknown type"))?)
                    }
                    None => return Err(bad("expected `property TYPE NAME`")),
                };
                let (Some(name), None) = (words.next(), words.next()) else {
                    return Err(bad("expected `property TYPE NAME`"));
                };
                let element = elements
                    .last_mut()
                    .ok_or_else(|| bad("a property before any element"))?;
                element.props.push(Property {
                    name: name.to_string(),
                    ty,
                });
            }
            "end_header" => {
                let encoding =
                    encoding.ok_or_else(|| malformed("the header has no `format` line"))?;
                return Ok(Header {
                    encoding,
                    elements,
                    payload_start: next,
                });
            }
            _ => return Err(bad("unknown header keyword")),
        }
        pos = next;
    }
}

/// Rejects declared counts that cannot fit in the payload, then counts over the limits.
fn check_counts(header: &Header, file_bytes: usize, limits: &Limits) -> Result<(), MeshError> {
    let payload = (file_bytes - header.payload_start.min(file_bytes)) as u64;
    let mut needed: u64 = 0;
    for e in &header.elements {
        if e.props.is_empty() {
            // Records without properties take no bytes; they are never read.
            continue;
        }
        let min_record = match header.encoding {
            // Every property is at least one token (a list: its length) of at least one
            // character plus a separator; the file's very last token may lack its separator.
            Encoding::Ascii => 2 * e.props.len() as u64,
            _ => e.props.iter().map(|p| p.ty.min_binary_size()).sum(),
        };
        needed = needed.saturating_add(e.count.saturating_mul(min_record));
        let available = match header.encoding {
            Encoding::Ascii => payload + 1,
            _ => payload,
        };
        if needed > available {
            return Err(MeshError::AbsurdCount {
                what: e.what(),
                declared: e.count,
                file_bytes: file_bytes as u64,
            });
        }
    }
    for e in &header.elements {
        match e.name.as_str() {
            "vertex" => limits.check_vertices(e.count)?,
            "face" if e.count > limits.max_triangles => {
                return Err(MeshError::TooLarge {
                    what: "faces",
                    count: e.count,
                    limit: limits.max_triangles,
                });
            }
            _ => {}
        }
    }
    Ok(())
}

/// A failed read, given context by the element loop.
enum ReadError {
    Eof,
    Token(String),
}

/// Reads scalars from the payload in either encoding.
trait Source {
    fn number(&mut self, ty: Scalar) -> Result<f64, ReadError>;
    fn int(&mut self, ty: Scalar) -> Result<i64, ReadError>;
    fn skip(&mut self, ty: Scalar, n: u64) -> Result<(), ReadError>;
}

struct Binary<'a> {
    data: &'a [u8],
    pos: usize,
    big: bool,
}

impl Binary<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], ReadError> {
        let end = self.pos.checked_add(N).ok_or(ReadError::Eof)?;
        let s = self.data.get(self.pos..end).ok_or(ReadError::Eof)?;
        let mut a: [u8; N] = s.try_into().map_err(|_| ReadError::Eof)?;
        if self.big {
            a.reverse();
        }
        self.pos = end;
        Ok(a)
    }
}

impl Source for Binary<'_> {
    fn number(&mut self, ty: Scalar) -> Result<f64, ReadError> {
        Ok(match ty {
            Scalar::F32 => f64::from(f32::from_le_bytes(self.take()?)),
            Scalar::F64 => f64::from_le_bytes(self.take()?),
            _ => self.int(ty)? as f64,
        })
    }

    fn int(&mut self, ty: Scalar) -> Result<i64, ReadError> {
        Ok(match ty {
            Scalar::I8 => i64::from(i8::from_le_bytes(self.take()?)),
            Scalar::U8 => i64::from(u8::from_le_bytes(self.take()?)),
            Scalar::I16 => i64::from(i16::from_le_bytes(self.take()?)),
            Scalar::U16 => i64::from(u16::from_le_bytes(self.take()?)),
            Scalar::I32 => i64::from(i32::from_le_bytes(self.take()?)),
            Scalar::U32 => i64::from(u32::from_le_bytes(self.take()?)),
            Scalar::F32 | Scalar::F64 => {
                let x = self.number(ty)?;
                return float_to_int(x).ok_or_else(|| ReadError::Token(x.to_string()));
            }
        })
    }

    fn skip(&mut self, ty: Scalar, n: u64) -> Result<(), ReadError> {
        let len = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(ty.size()))
            .ok_or(ReadError::Eof)?;
        let end = self.pos.checked_add(len).ok_or(ReadError::Eof)?;
        if end > self.data.len() {
            return Err(ReadError::Eof);
        }
        self.pos = end;
        Ok(())
    }
}

/// An integral float (some writers store list counts and indices as floats): its value.
fn float_to_int(x: f64) -> Option<i64> {
    (x.fract() == 0.0 && x.abs() < 9.0e15).then_some(x as i64)
}

struct Ascii<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Ascii<'a> {
    fn token(&mut self) -> Result<&'a str, ReadError> {
        let data = self.data;
        let mut i = self.pos;
        while i < data.len() && data[i].is_ascii_whitespace() {
            i += 1;
        }
        let start = i;
        while i < data.len() && !data[i].is_ascii_whitespace() {
            i += 1;
        }
        self.pos = i;
        if start == i {
            return Err(ReadError::Eof);
        }
        std::str::from_utf8(&data[start..i])
            .map_err(|_| ReadError::Token(String::from_utf8_lossy(&data[start..i]).into()))
    }
}

impl Source for Ascii<'_> {
    fn number(&mut self, _ty: Scalar) -> Result<f64, ReadError> {
        let t = self.token()?;
        // Rust's float syntax accepts `nan`, `inf`, `infinity` in any case, `.5` and `5.`.
        // C's printf also writes `-nan` and `nan(ind)`-like forms; map the common ones.
        let t2 = t.strip_prefix(['-', '+']).unwrap_or(t);
        if t2
            .as_bytes()
            .get(..3)
            .is_some_and(|b| b.eq_ignore_ascii_case(b"nan"))
        {
            return Ok(f64::NAN);
        }
        t.parse::<f64>()
            .map_err(|_| ReadError::Token(t.chars().take(40).collect()))
    }

    fn int(&mut self, _ty: Scalar) -> Result<i64, ReadError> {
        let t = self.token()?;
        t.parse::<i64>()
            .ok()
            .or_else(|| t.parse::<f64>().ok().and_then(float_to_int))
            .ok_or_else(|| ReadError::Token(t.chars().take(40).collect()))
    }

    fn skip(&mut self, _ty: Scalar, n: u64) -> Result<(), ReadError> {
        for _ in 0..n {
            self.token()?;
        }
        Ok(())
    }
}

/// What the reader does with each property of an element.
#[derive(Clone, Copy)]
enum Role {
    Skip,
    /// Vertex component: 0..3 position, 3..6 normal.
    Vertex(usize),
    FaceIndices,
}

pub(super) fn parse(bytes: &[u8], limits: &Limits) -> Result<Mesh, MeshError> {
    let header = parse_header(bytes)?;
    check_counts(&header, bytes.len(), limits)?;

    let vertex = header
        .elements
        .iter()
        .find(|e| e.name == "vertex")
        .ok_or_else(|| malformed("the file has no `vertex` element"))?;
    let find = |name: &str| {
        vertex
            .props
            .iter()
            .position(|p| p.name == name && matches!(p.ty, PropType::Scalar(_)))
    };
    for c in ["x", "y", "z"] {
        if find(c).is_none() {
            return Err(malformed(format!(
                "the vertex element has no scalar `{c}` property"
            )));
        }
    }
    let has_normals = ["nx", "ny", "nz"].iter().all(|c| find(c).is_some());
    let vertex_count = vertex.count;
    let face = header.elements.iter().find(|e| e.name == "face");
    if let Some(face) = face {
        match indices_type(face) {
            Some((_, item)) if item.is_int() => {}
            Some(_) => {
                return Err(malformed(
                    "the face element's vertex_indices is not a list of integers",
                ));
            }
            None => {
                return Err(malformed(
                    "the face element has no `vertex_indices` (or `vertex_index`) list",
                ));
            }
        }
    }
    let face_count = face.map_or(0, |f| f.count);
    if face_count == 0 {
        return Err(MeshError::NoTriangles);
    }

    // Counts are now known to fit in the file, so reserving them is bounded by its size. A face
    // yields a triangle only if it has at least three indices, which bounds that reservation
    // more tightly than its minimum record size.
    let payload = bytes.get(header.payload_start..).unwrap_or(&[]);
    let min_triangle_record = match (header.encoding, face.and_then(indices_type)) {
        (Encoding::Ascii, _) => 8,
        (_, Some((count, item))) => (count.size() + 3 * item.size()) as u64,
        (_, None) => 1,
    };
    let tri_reserve = face_count.min(payload.len() as u64 / min_triangle_record);
    let mut mesh = Mesh {
        positions: Vec::with_capacity(vertex_count as usize),
        normals: Vec::with_capacity(if has_normals {
            vertex_count as usize
        } else {
            0
        }),
        triangles: Vec::with_capacity(tri_reserve as usize),
        material_ids: Vec::new(),
        uvs: Vec::new(),
    };
    let mut reader = Reader {
        header: &header,
        vertex_count,
        limits,
        has_normals,
        mesh: &mut mesh,
        corners: Vec::new(),
    };
    match header.encoding {
        Encoding::Ascii => reader.read_all(&mut Ascii {
            data: payload,
            pos: 0,
        })?,
        enc => reader.read_all(&mut Binary {
            data: payload,
            pos: 0,
            big: enc == Encoding::BigEndian,
        })?,
    }
    finish(mesh)
}

/// The count and item types of a face's first indices list.
fn indices_type(face: &Element) -> Option<(Scalar, Scalar)> {
    face.props.iter().find_map(|p| match p.ty {
        PropType::List { count, item }
            if p.name == "vertex_indices" || p.name == "vertex_index" =>
        {
            Some((count, item))
        }
        _ => None,
    })
}

struct Reader<'a> {
    header: &'a Header,
    vertex_count: u64,
    limits: &'a Limits,
    has_normals: bool,
    mesh: &'a mut Mesh,
    corners: Vec<u32>,
}

impl Reader<'_> {
    fn read_all(&mut self, src: &mut dyn Source) -> Result<(), MeshError> {
        let header = self.header;
        for e in &header.elements {
            if e.props.is_empty() {
                continue;
            }
            let roles: Vec<Role> = e
                .props
                .iter()
                .map(|p| match (e.name.as_str(), p.name.as_str(), p.ty) {
                    ("vertex", n, PropType::Scalar(_)) => {
                        match ["x", "y", "z", "nx", "ny", "nz"]
                            .iter()
                            .position(|c| *c == n)
                        {
                            Some(i) if i < 3 || self.has_normals => Role::Vertex(i),
                            _ => Role::Skip,
                        }
                    }
                    ("face", "vertex_indices" | "vertex_index", PropType::List { .. }) => {
                        Role::FaceIndices
                    }
                    _ => Role::Skip,
                })
                .collect();
            // Only the first indices list of a face is used (a file could declare both names).
            let first_indices = roles.iter().position(|r| matches!(r, Role::FaceIndices));
            for record in 0..e.count {
                let mut v = [0f32; 6];
                for (k, (p, role)) in e.props.iter().zip(&roles).enumerate() {
                    let role = match role {
                        Role::FaceIndices if Some(k) != first_indices => &Role::Skip,
                        r => r,
                    };
                    self.read_property(src, p, *role, &mut v)
                        .map_err(|err| context(err, e, record, &p.name))?;
                }
                if e.name == "vertex" {
                    let pos = Vec3::new(v[0], v[1], v[2]);
                    if !pos.is_finite() {
                        return Err(MeshError::NonFinitePosition {
                            vertex: self.mesh.positions.len(),
                        });
                    }
                    self.mesh.positions.push(pos);
                    if self.has_normals {
                        self.mesh.normals.push(Vec3::new(v[3], v[4], v[5]));
                    }
                }
            }
        }
        Ok(())
    }

    fn read_property(
        &mut self,
        src: &mut dyn Source,
        p: &Property,
        role: Role,
        v: &mut [f32; 6],
    ) -> Result<(), PropError> {
        match (p.ty, role) {
            (PropType::Scalar(ty), Role::Vertex(i)) => {
                v[i] = src.number(ty)? as f32;
            }
            (PropType::Scalar(ty), _) => src.skip(ty, 1)?,
            (PropType::List { count, item }, Role::FaceIndices) => {
                let n = list_len(src.int(count)?)?;
                self.corners.clear();
                for _ in 0..n {
                    let i = src.int(item)?;
                    if i < 0 {
                        return Err(PropError::Mesh(malformed(format!(
                            "negative vertex index {i}"
                        ))));
                    }
                    let i = i as u64;
                    if i >= self.vertex_count {
                        return Err(PropError::Mesh(MeshError::IndexOutOfRange {
                            triangle: self.mesh.triangles.len(),
                            index: i,
                            vertices: self.vertex_count as usize,
                        }));
                    }
                    // vertex_count ≤ u32::MAX (checked against the limits).
                    self.corners.push(i as u32);
                    if self.corners.len() >= 3 {
                        let c = &self.corners;
                        let t = [c[0], c[c.len() - 2], c[c.len() - 1]];
                        if !is_degenerate(&t) {
                            self.limits
                                .check_triangles(self.mesh.triangles.len() as u64 + 1)
                                .map_err(PropError::Mesh)?;
                            self.mesh.triangles.push(t);
                        }
                    }
                }
            }
            (PropType::List { count, item }, _) => {
                let n = list_len(src.int(count)?)?;
                src.skip(item, n)?;
            }
        }
        Ok(())
    }
}

fn list_len(n: i64) -> Result<u64, PropError> {
    u64::try_from(n).map_err(|_| PropError::Mesh(malformed(format!("negative list length {n}"))))
}

enum PropError {
    Read(ReadError),
    Mesh(MeshError),
}

impl From<ReadError> for PropError {
    fn from(e: ReadError) -> Self {
        PropError::Read(e)
    }
}

fn context(err: PropError, e: &Element, record: u64, prop: &str) -> MeshError {
    let at = format!("{} {record} of {} (property `{prop}`)", e.name, e.count);
    match err {
        PropError::Read(ReadError::Eof) => malformed(format!("truncated: the file ends in {at}")),
        PropError::Read(ReadError::Token(t)) => malformed(format!("bad number {t:?} in {at}")),
        PropError::Mesh(MeshError::Malformed { message, .. }) => {
            malformed(format!("{message} in {at}"))
        }
        PropError::Mesh(m) => m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(s: &[u8]) -> Result<Mesh, MeshError> {
        parse(s, &Limits::default())
    }

    #[test]
    fn ascii_tokens_may_span_lines() {
        let m = load(
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
              property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
              0 0 0 1 0\n0 0 1 0\n3 0 1\n2",
        )
        .map_err(|e| e.to_string());
        let m = m.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        assert!((m.normals[0] - Vec3::Z).length() < 1e-6);
    }

    #[test]
    fn multibyte_tokens_are_errors() {
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                    property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
                    end_header\n\u{800} 0 0\n0 0 0\n0 0 0\n3 0 1 2\n";
        let r = load(text.as_bytes());
        assert!(
            matches!(&r, Err(MeshError::Malformed { message, .. }) if message.contains("bad number")),
            "{r:?}"
        );
    }

    #[test]
    fn nan_forms() {
        for tok in ["nan", "-nan", "NaN", "inf", "-inf", "1e39"] {
            let text = format!(
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                 property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
                 end_header\n0 0 0\n1 {tok} 0\n0 1 0\n3 0 1 2\n"
            );
            let r = load(text.as_bytes());
            assert!(
                matches!(r, Err(MeshError::NonFinitePosition { vertex: 1 })),
                "{tok}: {r:?}"
            );
        }
    }
}
