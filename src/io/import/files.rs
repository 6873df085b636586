//! The folder's files: listing, natural order, `--skip` globs, names that
//! may be camera names.

use super::*;

/// Every file under `folder` (up to 4 levels deep), as `/`-separated paths
/// relative to it, in natural order. Hidden files and folders are left out.
pub fn list_files(folder: &Path) -> Result<Vec<String>, IoError> {
    fn walk(dir: &Path, prefix: &str, depth: usize, out: &mut Vec<String>) -> Result<(), IoError> {
        let entries = std::fs::read_dir(dir).map_err(|source| IoError::Read { path: dir.to_path_buf(), source })?;
        for entry in entries {
            let entry = entry.map_err(|source| IoError::Read { path: dir.to_path_buf(), source })?;
            let Some(name) = entry.file_name().to_str().map(str::to_string) else {
                continue;
            };
            if name.starts_with('.') {
                continue;
            }
            let rel = if prefix.is_empty() { name.clone() } else { format!("{prefix}/{name}") };
            let kind = entry.file_type().map_err(|source| IoError::Read { path: entry.path(), source })?;
            let is_dir = kind.is_dir() || (kind.is_symlink() && entry.path().is_dir());
            if is_dir {
                if depth < 4 {
                    walk(&entry.path(), &rel, depth + 1, out)?;
                }
            } else {
                out.push(rel);
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(folder, "", 0, &mut out)?;
    out.sort_by(|a, b| natural_cmp(a, b));
    Ok(out)
}

/// True for the file extensions Sheen decodes.
pub fn is_image_file(path: &str) -> bool {
    let ext = path.rsplit_once('.').map(|(_, e)| e.to_ascii_lowercase()).unwrap_or_default();
    IMAGE_EXTENSIONS.contains(&ext.as_str())
}

/// Natural order: runs of digits compare as numbers (`2.bmp` < `10.bmp`),
/// the rest character by character (case-insensitive first, then exact).
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (ab, bb) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < ab.len() && j < bb.len() {
        if ab[i].is_ascii_digit() && bb[j].is_ascii_digit() {
            let si = i;
            while i < ab.len() && ab[i].is_ascii_digit() {
                i += 1;
            }
            let sj = j;
            while j < bb.len() && bb[j].is_ascii_digit() {
                j += 1;
            }
            let na = a[si..i].trim_start_matches('0');
            let nb = b[sj..j].trim_start_matches('0');
            let ord = na.len().cmp(&nb.len()).then_with(|| na.cmp(nb)).then_with(|| (i - si).cmp(&(j - sj)));
            if ord != Ordering::Equal {
                return ord;
            }
        } else {
            let (ca, cb) = (ab[i].to_ascii_lowercase(), bb[j].to_ascii_lowercase());
            if ca != cb {
                return ca.cmp(&cb);
            }
            i += 1;
            j += 1;
        }
    }
    (ab.len() - i).cmp(&(bb.len() - j)).then_with(|| a.cmp(b))
}

/// A `--skip` glob, compiled once: `*` (any run of characters), `?` (one
/// character), `[0-9]`, `[abc]` and `[!abc]` classes, as a shell writes them.
#[derive(Clone, Debug)]
pub struct SkipGlob {
    pub text: String,
    pattern: glob::Pattern,
}

impl SkipGlob {
    pub fn new(text: &str) -> Result<Self, ImportFault> {
        let pattern = glob::Pattern::new(text)
            .map_err(|e| ImportFault::BadSkip { glob: text.to_string(), problem: e.msg.to_string() })?;
        Ok(Self { text: text.to_string(), pattern })
    }

    /// Matches the path relative to the folder, or the file name alone (a
    /// glob without `/` names files in any camera's folder).
    pub fn matches(&self, file: &str) -> bool {
        let name = file.rsplit('/').next().unwrap_or(file);
        self.pattern.matches(file) || self.pattern.matches(name)
    }
}

pub(super) fn valid_camera_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && !name.starts_with('.')
        && name.chars().all(|c| c.is_alphanumeric() || c == '-' || c == '_' || c == '.')
}
