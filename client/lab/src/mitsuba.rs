//! `bspvt export-mitsuba`: the scene as a Mitsuba 3 scene that renders the same image as the
//! Monte Carlo ground truth ([`bspvt_client::groundtruth::render_mc_box`]) — the independent
//! cross-check (`client/tests/mitsuba_crosscheck.rs`, `docs/groundtruth.md`).
//!
//! What is written to `DIR`:
//! - `scene.xml` (`<scene version="3.0.0">`): `path` integrator with `max_depth = 2` (direct
//!   light only, like our renderers) and `hide_emitters` (our renderers do not draw the light);
//!   a `perspective` sensor (`fov_axis = "y"`, `fov`, `look_at`, near/far clip from the scene's
//!   size), `independent` sampler, `hdrfilm` (rgb) with a `box` reconstruction filter;
//! - `mesh_<k>.ply`: the triangles of material k (binary PLY with the vertex normals, which
//!   Mitsuba interpolates as shading normals — as our G-buffer does);
//! - `light<k>.ply`: light k's polygon (fan triangles, no normals: face normals
//!   `(v1 − v0) × (v2 − v0)`, which is both Mitsuba's and our emitting side), with an `area`
//!   emitter and a black `diffuse` BSDF. A two-sided light adds `light<k>_back.ply`: the same
//!   polygon with reversed winding, 1e-4 × its diagonal behind (Mitsuba's area emitters are
//!   one-sided; two coplanar copies would hide each other at random). Every light of the scene
//!   is written (the asset's lamps too), or the one `--light` names, as bspvt's renderers
//!   shade all of them (or `bspvt render --light k`). A lamp is a surface in the way of the
//!   others in both (the Monte Carlo's shadow rays stop at other lamps).
//!
//! **Materials.** Our BRDF is a sum, albedo/π + F·D·G₁G₁/(4 cos θo cos θi) with Schlick's F;
//! Mitsuba has no additive BSDF, but every term has an exact counterpart:
//! - `diffuse` with `reflectance = albedo` is albedo/π;
//! - `principled` with `metallic = 1`, `base_color = F0`, `roughness = √α` is exactly
//!   F0 + (1 − F0)(1 − ωi·h)⁵ times GGX D with separable Smith G (Mitsuba 3's
//!   `principled_fresnel` reduces to `calc_schlick(base_color, ωi·h)` when metallic = 1, and
//!   all other lobes have weight (1 − metallic) = 0) — for α ≥ 1e-3: Mitsuba clamps the
//!   principled α = roughness² to at least 1e-3. When F0 = 1 the specular lobe is written as
//!   `roughconductor` (`material = "none"`: F = 1; `distribution = "ggx"`, `alpha`,
//!   `sample_visible`), exact down to α = 1e-4. Below α = 1e-3 with F0 < 1 the lobe is
//!   rendered at α = 1e-3 (reported by [`export`]).
//! - The sum is a `blendbsdf` with weight ½ of the two, and the emitter's radiance is doubled:
//!   ∫ 2L (½ f_d + ½ f_s) cos = ∫ L (f_d + f_s) cos. Exact, because direct lighting is linear
//!   in the BRDF; the only visible side effect is that the (hidden) emitter's own radiance
//!   reads 2L in the file.
//! - Everything is wrapped in `twosided`: our renderers shade both sides of a surface (the
//!   G-buffer flips normals toward the viewer), Mitsuba's BSDFs are black from behind.
//! - A cut-out material ([`bspvt_proto::scene::Cutout`]) is wrapped in a `mask` whose opacity
//!   is `mask_<k>.png`: the cut-out's own test (`Cutout::covers`, bilinear alpha against the
//!   cut-off) evaluated at the centres of a finer grid (at least 256 texels a side), 0 or 1,
//!   read `nearest` — so Mitsuba's stochastic opacity is the same hard mask; the mesh then
//!   carries its UVs (glTF's and Mitsuba's bitmaps both put v = 0 at the image's top row).
//!   Such a scene renders with `volpath` (same `max_depth`): `path`'s shadow rays stop at any
//!   surface, masks included, where `volpath`'s pass through null BSDFs (measured on the
//!   checker canopy: `path` 18 % darker than our Monte Carlo, `volpath` within 0.1 %).
//! - Normal maps are not exported (warned): Mitsuba's `normalmap` builds its frame from
//!   ∂p/∂u, not MikkTSpace's, and has no rule for a bent normal that turns from the viewer.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use bspvt_proto::scene::{Cutout, open_scene};
use bspvt_proto::{Mesh, Scene};
use glam::{DVec3, Vec3};

use bspvt_client::light::{Light, scene_lights};

/// Arguments of `bspvt export-mitsuba`.
#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// Scene file or builtin:NAME.
    pub(crate) scene: Option<String>,
    /// …or a bare mesh (gets the default scene: ground plane, quad light, framing camera).
    #[arg(long)]
    pub(crate) mesh: Option<PathBuf>,
    /// Output folder (created).
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Image width in pixels.
    #[arg(long, default_value_t = 640)]
    pub(crate) width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 480)]
    pub(crate) height: u32,
    /// Samples per pixel (the sampler's `sample_count`).
    #[arg(long, default_value_t = 256)]
    pub(crate) spp: u32,
    /// Write only this light (its index in the scene) [default: every light].
    #[arg(long)]
    pub(crate) light: Option<usize>,
}

/// Runs `bspvt export-mitsuba`.
pub fn run(args: &ExportArgs) -> Result<()> {
    let scene = open_scene(args.scene.as_deref(), args.mesh.as_deref())?;
    let all: Vec<Light> = scene_lights(&scene)?.into_iter().map(|l| l.0).collect();
    let lights: Vec<Light> = match args.light {
        Some(k) => {
            let Some(l) = all.get(k) else {
                bail!("--light {k}: the scene has {} light(s)", all.len());
            };
            vec![l.clone()]
        }
        None => all,
    };
    let opts = ExportOptions {
        width: args.width,
        height: args.height,
        spp: args.spp,
    };
    let summary = export(&scene, &lights, &opts, &args.out)?;
    for w in &summary.warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "wrote {} ({} files); render with: mitsuba {} -o image.exr   (or python: \
         mi.set_variant('scalar_rgb'); mi.render(mi.load_file(...)))",
        summary.scene_xml.display(),
        summary.files.len(),
        summary.scene_xml.display()
    );
    Ok(())
}

/// Image settings of the exported scene.
#[derive(Clone, Copy, Debug)]
pub struct ExportOptions {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per pixel Mitsuba renders.
    pub spp: u32,
}

/// What [`export`] wrote.
#[derive(Clone, Debug)]
pub struct ExportSummary {
    /// The Mitsuba 3 scene file.
    pub scene_xml: PathBuf,
    /// Every file written (scene.xml first).
    pub(crate) files: Vec<PathBuf>,
    /// Where the Mitsuba scene is not exactly our BRDF (α < 1e-3 with F0 < 1).
    pub warnings: Vec<String>,
}

/// Smallest α Mitsuba's `principled` BSDF represents (it clamps roughness² to this).
pub(crate) const PRINCIPLED_MIN_ALPHA: f64 = 1e-3;

/// Writes `scene` lit by `lights` (world space; e.g. one frame of a moving light) as a
/// Mitsuba 3 scene in `dir`.
pub fn export(
    scene: &Scene,
    lights: &[Light],
    opts: &ExportOptions,
    dir: &Path,
) -> Result<ExportSummary> {
    if lights.is_empty() {
        bail!("no light to export");
    }
    for (k, light) in lights.iter().enumerate() {
        if light.is_polygon()
            && (light.vertices.len() < 3 || !light.vertices.iter().all(|v| v.is_finite()))
        {
            bail!("light {k} needs at least 3 finite vertices");
        }
    }
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut files = Vec::new();
    let mut warnings = Vec::new();
    let mesh = &scene.mesh;
    let bounds = mesh.bounds();
    let diag = f64::from(bounds.diagonal()).max(1e-30);

    let mut xml = String::new();
    let cam = &scene.camera;
    let eye = Vec3::from(cam.position).as_dvec3();
    let centre = bounds.center().as_dvec3();
    let near = 1e-4 * diag;
    let far = 10.0 * ((eye - centre).length() + diag);
    let _ = writeln!(xml, r#"<?xml version="1.0" encoding="utf-8"?>"#);
    let _ = writeln!(
        xml,
        "<!-- Written by `bspvt export-mitsuba`: direct light from polygonal lights, the \
         same image as bspvt's Monte Carlo ground truth with box-filtered pixels.\n     \
         Materials: twosided(blendbsdf(0.5, diffuse(albedo), GGX-Schlick specular)) with the \
         emitter's radiance doubled, which is exactly albedo/pi + F D G / (4 cos cos); see \
         client/src/mitsuba.rs and docs/groundtruth.md.\n     Render: mitsuba scene.xml -o \
         image.exr (variant scalar_rgb), or client/tests/mitsuba/render.py. -->"
    );
    let _ = writeln!(xml, r#"<scene version="3.0.0">"#);
    // `path` tests shadow rays against every surface (a mask's holes would block them); `volpath`
    // passes them through null BSDFs (`eval_null_transmission`), so cut-outs get it.
    let cutouts = scene
        .materials
        .iter()
        .any(|m| m.cutout.as_ref().is_some_and(|c| !c.is_opaque()));
    let _ = writeln!(
        xml,
        r#"    <integrator type="{integrator}">
        <integer name="max_depth" value="2"/>
        <boolean name="hide_emitters" value="true"/>
    </integrator>"#,
        integrator = if cutouts { "volpath" } else { "path" }
    );
    let _ = writeln!(
        xml,
        r#"    <sensor type="perspective">
        <string name="fov_axis" value="y"/>
        <float name="fov" value="{fov}"/>
        <float name="near_clip" value="{near:e}"/>
        <float name="far_clip" value="{far:e}"/>
        <transform name="to_world">
            <lookat origin="{o}" target="{t}" up="{u}"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="{spp}"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="{w}"/>
            <integer name="height" value="{h}"/>
            <string name="pixel_format" value="rgb"/>
            <rfilter type="box"/>
        </film>
    </sensor>"#,
        fov = cam.fov_y_deg,
        o = triple(cam.position.map(f64::from)),
        t = triple(cam.target.map(f64::from)),
        u = triple(cam.up.map(f64::from)),
        spp = opts.spp.max(1),
        w = opts.width.max(1),
        h = opts.height.max(1),
    );

    // Materials in use and their meshes.
    let mut used: Vec<u32> = mesh.material_ids.clone();
    used.sort_unstable();
    used.dedup();
    for &m in &used {
        let Some(mat) = scene.materials.get(m as usize) else {
            bail!(
                "material index {m} used, but the scene has {} materials",
                scene.materials.len()
            );
        };
        if mat.maps.is_some() {
            warnings.push(format!(
                "material {:?}'s textures are not exported: Mitsuba renders the textures' mean",
                mat.name
            ));
        }
        let alpha = bspvt_client::ggx::clamp_alpha(f64::from(mat.roughness));
        let f0 = mat.specular.map(f64::from);
        let albedo = mat.albedo.map(f64::from);
        let spec = if f0.iter().all(|&c| c >= 1.0) {
            format!(
                r#"<bsdf type="roughconductor">
                <string name="material" value="none"/>
                <string name="distribution" value="ggx"/>
                <float name="alpha" value="{a}"/>
                <boolean name="sample_visible" value="true"/>
            </bsdf>"#,
                a = num(alpha)
            )
        } else {
            if alpha < PRINCIPLED_MIN_ALPHA {
                warnings.push(format!(
                    "material {m} ({:?}): α = {alpha:e} < {PRINCIPLED_MIN_ALPHA:e} with F0 < 1: \
                     Mitsuba's principled BSDF renders it at α = {PRINCIPLED_MIN_ALPHA:e}",
                    mat.name
                ));
            }
            format!(
                r#"<bsdf type="principled">
                <rgb name="base_color" value="{f0}"/>
                <float name="metallic" value="1"/>
                <float name="roughness" value="{r}"/>
            </bsdf>"#,
                f0 = triple(f0),
                r = alpha.sqrt()
            )
        };
        let _ = writeln!(
            xml,
            r#"    <bsdf type="twosided" id="mat{m}">
        <!-- {name}: albedo {a}, F0 {f}, alpha {al} -->
        <bsdf type="blendbsdf">
            <float name="weight" value="0.5"/>
            <bsdf type="diffuse">
                <rgb name="reflectance" value="{a}"/>
            </bsdf>
            {spec}
        </bsdf>
    </bsdf>"#,
            name = xml_text(&mat.name),
            a = triple(albedo),
            f = triple(f0),
            al = num(alpha),
        );
        if mat.normal_map.is_some() {
            warnings.push(format!(
                "material {:?}'s normal map is not exported (Mitsuba's `normalmap` has no \
                 MikkTSpace frame and no silhouette rule): it renders with the mesh normals",
                mat.name
            ));
        }
        let cut = mat.cutout.as_ref().filter(|c| !c.is_opaque());
        if let Some(c) = cut {
            let (opacity, wrap) = mask_image(c, !mesh.uvs.is_empty());
            let file = format!("mask_{m}.png");
            let path = dir.join(&file);
            opacity
                .save(&path)
                .with_context(|| format!("cannot write {}", path.display()))?;
            files.push(path);
            if c.texture.as_ref().is_some_and(|t| t.wrap[0] != t.wrap[1]) {
                warnings.push(format!(
                    "material {:?}'s cut-out wraps differently along u and v: Mitsuba's mask \
                     wraps both as along u",
                    mat.name
                ));
            }
            let _ = writeln!(
                xml,
                r#"    <bsdf type="mask" id="mask{m}">
        <texture name="opacity" type="bitmap">
            <string name="filename" value="{file}"/>
            <string name="filter_type" value="nearest"/>
            <string name="wrap_mode" value="{wrap}"/>
            <boolean name="raw" value="true"/>
        </texture>
        <ref id="mat{m}"/>
    </bsdf>"#
            );
        }
        let file = format!("mesh_{m}.ply");
        let path = dir.join(&file);
        let mut part = submesh(mesh, m);
        if cut.is_none() {
            part.uvs.clear();
        }
        write_ply(&path, &part, true)?;
        files.push(path);
        let _ = writeln!(
            xml,
            r#"    <shape type="ply">
        <string name="filename" value="{file}"/>
        <ref id="{id}{m}"/>
    </shape>"#,
            id = if cut.is_some() { "mask" } else { "mat" }
        );
    }

    // The lights: emitting side = (v1 − v0) × (v2 − v0) in Mitsuba and here.
    for (k, light) in lights.iter().enumerate() {
        if !light.is_polygon() {
            round_light(&mut xml, &mut warnings, k, light);
            continue;
        }
        let mut verts = light.vertices.clone();
        if newell(&verts).dot(light.normal) < 0.0 {
            verts.reverse();
        }
        if light.texture.is_some() {
            warnings.push(format!(
                "light {k}'s texture is not exported: Mitsuba renders its radiance at the \
                 centroid, uniform"
            ));
        }
        let radiance = light.radiance_at(light.centroid()) * 2.0;
        let mut sides = vec![(format!("light{k}.ply"), verts.clone())];
        if light.two_sided {
            let size = polygon_diagonal(&verts);
            let back: Vec<DVec3> = verts
                .iter()
                .rev()
                .map(|&v| v - light.normal * (1e-4 * size))
                .collect();
            sides.push((format!("light{k}_back.ply"), back));
        }
        for (file, poly) in &sides {
            let path = dir.join(file);
            write_ply(&path, &polygon_mesh(poly), false)?;
            files.push(path);
            let _ = writeln!(
                xml,
                r#"    <shape type="ply">
        <string name="filename" value="{file}"/>
        <boolean name="face_normals" value="true"/>
        <bsdf type="diffuse">
            <rgb name="reflectance" value="0, 0, 0"/>
        </bsdf>
        <emitter type="area">
            <!-- 2 x light {k}'s radiance {l}: see the blendbsdf weights above -->
            <rgb name="radiance" value="{r}"/>
        </emitter>
    </shape>"#,
                l = triple((radiance / 2.0).to_array()),
                r = triple(radiance.to_array()),
            );
        }
    }
    let _ = writeln!(xml, "</scene>");
    let scene_xml = dir.join("scene.xml");
    std::fs::write(&scene_xml, xml)
        .with_context(|| format!("cannot write {}", scene_xml.display()))?;
    files.insert(0, scene_xml.clone());
    Ok(ExportSummary {
        scene_xml,
        files,
        warnings,
    })
}

/// A sphere or a sun in Mitsuba's terms (radiances doubled as the polygon lights' are): a
/// point light's sphere as a `sphere` with an area emitter (exactly ours); a spot as Mitsuba's
/// `spot`, a point of the same intensity whose falloff is linear in angle between the cone
/// angles (glTF's is quadratic in cos θ there); a sun as `directional` of the same
/// irradiance (a delta: sharp where ours has the disk's 0.53° penumbra).
fn round_light(xml: &mut String, warnings: &mut Vec<String>, k: usize, light: &Light) {
    use bspvt_client::light::Shape;
    match &light.shape {
        Shape::Polygon => {}
        Shape::Sphere(l) => {
            if l.range.is_some() {
                warnings.push(format!(
                    "light {k}'s range window is not exported (Mitsuba's lights have none)"
                ));
            }
            let c = Vec3::from(l.position).as_dvec3();
            match &l.spot {
                None => {
                    let _ = writeln!(
                        xml,
                        r#"    <shape type="sphere">
        <point name="center" value="{c}"/>
        <float name="radius" value="{r}"/>
        <bsdf type="diffuse">
            <rgb name="reflectance" value="0, 0, 0"/>
        </bsdf>
        <emitter type="area">
            <!-- 2 x light {k}'s radiance (a point light's sphere) -->
            <rgb name="radiance" value="{l}"/>
        </emitter>
    </shape>"#,
                        c = triple(c.to_array()),
                        r = num(f64::from(l.sphere_radius())),
                        l = triple((light.radiance * 2.0).to_array()),
                    );
                }
                Some(s) => {
                    warnings.push(format!(
                        "light {k} (a spot) is exported as Mitsuba's point spot: no sphere,                          and its falloff linear in angle between the cone angles"
                    ));
                    let d = Vec3::from(s.direction).as_dvec3();
                    let up = if d.y.abs() > 0.9 { DVec3::X } else { DVec3::Y };
                    let _ = writeln!(
                        xml,
                        r#"    <emitter type="spot">
        <!-- 2 x light {k}'s intensity -->
        <rgb name="intensity" value="{i}"/>
        <float name="cutoff_angle" value="{co}"/>
        <float name="beam_width" value="{ci}"/>
        <transform name="to_world">
            <lookat origin="{o}" target="{t}" up="{u}"/>
        </transform>
    </emitter>"#,
                        i = triple(l.intensity.map(|x| 2.0 * f64::from(x))),
                        co = num(f64::from(s.outer_cone_angle.to_degrees())),
                        ci = num(f64::from(s.inner_cone_angle.to_degrees())),
                        o = triple(c.to_array()),
                        t = triple((c + d).to_array()),
                        u = triple(up.to_array()),
                    );
                }
            }
        }
        Shape::Distant { toward, half_angle } => {
            // Irradiance facing the sun: E = L π sin²(half) (SunLight::disk_radiance).
            let omega = std::f64::consts::PI * half_angle.sin().powi(2);
            let _ = writeln!(
                xml,
                r#"    <emitter type="directional">
        <!-- 2 x light {k}'s irradiance (a sun) -->
        <vector name="direction" value="{d}"/>
        <rgb name="irradiance" value="{e}"/>
    </emitter>"#,
                d = triple((-*toward).to_array()),
                e = triple((light.radiance * omega * 2.0).to_array()),
            );
        }
    }
}

fn triple(v: [f64; 3]) -> String {
    format!("{}, {}, {}", num(v[0]), num(v[1]), num(v[2]))
}

/// The shortest text that reads back as `x`: as f32 when `x` came from one (scene files are
/// f32), so 0.6f32 prints as "0.6", not "0.6000000238418579".
fn num(x: f64) -> String {
    let f = x as f32;
    if f64::from(f) == x {
        format!("{f}")
    } else {
        format!("{x}")
    }
}

/// Text safe inside an XML comment.
fn xml_text(s: &str) -> String {
    s.replace("--", "- -")
        .chars()
        .filter(|c| !c.is_control())
        .collect()
}

fn newell(p: &[DVec3]) -> DVec3 {
    let mut n = DVec3::ZERO;
    for i in 0..p.len() {
        n += p[i].cross(p[(i + 1) % p.len()]);
    }
    n
}

fn polygon_diagonal(p: &[DVec3]) -> f64 {
    let (lo, hi) = p.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &v| (lo.min(v), hi.max(v)),
    );
    (hi - lo).length()
}

/// A cut-out as a hard opacity image for Mitsuba's `mask` (module docs) and its wrap mode:
/// [`Cutout::covers`] at the centres of a grid `k` times the texture's (k the smallest that
/// gives 256 a side, at most 4096 a side); one texel of the constant where there is no texture
/// or no UVs.
fn mask_image(c: &Cutout, uvs: bool) -> (image::GrayImage, &'static str) {
    let byte = |covers: bool| image::Luma([if covers { 255u8 } else { 0 }]);
    let Some(t) = c.texture.as_ref().filter(|_| uvs) else {
        return (
            image::GrayImage::from_pixel(1, 1, byte(c.covers(None))),
            "clamp",
        );
    };
    let (w, h) = (t.texture.width.max(1), t.texture.height.max(1));
    let k = 256u32.div_ceil(w.max(h)).clamp(1, (4096 / w.max(h)).max(1));
    let (gw, gh) = (w * k, h * k);
    let img = image::GrayImage::from_fn(gw, gh, |x, y| {
        let uv = glam::Vec2::new((x as f32 + 0.5) / gw as f32, (y as f32 + 0.5) / gh as f32);
        byte(c.covers(Some(uv)))
    });
    let wrap = match t.wrap[0] {
        bspvt_proto::texture::Wrap::Repeat => "repeat",
        bspvt_proto::texture::Wrap::Clamp => "clamp",
        bspvt_proto::texture::Wrap::Mirror => "mirror",
    };
    (img, wrap)
}

/// The triangles of material `m`, with only the vertices they use.
fn submesh(mesh: &Mesh, m: u32) -> Mesh {
    let mut remap = vec![u32::MAX; mesh.positions.len()];
    let mut out = Mesh::default();
    for (t, &id) in mesh.triangles.iter().zip(&mesh.material_ids) {
        if id != m {
            continue;
        }
        let tri = t.map(|v| {
            let r = &mut remap[v as usize];
            if *r == u32::MAX {
                *r = out.positions.len() as u32;
                out.positions.push(mesh.positions[v as usize]);
                out.normals.push(mesh.normals[v as usize]);
                if let Some(&uv) = mesh.uvs.get(v as usize) {
                    out.uvs.push(uv);
                }
            }
            *r
        });
        out.triangles.push(tri);
        out.material_ids.push(0);
    }
    out
}

/// A convex polygon as fan triangles (winding kept).
fn polygon_mesh(p: &[DVec3]) -> Mesh {
    let mut m = Mesh {
        positions: p.iter().map(|v| v.as_vec3()).collect(),
        ..Mesh::default()
    };
    m.normals = vec![Vec3::ZERO; p.len()];
    for i in 1..p.len().saturating_sub(1) {
        m.triangles.push([0, i as u32, i as u32 + 1]);
        m.material_ids.push(0);
    }
    m
}

/// Binary little-endian PLY: positions (and normals when `normals`), triangles.
fn write_ply(path: &Path, mesh: &Mesh, normals: bool) -> Result<()> {
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by bspvt export-mitsuba\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        mesh.positions.len()
    );
    if normals {
        header.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    let uvs = mesh.uvs.len() == mesh.positions.len() && !mesh.uvs.is_empty();
    if uvs {
        header.push_str("property float u\nproperty float v\n");
    }
    let _ = write!(
        header,
        "element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.triangles.len()
    );
    let per_vertex = if normals { 24 } else { 12 };
    let mut bytes = Vec::with_capacity(
        header.len() + mesh.positions.len() * per_vertex + mesh.triangles.len() * 13,
    );
    bytes.extend_from_slice(header.as_bytes());
    for (i, p) in mesh.positions.iter().enumerate() {
        for c in p.to_array() {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
        if normals {
            let n = mesh.normals.get(i).copied().unwrap_or(Vec3::Z);
            for c in n.to_array() {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        if uvs {
            for c in mesh.uvs[i].to_array() {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    for t in &mesh.triangles {
        bytes.push(3);
        for &v in t {
            bytes.extend_from_slice(&(v as i32).to_le_bytes());
        }
    }
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exports_the_builtin_scene() {
        let scene = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
        let light = Light::from_scene(&scene.lights[0]);
        let dir = std::env::temp_dir().join(format!("bspvt-mitsuba-{}", std::process::id()));
        let opts = ExportOptions {
            width: 32,
            height: 24,
            spp: 4,
        };
        let s = export(&scene, &[light], &opts, &dir).expect("export");
        let xml = std::fs::read_to_string(&s.scene_xml).expect("read scene.xml");
        assert!(xml.contains(r#"<scene version="3.0.0">"#));
        assert!(xml.contains(r#"<integer name="max_depth" value="2"/>"#));
        assert_eq!(xml.matches(r#"type="principled""#).count(), 3);
        assert!(xml.contains(r#"<rgb name="radiance" value="24, 22, 20"/>"#));
        assert!(s.warnings.is_empty());
        // Every triangle is in exactly one PLY.
        let mut tris = 0;
        for f in &s.files[1..] {
            let b = std::fs::read(f).expect("read ply");
            let text = String::from_utf8_lossy(&b[..b.len().min(400)]).to_string();
            let faces: usize = text
                .lines()
                .find_map(|l| l.strip_prefix("element face "))
                .and_then(|n| n.trim().parse().ok())
                .expect("face count");
            if !f.ends_with("light0.ply") {
                tris += faces;
            }
        }
        assert_eq!(tris, scene.mesh.triangles.len());
        let _ = std::fs::remove_dir_all(dir);
    }

    /// The asset's own materials and lamp (the built-in glTF room): the lamp's radiance is
    /// emissiveFactor × emissiveStrength = (1, 0.9, 0.75) × 12, written doubled; the gold box
    /// (metallic 1, baseColor (1, 0.78, 0.34), roughness 0.35) has albedo 0 and F0 = baseColor,
    /// the green plastic (metallic 0) albedo = baseColor and F0 = 0.04.
    #[test]
    fn exports_the_rooms_own_lamp_and_materials() {
        let scene = bspvt_proto::builtin::scene("room").expect("built-in room");
        let lights: Vec<Light> = scene.lights.iter().map(Light::from_scene).collect();
        assert_eq!(lights.len(), 1);
        let dir = std::env::temp_dir().join(format!("bspvt-mitsuba-room-{}", std::process::id()));
        let opts = ExportOptions {
            width: 32,
            height: 24,
            spp: 4,
        };
        let s = export(&scene, &lights, &opts, &dir).expect("export");
        let xml = std::fs::read_to_string(&s.scene_xml).expect("read scene.xml");
        // The numbers after `key` in the file, in order (each value="a, b, c" or "a").
        let values = |key: &str| -> Vec<Vec<f64>> {
            xml.split(key)
                .skip(1)
                .filter_map(|rest| rest.split('"').nth(1))
                .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect())
                .collect()
        };
        let close = |a: &[f64], b: &[f64]| {
            a.len() == b.len()
                && a.iter()
                    .zip(b)
                    .all(|(x, y)| (x - y).abs() <= 1e-6 * y.abs())
        };
        let radiance = values(r#"<rgb name="radiance" value="#);
        assert_eq!(radiance.len(), 1, "{xml}");
        assert!(close(&radiance[0], &[24.0, 21.6, 18.0]), "{radiance:?}");
        // The gold's specular: principled, base colour = F0 = baseColor, roughness = √α = 0.35.
        let base = values(r#"<rgb name="base_color" value="#);
        assert!(
            base.iter().any(|b| close(b, &[1.0, 0.78, 0.34])),
            "{base:?}"
        );
        let roughness = values(r#"<float name="roughness" value="#);
        assert!(roughness.iter().any(|r| close(r, &[0.35])), "{roughness:?}");
        assert!(xml.contains("brushed gold: albedo 0, 0, 0, F0 1, 0.78, 0.34"));
        assert!(xml.contains("glossy plastic: albedo 0.05, 0.3, 0.1, F0 0.04, 0.04, 0.04"));
        // One PLY per material in use, one for the lamp; the lamp is not in the meshes.
        let materials: std::collections::BTreeSet<u32> =
            scene.mesh.material_ids.iter().copied().collect();
        assert_eq!(s.files.len(), 1 + materials.len() + 1);
        assert!(dir.join("light0.ply").is_file());
        let _ = std::fs::remove_dir_all(dir);
    }
}
