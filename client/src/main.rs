//! `bspvt`: the client's command line.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bspvt_proto::encoding::decode_bake;
use bspvt_proto::scene::open_scene;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "bspvt", version, about = "bspvt client")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Decode a bake file, check it against its scene, and report (or export) light visibility.
    Inspect(InspectArgs),
    /// The main job on the built-in scene: bake it, read the trees back from disk, and
    /// evaluate the light's visibility at every vertex while the light moves.
    Demo(DemoArgs),
}

#[derive(clap::Args)]
struct DemoArgs {
    /// Output folder.
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
    /// Scene to bake (scene file or builtin:NAME).
    #[arg(long, default_value = "builtin:plate")]
    scene: String,
    /// Light positions to evaluate (frames).
    #[arg(long, default_value_t = 24)]
    frames: usize,
    #[arg(long)]
    face_res: Option<u32>,
}

#[derive(clap::Args)]
struct InspectArgs {
    /// Bake file written by `bspvt-server bake`.
    trees: PathBuf,
    /// The scene that was baked: scene file or builtin:NAME.
    #[arg(long)]
    scene: Option<String>,
    /// …or the bare mesh that was baked.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Write the mesh with per-vertex colours = visible fraction of light 0 (binary PLY).
    #[arg(long)]
    ply: Option<PathBuf>,
}

fn main() -> std::process::ExitCode {
    let result = match Cli::parse().command {
        Command::Inspect(a) => inspect(a),
        Command::Demo(a) => demo(a),
    };
    bspvt_proto::error::exit_code(result)
}

fn inspect(a: InspectArgs) -> Result<()> {
    let bytes =
        std::fs::read(&a.trees).with_context(|| format!("cannot read {}", a.trees.display()))?;
    let bake = decode_bake(&bytes)
        .with_context(|| format!("{} is not a valid bake", a.trees.display()))?;
    let h = &bake.header;
    let leaves: usize = bake.trees.iter().map(|t| t.leaf_count()).sum();
    let n = bake.trees.len().max(1) as f64;
    println!(
        "{}: {} vertices, {}² faces, ε = {}, {} bytes ({:.1} B/vertex), {:.1} leaves/vertex",
        a.trees.display(),
        h.vertex_count,
        h.face_res,
        h.epsilon,
        bytes.len(),
        bytes.len() as f64 / n,
        leaves as f64 / n
    );
    if a.scene.is_none() && a.mesh.is_none() {
        return Ok(());
    }
    let scene = open_scene(a.scene.as_deref(), a.mesh.as_deref())?;
    if scene.mesh.content_hash() != h.mesh_hash {
        bail!("the bake was made from a different mesh than this scene's");
    }
    let frac = bspvt::visibility::visible_fractions(&scene, 0, &h.codec(), &bake.trees);
    let seen: Vec<f64> = frac.iter().flatten().copied().collect();
    let shadowed = seen.iter().filter(|&&f| f < 0.999).count();
    let umbra = seen.iter().filter(|&&f| f < 0.001).count();
    println!(
        "light 0: {} vertices see it, {} in (partial) shadow, {} in umbra",
        seen.len(),
        shadowed,
        umbra
    );
    if let Some(p) = &a.ply {
        write_ply(p, &scene.mesh, &frac)?;
        println!("wrote {}", p.display());
    }
    Ok(())
}

fn demo(a: DemoArgs) -> Result<()> {
    use std::sync::atomic::AtomicBool;
    use std::time::Instant;

    let mut scene = open_scene(Some(&a.scene), None)?;
    if let Some(r) = a.face_res {
        scene.bake.face_res = r;
    }
    scene.validate()?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let baker = bspvt_server::bake::Baker::new(&scene);
    let n = baker.header().vertex_count as u64;
    println!(
        "baking {} ({n} vertices, {}² faces) on {} thread(s)",
        a.scene,
        scene.bake.face_res,
        rayon::current_num_threads()
    );
    let bar = indicatif::ProgressBar::new(n).with_style(
        indicatif::ProgressStyle::with_template(
            "{bar:40} {pos}/{len} vertices  {per_sec}  ETA {eta}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let out = baker.bake_all(&|done, _| bar.set_position(done), &AtomicBool::new(false))?;
    bar.finish();
    let file = a.out.join("trees.bspvt");
    std::fs::write(&file, &out.bytes)
        .with_context(|| format!("cannot write {}", file.display()))?;
    println!(
        "baked in {:.1} s: {} bytes ({:.1} B/vertex) -> {}",
        out.seconds,
        out.bytes.len(),
        out.bytes.len() as f64 / n.max(1) as f64,
        file.display()
    );

    // Read the trees back as a client would, then move the light through its region.
    let t = Instant::now();
    let bytes = std::fs::read(&file)?;
    let bake = decode_bake(&bytes)?;
    println!(
        "decoded {} vertices in {:.1} ms",
        bake.trees.len(),
        t.elapsed().as_secs_f64() * 1e3
    );
    let codec = bake.header.codec();
    let base = scene.lights[0].clone();
    let (lo, hi) = match base.region {
        Some(r) => (glam::Vec3::from(r.min), glam::Vec3::from(r.max)),
        None => {
            let c = glam::Vec3::from(base.vertices[0]);
            (c - glam::Vec3::ONE, c + glam::Vec3::ONE)
        }
    };
    let centre: glam::Vec3 = base.points().iter().sum::<glam::Vec3>() / base.vertices.len() as f32;
    let mut ms = Vec::new();
    for f in 0..a.frames.max(1) {
        // A circle through the region at the light's height, staying inside the region.
        let phase = std::f32::consts::TAU * f as f32 / a.frames.max(1) as f32;
        let radius = 0.35 * (hi - lo).x.min((hi - lo).z);
        let target = glam::Vec3::new(
            0.5 * (lo.x + hi.x) + radius * phase.cos(),
            centre.y,
            0.5 * (lo.z + hi.z) + radius * phase.sin(),
        );
        let shift = target - centre;
        scene.lights[0].vertices = base
            .vertices
            .iter()
            .map(|v| (glam::Vec3::from(*v) + shift).to_array())
            .collect();
        let t = Instant::now();
        let frac = bspvt::visibility::visible_fractions(&scene, 0, &codec, &bake.trees);
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        if f == 0 || f + 1 == a.frames {
            let p = a.out.join(format!("visibility-{f:03}.ply"));
            write_ply(&p, &scene.mesh, &frac)?;
        }
    }
    ms.sort_by(f64::total_cmp);
    println!(
        "light visibility for {} frames: median {:.1} ms/frame ({:.2} µs/vertex), PLYs in {}",
        ms.len(),
        ms[ms.len() / 2],
        ms[ms.len() / 2] * 1e3 / n.max(1) as f64,
        a.out.display()
    );
    Ok(())
}

/// Binary PLY with vertex colours: grey = visible fraction, dark blue = cannot see the light.
fn write_ply(path: &PathBuf, mesh: &bspvt_proto::Mesh, frac: &[Option<f64>]) -> Result<()> {
    let mut out = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?,
    );
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangles.len()
    )?;
    for (p, f) in mesh.positions.iter().zip(frac) {
        for c in p.to_array() {
            out.write_all(&c.to_le_bytes())?;
        }
        let rgb = match f {
            Some(f) => [(f * 255.0).round() as u8; 3],
            None => [10, 10, 60],
        };
        out.write_all(&rgb)?;
    }
    for t in &mesh.triangles {
        out.write_all(&[3])?;
        for i in t {
            out.write_all(&i.to_le_bytes())?;
        }
    }
    Ok(())
}
