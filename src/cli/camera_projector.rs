//! What `sheen check` and `sheen phase` say about a camera–projector rig's
//! Gray code and projector coordinates (issue 52), with the manifest's
//! file names in every error.

use std::path::Path;

use crate::engine::camera_projector::{self, ProjectorMaps, ProjectorMapsError};
use crate::engine::control::RunControl;
use crate::engine::fringe::Measurement;
use crate::engine::gray_code::GrayCodeError;
use crate::engine::phase_shift::PhaseParams;
use crate::io;

/// The error with the frames it is about named by their files.
pub fn explain(error: &ProjectorMapsError, manifest_path: &Path) -> anyhow::Error {
    let prefix = manifest_path.display();
    let ProjectorMapsError::Code { camera, axis, source } = error else {
        return anyhow::anyhow!("{prefix}: {error}");
    };
    let manifest = io::manifest::read_manifest(manifest_path).ok();
    let code = manifest.as_ref().and_then(|m| m.gray_code.as_ref());
    let list = if *axis == "x" { "columns" } else { "rows" };
    let frames = code.and_then(|c| if *axis == "x" { Some(&c.columns) } else { c.rows.as_ref() });
    let file = |k: usize| frames.and_then(|f| f.get(camera)).and_then(|l| l.get(k)).cloned().unwrap_or_default();
    match source {
        GrayCodeError::SwappedPlane { plane, pattern, inverse } => anyhow::anyhow!(
            "{prefix}: gray_code.{list} camera '{camera}': bit plane {plane} reads flipped at most pixels: its frames \
             {} (listed as the pattern) and {} (as the inverse) look swapped; list the pattern first",
            file(*pattern),
            file(*inverse)
        ),
        GrayCodeError::WhiteDarkerThanBlack { share_percent } => {
            let named = |map: Option<&std::collections::BTreeMap<String, String>>| {
                map.and_then(|m| m.get(camera)).cloned().unwrap_or_default()
            };
            anyhow::anyhow!(
                "{prefix}: gray_code camera '{camera}': the white frame {} is darker than the black frame {} at \
                 {share_percent:.0} % of the pixels; are they given the other way round?",
                named(code.map(|c| &c.white)),
                named(code.map(|c| &c.black))
            )
        }
        _ => anyhow::anyhow!("{prefix}: gray_code.{list}: {error}"),
    }
}

/// Each camera's Gray code decoded, one line per camera and axis.
pub fn gray_code_lines(m: &Measurement, manifest_path: &Path) -> anyhow::Result<Vec<String>> {
    let codes = camera_projector::decode_gray_codes(m).map_err(|e| explain(&e, manifest_path))?;
    let mut lines = Vec::new();
    for (camera, (x, y)) in m.cameras.iter().zip(codes) {
        for (axis, code) in [("x (columns)", Some(x)), ("y (rows)", y)] {
            let Some(code) = code else { continue };
            let (lit, decoded) = code.lit_and_decoded();
            lines.push(format!(
                "{} Gray code {axis}: {decoded} of {lit} lit pixels decoded ({:.1} %), {lit} of {} pixels lit",
                camera.name,
                100.0 * decoded as f64 / lit.max(1) as f64,
                code.cells.len()
            ));
        }
    }
    Ok(lines)
}

/// The absolute projector coordinates, where the manifest has a Gray code;
/// prints the warnings and what was measured and refused per axis.
pub fn projector_maps(
    m: &Measurement,
    phase: &PhaseParams,
    manifest_path: &Path,
    control: &RunControl,
    quiet: bool,
) -> anyhow::Result<Option<Vec<ProjectorMaps>>> {
    if m.projector.as_ref().and_then(|p| p.gray_code).is_none() {
        return Ok(None);
    }
    let maps = camera_projector::projector_maps(m, phase, control).map_err(|e| explain(&e, manifest_path))?;
    for camera in &maps {
        for w in &camera.warnings {
            eprintln!("warning: {w}");
        }
    }
    report(&maps, quiet);
    Ok(Some(maps))
}

/// One line per camera and axis: what was measured and refused, most first.
pub fn report(maps: &[ProjectorMaps], quiet: bool) {
    for camera in maps {
        if quiet {
            continue;
        }
        for (axis, coordinate) in [("x", &camera.x), ("y", &camera.y)] {
            let Some(c) = coordinate else { continue };
            let (lit, measured) = c.lit_and_measured();
            let mut refused = c.refusal_counts();
            refused.sort_by_key(|r| std::cmp::Reverse(r.1));
            let refused: Vec<String> = refused.iter().map(|(why, n)| format!("{n} {}", why.describe())).collect();
            eprintln!(
                "sheen: {} projector {axis}: {measured} of {lit} lit pixels ({:.1} %); refused: {}",
                camera.camera,
                100.0 * measured as f64 / lit.max(1) as f64,
                refused.join("; ")
            );
        }
    }
}
