//! The panels around the central views, one file each: menu bar, parameters,
//! pixel inspector, statistics, log, banner and status bar. Panels read the
//! session, edit only their own settings, and push [`super::commands::Command`]s.

pub mod inspector;
pub mod log;
pub mod parameters;
pub mod statistics;
pub mod status;
pub mod top_bar;
