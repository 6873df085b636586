//! Allocator settings for the whole process, set once at start.
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

/// The global allocator of Sheen's processes: buffers of 4 MiB and more (the
/// per-pixel maps of a full-size image are 3 to 12 MiB each, the sample
/// stacks 37 MiB) are mapped on 2 MiB boundaries and marked for transparent
/// huge pages (`MADV_HUGEPAGE`), so a one-shot run faults them in 2 MiB at a
/// time instead of 4 KiB: a full-size reconstruction touched about 260,000
/// fresh pages; with huge pages it takes 16,000 faults and a one-shot run
/// about 0.3 s less on the development VM when nothing else runs (under
/// load the kernel's compaction for huge pages can eat the gain). Freed blocks are
/// kept (up to 2 GiB) and handed out again for the same size, so the app's
/// re-run after a parameter change neither faults nor zeroes them again, as
/// [`keep_freed_memory_for_reuse`] arranges for the smaller ones. Smaller
/// blocks, and every block on other platforms, go to the system allocator.
pub struct HugePageAlloc;

#[cfg(all(target_os = "linux", target_env = "gnu"))]
mod huge {
    /// Transparent huge page size on x86-64 and most aarch64 kernels.
    pub const HUGE_PAGE: usize = 2 << 20;
    /// Blocks from this size on are mapped with huge pages.
    pub const THRESHOLD: usize = 4 << 20;

    pub fn is_huge(size: usize, align: usize) -> bool {
        size >= THRESHOLD && align <= HUGE_PAGE
    }

    pub fn mapped_len(size: usize) -> usize {
        size.div_ceil(HUGE_PAGE) * HUGE_PAGE
    }

    /// Freed mappings kept for reuse: `(address, mapped length)`, 0 = empty
    /// slot. A fixed array: the allocator must not allocate while it holds the lock.
    static KEPT: std::sync::Mutex<[(usize, usize); 128]> = std::sync::Mutex::new([(0, 0); 128]);
    /// Most bytes of freed mappings kept.
    const KEPT_MAX_BYTES: usize = 2 << 30;

    fn kept() -> std::sync::MutexGuard<'static, [(usize, usize); 128]> {
        KEPT.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// A block of `size` bytes on a huge-page boundary (zeroed if asked), or null.
    pub fn map(size: usize, zeroed: bool) -> *mut u8 {
        let len = mapped_len(size);
        let reused = kept().iter_mut().find(|slot| slot.0 != 0 && slot.1 == len).map(|slot| std::mem::take(slot).0);
        if let Some(address) = reused {
            let ptr = address as *mut u8;
            if zeroed {
                // SAFETY: the kept mapping is `len >= size` bytes, owned by no one else.
                unsafe { std::ptr::write_bytes(ptr, 0, size) };
            }
            return ptr;
        }
        fresh(len)
    }

    /// A fresh zeroed mapping of `len` bytes (a multiple of the huge page).
    fn fresh(len: usize) -> *mut u8 {
        // Over-map by one huge page and trim, so the block starts on a boundary.
        // SAFETY: an anonymous private mapping touches no existing memory.
        let raw = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len + HUGE_PAGE,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
                -1,
                0,
            )
        };
        if raw == libc::MAP_FAILED {
            return std::ptr::null_mut();
        }
        let start = raw as usize;
        let aligned = start.next_multiple_of(HUGE_PAGE);
        // SAFETY: the head and the tail lie inside the mapping just made and
        // outside the block handed out; madvise only advises.
        unsafe {
            if aligned > start {
                libc::munmap(raw, aligned - start);
            }
            let tail = start + len + HUGE_PAGE - (aligned + len);
            if tail > 0 {
                libc::munmap((aligned + len) as *mut libc::c_void, tail);
            }
            libc::madvise(aligned as *mut libc::c_void, len, libc::MADV_HUGEPAGE);
        }
        aligned as *mut u8
    }

    /// # Safety
    /// `ptr` must come from [`map`] with the same `size`.
    pub unsafe fn unmap(ptr: *mut u8, size: usize) {
        let len = mapped_len(size);
        {
            let mut kept = kept();
            let total: usize = kept.iter().filter(|s| s.0 != 0).map(|s| s.1).sum();
            if total + len <= KEPT_MAX_BYTES
                && let Some(slot) = kept.iter_mut().find(|s| s.0 == 0)
            {
                *slot = (ptr as usize, len);
                return;
            }
        }
        // SAFETY: per the contract, this is exactly the mapping `map` made.
        unsafe { libc::munmap(ptr.cast(), len) };
    }
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
// SAFETY: every block is served either by the system allocator or by a
// mapping of at least its size on a 2 MiB boundary (which satisfies any
// alignment up to 2 MiB), and is freed by the one that served it: which one
// follows from the layout alone.
unsafe impl std::alloc::GlobalAlloc for HugePageAlloc {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        if huge::is_huge(layout.size(), layout.align()) {
            huge::map(layout.size(), false)
        } else {
            // SAFETY: forwarded with the caller's layout.
            unsafe { std::alloc::System.alloc(layout) }
        }
    }

    unsafe fn alloc_zeroed(&self, layout: std::alloc::Layout) -> *mut u8 {
        if huge::is_huge(layout.size(), layout.align()) {
            huge::map(layout.size(), true)
        } else {
            // SAFETY: forwarded with the caller's layout.
            unsafe { std::alloc::System.alloc_zeroed(layout) }
        }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        if huge::is_huge(layout.size(), layout.align()) {
            // SAFETY: a huge layout was served by `huge::map` with this size.
            unsafe { huge::unmap(ptr, layout.size()) }
        } else {
            // SAFETY: a small layout was served by the system allocator.
            unsafe { std::alloc::System.dealloc(ptr, layout) }
        }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        let (old_huge, new_huge) =
            (huge::is_huge(layout.size(), layout.align()), huge::is_huge(new_size, layout.align()));
        if !old_huge && !new_huge {
            // SAFETY: both sizes are the system allocator's.
            return unsafe { std::alloc::System.realloc(ptr, layout, new_size) };
        }
        if old_huge && new_huge && huge::mapped_len(new_size) == huge::mapped_len(layout.size()) {
            return ptr;
        }
        // SAFETY: the new layout has the old alignment and a non-zero size.
        let new_layout = unsafe { std::alloc::Layout::from_size_align_unchecked(new_size, layout.align()) };
        // SAFETY: as for `alloc`.
        let new_ptr = unsafe { self.alloc(new_layout) };
        if !new_ptr.is_null() {
            // SAFETY: both blocks are valid for the smaller size and do not overlap.
            unsafe {
                std::ptr::copy_nonoverlapping(ptr, new_ptr, layout.size().min(new_size));
                self.dealloc(ptr, layout);
            }
        }
        new_ptr
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
// SAFETY: forwards everything to the system allocator.
unsafe impl std::alloc::GlobalAlloc for HugePageAlloc {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        unsafe { std::alloc::System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: std::alloc::Layout) -> *mut u8 {
        unsafe { std::alloc::System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        unsafe { std::alloc::System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        unsafe { std::alloc::System.realloc(ptr, layout, new_size) }
    }
}

#[cfg(test)]
mod tests {
    use std::alloc::{GlobalAlloc, Layout};

    use super::HugePageAlloc;

    #[test]
    fn large_blocks_are_zeroed_aligned_and_survive_growing_and_shrinking() {
        let a = HugePageAlloc;
        for size in [100, 5 << 20, (5 << 20) + 1] {
            let layout = Layout::from_size_align(size, 64).expect("layout");
            // SAFETY: a non-zero layout; the block is written within its size and freed once.
            unsafe {
                let p = a.alloc_zeroed(layout);
                assert!(!p.is_null());
                assert_eq!(p as usize % 64, 0);
                let block = std::slice::from_raw_parts_mut(p, size);
                assert!(block.iter().all(|&b| b == 0), "zeroed");
                block.iter_mut().enumerate().for_each(|(i, b)| *b = (i % 251) as u8);
                // Grow across the threshold and back: the contents move along.
                let q = a.realloc(p, layout, 9 << 20);
                let grown = std::slice::from_raw_parts(q, size);
                assert!(grown.iter().enumerate().all(|(i, &b)| b == (i % 251) as u8), "size {size} grown");
                let big = Layout::from_size_align(9 << 20, 64).expect("layout");
                let r = a.realloc(q, big, 50);
                let shrunk = std::slice::from_raw_parts(r, 50);
                assert!(shrunk.iter().enumerate().all(|(i, &b)| b == (i % 251) as u8));
                a.dealloc(r, Layout::from_size_align(50, 64).expect("layout"));
            }
        }
    }

    #[test]
    fn a_kept_block_is_handed_out_again_and_zeroed_when_asked() {
        let a = HugePageAlloc;
        let layout = Layout::from_size_align(6 << 20, 8).expect("layout");
        // SAFETY: a non-zero layout; each block is written within its size and freed once.
        unsafe {
            let p = a.alloc(layout);
            std::ptr::write_bytes(p, 0xAB, layout.size());
            a.dealloc(p, layout);
            // Other tests allocate concurrently: the block may go to them, but
            // whatever block comes back must be zeroed.
            let q = a.alloc_zeroed(layout);
            assert!(std::slice::from_raw_parts(q, layout.size()).iter().all(|&b| b == 0));
            a.dealloc(q, layout);
        }
    }
}
