//! Writers (and the X3P and SDF readers) for analysis results, generic over
//! `std::io::Write` / `Read + Seek`: no paths, no file system. The io module
//! opens files, writes through a temporary file and renames, and wraps these
//! errors with the path.
//!
//! - [`csv`]: section profiles and measurement tables as CSV.
//! - [`x3p`]: height maps as ISO 25178-72 X3P containers, and reading them back.
//! - [`sdf`]: reading ISO 25178-71 SDF height maps (text and binary) that other
//!   instruments write.

pub mod csv;
pub mod sdf;
pub mod x3p;
