//! Mesh import: round trips on small generated files, a corpus of malformed files with the
//! error each must give, the real test assets when present, and fuzzing of every format.

use std::path::{Path, PathBuf};

use bspvt_proto::import::{
    Format, Limits, load_asset_bytes, load_asset_uploaded, load_mesh, load_mesh_bytes,
};
use bspvt_proto::{Mesh, MeshError};
use glam::Vec3;
use proptest::prelude::*;

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

/// A fresh directory under the system temp dir, unique to this process and test, removed when
/// dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("bspvt-import-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create temp dir");
        TempDir(dir)
    }
}

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write temp file");
    p
}

fn load(bytes: &[u8], format: Format) -> Result<Mesh, MeshError> {
    load_mesh_bytes(bytes, format, &Limits::default())
}

fn ok(r: Result<Mesh, MeshError>) -> Mesh {
    match r {
        Ok(m) => m,
        Err(e) => panic!("expected a mesh, got error: {e}"),
    }
}

/// Checks the invariants every imported mesh must have.
fn check_invariants(m: &Mesh) {
    m.validate().expect("validate");
    assert_eq!(m.normals.len(), m.positions.len());
    for n in &m.normals {
        assert!((n.length() - 1.0).abs() < 1e-4, "normal {n} is not unit");
    }
    for t in &m.triangles {
        assert!(
            t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
            "degenerate {t:?}"
        );
    }
    let mut used = vec![false; m.positions.len()];
    m.triangles
        .iter()
        .flatten()
        .for_each(|&i| used[i as usize] = true);
    assert!(used.iter().all(|&u| u), "unused vertices were kept");
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).length() < 1e-5
}

/// Asserts `r` is an error whose message contains `needle`, and returns it.
fn err_containing(r: Result<Mesh, MeshError>, needle: &str) -> MeshError {
    match r {
        Ok(m) => panic!(
            "expected an error containing {needle:?}, got a mesh with {} vertices",
            m.vertex_count()
        ),
        Err(e) => {
            assert!(
                e.to_string().contains(needle),
                "error {:?} does not contain {needle:?}",
                e.to_string()
            );
            e
        }
    }
}

trait ExpectError {
    fn expect_error(self) -> MeshError;
}

impl ExpectError for Result<Mesh, MeshError> {
    fn expect_error(self) -> MeshError {
        match self {
            Ok(m) => panic!(
                "expected an error, got a mesh with {} vertices",
                m.vertex_count()
            ),
            Err(e) => e,
        }
    }
}

fn base64(bytes: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(T[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

// ---------------------------------------------------------------------------------------------
// OBJ
// ---------------------------------------------------------------------------------------------

/// A quad and a pentagon in two groups, CRLF line ends, relative indices, texture coordinates.
const OBJ_QUAD_PENT: &str = "# quad and pentagon\r\n\
    mtllib none.mtl\r\n\
    o shapes\r\n\
    g quad\r\n\
    v 0 0 0\r\n\
    v 1 0 0\r\n\
    v 1 1 0\r\n\
    v 0 1 0\r\n\
    vt 0 0\r\n\
    usemtl a\r\n\
    f -4 -3 -2 -1\r\n\
    g pentagon\r\n\
    v 2 0 0 1.0\r\n\
    v 3 0 0\r\n\
    v 3.5 1 0   # trailing comment\r\n\
    v 2.5 2 0\r\n\
    v 1.5 1 0\r\n\
    s 1\r\n\
    f -5/1 -4/1 -3/1 \\\r\n\
      -2/1 -1/1\r\n\
    l 1 2\r\n";

#[test]
fn obj_quad_and_pentagon() {
    let m = ok(load(OBJ_QUAD_PENT.as_bytes(), Format::Obj));
    check_invariants(&m);
    assert_eq!(m.vertex_count(), 9);
    assert_eq!(
        m.triangles,
        vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [4, 7, 8]]
    );
    assert!(close(m.positions[6], Vec3::new(3.5, 1.0, 0.0)));
    assert!(m.normals.iter().all(|&n| close(n, Vec3::Z)));
    // The same file with LF line ends gives the same mesh.
    let lf = OBJ_QUAD_PENT.replace("\r\n", "\n");
    assert_eq!(ok(load(lf.as_bytes(), Format::Obj)), m);
    // And from disk, by extension.
    let dir = TempDir::new("obj");
    let p = write(&dir, "shapes.OBJ", OBJ_QUAD_PENT.as_bytes());
    assert_eq!(ok(load_mesh(&p)), m);
}

#[test]
fn obj_complete_normals_split_vertices() {
    // Two triangles sharing an edge, each with its own (non-unit) normal: the shared positions
    // become two vertices each, and the file's normals are kept (normalised).
    let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
                vn 0 0 2\nvn 0 1 1\n\
                f 1//1 2//1 3//1\nf 1/7/2 3//2 4//2\n";
    let m = ok(load(text.as_bytes(), Format::Obj));
    check_invariants(&m);
    assert_eq!(m.vertex_count(), 6);
    assert_eq!(m.triangles.len(), 2);
    assert!(close(m.normals[0], Vec3::Z));
    assert!(close(m.normals[1], Vec3::new(0.0, 1.0, 1.0).normalize()));
    // Incomplete normals (one corner without) → computed normals, one vertex per position.
    let partial = text.replace("f 1/7/2 3//2 4//2", "f 1 3//2 4//2");
    let m = ok(load(partial.as_bytes(), Format::Obj));
    check_invariants(&m);
    assert_eq!(m.vertex_count(), 4);
    assert!(m.normals.iter().all(|&n| close(n, Vec3::Z)));
}

#[test]
fn obj_drops_degenerate_and_unused() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nf 1 2 2\nf 1 2 3\n";
    let m = ok(load(text.as_bytes(), Format::Obj));
    check_invariants(&m);
    assert_eq!(m.vertex_count(), 3);
    assert_eq!(m.triangles, vec![[0, 1, 2]]);
}

/// Copies of a triangle (the same vertices, either winding) are kept in the mesh and named in
/// a warning; `Mesh::unique_triangles` lists the first of each, which the ray casters build
/// their BVHs from.
#[test]
fn repeated_triangles_are_named_and_listed_once() {
    use bspvt_proto::import::load_asset_bytes;
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\nf 3 1 2\nf 3 2 1\nf 1 2 3\n";
    let a = load_asset_bytes(text.as_bytes(), Format::Obj, &Limits::default()).expect("obj");
    assert_eq!(a.mesh.triangles.len(), 5);
    assert_eq!(a.mesh.unique_triangles(), vec![0, 1]);
    assert!(
        a.warnings
            .iter()
            .any(|w| w.starts_with("3 triangles repeat")),
        "{:?}",
        a.warnings
    );
}

// ---------------------------------------------------------------------------------------------
// PLY
// ---------------------------------------------------------------------------------------------

/// Vertices (x, y, z, n, red) and faces of the PLY round trip: a quad, a triangle, one unused
/// vertex (index 2) and an extra element kind that must be skipped.
const PLY_VERTS: [[f32; 4]; 6] = [
    [0.0, 0.0, 0.0, 1.0],
    [1.0, 0.0, 0.0, 1.0],
    [9.0, 9.0, 9.0, 1.0],
    [1.0, 1.0, 0.0, 1.0],
    [0.0, 1.0, 0.0, 1.0],
    [0.5, 0.5, -1.0, 2.0],
];
const PLY_FACES: [&[u32]; 2] = [&[0, 1, 3, 4], &[0, 5, 1]];

fn ply_ascii() -> Vec<u8> {
    let mut s = String::from(
        "ply\r\nformat ascii 1.0\r\ncomment made by a test\r\nelement vertex 6\r\n\
         property float x\r\nproperty float y\r\nproperty float z\r\nproperty float nx\r\n\
         property float ny\r\nproperty float nz\r\nproperty uchar red\r\nelement face 2\r\n\
         property list uchar int vertex_indices\r\nproperty int flags\r\nelement edge 1\r\n\
         property int vertex1\r\nproperty int vertex2\r\nend_header\r\n",
    );
    for v in PLY_VERTS {
        s += &format!("{} {} {} 0 0 {} 255\r\n", v[0], v[1], v[2], v[3]);
    }
    for f in PLY_FACES {
        s += &format!("{}", f.len());
        for i in f {
            s += &format!(" {i}");
        }
        s += " 7\r\n";
    }
    s += "0 1\r\n";
    s.into_bytes()
}

/// The same mesh in binary: little-endian with double coordinates and `uint` indices, or
/// big-endian with float coordinates and a `ushort` list count.
fn ply_binary(big: bool) -> Vec<u8> {
    let (fmt, coord, list) = if big {
        ("binary_big_endian", "float", "ushort int")
    } else {
        ("binary_little_endian", "double", "uchar uint")
    };
    let mut out = format!(
        "ply\nformat {fmt} 1.0\nelement vertex 6\nproperty {coord} x\nproperty {coord} y\n\
         property {coord} z\nproperty float nx\nproperty float ny\nproperty float nz\n\
         property uchar red\nelement face 2\nproperty list {list} vertex_indices\n\
         property int flags\nelement edge 1\nproperty int vertex1\nproperty int vertex2\n\
         end_header\n"
    )
    .into_bytes();
    let put =
        |out: &mut Vec<u8>, le: &[u8], be: &[u8]| out.extend_from_slice(if big { be } else { le });
    for v in PLY_VERTS {
        for c in &v[..3] {
            if big {
                out.extend_from_slice(&c.to_be_bytes());
            } else {
                out.extend_from_slice(&f64::from(*c).to_le_bytes());
            }
        }
        for c in [0.0f32, 0.0, v[3]] {
            put(&mut out, &c.to_le_bytes(), &c.to_be_bytes());
        }
        out.push(255);
    }
    for f in PLY_FACES {
        if big {
            out.extend_from_slice(&(f.len() as u16).to_be_bytes());
        } else {
            out.push(f.len() as u8);
        }
        for &i in f {
            put(&mut out, &i.to_le_bytes(), &(i as i32).to_be_bytes());
        }
        put(&mut out, &7i32.to_le_bytes(), &7i32.to_be_bytes());
    }
    for i in [0i32, 1] {
        put(&mut out, &i.to_le_bytes(), &i.to_be_bytes());
    }
    out
}

#[test]
fn ply_ascii_and_binary_agree() {
    let a = ok(load(&ply_ascii(), Format::Ply));
    check_invariants(&a);
    // Vertex 2 is unused and dropped; the rest keep their order.
    assert_eq!(a.vertex_count(), 5);
    assert_eq!(a.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 4, 1]]);
    assert!(close(a.positions[4], Vec3::new(0.5, 0.5, -1.0)));
    // The file's normals (z = 1 or 2) are used, normalised.
    assert!(a.normals.iter().all(|&n| close(n, Vec3::Z)));
    let le = ok(load(&ply_binary(false), Format::Ply));
    let be = ok(load(&ply_binary(true), Format::Ply));
    assert_eq!(a, le);
    assert_eq!(a, be);
    let dir = TempDir::new("ply");
    let p = write(&dir, "mesh.ply", &ply_binary(true));
    assert_eq!(ok(load_mesh(&p)), a);
}

#[test]
fn ply_vertex_index_name_int_coords_and_zero_normals() {
    // `vertex_index`, integer coordinates, an all-zero normal (→ computed normals).
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty int x\nproperty short y\n\
                property uchar z\nproperty float nx\nproperty float ny\nproperty float nz\n\
                element face 1\nproperty list int short vertex_index\nend_header\n\
                0 0 0 0 0 1\n2 0 0 0 0 0\n0 2 0 0 0 1\n3 0 1 2\n";
    let m = ok(load(text.as_bytes(), Format::Ply));
    check_invariants(&m);
    assert!(close(m.positions[1], Vec3::new(2.0, 0.0, 0.0)));
    assert!(m.normals.iter().all(|&n| close(n, Vec3::Z)));
}

// ---------------------------------------------------------------------------------------------
// glTF / GLB
// ---------------------------------------------------------------------------------------------

/// Packs a GLB container (JSON chunk padded with spaces, BIN chunk with zeros).
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut j = json.as_bytes().to_vec();
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + if b.is_empty() { 0 } else { 8 + b.len() };
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    if !b.is_empty() {
        out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&b);
    }
    out
}

fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// BIN data of the test scene: primitive A (indexed triangle with normals) and primitive B
/// (a non-indexed triangle strip, a quad, without normals).
fn test_bin() -> Vec<u8> {
    let mut b = f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]); // 0: positions A
    b.extend(f32s(&[0., 0., 1., 0., 0., 1., 0., 0., 1.])); // 36: normals A
    b.extend([0u16, 1, 2].iter().flat_map(|x| x.to_le_bytes())); // 72: indices A
    b.extend([0, 0]); // pad to 80
    b.extend(f32s(&[0., 0., 1., 1., 0., 1., 0., 1., 1., 1., 1., 1.])); // 80: positions B
    assert_eq!(b.len(), 128);
    b
}

/// The test scene's JSON: node 0 (translation + uniform scale 2) is the parent of node 1,
/// which instances mesh 0 (two primitives). `buffer` is the buffer object's JSON.
fn test_json(buffer: &str, parent_extra: &str, accessor0_count: u64) -> String {
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [
    {{"children": [1], "translation": [1, 2, 3], "scale": [2, 2, 2]{parent_extra}}},
    {{"mesh": 0, "name": "child"}}
  ],
  "meshes": [{{"primitives": [
    {{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 2}},
    {{"attributes": {{"POSITION": 3}}, "mode": 5}}
  ]}}],
  "buffers": [{buffer}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 72}},
    {{"buffer": 0, "byteOffset": 72, "byteLength": 6}},
    {{"buffer": 0, "byteOffset": 80, "byteLength": 48}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": {accessor0_count}, "type": "VEC3",
      "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 0, "byteOffset": 36, "componentType": 5126, "count": 3, "type": "VEC3"}},
    {{"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}},
    {{"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC3",
      "min": [0, 0, 1], "max": [1, 1, 1]}}
  ]
}}"#
    )
}

fn test_glb() -> Vec<u8> {
    glb(&test_json(r#"{"byteLength": 128}"#, "", 3), &test_bin())
}

fn check_test_scene(m: &Mesh) {
    check_invariants(m);
    assert_eq!(m.vertex_count(), 7);
    assert_eq!(m.triangles, vec![[0, 1, 2], [3, 4, 5], [4, 6, 5]]);
    let expect = [
        [1., 2., 3.],
        [3., 2., 3.],
        [1., 4., 3.],
        [1., 2., 5.],
        [3., 2., 5.],
        [1., 4., 5.],
        [3., 4., 5.],
    ];
    for (p, e) in m.positions.iter().zip(expect) {
        assert!(close(*p, Vec3::from(e)), "{p} != {e:?}");
    }
    assert!(m.normals.iter().all(|&n| close(n, Vec3::Z)));
}

#[test]
fn glb_two_nodes_two_primitives() {
    let bytes = test_glb();
    check_test_scene(&ok(load(&bytes, Format::Glb)));
    let dir = TempDir::new("glb");
    let p = write(&dir, "scene.glb", &bytes);
    check_test_scene(&ok(load_mesh(&p)));
}

#[test]
fn gltf_with_data_uri() {
    let uri = format!(
        r#"{{"byteLength": 128, "uri": "data:application/octet-stream;base64,{}"}}"#,
        base64(&test_bin())
    );
    let json = test_json(&uri, "", 3);
    check_test_scene(&ok(load(json.as_bytes(), Format::Gltf)));
}

#[test]
fn gltf_external_buffer_from_path_but_not_from_bytes() {
    let dir = TempDir::new("gltf-external");
    write(&dir, "my data.bin", &test_bin());
    let json = test_json(r#"{"byteLength": 128, "uri": "my%20data.bin"}"#, "", 3);
    let p = write(&dir, "scene.gltf", json.as_bytes());
    check_test_scene(&ok(load_mesh(&p)));
    let e = err_containing(load(json.as_bytes(), Format::Gltf), "not uploaded");
    assert!(matches!(e, MeshError::Malformed { .. }));
    // Uploaded with the file it names (under its decoded name): the same mesh, and the file
    // is logged as read.
    let files = std::collections::BTreeMap::from([("my data.bin".to_string(), test_bin())]);
    let up = load_asset_uploaded(json.as_bytes(), Format::Gltf, &Limits::default(), &files)
        .expect("uploaded with its buffer");
    check_test_scene(&up.mesh);
    assert_eq!(up.files, ["my data.bin"]);
    let disk = bspvt_proto::import::load_asset(&p).expect("from disk");
    assert_eq!(disk.files, ["my data.bin"]);
}

#[test]
fn gltf_mirrored_node_flips_winding() {
    // Parent scale (-2, 2, 2): the winding must flip so that triangles still face their normals.
    let json = test_json(r#"{"byteLength": 128}"#, "", 3)
        .replace(r#""scale": [2, 2, 2]"#, r#""scale": [-2, 2, 2]"#);
    let m = ok(load(&glb(&json, &test_bin()), Format::Glb));
    check_invariants(&m);
    assert_eq!(m.triangles[0], [0, 2, 1]);
    for t in &m.triangles {
        let p = t.map(|i| m.positions[i as usize]);
        let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
        for &i in t {
            assert!(
                face.dot(m.normals[i as usize]) > 0.99,
                "{face} vs {}",
                m.normals[i as usize]
            );
        }
    }
}

#[test]
fn gltf_normals_use_inverse_transpose() {
    // Non-uniform scale (1, 4, 1) with a rotation-free matrix node: a file normal n must become
    // normalize(M⁻ᵀ n) = normalize(n.x, n.y / 4, n.z), and positions M p.
    let mut bin = f32s(&[1., 0., 0., 0., 1., 0., 1., 0., 1.]);
    let n = Vec3::ONE.normalize();
    bin.extend(f32s(&[n.x, n.y, n.z, n.x, n.y, n.z, n.x, n.y, n.z]));
    let json = r#"{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
      "nodes": [{"mesh": 0, "matrix": [1,0,0,0, 0,4,0,0, 0,0,1,0, 5,0,0,1]}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}}]}],
      "buffers": [{"byteLength": 72}],
      "bufferViews": [{"buffer": 0, "byteLength": 72, "byteStride": 12}],
      "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
        {"bufferView": 0, "byteOffset": 36, "componentType": 5126, "count": 3, "type": "VEC3"}]}"#;
    let m = ok(load(&glb(json, &bin), Format::Glb));
    check_invariants(&m);
    assert!(close(m.positions[1], Vec3::new(5.0, 4.0, 0.0)));
    let expect = Vec3::new(n.x, n.y / 4.0, n.z).normalize();
    assert!(
        m.normals.iter().all(|&v| close(v, expect)),
        "{:?}",
        m.normals
    );
}

#[test]
fn gltf_scenes_without_default_share_nodes() {
    // No default scene: the nodes of all scenes, each node instanced once even when two scenes
    // share it.
    let json = test_json(r#"{"byteLength": 128}"#, "", 3).replace(
        r#""scene": 0,
  "scenes": [{"nodes": [0]}],"#,
        r#""scenes": [{"nodes": [0]}, {"nodes": [0]}],"#,
    );
    assert!(!json.contains(r#""scene":"#));
    check_test_scene(&ok(load(&glb(&json, &test_bin()), Format::Glb)));
}

#[test]
fn gltf_without_scenes_and_fan() {
    // No scenes: every mesh once, untransformed. A triangle fan of four vertices → 2 triangles.
    let bin = f32s(&[0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.]);
    let json = r#"{"asset": {"version": "2.0"},
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "mode": 6},
                                 {"attributes": {"POSITION": 0}, "mode": 0}]}],
      "buffers": [{"byteLength": 48}],
      "bufferViews": [{"buffer": 0, "byteLength": 48}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"}]}"#;
    let m = ok(load(&glb(json, &bin), Format::Glb));
    check_invariants(&m);
    assert_eq!(m.triangles, vec![[1, 2, 0], [2, 3, 0]]);
    assert!(close(m.positions[2], Vec3::new(1.0, 1.0, 0.0)));
}

// ---------------------------------------------------------------------------------------------
// Malformed files: each gives a specific error, never a panic.
// ---------------------------------------------------------------------------------------------

const PLY_HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
                        property float y\nproperty float z\nelement face 1\n\
                        property list uchar int vertex_indices\nend_header\n";

#[test]
fn malformed_ply() {
    let ply = |body: &str| load(format!("{PLY_HEAD}{body}").as_bytes(), Format::Ply);
    // Sanity: the base file is fine.
    ok(ply("0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"));

    // 1. Truncated ASCII.
    //    Too short for what the header declares: refused before reading (each ASCII property
    //    needs at least two bytes)...
    let e = ply("0 0 0\n1 0 0\n0 1").expect_error();
    assert!(
        matches!(
            e,
            MeshError::AbsurdCount {
                what: "vertices",
                declared: 3,
                ..
            }
        ),
        "{e}"
    );
    //    ...or long enough for that, but cut inside the face list.
    err_containing(
        ply("0 0 0\n1 0 0\n0 1 0\n3 0 1"),
        "truncated: the file ends in face 0 of 1 (property `vertex_indices`)",
    );
    // 2. NaN and 3. Inf coordinates.
    let e = ply("0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n").expect_error();
    assert!(
        matches!(e, MeshError::NonFinitePosition { vertex: 1 }),
        "{e}"
    );
    let e = ply("0 0 0\n1 0 0\n0 -inf 0\n3 0 1 2\n").expect_error();
    assert!(
        matches!(e, MeshError::NonFinitePosition { vertex: 2 }),
        "{e}"
    );
    // 4. Index out of range.
    let e = ply("0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n").expect_error();
    assert!(
        matches!(
            e,
            MeshError::IndexOutOfRange {
                index: 3,
                vertices: 3,
                ..
            }
        ),
        "{e}"
    );
    // 5. Negative index.
    err_containing(
        ply("0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n"),
        "negative vertex index",
    );
    // 6. Zero faces.
    let zero = PLY_HEAD.replace("element face 1", "element face 0") + "0 0 0\n1 0 0\n0 1 0\n";
    assert!(matches!(
        load(zero.as_bytes(), Format::Ply),
        Err(MeshError::NoTriangles)
    ));
    // 7. Only degenerate faces.
    assert!(matches!(
        ply("0 0 0\n1 0 0\n0 1 0\n3 0 1 1\n"),
        Err(MeshError::NoTriangles)
    ));

    // 8. Absurd vertex count in a tiny file, ASCII and binary.
    let absurd = PLY_HEAD.replace("element vertex 3", "element vertex 4000000000") + "0 0 0\n";
    assert!(absurd.len() < 250);
    let e = load(absurd.as_bytes(), Format::Ply).expect_error();
    match e {
        MeshError::AbsurdCount {
            what,
            declared,
            file_bytes,
        } => {
            assert_eq!(
                (what, declared, file_bytes),
                ("vertices", 4_000_000_000, absurd.len() as u64)
            );
        }
        e => panic!("expected AbsurdCount, got {e}"),
    }
    let bin_absurd = PLY_HEAD
        .replace("ascii", "binary_little_endian")
        .replace("element vertex 3", "element vertex 18446744073709551615");
    let e = load(bin_absurd.as_bytes(), Format::Ply).expect_error();
    assert!(
        matches!(
            e,
            MeshError::AbsurdCount {
                what: "vertices",
                ..
            }
        ),
        "{e}"
    );
    // 9. Absurd face count.
    let absurd = PLY_HEAD.replace("element face 1", "element face 999999999")
        + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    let e = load(absurd.as_bytes(), Format::Ply).expect_error();
    assert!(
        matches!(
            e,
            MeshError::AbsurdCount {
                what: "faces",
                declared: 999_999_999,
                ..
            }
        ),
        "{e}"
    );
    err_containing(load(absurd.as_bytes(), Format::Ply), "999999999 faces");

    // 10. Truncated binary payload (cut inside the second vertex).
    let mut bin = PLY_HEAD.replace("ascii", "binary_big_endian").into_bytes();
    let header_len = bin.len();
    for v in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
        v.iter().for_each(|c| bin.extend(c.to_be_bytes()));
    }
    bin.push(3);
    [0i32, 1, 2]
        .iter()
        .for_each(|i| bin.extend(i.to_be_bytes()));
    ok(load(&bin, Format::Ply));
    // A cut anywhere in the payload is an error (the size check or a truncation, never a panic).
    for cut in header_len..bin.len() {
        assert!(load(&bin[..cut], Format::Ply).is_err(), "cut at {cut}");
    }
    // A short payload fails the size check before anything is read...
    let e = load(&bin[..header_len + 14], Format::Ply).expect_error();
    assert!(
        matches!(
            e,
            MeshError::AbsurdCount {
                what: "vertices",
                declared: 3,
                ..
            }
        ),
        "{e}"
    );
    // ...one cut inside the last face's index list passes it and is found truncated.
    err_containing(
        load(&bin[..bin.len() - 2], Format::Ply),
        "truncated: the file ends in face 0 of 1",
    );
    // 11. NaN in binary.
    let mut nan = bin.clone();
    nan[header_len + 16..header_len + 20].copy_from_slice(&f32::NAN.to_be_bytes());
    assert!(matches!(
        load(&nan, Format::Ply),
        Err(MeshError::NonFinitePosition { vertex: 1 })
    ));

    // 12. Empty file.
    err_containing(load(b"", Format::Ply), "empty");
    // 13. Binary garbage.
    let garbage: Vec<u8> = (0..200u32).map(|i| (i * 37 + 11) as u8).collect();
    err_containing(load(&garbage, Format::Ply), "not a PLY file");
    // 14. No end_header.
    let no_end = PLY_HEAD.replace("end_header\n", "");
    err_containing(load(no_end.as_bytes(), Format::Ply), "end_header");
    // 15. No vertex coordinates.
    let no_z = PLY_HEAD.replace("property float z\n", "") + "0 0\n1 0\n0 1\n3 0 1 2\n";
    err_containing(load(no_z.as_bytes(), Format::Ply), "no scalar `z`");
    // 16. Over the configured limits.
    let small = Limits {
        max_vertices: 2,
        ..Limits::default()
    };
    let e = load_mesh_bytes(
        format!("{PLY_HEAD}0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").as_bytes(),
        Format::Ply,
        &small,
    )
    .expect_error();
    assert!(
        matches!(
            e,
            MeshError::TooLarge {
                what: "vertices",
                count: 3,
                limit: 2
            }
        ),
        "{e}"
    );
    let tiny = Limits {
        max_bytes: 10,
        ..Limits::default()
    };
    assert!(matches!(
        load_mesh_bytes(PLY_HEAD.as_bytes(), Format::Ply, &tiny),
        Err(MeshError::TooLarge { what: "bytes", .. })
    ));
    // 17. A bad token.
    err_containing(ply("0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n"), "bad number");
}

#[test]
fn malformed_obj() {
    let obj = |s: &str| load(s.as_bytes(), Format::Obj);
    // 1. Index out of range (positive; forward references are only checked at the end).
    let e = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").expect_error();
    assert!(
        matches!(
            e,
            MeshError::IndexOutOfRange {
                triangle: 0,
                index: 3,
                vertices: 3
            }
        ),
        "{e}"
    );
    // 2. A relative index before the first vertex.
    err_containing(
        obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n"),
        "reaches before the first",
    );
    // 3. Index 0.
    err_containing(obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"), "start at 1");
    // 4. Indices that overflow 64-bit arithmetic (tobj panics on these in debug builds).
    err_containing(
        obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -9223372036854775808\n"),
        "reaches before the first",
    );
    let e = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9223372036854775807\n").expect_error();
    assert!(matches!(e, MeshError::IndexOutOfRange { .. }), "{e}");
    err_containing(
        obj("v 0 0 0\nf 1 2 99999999999999999999\n"),
        "bad vertex index",
    );
    // 5. NaN and Inf.
    let e = obj("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n").expect_error();
    assert!(
        matches!(e, MeshError::NonFinitePosition { vertex: 1 }),
        "{e}"
    );
    let e = obj("v 0 0 0\nv 1 0 0\nv 0 1e39 0\nf 1 2 3\n").expect_error();
    assert!(
        matches!(e, MeshError::NonFinitePosition { vertex: 2 }),
        "{e}"
    );
    // 6. No faces; only lines and points.
    assert!(matches!(
        obj("v 0 0 0\nv 1 0 0\nl 1 2\np 1\n"),
        Err(MeshError::NoTriangles)
    ));
    // 7. A face with two vertices.
    err_containing(obj("v 0 0 0\nv 1 0 0\nf 1 2\n"), "at least 3 vertices");
    // 8. A vertex with two coordinates.
    err_containing(obj("v 0 0\n"), "line 1: a vertex needs three numbers");
    // 9. Normal index out of range.
    err_containing(
        obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//2\n"),
        "normal index 2",
    );
    // 10. Bad corner syntax.
    err_containing(
        obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n"),
        "bad face corner",
    );
    // 11. Empty file and binary garbage.
    err_containing(obj(""), "empty");
    let garbage: Vec<u8> = (0..300u32).map(|i| (i * 97 + 3) as u8 | 0x80).collect();
    assert!(matches!(
        load(&garbage, Format::Obj),
        Err(MeshError::NoTriangles)
    ));
    // 12. Over the triangle limit.
    let small = Limits {
        max_triangles: 1,
        ..Limits::default()
    };
    let e = load_mesh_bytes(OBJ_QUAD_PENT.as_bytes(), Format::Obj, &small).expect_error();
    assert!(
        matches!(
            e,
            MeshError::TooLarge {
                what: "triangles",
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn malformed_gltf() {
    let good = test_glb();
    ok(load(&good, Format::Glb));

    // 1. Truncated at every length: always an error, never a panic.
    for cut in 0..good.len() {
        assert!(load(&good[..cut], Format::Glb).is_err(), "cut at {cut}");
    }
    err_containing(load(&good[..good.len() - 10], Format::Glb), "truncated");
    err_containing(load(&good[..7], Format::Glb), "12-byte GLB header");
    // 2. Header length below 12 (gltf's own GLB reader underflows on this).
    let mut short = good.clone();
    short[8..12].copy_from_slice(&4u32.to_le_bytes());
    assert!(matches!(
        load(&short, Format::Glb),
        Err(MeshError::Malformed { .. })
    ));
    // 3. A chunk length past the end of the file.
    let mut bad_chunk = good.clone();
    bad_chunk[12..16].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    err_containing(
        load(&bad_chunk, Format::Glb),
        "chunk 0 declares 4294967280 bytes",
    );
    // 4. Wrong version.
    let mut v1 = good.clone();
    v1[4] = 1;
    err_containing(load(&v1, Format::Glb), "unsupported GLB version 1");
    // 5. An absurd accessor count.
    let absurd = glb(
        &test_json(r#"{"byteLength": 128}"#, "", 1_000_000_000_000),
        &test_bin(),
    );
    let e = load(&absurd, Format::Glb).expect_error();
    assert!(
        matches!(
            e,
            MeshError::AbsurdCount {
                what: "accessor elements",
                declared: 1_000_000_000_000,
                ..
            }
        ),
        "{e}"
    );
    let huge = glb(
        &test_json(r#"{"byteLength": 128}"#, "", u64::MAX),
        &test_bin(),
    );
    assert!(load(&huge, Format::Glb).is_err());
    // 6. A count that fits the file but not its buffer view.
    let over = glb(&test_json(r#"{"byteLength": 128}"#, "", 7), &test_bin());
    err_containing(load(&over, Format::Glb), "do not fit in buffer view 0");
    // 7. A zero count (gltf's iterator underflows on `count - 1`): no vertices, the primitive
    //    is skipped; the other primitive still loads.
    let zero = glb(&test_json(r#"{"byteLength": 128}"#, "", 0), &test_bin());
    let m = ok(load(&zero, Format::Glb));
    assert_eq!(m.triangles.len(), 2);
    // 8. Buffer shorter than declared.
    let long = glb(&test_json(r#"{"byteLength": 4096}"#, "", 3), &test_bin());
    err_containing(load(&long, Format::Glb), "declares 4096 bytes but only 128");
    // 9. Index out of range.
    let mut bin = test_bin();
    bin[76..78].copy_from_slice(&9u16.to_le_bytes());
    let e = load(
        &glb(&test_json(r#"{"byteLength": 128}"#, "", 3), &bin),
        Format::Glb,
    )
    .expect_error();
    assert!(
        matches!(
            e,
            MeshError::IndexOutOfRange {
                triangle: 0,
                index: 9,
                vertices: 3
            }
        ),
        "{e}"
    );
    // 10. NaN position.
    let mut bin = test_bin();
    bin[12..16].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = load(
        &glb(&test_json(r#"{"byteLength": 128}"#, "", 3), &bin),
        Format::Glb,
    )
    .expect_error();
    assert!(
        matches!(e, MeshError::NonFinitePosition { vertex: 1 }),
        "{e}"
    );
    // 11. External URI through load_mesh_bytes; external image too.
    let ext = test_json(r#"{"byteLength": 128, "uri": "buffers/data.bin"}"#, "", 3);
    err_containing(
        load(ext.as_bytes(), Format::Gltf),
        "cannot read the external file \"buffers/data.bin\": it was not uploaded",
    );
    // An external image no material uses is never read.
    let img = test_json(r#"{"byteLength": 128}"#, "", 3).replace(
        r#""scene": 0,"#,
        r#""scene": 0, "images": [{"uri": "tex.png"}],"#,
    );
    let a = load_asset_bytes(&glb(&img, &test_bin()), Format::Glb, &Limits::default())
        .expect("an unused image is not read");
    assert!(a.files.is_empty());
    // Paths out of the asset's folder are refused, on disk as from an upload.
    for uri in [
        "../data.bin",
        "/etc/passwd",
        "C:/data.bin",
        "http://x/data.bin",
    ] {
        let j = test_json(&format!(r#"{{"byteLength": 128, "uri": "{uri}"}}"#), "", 3);
        err_containing(
            load(j.as_bytes(), Format::Gltf),
            "only files beside the asset",
        );
    }
    // ...and an undecodable percent-encoding from disk (gltf's importer panics on this one).
    let dir = TempDir::new("gltf-bad-uri");
    let p = write(
        &dir,
        "x.gltf",
        test_json(r#"{"byteLength": 128, "uri": "%FF.bin"}"#, "", 3).as_bytes(),
    );
    err_containing(load_mesh(&p), "bad percent-encoding");
    let p = write(
        &dir,
        "y.gltf",
        test_json(r#"{"byteLength": 128, "uri": "missing.bin"}"#, "", 3).as_bytes(),
    );
    assert!(matches!(load_mesh(&p), Err(MeshError::Io { .. })));
    // 12. Invalid JSON, and JSON that is not a valid glTF document.
    err_containing(load(b"{\"asset\": ", Format::Gltf), "invalid JSON");
    err_containing(
        load(
            br#"{"asset": {"version": "2.0"}, "scene": 3}"#,
            Format::Gltf,
        ),
        "invalid glTF",
    );
    // An attribute referring to a missing accessor (gltf-json's validator indexes it unchecked).
    let dangling =
        test_json(r#"{"byteLength": 128}"#, "", 3).replace(r#""POSITION": 3"#, r#""POSITION": 99"#);
    err_containing(
        load(&glb(&dangling, &test_bin()), Format::Glb),
        "refers to accessor 99, but there are 4",
    );
    // A required extension that changes geometry.
    let draco = test_json(r#"{"byteLength": 128}"#, "", 3).replace(
        r#""scene": 0,"#,
        r#""scene": 0, "extensionsRequired": ["KHR_draco_mesh_compression"],"#,
    );
    err_containing(
        load(&glb(&draco, &test_bin()), Format::Glb),
        "KHR_draco_mesh_compression",
    );
    // 13. Only points: no triangles.
    let points = test_json(r#"{"byteLength": 128}"#, "", 3)
        .replace(r#""indices": 2}"#, r#""indices": 2, "mode": 0}"#)
        .replace(r#""mode": 5"#, r#""mode": 1"#);
    assert!(matches!(
        load(&glb(&points, &test_bin()), Format::Glb),
        Err(MeshError::NoTriangles)
    ));
    // 14. A node cycle.
    let cycle = test_json(r#"{"byteLength": 128}"#, "", 3)
        .replace(
            r#"{"mesh": 0, "name": "child"}"#,
            r#"{"mesh": 0, "children": [0]}"#,
        )
        .replace(r#""nodes": [0]"#, r#""nodes": [1]"#);
    err_containing(
        load(&glb(&cycle, &test_bin()), Format::Glb),
        "reached twice",
    );
    // 15. A VEC2 position accessor (gltf's reader would read past each element).
    let vec2 = test_json(r#"{"byteLength": 128}"#, "", 3).replacen(
        r#""type": "VEC3""#,
        r#""type": "VEC2""#,
        1,
    );
    err_containing(
        load(&glb(&vec2, &test_bin()), Format::Glb),
        "not a valid position",
    );
    // 16. Work budget: many primitives sharing one accessor of degenerate triangles produce no
    //     output (so never reach the output limits) but may not cost unbounded decoding.
    let prims = vec![r#"{"attributes": {"POSITION": 0}, "indices": 1}"#; 20].join(",");
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}},
          "meshes": [{{"primitives": [{prims}]}}],
          "buffers": [{{"byteLength": 48}}],
          "bufferViews": [{{"buffer": 0, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 36, "byteLength": 12}}],
          "accessors": [
            {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}},
            {{"bufferView": 1, "componentType": 5121, "count": 12, "type": "SCALAR"}}]}}"#
    );
    let mut bin = f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
    bin.extend([0u8; 12]);
    let small = Limits {
        max_vertices: 10,
        max_triangles: 10,
        max_bytes: 1 << 20,
    };
    let e = load_mesh_bytes(&glb(&json, &bin), Format::Glb, &small).expect_error();
    assert!(
        matches!(
            e,
            MeshError::TooLarge {
                what: "accessor elements read",
                limit: 80,
                ..
            }
        ),
        "{e}"
    );
    assert!(matches!(
        load(&glb(&json, &bin), Format::Glb),
        Err(MeshError::NoTriangles)
    ));
    // 17. Empty input and binary garbage.
    err_containing(load(b"", Format::Gltf), "empty");
    let garbage: Vec<u8> = (0..200u32).map(|i| (i * 37 + 11) as u8).collect();
    err_containing(load(&garbage, Format::Glb), "invalid JSON");
}

#[test]
fn unsupported_and_missing_files() {
    let dir = TempDir::new("unsupported");
    let p = write(&dir, "mesh.stl", b"solid x\nendsolid x\n");
    assert!(matches!(
        load_mesh(&p),
        Err(MeshError::UnsupportedFormat(_))
    ));
    let p = write(&dir, "README", b"hello");
    assert!(matches!(
        load_mesh(&p),
        Err(MeshError::UnsupportedFormat(_))
    ));
    assert!(matches!(
        Format::from_name("upload.fbx"),
        Err(MeshError::UnsupportedFormat(_))
    ));
    assert!(matches!(
        load_mesh(&dir.join("absent.ply")),
        Err(MeshError::Io { .. })
    ));
    let p = write(&dir, "empty.glb", b"");
    err_containing(load_mesh(&p), "empty");
}

// ---------------------------------------------------------------------------------------------
// Real assets (skipped when absent)
// ---------------------------------------------------------------------------------------------

fn assets_dir() -> Option<PathBuf> {
    let dir = bspvt_proto::paths::assets_dir();
    let meshes = dir.join("meshes");
    if meshes.is_dir() {
        Some(meshes)
    } else {
        println!(
            "skipped: test assets not found at {} (set BSPVT_ASSETS)",
            meshes.display()
        );
        None
    }
}

fn load_asset(name: &str) -> Option<Mesh> {
    let path = assets_dir()?.join(name);
    if !path.is_file() {
        println!("skipped: {} not found", path.display());
        return None;
    }
    let t = std::time::Instant::now();
    let m = ok(load_mesh(&path));
    check_invariants(&m);
    println!(
        "{name}: {} vertices, {} triangles ({:.0} ms)",
        m.vertex_count(),
        m.triangles.len(),
        t.elapsed().as_secs_f64() * 1e3
    );
    Some(m)
}

#[test]
fn asset_teapot_obj() {
    if let Some(m) = load_asset("teapot.obj") {
        assert_eq!((m.vertex_count(), m.triangles.len()), (3644, 6320));
    }
}

#[test]
fn asset_bunny_ply() {
    if let Some(m) = load_asset("bunny.ply") {
        // 35,947 declared vertices, 1,113 of them used by no face.
        assert_eq!((m.vertex_count(), m.triangles.len()), (34_834, 69_451));
    }
}

#[test]
fn asset_dragon_and_decimated_bunnies() {
    for (name, tris) in [
        ("dragon_res4.ply", 11_102),
        ("bunny_res2.ply", 16_301),
        ("bunny_res3.ply", 3_851),
        ("bunny_res4.ply", 948),
    ] {
        if let Some(m) = load_asset(name) {
            assert_eq!(m.triangles.len(), tris, "{name}");
        }
    }
}

#[test]
fn asset_bunny_binary_round_trip() {
    // The ASCII bunny written as binary PLY (both byte orders) loads to the same mesh.
    let Some(ascii) = load_asset("bunny_res4.ply") else {
        return;
    };
    let Some(dir) = assets_dir() else { return };
    let text = std::fs::read(dir.join("bunny_res4.ply")).expect("read");
    let m = ok(load(&text, Format::Ply));
    assert_eq!(m, ascii);
    for big in [false, true] {
        let mut out = format!(
            "ply\nformat binary_{}_endian 1.0\nelement vertex {}\nproperty float x\n\
             property float y\nproperty float z\nelement face {}\n\
             property list uchar int vertex_indices\nend_header\n",
            if big { "big" } else { "little" },
            m.vertex_count(),
            m.triangles.len()
        )
        .into_bytes();
        for p in &m.positions {
            for c in p.to_array() {
                out.extend(if big {
                    c.to_be_bytes()
                } else {
                    c.to_le_bytes()
                });
            }
        }
        for t in &m.triangles {
            out.push(3);
            for i in t {
                out.extend(if big {
                    i.to_be_bytes()
                } else {
                    i.to_le_bytes()
                });
            }
        }
        assert_eq!(ok(load(&out, Format::Ply)), m);
    }
}

// ---------------------------------------------------------------------------------------------
// Fuzzing: random bytes and mutations of valid files never panic.
// ---------------------------------------------------------------------------------------------

fn valid_samples() -> Vec<(Format, Vec<u8>)> {
    let data_uri = test_json(
        &format!(
            r#"{{"byteLength": 128, "uri": "data:application/octet-stream;base64,{}"}}"#,
            base64(&test_bin())
        ),
        "",
        3,
    );
    vec![
        (Format::Obj, OBJ_QUAD_PENT.as_bytes().to_vec()),
        (Format::Ply, ply_ascii()),
        (Format::Ply, ply_binary(false)),
        (Format::Ply, ply_binary(true)),
        (Format::Glb, test_glb()),
        (Format::Gltf, data_uri.into_bytes()),
        // Textures (base colour, emissive, embedded PNGs), TEXCOORD_0, a punctual spot.
        (
            Format::Gltf,
            std::fs::read(
                Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/rooms/textured-floor.gltf"),
            )
            .expect("the textured asset"),
        ),
    ]
}

fn any_format() -> impl Strategy<Value = Format> {
    prop_oneof![
        Just(Format::Gltf),
        Just(Format::Glb),
        Just(Format::Obj),
        Just(Format::Ply)
    ]
}

/// Loading must return (Ok or Err) and an Ok mesh must be valid.
fn must_not_panic(bytes: &[u8], format: Format) {
    let limits = Limits {
        max_vertices: 100_000,
        max_triangles: 100_000,
        max_bytes: 1 << 20,
    };
    if let Ok(a) = bspvt_proto::import::load_asset_bytes(bytes, format, &limits) {
        check_invariants(&a.mesh);
        // Material ids index the file's materials (all 0 when it has none); every light and
        // material the importer made is valid.
        let n = a.materials.len().max(1) as u32;
        assert!(a.mesh.material_ids.iter().all(|&id| id < n));
        for m in &a.materials {
            assert!(m.roughness > 0.0 && m.roughness <= 1.0, "{m:?}");
            let unit = |c: &[f32; 3]| c.iter().all(|x| (0.0..=1.0).contains(x));
            assert!(unit(&m.albedo) && unit(&m.specular), "{m:?}");
        }
        for l in &a.lights {
            assert!(l.vertices.len() >= 3 && l.vertices.len() <= 8);
            assert!(l.radiance.iter().all(|x| x.is_finite() && *x >= 0.0));
            assert!(l.image.as_ref().is_none_or(|i| i.is_valid()));
        }
        assert!(a.mesh.uvs.is_empty() || a.mesh.uvs.len() == a.mesh.positions.len());
        assert!(a.mesh.uvs.iter().all(|u| u.is_finite()));
        for (i, p) in a.punctual.iter().enumerate() {
            assert!(
                p.position.iter().chain(&p.intensity).all(|x| x.is_finite()),
                "{i}: {p:?}"
            );
        }
    }
}

proptest! {
    // 512 cases per property by default; PROPTEST_CASES overrides for long fuzzing runs.
    #![proptest_config(ProptestConfig {
        cases: std::env::var("PROPTEST_CASES").ok().and_then(|c| c.parse().ok()).unwrap_or(512),
        ..ProptestConfig::default()
    })]

    #[test]
    fn fuzz_random_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..600), format in any_format()) {
        must_not_panic(&bytes, format);
    }

    #[test]
    fn fuzz_random_prefixed_bytes(
        which in 0usize..6,
        tail in proptest::collection::vec(any::<u8>(), 0..400),
    ) {
        // Random bytes behind a plausible start, so the parsers get past their magic checks.
        let le = PLY_HEAD.replace("ascii", "binary_little_endian");
        let be = PLY_HEAD.replace("ascii", "binary_big_endian");
        let (format, head): (Format, &[u8]) = [
            (Format::Ply, PLY_HEAD.as_bytes()),
            (Format::Ply, le.as_bytes()),
            (Format::Ply, be.as_bytes()),
            (Format::Glb, &b"glTF\x02\x00\x00\x00\x00\x01\x00\x00"[..]),
            (Format::Obj, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf "),
            (Format::Gltf, b"{\"asset\":{\"version\":\"2.0\"},\"meshes\":"),
        ][which];
        let mut bytes = head.to_vec();
        bytes.extend(&tail);
        must_not_panic(&bytes, format);
    }

    #[test]
    fn fuzz_mutated_valid_files(
        which in 0usize..7,
        flips in proptest::collection::vec((any::<prop::sample::Index>(), 0u8..8), 1..8),
        bytes_set in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..3),
        cut in proptest::option::of(any::<prop::sample::Index>()),
    ) {
        let samples = valid_samples();
        let (format, mut bytes) = samples[which].clone();
        for (at, bit) in flips {
            let i = at.index(bytes.len());
            bytes[i] ^= 1 << bit;
        }
        for (at, value) in bytes_set {
            let i = at.index(bytes.len());
            bytes[i] = value;
        }
        if let Some(cut) = cut {
            bytes.truncate(cut.index(bytes.len() + 1));
        }
        must_not_panic(&bytes, format);
    }

    #[test]
    fn fuzz_digit_mutations(which in 0usize..7, at in any::<prop::sample::Index>(), digits in "[0-9]{1,12}") {
        // Replace one ASCII digit run position with a long number: counts, indices and offsets
        // become huge.
        let samples = valid_samples();
        let (format, bytes) = samples[which].clone();
        let positions: Vec<usize> = bytes.iter().enumerate().filter(|(_, b)| b.is_ascii_digit()).map(|(i, _)| i).collect();
        prop_assume!(!positions.is_empty());
        let i = positions[at.index(positions.len())];
        let mut out = bytes[..i].to_vec();
        out.extend(digits.as_bytes());
        out.extend(&bytes[i + 1..]);
        must_not_panic(&out, format);
    }
}
