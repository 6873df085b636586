//! Sheen: microscopic 3D measurement of shiny surfaces with saturation-aware
//! multi-frequency phase shifting and a dual-telecentric stereo rig
//! (Hu et al., "Microscopic 3D measurement of shiny surfaces based on a
//! multi-frequency phase-shifting scheme", Optics and Lasers in Engineering).
//!
//! Crate map (see ARCHITECTURE.md): `engine` computes, `analysis` measures on
//! its results, `io` reads and writes formats, `records` keeps inspected
//! parts in a database, `sim` renders a virtual rig, `cli` and `app` are the
//! two front ends.

pub mod analysis;
pub mod app;
pub mod cli;
pub mod engine;
pub mod error_text;
pub mod io;
pub mod platform;
pub mod records;
pub mod sim;
