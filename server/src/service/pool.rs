//! The bake's thread pool, at background priority: on a machine that also runs a viewer (the
//! embedded service under `bspvt demo` or `view`, a workstation that serves its own scenes)
//! or answers requests, the bake takes the cores the interactive work leaves, and an idle
//! machine bakes as fast as before. Linux schedules each thread by its own nice value (CFS
//! weights: nice 10 weighs 110 against nice 0's 1,024), so only the pool's threads are
//! lowered, not the API's; elsewhere the setting does nothing. docs/service.md,
//! "Configuration" (`bake_nice`).

use anyhow::{Context, Result};

/// The nice value a bake thread adds to its own by default.
pub(crate) const DEFAULT_NICE: i32 = 10;

/// How the bake pool runs.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PoolSettings {
    /// Threads (0: one per core).
    pub(crate) threads: usize,
    /// Added to each pool thread's nice value (clamped to 19; 0: as the process).
    pub(crate) nice: i32,
}

impl PoolSettings {
    /// The pool, its threads named `bake-pool-N`, each lowered by `nice` as it starts.
    pub(crate) fn build(self) -> Result<rayon::ThreadPool> {
        let nice = self.nice;
        rayon::ThreadPoolBuilder::new()
            .num_threads(self.threads)
            .thread_name(|i| format!("bake-pool-{i}"))
            .start_handler(move |_| lower_this_thread(nice))
            .build()
            .context("cannot start the bake thread pool")
    }
}

/// Adds `nice` to the calling thread's nice value (Linux: per thread). Raising it needs no
/// privilege; a failure leaves the thread as it was and says so in the log.
fn lower_this_thread(nice: i32) {
    #[cfg(target_os = "linux")]
    if nice > 0 {
        use rustix::process::{getpriority_process, setpriority_process};
        let tid = Some(rustix::thread::gettid());
        let now = getpriority_process(tid).unwrap_or(0);
        if let Err(e) = setpriority_process(tid, (now + nice).min(19)) {
            tracing::debug!("the bake thread keeps its priority: {e}");
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = nice;
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    #[test]
    fn the_pools_threads_run_lowered_and_the_caller_does_not() {
        let tid = || Some(rustix::thread::gettid());
        let caller = rustix::process::getpriority_process(tid()).expect("own priority");
        let pool = PoolSettings {
            threads: 2,
            nice: 5,
        }
        .build()
        .expect("a pool");
        let inside = pool.install(|| rustix::process::getpriority_process(tid()).expect("prio"));
        assert_eq!(inside, (caller + 5).min(19));
        let after = rustix::process::getpriority_process(tid()).expect("own priority");
        assert_eq!(after, caller, "only the pool's threads are lowered");
        let plain = PoolSettings {
            threads: 1,
            nice: 0,
        }
        .build()
        .expect("a pool");
        assert_eq!(
            plain.install(|| rustix::process::getpriority_process(tid()).expect("prio")),
            caller
        );
    }
}
