//! The memory budget: uploads being parsed and scenes being baked reserve their estimated
//! peak memory before they start, so that the sum of what runs at once stays under a
//! configured figure instead of growing with whatever clients send.
//!
//! Guarantees:
//! - a reservation is released when dropped (an error path cannot leak budget);
//! - nothing reserves more than the budget: an upload or a scene that could never fit is
//!   refused with its estimate and the budget (413 at submission, `failed` at bake time);
//! - the estimates are upper bounds fitted to measurements (`examples/memory_probe.rs`;
//!   the figures and the formulas are in docs/service.md, "Memory budget").

use std::sync::{Arc, Mutex, Weak};

/// Bytes in a MiB.
pub(crate) const MIB: u64 = 1 << 20;

/// Resident memory of the idle service (runtime, database, thread stacks), always reserved.
pub(crate) const BASE_BYTES: u64 = 64 * MIB;

/// Peak memory of parsing an upload, beyond its body: the decompressed file (for `.zst`)
/// plus the importer's working set, which the probe measured at most 2.9× the mesh file's
/// bytes (OBJ text; binary PLY and glB less). Bounded from the file size alone because the
/// counts are not known before the parse.
pub(crate) fn parse_bytes(decompressed: u64) -> u64 {
    decompressed.saturating_mul(4)
}

/// Peak memory of baking a scene of `vertices` and `triangles` on `threads` bake threads
/// with `face_res`² cube-map faces: the mesh, its BVHs (built on the bake's threads, whose
/// reinsertion pass holds a candidate per node), adjacency and ray origins, plus each
/// thread's cube map and fitting buffers (measured by the probe; docs/service.md).
pub(crate) fn bake_bytes(vertices: u64, triangles: u64, face_res: u32, threads: usize) -> u64 {
    let per_thread = 6 * u64::from(face_res).pow(2) * 64 + 4 * MIB;
    vertices
        .saturating_mul(200)
        .saturating_add(triangles.saturating_mul(400))
        .saturating_add((threads as u64).saturating_mul(per_thread))
        .saturating_add(16 * MIB)
}

/// Half the machine's memory (or of the cgroup limit when lower), in MiB; 2048 when neither
/// can be read.
pub(crate) fn default_budget_mib() -> u64 {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        s.lines()
            .find_map(|l| l.strip_prefix("MemTotal:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            .map(|kib| kib * 1024)
    });
    let cgroup = std::fs::read_to_string("/sys/fs/cgroup/memory.max")
        .ok()
        .and_then(|s| s.trim().parse::<u64>().ok());
    match (meminfo, cgroup) {
        (Some(m), Some(c)) => m.min(c) / 2 / MIB,
        (Some(m), None) => m / 2 / MIB,
        (None, Some(c)) => c / 2 / MIB,
        (None, None) => 2048,
    }
}

/// Why a reservation was not granted.
#[derive(Debug)]
pub(crate) enum Refusal {
    /// More than the whole budget: it can never run here.
    Never { needed: u64, budget: u64 },
    /// Not now: other work holds the budget.
    Busy {
        needed: u64,
        available: u64,
        budget: u64,
    },
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mib = |b: &u64| b.div_ceil(MIB);
        match self {
            Refusal::Never { needed, budget } => write!(
                f,
                "needs an estimated {} MiB of memory; the server's memory budget is {} MiB \
                 (memory_budget_mib)",
                mib(needed),
                mib(budget)
            ),
            Refusal::Busy {
                needed,
                available,
                budget,
            } => write!(
                f,
                "needs an estimated {} MiB of memory; {} of the server's {} MiB are free now",
                mib(needed),
                mib(available),
                mib(budget)
            ),
        }
    }
}

/// The budget and what is reserved from it.
pub(crate) struct MemoryBudget {
    total: u64,
    used: Mutex<u64>,
    /// Called after every release (the scheduler waits for room to start a scene).
    on_release: Mutex<Option<Box<dyn Fn() + Send + Sync>>>,
}

impl MemoryBudget {
    /// A budget of `total` bytes, of which [`BASE_BYTES`] are the idle service's.
    pub(crate) fn new(total: u64) -> Arc<MemoryBudget> {
        Arc::new(MemoryBudget {
            total,
            used: Mutex::new(BASE_BYTES.min(total)),
            on_release: Mutex::new(None),
        })
    }

    pub(crate) fn total(&self) -> u64 {
        self.total
    }

    /// Bytes reserved now (the base included).
    pub(crate) fn used(&self) -> u64 {
        *self.used.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Calls `f` after every release.
    pub(crate) fn set_on_release(&self, f: impl Fn() + Send + Sync + 'static) {
        *self.on_release.lock().unwrap_or_else(|p| p.into_inner()) = Some(Box::new(f));
    }

    /// Whether `bytes` could ever be reserved.
    pub(crate) fn check_fits(&self, bytes: u64) -> Result<(), Refusal> {
        let room = self.total.saturating_sub(BASE_BYTES.min(self.total));
        if bytes > room {
            return Err(Refusal::Never {
                needed: bytes,
                budget: self.total,
            });
        }
        Ok(())
    }

    /// Reserves `bytes` now, or says why not.
    pub(crate) fn try_reserve(self: &Arc<Self>, bytes: u64) -> Result<Reservation, Refusal> {
        self.check_fits(bytes)?;
        let mut used = self.used.lock().unwrap_or_else(|p| p.into_inner());
        let available = self.total.saturating_sub(*used);
        if bytes > available {
            return Err(Refusal::Busy {
                needed: bytes,
                available,
                budget: self.total,
            });
        }
        *used += bytes;
        Ok(Reservation {
            budget: Arc::downgrade(self),
            bytes,
        })
    }

    fn release(&self, bytes: u64) {
        give_back_freed();
        {
            let mut used = self.used.lock().unwrap_or_else(|p| p.into_inner());
            *used = used.saturating_sub(bytes);
        }
        if let Some(f) = self
            .on_release
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
        {
            f();
        }
    }
}

/// Bytes held from a [`MemoryBudget`] until dropped.
pub(crate) struct Reservation {
    budget: Weak<MemoryBudget>,
    bytes: u64,
}

impl Reservation {
    pub(crate) fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Grows the reservation to `bytes` in all (never shrinks it), or says why not; on
    /// refusal the reservation is unchanged.
    pub(crate) fn grow_to(&mut self, bytes: u64) -> Result<(), Refusal> {
        if bytes <= self.bytes {
            return Ok(());
        }
        let Some(budget) = self.budget.upgrade() else {
            return Ok(());
        };
        let extra = budget
            .try_reserve(bytes - self.bytes)
            .map_err(|r| match r {
                Refusal::Never { budget: b, .. } => Refusal::Never {
                    needed: bytes,
                    budget: b,
                },
                Refusal::Busy {
                    available,
                    budget: b,
                    ..
                } => Refusal::Busy {
                    needed: bytes,
                    available: available + self.bytes,
                    budget: b,
                },
            })?;
        self.bytes += extra.bytes;
        std::mem::forget(extra);
        Ok(())
    }
}

impl Drop for Reservation {
    fn drop(&mut self) {
        if let Some(b) = self.budget.upgrade() {
            b.release(self.bytes);
        }
    }
}

/// Returns the allocator's free memory to the system (glibc's `malloc_trim`). glibc keeps
/// what a thread freed in that thread's arena; after a parse on one thread and a bake on
/// others, the resident set would hold both unless the first is given back. Called when a
/// reservation's work ends; a no-op on other C libraries, and with `BSPVT_MALLOC_TRIM=0` (to
/// measure the resident set without it: `server/examples/soak.rs --no-trim`).
pub(crate) fn give_back_freed() {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    if !*ON.get_or_init(|| std::env::var("BSPVT_MALLOC_TRIM").map_or(true, |v| v != "0")) {
        return;
    }
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[allow(unsafe_code)]
    // SAFETY: `malloc_trim` takes no pointers, is thread-safe (it locks each arena) and only
    // releases free pages.
    unsafe {
        libc::malloc_trim(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reservations_add_up_and_release_on_drop() {
        let b = MemoryBudget::new(BASE_BYTES + 100);
        let r1 = b.try_reserve(60).expect("fits");
        assert!(matches!(b.try_reserve(50), Err(Refusal::Busy { .. })));
        assert!(matches!(b.try_reserve(101), Err(Refusal::Never { .. })));
        let mut r2 = b.try_reserve(40).expect("fits");
        assert!(r2.grow_to(41).is_err());
        assert_eq!(r2.bytes(), 40);
        drop(r1);
        r2.grow_to(90).expect("room again");
        assert_eq!(b.used(), BASE_BYTES + 90);
        drop(r2);
        assert_eq!(b.used(), BASE_BYTES);
    }

    #[test]
    fn release_wakes_the_listener() {
        let b = MemoryBudget::new(BASE_BYTES + 10);
        let woken = Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let w = woken.clone();
        b.set_on_release(move || {
            w.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        });
        drop(b.try_reserve(10).expect("fits"));
        assert_eq!(woken.load(std::sync::atomic::Ordering::Relaxed), 1);
    }
}
