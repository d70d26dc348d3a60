//! The form a local scene is submitted as (`POST /v1/scenes`, multipart): the scene JSON, its
//! one mesh file, the mesh's other files — an OBJ's material libraries and textures, a
//! `.gltf`'s external buffers and images — and its lights' texture files, which the service
//! reads only from the upload.
//! Which other files a mesh needs is learnt by loading it here, with the same importer the
//! service runs, so exactly the files it reads are sent.

use std::path::Path;

use anyhow::{Context, Result, bail};
use bspvt_proto::hash::Fnv1a;
use bspvt_proto::scene::{MeshRef, SceneFile};

/// One field of the form.
pub(crate) struct Part {
    /// `mesh`, `file` or `scene`.
    pub(crate) name: &'static str,
    /// The file name sent with a file field.
    pub(crate) file_name: Option<String>,
    pub(crate) data: Vec<u8>,
}

/// A submission's fields, in order.
pub(crate) struct Form {
    pub(crate) parts: Vec<Part>,
}

impl Form {
    /// The form of a scene file, `builtin:NAME`, or a bare mesh.
    pub(crate) fn local(scene: Option<&str>, mesh: Option<&Path>) -> Result<Form> {
        let mut parts = Vec::new();
        match (scene, mesh) {
            (Some(s), None) => {
                let file = match s.strip_prefix("builtin:") {
                    Some(name) => super::remote::builtin_scene_file(name)?,
                    None => {
                        let path = Path::new(s);
                        let text = std::fs::read_to_string(path)
                            .with_context(|| format!("cannot read {s}"))?;
                        let mut file: SceneFile = serde_json::from_str(&text)
                            .with_context(|| format!("{s} is not a valid scene file"))?;
                        let files: Vec<&mut MeshRef> = file
                            .meshes
                            .iter_mut()
                            .filter(|m| !m.path.starts_with("builtin:"))
                            .collect();
                        if files.len() > 1 {
                            bail!(
                                "{s} names {} mesh files; the service takes one upload per scene",
                                files.len()
                            );
                        }
                        let dir = path.parent().unwrap_or(Path::new("."));
                        if let Some(m) = files.into_iter().next() {
                            m.path = push_mesh(&mut parts, &dir.join(&m.path))?;
                        }
                        // Light textures go by their file name, as the service matches them.
                        for t in file.lights.iter().filter_map(|l| l.texture.as_deref()) {
                            let name = Path::new(t)
                                .file_name()
                                .and_then(|n| n.to_str())
                                .with_context(|| format!("light texture {t:?} has no file name"))?
                                .to_string();
                            check_name(&name)?;
                            let data = std::fs::read(dir.join(t))
                                .with_context(|| format!("cannot read light texture {t}"))?;
                            match parts.iter().find(|p| p.file_name.as_deref() == Some(&name)) {
                                Some(p) if p.data == data => {}
                                Some(_) => bail!(
                                    "{s}: two different files are named {name:?} (light \
                                     textures and the mesh's files go up by file name)"
                                ),
                                None => parts.push(Part {
                                    name: "file",
                                    file_name: Some(name),
                                    data,
                                }),
                            }
                        }
                        file
                    }
                };
                parts.push(Part {
                    name: "scene",
                    file_name: None,
                    data: serde_json::to_vec(&file)?,
                });
            }
            (None, Some(m)) => {
                push_mesh(&mut parts, m)?;
            }
            _ => bail!("give a scene (file or builtin:NAME) or --mesh PATH"),
        }
        Ok(Form { parts })
    }

    /// What the form holds, as a key: equal forms are the same submission.
    pub(crate) fn content_hash(&self, h: &mut Fnv1a) {
        for p in &self.parts {
            for bytes in [
                p.name.as_bytes(),
                p.file_name.as_deref().unwrap_or("").as_bytes(),
            ] {
                h.write(&(bytes.len() as u64).to_le_bytes());
                h.write(bytes);
            }
            h.write(&(p.data.len() as u64).to_le_bytes());
            h.write(&p.data);
        }
    }

    /// The multipart body with `boundary`.
    pub(crate) fn body(&self, boundary: &str) -> Vec<u8> {
        let mut body = Vec::new();
        for p in &self.parts {
            body.extend_from_slice(format!("--{boundary}\r\n").as_bytes());
            let disposition = match &p.file_name {
                Some(f) => format!(
                    "Content-Disposition: form-data; name=\"{}\"; filename=\"{f}\"\r\nContent-Type: application/octet-stream\r\n\r\n",
                    p.name
                ),
                None => format!(
                    "Content-Disposition: form-data; name=\"{}\"\r\n\r\n",
                    p.name
                ),
            };
            body.extend_from_slice(disposition.as_bytes());
            body.extend_from_slice(&p.data);
            body.extend_from_slice(b"\r\n");
        }
        body.extend_from_slice(format!("--{boundary}--\r\n").as_bytes());
        body
    }
}

/// Adds a mesh file and the other files it reads; returns the name it is uploaded under.
fn push_mesh(parts: &mut Vec<Part>, path: &Path) -> Result<String> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .with_context(|| format!("{} has no file name", path.display()))?
        .to_string();
    check_name(&name)?;
    let data = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    parts.push(Part {
        name: "mesh",
        file_name: Some(name.clone()),
        data,
    });
    // PLY has no other files; the others are loaded here to learn which they read.
    let lower = name.to_ascii_lowercase();
    if [".obj", ".gltf", ".glb"].iter().any(|e| lower.ends_with(e)) {
        let asset = bspvt_proto::import::load_asset(path)
            .with_context(|| format!("cannot load {}", path.display()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        for file in asset.files {
            check_name(&file)?;
            let data = std::fs::read(dir.join(&file))
                .with_context(|| format!("cannot read {file}, which {name} refers to"))?;
            parts.push(Part {
                name: "file",
                file_name: Some(file),
                data,
            });
        }
    }
    Ok(name)
}

/// A file name the form can carry as it is (a quote or a line break would end the header).
fn check_name(name: &str) -> Result<()> {
    if name.contains(['"', '\r', '\n']) {
        bail!("cannot upload a file named {name:?}: rename it without quotes or line breaks");
    }
    Ok(())
}
