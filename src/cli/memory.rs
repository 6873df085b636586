//! Allocator settings for the whole process, set once at start.
//!
//! The binaries' global allocator is mimalloc (see `main.rs`): measured on
//! the full-size one-shot run it both faults fewer pages and keeps less
//! memory than the hand-written huge-page allocator it replaced (0.76 s and
//! 850 MB peak against 1.16 s and 1.16 GB, docs/benchmarks-history.md). What follows
//! tunes glibc's malloc, which C code in the process still uses.
//!
//! A full-resolution result is about 0.75 GB of maps and cloud in buffers of
//! 12 MB and more. glibc serves such buffers with fresh `mmap`s and returns
//! them on free, so every engine run faults every page in again; on the
//! development VM a 4 KiB page fault costs about 3 µs, a quarter of a
//! full-size run (see docs/benchmarks-history.md). Serving buffers up to glibc's largest
//! threshold (32 MiB) from the heap and never trimming it lets each re-run
//! (a threshold drag, a set toggle) reuse the previous result's pages. The
//! price is that memory freed by a run stays with the process until it exits,
//! which for an app that recomputes the same measurement is the point.

/// Keeps freed buffers of up to 32 MiB in the process for reuse. Call once,
/// before any large allocation; it does nothing outside glibc.
pub fn keep_freed_memory_for_reuse() {
    crate::platform::keep_freed_malloc_memory();
}

/// mimalloc's number for its purge delay (`mi_option_purge_delay` in
/// `mimalloc.h`, the same in its v2 and v3).
const MI_OPTION_PURGE_DELAY: std::ffi::c_int = 15;

/// Keeps the pages mimalloc frees in the process instead of returning them
/// to the OS after its purge delay, for processes that run the engine again
/// and again on inputs of one size (the watch, the app): the next part's
/// buffers then land on pages already faulted in. At full size a fresh run
/// spends about a third of its CPU time having the kernel zero new pages;
/// kept, a watched part takes about 0.8 s less (docs/benchmarks-history.md). The
/// resident size stays at the largest run's instead of falling between runs;
/// it does not grow, since the freed blocks are reused.
pub fn keep_freed_pages_between_runs() {
    // SAFETY: mi_option_set stores an option's value; mimalloc reads it at
    // each purge, so setting it at any time is sound.
    unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1) }
}

/// Both settings, as the app and the watch run with them: for benchmarks
/// and examples that measure the engine run after run as the app does.
pub fn keep_memory_as_the_app_does() {
    keep_freed_memory_for_reuse();
    keep_freed_pages_between_runs();
}
