//! The `sheen` binary: the GUI with no subcommand (`sheen` or `sheen
//! MANIFEST`), the batch CLI otherwise. Errors print one line to stderr.

/// Large buffers on transparent huge pages (`cli::memory`).
#[global_allocator]
static ALLOCATOR: sheen::cli::HugePageAlloc = sheen::cli::HugePageAlloc;

fn main() -> std::process::ExitCode {
    sheen::cli::main()
}
