//! What a user names — a scene URL, a scene id, a scene file or `builtin:NAME`, a bare mesh —
//! turned into a scene on a service. Local scenes go to an embedded service (in this process,
//! on loopback, data in a local folder) unless `--server` names one; a local scene submitted
//! before (same content) is not baked again: its id is remembered next to the data.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use bspvt_proto::api::JobState;
use bspvt_proto::hash::Fnv1a;

use super::form::Form;
use super::remote::Remote;

/// What the user asked to view.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Source {
    /// `http://HOST:PORT/v1/scenes/ID`.
    Url { base: String, id: String },
    /// A scene id on `--server`.
    Id(String),
    /// A scene file, `builtin:NAME`, or a bare mesh: submitted, then streamed.
    Local {
        scene: Option<String>,
        mesh: Option<PathBuf>,
    },
}

impl Source {
    pub(crate) fn parse(arg: Option<&str>, mesh: Option<&Path>) -> Result<Source> {
        match (arg, mesh) {
            (Some(_), Some(_)) => bail!("give either a scene (URL, id, file) or --mesh, not both"),
            (None, Some(m)) => Ok(Source::Local {
                scene: None,
                mesh: Some(m.to_path_buf()),
            }),
            (None, None) => bail!(
                "nothing to view: give URL, SCENE_ID, SCENE.json, builtin:NAME or --mesh PATH"
            ),
            (Some(a), None) => {
                if a.starts_with("http://") || a.starts_with("https://") {
                    let (base, id) = a
                        .trim_end_matches('/')
                        .split_once("/v1/scenes/")
                        .with_context(|| format!("{a} is not a scene URL (…/v1/scenes/ID)"))?;
                    let id = id.split('/').next().unwrap_or_default();
                    if !is_id(id) {
                        bail!("{a}: {id:?} is not a scene id");
                    }
                    Ok(Source::Url {
                        base: base.to_string(),
                        id: id.to_string(),
                    })
                } else if is_id(a) && !Path::new(a).exists() {
                    Ok(Source::Id(a.to_string()))
                } else {
                    Ok(Source::Local {
                        scene: Some(a.to_string()),
                        mesh: None,
                    })
                }
            }
        }
    }
}

/// A scene id: 32 hex digits.
fn is_id(s: &str) -> bool {
    s.len() == 32 && s.bytes().all(|b| b.is_ascii_hexdigit())
}

/// A baking service this process can run itself, on loopback (the command line provides one
/// with its `service` feature; this library never depends on the service's crate).
pub trait Embedded: Send + Sync {
    /// Starts a service keeping its data in `data_dir`, listening on a free loopback port.
    fn start(&self, data_dir: &Path) -> Result<EmbeddedService>;
}

/// A running embedded service: its address, and whatever keeps it running (dropping this
/// value stops it).
pub struct EmbeddedService {
    /// Where it listens (127.0.0.1, a free port).
    pub addr: SocketAddr,
    /// Stops the service when dropped.
    pub guard: Box<dyn std::any::Any + Send>,
}

/// A scene on a service, and the embedded service when this process runs it.
pub struct Served {
    /// The service.
    pub remote: Remote,
    /// The scene's id on it.
    pub id: String,
    /// The embedded service, when this process runs it (stops when dropped).
    pub embedded: Option<EmbeddedService>,
    /// Whether this call submitted the scene (false: already on the service).
    pub submitted: bool,
}

/// Where the embedded service and the client cache live.
pub(crate) struct Places {
    /// `--server URL` for ids and local scenes (local scenes otherwise go to an embedded one).
    pub(crate) server: Option<String>,
    pub(crate) api_key: Option<String>,
    /// Data folder of the embedded service.
    pub(crate) data_dir: PathBuf,
    /// The embedded service for local scenes when no `server` is given (`None`: this build
    /// has none, and local scenes need `--server`).
    pub(crate) embedded: Option<&'static dyn Embedded>,
}

/// Resolves `src` to a scene on a service, submitting local scenes.
pub(crate) fn open(src: &Source, places: &Places) -> Result<Served> {
    match src {
        Source::Url { base, id } => Ok(Served {
            remote: Remote::new(base, places.api_key.clone()),
            id: id.clone(),
            embedded: None,
            submitted: false,
        }),
        Source::Id(id) => {
            let base = places.server.as_deref().with_context(|| {
                format!("scene id {id} given without --server URL (or BSPVT_SERVER)")
            })?;
            Ok(Served {
                remote: Remote::new(base, places.api_key.clone()),
                id: id.clone(),
                embedded: None,
                submitted: false,
            })
        }
        Source::Local { scene, mesh } => {
            let (remote, embedded) = match &places.server {
                Some(base) => (Remote::new(base, places.api_key.clone()), None),
                None => {
                    let Some(starter) = places.embedded else {
                        bail!(
                            "this build has no embedded service: give --server URL (or \
                             BSPVT_SERVER) to bake a local scene"
                        );
                    };
                    let bg = starter.start(&places.data_dir).with_context(|| {
                        format!(
                            "cannot start the embedded service in {}",
                            places.data_dir.display()
                        )
                    })?;
                    (Remote::new(&format!("http://{}", bg.addr), None), Some(bg))
                }
            };
            let form = Form::local(scene.as_deref(), mesh.as_deref())?;
            let key = content_key(&form);
            let known_path = places.data_dir.join("client-submissions.json");
            let mut known: BTreeMap<String, BTreeMap<String, String>> = std::fs::read(&known_path)
                .ok()
                .and_then(|b| serde_json::from_slice(&b).ok())
                .unwrap_or_default();
            let server_key = remote.base().to_string();
            let server_key = if embedded.is_some() {
                "embedded".to_string()
            } else {
                server_key
            };
            if let Some(id) = known.get(&server_key).and_then(|m| m.get(&key))
                && let Ok(s) = remote.status(id)
                && !matches!(s.state, JobState::Failed | JobState::Cancelled)
            {
                return Ok(Served {
                    remote,
                    id: id.clone(),
                    embedded,
                    submitted: false,
                });
            }
            let id = remote.submit_form(&form)?;
            known.entry(server_key).or_default().insert(key, id.clone());
            if let Some(parent) = known_path.parent() {
                std::fs::create_dir_all(parent)?;
            }
            std::fs::write(&known_path, serde_json::to_vec_pretty(&known)?)
                .with_context(|| format!("cannot write {}", known_path.display()))?;
            Ok(Served {
                remote,
                id,
                embedded,
                submitted: true,
            })
        }
    }
}

/// Identity of a local scene's content: the bake's algorithm version and the form it is
/// submitted as (scene JSON, mesh file and the mesh's other files, bytes and names).
fn content_key(form: &Form) -> String {
    let mut h = Fnv1a::default();
    // A scene submitted by an older bake is submitted again (new trees) after an upgrade.
    h.write(&bspvt_bake::ALGORITHM_VERSION.to_le_bytes());
    form.content_hash(&mut h);
    format!("{:016x}", h.finish())
}
