//! A cache-line prefetch: the one place the workspace asks the CPU for memory ahead of use.

/// Asks for the cache line holding `items[i]`, so that it is on its way when it is read
/// (out of range: nothing). A prefetch is a hint: it neither faults nor makes anything wait,
/// so a line that is not used after all costs only its fetch.
#[inline(always)]
pub fn prefetch<T>(items: &[T], i: usize) {
    if let Some(item) = items.get(i) {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `_mm_prefetch` reads nothing and cannot fault, whatever the address; SSE is
        // part of the x86-64 baseline.
        #[allow(unsafe_code)]
        unsafe {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                (item as *const T).cast(),
            );
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = item;
    }
}
