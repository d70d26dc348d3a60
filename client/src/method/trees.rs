//! The trees a method needs: read from a bake file (checked against the scene), or baked once
//! and cached by the content hash of the scene's mesh and bake settings.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use anyhow::{Context, Result, bail};
use bspvt_proto::Scene;
use bspvt_proto::encoding::{Bake, decode_bake};
use serde::{Deserialize, Serialize};

/// Reads a bake file and checks it belongs to `scene` (same mesh, same vertex count).
pub fn load_checked(path: &Path, scene: &Scene) -> Result<Bake> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let bake =
        decode_bake(&bytes).with_context(|| format!("{} is not a valid bake", path.display()))?;
    if bake.header.mesh_hash != scene.mesh.content_hash()
        || bake.trees.len() != scene.mesh.vertex_count()
    {
        bail!(
            "{} was baked from a different mesh than this scene's ({} vertices in the bake, {} in the scene)",
            path.display(),
            bake.trees.len(),
            scene.mesh.vertex_count()
        );
    }
    Ok(bake)
}

/// A bake in the cache folder, and what it cost when it was made.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CachedBake {
    /// The bake file.
    pub path: PathBuf,
    /// Vertices baked.
    pub vertices: usize,
    /// The file's size.
    pub bytes: usize,
    /// Wall time of the bake.
    pub seconds: f64,
    /// Threads it ran on.
    pub threads: usize,
    /// False when the file was baked by this call.
    #[serde(skip)]
    pub from_cache: bool,
}

/// `name` as a file-name stem: its file stem, with anything but ASCII letters, digits and
/// `-` replaced by `_`.
pub fn file_stem(name: &str) -> String {
    let base = Path::new(name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| name.to_string());
    base.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// What the rays see of the scene's alpha cut-outs (0: none), beside the mesh's content hash
/// in the keys of bakes and references ([`bspvt_raytrace::Cutouts::content_hash`]).
pub fn cutout_hash(scene: &Scene) -> u64 {
    bspvt_raytrace::Cutouts::of(&scene.mesh, &scene.materials).map_or(0, |c| c.content_hash())
}

/// The bake of `scene` in `cache` (`NAME-HASH.bspvt`, HASH over the bake's
/// [`bspvt_bake::ALGORITHM_VERSION`], the mesh's content hash, its cut-outs, the bake settings and the
/// lights — their regions, planes, polygons and spheres, and whether a sun makes every direction matter, decide which directions matter and where rays end; none:
/// the sky's, whose rays are aimed at its suns at rest), baking it first when absent. `progress(done, total)` follows the
/// vertices while it bakes.
pub fn cached_bake(
    name: &str,
    scene: &Scene,
    cache: &Path,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<CachedBake> {
    let mut h = bspvt_proto::hash::Fnv1a::default();
    h.write(
        format!(
            "{}:{:x}:{:x}{:?}{:?}{:?}{:?}",
            bspvt_bake::ALGORITHM_VERSION,
            scene.mesh.content_hash(),
            cutout_hash(scene),
            scene.bake,
            scene.lights,
            scene.punctual,
            scene.suns
        )
        .as_bytes(),
    );
    let key = h.finish();
    let path = cache.join(format!("{}-{key:016x}.bspvt", file_stem(name)));
    let meta = path.with_extension("bspvt.json");
    if path.exists()
        && let Ok(text) = std::fs::read_to_string(&meta)
        && let Ok(mut b) = serde_json::from_str::<CachedBake>(&text)
    {
        b.path = path;
        b.from_cache = true;
        return Ok(b);
    }
    std::fs::create_dir_all(cache).with_context(|| format!("cannot create {}", cache.display()))?;
    let baker = bspvt_bake::Baker::new(scene);
    let vertices = baker.header().vertex_count as usize;
    eprintln!(
        "baking {name} ({vertices} vertices, {}² faces, ε = {}) once, cached in {}…",
        scene.bake.face_res,
        scene.bake.epsilon,
        cache.display()
    );
    let total = vertices as u64;
    let out = baker.bake_all(&|done, _| progress(done, total), &AtomicBool::new(false))?;
    eprintln!("baked in {:.1} s", out.seconds);
    // Written under a temporary name and renamed: an interrupted bake leaves no file that
    // a later run would take for a finished one.
    let tmp = path.with_extension("bspvt.tmp");
    std::fs::write(&tmp, &out.bytes).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, &path).with_context(|| format!("cannot write {}", path.display()))?;
    let b = CachedBake {
        path,
        vertices,
        bytes: out.bytes.len(),
        seconds: out.seconds,
        threads: rayon::current_num_threads(),
        from_cache: false,
    };
    std::fs::write(&meta, serde_json::to_string_pretty(&b)?)
        .with_context(|| format!("cannot write {}", meta.display()))?;
    Ok(b)
}

/// The bakes `method` needs for `scene`: the scene's own (its lamps'), read from `given` when
/// a bake file is given, else baked once into `cache`; and the sky's
/// ([`bspvt_proto::Scene::sky`], always from `cache`). `None` where the method needs none.
pub fn bakes_for(
    method: &dyn super::FrameMethod,
    name: &str,
    scene: &Scene,
    given: Option<&Path>,
    cache: &Path,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<(Option<Bake>, Option<Bake>)> {
    let needs = method.needs();
    let lamps = match given {
        Some(p) => Some(load_checked(p, scene)?),
        None if needs.lamp_trees(scene) => {
            let c = cached_bake(name, scene, cache, progress)?;
            Some(load_checked(&c.path, scene)?)
        }
        None => None,
    };
    let sky = if needs.sky_trees_for(scene) {
        Some(cached_sky_bake(scene, cache, progress)?.1)
    } else {
        None
    };
    Ok((lamps, sky))
}

/// The bake of the sky of `scene` ([`bspvt_proto::Scene::sky`]) in `cache` as `sky-HASH.bspvt`
/// (one name whoever asks: `render`, the viewer, the report and the benchmarks share it), baked
/// first when absent; with the bake read back.
pub fn cached_sky_bake(
    scene: &Scene,
    cache: &Path,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<(CachedBake, Bake)> {
    let sky = scene.sky();
    let c = cached_bake("sky", &sky, cache, progress)?;
    let bake = load_checked(&c.path, &sky)?;
    Ok((c, bake))
}
