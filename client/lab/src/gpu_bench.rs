//! `bspvt bench-gpu`: BSPVT shading per vertex and whole frames on the GPU (wgpu; lavapipe
//! where there is no GPU) against the CPU (the reference renderer, all cores) in the same run,
//! while the light moves: per-vertex shading µs and frame ms, per vertex and per pixel, per
//! mesh and image size. Larger meshes are made by midpoint subdivision of a baked one (each
//! new vertex takes the trees of its edge's first endpoint: the same trees, not a bake).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use bspvt_client::gpu::Gpu;
use bspvt_client::gpu::frame::GpuFrames;
use bspvt_client::gpu::present::{Compositor, Offscreen, Pixels};
use bspvt_client::light::Light;
use bspvt_client::method::trees::{cached_bake, load_checked};
use bspvt_client::render::renderer::{Mode, Renderer, Trees};
use bspvt_proto::Scene;
use bspvt_proto::bspvt::VertexTrees;
use serde::Serialize;

/// `bspvt bench-gpu`.
#[derive(clap::Args, Clone, Debug)]
pub struct BenchGpuArgs {
    /// Meshes (file names under ../shared/assets/meshes, or paths), with the default ground
    /// and light.
    #[arg(long, value_delimiter = ',', default_values_t = vec!["bunny.ply".to_string()])]
    pub meshes: Vec<String>,
    /// Midpoint subdivisions of each mesh after its bake (each ×4 triangles, ~×4 vertices).
    #[arg(long, value_delimiter = ',', default_values_t = vec![0u32, 1, 2])]
    pub subdivide: Vec<u32>,
    /// Image sizes, WIDTHxHEIGHT.
    #[arg(long, value_delimiter = ',', default_values_t = vec!["512x512".to_string(), "1920x1080".to_string()])]
    pub sizes: Vec<String>,
    /// Timed GPU frames per configuration (the median is reported).
    #[arg(long, default_value_t = 8)]
    pub frames: usize,
    /// Timed CPU frames per configuration.
    #[arg(long, default_value_t = 3)]
    pub cpu_frames: usize,
    /// MSAA samples of the GPU frames (1 or 4).
    #[arg(long, default_value_t = 4)]
    pub samples: u32,
    /// Where bakes are cached (by the scene's hash).
    #[arg(long, default_value = "out/cache/bakes")]
    pub cache: PathBuf,
    /// Writes the rows as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One row: a mesh at one size, one mode.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// The mesh and its subdivisions.
    pub mesh: String,
    /// Vertices of the (subdivided) mesh, ground included.
    pub vertices: usize,
    /// Vertices the camera sees (shaded per frame).
    pub visible: usize,
    /// Image size.
    pub size: String,
    /// `vertex` or `pixel`.
    pub mode: String,
    /// GPU: the compute pass alone (eq. 2 for every visible vertex), µs.
    pub gpu_shade_us: f64,
    /// GPU: a whole frame (shading, raster, read-back into an image), ms.
    pub gpu_frame_ms: f64,
    /// GPU: a frame as the window presents it (shading, raster, tone mapping and the
    /// overlay into an 8-bit target; no read-back), waited for, ms.
    pub gpu_present_ms: f64,
    /// The presented frame's parts, ms (medians): the CPU recording and submitting the
    /// frame's passes, the CPU uploading the overlay and recording the composite, and the
    /// wait for the GPU after both.
    pub present_cpu_frame_ms: f64,
    /// See `present_cpu_frame_ms`.
    pub present_cpu_composite_ms: f64,
    /// See `present_cpu_frame_ms`.
    pub present_wait_ms: f64,
    /// GPU time of each pass of the presented frame (timestamps; `shade`, `raster`,
    /// `resolve`, `composite`), ms (medians); empty where the device has no timestamps.
    pub gpu_pass_ms: Vec<(String, f64)>,
    /// The first frame of the configuration (read back): the scene's and trees' uploads,
    /// the records, pipelines not yet made, ms.
    pub first_frame_ms: f64,
    /// CPU: per-vertex shading of every visible vertex, µs.
    pub cpu_shade_us: f64,
    /// CPU: a whole frame, ms.
    pub cpu_frame_ms: f64,
}

/// The adapter and the rows.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// The GPU's adapter.
    pub adapter: String,
    /// CPU threads.
    pub threads: usize,
    /// One per mesh, size and mode.
    pub rows: Vec<Row>,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Midpoint subdivision: every triangle into four; an edge's new vertex is its midpoint
/// (normal renormalised) and takes the trees of the edge's lower-index endpoint.
fn subdivide(scene: &mut Scene, trees: &mut Vec<VertexTrees>) {
    let m = &mut scene.mesh;
    let mut mid = std::collections::HashMap::new();
    let mut tris = Vec::with_capacity(m.triangles.len() * 4);
    let mut ids = Vec::with_capacity(m.triangles.len() * 4);
    let has_uv = m.uvs.len() == m.positions.len();
    for (t, &[a, b, c]) in m.triangles.clone().iter().enumerate() {
        let mut at = |i: u32, j: u32| -> u32 {
            let key = (i.min(j), i.max(j));
            *mid.entry(key).or_insert_with(|| {
                let (i, j) = (key.0 as usize, key.1 as usize);
                m.positions.push((m.positions[i] + m.positions[j]) * 0.5);
                let n = (m.normals[i] + m.normals[j]).normalize_or(m.normals[i]);
                m.normals.push(n);
                if has_uv {
                    m.uvs.push((m.uvs[i] + m.uvs[j]) * 0.5);
                }
                trees.push(trees[i].clone());
                (m.positions.len() - 1) as u32
            })
        };
        let (ab, bc, ca) = (at(a, b), at(b, c), at(c, a));
        tris.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        let id = m.material_ids.get(t).copied().unwrap_or(0);
        ids.extend([id; 4]);
    }
    m.triangles = tris;
    m.material_ids = ids;
}

fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s
        .split_once('x')
        .with_context(|| format!("size {s:?} is not WIDTHxHEIGHT"))?;
    Ok((w.parse()?, h.parse()?))
}

/// Runs the benchmark.
pub fn run(a: &BenchGpuArgs) -> Result<Report> {
    let gpu = Gpu::shared().context("bench-gpu needs a GPU adapter")?;
    let mut report = Report {
        adapter: gpu.adapter.clone(),
        threads: rayon::current_num_threads(),
        rows: Vec::new(),
    };
    eprintln!("adapter: {}", gpu.adapter);
    for name in &a.meshes {
        let path = {
            let p = PathBuf::from(name);
            if p.exists() {
                p
            } else {
                bspvt_proto::paths::meshes_dir().join(name)
            }
        };
        let base =
            Scene::from_mesh_path(&path).with_context(|| format!("loading {}", path.display()))?;
        let c = cached_bake(
            &bspvt_client::method::trees::file_stem(name),
            &base,
            &a.cache,
            &|_, _| {},
        )?;
        let bake = load_checked(&c.path, &base)?;
        let codec = bake.header.codec();
        let mut levels: Vec<u32> = a.subdivide.clone();
        levels.sort_unstable();
        let (mut scene, mut trees, mut level) = (base.clone(), bake.trees.clone(), 0);
        for &target in &levels {
            while level < target {
                subdivide(&mut scene, &mut trees);
                level += 1;
            }
            let label = if level == 0 {
                name.clone()
            } else {
                format!("{name} ÷{level}")
            };
            let all = Trees::full(&trees, codec.clone());
            for size in &a.sizes {
                let (w, h) = parse_size(size)?;
                let r = Renderer::new(&scene, w, h);
                let rest = Light::from_scene(&scene.lights[0]);
                let centre = scene.mesh.bounds().center().as_dvec3();
                let pose = |k: usize| {
                    let rot = glam::DAffine3::from_translation(centre)
                        * glam::DAffine3::from_rotation_y(0.05 * k as f64)
                        * glam::DAffine3::from_translation(-centre);
                    rest.transformed(&rot)
                };
                let mut frames = GpuFrames::new(gpu, &scene, a.samples)?;
                let mut compositor = Compositor::new(gpu, Offscreen::FORMAT)?;
                let timed = frames.time_passes(gpu) & compositor.time_passes(gpu);
                let target = Offscreen::new(gpu, w, h)?;
                let overlay = vec![0u32; (w * h) as usize];
                for mode in [Mode::Vertex, Mode::Pixel] {
                    // Warm-up: uploads, pipelines.
                    let t = Instant::now();
                    frames.frame(gpu, &r, &pose(0), Some(&all), mode)?;
                    let first_frame_ms = t.elapsed().as_secs_f64() * 1e3;
                    // The presented frame, its CPU parts (ms): recording the frame, the
                    // composite, the wait.
                    let present = |frames: &mut GpuFrames, c: &mut Compositor, k: usize| {
                        let t = Instant::now();
                        let (img, _) = frames.frame_on_gpu(gpu, &r, &pose(k), Some(&all), mode)?;
                        let t1 = Instant::now();
                        c.draw(gpu, Pixels::Gpu(&img), 1.0, &overlay, &target.view())?;
                        let t2 = Instant::now();
                        target.finish(gpu)?;
                        let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
                        anyhow::Ok([ms(t, t1), ms(t1, t2), ms(t2, Instant::now())])
                    };
                    present(&mut frames, &mut compositor, 0)?;
                    let (mut gs, mut gf, mut cs, mut cf) = (vec![], vec![], vec![], vec![]);
                    let (mut gp, mut parts) = (vec![], [vec![], vec![], vec![]]);
                    let mut passes: Vec<(&'static str, Vec<f64>)> = Vec::new();
                    for k in 0..a.frames {
                        let t = Instant::now();
                        frames.shade_only(gpu, &r, &pose(k + 1), Some(&all))?;
                        gs.push(t.elapsed().as_secs_f64() * 1e6);
                        let t = Instant::now();
                        frames.frame(gpu, &r, &pose(k + 1), Some(&all), mode)?;
                        gf.push(t.elapsed().as_secs_f64() * 1e3);
                        let t = Instant::now();
                        let p = present(&mut frames, &mut compositor, k + 1)?;
                        gp.push(t.elapsed().as_secs_f64() * 1e3);
                        for (v, x) in parts.iter_mut().zip(p) {
                            v.push(x);
                        }
                        if timed {
                            let mut times = frames.pass_times(gpu)?;
                            times.extend(compositor.pass_times(gpu)?);
                            for (label, ms) in times {
                                match passes.iter_mut().find(|(l, _)| *l == label) {
                                    Some((_, v)) => v.push(ms),
                                    None => passes.push((label, vec![ms])),
                                }
                            }
                        }
                    }
                    let [pf, pc, pw] = parts.map(median);
                    for k in 0..a.cpu_frames {
                        let t = Instant::now();
                        let _ = r.shade_vertices(std::slice::from_ref(&pose(k + 1)), &all, false);
                        cs.push(t.elapsed().as_secs_f64() * 1e6);
                        let t = Instant::now();
                        let _ = r.bspvt(std::slice::from_ref(&pose(k + 1)), &all, mode);
                        cf.push(t.elapsed().as_secs_f64() * 1e3);
                    }
                    let row = Row {
                        mesh: label.clone(),
                        vertices: scene.mesh.vertex_count(),
                        visible: r.visible_vertex_count(),
                        size: size.clone(),
                        mode: format!("{mode:?}").to_lowercase(),
                        gpu_shade_us: median(gs),
                        gpu_frame_ms: median(gf),
                        gpu_present_ms: median(gp),
                        present_cpu_frame_ms: pf,
                        present_cpu_composite_ms: pc,
                        present_wait_ms: pw,
                        gpu_pass_ms: passes
                            .into_iter()
                            .map(|(l, v)| (l.to_string(), median(v)))
                            .collect(),
                        first_frame_ms,
                        cpu_shade_us: median(cs),
                        cpu_frame_ms: median(cf),
                    };
                    let passes: Vec<String> = row
                        .gpu_pass_ms
                        .iter()
                        .map(|(l, ms)| format!("{l} {ms:.3}"))
                        .collect();
                    eprintln!(
                        "{} ({} vertices, {} visible) {} {}: GPU shade {:.0} µs, frame {:.1} ms read back, {:.1} ms presented (CPU: frame {:.2}, composite {:.2}, wait {:.2} ms; GPU passes ms: {}); first frame {:.1} ms | CPU shade {:.0} µs, frame {:.1} ms",
                        row.mesh,
                        row.vertices,
                        row.visible,
                        row.size,
                        row.mode,
                        row.gpu_shade_us,
                        row.gpu_frame_ms,
                        row.gpu_present_ms,
                        row.present_cpu_frame_ms,
                        row.present_cpu_composite_ms,
                        row.present_wait_ms,
                        if passes.is_empty() {
                            "no timestamps".to_string()
                        } else {
                            passes.join(", ")
                        },
                        row.first_frame_ms,
                        row.cpu_shade_us,
                        row.cpu_frame_ms
                    );
                    report.rows.push(row);
                }
            }
        }
    }
    if let Some(p) = &a.json {
        std::fs::write(p, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(report)
}
