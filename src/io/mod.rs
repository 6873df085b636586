//! Reading and writing Sheen's file formats.
//!
//! - [`manifest`]: the fringe-set manifest (JSON beside its images) and
//!   loading it into an `engine::fringe::Measurement` (parallel decoding,
//!   progress and cancel through `engine::control::RunControl`);
//! - [`images`]: decoding one grayscale image (PNG, TIFF, BMP, PGM; 8/16-bit)
//!   with the bit-depth, size and colour checks;
//! - [`calibration`]: the affine stereo calibration contract, to and from
//!   `engine::camera_model::StereoCalibration`;
//! - [`calibration_set`]: the calibration-set contract (target images in
//!   several poses), calibrating from it (`engine::calibration`), the
//!   calibration report, and writing simulated sets with their truth;
//! - [`ply`]: point clouds (`engine::point_cloud::PointCloud`) as PLY, and a
//!   generic PLY vertex reader;
//! - [`maps`]: the per-camera map files (float32 TIFF + PNG preview);
//! - [`height_map_file`]: other instruments' height maps (X3P, SDF, float
//!   TIFF) read as a `HeightMap`, so an inspection runs on them too;
//! - [`dataset`]: a whole in-memory measurement written as a fringe set
//!   (images, calibration, manifest);
//! - [`colormap`]: colour maps and colour-bar PNG rendering, shared with the GUI;
//! - [`atomic`]: atomic file replacement and the guard that keeps exports off
//!   the inputs;
//! - [`json`]: key-by-key JSON reading with located faults;
//! - [`report`]: the part report as self-contained HTML and A4 PDF;
//! - [`x3p`]: height maps as ISO 25178-72 X3P containers, written and read
//!   back (other instruments' files too), over `Write` / `Read + Seek`;
//! - [`sdf`]: ISO 25178-71 SDF height maps (text and binary) read;
//! - [`csv`]: section profiles and measurement tables as CSV;
//! - [`watch_line`]: `sheen watch --json`'s line, the watch's and the Line
//!   view's one contract;
//! - [`exchange`]: a part as the plant's quality systems receive it, and
//!   its writers [`aqdef`] (Q-DAS `.dfq`) and [`qif`] (QIF 3.0 Results);
//! - [`error`]: [`IoError`], the one error type of this module.
//!
//! Architecture invariant: `io` may use `engine` (and `analysis`) types but
//! never the GUI crates (egui, eframe, wgpu, rfd). Every file it writes goes
//! through [`atomic::write_atomic`], so a failed export leaves any existing
//! file untouched, and every error is an [`IoError`] naming the file (and the
//! set, camera and image where it applies).

pub mod aqdef;
pub mod atomic;
pub mod calibration;
pub mod calibration_set;
pub mod colormap;
pub mod csv;
pub mod dataset;
pub mod error;
pub mod exchange;
pub mod height_map_file;
pub mod images;
pub mod import;
pub mod json;
pub mod manifest;
pub mod maps;
pub mod paths;
pub mod pinhole_calibration;
pub mod ply;
pub mod qif;
pub mod recipe_file;
pub mod report;
pub mod sdf;
pub mod watch_line;
pub mod x3p;

pub use error::IoError;
