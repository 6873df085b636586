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
            phase_shifts_rad: spec.phase_shifts_rad(set.shifts),
            images: set
                .files
                .iter()
                .map(|(cam, files)| (cam.clone(), files.iter().map(|f| join(f)).collect()))
                .collect(),
        })
        .collect();
    let manifest = Manifest { bit_depth, saturation_level: None, calibration, sets, warnings: Vec::new() };
    manifest.validate(manifest_path)?;
    Ok(manifest)
}
