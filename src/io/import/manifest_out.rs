//! The fringe-set manifest of an assignment, with paths relative to it.

use super::*;

/// Makes `path` absolute against the working folder, without resolving links.
pub(super) fn absolute(path: &Path) -> PathBuf {
    if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().map_or_else(|_| path.to_path_buf(), |d| d.join(path))
    }
}

/// `path` relative to `base` (both resolved), with `/` separators, when it
/// lies inside `base`.
pub(super) fn relative_inside(base: &Path, path: &Path) -> Option<String> {
    let resolve = |p: &Path| p.canonicalize().unwrap_or_else(|_| absolute(p));
    let (b, p) = (resolve(base), resolve(path));
    let rel = p.strip_prefix(&b).ok()?;
    let parts: Vec<String> = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    Some(parts.join("/"))
}

/// The manifest for an assignment, with paths relative to `manifest_path`
/// (which must lie in `folder` or a folder above it).
pub fn build_manifest(
    folder: &Path,
    manifest_path: &Path,
    assignment: &Assignment,
    spec: &ImportSpec,
    bit_depth: u32,
) -> Result<Manifest, ImportError> {
    let at = ImportError::at(folder);
    let manifest_dir = crate::io::manifest::folder_of(manifest_path);
    let prefix = relative_inside(&manifest_dir, folder)
        .ok_or_else(|| at(ImportFault::ManifestOutside { manifest: manifest_path.to_path_buf() }))?;
    let join = |f: &str| if prefix.is_empty() { f.to_string() } else { format!("{prefix}/{f}") };
    for set in &assignment.sets {
        for f in set.files.values().flatten() {
            let image = folder.join(f);
            if image.canonicalize().ok().zip(absolute(manifest_path).canonicalize().ok()).is_some_and(|(a, b)| a == b)
                || (image == manifest_path)
            {
                return Err(at(ImportFault::ManifestIsImage { path: manifest_path.to_path_buf() }));
            }
        }
    }
    let calibration = match &spec.calibration {
        None => None,
        Some(c) => {
            let rel = relative_inside(&manifest_dir, c).filter(|r| !r.is_empty()).ok_or_else(|| {
                at(ImportFault::CalibrationOutside { calibration: c.clone(), folder: manifest_dir.clone() })
            })?;
            Some(CalibrationSource::File(rel))
        }
    };
    let sets = assignment
        .sets
        .iter()
        .map(|set| ManifestSet {
            period_px: set.period_px,
            shifts: set.shifts,
            axis: set.axis,
            phase_shifts_rad: spec.phase_shifts_rad(set.shifts),
            images: set
                .files
                .iter()
                .map(|(cam, files)| (cam.clone(), files.iter().map(|f| join(f)).collect()))
                .collect(),
        })
        .collect();
    let gray_code = spec.gray_code.zip(spec.projector).map(|(code, projector)| {
        let (columns, rows) = code.frames_per_axis(projector);
        let mut out = ManifestGrayCode {
            cell_px: code.cell_px,
            columns: BTreeMap::new(),
            rows: code.rows.then(BTreeMap::new),
            white: BTreeMap::new(),
            black: BTreeMap::new(),
        };
        for (camera, frames) in &assignment.gray_frames {
            let frames: Vec<String> = frames.iter().map(|f| join(f)).collect();
            out.columns.insert(camera.clone(), frames[..columns].to_vec());
            if let Some(r) = &mut out.rows {
                r.insert(camera.clone(), frames[columns..columns + rows].to_vec());
            }
            out.white.insert(camera.clone(), frames[columns + rows].clone());
            out.black.insert(camera.clone(), frames[columns + rows + 1].clone());
        }
        out
    });
    let manifest = Manifest {
        bit_depth,
        saturation_level: None,
        calibration,
        projector: spec.projector,
        sets,
        gray_code,
        warnings: Vec::new(),
    };
    manifest.validate(manifest_path)?;
    Ok(manifest)
}
