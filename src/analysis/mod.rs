//! Quality-control measurements on reconstructed data, as operators use them
//! on watch plates (coplanarity, height differences between planes) and
//! gaskets (deformation seen in sections, the paper's Figs. 6-7).
//!
//! Data flow: an organized [`PointCloud`](crate::engine::point_cloud::PointCloud)
//! is resampled into a [`height_map::HeightMap`] (mm, holes kept as NaN);
//! [`region`]s select parts of it; [`plane_fit`] fits least-squares planes,
//! levels the map and reports flatness; [`step_height`] and [`coplanarity`]
//! compare planes; [`profile`] extracts averaged sections. Results go into a
//! [`measurement_table`] with tolerances; `io` writes them (CSV, X3P).
//! [`session`] and [`inspection`] are the serde forms of a whole setup, so the
//! GUI, the CLI and a production line run the same inspection.
//!
//! Architecture invariant: pure computation over engine types. No GUI crate,
//! no file system: writers take `impl Write (+ Seek)` and readers
//! `impl Read + Seek`, and the caller (io) adds paths and atomic replacement.
//! Measurements never see filled holes: display filling returns its own type.

pub mod alignment;
pub mod binning;
pub mod coplanarity;
pub mod error;
pub mod gauge;
pub mod height_map;
pub mod inspection;
pub mod measurement_record;
pub mod measurement_table;
pub mod plane_fit;
pub mod profile;
pub mod recipe;
pub mod region;
pub mod session;
pub mod step_height;
#[cfg(test)]
pub(crate) mod testing;
pub mod texture;
pub mod uncertainty;

pub use error::AnalysisError;
