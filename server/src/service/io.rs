//! The runtime of the distributed shape's network clients (PostgreSQL, S3): one small tokio
//! runtime of its own, so that the service's blocking code (scheduler threads, tokio's
//! blocking pool, `bspvt-server worker`) can wait for an async client from any thread, and
//! the clients' connections never depend on a runtime that may be busy or gone.

use std::future::Future;
use std::sync::OnceLock;

use anyhow::{Context, Result};

static RUNTIME: OnceLock<std::result::Result<tokio::runtime::Runtime, String>> = OnceLock::new();

fn runtime() -> Result<&'static tokio::runtime::Runtime> {
    RUNTIME
        .get_or_init(|| {
            tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .thread_name("bspvt-io")
                .enable_all()
                .build()
                .map_err(|e| e.to_string())
        })
        .as_ref()
        .map_err(|e| anyhow::anyhow!("cannot start the network runtime: {e}"))
}

/// Runs `f` on the network runtime and waits for it (blocking the calling thread, which must
/// not be one that drives async tasks).
pub(crate) fn block_on<F, T>(f: F) -> Result<T>
where
    F: Future<Output = Result<T>> + Send + 'static,
    T: Send + 'static,
{
    let (tx, rx) = std::sync::mpsc::channel();
    runtime()?.spawn(async move {
        let _ = tx.send(f.await);
    });
    rx.recv().context("the network runtime dropped a request")?
}

/// Runs `f` on the network runtime from async code.
pub(crate) async fn spawn<F, T>(f: F) -> Result<T>
where
    F: Future<Output = Result<T>> + Send + 'static,
    T: Send + 'static,
{
    runtime()?.spawn(f).await.context("a network task failed")?
}
