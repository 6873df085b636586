//! The `sheen` binary: the GUI with no subcommand (`sheen` or `sheen
//! MANIFEST`), the batch CLI otherwise. Errors print one line to stderr.

fn main() -> std::process::ExitCode {
    sheen::cli::main()
}
