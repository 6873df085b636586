//! Full-size per-pixel buffers, filled by every core.
//!
//! `vec![value; len]` fills on one thread. For a 2048x1536 map that is a
//! serial 12 MB memset of reused memory in a warm run, and in a fresh process
//! a serial run of page faults on new memory, while the other core waits
//! (the one-core gaps of a one-shot run's timeline, docs/benchmarks-history.md). Filling
//! in parallel bands halves both.

use rayon::prelude::*;

/// Elements per parallel band: large enough that a band's bookkeeping is
/// negligible, small enough that both cores share even a quarter-size map.
const MIN_BAND: usize = 1 << 16;

/// A vector of `len` copies of `value`, written by all of rayon's threads,
/// each a band at a time with the store loop a memset compiles to (rayon's
/// element-by-element collect took twice the memset's time).
pub fn filled<T: Copy + Send + Sync>(len: usize, value: T) -> Vec<T> {
    let mut v = Vec::with_capacity(len);
    v.spare_capacity_mut()[..len]
        .par_chunks_mut(MIN_BAND)
        .for_each(|band| band.fill(std::mem::MaybeUninit::new(value)));
    // SAFETY: the capacity holds at least `len` elements, and the bands
    // above cover the first `len` of them, each written with `value`.
    unsafe { v.set_len(len) };
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_filled_buffer_holds_exactly_len_copies_at_any_length() {
        for len in [0, 1, MIN_BAND - 1, MIN_BAND, 3 * MIN_BAND + 17] {
            let v = filled(len, f32::NAN);
            assert_eq!(v.len(), len);
            assert!(v.iter().all(|x| x.is_nan()), "len {len}");
            let w = filled(len, -1i8);
            assert_eq!(w.len(), len);
            assert!(w.iter().all(|&x| x == -1), "len {len}");
        }
    }
}
