//! How a file that another file refers to is stored in it.

use std::path::{Path, PathBuf};

/// A name (a part ID, a measurement, a folder) as a file-name piece:
/// anything but ASCII letters, digits, `.`, `-` and `_` becomes `_` (the
/// name is the operator's text, the file name must be safe on every file
/// system).
pub fn safe_file_stem(name: &str) -> String {
    let s: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') { c } else { '_' }).collect();
    if s.is_empty() { "unnamed".into() } else { s }
}

/// `path` as stored in a file kept in `folder` (a session, a recipe):
/// relative to the folder when it lies inside it (the two can be moved
/// together), else absolute when it exists, else as given.
pub fn relative_to(path: &Path, folder: &Path) -> PathBuf {
    if path.as_os_str().is_empty() {
        return PathBuf::new();
    }
    let folder = if folder.as_os_str().is_empty() { Path::new(".") } else { folder };
    match (folder.canonicalize().ok(), path.canonicalize().ok()) {
        (Some(folder), Some(full)) => full.strip_prefix(&folder).map_or(full.clone(), Path::to_path_buf),
        _ => path.to_path_buf(),
    }
}

/// Where `sheen watch` (and the app's Line view, which runs it) writes the
/// parts' results when not told: `INBOX.results` beside the inbox.
pub fn default_results_folder(inbox: &Path) -> PathBuf {
    let mut name = inbox.file_name().unwrap_or_default().to_os_string();
    name.push(".results");
    inbox.with_file_name(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inside_is_relative_and_outside_absolute() {
        let dir = std::env::temp_dir().join(format!("sheen-paths-{}", std::process::id()));
        let inner = dir.join("a").join("m.json");
        std::fs::create_dir_all(inner.parent().expect("parent")).expect("dir");
        std::fs::write(&inner, "{}").expect("write");
        assert_eq!(relative_to(&inner, &dir), PathBuf::from("a/m.json"));
        let outside = relative_to(&inner, &dir.join("a").join("b_missing"));
        assert_eq!(outside, inner, "a folder that cannot be resolved keeps the path as given");
        let sibling = dir.join("c");
        std::fs::create_dir_all(&sibling).expect("dir");
        assert!(relative_to(&inner, &sibling).is_absolute());
        std::fs::remove_dir_all(&dir).ok();
    }
}
