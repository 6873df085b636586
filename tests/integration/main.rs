//! One integration test binary (ripgrep's layout): a module per area.

mod cli;
mod end_to_end;
mod engine_phase;
mod engine_stereo;
mod engine_unwrap;
mod tidy;
mod util;
