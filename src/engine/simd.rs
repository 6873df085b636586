//! Which vector instructions the per-pixel kernels are compiled for, chosen
//! once at run time from what the CPU has.
//!
//! The hot loops (the phase kernel, the order decisions) are written once as
//! plain Rust and compiled several times with `#[target_feature]`; the
//! compiler vectorises each copy for its instruction set. Every copy computes
//! the same IEEE operations in the same order (Rust never fuses a multiply
//! and an add on its own), so the maps are bit for bit the same whichever
//! copy runs; the tests compare them. AVX-512 matters even on cores that
//! split its 512-bit operations in two (AMD Zen 4): its mask registers
//! replace the pack-and-blend sequences that AVX2 needs for every comparison
//! of f64 lanes that ends in a byte or `u16` map.

use std::sync::atomic::{AtomicU8, Ordering};

/// An instruction set a kernel copy is compiled for, in increasing order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// The target's baseline (SSE2 on x86-64).
    Baseline = 0,
    /// AVX2 with FMA.
    Avx2 = 1,
    /// AVX-512 F, VL, BW and DQ (with AVX2 and FMA).
    Avx512 = 2,
}

impl Level {
    pub const ALL: [Level; 3] = [Level::Baseline, Level::Avx2, Level::Avx512];

    /// As [`LIMIT_VARIABLE`] and the run report spell it.
    pub fn name(self) -> &'static str {
        match self {
            Level::Baseline => "baseline",
            Level::Avx2 => "avx2",
            Level::Avx512 => "avx512",
        }
    }

    /// The level stored as `v`; `None` for a number that names none (the
    /// widest would run instructions nobody checked the CPU for).
    fn from_u8(v: u8) -> Option<Level> {
        Level::ALL.into_iter().find(|&l| l as u8 == v)
    }
}

/// The highest level the kernels may use: every level until lowered.
static LIMIT: AtomicU8 = AtomicU8::new(Level::Avx512 as u8);

/// Keeps the kernels at or below `level`: to compare the copies (tests,
/// benchmarks) or to rule out a CPU's wide instructions.
pub fn set_limit(level: Level) {
    LIMIT.store(level as u8, Ordering::Relaxed);
}

/// The environment variable that lowers the limit for a whole process
/// (`avx2` or `baseline`): for CPUs that slow down on wide instructions, and
/// to compare the copies in any front end.
pub const LIMIT_VARIABLE: &str = "SHEEN_SIMD";

/// A value of [`LIMIT_VARIABLE`] that names no level.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{LIMIT_VARIABLE}={value}: expected avx512, avx2 or baseline")]
pub struct UnknownLevel {
    /// The value as given (lossily decoded where it was not Unicode).
    pub value: String,
}

/// A limit as [`LIMIT_VARIABLE`] spells it (any case).
pub fn parse_limit(value: &str) -> Result<Level, UnknownLevel> {
    match value.to_ascii_lowercase().as_str() {
        "avx512" => Ok(Level::Avx512),
        "avx2" => Ok(Level::Avx2),
        "baseline" => Ok(Level::Baseline),
        _ => Err(UnknownLevel { value: value.to_string() }),
    }
}

/// Sets the limit from [`LIMIT_VARIABLE`] when it is set; a value that names
/// no level is an error, not ignored.
pub fn limit_from_env() -> Result<(), UnknownLevel> {
    match std::env::var(LIMIT_VARIABLE) {
        Err(std::env::VarError::NotPresent) => Ok(()),
        Err(std::env::VarError::NotUnicode(v)) => Err(UnknownLevel { value: format!("{v:?}") }),
        Ok(v) => parse_limit(&v).map(set_limit),
    }
}

/// The highest level this CPU supports, whatever the limit.
pub fn supported() -> Level {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        if has!("avx512f") && has!("avx512vl") && has!("avx512bw") && has!("avx512dq") && has!("avx2") && has!("fma") {
            return Level::Avx512;
        }
        if has!("avx2") && has!("fma") {
            return Level::Avx2;
        }
    }
    Level::Baseline
}

/// The level the kernels use now: what the CPU supports, within the limit.
#[inline]
pub fn level() -> Level {
    // Only `set_limit` stores the limit, always a level; were it ever
    // anything else, the baseline is the one copy every CPU runs.
    supported().min(Level::from_u8(LIMIT.load(Ordering::Relaxed)).unwrap_or(Level::Baseline))
}

/// Runs `kernel` compiled for [`level`]: the closure, marked
/// `#[inline(always)]` by the caller, is inlined into a copy of this function
/// per instruction set, so a loop inside it is vectorised for each.
#[inline(always)]
pub fn dispatch<R>(kernel: impl FnOnce() -> R) -> R {
    match level() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `level` is at most what the CPU supports.
        Level::Avx512 => unsafe { with_avx512(kernel) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above.
        Level::Avx2 => unsafe { with_avx2(kernel) },
        _ => kernel(),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx2,fma")]
fn with_avx512<R>(kernel: impl FnOnce() -> R) -> R {
    kernel()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn with_avx2<R>(kernel: impl FnOnce() -> R) -> R {
    kernel()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_level_never_exceeds_the_cpu_or_the_limit() {
        let cpu = supported();
        assert!(level() <= cpu);
        for l in Level::ALL {
            assert_eq!(Level::from_u8(l as u8), Some(l));
        }
        assert_eq!(Level::from_u8(Level::Avx512 as u8 + 1), None, "an unknown level is refused, not the widest");
    }

    #[test]
    fn the_limit_variable_names_a_level_or_is_refused() {
        assert_eq!(parse_limit("AVX2"), Ok(Level::Avx2));
        assert_eq!(parse_limit("avx512"), Ok(Level::Avx512));
        assert_eq!(parse_limit("baseline"), Ok(Level::Baseline));
        for l in Level::ALL {
            assert_eq!(parse_limit(l.name()), Ok(l));
        }
        let e = parse_limit("sse4").unwrap_err();
        assert_eq!(e, UnknownLevel { value: "sse4".into() });
        let text = e.to_string();
        assert!(text.contains("SHEEN_SIMD=sse4") && text.contains("avx2"), "{text}");
    }
}
