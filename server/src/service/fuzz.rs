//! The submission path as the coverage-guided fuzz targets (`fuzz/`) and their regression
//! tests drive it: a `multipart/form-data` body through axum's parser and the service's own
//! form reading (`api`), then `input::prepare` (decompression, the importers, the scene JSON,
//! composition, refinement, the limits) — everything `POST /scenes` does before the job is
//! stored. Each function panics, the fuzzer's "crash", when a step panics or what it accepts
//! is unsound: a non-finite position, an index out of range, a stored form that does not
//! round-trip.

use axum::body::Body;
use axum::extract::{FromRequest, Multipart};
use axum::http::{Request, header};

use bspvt_proto::import::Limits;

use super::api::{Pace, read_upload};
use super::input::{InputLimits, Prepared, Upload, decode_scene, encode_scene, prepare};
use super::memory::MemoryBudget;

/// The boundary of [`upload`]'s bodies.
pub const BOUNDARY: &str = "bspvt-fuzz";

/// The limits of a fuzzed submission: the service's defaults, scaled down so that a mutated
/// count cannot make a case slow.
fn limits() -> InputLimits {
    InputLimits {
        mesh: Limits {
            max_vertices: 200_000,
            max_triangles: 400_000,
            max_bytes: 16 << 20,
        },
        max_face_res: 64,
        max_supersampling: 4,
    }
}

/// A whole submission: `body` is a `multipart/form-data` body with the boundary [`BOUNDARY`]
/// (fields `mesh`, `file`, `scene`, `settings`). Returns whether it was accepted.
pub fn upload(body: &[u8]) -> bool {
    let request = Request::post("/scenes")
        .header(
            header::CONTENT_TYPE,
            format!("multipart/form-data; boundary={BOUNDARY}"),
        )
        .body(Body::from(body.to_vec()));
    let Ok(request) = request else {
        return false;
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .expect("a tokio runtime");
    let form = runtime.block_on(async {
        let mp = Multipart::from_request(request, &()).await.ok()?;
        let pace = Pace::new(std::time::Duration::from_secs(3600), 0);
        read_upload(mp, limits().mesh.max_bytes, pace).await.ok()
    });
    form.is_some_and(submit)
}

/// A scene JSON submitted with a small OBJ (`mesh.obj`, which the scene's mesh path may name)
/// or alone (naming a `builtin:` mesh). Returns whether either was accepted.
pub fn scene_json(text: &[u8]) -> bool {
    let Ok(json) = std::str::from_utf8(text) else {
        return false;
    };
    let obj = b"v 0 0 0\nv 1 0 0\nv 0 0 1\nv 1 0.5 1\nf 1 3 2\nf 2 3 4\n".to_vec();
    let with_mesh = submit(Upload {
        mesh: Some(("mesh.obj".into(), obj)),
        files: Default::default(),
        scene: Some(json.to_string()),
        settings: None,
    });
    let alone = submit(Upload {
        mesh: None,
        files: Default::default(),
        scene: Some(json.to_string()),
        settings: None,
    });
    with_mesh || alone
}

/// `input::prepare` on a parsed form, and the checks on what it accepts.
fn submit(up: Upload) -> bool {
    let mut mem = MemoryBudget::new(u64::MAX)
        .try_reserve(0)
        .expect("an unbounded budget");
    let Ok(Prepared { scene, .. }) = prepare(up, &limits(), &mut mem) else {
        return false;
    };
    if let Err(e) = scene.mesh.validate() {
        panic!("accepted an unsound mesh: {e}");
    }
    // The stored form carries every bit of the bake's identity (warnings and the environment
    // are kept elsewhere: the job's row, the client's own map).
    let mut stored = decode_scene(&encode_scene(&scene)).expect("a stored scene decodes");
    let mut scene = scene;
    for s in [&mut stored, &mut scene] {
        s.warnings.clear();
        s.environment = None;
    }
    assert!(stored == scene, "the stored scene does not round-trip");
    true
}
