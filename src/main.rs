//! The `sheen` binary: the GUI with no subcommand (`sheen` or `sheen
//! MANIFEST`), the batch CLI otherwise. Errors print one line to stderr.

/// mimalloc: fewer page faults and a lower peak than glibc's malloc or the
/// huge-page allocator Sheen had (docs/benchmarks-history.md, one measurement per process).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> std::process::ExitCode {
    sheen::cli::main()
}
