//! `bspvt bench`: shading speed on real meshes.
//!
//! For each mesh (its default `--mesh` scene), the trees are baked once (cached under the
//! output folder, keyed by the mesh hash and settings), then:
//! - **kernel**: every vertex shaded once on one thread (µs per vertex per core), BSPVT and
//!   unshadowed LTC (the baseline, same run);
//! - **frames**: a 512² frame sequence while the light moves, per-vertex and per-pixel modes,
//!   on all threads (ms per frame, fps), with unshadowed LTC in the same run as the ratio.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use bspvt_proto::Scene;
use bspvt_proto::encoding::decode_bake;
use rayon::prelude::*;
use serde::Serialize;

pub(crate) use bspvt_client::method::trees::{cached_bake, file_stem};

use bspvt_client::light::Light;
use bspvt_client::ltc::table::LtcTable;
use bspvt_client::method::sequence::{Options, render_sequence};
use bspvt_client::method::{Settings, registry};
use bspvt_client::render::path::LightPath;
use bspvt_client::render::renderer::{Mode, Trees};
use bspvt_client::shade::bspvt::shade_vertex;
use bspvt_client::shade::{Lobes, unshadowed};

/// `bspvt bench`: shading speed on real meshes (kernel µs per vertex, frame times).
#[derive(clap::Args, Clone, Debug)]
pub struct BenchArgs {
    /// Folder holding the meshes (default: $BSPVT_ASSETS/meshes or ../shared/assets/meshes).
    #[arg(long)]
    pub(crate) meshes_dir: Option<PathBuf>,
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "bunny.ply,dragon_res4.ply"
    )]
    pub(crate) meshes: Vec<String>,
    /// Also measure the built-in scene.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub(crate) builtin: bool,
    #[arg(long, default_value_t = 512)]
    pub(crate) size: u32,
    /// Frames per sequence (the light moves along its path).
    #[arg(long, default_value_t = 32)]
    pub(crate) frames: usize,
    /// Where baked trees are cached.
    #[arg(long, default_value = "out/bench")]
    pub(crate) cache: PathBuf,
    #[arg(long)]
    pub(crate) json: Option<PathBuf>,
}

#[derive(Clone, Debug, Serialize)]
pub(crate) struct KernelRow {
    pub(crate) scene: String,
    pub(crate) vertices: usize,
    /// Vertices that see the light (the rest cost only the horizon test).
    pub(crate) lit_vertices: usize,
    pub(crate) bspvt_us_per_vertex: f64,
    /// The same light with a 256² texture (prefiltered, fetched per piece and lobe).
    pub(crate) bspvt_textured_us_per_vertex: f64,
    pub(crate) ltc_us_per_vertex: f64,
    pub(crate) bspvt_us_per_lit_vertex: f64,
    pub(crate) pieces_per_lit_vertex: f64,
    /// Boundary experiment (diffuse lobe, visible leaves v̄ ≥ ½ taken as 1): edges integrated
    /// per lit vertex piece by piece vs boundary only, and the time of each (µs/lit vertex).
    pub(crate) edges_per_piece_sum: f64,
    pub(crate) edges_boundary_only: f64,
    pub(crate) us_pieces: f64,
    pub(crate) us_boundary: f64,
    pub(crate) boundary_max_rel_diff: f64,
}

#[derive(Clone, Debug, Serialize)]
pub(crate) struct FrameRow {
    pub(crate) scene: String,
    #[serde(serialize_with = "bspvt_client::method::serialize_name")]
    pub method: &'static dyn bspvt_client::method::FrameMethod,
    pub mode: Mode,
    pub ms_per_frame: f64,
    pub fps: f64,
    pub(crate) us_per_vertex_per_core: f64,
    pub(crate) vertices_shaded: usize,
    pub(crate) threads: usize,
}

#[derive(Clone, Debug, Serialize)]
pub(crate) struct Report {
    pub(crate) kernel: Vec<KernelRow>,
    pub(crate) frames: Vec<FrameRow>,
}

/// Runs `bspvt bench`: prints the rows and writes them as JSON when asked.
pub fn run(a: &BenchArgs) -> Result<()> {
    let dir = a
        .meshes_dir
        .clone()
        .unwrap_or_else(bspvt_proto::paths::meshes_dir);
    let mut scenes: Vec<(String, Scene)> = Vec::new();
    if a.builtin {
        scenes.push((
            "builtin:plate".into(),
            bspvt_proto::builtin::scene("plate").context("built-in scene missing")?,
        ));
    }
    for m in a.meshes.iter().filter(|m| !m.is_empty()) {
        let p = dir.join(m);
        let s = Scene::from_mesh_path(&p).with_context(|| {
            format!(
                "cannot open {} (set --meshes-dir or BSPVT_ASSETS)",
                p.display()
            )
        })?;
        scenes.push((m.clone(), s));
    }
    let mut report = Report {
        kernel: Vec::new(),
        frames: Vec::new(),
    };
    for (name, scene) in &scenes {
        let bake_path = cached_bake(name, scene, &a.cache, &|_, _| {})?.path;
        let bytes = std::fs::read(&bake_path)?;
        let bake = decode_bake(&bytes)?;
        let trees = Trees::full(&bake.trees, bake.header.codec());
        let k = kernel(name, scene, &trees);
        println!(
            "{name}: boundary experiment: {:.1} edges/lit vertex piece by piece ({:.3} µs) vs {:.1} boundary edges ({:.3} µs incl. cancelling), results differ by ≤ {:.1e}",
            k.edges_per_piece_sum,
            k.us_pieces,
            k.edges_boundary_only,
            k.us_boundary,
            k.boundary_max_rel_diff
        );
        println!(
            "{name}: kernel {:.3} µs/vertex/core BSPVT ({:.3} per lit vertex, {:.1} pieces), {:.3} unshadowed LTC; {} of {} vertices lit",
            k.bspvt_us_per_vertex,
            k.bspvt_us_per_lit_vertex,
            k.pieces_per_lit_vertex,
            k.ltc_us_per_vertex,
            k.lit_vertices,
            k.vertices
        );
        report.kernel.push(k);
        for method in [registry::lookup("bspvt")?, registry::lookup("ltc")?] {
            for mode in [Mode::Vertex, Mode::Pixel] {
                let opts = Options {
                    method,
                    width: a.size,
                    height: a.size,
                    frames: a.frames,
                    light: None,
                    env_spin_deg: 0.0,
                    settings: Settings {
                        mode,
                        spp: 1,
                        ..Settings::default()
                    },
                };
                let s = render_sequence(scene, Some(&trees), None, &opts, |_, _| Ok(()))?;
                println!(
                    "{name}: {} {mode:?} {:.2} ms/frame ({:.1} fps), {:.3} µs/vertex/core, {} vertices",
                    method.name(),
                    s.ms_per_frame,
                    s.fps,
                    s.us_per_vertex_per_core,
                    s.vertices_shaded
                );
                report.frames.push(FrameRow {
                    scene: name.clone(),
                    method,
                    mode,
                    ms_per_frame: s.ms_per_frame,
                    fps: s.fps,
                    us_per_vertex_per_core: s.us_per_vertex_per_core,
                    vertices_shaded: s.vertices_shaded,
                    threads: s.threads,
                });
            }
        }
    }
    print_tables(&report);
    if let Some(p) = &a.json {
        std::fs::write(p, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}

/// The file a scene name stands for: `teapot`, `bunny`, `dragon` name the shared meshes;
/// a name with an extension is looked up in `meshes_dir` first, then as a path.
pub(crate) fn named_scene_path(name: &str, meshes_dir: &Path) -> PathBuf {
    match name {
        "teapot" => meshes_dir.join("teapot.obj"),
        "bunny" => meshes_dir.join("bunny.ply"),
        "dragon" => meshes_dir.join("dragon_res4.ply"),
        other => {
            let in_dir = meshes_dir.join(other);
            if !other.contains('/') && in_dir.exists() {
                in_dir
            } else {
                PathBuf::from(other)
            }
        }
    }
}

/// A scene by name: a built-in scene (`plate`, `plate-small`), a shared mesh (see
/// [`named_scene_path`]) as its default `--mesh` scene, or a scene JSON file. `None` when the
/// file does not exist (the caller says so and skips it).
pub(crate) fn load_named_scene(name: &str, meshes_dir: &Path) -> Result<Option<Scene>> {
    let mut scene = if let Some(s) = bspvt_proto::builtin::scene(name) {
        s
    } else {
        let file = named_scene_path(name, meshes_dir);
        if !file.exists() {
            return Ok(None);
        }
        let is_json = file.extension().is_some_and(|e| e == "json");
        let scene = if is_json {
            bspvt_proto::scene::open_scene(Some(&file.to_string_lossy()), None)
        } else {
            Scene::from_mesh_path(&file)
        };
        scene.with_context(|| format!("cannot load scene {name} ({})", file.display()))?
    };
    // The mesh every path bakes and shades: refined where the scene asks (rooms, assets with
    // their own lamps).
    bspvt_client::scene::refine(&mut scene)?;
    Ok(Some(scene))
}

/// Median wall time (ms) of `frames` calls of `f`, and the last result.
pub(crate) fn median_ms<T>(frames: usize, mut f: impl FnMut() -> Result<T>) -> Result<(f64, T)> {
    let mut ms = Vec::with_capacity(frames);
    let mut last = None;
    for _ in 0..frames.max(1) {
        let t = Instant::now();
        let out = f()?;
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        last = Some(out);
    }
    ms.sort_by(f64::total_cmp);
    let out = last.context("nothing was run")?;
    Ok((ms[ms.len() / 2], out))
}

/// Every vertex once, on one thread, with the light at the middle of its path.
fn kernel(name: &str, scene: &Scene, trees: &Trees) -> KernelRow {
    let light = LightPath::new(
        scene.lights[0].motion(),
        Light::from_scene(&scene.lights[0]),
    )
    .at(0.125);
    let table = LtcTable::builtin();
    let mesh = &scene.mesh;
    let eye = glam::Vec3::from(scene.camera.position).as_dvec3();
    let material = &scene.materials[0];
    let setup: Vec<(Lobes, glam::DVec3, glam::DVec3)> = (0..mesh.vertex_count())
        .into_par_iter()
        .map(|v| {
            let p = mesh.positions[v].as_dvec3();
            let n = mesh.normals[v].as_dvec3().normalize_or(glam::DVec3::Y);
            (
                Lobes::new(table, material, n, (eye - p).normalize_or(n)),
                p,
                n,
            )
        })
        .collect();
    let one = |f: &mut dyn FnMut(usize) -> u32| {
        let t = Instant::now();
        let mut acc = 0u64;
        for v in 0..mesh.vertex_count() {
            acc += u64::from(f(v));
        }
        (t.elapsed().as_secs_f64(), acc)
    };
    let mut lit = 0usize;
    let (t_bspvt, pieces) = one(&mut |v| {
        let (l, p, n) = &setup[v];
        let r = shade_vertex(l, &light, *p, *n, &trees.trees[v], &trees.codec);
        if r.unshadowed.integrals.diffuse > 0.0 {
            lit += 1;
        }
        std::hint::black_box(r.shadowed.integrals.diffuse);
        r.pieces
    });
    // The same light with a 256² texture (a smooth gradient times a checker).
    let mut textured = light.clone();
    let n = 256;
    let texels: Vec<[f32; 3]> = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f32 / n as f32, (i / n) as f32 / n as f32);
            let c = if ((i % n) / 32 + (i / n) / 32) % 2 == 0 {
                1.0
            } else {
                0.3
            };
            [c * x, c * y, c]
        })
        .collect();
    textured.texture = bspvt_client::texture::LightTexture::from_texels(n, n, &texels)
        .ok()
        .map(std::sync::Arc::new);
    let (t_tex, _) = one(&mut |v| {
        let (l, p, n) = &setup[v];
        let r = shade_vertex(l, &textured, *p, *n, &trees.trees[v], &trees.codec);
        std::hint::black_box(r.shadowed.diffuse_rgb);
        0
    });
    let (t_ltc, _) = one(&mut |v| {
        let (l, p, n) = &setup[v];
        std::hint::black_box(unshadowed(l, &light, *p, *n).integrals.diffuse);
        0
    });
    let b = boundary_experiment(&setup, &light, trees);
    let nv = mesh.vertex_count().max(1) as f64;
    KernelRow {
        scene: name.to_string(),
        vertices: mesh.vertex_count(),
        lit_vertices: lit,
        bspvt_us_per_vertex: t_bspvt * 1e6 / nv,
        bspvt_textured_us_per_vertex: t_tex * 1e6 / nv,
        ltc_us_per_vertex: t_ltc * 1e6 / nv,
        bspvt_us_per_lit_vertex: t_bspvt * 1e6 / lit.max(1) as f64,
        pieces_per_lit_vertex: pieces as f64 / lit.max(1) as f64,
        edges_per_piece_sum: b.0,
        edges_boundary_only: b.1,
        us_pieces: b.2,
        us_boundary: b.3,
        boundary_max_rel_diff: b.4,
    }
}

/// Is integrating only the boundary of the visible region faster than piece by piece?
/// Both sum the diffuse edge integral over the pieces in visible leaves (v̄ ≥ ½ as 1); the
/// boundary variant first cancels every edge that two visible pieces share (the same two
/// vertices, bit for bit, in opposite directions), then integrates what is left.
/// Returns (edges per lit vertex by pieces, by boundary, µs by pieces, µs by boundary,
/// largest relative difference of the two results).
fn boundary_experiment(
    setup: &[(Lobes, glam::DVec3, glam::DVec3)],
    light: &Light,
    trees: &Trees,
) -> (f64, f64, f64, f64, f64) {
    use bspvt_client::ltc::polygon::{edge, edge_sum};
    use bspvt_client::shade::light_directions;
    use std::collections::HashMap;
    type Key = [u64; 6];
    let key = |a: glam::DVec3, b: glam::DVec3| -> Key {
        [a.x, a.y, a.z, b.x, b.y, b.z].map(f64::to_bits)
    };
    // Collect the visible pieces first so both variants time only their own work.
    let mut polys: Vec<Vec<bspvt_proto::sphere::SphPoly>> = Vec::new();
    for (v, (l, p, n)) in setup.iter().enumerate() {
        let dirs = light_directions(light, *p, *n);
        if dirs.len() < 3 {
            continue;
        }
        let mut pieces = Vec::new();
        trees.trees[v].split_polygon(&trees.codec, &dirs, &mut |piece, value, _| {
            if value >= 128 {
                pieces.push(piece.iter().map(|d| l.to_local * *d).collect());
            }
        });
        polys.push(pieces);
    }
    let lit = polys.len().max(1) as f64;
    let t = Instant::now();
    let by_pieces: Vec<f64> = polys
        .iter()
        .map(|ps| ps.iter().map(|q| edge_sum(q)).sum::<f64>())
        .collect();
    let us_pieces = t.elapsed().as_secs_f64() * 1e6 / lit;
    let edges_pieces: usize = polys.iter().flatten().map(|q| q.len()).sum();
    let t = Instant::now();
    let mut edges_left = 0usize;
    let mut map: HashMap<Key, (glam::DVec3, glam::DVec3, i32)> = HashMap::new();
    let by_boundary: Vec<f64> = polys
        .iter()
        .map(|ps| {
            map.clear();
            for q in ps {
                for i in 0..q.len() {
                    let (a, b) = (q[i], q[(i + 1) % q.len()]);
                    if let Some(e) = map.get_mut(&key(b, a)) {
                        e.2 -= 1;
                    } else {
                        map.entry(key(a, b)).or_insert((a, b, 0)).2 += 1;
                    }
                }
            }
            let mut s = 0.0;
            for (a, b, c) in map.values() {
                if *c != 0 {
                    edges_left += 1;
                    s += f64::from(*c) * edge(*a, *b);
                }
            }
            s
        })
        .collect();
    let us_boundary = t.elapsed().as_secs_f64() * 1e6 / lit;
    let worst = by_pieces
        .iter()
        .zip(&by_boundary)
        .map(|(a, b)| (a - b).abs() / a.abs().max(1e-12))
        .fold(0.0, f64::max);
    (
        edges_pieces as f64 / lit,
        edges_left as f64 / lit,
        us_pieces,
        us_boundary,
        worst,
    )
}

fn print_tables(r: &Report) {
    println!(
        "\n| scene | vertices | lit | BSPVT µs/vertex/core | textured | per lit vertex | pieces/lit vertex | unshadowed LTC µs/vertex/core | BSPVT / LTC |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for k in &r.kernel {
        println!(
            "| {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.1} | {:.3} | {:.2}× |",
            k.scene,
            k.vertices,
            k.lit_vertices,
            k.bspvt_us_per_vertex,
            k.bspvt_textured_us_per_vertex,
            k.bspvt_us_per_lit_vertex,
            k.pieces_per_lit_vertex,
            k.ltc_us_per_vertex,
            k.bspvt_us_per_vertex / k.ltc_us_per_vertex.max(1e-12)
        );
    }
    println!(
        "\n| scene | method | mode | ms/frame | fps | µs/vertex/core | vertices shaded | threads |"
    );
    println!("|---|---|---|---:|---:|---:|---:|---:|");
    for f in &r.frames {
        let per_vertex = if f.vertices_shaded > 0 {
            format!("{:.3}", f.us_per_vertex_per_core)
        } else {
            "–".into()
        };
        println!(
            "| {} | {:?} | {:?} | {:.2} | {:.1} | {per_vertex} | {} | {} |",
            f.scene, f.method, f.mode, f.ms_per_frame, f.fps, f.vertices_shaded, f.threads
        );
    }
}
