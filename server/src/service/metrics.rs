//! Service metrics in the Prometheus text exposition format (version 0.0.4), hand-written: a
//! few atomic counters and gauges need no metrics framework.
//!
//! Guarantees: counters only grow within a process (they restart at 0 with it); every series
//! has `# HELP` and `# TYPE` lines; recording a metric never blocks on I/O.

use std::collections::VecDeque;
use std::fmt::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// Counters updated by the handlers and the bake workers.
pub(crate) struct Metrics {
    started: Instant,
    /// Responses by status class (index 1..=5).
    responses: [AtomicU64; 6],
    pub scenes_submitted: AtomicU64,
    pub scenes_done: AtomicU64,
    pub scenes_failed: AtomicU64,
    pub scenes_cancelled: AtomicU64,
    pub chunks_baked: AtomicU64,
    pub vertices_baked: AtomicU64,
    bake_micros: AtomicU64,
    pub chunks_corrupt: AtomicU64,
    pub chunks_served: AtomicU64,
    pub tree_bytes_served: AtomicU64,
    pub other_bytes_served: AtomicU64,
    pub streams_open: AtomicI64,
    pub bake_errors: AtomicU64,
    recent_chunks: Mutex<VecDeque<Instant>>,
}

/// Values read from the scheduler when metrics are rendered.
#[derive(Default)]
pub(crate) struct Gauges {
    pub scenes_queued: u64,
    pub scenes_baking: u64,
    pub chunks_pending: u64,
    pub chunks_in_flight: u64,
    pub workers: u64,
    pub generation: i64,
}

/// Window over which `bspvt_chunks_per_second` is averaged.
const RATE_WINDOW: Duration = Duration::from_secs(60);

impl Default for Metrics {
    fn default() -> Self {
        Metrics {
            started: Instant::now(),
            responses: Default::default(),
            scenes_submitted: AtomicU64::new(0),
            scenes_done: AtomicU64::new(0),
            scenes_failed: AtomicU64::new(0),
            scenes_cancelled: AtomicU64::new(0),
            chunks_baked: AtomicU64::new(0),
            vertices_baked: AtomicU64::new(0),
            bake_micros: AtomicU64::new(0),
            chunks_corrupt: AtomicU64::new(0),
            chunks_served: AtomicU64::new(0),
            tree_bytes_served: AtomicU64::new(0),
            other_bytes_served: AtomicU64::new(0),
            streams_open: AtomicI64::new(0),
            bake_errors: AtomicU64::new(0),
            recent_chunks: Mutex::new(VecDeque::new()),
        }
    }
}

impl Metrics {
    pub(crate) fn response(&self, status: u16) {
        let class = (status / 100).clamp(1, 5) as usize;
        self.responses[class].fetch_add(1, Relaxed);
    }

    /// A chunk became durable.
    pub(crate) fn chunk_baked(&self, vertices: u64, took: Duration) {
        self.chunks_baked.fetch_add(1, Relaxed);
        self.vertices_baked.fetch_add(vertices, Relaxed);
        self.bake_micros.fetch_add(took.as_micros() as u64, Relaxed);
        let now = Instant::now();
        let mut q = self.recent_chunks.lock().unwrap_or_else(|p| p.into_inner());
        q.push_back(now);
        while q
            .front()
            .is_some_and(|t| now.duration_since(*t) > RATE_WINDOW)
        {
            q.pop_front();
        }
    }

    /// Chunks made durable per second over the last minute (or since start, if shorter).
    pub(crate) fn chunks_per_second(&self) -> f64 {
        let now = Instant::now();
        let q = self.recent_chunks.lock().unwrap_or_else(|p| p.into_inner());
        let n = q
            .iter()
            .filter(|t| now.duration_since(**t) <= RATE_WINDOW)
            .count();
        let window = now.duration_since(self.started).min(RATE_WINDOW);
        n as f64 / window.as_secs_f64().max(1.0)
    }

    /// The exposition text.
    pub(crate) fn render(&self, g: &Gauges) -> String {
        let mut o = String::new();
        let mut one = |name: &str, kind: &str, help: &str, value: String| {
            let _ = writeln!(
                o,
                "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {value}"
            );
        };
        let c = |a: &AtomicU64| a.load(Relaxed).to_string();
        one(
            "bspvt_uptime_seconds",
            "gauge",
            "Seconds since this process started.",
            format!("{:.3}", self.started.elapsed().as_secs_f64()),
        );
        one(
            "bspvt_generation",
            "gauge",
            "Process generation of the data directory (starts of the service).",
            g.generation.to_string(),
        );
        one(
            "bspvt_workers",
            "gauge",
            "Bake workers.",
            g.workers.to_string(),
        );
        one(
            "bspvt_queue_depth_scenes",
            "gauge",
            "Scenes queued, waiting for a bake slot.",
            g.scenes_queued.to_string(),
        );
        one(
            "bspvt_scenes_baking",
            "gauge",
            "Scenes being baked.",
            g.scenes_baking.to_string(),
        );
        one(
            "bspvt_queue_depth_chunks",
            "gauge",
            "Chunks waiting to be baked (scenes queued or baking).",
            g.chunks_pending.to_string(),
        );
        one(
            "bspvt_chunks_in_flight",
            "gauge",
            "Chunks being baked now.",
            g.chunks_in_flight.to_string(),
        );
        one(
            "bspvt_chunks_baked_total",
            "counter",
            "Chunks baked and made durable by this process.",
            c(&self.chunks_baked),
        );
        one(
            "bspvt_chunks_per_second",
            "gauge",
            "Chunks made durable per second, averaged over the last minute.",
            format!("{:.4}", self.chunks_per_second()),
        );
        one(
            "bspvt_vertices_baked_total",
            "counter",
            "Vertices baked by this process.",
            c(&self.vertices_baked),
        );
        one(
            "bspvt_bake_seconds_total",
            "counter",
            "Wall seconds spent baking chunks, summed over workers.",
            format!("{:.6}", self.bake_micros.load(Relaxed) as f64 * 1e-6),
        );
        one(
            "bspvt_chunks_corrupt_total",
            "counter",
            "Stored chunks found corrupt or missing on read (never served; re-baked).",
            c(&self.chunks_corrupt),
        );
        one(
            "bspvt_bake_errors_total",
            "counter",
            "Bakes that failed (storage errors, unreadable stored scenes, panics).",
            c(&self.bake_errors),
        );
        one(
            "bspvt_chunks_served_total",
            "counter",
            "Chunk frames sent to clients.",
            c(&self.chunks_served),
        );
        let _ = writeln!(
            o,
            "# HELP bspvt_bytes_served_total Response body bytes sent, by kind.\n# TYPE bspvt_bytes_served_total counter\nbspvt_bytes_served_total{{kind=\"trees\"}} {}\nbspvt_bytes_served_total{{kind=\"other\"}} {}",
            self.tree_bytes_served.load(Relaxed),
            self.other_bytes_served.load(Relaxed)
        );
        let _ = writeln!(
            o,
            "# HELP bspvt_streams_open Tree and event streams open now.\n# TYPE bspvt_streams_open gauge\nbspvt_streams_open {}",
            self.streams_open.load(Relaxed)
        );
        let _ = writeln!(
            o,
            "# HELP bspvt_scenes_total Scenes by what happened to them in this process.\n# TYPE bspvt_scenes_total counter"
        );
        for (event, v) in [
            ("submitted", &self.scenes_submitted),
            ("done", &self.scenes_done),
            ("failed", &self.scenes_failed),
            ("cancelled", &self.scenes_cancelled),
        ] {
            let _ = writeln!(
                o,
                "bspvt_scenes_total{{event=\"{event}\"}} {}",
                v.load(Relaxed)
            );
        }
        let _ = writeln!(
            o,
            "# HELP bspvt_http_responses_total HTTP responses by status class (4xx and 5xx are errors).\n# TYPE bspvt_http_responses_total counter"
        );
        for class in 1..=5 {
            let _ = writeln!(
                o,
                "bspvt_http_responses_total{{class=\"{class}xx\"}} {}",
                self.responses[class].load(Relaxed)
            );
        }
        o
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exposition_has_help_type_and_values() {
        let m = Metrics::default();
        m.response(404);
        m.chunk_baked(64, Duration::from_millis(5));
        let t = m.render(&Gauges {
            scenes_queued: 3,
            ..Gauges::default()
        });
        assert!(t.contains("bspvt_http_responses_total{class=\"4xx\"} 1\n"));
        assert!(t.contains("bspvt_chunks_baked_total 1\n"));
        assert!(t.contains("bspvt_queue_depth_scenes 3\n"));
        for line in t.lines().filter(|l| !l.starts_with('#')) {
            let (name, value) = line.rsplit_once(' ').expect("name value");
            assert!(value.parse::<f64>().is_ok(), "{line}");
            let base = name.split('{').next().expect("name");
            assert!(t.contains(&format!("# TYPE {base} ")), "{base} has no TYPE");
        }
    }
}
