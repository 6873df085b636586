//! One integration test binary (ripgrep's layout): a module per area.

mod calibration_cli;
mod calibration_detect;
mod calibration_io;
mod calibration_scene;
mod calibration_solve;
mod cli;
mod docs;
mod end_to_end;
mod engine_phase;
mod engine_simd;
mod engine_stereo;
mod engine_unwrap;
mod exchange_cli;
mod gauge;
mod gray_code_real;
mod import;
mod length_units;
mod line;
mod qc_acceptance;
mod records;
mod records_cli;
mod records_tls;
mod reliability;
mod texture_cli;
mod tidy;
mod util;
