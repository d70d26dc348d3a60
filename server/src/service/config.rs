//! Service configuration: command-line flags, `BSPVT_*` environment variables and an optional
//! TOML file, merged in that order of precedence over the built-in defaults.
//!
//! Guarantees: every limit the service enforces is a field of [`Config`], has a default that
//! is safe on a small machine, and is checked for sanity (`Config::resolve` refuses zero
//! workers, zero limits and an unparsable address before anything is opened).

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::Deserialize;

/// `bspvt-server serve` flags. Each flag can also come from the environment variable named
/// beside it, or from the `--config` file (same names, snake_case); flags win over the
/// environment, which wins over the file.
#[derive(clap::Args, Debug, Default, Clone)]
pub struct ServeArgs {
    /// TOML configuration file (keys as the flags below, snake_case).
    #[arg(long, env = "BSPVT_CONFIG")]
    pub config: Option<PathBuf>,
    /// Directory holding everything the service stores (database, scenes, chunks): the short
    /// form of `--database DIR/bspvt.sqlite --store DIR`.
    #[arg(long, env = "BSPVT_DATA_DIR")]
    pub data_dir: Option<PathBuf>,
    /// The database: a SQLite file (the embedded default), or `postgres://USER@HOST/DB` for
    /// the distributed shape (any number of API instances and `bspvt-server worker`s).
    #[arg(long, env = "BSPVT_DATABASE", hide_env_values = true)]
    pub database: Option<String>,
    /// Where scenes and chunks are stored: a folder, or `s3://BUCKET/PREFIX` (credentials,
    /// region and endpoint from AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY, AWS_REGION,
    /// AWS_ENDPOINT_URL, AWS_ALLOW_HTTP; an s3:// store needs a postgres:// database).
    #[arg(long, env = "BSPVT_STORE")]
    pub store: Option<String>,
    /// Seconds a worker's chunk lease lasts without a heartbeat (distributed shape).
    #[arg(long, env = "BSPVT_LEASE_S")]
    pub lease_s: Option<u64>,
    /// Address to listen on (`HOST:PORT`; port 0 picks a free port, printed on stdout).
    #[arg(long, env = "BSPVT_ADDR")]
    pub addr: Option<String>,
    /// When set, `Authorization: Bearer KEY` is required for writes (POST, DELETE).
    #[arg(long, env = "BSPVT_API_KEY", hide_env_values = true)]
    pub api_key: Option<String>,
    /// …or read from this file (its first line, whitespace trimmed), so that the key is not
    /// on the command line where `ps` shows it.
    #[arg(long, env = "BSPVT_API_KEY_FILE", conflicts_with = "api_key")]
    pub api_key_file: Option<PathBuf>,
    /// Bake workers: chunks baked at the same time, taken round-robin across scenes.
    #[arg(long, env = "BSPVT_WORKERS")]
    pub workers: Option<usize>,
    /// Threads of the shared bake pool (0 = one per core).
    #[arg(long, env = "BSPVT_THREADS")]
    pub threads: Option<usize>,
    /// Added to the bake threads' nice value (Linux; 0 = the process's priority): a viewer or
    /// the API on the same machine goes first, an idle machine bakes as fast [default: 10].
    #[arg(long, env = "BSPVT_BAKE_NICE")]
    pub bake_nice: Option<i32>,
    /// Where the workers cast rays: `cpu` (default) or `gpu` (the fit stays on the pool; the
    /// service does not start without a GPU adapter). Same bakes, docs/bake.md.
    #[arg(long, env = "BSPVT_BAKE_BACKEND")]
    pub bake_backend: Option<String>,
    /// Largest request body in bytes (uploads).
    #[arg(long, env = "BSPVT_MAX_BODY_BYTES")]
    pub max_body_bytes: Option<u64>,
    /// Largest mesh file in bytes, after zstd decompression.
    #[arg(long, env = "BSPVT_MAX_MESH_BYTES")]
    pub max_mesh_bytes: Option<u64>,
    /// Most vertices of a submitted scene.
    #[arg(long, env = "BSPVT_MAX_MESH_VERTICES")]
    pub max_mesh_vertices: Option<u64>,
    /// Most triangles of a submitted mesh.
    #[arg(long, env = "BSPVT_MAX_MESH_TRIANGLES")]
    pub max_mesh_triangles: Option<u64>,
    /// Largest cube-map face resolution a submitted scene may ask for.
    #[arg(long, env = "BSPVT_MAX_FACE_RES")]
    pub max_face_res: Option<u32>,
    /// Largest supersampling a submitted scene may ask for.
    #[arg(long, env = "BSPVT_MAX_SUPERSAMPLING")]
    pub max_supersampling: Option<u32>,
    /// Most scenes queued or baking; further submissions get 429.
    #[arg(long, env = "BSPVT_MAX_QUEUED_SCENES")]
    pub max_queued_scenes: Option<usize>,
    /// Most scenes baking at once (the rest wait in submission order).
    #[arg(long, env = "BSPVT_MAX_ACTIVE_SCENES")]
    pub max_active_scenes: Option<usize>,
    /// Most requests being handled at once (a stream counts until its headers are sent;
    /// open streams are limited by max_streams).
    #[arg(long, env = "BSPVT_MAX_CONCURRENT_REQUESTS")]
    pub max_concurrent_requests: Option<usize>,
    /// Most open tree and event streams.
    #[arg(long, env = "BSPVT_MAX_STREAMS")]
    pub max_streams: Option<usize>,
    /// Most uploads being read and parsed at once.
    #[arg(long, env = "BSPVT_MAX_UPLOADS")]
    pub max_uploads: Option<usize>,
    /// Uploads being read from one remote address at once.
    #[arg(long, env = "BSPVT_MAX_UPLOADS_PER_CLIENT")]
    pub max_uploads_per_client: Option<u32>,
    /// Open tree and event streams from one remote address at once.
    #[arg(long, env = "BSPVT_MAX_STREAMS_PER_CLIENT")]
    pub max_streams_per_client: Option<u32>,
    /// Seconds an event stream must have sent no status before it may be shed, when every
    /// stream slot is taken, for a new stream.
    #[arg(long, env = "BSPVT_SHED_IDLE_STREAMS_AFTER_S")]
    pub shed_idle_streams_after_s: Option<u64>,
    /// Seconds an upload may send nothing before it is cut off (408), between two reads.
    #[arg(long, env = "BSPVT_BODY_READ_TIMEOUT_S")]
    pub body_read_timeout_s: Option<u64>,
    /// Least average rate of an upload, bytes per second, once `body_read_timeout_s` has
    /// passed (Apache's `RequestReadTimeout … MinRate`); 0 turns the check off.
    #[arg(long, env = "BSPVT_MIN_UPLOAD_RATE")]
    pub min_upload_rate: Option<u64>,
    /// Seconds a non-streaming request (including an upload) may take.
    #[arg(long, env = "BSPVT_REQUEST_TIMEOUT_S")]
    pub request_timeout_s: Option<u64>,
    /// Memory the service may plan for, in MiB: uploads being parsed and scenes being baked
    /// reserve their estimated peak from it (default: half the machine's memory).
    #[arg(long, env = "BSPVT_MEMORY_BUDGET_MIB")]
    pub memory_budget_mib: Option<u64>,
    /// Seconds SIGTERM/SIGINT waits for open requests and for chunks being baked before the
    /// process exits (unfinished chunks are baked again at the next start).
    #[arg(long, env = "BSPVT_SHUTDOWN_TIMEOUT_S")]
    pub shutdown_timeout_s: Option<u64>,
    /// Most open client connections; further connections are closed at once.
    #[arg(long, env = "BSPVT_MAX_CONNECTIONS")]
    pub max_connections: Option<usize>,
    /// Seconds a client may take to send a request's headers (slow clients are cut off).
    #[arg(long, env = "BSPVT_HEADER_READ_TIMEOUT_S")]
    pub header_read_timeout_s: Option<u64>,
    /// Log format on stderr: `text` or `json`.
    #[arg(long, env = "BSPVT_LOG_FORMAT")]
    pub log_format: Option<String>,
    /// Origins allowed to call the API from a browser (CORS), comma-separated, e.g.
    /// `https://app.example,http://localhost:5173`; `*` allows any origin. Off when unset.
    #[arg(long, env = "BSPVT_CORS_ORIGINS", value_delimiter = ',')]
    pub cors_origins: Option<Vec<String>>,
}

/// The same settings as a TOML file.
#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
struct FileConfig {
    data_dir: Option<PathBuf>,
    database: Option<String>,
    store: Option<String>,
    lease_s: Option<u64>,
    addr: Option<String>,
    api_key: Option<String>,
    api_key_file: Option<PathBuf>,
    workers: Option<usize>,
    threads: Option<usize>,
    bake_nice: Option<i32>,
    bake_backend: Option<String>,
    max_body_bytes: Option<u64>,
    max_mesh_bytes: Option<u64>,
    max_mesh_vertices: Option<u64>,
    max_mesh_triangles: Option<u64>,
    max_face_res: Option<u32>,
    max_supersampling: Option<u32>,
    max_queued_scenes: Option<usize>,
    max_active_scenes: Option<usize>,
    max_concurrent_requests: Option<usize>,
    max_streams: Option<usize>,
    max_uploads: Option<usize>,
    max_uploads_per_client: Option<u32>,
    max_streams_per_client: Option<u32>,
    body_read_timeout_s: Option<u64>,
    shed_idle_streams_after_s: Option<u64>,
    min_upload_rate: Option<u64>,
    request_timeout_s: Option<u64>,
    memory_budget_mib: Option<u64>,
    shutdown_timeout_s: Option<u64>,
    max_connections: Option<usize>,
    header_read_timeout_s: Option<u64>,
    log_format: Option<String>,
    cors_origins: Option<Vec<String>>,
}

/// Log output format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogFormat {
    /// Human-readable lines.
    Text,
    /// One JSON object per line.
    Json,
}

/// The resolved configuration of a running service.
#[derive(Clone, Debug)]
pub struct Config {
    /// Directory holding everything the service stores (database, scenes, chunks).
    pub data_dir: PathBuf,
    /// The database, when not `data_dir`'s: a SQLite file or a `postgres://` URL.
    pub database: Option<String>,
    /// The store, when not `data_dir`: a folder or `s3://BUCKET/PREFIX`.
    pub store: Option<String>,
    /// Seconds a worker's chunk lease lasts without a heartbeat (distributed shape).
    pub lease_s: u64,
    /// Different workers a chunk may fail on before its scene fails (distributed shape).
    pub max_chunk_failures: u32,
    /// Address to listen on (port 0 picks a free port).
    pub addr: SocketAddr,
    /// When set, `Authorization: Bearer KEY` is required for writes.
    pub api_key: Option<String>,
    /// Bake workers: chunks baked at the same time.
    pub workers: usize,
    /// Threads of the shared bake pool (0 = one per core).
    pub threads: usize,
    /// Added to the bake pool threads' nice value (service/pool.rs).
    pub bake_nice: i32,
    /// Where the workers cast rays.
    pub bake_backend: bspvt_bake::Backend,
    /// Largest request body in bytes.
    pub max_body_bytes: u64,
    /// Largest mesh file in bytes, after zstd decompression.
    pub max_mesh_bytes: u64,
    /// Most vertices of a submitted scene.
    pub max_mesh_vertices: u64,
    /// Most triangles of a submitted mesh.
    pub max_mesh_triangles: u64,
    /// Largest cube-map face resolution a submitted scene may ask for.
    pub max_face_res: u32,
    /// Largest supersampling a submitted scene may ask for.
    pub max_supersampling: u32,
    /// Most scenes queued or baking; further submissions get 429.
    pub max_queued_scenes: usize,
    /// Most scenes baking at once.
    pub max_active_scenes: usize,
    /// Most requests being handled at once.
    pub max_concurrent_requests: usize,
    /// Most open tree and event streams.
    pub max_streams: usize,
    /// Most uploads being read and parsed at once.
    pub max_uploads: usize,
    /// Uploads being read from one remote address at once.
    pub max_uploads_per_client: u32,
    /// Open streams from one remote address at once.
    pub max_streams_per_client: u32,
    /// Seconds an event stream must have sent no status before it may be shed for a new
    /// stream when every stream slot is taken.
    pub shed_idle_streams_after_s: u64,
    /// Seconds an upload may send nothing (between two reads) before 408.
    pub body_read_timeout_s: u64,
    /// Least average upload rate in bytes/s after `body_read_timeout_s` (0: no check).
    pub min_upload_rate: u64,
    /// Seconds a non-streaming request may take.
    pub request_timeout_s: u64,
    /// Memory for uploads being parsed and scenes being baked, in MiB.
    pub memory_budget_mib: u64,
    /// Seconds a shutdown waits for requests and chunks in progress.
    pub shutdown_timeout_s: u64,
    /// Most open client connections.
    pub max_connections: usize,
    /// Seconds a client may take to send a request's headers.
    pub header_read_timeout_s: u64,
    /// Log format on stderr.
    pub log_format: LogFormat,
    /// Browser origins allowed by CORS (`scheme://host[:port]`, or `*` for any); empty: no
    /// CORS headers are sent and browsers on other origins cannot read the API.
    pub cors_origins: Vec<String>,
}

impl Config {
    /// Defaults for everything but the data directory.
    pub fn with_data_dir(data_dir: impl Into<PathBuf>) -> Config {
        Config {
            data_dir: data_dir.into(),
            database: None,
            store: None,
            lease_s: 30,
            max_chunk_failures: 3,
            addr: SocketAddr::from(([127, 0, 0, 1], 8080)),
            api_key: None,
            workers: 2,
            threads: 0,
            bake_nice: super::pool::DEFAULT_NICE,
            bake_backend: bspvt_bake::Backend::Cpu,
            max_body_bytes: 256 << 20,
            max_mesh_bytes: 256 << 20,
            max_mesh_vertices: 5_000_000,
            max_mesh_triangles: 10_000_000,
            max_face_res: 256,
            max_supersampling: 4,
            max_queued_scenes: 64,
            max_active_scenes: 4,
            max_concurrent_requests: 1024,
            max_streams: 512,
            max_uploads: 4,
            max_uploads_per_client: 2,
            max_streams_per_client: 64,
            body_read_timeout_s: 60,
            shed_idle_streams_after_s: 30,
            min_upload_rate: 500,
            request_timeout_s: 300,
            memory_budget_mib: super::memory::default_budget_mib(),
            shutdown_timeout_s: 30,
            max_connections: 4096,
            header_read_timeout_s: 30,
            log_format: LogFormat::Text,
            cors_origins: Vec::new(),
        }
    }

    /// Merges flags/environment (already merged by clap), the `--config` file and defaults,
    /// then checks the result.
    pub(crate) fn resolve(args: &ServeArgs) -> Result<Config> {
        let file = match &args.config {
            Some(p) => read_file(p)?,
            None => FileConfig::default(),
        };
        let database = args.database.clone().or(file.database);
        let store = args.store.clone().or(file.store);
        let data_dir = match args.data_dir.clone().or(file.data_dir) {
            Some(d) => d,
            None if database.is_some() && store.is_some() => PathBuf::new(),
            None => bail!(
                "no data directory: give --data-dir, BSPVT_DATA_DIR or data_dir in the config \
                 file (or both --database and --store)"
            ),
        };
        let mut c = Config::with_data_dir(data_dir);
        c.database = database;
        c.store = store;
        if let Some(l) = args.lease_s.or(file.lease_s) {
            c.lease_s = l;
        }
        if let Some(a) = args.addr.clone().or(file.addr) {
            c.addr = a
                .parse()
                .with_context(|| format!("address {a:?} is not HOST:PORT (e.g. 0.0.0.0:8080)"))?;
        }
        let key_file = args.api_key_file.clone().or(file.api_key_file);
        c.api_key = match (args.api_key.clone().or(file.api_key), key_file) {
            (Some(_), Some(_)) => bail!("give the API key or a file that holds it, not both"),
            (key, None) => key,
            (None, Some(p)) => Some(read_key_file(&p)?),
        };
        macro_rules! take {
            ($($f:ident),*) => {$(
                if let Some(v) = args.$f.or(file.$f) {
                    c.$f = v;
                }
            )*};
        }
        take!(
            workers,
            threads,
            bake_nice,
            max_body_bytes,
            max_mesh_bytes,
            max_mesh_vertices,
            max_mesh_triangles,
            max_face_res,
            max_supersampling,
            max_queued_scenes,
            max_active_scenes,
            max_concurrent_requests,
            max_streams,
            max_uploads,
            max_uploads_per_client,
            max_streams_per_client,
            body_read_timeout_s,
            shed_idle_streams_after_s,
            min_upload_rate,
            request_timeout_s,
            memory_budget_mib,
            shutdown_timeout_s,
            max_connections,
            header_read_timeout_s
        );
        if let Some(b) = args.bake_backend.clone().or(file.bake_backend) {
            c.bake_backend = match b.as_str() {
                "cpu" => bspvt_bake::Backend::Cpu,
                "gpu" => bspvt_bake::Backend::Gpu,
                _ => bail!("bake backend {b:?} is neither `cpu` nor `gpu`"),
            };
        }
        if let Some(f) = args.log_format.clone().or(file.log_format) {
            c.log_format = match f.as_str() {
                "text" => LogFormat::Text,
                "json" => LogFormat::Json,
                _ => bail!("log format {f:?} is neither `text` nor `json`"),
            };
        }
        if let Some(o) = args.cors_origins.clone().or(file.cors_origins) {
            c.cors_origins = o
                .into_iter()
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty())
                .collect();
        }
        c.check()?;
        Ok(c)
    }

    /// Refuses settings the service cannot run with.
    pub fn check(&mut self) -> Result<()> {
        if matches!(&self.api_key, Some(k) if k.is_empty()) {
            bail!("the API key is empty");
        }
        if self.distributed() {
            if self.store.is_none() {
                bail!(
                    "a postgres:// database needs --store (s3://BUCKET/PREFIX, or a folder every \
                     machine shares)"
                );
            }
            if !(2..=3600).contains(&self.lease_s) {
                bail!("lease_s = {} is outside 2..=3600", self.lease_s);
            }
        } else if self
            .store
            .as_deref()
            .is_some_and(|s| s.starts_with("s3://"))
        {
            bail!(
                "an s3:// store needs a postgres:// database (the embedded SQLite database is \
                 one machine's; give --database postgres://…)"
            );
        }
        // `--workers 0`: an API-only instance, for the distributed shape only.
        let min_workers = u64::from(!self.distributed());
        if (self.workers as u64) < min_workers {
            bail!("workers must be at least 1 (0 only with a postgres:// database: API only)");
        }
        let positive = [
            ("max_body_bytes", self.max_body_bytes),
            ("max_mesh_bytes", self.max_mesh_bytes),
            ("max_mesh_vertices", self.max_mesh_vertices),
            ("max_mesh_triangles", self.max_mesh_triangles),
            ("max_queued_scenes", self.max_queued_scenes as u64),
            (
                "max_concurrent_requests",
                self.max_concurrent_requests as u64,
            ),
            ("max_streams", self.max_streams as u64),
            ("max_uploads", self.max_uploads as u64),
            (
                "max_uploads_per_client",
                u64::from(self.max_uploads_per_client),
            ),
            (
                "max_streams_per_client",
                u64::from(self.max_streams_per_client),
            ),
            ("body_read_timeout_s", self.body_read_timeout_s),
            ("request_timeout_s", self.request_timeout_s),
            ("memory_budget_mib", self.memory_budget_mib),
            ("shutdown_timeout_s", self.shutdown_timeout_s),
            ("max_connections", self.max_connections as u64),
            ("header_read_timeout_s", self.header_read_timeout_s),
        ];
        for (name, v) in positive {
            if v == 0 {
                bail!("{name} must be at least 1");
            }
        }
        if self.workers > 256 {
            bail!("workers = {} is more than 256", self.workers);
        }
        if !(4..=bspvt_proto::BakeSettings::MAX_FACE_RES).contains(&self.max_face_res) {
            bail!(
                "max_face_res = {} is outside 4..={}",
                self.max_face_res,
                bspvt_proto::BakeSettings::MAX_FACE_RES
            );
        }
        if !(1..=bspvt_proto::BakeSettings::MAX_SUPERSAMPLING).contains(&self.max_supersampling) {
            bail!(
                "max_supersampling = {} is outside 1..={}",
                self.max_supersampling,
                bspvt_proto::BakeSettings::MAX_SUPERSAMPLING
            );
        }
        for o in &self.cors_origins {
            check_origin(o)?;
        }
        if self.cors_origins.len() > 1 && self.cors_origins.iter().any(|o| o == "*") {
            bail!("cors_origins: `*` allows every origin; give it alone, not with a list");
        }
        // With fewer active scenes than workers a worker could idle while scenes wait.
        self.max_active_scenes = self.max_active_scenes.max(self.workers);
        Ok(())
    }

    /// The embedded database's file.
    pub(crate) fn db_path(&self) -> PathBuf {
        match &self.database {
            Some(d) if !self.distributed() => PathBuf::from(d),
            _ => self.data_dir.join("bspvt.sqlite"),
        }
    }

    /// The embedded store's folder.
    pub(crate) fn store_dir(&self) -> PathBuf {
        match &self.store {
            Some(s) if !self.distributed() => PathBuf::from(s),
            _ => self.data_dir.clone(),
        }
    }

    /// Whether the database is PostgreSQL (the distributed shape).
    pub fn distributed(&self) -> bool {
        self.database.as_deref().is_some_and(is_postgres_url)
    }
}

/// `postgres://…` or `postgresql://…`.
pub(crate) fn is_postgres_url(s: &str) -> bool {
    s.starts_with("postgres://") || s.starts_with("postgresql://")
}

/// A CORS origin as browsers send it: `*`, or `scheme://host[:port]` with `http` or `https`,
/// no path, no trailing slash (an origin with one never matches a browser's `Origin`).
fn check_origin(o: &str) -> Result<()> {
    if o == "*" {
        return Ok(());
    }
    let rest = o
        .strip_prefix("https://")
        .or_else(|| o.strip_prefix("http://"))
        .with_context(|| {
            format!("CORS origin {o:?} must start with http:// or https:// (or be `*`)")
        })?;
    let host_ok = !rest.is_empty()
        && rest
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"-.:[]".contains(&b));
    if !host_ok {
        bail!(
            "CORS origin {o:?} must be scheme://host[:port] with no path or trailing slash \
             (as a browser sends it in `Origin`, e.g. https://app.example:8443)"
        );
    }
    Ok(())
}

/// The API key in `path`: its first line, surrounding whitespace trimmed; never empty.
fn read_key_file(path: &Path) -> Result<String> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the API key file {}", path.display()))?;
    let key = text.lines().next().unwrap_or("").trim();
    if key.is_empty() {
        bail!("the API key file {} is empty", path.display());
    }
    Ok(key.to_string())
}

fn read_file(path: &Path) -> Result<FileConfig> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read config file {}", path.display()))?;
    toml::from_str(&text).with_context(|| format!("bad config file {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_win_over_file_and_defaults_fill_the_rest() {
        let dir = tempfile::tempdir().expect("temp dir");
        let file = dir.path().join("bspvt.toml");
        std::fs::write(
            &file,
            "data_dir = \"/srv/bspvt\"\naddr = \"0.0.0.0:9000\"\nworkers = 3\nmax_streams = 7\n",
        )
        .expect("write config");
        let args = ServeArgs {
            config: Some(file),
            workers: Some(5),
            ..ServeArgs::default()
        };
        let c = Config::resolve(&args).expect("valid config");
        assert_eq!(c.data_dir, PathBuf::from("/srv/bspvt"));
        assert_eq!(c.addr.port(), 9000);
        assert_eq!(c.workers, 5);
        assert_eq!(c.max_streams, 7);
        assert_eq!(c.max_uploads, 4);
        assert!(c.max_active_scenes >= c.workers);
    }

    #[test]
    fn the_api_key_can_come_from_a_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let key = dir.path().join("key");
        std::fs::write(&key, "  s3cret-key \n# a comment\n").expect("write key");
        let args = ServeArgs {
            data_dir: Some("/x".into()),
            api_key_file: Some(key.clone()),
            ..ServeArgs::default()
        };
        let c = Config::resolve(&args).expect("valid config");
        assert_eq!(c.api_key.as_deref(), Some("s3cret-key"));
        let both = ServeArgs {
            api_key: Some("other".into()),
            ..args
        };
        assert!(
            Config::resolve(&both).is_err(),
            "a key and a key file accepted"
        );
        std::fs::write(&key, "\n").expect("write key");
        let empty = ServeArgs {
            data_dir: Some("/x".into()),
            api_key_file: Some(key),
            ..ServeArgs::default()
        };
        let e = Config::resolve(&empty).expect_err("empty key file accepted");
        assert!(format!("{e:#}").contains("is empty"), "{e:#}");
    }

    #[test]
    fn bad_settings_are_refused() {
        let dir = tempfile::tempdir().expect("temp dir");
        let file = dir.path().join("bad.toml");
        std::fs::write(&file, "data_dir = \"/x\"\nwrokers = 3\n").expect("write config");
        let args = ServeArgs {
            config: Some(file),
            ..ServeArgs::default()
        };
        assert!(Config::resolve(&args).is_err(), "unknown key accepted");
        let args = ServeArgs {
            data_dir: Some("/x".into()),
            workers: Some(0),
            ..ServeArgs::default()
        };
        assert!(Config::resolve(&args).is_err(), "zero workers accepted");
        let args = ServeArgs {
            data_dir: Some("/x".into()),
            addr: Some("localhost".into()),
            ..ServeArgs::default()
        };
        assert!(
            Config::resolve(&args).is_err(),
            "address without port accepted"
        );
        assert!(
            Config::resolve(&ServeArgs::default()).is_err(),
            "no data dir"
        );
        for bad in [
            "app.example",
            "https://app.example/",
            "https://a.example/x",
            "ftp://a",
        ] {
            let args = ServeArgs {
                data_dir: Some("/x".into()),
                cors_origins: Some(vec![bad.into()]),
                ..ServeArgs::default()
            };
            assert!(
                Config::resolve(&args).is_err(),
                "CORS origin {bad:?} accepted"
            );
        }
    }

    #[test]
    fn cors_origins_from_flags_or_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let file = dir.path().join("bspvt.toml");
        std::fs::write(
            &file,
            "data_dir = \"/x\"\ncors_origins = [\"https://app.example\", \"http://localhost:5173\"]\n",
        )
        .expect("write config");
        let args = ServeArgs {
            config: Some(file),
            ..ServeArgs::default()
        };
        let c = Config::resolve(&args).expect("valid config");
        assert_eq!(
            c.cors_origins,
            ["https://app.example", "http://localhost:5173"]
        );
        let args = ServeArgs {
            cors_origins: Some(vec!["*".into()]),
            ..args
        };
        assert_eq!(Config::resolve(&args).expect("valid").cors_origins, ["*"]);
        assert!(
            Config::with_data_dir("/x").cors_origins.is_empty(),
            "CORS on by default"
        );
    }
}
