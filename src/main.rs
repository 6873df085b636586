//! The `sheen` binary. `sheen` opens the inspection app on the simulated demo,
//! `sheen MANIFEST` opens it on a measurement; the command-line subcommands
//! (`cli`) will dispatch here too.

use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    let mut args = std::env::args_os().skip(1);
    let manifest = args.next().map(PathBuf::from);
    if args.next().is_some() {
        eprintln!("usage: sheen [MANIFEST]");
        return ExitCode::from(2);
    }
    match sheen::app::run(manifest) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sheen: {e:#}");
            ExitCode::FAILURE
        }
    }
}
