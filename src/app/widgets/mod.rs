//! Widgets shared by the views: the zoomable map and its colour legend.

pub mod legend;
pub mod map_view;
