//! Reading and writing Sheen's file formats: fringe-set manifests and their
//! images, calibration, point clouds (PLY), float32 map files (TIFF) and
//! colour-mapped previews (PNG).
//!
//! Architecture invariant: `io` may use `engine` (and `analysis`) types but
//! never the GUI crates; every file it writes goes through
//! [`atomic::write_atomic`], and every error is an [`IoError`] naming the
//! file (and the set, camera and image where it applies).

pub mod atomic;
pub mod calibration;
pub mod colormap;
pub mod error;
pub mod images;
pub mod json;
pub mod manifest;
pub mod ply;

pub use error::IoError;
