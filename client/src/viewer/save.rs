//! What the viewer writes: screenshots (PNG) and the view (camera and light) as a scene file.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use bspvt_proto::scene::{Camera, MeshRef, PolygonLight, SceneFile, builtin};

use crate::light::Light;

/// Where the viewed scene came from, for writing it back with a new view.
#[derive(Clone, Debug, Default)]
pub struct SceneSource {
    /// The scene argument: a scene file, `builtin:NAME`, or a service's scene (URL or id).
    pub scene: Option<String>,
    /// A bare mesh (`--mesh`).
    pub mesh: Option<PathBuf>,
}

/// Writes the window's pixels (0RGB) as a PNG in `dir`: `bspvt-<seconds since 1970>-<n>.png`.
pub(crate) fn screenshot(
    dir: &Path,
    pixels: &[u32],
    width: usize,
    height: usize,
    n: u64,
) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let path = dir.join(format!("bspvt-{secs}-{n}.png"));
    let img = image::RgbImage::from_fn(width as u32, height as u32, |x, y| {
        let p = pixels[y as usize * width + x as usize];
        image::Rgb([(p >> 16) as u8, (p >> 8) as u8, p as u8])
    });
    img.save(&path)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// Whether the loader put a ground plane (and a quad light) around the scene: a bare mesh
/// that brings no light of its own. The asset itself is asked: the scene a service serves
/// carries no loader warnings to tell (the viewer once matched one, and saved every bare mesh's
/// view without its ground).
pub(crate) fn added_ground(source: &SceneSource) -> bool {
    source.mesh.as_deref().is_some_and(|m| {
        bspvt_proto::import::load_asset(m).is_ok_and(|a| bspvt_proto::Scene::adds_ground(&a))
    })
}

/// The scene file of `source` with `camera` and light k replaced by `light` = (k, light as
/// posed now), and where to write it: `out` if given, else `<scene>.view.json` beside a scene file
/// (its relative mesh paths stay valid), `out/views/<name>.view.json` for a built-in scene or a
/// bare mesh. The scene file itself is never overwritten. `added_ground`: the loader put a
/// ground under a bare mesh that brought no lamp.
pub(crate) fn view_file(
    source: &SceneSource,
    out: Option<&Path>,
    scene_lights: &[PolygonLight],
    added_ground: bool,
    camera: Camera,
    light: Option<(usize, &Light)>,
) -> Result<(SceneFile, PathBuf)> {
    let (mut file, default_out, from_file) = match (&source.scene, &source.mesh) {
        (Some(s), _) if s.starts_with("builtin:") => {
            let name = &s["builtin:".len()..];
            let f = builtin::scene_file(name)
                .with_context(|| format!("unknown built-in scene {name:?}"))?;
            (
                f,
                PathBuf::from(format!("out/views/{name}.view.json")),
                true,
            )
        }
        (Some(s), _) if Path::new(s).is_file() => {
            let p = Path::new(s);
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            let f: SceneFile = serde_json::from_str(&text)
                .with_context(|| format!("{} is not a scene file", p.display()))?;
            let stem = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "scene".into());
            (f, p.with_file_name(format!("{stem}.view.json")), true)
        }
        (None, Some(m)) => {
            let abs = std::path::absolute(m)
                .with_context(|| format!("cannot resolve {}", m.display()))?;
            let stem = m
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "mesh".into());
            let f = SceneFile {
                meshes: vec![MeshRef {
                    path: abs.to_string_lossy().into_owned(),
                    material: None,
                    transform: None,
                    motion: None,
                }],
                ground_plane: false,
                ground_material: 0,
                materials: vec![Default::default()],
                lights: Vec::new(),
                punctual: Vec::new(),
                suns: Vec::new(),
                punctual_radius: None,
                asset_lights: true,
                camera: None,
                bake: Default::default(),
                environment: None,
            };
            (
                f,
                PathBuf::from(format!("out/views/{stem}.view.json")),
                false,
            )
        }
        (Some(s), _) => bail!(
            "the scene {s:?} came from a service: save view needs a local scene file, \
             builtin:NAME or --mesh"
        ),
        (None, None) => bail!("no scene source to save the view of"),
    };
    file.camera = Some(Camera {
        aspect: None,
        ..camera
    });
    // A point, spot or sun light stays as its scene has it (only polygon lights are saved
    // posed).
    if let Some((k, l)) = light.filter(|(k, l)| l.is_polygon() && *k < scene_lights.len()) {
        let posed = |base: &PolygonLight| PolygonLight {
            vertices: l.vertices.iter().map(|v| v.as_vec3().to_array()).collect(),
            radiance: l.radiance.as_vec3().to_array(),
            two_sided: l.two_sided,
            texture: base.texture.clone(),
            region: base.region,
            moves_in_plane: base.moves_in_plane,
            image: None,
        };
        match file.lights.get_mut(k) {
            // The scene file's own lights come first in the scene's.
            Some(own) if from_file => *own = posed(own),
            _ => {
                // The light came from the asset (a lamp, or the quad added over a bare mesh):
                // the scene file takes every light explicitly, the moved one posed.
                file.lights = scene_lights.to_vec();
                if let Some(moved) = file.lights.get_mut(k) {
                    *moved = posed(moved);
                }
                file.asset_lights = false;
                if !from_file {
                    // A bare mesh without lamps was given a ground with its quad light.
                    file.ground_plane = added_ground;
                }
            }
        }
    }
    let out = out.map(Path::to_path_buf).unwrap_or(default_out);
    if let Some(src) = source.scene.as_deref().map(Path::new)
        && std::path::absolute(src).ok() == std::path::absolute(&out).ok()
    {
        bail!("will not overwrite the scene file {}", out.display());
    }
    Ok((file, out))
}

/// Writes the view file (via a temporary file and a rename, so a failed write leaves any
/// earlier one whole).
pub(crate) fn write_view(file: &SceneFile, out: &Path) -> Result<()> {
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let text = serde_json::to_string_pretty(file)?;
    let tmp = out.with_extension("json.tmp");
    std::fs::write(&tmp, text).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, out).with_context(|| format!("cannot write {}", out.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn a_built_in_scene_is_written_with_the_moved_light_and_never_over_its_source() {
        let scene = builtin::scene("plate").expect("built-in plate");
        let mut light = Light::from_scene(&scene.lights[0]);
        for v in &mut light.vertices {
            *v += DVec3::new(0.25, 0.0, 0.0);
        }
        let camera = Camera {
            fov_y_deg: 33.0,
            ..scene.camera.clone()
        };
        let source = SceneSource {
            scene: Some("builtin:plate".into()),
            mesh: None,
        };
        let (file, out) = view_file(
            &source,
            None,
            &scene.lights,
            false,
            camera,
            Some((0, &light)),
        )
        .expect("view");
        assert_eq!(out, PathBuf::from("out/views/plate.view.json"));
        assert_eq!(file.camera.as_ref().map(|c| c.fov_y_deg), Some(33.0));
        let (a, b) = (file.lights[0].vertices[0], scene.lights[0].vertices[0]);
        assert!((a[0] - b[0] - 0.25).abs() < 1e-6 && a[1] == b[1] && a[2] == b[2]);
        assert_eq!(file.lights[0].region, scene.lights[0].region);
        // The written file is a scene that loads, with the new light.
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("v.json");
        write_view(&file, &path).expect("write");
        let back = bspvt_proto::Scene::load(&path).expect("loads");
        assert_eq!(back.lights[0].vertices, file.lights[0].vertices);
        // A scene file is never overwritten by its own view.
        let src = dir.path().join("s.json");
        std::fs::copy(&path, &src).expect("copy");
        let from_file = SceneSource {
            scene: Some(src.to_string_lossy().into_owned()),
            mesh: None,
        };
        let err = view_file(
            &from_file,
            Some(&src),
            &scene.lights,
            false,
            scene.camera.clone(),
            None,
        )
        .expect_err("refuses");
        assert!(err.to_string().contains("will not overwrite"), "{err}");
        // A service's scene has no file to write back.
        let remote = SceneSource {
            scene: Some("http://127.0.0.1:1/v1/scenes/abc".into()),
            mesh: None,
        };
        let err =
            view_file(&remote, None, &[], false, scene.camera.clone(), None).expect_err("no file");
        assert!(err.to_string().contains("came from a service"), "{err}");
    }

    /// A bare mesh without lights gets a ground from the loader, and its saved view keeps it
    /// (the scene as served has no warnings to say so: the asset is asked). A mesh with its own
    /// lamp (the Cornell box) and a built-in scene get none.
    #[test]
    fn a_bare_mesh_view_keeps_the_ground_it_was_given() {
        let dir = tempfile::tempdir().expect("temp dir");
        let obj = dir.path().join("tri.obj");
        std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 1\nf 1 2 3\n").expect("obj");
        let bare = SceneSource {
            scene: None,
            mesh: Some(obj.clone()),
        };
        assert!(added_ground(&bare));
        let cornell = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../assets/rooms/cornell-box.obj");
        assert!(!added_ground(&SceneSource {
            scene: None,
            mesh: Some(cornell),
        }));
        assert!(!added_ground(&SceneSource {
            scene: Some("builtin:plate".into()),
            mesh: None,
        }));
        let scene = bspvt_proto::Scene::from_mesh_path(&obj).expect("scene");
        let light = Light::from_scene(&scene.lights[0]);
        let out = dir.path().join("tri.view.json");
        let (file, out) = view_file(
            &bare,
            Some(&out),
            &scene.lights,
            added_ground(&bare),
            scene.camera.clone(),
            Some((0, &light)),
        )
        .expect("view");
        assert!(file.ground_plane);
        write_view(&file, &out).expect("write");
        let again = bspvt_proto::Scene::load(&out).expect("the saved view loads");
        assert_eq!(
            again.mesh.triangles.len(),
            scene.mesh.triangles.len(),
            "the ground is there again"
        );
    }
}
