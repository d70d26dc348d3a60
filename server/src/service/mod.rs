//! The HTTP baking service (`bspvt-server serve`): axum on tokio, an embedded SQLite database
//! for jobs and metadata, chunk files for the trees, all under one data directory.
//!
//! Modules: [`config`] (flags, environment, TOML), `api` (handlers), `stream` (tree
//! streaming, also as GPU words), `gpu_scene` (a scene as the GPU shaders read it, for the
//! browser viewer), `sse` (status events), `openapi` (the API document and its handler),
//! `state` (what every handler reaches: state, scene lookup, stream accounting), `http`
//! (query strings, conditional requests), `jobs` (scheduler and workers), `store` (files),
//! `db` (SQLite), `input` (uploads → scenes), `metrics`, `error`, `pool` (the bake's threads,
//! at background priority). Only [`config`] and
//! the service handles below are public. The modules depend on each other without cycles, top
//! to bottom: this module (router, server) → `openapi` → the handlers `api`, `stream`, `sse`,
//! `gpu_scene` →
//! `state`, `http` → `jobs` → `store`, `input`, `metrics`, `pool` → `db`, `error`, `config` →
//! `memory` (the memory budget); `web` (the browser dashboard at `/`) beside the handlers.
//! docs/service.md describes the API, the storage layout and the invariants.
//!
//! Guarantees of this module: every request runs in a tracing span (id, method, path) and is
//! logged with its status and latency; requests beyond `max_concurrent_requests` get 429;
//! non-streaming requests are cut at `request_timeout_s` (408); every error response is JSON
//! (`error::json_errors`); on SIGINT/SIGTERM the server stops accepting, ends open streams,
//! lets the workers store the chunks they are baking, and exits (a SIGKILL instead loses
//! nothing durable: see `jobs`).

mod api;
mod bench_cluster;
mod bodies;
mod chunk;
mod clients;
mod cluster;
pub mod config;
mod db;
mod error;
#[doc(hidden)]
pub mod fuzz;
mod gpu_scene;
mod http;
mod idle;
mod input;
mod io;
mod jobs;
mod memory;
mod metrics;
mod objstore;
mod openapi;
mod pg;
mod pool;
mod rays;
mod rows;
mod sse;
mod state;
mod store;
mod stream;
mod web;

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use axum::Router;
use axum::extract::MatchedPath;
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::StatusCode;
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{MethodRouter, get};
use tokio::sync::{Semaphore, watch};
use tracing::Instrument;

pub use bench_cluster::{ClusterBenchArgs, cluster_bench_command};
pub use cluster::WorkerArgs;
pub use config::{Config, ServeArgs};
use db::Db;
use error::ApiError;
use jobs::Jobs;
use metrics::Metrics;
use rays::Rays;
use state::{AppState, Shared};
use store::Store;

/// Every route: its path template and handlers. The router is built from this list, and a
/// test checks each path against the OpenAPI document (`openapi::document`).
pub(crate) fn routes() -> Vec<(&'static str, MethodRouter<Shared>)> {
    vec![
        ("/v1/scenes", get(api::list_scenes).post(api::submit)),
        (
            "/v1/scenes/{id}",
            get(api::get_scene).delete(api::delete_scene),
        ),
        ("/v1/scenes/{id}/events", get(sse::get_events)),
        ("/v1/scenes/{id}/mesh", get(api::get_mesh)),
        ("/v1/scenes/{id}/scene", get(api::get_scene_file)),
        ("/v1/scenes/{id}/trees", get(stream::get_trees)),
        ("/v1/scenes/{id}/gpu-scene", get(gpu_scene::get_gpu_scene)),
        ("/v1/openapi.json", get(openapi::openapi)),
        ("/healthz", get(api::healthz)),
        ("/metrics", get(api::metrics)),
    ]
}

/// The router with its middleware.
pub(crate) fn router(state: Shared) -> Router {
    let body_limit = usize::try_from(state.cfg.max_body_bytes).unwrap_or(usize::MAX);
    let cors = cors_layer(&state.cfg.cors_origins);
    let r = routes()
        .into_iter()
        .chain(web::routes())
        .fold(Router::new(), |r, (path, handlers)| r.route(path, handlers))
        .fallback(api::not_found)
        .layer(compression())
        .layer(DefaultBodyLimit::max(body_limit))
        .layer(middleware::from_fn_with_state(state.clone(), observe))
        .layer(middleware::map_response(error::json_errors));
    // Outermost: preflights are answered before limits and keys, and every response, errors
    // included, carries the CORS headers a browser needs to read it.
    match cors {
        Some(c) => r.layer(c),
        None => r,
    }
    .with_state(state)
}

/// gzip (when the request accepts it) for what browsers fetch and is not compressed already:
/// the viewer's GPU words and scene bundle (3–6× smaller: docs/service.md, "Viewer"), the
/// pages, scripts, styles and shaders. Never the event streams (each event must go out at
/// once), the encoded trees (zstd inside) or the API's JSON.
fn compression()
-> tower_http::compression::CompressionLayer<impl tower_http::compression::Predicate> {
    use axum::http::{Extensions, HeaderMap, Version, header};
    use tower_http::compression::predicate::{Predicate, SizeAbove};
    let browser_bodies = |_: StatusCode, _: Version, h: &HeaderMap, _: &Extensions| {
        h.get(header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .is_some_and(|t| {
                [
                    "application/vnd.bspvt-gpu",
                    "text/html",
                    "text/css",
                    "text/javascript",
                    "text/wgsl",
                ]
                .iter()
                .any(|p| t.starts_with(p))
            })
    };
    tower_http::compression::CompressionLayer::new()
        .compress_when(SizeAbove::new(1024).and(browser_bodies))
}

/// CORS for browser clients on `origins` (`*`: any); none when the list is empty. Requests
/// carry keys in headers, never cookies, so credentials are not allowed.
fn cors_layer(origins: &[String]) -> Option<tower_http::cors::CorsLayer> {
    use axum::http::{HeaderName, HeaderValue, Method, header};
    use tower_http::cors::{AllowOrigin, CorsLayer};
    if origins.is_empty() {
        return None;
    }
    let allow = if origins.iter().any(|o| o == "*") {
        AllowOrigin::any()
    } else {
        // Checked by `Config::check`: every origin is a valid header value.
        AllowOrigin::list(origins.iter().filter_map(|o| HeaderValue::from_str(o).ok()))
    };
    Some(
        CorsLayer::new()
            .allow_origin(allow)
            .allow_methods([Method::GET, Method::POST, Method::DELETE])
            .allow_headers([
                header::AUTHORIZATION,
                header::CONTENT_TYPE,
                header::IF_NONE_MATCH,
                HeaderName::from_static("x-api-key"),
                HeaderName::from_static("idempotency-key"),
            ])
            .expose_headers([
                header::LOCATION,
                header::ETAG,
                header::LINK,
                header::RETRY_AFTER,
                HeaderName::from_static("idempotent-replayed"),
                HeaderName::from_static("x-bspvt-vertices"),
                HeaderName::from_static("x-bspvt-chunks"),
                HeaderName::from_static("x-bspvt-mesh-hash"),
            ])
            .max_age(Duration::from_secs(600)),
    )
}

/// Per-request span, log line, metrics, concurrency limit and timeout.
async fn observe(State(st): State<Shared>, req: Request, next: Next) -> Response {
    let n = st.next_request.fetch_add(1, Ordering::Relaxed);
    let method = req.method().clone();
    let path = error::truncate(req.uri().path(), 200);
    // The route's template (`/v1/scenes/{id}`), never the raw path: bounded label values.
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or("unmatched", |m| m.as_str())
        .to_string();
    let span = tracing::info_span!("request", id = n, method = %method, path = %path);
    async move {
        let t0 = Instant::now();
        let exempt = path == "/healthz" || path == "/metrics";
        let permit = if exempt {
            None
        } else {
            match st.requests.clone().try_acquire_owned() {
                Ok(p) => Some(p),
                Err(_) => {
                    st.metrics.response(429);
                    st.metrics
                        .request_latency(&route, &method, 429, t0.elapsed());
                    tracing::warn!("too many concurrent requests");
                    return ApiError::too_many("too many concurrent requests; retry shortly")
                        .into_response();
                }
            }
        };
        let timeout = Duration::from_secs(st.cfg.request_timeout_s);
        let response = match tokio::time::timeout(timeout, next.run(req)).await {
            Ok(r) => r,
            Err(_) => ApiError::new(
                StatusCode::REQUEST_TIMEOUT,
                "timeout",
                format!("the request took longer than {} s", timeout.as_secs()),
            )
            .into_response(),
        };
        drop(permit);
        let status = response.status();
        st.metrics.response(status.as_u16());
        let took = t0.elapsed();
        st.metrics
            .request_latency(&route, &method, status.as_u16(), took);
        let ms = took.as_secs_f64() * 1e3;
        if status.is_server_error() {
            tracing::error!(status = status.as_u16(), ms, "request failed");
        } else if status.is_client_error() {
            tracing::info!(status = status.as_u16(), ms, "request rejected");
        } else {
            tracing::info!(status = status.as_u16(), ms, "request");
        }
        response
    }
    .instrument(span)
    .await
}

/// Refuses a data folder the service cannot write (a read-only mount, no permission) with a
/// message that says so, before SQLite reports it as a "disk I/O error". Other failures of the
/// probe (a full disk) are left to the start-up that handles them.
fn check_writable(dir: &std::path::Path) -> Result<()> {
    let probe = dir.join(".write-probe");
    match std::fs::write(&probe, b"") {
        Ok(()) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::ReadOnlyFilesystem | std::io::ErrorKind::PermissionDenied
            ) =>
        {
            anyhow::bail!(
                "the data folder {} is not writable ({e}): the service keeps its database and \
                 the baked chunks there. Make it writable (remount it read-write, fix its \
                 permissions) or give another --data-dir; nothing was changed",
                dir.display()
            )
        }
        Err(_) => Ok(()),
    }
}

/// A service that is running.
pub(crate) struct Service {
    pub state: Shared,
    pub addr: SocketAddr,
    listener: tokio::net::TcpListener,
    stop_tx: watch::Sender<bool>,
}

impl Service {
    /// Opens the data directory (database, store), resumes unfinished bakes, starts the
    /// workers and binds the listener.
    pub(crate) async fn open(cfg: Config) -> Result<Service> {
        if cfg.distributed() {
            return Service::open_cluster(cfg).await;
        }
        let store_dir = cfg.store_dir();
        if store_dir != cfg.data_dir {
            // `--database FILE --store DIR`: the embedded shape with its two parts named.
            let mut c = cfg.clone();
            c.data_dir = store_dir;
            if let Some(parent) = cfg.db_path().parent().filter(|p| !p.as_os_str().is_empty()) {
                std::fs::create_dir_all(parent)
                    .with_context(|| format!("cannot create {}", parent.display()))?;
            }
            return Service::open_embedded(c, cfg.db_path()).await;
        }
        let db_path = cfg.db_path();
        Service::open_embedded(cfg, db_path).await
    }

    /// The embedded shape: a database file and a store folder (`data_dir`).
    async fn open_embedded(cfg: Config, db_path: std::path::PathBuf) -> Result<Service> {
        std::fs::create_dir_all(&cfg.data_dir)
            .with_context(|| format!("cannot create data dir {}", cfg.data_dir.display()))?;
        check_writable(&cfg.data_dir)?;
        // Scene folders without their database: start-up garbage collection would take them
        // all for leftovers of crashed uploads. Stop before anything is created or deleted.
        if !db_path.exists() {
            let n = Store::scene_folders(&cfg.data_dir)
                .with_context(|| format!("cannot read data dir {}", cfg.data_dir.display()))?;
            if n > 0 {
                anyhow::bail!(
                    "{} holds {n} scene folder(s) but no database ({} is missing): refusing to \
                     start, nothing was deleted. Restore the database (with its -wal file), or \
                     move {} away to start empty",
                    cfg.data_dir.display(),
                    db_path.display(),
                    cfg.data_dir.join("scenes").display()
                );
            }
        }
        let db = Arc::new(Db::open(&db_path)?);
        let store = Arc::new(
            Store::open(&cfg.data_dir)
                .with_context(|| format!("cannot open the store in {}", cfg.data_dir.display()))?,
        );
        let metrics = Arc::new(Metrics::default());
        let memory = memory::MemoryBudget::new(cfg.memory_budget_mib.saturating_mul(memory::MIB));
        let jobs = {
            let (db, store, metrics, c) = (db.clone(), store.clone(), metrics.clone(), cfg.clone());
            tokio::task::spawn_blocking(move || {
                Jobs::start(db, store, metrics, memory, Rays::open(c.bake_backend)?, &c)
            })
            .await??
        };
        Service::listen(cfg, db, store, jobs, metrics).await
    }

    /// The distributed shape: PostgreSQL and an object store; no local state.
    async fn open_cluster(cfg: Config) -> Result<Service> {
        let url = cfg.database.clone().unwrap_or_default();
        let store_url = objstore::StoreUrl::parse(cfg.store.as_deref().unwrap_or_default())?;
        let lease = Duration::from_secs(cfg.lease_s);
        let c = cfg.clone();
        let jobs_db_store = tokio::task::spawn_blocking(move || -> Result<_> {
            let db = Arc::new(Db::Pg(pg::PgDb::open(&url, lease)?));
            let objects = objstore::ObjStore::open(&store_url)?;
            objects
                .check()
                .with_context(|| format!("cannot use the store {}", objects.url))?;
            let store = Arc::new(Store::object(objects));
            let metrics = Arc::new(Metrics::default());
            let memory = memory::MemoryBudget::new(c.memory_budget_mib.saturating_mul(memory::MIB));
            let jobs = Jobs::start_cluster(db.clone(), store.clone(), metrics.clone(), memory, &c)?;
            Ok((db, store, jobs, metrics))
        })
        .await??;
        let (db, store, jobs, metrics) = jobs_db_store;
        tracing::info!(
            workers = cfg.workers,
            "distributed shape: PostgreSQL and object store"
        );
        Service::listen(cfg, db, store, jobs, metrics).await
    }

    async fn listen(
        cfg: Config,
        db: Arc<Db>,
        store: Arc<Store>,
        jobs: Arc<Jobs>,
        metrics: Arc<Metrics>,
    ) -> Result<Service> {
        let listener = tokio::net::TcpListener::bind(cfg.addr)
            .await
            .with_context(|| format!("cannot listen on {}", cfg.addr))?;
        let addr = listener.local_addr()?;
        let (stop_tx, stop_rx) = watch::channel(false);
        let state = Arc::new(AppState {
            uploads: Arc::new(Semaphore::new(cfg.max_uploads)),
            streams: Arc::new(Semaphore::new(cfg.max_streams)),
            clients: Arc::new(clients::ClientSlots::default()),
            idle_streams: Arc::new(idle::IdleStreams::default()),
            requests: Arc::new(Semaphore::new(cfg.max_concurrent_requests)),
            reencode: Semaphore::new(std::thread::available_parallelism().map_or(2, |n| n.get())),
            bodies: Default::default(),
            cfg,
            db,
            store,
            metrics,
            memory: jobs.memory().clone(),
            jobs,
            shutdown: stop_rx,
            started: Instant::now(),
            next_request: AtomicU64::new(0),
            idempotency_in_flight: Default::default(),
        });
        Ok(Service {
            state,
            addr,
            listener,
            stop_tx,
        })
    }

    /// Serves until `stop` resolves, then shuts down within `shutdown_timeout_s`: streams
    /// end, connections get up to a third of it to finish, workers the rest to store the
    /// chunks they are baking (a chunk not stored by then is baked again at the next start;
    /// a worker still building a BVH is abandoned, not waited for).
    pub(crate) async fn run(
        self,
        stop: impl std::future::Future<Output = ()> + Send + 'static,
    ) -> Result<()> {
        let Service {
            state,
            addr,
            listener,
            stop_tx,
        } = self;
        let jobs = state.jobs.clone();
        let shutdown = Duration::from_secs(state.cfg.shutdown_timeout_s);
        let limits = ConnLimits {
            max: state.cfg.max_connections,
            header_timeout: Duration::from_secs(state.cfg.header_read_timeout_s),
            grace: Duration::from_secs(state.cfg.shutdown_timeout_s) / 3,
        };
        let app = router(state);
        let stopped = stop_tx.subscribe();
        tokio::spawn(async move {
            stop.await;
            tracing::info!("shutting down");
            let _ = stop_tx.send(true);
        });
        tracing::info!(%addr, "serving");
        let stop_at = accept_loop(listener, app, stopped, limits).await;
        // The clock starts at the signal: the connections' grace period is part of it.
        let left = shutdown.saturating_sub(stop_at.elapsed());
        tokio::task::spawn_blocking(move || jobs.shutdown(left)).await?;
        Ok(())
    }
}

struct ConnLimits {
    max: usize,
    header_timeout: Duration,
    /// How long open connections may take to finish after a shutdown begins.
    grace: Duration,
}

/// Accepts HTTP/1.1 connections (hyper, with a header-read timeout against slow clients and a
/// cap on open connections) until `stop` turns true, then shuts them down gracefully.
/// Returns when `stop` was seen.
async fn accept_loop(
    listener: tokio::net::TcpListener,
    app: Router,
    mut stop: watch::Receiver<bool>,
    limits: ConnLimits,
) -> Instant {
    use hyper_util::rt::{TokioIo, TokioTimer};
    let graceful = hyper_util::server::graceful::GracefulShutdown::new();
    let open = Arc::new(Semaphore::new(limits.max));
    loop {
        let (socket, peer) = tokio::select! {
            r = listener.accept() => match r {
                Ok(c) => c,
                Err(e) => {
                    // Out of file descriptors and the like: back off instead of spinning.
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            _ = stop.wait_for(|s| *s) => break,
        };
        let Ok(permit) = open.clone().try_acquire_owned() else {
            tracing::warn!(%peer, "connection limit reached; closing a new connection");
            continue;
        };
        let _ = socket.set_nodelay(true);
        let app = app
            .clone()
            .layer(axum::Extension(clients::Client(peer.ip())));
        let service = hyper_util::service::TowerToHyperService::new(app);
        let conn = hyper::server::conn::http1::Builder::new()
            .timer(TokioTimer::new())
            .header_read_timeout(limits.header_timeout)
            .serve_connection(TokioIo::new(socket), service);
        let conn = graceful.watch(conn);
        tokio::spawn(async move {
            if let Err(e) = conn.await {
                tracing::debug!(%peer, error = %e, "connection ended with an error");
            }
            drop(permit);
        });
    }
    let stop_at = Instant::now();
    tokio::select! {
        _ = graceful.shutdown() => {}
        _ = tokio::time::sleep(limits.grace) => {
            tracing::warn!(grace_s = limits.grace.as_secs_f64(), "connections still open after the shutdown grace period; closing them");
        }
    }
    stop_at
}

/// SIGINT or SIGTERM.
async fn signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}

/// Sets up logging on stderr (`RUST_LOG` filters; default `info`).
pub(crate) fn init_logging(format: config::LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    // A log line that cannot be written (stderr on a full disk) is dropped: the default
    // reports it with `eprintln!`, which panics when stderr fails too, and the panic took the
    // request's connection down with it.
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr)
        .log_internal_errors(false);
    let _ = match format {
        config::LogFormat::Json => builder.json().try_init(),
        config::LogFormat::Text => builder.try_init(),
    };
}

/// `bspvt-server serve`: runs until SIGINT/SIGTERM. Prints `listening on http://ADDR` on
/// stdout once the socket is bound.
pub fn serve_command(args: &ServeArgs) -> Result<()> {
    let cfg = Config::resolve(args)?;
    init_logging(cfg.log_format);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("bspvt-http")
        .build()
        .context("cannot start the async runtime")?;
    let result = rt.block_on(async move {
        let svc = Service::open(cfg).await?;
        {
            use std::io::Write;
            let mut out = std::io::stdout().lock();
            writeln!(out, "listening on http://{}", svc.addr)?;
            out.flush()?;
        }
        svc.run(signal()).await
    });
    // Work still running on the blocking pool (an upload being parsed) is abandoned, not
    // waited for: nothing of it was reported, and the deadline has passed.
    rt.shutdown_timeout(Duration::from_millis(200));
    result
}

/// `bspvt-server worker`: bakes chunks leased from a PostgreSQL database (the distributed
/// shape) until SIGINT/SIGTERM, then finishes the chunks it holds and gives back its leases.
pub fn worker_command(args: &WorkerArgs) -> Result<()> {
    init_logging(match args.log_format.as_str() {
        "json" => config::LogFormat::Json,
        "text" => config::LogFormat::Text,
        f => anyhow::bail!("log format {f:?} is neither `text` nor `json`"),
    });
    if !config::is_postgres_url(&args.database) {
        anyhow::bail!("--database must be a postgres:// URL (workers share a PostgreSQL database)");
    }
    if !(2..=3600).contains(&args.lease_s) || args.chunks == 0 || args.max_chunk_failures == 0 {
        anyhow::bail!(
            "--lease-s must be in 2..=3600, --chunks and --max-chunk-failures at least 1"
        );
    }
    let db = Arc::new(Db::Pg(pg::PgDb::open(
        &args.database,
        Duration::from_secs(args.lease_s),
    )?));
    let objects = objstore::ObjStore::open(&objstore::StoreUrl::parse(&args.store)?)?;
    objects
        .check()
        .with_context(|| format!("cannot use the store {}", objects.url))?;
    let store = Arc::new(Store::object(objects));
    let id = args.id.clone().unwrap_or_else(cluster::new_worker_id);
    let (workers, handles) = cluster::Workers::start(
        db,
        store,
        Arc::new(Metrics::default()),
        id.clone(),
        args.chunks,
        pool::PoolSettings {
            threads: args.threads,
            nice: args.bake_nice,
        },
        args.max_chunk_failures,
    )?;
    {
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        writeln!(out, "worker {id} started")?;
        out.flush()?;
    }
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the signal handler")?;
    rt.block_on(signal());
    tracing::info!(worker = %id, "stopping: finishing the chunks held");
    workers.stop();
    for h in handles {
        let _ = h.join();
    }
    workers.finish();
    Ok(())
}

/// A service running on its own runtime thread (benchmarks, embedding).
pub struct Background {
    /// The address the service listens on.
    pub addr: SocketAddr,
    /// Holds the shared state for as long as the handle lives (read by nothing outside).
    #[expect(
        dead_code,
        reason = "kept alive with the handle, as before the API was narrowed"
    )]
    state: Shared,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<Result<()>>>,
}

impl Background {
    /// Starts a service in the background and returns once it listens.
    pub fn start(cfg: Config) -> Result<Background> {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .thread_name("bspvt-http")
            .build()
            .context("cannot start the async runtime")?;
        let svc = rt.block_on(Service::open(cfg))?;
        let (addr, state) = (svc.addr, svc.state.clone());
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let thread = std::thread::Builder::new()
            .name("bspvt-service".into())
            .spawn(move || {
                rt.block_on(svc.run(async {
                    let _ = rx.await;
                }))
            })?;
        Ok(Background {
            addr,
            state,
            stop: Some(tx),
            thread: Some(thread),
        })
    }

    /// Shuts the service down and waits for it.
    pub fn stop(mut self) -> Result<()> {
        self.shutdown()
    }

    fn shutdown(&mut self) -> Result<()> {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        match self.thread.take() {
            Some(t) => t
                .join()
                .map_err(|_| anyhow::anyhow!("the service thread panicked"))?,
            None => Ok(()),
        }
    }
}

impl Drop for Background {
    fn drop(&mut self) {
        let _ = self.shutdown();
    }
}

#[cfg(test)]
mod tests {
    /// Every route the router serves is in the OpenAPI document, and the document names no
    /// path the router lacks (the methods of each are checked against the live server in
    /// `server/tests/service_api.rs`).
    #[test]
    fn every_route_is_documented() {
        let doc = super::openapi::document();
        let documented: std::collections::BTreeSet<&str> = doc["paths"]
            .as_object()
            .expect("paths")
            .keys()
            .map(String::as_str)
            .collect();
        let routed: std::collections::BTreeSet<&str> =
            super::routes().into_iter().map(|(p, _)| p).collect();
        assert_eq!(routed, documented);
    }
}
