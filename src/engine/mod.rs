//! Pure computation of the measurement, from fringe images to a point cloud.
//!
//! Architecture invariant: nothing here reads files, talks to a GUI or knows
//! about egui/eframe/wgpu/rfd; inputs are in-memory [`fringe::Measurement`]s,
//! outputs are plain structs of maps. The GUI and the CLI are two front ends
//! over these functions.

pub mod buffers;
pub mod calibration;
pub mod camera_model;
pub mod camera_projector;
pub mod continuity;
pub mod control;
pub mod fringe;
pub mod fusion;
pub mod gray_code;
pub mod length_unit;
pub mod phase_shift;
pub mod pinhole;
pub mod pipeline;
pub mod point_cloud;
pub mod projector_coordinate;
pub mod rectify;
pub mod report;
pub mod shift_estimate;
pub mod simd;
pub mod stereo;
pub mod stereo_match;
pub mod triangulate;
pub mod unwrap;
pub mod warning;
