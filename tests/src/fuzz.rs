//! What every fuzzer of bspvt checks, one function per reader of untrusted bytes: the
//! coverage-guided `cargo fuzz` targets (`fuzz/`), the mutation fuzzer (`tests/fuzz.rs`) and the
//! replay of the crashes they found (`fuzz/regressions/`) call these, so the three check the
//! same invariants. Each returns whether the input was accepted and panics (the fuzzer's
//! "crash") when a reader panics or accepts something unsound.

use std::sync::OnceLock;

use bspvt_proto::encoding::{BakeHeader, decode_bake, decode_chunk, decode_header};
use bspvt_proto::import::{Format, Limits, load_asset_bytes};

/// The importers' limits under fuzzing: small enough that a mutated count cannot make a case
/// slow, large enough for every seed.
pub fn limits() -> Limits {
    Limits {
        max_vertices: 200_000,
        max_triangles: 400_000,
        max_bytes: 16 << 20,
    }
}

/// One mesh file through its importer, then into a scene: what is accepted passes
/// [`bspvt_proto::Mesh::validate`] (finite positions and normals, indices in range, one normal
/// per position), and becoming a scene does not panic.
pub fn import(bytes: &[u8], format: Format) -> bool {
    let Ok(asset) = load_asset_bytes(bytes, format, &limits()) else {
        return false;
    };
    if let Err(e) = asset.mesh.validate() {
        panic!("{format:?}: accepted an unsound mesh: {e}");
    }
    let _ = bspvt_proto::Scene::from_asset(asset);
    true
}

/// A small real bake (the built-in small plate, 8² faces, as `bspvt-server bake
/// builtin:plate-small --face-res 8` bakes it: `fuzz/seed.py`'s seed): its header and first
/// chunk, the seeds of the decoders' fuzzing and the header chunks are decoded against.
pub fn small_bake() -> &'static (BakeHeader, Vec<u8>) {
    static BAKE: OnceLock<(BakeHeader, Vec<u8>)> = OnceLock::new();
    BAKE.get_or_init(|| {
        let scene = bspvt_proto::builtin::scene("plate-small").expect("the built-in plate");
        let mut settings = scene.bake.clone();
        settings.face_res = 8;
        let baker = bspvt_bake::Baker::with_settings(scene.mesh.clone(), settings, None);
        let (chunk, _) = baker.bake_chunk(0);
        (baker.header().clone(), chunk)
    })
}

/// The bake decoders (header, chunk against [`small_bake`]'s header, whole file) on the same
/// bytes: none panics. Returns whether any accepted them.
pub fn decode(bytes: &[u8]) -> bool {
    let header = &small_bake().0;
    let a = decode_header(bytes).is_ok();
    let b = decode_chunk(bytes, header).is_ok();
    let c = decode_bake(bytes).is_ok();
    a || b || c
}
