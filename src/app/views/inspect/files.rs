//! The Inspect view's files: exports (profiles CSV, profile plot PNG,
//! measurement CSV, height map X3P / float TIFF / PNG with colour bar, point
//! cloud PLY) and sessions. No GUI types: the view builds an [`Export`] from
//! what is on screen, and a job thread asks where to save (rfd), refuses to
//! overwrite the measurement's inputs and writes atomically through `io`.
//!
//! Height-map image files (TIFF, PNG) are written north up (first row = the
//! largest Y), as the view shows them; the TIFF holds heights in micrometres,
//! NaN for holes. The X3P stores its rows north first too (its Y grows
//! southward; `io::x3p`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::analysis::height_map::{HeightMap, rows_north_up, z_um};
use crate::analysis::measurement_table::MeasurementTable;
use crate::analysis::profile::Profile;
use crate::analysis::recipe::Recipe;
use crate::analysis::session::Session;
use crate::engine::pipeline::Reconstruction;
use crate::io::atomic::{refuse_overwriting_inputs, write_atomic};
use crate::io::colormap::{ColorBar, Colormap, ValueRange, write_map_png, write_png};
use crate::io::csv::{write_measurement_csv, write_profile_csv};
use crate::io::maps::{TiffCompression, write_f32_tiff};
use crate::io::ply::{PlyWriteOptions, write_ply};
use crate::io::x3p::{X3pDataType, X3pMetadata, write_x3p, xsd_date_time_utc};
use anyhow::Context as _;

use super::plot_png::{PlotSeries, render_profile_plot};
use super::record::{ReportPayload, write_report};

pub use crate::app::exports::ExportKind;

/// The data of one export, owned (or shared) so the job thread can write it.
pub enum Payload {
    Profiles(Vec<Profile>),
    Plot { series: Vec<PlotSeries>, cursors: [Option<f64>; 2] },
    Table(MeasurementTable),
    Map { map: Arc<HeightMap>, levelled: bool },
    MapPng { map: Arc<HeightMap>, display_um: Arc<Vec<f32>>, colormap: Colormap, range_um: (f32, f32) },
    Cloud(Arc<Reconstruction>),
    Session(Box<Session>),
    Report(Box<ReportPayload>),
    Exchange(Box<super::record::ExchangePayload>),
    Recipe { session: Box<Session>, map: Arc<HeightMap> },
}

/// One export request.
pub struct Export {
    pub kind: ExportKind,
    pub payload: Payload,
    /// What the data was computed from, for file headers.
    pub source: String,
    /// The manifest of the measurement: its inputs are never overwritten.
    pub manifest: Option<PathBuf>,
}

/// What a native file dialog gave.
#[derive(Clone, Debug, PartialEq)]
pub enum Asked {
    Path(PathBuf),
    /// The operator closed the dialog.
    Cancelled,
    /// No dialog could be shown (rfd needs xdg-desktop-portal or zenity).
    Unavailable,
}

fn asked(picked: Option<PathBuf>, started: std::time::Instant) -> Asked {
    // rfd returns None at once when no portal or zenity can show a dialog.
    match picked {
        Some(p) => Asked::Path(p),
        None if started.elapsed() < std::time::Duration::from_millis(400) => Asked::Unavailable,
        None => Asked::Cancelled,
    }
}

/// Asks where to save `kind` (native dialog, starting in `folder`).
pub fn ask_path(kind: ExportKind, folder: &Path) -> Asked {
    let started = std::time::Instant::now();
    let (filter, extensions) = kind.filter();
    let picked = rfd::FileDialog::new()
        .set_title(format!("Export {}", kind.label()))
        .add_filter(filter, extensions)
        .set_directory(folder)
        .set_file_name(kind.default_file_name())
        .save_file();
    asked(picked, started)
}

/// Every file the measurement was read from (manifest, calibration, images).
fn inputs_of(manifest: Option<&Path>) -> Vec<PathBuf> {
    let Some(manifest) = manifest else { return Vec::new() };
    match crate::io::manifest::read_manifest(manifest) {
        Ok(m) => m.input_paths(manifest),
        Err(_) => vec![manifest.to_path_buf()],
    }
}

/// `folder/stem_NAME.ext` for one of several profiles (the name made safe for file systems).
fn profile_path(path: &Path, name: &str) -> PathBuf {
    let safe: String = name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
    let stem = path.file_stem().map_or_else(|| "profile".into(), |s| s.to_string_lossy().into_owned());
    let ext = path.extension().map_or_else(|| "csv".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}_{safe}.{ext}"))
}

/// Writes `export` to `path`; returns the files written.
pub fn write_export(export: &Export, path: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let inputs = inputs_of(export.manifest.as_deref());
    let guard = |p: &Path| refuse_overwriting_inputs(p, &inputs);
    match &export.payload {
        Payload::Profiles(profiles) => {
            if profiles.is_empty() {
                anyhow::bail!("there is no profile to export; draw a section first");
            }
            let paths: Vec<PathBuf> = if profiles.len() == 1 {
                vec![path.to_path_buf()]
            } else {
                profiles.iter().map(|p| profile_path(path, &p.name)).collect()
            };
            for (p, profile) in paths.iter().zip(profiles) {
                guard(p)?;
                write_atomic(p, |w| write_profile_csv(w, profile, &export.source))?;
            }
            Ok(paths)
        }
        Payload::Plot { series, cursors } => {
            if series.is_empty() {
                anyhow::bail!("there is no profile to plot; draw a section first");
            }
            guard(path)?;
            let img = render_profile_plot(series, *cursors, &export.source, [1200, 700]);
            write_png(path, &img)?;
            Ok(vec![path.to_path_buf()])
        }
        Payload::Table(table) => {
            guard(path)?;
            write_atomic(path, |w| write_measurement_csv(w, table, &export.source))?;
            Ok(vec![path.to_path_buf()])
        }
        Payload::Map { map, levelled } => {
            guard(path)?;
            if export.kind == ExportKind::MapTiff {
                let data = rows_north_up(&z_um(map), map.width);
                write_f32_tiff(path, map.width, map.height, &data, TiffCompression::None)?;
            } else {
                let mut meta = X3pMetadata::sheen(xsd_date_time_utc(std::time::SystemTime::now()));
                meta.comment = Some(format!(
                    "{}; {}",
                    export.source,
                    if *levelled { "levelled to the reference regions" } else { "as measured (not levelled)" }
                ));
                write_atomic(path, |w| {
                    write_x3p(w, map, &meta, X3pDataType::Float64).map(|_| ()).map_err(std::io::Error::other)
                })?;
            }
            Ok(vec![path.to_path_buf()])
        }
        Payload::MapPng { map, display_um, colormap, range_um } => {
            guard(path)?;
            let data = rows_north_up(display_um, map.width);
            let range = ValueRange::new(range_um.0, range_um.1);
            write_map_png(path, &data, map.width, map.height, *colormap, range, &ColorBar::unit("um"))?;
            Ok(vec![path.to_path_buf()])
        }
        Payload::Cloud(rec) => {
            let cloud = rec.cloud().context("the result has no point cloud")?;
            guard(path)?;
            let options = PlyWriteOptions { source: Some(export.source.clone()), ..PlyWriteOptions::default() };
            write_ply(path, cloud, &options)?;
            Ok(vec![path.to_path_buf()])
        }
        Payload::Report(report) => {
            guard(path)?;
            write_report(report, path, export.kind == ExportKind::ReportPdf)?;
            Ok(vec![path.to_path_buf()])
        }
        Payload::Exchange(exchange) => {
            guard(path)?;
            super::record::write_exchange(exchange, path, export.kind == ExportKind::Dfq)?;
            Ok(vec![path.to_path_buf()])
        }
        Payload::Session(session) => {
            guard(path)?;
            let mut session = (**session).clone();
            session.manifest = relative_to(&session.manifest, path);
            let json = session.to_json();
            write_atomic(path, |w| std::io::Write::write_all(w, json.as_bytes()))?;
            Ok(vec![path.to_path_buf()])
        }
        Payload::Recipe { session, map } => {
            let (recipe, map_path) = recipe_of(session, map, path);
            guard(path)?;
            guard(&map_path)?;
            let meta = X3pMetadata {
                comment: Some(format!("{}; the reference part of recipe '{}'", export.source, recipe.name)),
                ..X3pMetadata::sheen(xsd_date_time_utc(std::time::SystemTime::now()))
            };
            write_atomic(&map_path, |w| {
                write_x3p(w, map, &meta, X3pDataType::Float64).map(|_| ()).map_err(std::io::Error::other)
            })?;
            let json = recipe.to_json();
            write_atomic(path, |w| std::io::Write::write_all(w, json.as_bytes()))?;
            Ok(vec![path.to_path_buf(), map_path])
        }
    }
}

/// The recipe a session and its map make at `path`, and where its
/// reference map goes (`NAME.reference.x3p` beside it). The inspection's
/// pitch is fixed to the map's, so every part is rasterized alike.
fn recipe_of(session: &Session, map: &HeightMap, path: &Path) -> (Recipe, PathBuf) {
    let name = Recipe::name_of_file(path);
    let map_name = format!("{name}.reference.x3p");
    let mut session = session.clone();
    session.manifest = relative_to(&session.manifest, path);
    session.view = serde_json::Value::Null;
    session.inspection.height_map.pitch_mm = Some(map.pitch_mm);
    (Recipe::new(name, session, &map_name), path.with_file_name(map_name))
}

/// The manifest path as stored in a session at `session_path`
/// ([`crate::io::paths::relative_to`] its folder).
fn relative_to(manifest: &Path, session_path: &Path) -> PathBuf {
    crate::io::paths::relative_to(manifest, session_path.parent().unwrap_or(Path::new("")))
}

/// Reads a session file; the manifest comes back resolved against the
/// session's folder (empty = the simulated demo).
pub fn read_session(path: &Path) -> anyhow::Result<Session> {
    let text = std::fs::read_to_string(path).with_context(|| format!("session {}", path.display()))?;
    let mut session = Session::from_json(&text).with_context(|| format!("session {}", path.display()))?;
    if !session.manifest.as_os_str().is_empty() && session.manifest.is_relative() {
        let folder = path.parent().unwrap_or(Path::new("."));
        session.manifest = folder.join(&session.manifest);
    }
    Ok(session)
}

/// Asks which session to open (native dialog).
/// Asks which recipe to follow.
pub fn ask_recipe_path(folder: &Path) -> Asked {
    let started = std::time::Instant::now();
    let dialog = rfd::FileDialog::new()
        .set_title("Follow a Sheen recipe")
        .add_filter("Sheen recipe", &["json"])
        .add_filter("All files", &["*"])
        .set_directory(folder);
    asked(dialog.pick_file(), started)
}

pub fn ask_session_path(folder: Option<&Path>) -> Asked {
    let started = std::time::Instant::now();
    let mut dialog = rfd::FileDialog::new()
        .set_title("Open a Sheen session")
        .add_filter("Sheen session", &["json"])
        .add_filter("All files", &["*"]);
    if let Some(folder) = folder {
        dialog = dialog.set_directory(folder);
    }
    asked(dialog.pick_file(), started)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::profile::{ProfileLine, ProfileSpec, extract_profile};
    use crate::analysis::testing::node_map;
    use crate::engine::pipeline::Params;
    use crate::io::x3p::read_x3p;

    fn map() -> Arc<HeightMap> {
        Arc::new(node_map(30, 20, [1.0, 2.0], 0.01, |x, y| (x < 1.25).then_some(0.002 * x + y * 0.001)))
    }

    fn export(kind: ExportKind, payload: Payload) -> Export {
        Export { kind, payload, source: "test map".into(), manifest: None }
    }

    #[test]
    fn maps_are_written_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let m = map();
        let x3p = dir.path().join("m.x3p");
        write_export(&export(ExportKind::MapX3p, Payload::Map { map: Arc::clone(&m), levelled: false }), &x3p).unwrap();
        let back = read_x3p(std::fs::File::open(&x3p).unwrap()).unwrap();
        assert_eq!((back.map.width, back.map.height), (30, 20));
        for (a, b) in back.map.z.iter().zip(&m.z) {
            assert!(a.is_nan() && b.is_nan() || a == b, "{a} {b}");
        }
        let tif = dir.path().join("m.tif");
        write_export(&export(ExportKind::MapTiff, Payload::Map { map: Arc::clone(&m), levelled: false }), &tif)
            .unwrap();
        let t = crate::io::maps::read_f32_tiff(&tif).unwrap();
        // North up, in um: the first row is the last map row.
        assert!((t.data[0] - m.z[19 * 30] * 1000.0).abs() < 1e-4);
        assert!(t.data[29].is_nan());
    }

    #[test]
    fn several_profiles_go_to_one_file_each_and_inputs_are_protected() {
        let dir = tempfile::tempdir().unwrap();
        let m = map();
        let profiles: Vec<Profile> = ["A-A", "B B"]
            .iter()
            .map(|n| {
                let spec = ProfileSpec {
                    name: (*n).into(),
                    line: ProfileLine::Horizontal { through_mm: [1.0, 2.1] },
                    step_mm: None,
                    width_mm: 0.0,
                    raw_samples: false,
                };
                extract_profile(&m, &spec).unwrap()
            })
            .collect();
        let written =
            write_export(&export(ExportKind::ProfilesCsv, Payload::Profiles(profiles)), &dir.path().join("p.csv"))
                .unwrap();
        assert_eq!(written, vec![dir.path().join("p_A-A.csv"), dir.path().join("p_B_B.csv")]);
        let text = std::fs::read_to_string(&written[1]).unwrap();
        assert!(text.contains("# name: B B") && text.contains("distance_mm,x_mm,y_mm,z_um,n"), "{text}");

        let manifest = dir.path().join("manifest.json");
        std::fs::write(&manifest, "{}").unwrap();
        let mut e = export(ExportKind::MeasurementsCsv, Payload::Table(MeasurementTable::default()));
        e.manifest = Some(manifest.clone());
        let refused = write_export(&e, &manifest).unwrap_err();
        match refused.downcast_ref::<crate::io::IoError>() {
            Some(crate::io::IoError::OverwritesInput { input, .. }) => assert_eq!(input, &manifest),
            _ => panic!("the input's protection must refuse, keeping its cause: {refused:#}"),
        }
        assert_eq!(std::fs::read_to_string(&manifest).unwrap(), "{}", "the input is untouched");
    }

    #[test]
    fn a_session_stores_its_manifest_relative_and_reads_back_resolved() {
        let dir = tempfile::tempdir().unwrap();
        let manifest = dir.path().join("lot 7").join("manifest.json");
        std::fs::create_dir_all(manifest.parent().unwrap()).unwrap();
        std::fs::write(&manifest, "{}").unwrap();
        let session = Session::new(&manifest, Params::default());
        let path = dir.path().join("s.json");
        write_export(&export(ExportKind::Session, Payload::Session(Box::new(session))), &path).unwrap();
        assert!(std::fs::read_to_string(&path).unwrap().contains("\"manifest\": \"lot 7/manifest.json\""));
        let back = read_session(&path).unwrap();
        assert_eq!(back.manifest.canonicalize().unwrap(), manifest.canonicalize().unwrap());
        let e = read_session(&dir.path().join("missing.json")).unwrap_err();
        assert!(format!("{e:#}").contains("missing.json"), "{e:#}");
        let cause = e.root_cause().downcast_ref::<std::io::Error>().map(std::io::Error::kind);
        assert_eq!(cause, Some(std::io::ErrorKind::NotFound), "the cause is kept: {e:#}");
    }
}
