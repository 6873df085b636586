//! Content hashes of a record's input and height map (SHA-256, lower-case
//! hex), so a record proves which images it was measured from.
//!
//! A manifest's hash covers the manifest, its calibration file and every
//! image it names, in the manifest's order. It is the SHA-256 of the
//! `sha256sum` listing of those files (`HASH  NAME\n`, names as the manifest
//! writes them, relative to its folder), so anyone can check it without
//! Sheen: `cd FOLDER && sha256sum fringe-set.json calibration.json IMAGES...
//! | sha256sum`.

use std::io::Read as _;
use std::path::Path;

use sha2::{Digest, Sha256};

use crate::io::IoError;
use crate::io::manifest::{Manifest, folder_of};

/// Lower-case hex of a digest.
fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// SHA-256 of bytes in memory.
pub fn sha256_bytes(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// SHA-256 of a file, read in blocks.
pub fn sha256_file(path: &Path) -> Result<String, IoError> {
    let read_err = |source| IoError::Read { path: path.to_path_buf(), source };
    let mut file = std::fs::File::open(path).map_err(read_err)?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = file.read(&mut buf).map_err(read_err)?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hex(&hasher.finalize()))
}

/// The hash of a manifest and every file it names (see the module docs).
pub fn manifest_hash(manifest_path: &Path, manifest: &Manifest) -> Result<String, IoError> {
    let folder = folder_of(manifest_path);
    let paths = manifest.input_paths(manifest_path);
    let names = paths.iter().map(|path| {
        if path == manifest_path {
            manifest_path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned())
        } else {
            path.strip_prefix(&folder).unwrap_or(path).display().to_string()
        }
    });
    Ok(sha256_bytes(listing(names, &file_hashes(&paths)?).as_bytes()))
}

/// The hash of every file in a folder and its subfolders, by relative
/// name in sorted order, as the same `sha256sum` listing: the content of a
/// part that cannot be read as a manifest (one is missing or broken), so it
/// is still known again when it comes back unchanged.
pub fn folder_hash(folder: &Path) -> Result<String, IoError> {
    fn walk(dir: &Path, files: &mut Vec<std::path::PathBuf>) -> Result<(), IoError> {
        let entries = std::fs::read_dir(dir).map_err(|source| IoError::Read { path: dir.to_path_buf(), source })?;
        for entry in entries.filter_map(Result::ok) {
            let path = entry.path();
            if path.is_dir() { walk(&path, files)? } else { files.push(path) }
        }
        Ok(())
    }
    let mut files = Vec::new();
    walk(folder, &mut files)?;
    files.sort();
    let names = files.iter().map(|path| path.strip_prefix(folder).unwrap_or(path).display().to_string());
    Ok(sha256_bytes(listing(names, &file_hashes(&files)?).as_bytes()))
}

/// Each file's SHA-256, in parallel (a full-size part is 96 images and
/// 300 MB: one thread took 0.15 s of each part on the line), in order.
fn file_hashes(paths: &[std::path::PathBuf]) -> Result<Vec<String>, IoError> {
    use rayon::prelude::*;
    paths.par_iter().map(|path| sha256_file(path)).collect()
}

/// The `sha256sum` listing, `HASH  NAME` per line.
fn listing(names: impl Iterator<Item = String>, hashes: &[String]) -> String {
    names.zip(hashes).map(|(name, hash)| format!("{hash}  {name}\n")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The module's promise: anyone checks a record's hash without Sheen,
    /// `sha256sum FILES... | sha256sum` in the manifest's folder. Checked
    /// against coreutils' own tools on files of more than one read buffer.
    #[test]
    fn the_hash_is_what_sha256sum_gives_without_sheen() {
        let dir = tempfile::tempdir().unwrap();
        let names = ["fringe-set.json", "left/p0912_00.png"];
        std::fs::create_dir(dir.path().join("left")).unwrap();
        std::fs::write(dir.path().join(names[0]), b"{\"sheen_fringe_set\": 1}").unwrap();
        std::fs::write(dir.path().join(names[1]), (0..200_000u32).map(|i| (i * 7 % 251) as u8).collect::<Vec<_>>())
            .unwrap();
        let mut listing = String::new();
        for name in names {
            listing.push_str(&format!("{}  {name}\n", sha256_file(&dir.path().join(name)).unwrap()));
        }
        let Ok(out) = std::process::Command::new("sh")
            .arg("-c")
            .arg(format!("sha256sum {} {} | sha256sum", names[0], names[1]))
            .current_dir(dir.path())
            .output()
        else {
            eprintln!("no sh here: the comparison with sha256sum is skipped");
            return;
        };
        let coreutils = String::from_utf8_lossy(&out.stdout);
        assert_eq!(coreutils.split_whitespace().next(), Some(sha256_bytes(listing.as_bytes()).as_str()), "{listing}");
        // A folder's hash, its files hashed in parallel, is the same listing.
        assert_eq!(coreutils.split_whitespace().next(), Some(folder_hash(dir.path()).unwrap().as_str()));
    }
}
