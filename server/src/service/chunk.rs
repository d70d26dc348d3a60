//! Baking one chunk, the step every scheduler shares (the embedded one in `jobs`, the
//! distributed workers in `cluster`): the baker of a stored scene, checked against the hash
//! and header its row recorded, and one chunk's frame with a panic caught as an error.
//! Each chunk is [`Baker::bake_chunk`], so the frames are the offline bake's byte for byte.

use std::panic::AssertUnwindSafe;
use std::time::Instant;

use bspvt_bake::Baker;
use bspvt_proto::encoding::encode_header;

use super::db::{ChunkMeta, SceneRow};
use super::store::Store;

/// Builds the baker (BVH and all) of scene `row` from its stored scene. The error is public
/// (a scene's reason).
pub(crate) fn baker(
    store: &Store,
    row: &SceneRow,
    pool: &rayon::ThreadPool,
) -> Result<Baker, String> {
    baker_of(&store.read_scene(&row.id)?, row, pool)
}

/// [`baker`] of the stored scene's `bytes`, read already.
pub(crate) fn baker_of(
    bytes: &[u8],
    row: &SceneRow,
    pool: &rayon::ThreadPool,
) -> Result<Baker, String> {
    let scene = super::input::decode_scene(bytes)?;
    if scene.mesh.content_hash() != row.mesh_hash {
        return Err("the stored scene's mesh does not match its recorded hash".into());
    }
    let t0 = Instant::now();
    let baker = pool.install(|| Baker::new(&scene));
    if encode_header(baker.header()) != row.header {
        return Err("the stored scene does not match its recorded bake header".into());
    }
    tracing::debug!(ms = t0.elapsed().as_secs_f64() * 1e3, "baker ready");
    Ok(baker)
}

/// Chunk `c`'s frame and what the database records of it, or why it could not be baked;
/// `cast` bakes it (on the pool, with the rays on the CPU or the GPU: `rays`).
pub(crate) fn bake(
    c: u32,
    cast: impl FnOnce() -> Result<(Vec<u8>, bspvt_bake::Totals), String>,
) -> Result<(Vec<u8>, ChunkMeta, u64), String> {
    match std::panic::catch_unwind(AssertUnwindSafe(cast)) {
        Ok(Ok((frame, totals))) => {
            let meta = ChunkMeta {
                bytes: frame.len() as u32,
                crc32: crc32fast::hash(&frame),
            };
            Ok((frame, meta, totals.vertices))
        }
        Ok(Err(reason)) => Err(reason),
        Err(panic) => {
            let msg = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("unknown panic");
            Err(format!("internal error: baking chunk {c} panicked: {msg}"))
        }
    }
}
