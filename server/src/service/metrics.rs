//! Service metrics in the Prometheus text exposition format (version 0.0.4), hand-written: a
//! few atomic counters and gauges need no metrics framework.
//!
//! Guarantees: counters only grow within a process (they restart at 0 with it); every series
//! has `# HELP` and `# TYPE` lines; recording a metric never blocks on I/O. The request-latency
//! histogram is labelled by route template (never the raw path), a fixed set of methods and
//! the status class, so its label values are bounded whatever clients send.

use std::collections::{BTreeMap, VecDeque};
use std::fmt::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// Counters updated by the handlers and the bake workers.
pub(crate) struct Metrics {
    started: Instant,
    /// Responses by status class (index 1..=5).
    responses: [AtomicU64; 6],
    /// Requests whose client went away before its body ended (status 499, counted in 4xx too).
    client_aborts: AtomicU64,
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
    /// Idle event streams ended to free a slot.
    pub streams_shed: AtomicU64,
    pub bake_errors: AtomicU64,
    /// `/healthz` probes that found the object store failing (the distributed shape).
    pub store_probe_failures: AtomicU64,
    recent_chunks: Mutex<VecDeque<Instant>>,
    /// Request latency by (route template, method, status class).
    latency: Mutex<BTreeMap<(String, &'static str, u16), Histogram>>,
}

/// Upper bounds (seconds) of the request-latency histogram's buckets (`+Inf` is implied):
/// from 1 ms (status, metrics) to 60 s (large uploads).
pub(crate) const LATENCY_BUCKETS_S: [f64; 14] = [
    0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 60.0,
];

/// One series of the histogram: cumulative counts are computed when rendered.
#[derive(Default)]
struct Histogram {
    /// Observations per bucket (not cumulative); the last is above every bound.
    buckets: [u64; LATENCY_BUCKETS_S.len() + 1],
    sum_s: f64,
    count: u64,
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
    pub memory_budget_bytes: u64,
    pub memory_reserved_bytes: u64,
    /// The distributed shape: the queue and the workers, from the database.
    pub cluster: Option<super::pg::ClusterGauges>,
    /// `--bake-backend gpu`: seconds the GPU has had a bake dispatch in flight.
    pub gpu_busy_seconds: Option<f64>,
}

/// The distributed shape's series: the workers the database knows (seen in the last hour).
fn render_cluster(o: &mut String, cl: &super::pg::ClusterGauges) {
    let live = cl.workers.iter().filter(|w| w.live).count();
    let _ = writeln!(
        o,
        "# HELP bspvt_cluster_workers_live Bake workers with a heartbeat within the lease time.\n# TYPE bspvt_cluster_workers_live gauge\nbspvt_cluster_workers_live {live}"
    );
    let _ = writeln!(
        o,
        "# HELP bspvt_cluster_chunks_fenced_total Stale results refused (their lease had been taken over), all workers.\n# TYPE bspvt_cluster_chunks_fenced_total counter\nbspvt_cluster_chunks_fenced_total {}",
        cl.chunks_fenced
    );
    let series: [(&str, &str, &str); 3] = [
        (
            "bspvt_worker_chunks_leased",
            "gauge",
            "Chunks a worker holds a lease on.",
        ),
        (
            "bspvt_worker_chunks_done_total",
            "counter",
            "Chunks a worker recorded.",
        ),
        (
            "bspvt_worker_last_seen_seconds",
            "gauge",
            "Seconds since a worker's last heartbeat.",
        ),
    ];
    for (name, kind, help) in series {
        let _ = writeln!(o, "# HELP {name} {help}\n# TYPE {name} {kind}");
        for w in &cl.workers {
            let id: String =
                w.id.chars()
                    .map(|c| {
                        if c == '"' || c == '\\' || c.is_control() {
                            '_'
                        } else {
                            c
                        }
                    })
                    .collect();
            let v = match name {
                "bspvt_worker_chunks_leased" => w.chunks_leased.to_string(),
                "bspvt_worker_chunks_done_total" => w.chunks_done.to_string(),
                _ => format!("{:.3}", w.last_seen_s),
            };
            let _ = writeln!(o, "{name}{{worker=\"{id}\"}} {v}");
        }
    }
}

/// Window over which `bspvt_chunks_per_second` is averaged.
const RATE_WINDOW: Duration = Duration::from_secs(60);

impl Default for Metrics {
    fn default() -> Self {
        Metrics {
            started: Instant::now(),
            responses: Default::default(),
            client_aborts: AtomicU64::new(0),
            store_probe_failures: AtomicU64::new(0),
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
            streams_shed: AtomicU64::new(0),
            bake_errors: AtomicU64::new(0),
            recent_chunks: Mutex::new(VecDeque::new()),
            latency: Mutex::new(BTreeMap::new()),
        }
    }
}

impl Metrics {
    pub(crate) fn response(&self, status: u16) {
        let class = (status / 100).clamp(1, 5) as usize;
        self.responses[class].fetch_add(1, Relaxed);
        if status == super::error::CLIENT_CLOSED_REQUEST {
            self.client_aborts.fetch_add(1, Relaxed);
        }
    }

    /// A request answered with `status` after `took` (to its response head: a streamed body
    /// is not included). `route` is the matched route template or `unmatched`.
    pub(crate) fn request_latency(
        &self,
        route: &str,
        method: &axum::http::Method,
        status: u16,
        took: Duration,
    ) {
        use axum::http::Method;
        let method = match *method {
            Method::GET => "GET",
            Method::POST => "POST",
            Method::DELETE => "DELETE",
            Method::HEAD => "HEAD",
            Method::OPTIONS => "OPTIONS",
            Method::PUT => "PUT",
            Method::PATCH => "PATCH",
            _ => "other",
        };
        let class = (status / 100).clamp(1, 5);
        let s = took.as_secs_f64();
        let i = LATENCY_BUCKETS_S
            .iter()
            .position(|&b| s <= b)
            .unwrap_or(LATENCY_BUCKETS_S.len());
        let mut m = self.latency.lock().unwrap_or_else(|p| p.into_inner());
        let h = m.entry((route.to_string(), method, class)).or_default();
        h.buckets[i] += 1;
        h.sum_s += s;
        h.count += 1;
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
            "bspvt_memory_budget_bytes",
            "gauge",
            "Memory the service plans for (memory_budget_mib).",
            g.memory_budget_bytes.to_string(),
        );
        one(
            "bspvt_memory_reserved_bytes",
            "gauge",
            "Estimated peak memory reserved now by the idle service, uploads being parsed and scenes being baked.",
            g.memory_reserved_bytes.to_string(),
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
            "# HELP bspvt_streams_shed_total Idle event streams ended to give their slot to a new stream.\n# TYPE bspvt_streams_shed_total counter\nbspvt_streams_shed_total {}",
            self.streams_shed.load(Relaxed)
        );
        if let Some(busy) = g.gpu_busy_seconds {
            let _ = writeln!(
                o,
                "# HELP bspvt_gpu_busy_seconds_total Seconds this process's GPU had at least one bake dispatch in flight (upload to read-back); its rate is the GPU's utilisation by the bake.\n# TYPE bspvt_gpu_busy_seconds_total counter\nbspvt_gpu_busy_seconds_total {busy:.3}"
            );
        }
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
        let _ = writeln!(
            o,
            "# HELP bspvt_http_client_aborts_total Requests whose client closed the connection before its body ended (answered 499, nginx's convention, and counted as 4xx: not a server error).\n# TYPE bspvt_http_client_aborts_total counter\nbspvt_http_client_aborts_total {}",
            self.client_aborts.load(Relaxed)
        );
        self.render_latency(&mut o);
        if let Some(cl) = &g.cluster {
            let _ = writeln!(
                o,
                "# HELP bspvt_store_probe_failures_total Health probes (/healthz) that found the object store failing (an error, a 5xx or no answer within 2 s); its requests meanwhile are retried.\n# TYPE bspvt_store_probe_failures_total counter\nbspvt_store_probe_failures_total {}",
                self.store_probe_failures.load(Relaxed)
            );
            render_cluster(&mut o, cl);
        }
        o
    }

    fn render_latency(&self, o: &mut String) {
        let name = "bspvt_http_request_duration_seconds";
        let _ = writeln!(
            o,
            "# HELP {name} Time from a request's arrival to its response head, by route template, method and status class.\n# TYPE {name} histogram"
        );
        let m = self.latency.lock().unwrap_or_else(|p| p.into_inner());
        for ((route, method, class), h) in m.iter() {
            // Route templates are the router's own strings: no quote or backslash to escape.
            let labels = format!("route=\"{route}\",method=\"{method}\",class=\"{class}xx\"");
            let mut cumulative = 0;
            for (bound, n) in LATENCY_BUCKETS_S.iter().zip(&h.buckets) {
                cumulative += n;
                let _ = writeln!(o, "{name}_bucket{{{labels},le=\"{bound}\"}} {cumulative}");
            }
            let _ = writeln!(o, "{name}_bucket{{{labels},le=\"+Inf\"}} {}", h.count);
            let _ = writeln!(o, "{name}_sum{{{labels}}} {:.6}", h.sum_s);
            let _ = writeln!(o, "{name}_count{{{labels}}} {}", h.count);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exposition_has_help_type_and_values() {
        let m = Metrics::default();
        m.response(404);
        let get = axum::http::Method::GET;
        m.request_latency("/healthz", &get, 200, Duration::from_micros(300));
        m.request_latency("/healthz", &get, 200, Duration::from_millis(30));
        m.request_latency("/healthz", &get, 200, Duration::from_secs(100));
        m.chunk_baked(64, Duration::from_millis(5));
        let t = m.render(&Gauges {
            scenes_queued: 3,
            ..Gauges::default()
        });
        assert!(t.contains("bspvt_http_responses_total{class=\"4xx\"} 1\n"));
        assert!(t.contains("bspvt_chunks_baked_total 1\n"));
        assert!(t.contains("bspvt_queue_depth_scenes 3\n"));
        // Cumulative buckets: 0.3 ms in the first, 30 ms from le=0.05 on, 100 s only in +Inf.
        let h = |le: &str| {
            metric_value(
                &t,
                &format!(
                    "bspvt_http_request_duration_seconds_bucket{{route=\"/healthz\",method=\"GET\",class=\"2xx\",le=\"{le}\"}}"
                ),
            )
        };
        assert_eq!(
            [h("0.001"), h("0.025"), h("0.05"), h("60"), h("+Inf")],
            [1.0, 1.0, 2.0, 2.0, 3.0]
        );
        assert_eq!(
            metric_value(
                &t,
                "bspvt_http_request_duration_seconds_count{route=\"/healthz\",method=\"GET\",class=\"2xx\"}"
            ),
            3.0
        );
        for line in t.lines().filter(|l| !l.starts_with('#')) {
            let (name, value) = line.rsplit_once(' ').expect("name value");
            assert!(value.parse::<f64>().is_ok(), "{line}");
            let base = name.split('{').next().expect("name");
            let family = ["_bucket", "_sum", "_count"]
                .iter()
                .find_map(|s| base.strip_suffix(s))
                .filter(|f| t.contains(&format!("# TYPE {f} histogram")))
                .unwrap_or(base);
            assert!(
                t.contains(&format!("# TYPE {family} ")),
                "{base} has no TYPE"
            );
        }
    }

    fn metric_value(t: &str, series: &str) -> f64 {
        t.lines()
            .find_map(|l| l.strip_prefix(series).and_then(|v| v.strip_prefix(' ')))
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("{series} missing in\n{t}"))
    }
}
