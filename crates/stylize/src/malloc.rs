//! The C allocator's policy for the loop's large per-iteration buffers.
//!
//! Every text iteration allocates and frees buffers of several megabytes: the renders (8 views of
//! 512² RGB in `f32`: 25 MB), their grey values and per-view ids and colours, each guidance
//! evaluation's image gradient (25 MB), the renderer backward's grey gradients. glibc's `malloc`
//! serves blocks above `M_MMAP_THRESHOLD` (128 KiB, raised by itself up to 32 MiB as such blocks
//! are freed) with a fresh `mmap` and unmaps them on `free`, and gives the free memory at the top
//! of a heap back to the kernel once it exceeds `M_TRIM_THRESHOLD`. Either way the next
//! iteration's buffers are new pages, which the kernel must fault in and zero one 4 KiB page at a
//! time: on the 2-core machine of `docs/benchmarks.md` ("The loop") that was a quarter of one
//! iteration's work outside the UNets.
//!
//! [`retain_freed_buffers`] fixes both thresholds at process start, so freed buffers stay in the
//! process and are reused by the next iteration: the resident set stays at its peak instead of
//! shrinking between iterations (the run's peak does not change measurably: the ONNX Runtime
//! arena dominates it). It changes the allocator of the whole process, so it is a program's
//! decision (the `stylize` command line makes it), never taken by the library itself.

/// Largest block served from the heap instead of its own `mmap` (glibc's maximum for
/// `M_MMAP_THRESHOLD` on 64-bit targets: 32 MiB).
pub const MMAP_THRESHOLD: usize = 32 << 20;

/// Free memory kept at the top of a heap before it is returned to the kernel.
pub const TRIM_THRESHOLD: usize = 1 << 30;

/// Sets glibc's `M_MMAP_THRESHOLD` to [`MMAP_THRESHOLD`] and `M_TRIM_THRESHOLD` to
/// [`TRIM_THRESHOLD`] (see the module docs). Returns whether both were set: false on other
/// platforms and C libraries (nothing to do there), and false without touching anything when the
/// environment sets `GLIBC_TUNABLES` (the user's own allocator settings win).
///
/// Call it first thing in `main`, before other threads allocate.
pub fn retain_freed_buffers() -> bool {
    if std::env::var_os("GLIBC_TUNABLES").is_some() {
        return false;
    }
    set_thresholds()
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn set_thresholds() -> bool {
    let (Ok(mmap), Ok(trim)) = (
        libc::c_int::try_from(MMAP_THRESHOLD),
        libc::c_int::try_from(TRIM_THRESHOLD),
    ) else {
        return false;
    };
    // SAFETY: mallopt only changes two tuning parameters of glibc's allocator (it takes the
    // allocator's lock); it returns 1 on success and 0 for a value it refuses.
    #[allow(unsafe_code)]
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, mmap) == 1
            && libc::mallopt(libc::M_TRIM_THRESHOLD, trim) == 1
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn set_thresholds() -> bool {
    false
}

#[cfg(test)]
mod tests {
    #[test]
    fn glibc_accepts_both_thresholds() {
        // Runs in the test process: the thresholds only change how freed memory is kept.
        let expected = cfg!(all(target_os = "linux", target_env = "gnu"))
            && std::env::var_os("GLIBC_TUNABLES").is_none();
        assert_eq!(super::retain_freed_buffers(), expected);
    }
}
