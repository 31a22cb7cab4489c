//! Bringing the memory a tick touches into the cache ahead of it, for a driver that warms its loop before
//! a deadline (`crate::driver::rehearsal`).

use super::*;

impl<S: Space> VeCore<S> {
    /// Prefetches the per-user state the next tick reads first (users and couplings, each one contiguous
    /// block) and the state vectors.
    pub fn prefetch(&self) {
        prefetch(&self.users);
        prefetch(&self.couplings);
        prefetch(self.q.as_slice());
        prefetch(self.qd.as_slice());
    }
}

/// Asks the core to bring `items`' memory into its nearest cache ahead of use: a hint, nothing is read (on
/// targets without the instruction nothing happens).
pub fn prefetch<T>(items: &[T]) {
    #[cfg(target_arch = "x86_64")]
    each_line(items, |line| {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // SAFETY: a prefetch never faults and reads nothing; the address is inside the slice.
        unsafe { _mm_prefetch(line.cast::<i8>(), _MM_HINT_T0) };
    });
    #[cfg(not(target_arch = "x86_64"))]
    let _ = items;
}

/// Asks the core to bring `items`' memory into its nearest cache for writing (`PREFETCHW`: the line is
/// taken exclusive, so the store that follows does not first have to take it from the core that last held
/// it); a hint, nothing is read or written (on targets without the instruction nothing happens).
pub fn prefetch_for_write<T>(items: &[T]) {
    #[cfg(target_arch = "x86_64")]
    each_line(items, |line| {
        // SAFETY: a prefetch never faults, reads and writes nothing; the address is inside the slice.
        // CPUs without PREFETCHW (before Broadwell) execute it as a no-op.
        unsafe { std::arch::asm!("prefetchw [{0}]", in(reg) line, options(nostack, readonly, preserves_flags)) };
    });
    #[cfg(not(target_arch = "x86_64"))]
    let _ = items;
}

/// Calls `hint` with an address in each 64-byte cache line of `items`' memory.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn each_line<T>(items: &[T], hint: impl Fn(*const u8)) {
    let start = items.as_ptr().cast::<u8>();
    for offset in (0..std::mem::size_of_val(items)).step_by(64) {
        hint(start.wrapping_add(offset));
    }
}
