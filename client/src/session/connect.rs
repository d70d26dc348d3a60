//! The whole client start-up shared by `view`, `animate` and `demo`: resolve the source, get
//! the scene (cached), build the session, start the fetcher with the camera's vertices first.

use std::path::PathBuf;

use anyhow::Result;
use bspvt_proto::Scene;

use crate::session::Session;
use crate::stream::cache::Cache;
use crate::stream::fetch::{self, FetchOptions};
use crate::stream::source::{self, Embedded, Places, Served, Source};
use crate::stream::trees::StreamedTrees;

/// Where to find the scene and where to keep things (`bspvt view`'s and `animate`'s source
/// options).
#[derive(Clone, Debug)]
pub struct ConnectOptions {
    /// `http://HOST:PORT/v1/scenes/ID`, a scene id (with `server`), a scene file or
    /// `builtin:NAME`.
    pub source: Option<String>,
    /// A bare mesh (.glb/.gltf/.obj/.ply) with the default scene around it.
    pub mesh: Option<PathBuf>,
    /// Service for scene ids and local scenes (default for local scenes: an embedded service).
    pub server: Option<String>,
    /// The service's API key.
    pub api_key: Option<String>,
    /// Data folder of the embedded service.
    pub data_dir: PathBuf,
    /// Where received trees are cached (by scene id); `None`: no cache.
    pub cache_dir: Option<PathBuf>,
    /// The embedded service for local scenes without `server`.
    pub embedded: Option<&'static dyn Embedded>,
}

impl std::fmt::Debug for dyn Embedded {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Embedded")
    }
}

/// A served scene and its bytes.
pub struct Connected {
    /// The service and the scene id.
    pub served: Served,
    /// The scene as the service baked it.
    pub scene: Scene,
    /// Scene bytes fetched (0 when it came from the cache).
    pub scene_bytes_fetched: u64,
}

/// Resolves the source and fetches the scene.
pub fn connect(a: &ConnectOptions) -> Result<Connected> {
    let src = Source::parse(a.source.as_deref(), a.mesh.as_deref())?;
    let served = source::open(
        &src,
        &Places {
            server: a.server.clone(),
            api_key: a.api_key.clone(),
            data_dir: a.data_dir.clone(),
            embedded: a.embedded,
        },
    )?;
    let cache = a
        .cache_dir
        .as_ref()
        .map(|d| Cache::new(d, &served.id))
        .transpose()?;
    let (mut scene, scene_bytes_fetched) = served.remote.scene(&served.id, cache.as_ref())?;
    // What the service's importer added or left out (a default light and ground, a material
    // library not uploaded, …) is in the status, not in the stored scene: the session says it
    // as a local load does.
    if let Ok(status) = served.remote.status(&served.id) {
        scene.warnings = status.warnings;
    }
    // The service keeps what the bake needs; the sky of a local scene file is the client's.
    if scene.environment.is_none() {
        scene.environment = local_environment(&src);
    }
    Ok(Connected {
        served,
        scene,
        scene_bytes_fetched,
    })
}

/// The `environment` of a local scene file, its path resolved against the file's folder.
fn local_environment(src: &Source) -> Option<bspvt_proto::scene::Environment> {
    let Source::Local {
        scene: Some(path), ..
    } = src
    else {
        return None;
    };
    let path = std::path::Path::new(path);
    let text = std::fs::read_to_string(path).ok()?;
    let file: bspvt_proto::scene::SceneFile = serde_json::from_str(&text).ok()?;
    let mut env = file.environment?;
    env.path = path
        .parent()
        .unwrap_or(std::path::Path::new("."))
        .join(&env.path)
        .to_string_lossy()
        .into_owned();
    Some(env)
}

/// The longest a new session waits for the disk cache before its first frame.
const CACHE_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

impl Connected {
    /// A session on the scene, its trees streaming in (camera's vertices first).
    pub fn session(&self, a: &ConnectOptions, width: u32, height: u32) -> Result<Session<'_>> {
        let mut session = Session::new(
            &self.scene,
            width,
            height,
            StreamedTrees::default(),
            None,
            None,
        )?;
        let cache = a
            .cache_dir
            .as_ref()
            .map(|d| Cache::new(d, &self.served.id))
            .transpose()?;
        let (rx, counters, _thread) = fetch::spawn(
            self.served.remote.clone(),
            self.served.id.clone(),
            FetchOptions {
                priority: session.visible_vertices().to_vec(),
                cache,
                ..FetchOptions::default()
            },
        );
        session.attach(rx, counters.clone());
        // What the disk cache holds is drawn from the first frame: wait (bounded) for the
        // fetcher to have sent it, then take it, so a scene whose trees are all cached opens
        // shadowed.
        let t0 = std::time::Instant::now();
        while !counters
            .cache_read
            .load(std::sync::atomic::Ordering::Acquire)
            && !counters.finished.load(std::sync::atomic::Ordering::Relaxed)
            && t0.elapsed() < CACHE_WAIT
        {
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        session.poll();
        if let Some(c) = &a.cache_dir {
            session.sky_cache = c.join("bakes");
        }
        Ok(session)
    }
}
