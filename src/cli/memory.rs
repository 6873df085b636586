//! Allocator settings for the whole process, set once at start.
//!
//! The binaries' global allocator is mimalloc (see `main.rs`): measured on
//! the full-size one-shot run it both faults fewer pages and keeps less
//! memory than the hand-written huge-page allocator it replaced (0.76 s and
//! 850 MB peak against 1.16 s and 1.16 GB, BENCHMARKS.md). What follows
//! tunes glibc's malloc, which C code in the process still uses.
//!
//! A full-resolution result is about 0.75 GB of maps and cloud in buffers of
//! 12 MB and more. glibc serves such buffers with fresh `mmap`s and returns
//! them on free, so every engine run faults every page in again; on the
//! development VM a 4 KiB page fault costs about 3 µs, a quarter of a
//! full-size run (see BENCHMARKS.md). Serving buffers up to glibc's largest
//! threshold (32 MiB) from the heap and never trimming it lets each re-run
//! (a threshold drag, a set toggle) reuse the previous result's pages. The
//! price is that memory freed by a run stays with the process until it exits,
//! which for an app that recomputes the same measurement is the point.

/// Keeps freed buffers of up to 32 MiB in the process for reuse. Call once,
/// before any large allocation; it does nothing outside glibc.
pub fn keep_freed_memory_for_reuse() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        const MMAP_THRESHOLD_MAX_BYTES: libc::c_int = 32 * 1024 * 1024;
        // SAFETY: mallopt only changes allocator parameters; it is called
        // before the program starts other threads or allocates large blocks.
        unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_MAX_BYTES);
            libc::mallopt(libc::M_TRIM_THRESHOLD, libc::c_int::MAX);
        }
    }
}
