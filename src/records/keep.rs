//! Keeping one record: its height map written into the records folder, the
//! record into the store, and the map removed again when the store refuses
//! it (no file without a record pointing at it). Shared by `sheen analyze
//! --record` and the app's Record button.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use super::{DbLocation, PartRecord, RecordsError, Store, hash};
use crate::analysis::height_map::HeightMap;
use crate::io;
use crate::io::manifest::Manifest;
use crate::io::x3p::{X3pDataType, X3pError, X3pMetadata, write_x3p, xsd_date_time_utc};

/// The manifest's folder name (a folder per part is how a line stores its
/// measurements), else the input's file stem.
pub fn default_part_id(input: &Path, is_manifest: bool) -> String {
    let stem = || input.file_stem().map_or_else(|| input.display().to_string(), |s| s.to_string_lossy().into_owned());
    if !is_manifest {
        return stem();
    }
    absolute(input).parent().and_then(Path::file_name).map_or_else(stem, |n| n.to_string_lossy().into_owned())
}

pub fn absolute(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).or_else(|_| std::path::absolute(path)).unwrap_or_else(|_| path.to_path_buf())
}

/// The manifest with every file it names, or the PLY; `None` when a file is
/// missing or unreadable (the record's reason then says which).
pub fn input_hash(input: &Path, manifest: Option<&Manifest>) -> Option<String> {
    match manifest {
        Some(m) => hash::manifest_hash(input, m).ok(),
        None => hash::sha256_file(input).ok(),
    }
}

/// Why a record was not kept.
#[derive(Debug, thiserror::Error)]
pub enum KeepError {
    #[error("cannot create the records folder {}: {source}", dir.display())]
    Folder { dir: PathBuf, source: std::io::Error },
    #[error("height map {}: {source}", path.display())]
    Encode { path: PathBuf, source: X3pError },
    #[error(transparent)]
    Write(#[from] io::error::IoError),
    #[error(transparent)]
    Store(#[from] RecordsError),
}

/// The height map a record keeps: the map itself, encoded here, or the X3P
/// file the measurement already wrote for the part (one encoding of a
/// full-size map is a tenth of a line's part time; the records' copy is
/// then the same bytes).
#[derive(Clone, Copy)]
pub enum RecordMap<'a> {
    Map(&'a HeightMap),
    /// The encoded file and, where it was written, its path: the record then
    /// links to that file instead of writing a second copy of its bytes.
    EncodedX3p {
        bytes: &'a [u8],
        written_to: Option<&'a Path>,
    },
}

/// Writes the height map into the records folder and the record into the
/// store; on failure removes the map again (no record refers to it).
pub fn keep(
    location: &DbLocation,
    height_map_dir: &Path,
    record: &mut PartRecord,
    map: Option<RecordMap<'_>>,
) -> Result<i64, KeepError> {
    let mut written: Option<PathBuf> = None;
    if let Some(map) = map {
        let (path, digest) = write_record_height_map(height_map_dir, record, map)?;
        record.height_map_path = Some(stored_map_path(location, &path));
        record.height_map_hash = Some(digest);
        written = Some(path);
    }
    let result = Store::open(location).and_then(|mut store| store.insert(record)).map_err(KeepError::from);
    if result.is_err()
        && let Some(path) = written
    {
        let _ = std::fs::remove_file(path);
    }
    result
}

/// `records/<time>_<part>_<pid>.x3p`: unique per record without asking the
/// store first (the record's row id exists only once it is committed).
fn write_record_height_map(
    dir: &Path,
    record: &PartRecord,
    map: RecordMap<'_>,
) -> Result<(PathBuf, String), KeepError> {
    std::fs::create_dir_all(dir).map_err(|source| KeepError::Folder { dir: dir.to_path_buf(), source })?;
    let stamp: String = super::time::stored(record.time_utc).chars().filter(|c| !matches!(c, '-' | ':')).collect();
    let path =
        dir.join(format!("{stamp}_{}_{}.x3p", crate::io::paths::safe_file_stem(&record.part_id), std::process::id()));
    let encoded;
    let bytes = match map {
        RecordMap::EncodedX3p { bytes, written_to } => {
            // A second name for the part's own X3P where both lie on one file
            // system: at the line's pace a copy was 16 MB more on disk and
            // one more file to sync per full-size part. The results' file is
            // only ever replaced (a new file renamed over it), never written
            // in place, so the record's bytes stay the ones hashed here;
            // anything else (another disk, no links) gets its own copy.
            if let Some(source) = written_to
                && link_durably(source, &path).is_ok()
            {
                return Ok((path, hash::sha256_bytes(bytes)));
            }
            bytes
        }
        RecordMap::Map(map) => {
            let date = xsd_date_time_utc(std::time::SystemTime::now());
            let comment = record_x3p_comment(&record.part_id, &record.recipe, &record.input_path);
            let meta = X3pMetadata { comment: Some(comment), ..X3pMetadata::sheen(&date) };
            encoded = write_x3p(Cursor::new(Vec::new()), map, &meta, X3pDataType::Float64)
                .map_err(|source| KeepError::Encode { path: path.clone(), source })?
                .into_inner();
            &encoded
        }
    };
    io::atomic::write_atomic(&path, |w| std::io::Write::write_all(w, bytes))?;
    Ok((path, hash::sha256_bytes(bytes)))
}

/// Links `path` to `source` and makes the new name durable.
fn link_durably(source: &Path, path: &Path) -> std::io::Result<()> {
    std::fs::hard_link(source, path)?;
    io::atomic::sync_parent_folder(path);
    Ok(())
}

/// What a recorded height map's X3P says of itself, so the file still names
/// its part when it is copied out of the records folder.
fn record_x3p_comment(part_id: &str, recipe: &str, source: &str) -> String {
    format!("part {part_id}; recipe {recipe}; source: {source}; heights as measured")
}

/// A SQLite store keeps the map's path relative to its own folder, so the
/// file and its `records/` folder can move together; a server's records
/// name the station's absolute path.
fn stored_map_path(location: &DbLocation, path: &Path) -> String {
    if let DbLocation::Sqlite(db) = location {
        let folder = db.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        if let Ok(relative) = path.strip_prefix(folder) {
            return relative.display().to_string();
        }
    }
    absolute(path).display().to_string()
}
