//! Response bodies that never change for their ETag — a scene's stored bytes, its mesh as JSON
//! or PLY — built once and shared by every request for them (`Bytes` clones, no copy), within
//! [`CAPACITY`] bytes, the least recently asked for dropped first.
//!
//! Without it each request read the stored scene, decoded it and encoded the mesh again, and
//! held its own copy until the client had it: 200 viewers opening a 28K-vertex scene held
//! ~250 MiB of such copies (server/examples/soak.rs). Concurrent requests for a body being
//! built wait for that one build. A body larger than the capacity is built per request, as
//! before, and not kept.

use std::collections::HashMap;
use std::future::Future;
use std::sync::{Arc, Mutex};

use axum::body::Bytes;
use tokio::sync::OnceCell;

use super::error::ApiResult;

/// Bytes kept: part of the idle service's memory (`memory::BASE_BYTES`, 64 MiB, of which the
/// idle process uses ~30 MiB), not reserved from the budget of uploads and bakes.
pub(crate) const CAPACITY: usize = 32 << 20;

/// The shared bodies, by ETag.
#[derive(Default)]
pub(crate) struct Bodies {
    inner: Mutex<Inner>,
}

#[derive(Default)]
struct Inner {
    entries: HashMap<String, Entry>,
    /// Bytes of the built entries.
    bytes: usize,
    /// A counter of requests: an entry's `last` is when it was last asked for.
    tick: u64,
}

struct Entry {
    cell: Arc<OnceCell<Bytes>>,
    last: u64,
    /// 0 until built.
    size: usize,
}

impl Bodies {
    /// The body named `etag`, built by `build` when no request has built it yet.
    pub(crate) async fn get_or_build<F, Fut>(&self, etag: &str, build: F) -> ApiResult<Bytes>
    where
        F: FnOnce() -> Fut,
        Fut: Future<Output = ApiResult<Vec<u8>>>,
    {
        let cell = {
            let mut g = self.lock();
            g.tick += 1;
            let tick = g.tick;
            let e = g.entries.entry(etag.to_string()).or_insert_with(|| Entry {
                cell: Arc::new(OnceCell::new()),
                last: tick,
                size: 0,
            });
            e.last = tick;
            e.cell.clone()
        };
        let body = cell
            .get_or_try_init(|| async { build().await.map(Bytes::from) })
            .await?
            .clone();
        let mut g = self.lock();
        let inner = &mut *g;
        if let Some(e) = inner.entries.get_mut(etag)
            && e.size == 0
            && Arc::ptr_eq(&e.cell, &cell)
        {
            if body.len() > CAPACITY {
                inner.entries.remove(etag);
            } else {
                e.size = body.len();
                inner.bytes += body.len();
            }
        }
        // The least recently asked for go first; entries being built (size 0) stay.
        while inner.bytes > CAPACITY {
            let Some(oldest) = inner
                .entries
                .iter()
                .filter(|(_, e)| e.size > 0)
                .min_by_key(|(_, e)| e.last)
                .map(|(k, _)| k.clone())
            else {
                break;
            };
            if let Some(e) = inner.entries.remove(&oldest) {
                inner.bytes -= e.size;
            }
        }
        Ok(body)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Bytes kept now.
    #[cfg(test)]
    fn bytes(&self) -> usize {
        self.lock().bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[tokio::test]
    async fn built_once_kept_within_capacity_oldest_dropped_first() {
        let bodies = Bodies::default();
        let builds = AtomicUsize::new(0);
        let make = |n: usize| {
            builds.fetch_add(1, Ordering::Relaxed);
            async move { Ok(vec![7u8; n]) }
        };
        let a = bodies
            .get_or_build("a", || make(CAPACITY / 2))
            .await
            .expect("built");
        let a2 = bodies.get_or_build("a", || make(1)).await.expect("built");
        assert_eq!(
            builds.load(Ordering::Relaxed),
            1,
            "a second request builds nothing"
        );
        assert_eq!(a.as_ptr(), a2.as_ptr(), "the same bytes, not a copy");
        bodies
            .get_or_build("b", || make(CAPACITY / 2))
            .await
            .expect("built");
        assert_eq!(bodies.bytes(), CAPACITY);
        // `a` asked for again, then `c`: `b` is the least recently asked for and goes.
        bodies.get_or_build("a", || make(1)).await.expect("built");
        bodies.get_or_build("c", || make(10)).await.expect("built");
        assert_eq!(bodies.bytes(), CAPACITY / 2 + 10);
        bodies.get_or_build("a", || make(1)).await.expect("built");
        assert_eq!(builds.load(Ordering::Relaxed), 3, "a is still kept");
        bodies.get_or_build("b", || make(1)).await.expect("built");
        assert_eq!(
            builds.load(Ordering::Relaxed),
            4,
            "b was dropped and is built again"
        );
        // Too large to keep: served, not kept.
        let big = bodies
            .get_or_build("big", || make(CAPACITY + 1))
            .await
            .expect("built");
        assert_eq!(big.len(), CAPACITY + 1);
        assert!(bodies.bytes() <= CAPACITY);
    }

    #[tokio::test]
    async fn a_failed_build_is_not_kept() {
        let bodies = Bodies::default();
        let r = bodies
            .get_or_build("x", || async {
                Err(crate::service::error::ApiError::internal(
                    "disk".to_string(),
                ))
            })
            .await;
        assert!(r.is_err());
        let ok = bodies
            .get_or_build("x", || async { Ok(b"fine".to_vec()) })
            .await
            .expect("built");
        assert_eq!(&ok[..], b"fine");
    }
}
