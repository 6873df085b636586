//! Every call into the operating system beyond `std`, in one room.
//!
//! Each function has one implementation per platform family, chosen by
//! `cfg`, and a portable fallback that keeps the program correct where the
//! call does not exist: the calls here are speed-ups or hints (direct I/O,
//! write-back hints, thread priorities, allocator settings, resident
//! memory), never something a result depends on. `libc` is a dependency
//! only for Linux with glibc (`Cargo.toml`), so every use of it sits in
//! `linux_gnu`; the tidy test `tests/integration/tidy.rs` fails when a
//! `libc::` or `std::os::unix` use appears outside such a gated item, since
//! this machine cannot build for another target to find out.

use std::fs::File;

#[cfg(all(target_os = "linux", target_env = "gnu"))]
mod linux_gnu {
    use std::fs::File;
    use std::os::fd::AsRawFd as _;

    pub fn set_direct_io(file: &File, on: bool) -> bool {
        let fd = file.as_raw_fd();
        // SAFETY: F_GETFL and F_SETFL read and set the open file's status
        // flags; they touch no memory of this process.
        unsafe {
            let flags = libc::fcntl(fd, libc::F_GETFL);
            if flags < 0 {
                return false;
            }
            let wanted = if on { flags | libc::O_DIRECT } else { flags & !libc::O_DIRECT };
            libc::fcntl(fd, libc::F_SETFL, wanted) == 0 && on
        }
    }

    pub fn hint_writeback(file: &File) {
        // SAFETY: sync_file_range only starts the write-out of the open
        // file's dirty pages (offset 0, length 0: all of them); it reads
        // and writes no memory of this process. Its result is advice:
        // an error shows again at the final sync.
        unsafe {
            libc::sync_file_range(file.as_raw_fd(), 0, 0, libc::SYNC_FILE_RANGE_WRITE);
        }
    }

    pub fn page_bytes() -> Option<usize> {
        // SAFETY: sysconf only reads a system constant.
        usize::try_from(unsafe { libc::sysconf(libc::_SC_PAGESIZE) }).ok()
    }

    pub fn this_threads_niceness() -> Option<i32> {
        // SAFETY: gettid and getpriority only read the calling thread's
        // attributes; errno is cleared first because -1 is a valid niceness.
        unsafe {
            let tid = libc::gettid() as libc::id_t;
            *libc::__errno_location() = 0;
            let nice = libc::getpriority(libc::PRIO_PROCESS, tid);
            if nice == -1 && *libc::__errno_location() != 0 {
                return None;
            }
            Some(nice)
        }
    }

    pub fn set_this_threads_niceness(nice: i32) {
        // SAFETY: setpriority on the calling thread's own id changes only its
        // scheduling weight; lowering priority needs no privilege.
        unsafe {
            libc::setpriority(libc::PRIO_PROCESS, libc::gettid() as libc::id_t, nice);
        }
    }

    pub fn keep_freed_malloc_memory() {
        const MMAP_THRESHOLD_MAX_BYTES: libc::c_int = 32 * 1024 * 1024;
        // SAFETY: mallopt only changes allocator parameters; it is called
        // before the program starts other threads or allocates large blocks.
        unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_MAX_BYTES);
            libc::mallopt(libc::M_TRIM_THRESHOLD, libc::c_int::MAX);
        }
    }
}

/// Turns direct I/O (`O_DIRECT`) on or off for `file`; whether it is now on.
/// Elsewhere always off: writes go through the page cache.
pub fn set_direct_io(file: &File, on: bool) -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        linux_gnu::set_direct_io(file, on)
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        let _ = (file, on);
        false
    }
}

/// Asks the kernel to start writing `file`'s dirty pages to disk (Linux's
/// `sync_file_range`); elsewhere nothing, and the final sync writes them.
pub fn hint_writeback(file: &File) {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    linux_gnu::hint_writeback(file);
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    let _ = file;
}

/// Resident memory of this process in bytes (Linux; `None` elsewhere).
pub fn resident_bytes() -> Option<usize> {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
        let pages: usize = statm.split_whitespace().nth(1)?.parse().ok()?;
        Some(pages * linux_gnu::page_bytes()?)
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        None
    }
}

/// The niceness of the calling thread, where the system has one per thread
/// (Linux); `None` elsewhere or if it cannot be read.
pub fn this_threads_niceness() -> Option<i32> {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        linux_gnu::this_threads_niceness()
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        None
    }
}

/// Sets the calling thread's niceness (19 is the lowest priority). Best
/// effort: where the system does not allow it, the thread keeps its priority.
pub fn set_this_threads_niceness(nice: i32) {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    linux_gnu::set_this_threads_niceness(nice);
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    let _ = nice;
}

/// What tells a folder from another made later under the same name: its
/// device and inode on Unix, its creation time elsewhere. `None` where the
/// folder cannot be read.
pub type FolderIdentity = (u64, u64);

pub fn folder_identity(path: &std::path::Path) -> Option<FolderIdentity> {
    let m = std::fs::metadata(path).ok()?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        Some((m.dev(), m.ino()))
    }
    #[cfg(not(unix))]
    {
        let t = m.created().ok()?.duration_since(std::time::UNIX_EPOCH).ok()?;
        Some((t.as_secs(), u64::from(t.subsec_nanos())))
    }
}

/// Keeps glibc malloc's freed buffers of up to 32 MiB in the process
/// (`cli::memory`); nothing outside glibc.
pub fn keep_freed_malloc_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    linux_gnu::keep_freed_malloc_memory();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fallbacks and the Linux calls alike leave a file writable and
    /// give plausible answers.
    #[test]
    fn the_hints_leave_a_file_writable_and_answer_plausibly() {
        use std::io::Write as _;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.bin");
        let mut file = File::create(&path).unwrap();
        let direct = set_direct_io(&file, false);
        assert!(!direct, "turning direct I/O off never reports it on");
        file.write_all(b"sheen").unwrap();
        hint_writeback(&file);
        file.sync_all().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"sheen");
        if cfg!(all(target_os = "linux", target_env = "gnu")) {
            assert!(resident_bytes().is_some_and(|b| b > 1 << 20), "a test process holds more than 1 MiB");
            assert!(this_threads_niceness().is_some_and(|n| (-20..=19).contains(&n)));
        } else {
            assert_eq!(resident_bytes(), None);
            assert_eq!(this_threads_niceness(), None);
        }
    }
}
