//! A counting global allocator with a cap, for the fuzzer's memory limit.
//!
//! Every allocation adds its size to a process-wide count of live bytes (deallocations subtract).
//! While a cap is set ([`set_cap`]), an allocation that would raise the live bytes above it is
//! refused: the breach is recorded ([`breached`]) and the allocator returns null, which Rust turns
//! into "memory allocation of N bytes failed" and an abort. The fuzzer runs its inputs in a child
//! process that a supervisor restarts, so a breach costs one restart and is reported with the
//! input, instead of the machine running out of memory or the whole fuzz run ending.
//!
//! Outside the fuzzer (gradcheck, check-deps) no cap is set and the cost is two relaxed atomic
//! operations per allocation.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

static LIVE: AtomicUsize = AtomicUsize::new(0);
static CAP: AtomicUsize = AtomicUsize::new(usize::MAX);
static BREACH: AtomicUsize = AtomicUsize::new(0);

/// The system allocator, counted and capped.
pub struct Counting;

// SAFETY: forwards to `System` with the caller's layout; only adds bookkeeping on atomics and
// returns null (which `GlobalAlloc` allows) when the cap would be exceeded.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if !reserve(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: same contract as ours.
        let p = unsafe { System.alloc(layout) };
        if p.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if !reserve(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: same contract as ours.
        let p = unsafe { System.alloc_zeroed(layout) };
        if p.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System` with this layout.
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let old = layout.size();
        if new_size > old && !reserve(new_size - old) {
            return std::ptr::null_mut();
        }
        // SAFETY: same contract as ours.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if p.is_null() {
            if new_size > old {
                LIVE.fetch_sub(new_size - old, Ordering::Relaxed);
            }
        } else if new_size < old {
            LIVE.fetch_sub(old - new_size, Ordering::Relaxed);
        }
        p
    }
}

/// Counts `size` more live bytes unless that exceeds the cap (then records the breach).
fn reserve(size: usize) -> bool {
    let before = LIVE.fetch_add(size, Ordering::Relaxed);
    if before.saturating_add(size) > CAP.load(Ordering::Relaxed) {
        LIVE.fetch_sub(size, Ordering::Relaxed);
        BREACH.store(size.max(1), Ordering::Relaxed);
        return false;
    }
    true
}

/// Bytes currently allocated by the whole process.
pub fn live() -> usize {
    LIVE.load(Ordering::Relaxed)
}

/// Refuses allocations that would raise the live bytes above `cap` (`usize::MAX`: no cap).
pub fn set_cap(cap: usize) {
    BREACH.store(0, Ordering::Relaxed);
    CAP.store(cap, Ordering::Relaxed);
}

/// The size of the last refused allocation since [`set_cap`], if any.
pub fn breached() -> Option<usize> {
    match BREACH.load(Ordering::Relaxed) {
        0 => None,
        n => Some(n),
    }
}
