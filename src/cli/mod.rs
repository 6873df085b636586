//! The command-line front end (clap subcommands) over the engine.
