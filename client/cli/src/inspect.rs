//! `bspvt inspect`: a bake file's figures, checked against its scene; the visible fraction of
//! light 0 per vertex, optionally as a coloured PLY.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bspvt_proto::encoding::decode_bake;

#[derive(clap::Args)]
pub(crate) struct InspectArgs {
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

pub(crate) fn run(a: InspectArgs) -> Result<()> {
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
    let scene = bspvt_client::scene::open(a.scene.as_deref(), a.mesh.as_deref())?;
    if scene.mesh.content_hash() != h.mesh_hash {
        bail!("the bake was made from a different mesh than this scene's");
    }
    let frac = bspvt_client::visibility::visible_fractions(&scene, 0, &h.codec(), &bake.trees);
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
