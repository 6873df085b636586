//! The one error type of `io`: every variant names the file it is about and,
//! where it applies, the set, camera and image; the message says what is
//! wrong, what was expected and what to do (the CLI prints it as one line, the
//! app shows it in a banner).

use std::path::PathBuf;

use crate::engine::control::Cancelled;

/// Why reading or writing a file failed.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    #[error("cannot read {}: {}", path.display(), os_cause(source))]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write {}: {}; an existing file there was left untouched", path.display(), os_cause(source))]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "refusing to write {}: it is an input of this measurement ({}); choose another output path",
        path.display(),
        input.display()
    )]
    OverwritesInput { path: PathBuf, input: PathBuf },
    #[error("manifest {}: {fault}", path.display())]
    Manifest { path: PathBuf, fault: crate::io::manifest::ManifestFault },
    #[error(
        "the images of {} need {:.1} GiB of memory for their samples, but {}; load fewer sets or cameras, or use a \
         machine with more memory",
        path.display(),
        gib(*bytes),
        match available { Some(a) => format!("only {:.1} GiB is available", gib(*a)), None => "that much cannot be allocated".into() }
    )]
    OutOfMemory { path: PathBuf, bytes: u64, available: Option<u64> },
    #[error("{} {fault}", image_subject(path, location.as_deref()))]
    Image {
        path: PathBuf,
        /// Camera, set and image index when the file belongs to a manifest.
        location: Option<Box<crate::io::images::ImageLocation>>,
        fault: crate::io::images::ImageFault,
    },
    #[error("{}: {fault}", calibration_origin(path, *inline))]
    Calibration {
        /// The calibration file, or the manifest holding it inline.
        path: PathBuf,
        inline: bool,
        fault: crate::io::calibration::CalibrationFault,
    },
    #[error("calibration set {}: {fault}", path.display())]
    CalibrationSet { path: PathBuf, fault: Box<crate::io::calibration_set::CalibrationSetFault> },
    #[error("PLY {}: {fault}", path.display())]
    Ply { path: PathBuf, fault: crate::io::ply::PlyFault },
    #[error("TIFF {}: {message}", path.display())]
    Tiff { path: PathBuf, message: String },
    #[error("height map {}: {fault}", path.display())]
    HeightMap { path: PathBuf, fault: crate::io::height_map_file::HeightMapFault },
    #[error("cancelled")]
    Cancelled(#[from] Cancelled),
}

fn gib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 30) as f64
}

fn image_subject(path: &std::path::Path, location: Option<&crate::io::images::ImageLocation>) -> String {
    match location {
        Some(l) => l.to_string(),
        None => format!("image {}", path.display()),
    }
}

fn calibration_origin(path: &std::path::Path, inline: bool) -> String {
    if inline { format!("inline calibration in {}", path.display()) } else { format!("calibration {}", path.display()) }
}

/// The operating system's cause in words, with the remedy for the causes a
/// user can fix (permissions, read-only media, a full disk).
pub(crate) fn os_cause(e: &std::io::Error) -> String {
    use std::io::ErrorKind as K;
    let remedy = match e.kind() {
        K::PermissionDenied => "; check the file's and the folder's permissions or choose another folder",
        K::ReadOnlyFilesystem => "; the file system is read-only: choose a writable folder",
        K::StorageFull | K::QuotaExceeded => "; the disk is full: free space or choose another disk",
        K::NotFound => "; check that the path exists",
        K::IsADirectory => "; the path is a folder, not a file",
        _ => "",
    };
    format!("{e}{remedy}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_error_names_path_cause_and_remedy() {
        let e = IoError::Write {
            path: PathBuf::from("/data/out/cloud.ply"),
            source: std::io::Error::from(std::io::ErrorKind::PermissionDenied),
        };
        let msg = e.to_string();
        assert!(msg.contains("/data/out/cloud.ply"), "{msg}");
        assert!(msg.contains("permission denied"), "{msg}");
        assert!(msg.contains("choose another folder"), "{msg}");
        assert!(msg.contains("left untouched"), "{msg}");
    }

    #[test]
    fn full_disk_says_so() {
        let e = IoError::Write {
            path: PathBuf::from("x.tif"),
            source: std::io::Error::from(std::io::ErrorKind::StorageFull),
        };
        assert!(e.to_string().contains("the disk is full"), "{e}");
    }
}
