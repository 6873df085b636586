//! What panels and views ask the app to do. They push commands while drawing;
//! the app runs them after the frame, so drawing code never mutates the
//! session, starts jobs or touches another panel's state.

use std::path::PathBuf;

use crate::engine::pipeline::Method;

/// A pixel of one camera's image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PixelRef {
    pub camera: usize,
    pub u: usize,
    pub v: usize,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// Show the native file dialog.
    OpenDialog,
    /// Load a manifest.
    Open(PathBuf),
    /// Load the simulated demo.
    OpenDemo,
    /// Show the Import dialog (a folder of another rig's images into a manifest).
    OpenImport,
    /// Stop the running load.
    CancelLoad,
    /// Remove a file from the recent list (it no longer exists).
    ForgetRecent(PathBuf),
    /// A parameter changed: re-run after the debounce delay (if auto-run is on).
    ParamsChanged,
    /// Run the engine now.
    Run,
    /// Stop the engine run (and a scheduled one).
    Cancel,
    /// Run the comparison for these two methods if it is missing.
    Compare([Method; 2]),
    SelectPixel(PixelRef),
    ClearSelection,
    /// Step the shared set / shift cursor (keyboard or buttons).
    StepSet(i32),
    StepShift(i32),
    /// Reset zoom and pan of every map of this camera.
    ResetZoom(usize),
    DismissBanner,
    ClearLog,
    /// Show the calibration window.
    OpenCalibration,
    /// Horizontal and vertical section profiles through a point (X, Y in mm,
    /// e.g. one picked in the 3D view), shown in the Inspect view.
    SectionsThrough {
        x_mm: f64,
        y_mm: f64,
    },
    /// Export from the Inspect view (asks where, or uses its export folder).
    InspectExport(crate::app::exports::ExportKind),
    /// Save the session (manifest, parameters, inspection); `None` asks where.
    SaveSession(Option<PathBuf>),
    /// Save the session and its height map as a line's recipe; `None` asks where.
    SaveRecipe(Option<PathBuf>),
    /// Open a session file; `None` asks which.
    OpenSession(Option<PathBuf>),
    /// Follow a line's recipe in the Inspect view; `None` asks which.
    FollowRecipe(Option<PathBuf>),
    /// Keep the part on screen as an inspection record (Inspect > Record).
    InspectRecord,
    /// Open a recorded part again: its measurement, parameters and
    /// inspection (History view).
    OpenRecord(Box<crate::records::StoredPart>),
}
