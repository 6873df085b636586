//! A virtual dual-telecentric fringe projection rig that renders fringe sets
//! with known truth. Uses `engine` types; the engine never uses it.

pub mod target;
