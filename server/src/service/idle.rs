//! Idle event streams, shed first when the server's stream slots run out: an event stream
//! that has sent no status for the longest time (keep-alive comments do not count) is asked
//! to end, so that a new stream — a tree download, or events someone is waiting on — gets its
//! slot instead of a 429. An `EventSource` reconnects by itself, after the `retry` delay the
//! final event names.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::sync::Notify;

/// The open event streams and when each last sent a status.
#[derive(Default)]
pub(crate) struct IdleStreams {
    next: AtomicU64,
    open: Mutex<HashMap<u64, Watched>>,
}

struct Watched {
    last: Instant,
    shed: Arc<Notify>,
}

/// An event stream's entry; removed when dropped.
pub(crate) struct Registration {
    streams: Arc<IdleStreams>,
    id: u64,
    /// Notified when the stream is asked to end.
    pub shed: Arc<Notify>,
}

impl IdleStreams {
    pub(crate) fn register(self: &Arc<Self>) -> Registration {
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let shed = Arc::new(Notify::new());
        self.lock().insert(
            id,
            Watched {
                last: Instant::now(),
                shed: shed.clone(),
            },
        );
        Registration {
            streams: self.clone(),
            id,
            shed,
        }
    }

    /// Asks the stream idle the longest, if idle at least `min_idle`, to end; true if one was
    /// asked (it is forgotten at once, so that it is not chosen twice).
    pub(crate) fn shed_one(&self, min_idle: Duration) -> bool {
        let mut open = self.lock();
        let now = Instant::now();
        let oldest = open
            .iter()
            .filter(|(_, w)| now.duration_since(w.last) >= min_idle)
            .min_by_key(|(_, w)| w.last)
            .map(|(&id, _)| id);
        match oldest.and_then(|id| open.remove(&id)) {
            Some(w) => {
                // `notify_one` keeps the wake-up for a stream not waiting at this instant.
                w.shed.notify_one();
                true
            }
            None => false,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<u64, Watched>> {
        self.open.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl Registration {
    /// The stream sent a status now.
    pub(crate) fn touch(&self) {
        if let Some(w) = self.streams.lock().get_mut(&self.id) {
            w.last = Instant::now();
        }
    }
}

impl Drop for Registration {
    fn drop(&mut self) {
        self.streams.lock().remove(&self.id);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_longest_idle_is_shed_once_and_only_past_the_minimum() {
        let s = Arc::new(IdleStreams::default());
        let a = s.register();
        std::thread::sleep(Duration::from_millis(20));
        let b = s.register();
        assert!(
            !s.shed_one(Duration::from_secs(60)),
            "none idle long enough"
        );
        a.touch();
        // b is now the longest idle.
        assert!(s.shed_one(Duration::ZERO));
        assert!(!s.lock().contains_key(&b.id));
        assert!(s.lock().contains_key(&a.id));
        drop(a);
        assert!(!s.shed_one(Duration::ZERO), "b was forgotten, a is gone");
    }
}
