//! Importing a folder of fringe images written by another rig's acquisition
//! software: which file is which camera, set and shift, checked
//! before anything is written, and the fringe-set manifest that says so.
//!
//! Three ways to name the files:
//!
//! - a PATTERN with placeholders, matched against each file's path relative
//!   to the folder: `{camera}`, `{period}` (projector pixels), `{set}` (set
//!   number, sparsest first), `{shift}`, and `{index}`, which counts through
//!   all images of a camera in set order, sparsest first. Numeric
//!   placeholders take a width, `{shift:02}`, meaning exactly that many
//!   digits. Numbering may start anywhere (0 or 1 are usual): the smallest
//!   number found is the first image;
//! - without a pattern, one subfolder per camera (or the folder itself for
//!   one camera), its image files in natural sort order (`2.bmp` before
//!   `10.bmp`), assigned to sets and shifts in turn;
//! - in both cases `--skip` globs (`*`, `?`) leave out Gray-code or other
//!   extra images.
//!
//! [`assign`] is pure (it sees only file names), [`inspect_images`] reads
//! headers (and samples only where the bit depth must be measured), and
//! [`build_manifest`] writes paths relative to the manifest.

use std::cmp::Ordering;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::error::IoError;
use super::images::{self, GrayPixels};
use super::manifest::{CalibrationSource, Manifest, ManifestSet};
use crate::engine::control::RunControl;
use crate::engine::phase_shift::MAX_SHIFTS;
use crate::engine::unwrap::MAX_SETS;

/// File extensions taken as images (case-insensitive).
pub const IMAGE_EXTENSIONS: [&str; 6] = ["png", "tif", "tiff", "bmp", "pgm", "pnm"];

/// Camera name used when the data has one camera and none is named.
pub const DEFAULT_CAMERA: &str = "camera";

/// The camera's name when the files name no camera: the one given, or the
/// default; asking for more cameras than the files can hold is an error.
fn single_camera_name(spec: &ImportSpec, found: &str) -> Result<String, ImportFault> {
    match spec.cameras.as_slice() {
        [] => Ok(DEFAULT_CAMERA.to_string()),
        [one] => Ok(one.name.clone()),
        more => Err(ImportFault::CameraMissing { camera: more[1].name.clone(), found: found.into() }),
    }
}

/// A camera of the import: its manifest name and what identifies its files
/// (the `{camera}` text, or the subfolder name).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CameraSpec {
    pub name: String,
    pub key: String,
}

/// What the user said about the folder.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportSpec {
    /// Fringe periods in projector pixels, sparsest first; may be empty when
    /// the pattern has `{period}` (then the periods found are used).
    pub periods_px: Vec<f64>,
    /// Shifts per set: one number for every set, or one per set; may be empty
    /// when the pattern has `{shift}` (then counted from the files).
    pub shifts: Vec<usize>,
    pub pattern: Option<String>,
    /// Cameras to take, in order; empty: every camera found.
    pub cameras: Vec<CameraSpec>,
    /// Globs of files to leave out (matched against the relative path and the file name).
    pub skip: Vec<String>,
    /// Calibration file (absolute, or relative to the working folder).
    pub calibration: Option<PathBuf>,
    pub bit_depth: Option<u32>,
    /// +1: `delta_k = offset + 2 pi k / N`; -1: `offset - 2 pi k / N`.
    pub shift_sign: f64,
    pub shift_offset_rad: f64,
}

impl Default for ImportSpec {
    fn default() -> Self {
        Self {
            periods_px: Vec::new(),
            shifts: Vec::new(),
            pattern: None,
            cameras: Vec::new(),
            skip: Vec::new(),
            calibration: None,
            bit_depth: None,
            shift_sign: 1.0,
            shift_offset_rad: 0.0,
        }
    }
}

impl ImportSpec {
    /// The phase shifts the manifest will give a set of `n` images, or `None`
    /// for the default `2 pi k / N`.
    pub fn phase_shifts_rad(&self, n: usize) -> Option<Vec<f64>> {
        if self.shift_sign > 0.0 && self.shift_offset_rad == 0.0 {
            return None;
        }
        let sign = if self.shift_sign < 0.0 { -1.0 } else { 1.0 };
        Some((0..n).map(|k| self.shift_offset_rad + sign * std::f64::consts::TAU * k as f64 / n as f64).collect())
    }
}

/// Parses `left,right` or `left=L,right=R` (manifest name = file key).
pub fn parse_cameras(text: &str) -> Result<Vec<CameraSpec>, ImportFault> {
    let mut out: Vec<CameraSpec> = Vec::new();
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (name, key) = match item.split_once('=') {
            Some((n, k)) => (n.trim(), k.trim()),
            None => (item, item),
        };
        if !valid_camera_name(name) || key.is_empty() {
            return Err(ImportFault::BadCameraName { name: item.to_string() });
        }
        if out.iter().any(|c| c.name == name || c.key == key) {
            return Err(ImportFault::RepeatedCamera { name: item.to_string() });
        }
        out.push(CameraSpec { name: name.to_string(), key: key.to_string() });
    }
    Ok(out)
}

/// Parses a list of numbers such as `912,144,24,12`.
pub fn parse_list<T: std::str::FromStr>(text: &str, what: &'static str) -> Result<Vec<T>, ImportFault> {
    text.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().map_err(|_| ImportFault::BadNumber { what, found: s.to_string() }))
        .collect()
}

/// What is wrong with an import (the folder is named by [`ImportError`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ImportFault {
    #[error("'{found}' in {what} is not a number")]
    BadNumber { what: &'static str, found: String },
    #[error("camera '{name}' is not usable: write NAME or NAME=KEY with letters, digits, '-' or '_'")]
    BadCameraName { name: String },
    #[error("camera '{name}' is given twice")]
    RepeatedCamera { name: String },
    #[error("pattern '{pattern}': {problem}")]
    BadPattern { pattern: String, problem: String },
    #[error("no fringe periods: give the periods (--periods), e.g. 912,144,24,12, sparsest first")]
    NoPeriods,
    #[error("periods {periods} must be positive and strictly decreasing (sparsest first)")]
    PeriodOrder { periods: String },
    #[error("{sets} fringe sets; at most {MAX_SETS} are supported")]
    TooManySets { sets: usize },
    #[error("no shift counts: give the shifts per set (--shifts), e.g. 12, or 12,12,12,4 per set")]
    NoShifts,
    #[error("--shifts lists {found} counts for {sets} sets; give one count, or one per set")]
    ShiftsLength { found: usize, sets: usize },
    #[error("a set needs 3 to {MAX_SHIFTS} shifts, found {found}")]
    BadShiftCount { found: usize },
    #[error("--shift-sign must be 1 or -1, found {found}")]
    BadShiftSign { found: String },
    #[error("holds no image files (PNG, TIFF, BMP or PGM){}", if *skipped > 0 { format!(" that --skip leaves in ({skipped} skipped)") } else { String::new() })]
    NoImages { skipped: usize },
    #[error("no file matches the pattern '{pattern}'{}", example.as_ref().map(|e| format!(" (e.g. {e} does not)")).unwrap_or_default())]
    NothingMatches { pattern: String, example: Option<String> },
    #[error("camera '{camera}' is not in the folder (found: {found})")]
    CameraMissing { camera: String, found: String },
    #[error("camera name '{key}' (from {file}) is not usable in file names: name it with --cameras NAME={key}")]
    UnusableCameraKey { key: String, file: String },
    #[error("holds images of both camera subfolders and loose files; give a --pattern, or --skip the loose ones")]
    Ambiguous,
    #[error("{what} has {found} images but the sets need {needed} ({counts}){hint}")]
    Count { what: String, found: usize, needed: usize, counts: String, hint: &'static str },
    #[error("{what}: {a} and {b} both give {number}")]
    Duplicate { what: String, a: String, b: String, number: String },
    #[error("{what}: image number {missing} is missing (numbers {first} to {last} expected){}", after.as_ref().map(|a| format!(", after {a}")).unwrap_or_default())]
    Gap { what: String, missing: u64, first: u64, last: u64, after: Option<String> },
    #[error("period {period} (from {file}) is not one of --periods {periods}")]
    UnknownPeriod { period: String, file: String, periods: String },
    #[error("camera '{camera}' has no images of set {set} (period {period} px)")]
    SetMissing { camera: String, set: usize, period: String },
    #[error("set {set} (period {period} px) has {a} shifts for camera '{cam_a}' but {b} for '{cam_b}'")]
    ShiftsDiffer { set: usize, period: String, cam_a: String, a: usize, cam_b: String, b: usize },
    #[error("set numbers {found} from {{set}} do not fit --periods ({sets} sets)")]
    SetNumbers { found: String, sets: usize },
    #[error(
        "{file} is {width}x{height} px, but {reference} is {ref_width}x{ref_height} px: one camera's images must all have one size"
    )]
    SizeMismatch { file: String, width: usize, height: usize, reference: String, ref_width: usize, ref_height: usize },
    #[error(
        "{file} is a {bits}-bit file, but {reference} is {ref_bits}-bit: one camera's images must share one sample type"
    )]
    MixedContainers { file: String, bits: u32, reference: String, ref_bits: u32 },
    #[error("--bit-depth {bit_depth} does not fit {file}: {problem}")]
    BitDepth { bit_depth: u32, file: String, problem: String },
    #[error(
        "the manifest {} must be in the image folder or a folder above it (its paths are relative and stay inside its folder)",
        manifest.display()
    )]
    ManifestOutside { manifest: PathBuf },
    #[error(
        "the calibration {} is not in the manifest's folder {} or below it: copy it there (manifest paths stay inside that folder)",
        calibration.display(),
        folder.display()
    )]
    CalibrationOutside { calibration: PathBuf, folder: PathBuf },
    #[error("refusing to write the manifest over {}: it is one of the images", path.display())]
    ManifestIsImage { path: PathBuf },
}

/// An import failure: what, and in which folder.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    #[error("import {}: {fault}", folder.display())]
    Fault { folder: PathBuf, fault: Box<ImportFault> },
    #[error(transparent)]
    Io(#[from] IoError),
}

impl ImportError {
    /// `fault` found while importing `folder`.
    pub fn new(folder: &Path, fault: ImportFault) -> Self {
        ImportError::Fault { folder: folder.to_path_buf(), fault: Box::new(fault) }
    }

    fn at(folder: &Path) -> impl Fn(ImportFault) -> ImportError + '_ {
        move |fault| ImportError::new(folder, fault)
    }
}

// ---------------------------------------------------------------- listing

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

/// Glob match with `*` (any run of characters) and `?` (one character).
pub fn glob_match(glob: &str, text: &str) -> bool {
    let (g, t): (Vec<char>, Vec<char>) = (glob.chars().collect(), text.chars().collect());
    let (mut gi, mut ti) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while ti < t.len() {
        if gi < g.len() && (g[gi] == '?' || g[gi] == t[ti]) {
            gi += 1;
            ti += 1;
        } else if gi < g.len() && g[gi] == '*' {
            star = Some((gi, ti));
            gi += 1;
        } else if let Some((sg, st)) = star {
            gi = sg + 1;
            ti = st + 1;
            star = Some((sg, st + 1));
        } else {
            return false;
        }
    }
    g[gi..].iter().all(|&c| c == '*')
}

fn skipped_by(skip: &[String], file: &str) -> bool {
    let name = file.rsplit('/').next().unwrap_or(file);
    skip.iter().any(|g| glob_match(g, file) || glob_match(g, name))
}

fn valid_camera_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && !name.starts_with('.')
        && name.chars().all(|c| c.is_alphanumeric() || c == '-' || c == '_' || c == '.')
}

// ---------------------------------------------------------------- patterns

#[derive(Clone, Debug, PartialEq)]
enum Token {
    Literal(String),
    Camera,
    Period,
    Set(Option<usize>),
    Shift(Option<usize>),
    Index(Option<usize>),
}

/// A compiled file-name pattern.
#[derive(Clone, Debug, PartialEq)]
pub struct Pattern {
    text: String,
    tokens: Vec<Token>,
}

/// What a pattern read from one file name.
#[derive(Clone, Debug, Default, PartialEq)]
struct Captures {
    camera: Option<String>,
    period: Option<String>,
    set: Option<u64>,
    shift: Option<u64>,
    index: Option<u64>,
}

impl Pattern {
    pub fn parse(text: &str) -> Result<Pattern, ImportFault> {
        let bad = |problem: String| ImportFault::BadPattern { pattern: text.to_string(), problem };
        let mut tokens = Vec::new();
        let mut literal = String::new();
        let mut rest = text;
        while let Some(open) = rest.find('{') {
            literal.push_str(&rest[..open]);
            let close = rest[open..].find('}').ok_or_else(|| bad("a '{' is not closed".into()))? + open;
            let inner = &rest[open + 1..close];
            let (name, width) = match inner.split_once(':') {
                Some((n, w)) => {
                    let width: usize = w
                        .trim_start_matches('0')
                        .parse()
                        .ok()
                        .filter(|&w| w > 0 && w < 20)
                        .ok_or_else(|| bad(format!("{{{inner}}}: the width must be a number such as 02")))?;
                    (n, Some(width))
                }
                None => (inner, None),
            };
            if !literal.is_empty() {
                tokens.push(Token::Literal(std::mem::take(&mut literal)));
            }
            let token = match (name, width) {
                ("camera", None) => Token::Camera,
                ("period", None) => Token::Period,
                ("set", w) => Token::Set(w),
                ("shift", w) => Token::Shift(w),
                ("index", w) => Token::Index(w),
                ("camera" | "period", Some(_)) => return Err(bad(format!("{{{name}}} takes no width"))),
                _ => {
                    return Err(bad(format!(
                        "unknown placeholder {{{inner}}}; use {{camera}}, {{period}}, {{set}}, {{shift}} or {{index}}"
                    )));
                }
            };
            if tokens.iter().any(|t| std::mem::discriminant(t) == std::mem::discriminant(&token)) {
                return Err(bad(format!("{{{name}}} appears twice")));
            }
            tokens.push(token);
            rest = &rest[close + 1..];
        }
        literal.push_str(rest);
        if literal.contains('}') {
            return Err(bad("a '}' has no '{'".into()));
        }
        if !literal.is_empty() {
            tokens.push(Token::Literal(literal));
        }
        let has = |f: fn(&Token) -> bool| tokens.iter().any(f);
        let index = has(|t| matches!(t, Token::Index(_)));
        let shift = has(|t| matches!(t, Token::Shift(_)));
        let set = has(|t| matches!(t, Token::Period | Token::Set(_)));
        if index && (shift || set) {
            return Err(bad(
                "number the images either with {index} (through all sets) or with {period} (or {set}) and {shift}, \
                 not both"
                    .into(),
            ));
        }
        if !(index || (shift && set)) {
            return Err(bad(
                "needs {index}, or {shift} together with {period} or {set}, to tell the images apart".into()
            ));
        }
        if has(|t| matches!(t, Token::Period)) && has(|t| matches!(t, Token::Set(_))) {
            return Err(bad("use {period} or {set}, not both".into()));
        }
        for pair in tokens.windows(2) {
            if !matches!(pair[0], Token::Literal(_)) && !matches!(pair[1], Token::Literal(_)) {
                let unsized_number =
                    |t: &Token| matches!(t, Token::Set(None) | Token::Shift(None) | Token::Index(None));
                if matches!(pair[0], Token::Camera) || unsized_number(&pair[0]) || matches!(pair[0], Token::Period) {
                    return Err(bad(
                        "two placeholders touch; put text between them or give the first a width, e.g. {shift:02}"
                            .into(),
                    ));
                }
            }
        }
        Ok(Pattern { text: text.to_string(), tokens })
    }

    pub fn text(&self) -> &str {
        &self.text
    }

    fn has_camera(&self) -> bool {
        self.tokens.contains(&Token::Camera)
    }

    fn uses_index(&self) -> bool {
        self.tokens.iter().any(|t| matches!(t, Token::Index(_)))
    }

    fn uses_period(&self) -> bool {
        self.tokens.contains(&Token::Period)
    }

    fn captures(&self, text: &str) -> Option<Captures> {
        let mut caps = Captures::default();
        match_from(&self.tokens, text, &mut caps).then_some(caps)
    }
}

/// Backtracking match of `tokens` against all of `text`.
fn match_from(tokens: &[Token], text: &str, caps: &mut Captures) -> bool {
    let Some((first, rest)) = tokens.split_first() else {
        return text.is_empty();
    };
    match first {
        Token::Literal(l) => text.strip_prefix(l.as_str()).is_some_and(|t| match_from(rest, t, caps)),
        Token::Camera => {
            // Shortest first: `cam{camera}_{index}` reads `camL_3` as L.
            for (end, c) in text.char_indices().map(|(i, c)| (i + c.len_utf8(), c)) {
                if c == '/' {
                    break;
                }
                if match_from(rest, &text[end..], caps) {
                    caps.camera = Some(text[..end].to_string());
                    return true;
                }
            }
            false
        }
        Token::Period => {
            let run = text.bytes().take_while(|b| b.is_ascii_digit() || *b == b'.').count();
            for end in (1..=run).rev() {
                let s = &text[..end];
                if s.starts_with('.') || s.ends_with('.') || s.matches('.').count() > 1 {
                    continue;
                }
                if match_from(rest, &text[end..], caps) {
                    caps.period = Some(s.to_string());
                    return true;
                }
            }
            false
        }
        Token::Set(width) | Token::Shift(width) | Token::Index(width) => {
            let run = text.bytes().take_while(u8::is_ascii_digit).count();
            let ends: Vec<usize> = match width {
                Some(w) if *w <= run => vec![*w],
                Some(_) => Vec::new(),
                None => (1..=run.min(18)).rev().collect(),
            };
            for end in ends {
                let Ok(n) = text[..end].parse::<u64>() else { continue };
                if match_from(rest, &text[end..], caps) {
                    match first {
                        Token::Set(_) => caps.set = Some(n),
                        Token::Shift(_) => caps.shift = Some(n),
                        _ => caps.index = Some(n),
                    }
                    return true;
                }
            }
            false
        }
    }
}

// ---------------------------------------------------------------- assignment

/// One fringe set of the assignment.
#[derive(Clone, Debug, PartialEq)]
pub struct AssignedSet {
    pub period_px: f64,
    pub shifts: usize,
    /// Per camera (manifest name), the file of each shift, relative to the folder.
    pub files: BTreeMap<String, Vec<String>>,
}

/// Which file is which camera, set and shift.
#[derive(Clone, Debug, PartialEq)]
pub struct Assignment {
    /// Manifest camera names, in the order found or given.
    pub cameras: Vec<String>,
    /// Sparsest first.
    pub sets: Vec<AssignedSet>,
    /// Image files left out because of `--skip`.
    pub skipped: Vec<String>,
    /// Image files left out for another reason, with it.
    pub ignored: Vec<(String, String)>,
    /// Things worth telling the user that are not errors.
    pub notes: Vec<String>,
}

/// One row of the assignment table.
#[derive(Clone, Debug, PartialEq)]
pub struct AssignmentRow {
    pub camera: String,
    pub set: usize,
    pub period_px: f64,
    pub shift: usize,
    pub file: String,
}

impl Assignment {
    /// Every assigned image, camera by camera, in set and shift order.
    pub fn rows(&self) -> Vec<AssignmentRow> {
        let mut rows = Vec::new();
        for camera in &self.cameras {
            for (s, set) in self.sets.iter().enumerate() {
                for (k, file) in set.files[camera].iter().enumerate() {
                    rows.push(AssignmentRow {
                        camera: camera.clone(),
                        set: s,
                        period_px: set.period_px,
                        shift: k,
                        file: file.clone(),
                    });
                }
            }
        }
        rows
    }

    pub fn image_count(&self) -> usize {
        self.sets.iter().map(|s| s.files.values().map(Vec::len).sum::<usize>()).sum()
    }

    /// The full table as text: one row per image (camera, set, period, shift, file).
    pub fn listing(&self) -> String {
        let mut out = format!("{:<10} {:>3} {:>9} {:>5}  file\n", "camera", "set", "period", "shift");
        for r in self.rows() {
            out.push_str(&format!(
                "{:<10} {:>3} {:>9} {:>5}  {}\n",
                r.camera,
                r.set,
                super::maps::period_label(r.period_px),
                r.shift,
                r.file
            ));
        }
        out
    }

    /// The table as text, condensed: per camera and set, the shift count and its files.
    pub fn table(&self) -> String {
        let mut out = format!("{:<10} {:>3} {:>9} {:>6}  files\n", "camera", "set", "period", "shifts");
        for camera in &self.cameras {
            for (s, set) in self.sets.iter().enumerate() {
                let files = &set.files[camera];
                let shown = match files.len() {
                    0 => String::new(),
                    1..=3 => files.join(", "),
                    n => format!("{}, {}, ... {} ({n} files)", files[0], files[1], files[n - 1]),
                };
                out.push_str(&format!(
                    "{:<10} {:>3} {:>9} {:>6}  {shown}\n",
                    camera,
                    s,
                    super::maps::period_label(set.period_px),
                    set.shifts
                ));
            }
        }
        out
    }
}

fn counts_text(shifts: &[usize]) -> String {
    shifts.iter().map(usize::to_string).collect::<Vec<_>>().join("+")
}

fn periods_text(periods: &[f64]) -> String {
    periods.iter().map(|p| super::maps::period_label(*p)).collect::<Vec<_>>().join(",")
}

/// The periods and shift counts the user gave, checked; shift counts are
/// broadcast to every set.
fn declared_sets(spec: &ImportSpec) -> Result<(Vec<f64>, Option<Vec<usize>>), ImportFault> {
    let periods = spec.periods_px.clone();
    if periods.len() > MAX_SETS {
        return Err(ImportFault::TooManySets { sets: periods.len() });
    }
    if periods.iter().any(|p| !(p.is_finite() && *p > 0.0)) || periods.windows(2).any(|w| w[1] >= w[0]) {
        return Err(ImportFault::PeriodOrder { periods: periods_text(&periods) });
    }
    let shifts = match spec.shifts.len() {
        0 => None,
        1 => Some(vec![spec.shifts[0]; periods.len().max(1)]),
        n if n == periods.len() || periods.is_empty() => Some(spec.shifts.clone()),
        n => return Err(ImportFault::ShiftsLength { found: n, sets: periods.len() }),
    };
    if let Some(s) = &shifts
        && let Some(&bad) = s.iter().find(|&&n| !(3..=MAX_SHIFTS).contains(&n))
    {
        return Err(ImportFault::BadShiftCount { found: bad });
    }
    if !(spec.shift_sign == 1.0 || spec.shift_sign == -1.0) {
        return Err(ImportFault::BadShiftSign { found: spec.shift_sign.to_string() });
    }
    Ok((periods, shifts))
}

/// Assigns the files of a folder (relative paths, e.g. from [`list_files`])
/// to cameras, sets and shifts. Pure: only the names are looked at.
pub fn assign(files: &[String], spec: &ImportSpec) -> Result<Assignment, ImportFault> {
    let (periods, shifts) = declared_sets(spec)?;
    let mut skipped = Vec::new();
    let mut images = Vec::new();
    for f in files.iter().filter(|f| is_image_file(f)) {
        if skipped_by(&spec.skip, f) {
            skipped.push(f.clone());
        } else {
            images.push(f.clone());
        }
    }
    images.sort_by(|a, b| natural_cmp(a, b));
    if images.is_empty() {
        return Err(ImportFault::NoImages { skipped: skipped.len() });
    }
    let mut assignment = match &spec.pattern {
        Some(p) if !p.trim().is_empty() => {
            let pattern = Pattern::parse(p.trim())?;
            assign_by_pattern(&pattern, &images, spec, &periods, shifts)?
        }
        _ => assign_by_folders(&images, spec, &periods, shifts)?,
    };
    assignment.skipped = skipped;
    Ok(assignment)
}

/// Folder mode: subfolders are cameras (or the folder is the one camera),
/// files in natural order.
fn assign_by_folders(
    images: &[String],
    spec: &ImportSpec,
    periods: &[f64],
    shifts: Option<Vec<usize>>,
) -> Result<Assignment, ImportFault> {
    if periods.is_empty() {
        return Err(ImportFault::NoPeriods);
    }
    let shifts = shifts.ok_or(ImportFault::NoShifts)?;
    let mut by_folder: BTreeMap<String, Vec<String>> = BTreeMap::new();
    let mut loose = Vec::new();
    let mut ignored = Vec::new();
    for f in images {
        match f.split_once('/') {
            Some((dir, rest)) if !rest.contains('/') => by_folder.entry(dir.to_string()).or_default().push(f.clone()),
            Some(_) => ignored.push((f.clone(), "is nested deeper than one camera folder".to_string())),
            None => loose.push(f.clone()),
        }
    }
    let mut notes = Vec::new();
    let cameras: Vec<(String, Vec<String>)> = if by_folder.is_empty() {
        let name = single_camera_name(spec, "one camera (the images lie in the folder itself)")?;
        vec![(name, loose)]
    } else {
        if !loose.is_empty() {
            if spec.cameras.is_empty() {
                return Err(ImportFault::Ambiguous);
            }
            for f in loose {
                ignored.push((f, "lies outside the camera folders".to_string()));
            }
        }
        let mut folders: Vec<(String, Vec<String>)> = by_folder.into_iter().collect();
        folders.sort_by(|a, b| natural_cmp(&a.0, &b.0));
        if spec.cameras.is_empty() {
            for (dir, _) in &folders {
                if !valid_camera_name(dir) {
                    return Err(ImportFault::UnusableCameraKey { key: dir.clone(), file: format!("{dir}/") });
                }
            }
            folders
        } else {
            let found = folders.iter().map(|(d, _)| d.clone()).collect::<Vec<_>>().join(", ");
            let mut chosen = Vec::new();
            for cam in &spec.cameras {
                let Some((_, files)) = folders.iter().find(|(d, _)| *d == cam.key) else {
                    return Err(ImportFault::CameraMissing { camera: cam.key.clone(), found });
                };
                chosen.push((cam.name.clone(), files.clone()));
            }
            for (dir, files) in &folders {
                if !spec.cameras.iter().any(|c| c.key == *dir) {
                    notes.push(format!("folder {dir}/ ({} images) is not a chosen camera; left out", files.len()));
                }
            }
            chosen
        }
    };
    let needed: usize = shifts.iter().sum();
    let mut sets: Vec<AssignedSet> = periods
        .iter()
        .zip(&shifts)
        .map(|(&p, &n)| AssignedSet { period_px: p, shifts: n, files: BTreeMap::new() })
        .collect();
    for (name, files) in &cameras {
        if files.len() != needed {
            let dir = files.first().and_then(|f| f.rsplit_once('/')).map_or(".".to_string(), |(d, _)| format!("{d}/"));
            return Err(ImportFault::Count {
                what: format!("camera '{name}' (folder {dir})"),
                found: files.len(),
                needed,
                counts: counts_text(&shifts),
                hint: if files.len() > needed {
                    ": skip the extra images (e.g. Gray code, --skip) or correct the shifts"
                } else {
                    ": check the periods and shifts, and that no image is missing"
                },
            });
        }
        let mut it = files.iter().cloned();
        for set in &mut sets {
            set.files.insert(name.clone(), it.by_ref().take(set.shifts).collect());
        }
    }
    Ok(Assignment { cameras: cameras.into_iter().map(|(n, _)| n).collect(), sets, skipped: Vec::new(), ignored, notes })
}

/// A matched file: camera key and captures.
struct Matched {
    file: String,
    camera: String,
    caps: Captures,
}

fn assign_by_pattern(
    pattern: &Pattern,
    images: &[String],
    spec: &ImportSpec,
    periods: &[f64],
    shifts: Option<Vec<usize>>,
) -> Result<Assignment, ImportFault> {
    let mut matched = Vec::new();
    let mut ignored = Vec::new();
    for f in images {
        match pattern.captures(f) {
            Some(caps) => {
                let camera = caps.camera.clone().unwrap_or_default();
                matched.push(Matched { file: f.clone(), camera, caps });
            }
            None => ignored.push((f.clone(), format!("does not match '{}'", pattern.text()))),
        }
    }
    if matched.is_empty() {
        return Err(ImportFault::NothingMatches {
            pattern: pattern.text().to_string(),
            example: images.first().cloned(),
        });
    }
    // Cameras: keys found (natural order) or the ones given.
    let mut notes = Vec::new();
    let cameras: Vec<CameraSpec> = if !pattern.has_camera() {
        let name = single_camera_name(spec, "one camera (the pattern has no {camera})")?;
        vec![CameraSpec { name, key: String::new() }]
    } else {
        let mut keys: Vec<String> = matched.iter().map(|m| m.camera.clone()).collect();
        keys.sort_by(|a, b| natural_cmp(a, b));
        keys.dedup();
        if spec.cameras.is_empty() {
            for key in &keys {
                if !valid_camera_name(key) {
                    let file = matched.iter().find(|m| m.camera == *key).map(|m| m.file.clone()).unwrap_or_default();
                    return Err(ImportFault::UnusableCameraKey { key: key.clone(), file });
                }
            }
            keys.into_iter().map(|k| CameraSpec { name: k.clone(), key: k }).collect()
        } else {
            for cam in &spec.cameras {
                if !keys.contains(&cam.key) {
                    return Err(ImportFault::CameraMissing { camera: cam.key.clone(), found: keys.join(", ") });
                }
            }
            for m in matched.iter().filter(|m| !spec.cameras.iter().any(|c| c.key == m.camera)) {
                ignored.push((m.file.clone(), format!("its camera '{}' is not one of --cameras", m.camera)));
            }
            spec.cameras.clone()
        }
    };
    matched.retain(|m| cameras.iter().any(|c| c.key == m.camera));

    if pattern.uses_index() {
        if periods.is_empty() {
            return Err(ImportFault::NoPeriods);
        }
        let shifts = shifts.ok_or(ImportFault::NoShifts)?;
        let mut sets: Vec<AssignedSet> = periods
            .iter()
            .zip(&shifts)
            .map(|(&p, &n)| AssignedSet { period_px: p, shifts: n, files: BTreeMap::new() })
            .collect();
        let needed: usize = shifts.iter().sum();
        for cam in &cameras {
            let mut numbered: Vec<(u64, String)> = matched
                .iter()
                .filter(|m| m.camera == cam.key)
                .map(|m| (m.caps.index.unwrap_or(0), m.file.clone()))
                .collect();
            numbered.sort_by(|a, b| a.0.cmp(&b.0).then_with(|| natural_cmp(&a.1, &b.1)));
            let files = sequence(&numbered, needed, &format!("camera '{}'", cam.name), &shifts)?;
            let mut it = files.into_iter();
            for set in &mut sets {
                set.files.insert(cam.name.clone(), it.by_ref().take(set.shifts).collect());
            }
        }
        return Ok(Assignment {
            cameras: cameras.into_iter().map(|c| c.name).collect(),
            sets,
            skipped: Vec::new(),
            ignored,
            notes,
        });
    }

    // {period} or {set}, with {shift}.
    let (set_periods, set_of): (Vec<f64>, Vec<Option<usize>>) = if pattern.uses_period() {
        let values: Vec<f64> = matched
            .iter()
            .map(|m| m.caps.period.as_deref().and_then(|p| p.parse::<f64>().ok()).unwrap_or(f64::NAN))
            .collect();
        let list = if periods.is_empty() {
            let mut found: Vec<f64> = values.iter().copied().filter(|v| v.is_finite() && *v > 0.0).collect();
            found.sort_by(|a, b| b.total_cmp(a));
            found.dedup();
            if found.len() > MAX_SETS {
                return Err(ImportFault::TooManySets { sets: found.len() });
            }
            notes.push(format!("periods from the file names: {}", periods_text(&found)));
            found
        } else {
            periods.to_vec()
        };
        let mut set_of = Vec::with_capacity(values.len());
        for (m, v) in matched.iter().zip(&values) {
            let idx = list.iter().position(|p| (p - v).abs() <= 1e-9 * p.abs().max(1.0));
            if idx.is_none() {
                ignored.push((
                    m.file.clone(),
                    format!("period {} is not in --periods", m.caps.period.clone().unwrap_or_default()),
                ));
            }
            set_of.push(idx);
        }
        (list, set_of)
    } else {
        if periods.is_empty() {
            return Err(ImportFault::NoPeriods);
        }
        let numbers: Vec<u64> = matched.iter().map(|m| m.caps.set.unwrap_or(0)).collect();
        let mut distinct = numbers.clone();
        distinct.sort_unstable();
        distinct.dedup();
        let first = distinct.first().copied().unwrap_or(0);
        if distinct.len() != periods.len() || distinct.iter().enumerate().any(|(i, &n)| n != first + i as u64) {
            return Err(ImportFault::SetNumbers {
                found: distinct.iter().map(u64::to_string).collect::<Vec<_>>().join(","),
                sets: periods.len(),
            });
        }
        (periods.to_vec(), numbers.iter().map(|&n| Some((n - first) as usize)).collect())
    };
    let mut sets: Vec<AssignedSet> = set_periods
        .iter()
        .enumerate()
        .map(|(s, &p)| AssignedSet {
            period_px: p,
            shifts: shifts.as_ref().map_or(0, |v| v.get(s).copied().unwrap_or(v[0])),
            files: BTreeMap::new(),
        })
        .collect();
    for (s, set) in sets.iter_mut().enumerate() {
        let period = super::maps::period_label(set.period_px);
        let mut counted: Option<(String, usize)> = None;
        for cam in &cameras {
            let mut numbered: Vec<(u64, String)> = matched
                .iter()
                .zip(&set_of)
                .filter(|(m, idx)| m.camera == cam.key && **idx == Some(s))
                .map(|(m, _)| (m.caps.shift.unwrap_or(0), m.file.clone()))
                .collect();
            if numbered.is_empty() {
                return Err(ImportFault::SetMissing { camera: cam.name.clone(), set: s, period });
            }
            numbered.sort_by(|a, b| a.0.cmp(&b.0).then_with(|| natural_cmp(&a.1, &b.1)));
            let what = format!("camera '{}' set {s} (period {period} px)", cam.name);
            let needed = if shifts.is_some() { set.shifts } else { numbered.len() };
            if !(3..=MAX_SHIFTS).contains(&needed) {
                return Err(ImportFault::BadShiftCount { found: needed });
            }
            let files = sequence(&numbered, needed, &what, &[needed])?;
            if let Some((other, n)) = &counted
                && *n != files.len()
            {
                return Err(ImportFault::ShiftsDiffer {
                    set: s,
                    period,
                    cam_a: other.clone(),
                    a: *n,
                    cam_b: cam.name.clone(),
                    b: files.len(),
                });
            }
            counted = Some((cam.name.clone(), files.len()));
            set.shifts = files.len();
            set.files.insert(cam.name.clone(), files);
        }
    }
    Ok(Assignment { cameras: cameras.into_iter().map(|c| c.name).collect(), sets, skipped: Vec::new(), ignored, notes })
}

/// Files numbered `first..first + needed` (the smallest number found is the
/// first), in number order; errors name repeats, gaps and wrong counts.
fn sequence(
    numbered: &[(u64, String)],
    needed: usize,
    what: &str,
    shifts: &[usize],
) -> Result<Vec<String>, ImportFault> {
    for pair in numbered.windows(2) {
        if pair[0].0 == pair[1].0 {
            return Err(ImportFault::Duplicate {
                what: what.to_string(),
                a: pair[0].1.clone(),
                b: pair[1].1.clone(),
                number: pair[0].0.to_string(),
            });
        }
    }
    let first = numbered.first().map_or(0, |n| n.0);
    if let Some(i) = numbered.iter().enumerate().position(|(i, n)| n.0 != first + i as u64)
        && i < needed
    {
        return Err(ImportFault::Gap {
            what: what.to_string(),
            missing: first + i as u64,
            first,
            last: first + needed as u64 - 1,
            after: i.checked_sub(1).map(|j| numbered[j].1.clone()),
        });
    }
    if numbered.len() != needed {
        return Err(ImportFault::Count {
            what: what.to_string(),
            found: numbered.len(),
            needed,
            counts: counts_text(shifts),
            hint: if numbered.len() > needed {
                ": skip the extra images (e.g. Gray code, --skip) or correct the shifts"
            } else {
                ": check the periods and shifts, and that no image is missing"
            },
        });
    }
    Ok(numbered.iter().map(|n| n.1.clone()).collect())
}

// ---------------------------------------------------------------- images

/// What the image files hold, per camera.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageFacts {
    /// Per camera (assignment order): width, height, bits per sample of the files.
    pub cameras: Vec<CameraFacts>,
    /// Largest sample over all images, when samples were read (16-bit files).
    pub max_value_dn: Option<u16>,
    /// The bit depth for the manifest: given, 8 for 8-bit files, or the
    /// smallest usual camera depth (10, 12, 14, 16) that holds the largest value.
    pub bit_depth: u32,
    pub notes: Vec<String>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct CameraFacts {
    pub name: String,
    pub width: usize,
    pub height: usize,
    pub container_bits: u32,
}

/// Size and sample type of an image from its header alone where the format
/// allows (PNG, BMP, PGM, TIFF read only what they need), else a full probe.
pub fn read_header(path: &Path) -> Result<images::ImageHeader, IoError> {
    let quick = || -> Option<images::ImageHeader> {
        use image::ImageDecoder as _;
        let decoder = image::ImageReader::open(path).ok()?.with_guessed_format().ok()?.into_decoder().ok()?;
        let (w, h) = decoder.dimensions();
        let bits = match decoder.color_type() {
            image::ColorType::L8 | image::ColorType::La8 | image::ColorType::Rgb8 | image::ColorType::Rgba8 => 8,
            image::ColorType::L16 | image::ColorType::La16 | image::ColorType::Rgb16 | image::ColorType::Rgba16 => 16,
            _ => return None,
        };
        Some(images::ImageHeader { width: w as usize, height: h as usize, container_bits: bits })
    };
    match quick() {
        Some(h) => Ok(h),
        None => images::read_image_header(path),
    }
}

/// Reads the headers of every assigned image (in parallel) and checks one
/// size and one sample type per camera; with `measure_bit_depth`, decodes
/// the 16-bit images to find the largest value (12-bit data in 16-bit files).
pub fn inspect_images(
    folder: &Path,
    assignment: &Assignment,
    spec: &ImportSpec,
    measure_bit_depth: bool,
    control: &RunControl,
) -> Result<ImageFacts, ImportError> {
    let at = ImportError::at(folder);
    control.begin_stage("reading image headers");
    let mut cameras = Vec::new();
    for camera in &assignment.cameras {
        let files: Vec<&String> = assignment.sets.iter().flat_map(|s| s.files[camera].iter()).collect();
        let headers: Vec<Result<images::ImageHeader, IoError>> =
            files.par_iter().map(|f| read_header(&folder.join(f))).collect();
        control.check().map_err(IoError::from)?;
        let mut reference: Option<(&String, images::ImageHeader)> = None;
        for (file, header) in files.iter().zip(headers) {
            let header = header?;
            match &reference {
                None => reference = Some((file, header)),
                Some((rf, rh)) => {
                    if (header.width, header.height) != (rh.width, rh.height) {
                        return Err(at(ImportFault::SizeMismatch {
                            file: (*file).clone(),
                            width: header.width,
                            height: header.height,
                            reference: (*rf).clone(),
                            ref_width: rh.width,
                            ref_height: rh.height,
                        }));
                    }
                    if header.container_bits != rh.container_bits {
                        return Err(at(ImportFault::MixedContainers {
                            file: (*file).clone(),
                            bits: header.container_bits,
                            reference: (*rf).clone(),
                            ref_bits: rh.container_bits,
                        }));
                    }
                }
            }
        }
        if let Some((_, h)) = reference {
            cameras.push(CameraFacts {
                name: camera.clone(),
                width: h.width,
                height: h.height,
                container_bits: h.container_bits,
            });
        }
    }
    let mut notes = Vec::new();
    let sixteen = cameras.iter().any(|c| c.container_bits == 16);
    if sixteen && let Some(c) = cameras.iter().find(|c| c.container_bits == 8) {
        let first = assignment.sets[0].files[&c.name][0].clone();
        return Err(at(ImportFault::MixedContainers {
            file: first,
            bits: 8,
            reference: format!("camera '{}'", cameras.iter().find(|c| c.container_bits == 16).map_or("", |c| &c.name)),
            ref_bits: 16,
        }));
    }
    let mut max_value_dn = None;
    let mut max_file = String::new();
    if sixteen && (measure_bit_depth || spec.bit_depth.is_some()) {
        control.begin_stage("reading the largest sample value");
        let files: Vec<&String> = assignment.sets.iter().flat_map(|s| s.files.values().flatten()).collect();
        let done = std::sync::atomic::AtomicUsize::new(0);
        let maxima: Vec<Result<u16, IoError>> = files
            .par_iter()
            .map(|f| {
                control.check()?;
                let image = images::read_gray_image(&folder.join(f))?;
                let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                control.set_fraction(n as f32 / files.len() as f32);
                Ok(image.max_value_dn)
            })
            .collect();
        let mut best = 0u16;
        for (f, m) in files.iter().zip(maxima) {
            let m = m?;
            if m > best || max_file.is_empty() {
                best = best.max(m);
                max_file = (*f).clone();
            }
        }
        max_value_dn = Some(best);
    }
    let bit_depth = match spec.bit_depth {
        Some(b) => {
            let first = assignment.sets[0].files[&assignment.cameras[0]][0].clone();
            if !(8..=16).contains(&b) {
                return Err(at(ImportFault::BitDepth {
                    bit_depth: b,
                    file: first,
                    problem: "the bit depth must be 8 to 16".into(),
                }));
            }
            if b == 8 && sixteen {
                return Err(at(ImportFault::BitDepth {
                    bit_depth: b,
                    file: first,
                    problem: "it is a 16-bit file; give the camera's bit depth (10, 12, 14 or 16)".into(),
                }));
            }
            if b > 8 && !sixteen {
                return Err(at(ImportFault::BitDepth {
                    bit_depth: b,
                    file: first,
                    problem: "it is an 8-bit file; use --bit-depth 8 or leave it out".into(),
                }));
            }
            if let Some(m) = max_value_dn
                && u32::from(m) > (1u32 << b) - 1
            {
                return Err(at(ImportFault::BitDepth {
                    bit_depth: b,
                    file: max_file,
                    problem: format!(
                        "it holds values up to {m}, above 2^{b} - 1 = {}; the data is {}-bit",
                        (1u32 << b) - 1,
                        images::bits_for_value(m)
                    ),
                }));
            }
            b
        }
        None if !sixteen => 8,
        None => match max_value_dn {
            Some(m) => {
                let needed = images::bits_for_value(m).max(9);
                let depth = [10, 12, 14, 16].into_iter().find(|&d| d >= needed).unwrap_or(16);
                notes.push(format!(
                    "bit depth {depth}: 16-bit files whose largest value is {m} (in {max_file}); give --bit-depth if \
                     the camera has more bits"
                ));
                depth
            }
            None => 16,
        },
    };
    Ok(ImageFacts { cameras, max_value_dn, bit_depth, notes })
}

// ---------------------------------------------------------------- manifest

/// Makes `path` absolute against the working folder, without resolving links.
fn absolute(path: &Path) -> PathBuf {
    if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().map_or_else(|_| path.to_path_buf(), |d| d.join(path))
    }
}

/// `path` relative to `base` (both resolved), with `/` separators, when it
/// lies inside `base`.
fn relative_inside(base: &Path, path: &Path) -> Option<String> {
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
    let manifest_dir = super::manifest::folder_of(manifest_path);
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

// ---------------------------------------------------------------- thumbnails

/// A small 8-bit preview of an image (for the import dialog).
#[derive(Clone, Debug, PartialEq)]
pub struct Thumbnail {
    pub width: usize,
    pub height: usize,
    pub luma: Vec<u8>,
}

/// Decodes `path` and scales it (box average) to at most `max_side` pixels,
/// stretched to its own largest value so 12-bit data in 16-bit files shows.
pub fn thumbnail(path: &Path, max_side: usize) -> Result<Thumbnail, IoError> {
    let image = images::read_gray_image(path)?;
    let (w, h) = (image.width, image.height);
    let step = w.max(h).div_ceil(max_side.max(1)).max(1);
    let (tw, th) = (w.div_ceil(step).max(1), h.div_ceil(step).max(1));
    let sample = |i: usize| -> f32 {
        match &image.pixels {
            GrayPixels::U8(v) => f32::from(v[i]),
            GrayPixels::U16(v) => f32::from(v[i]),
        }
    };
    let scale = 255.0 / f32::from(image.max_value_dn.max(1));
    let mut luma = vec![0u8; tw * th];
    for ty in 0..th {
        for tx in 0..tw {
            let (mut sum, mut n) = (0.0f32, 0u32);
            for y in ty * step..((ty + 1) * step).min(h) {
                for x in tx * step..((tx + 1) * step).min(w) {
                    sum += sample(y * w + x);
                    n += 1;
                }
            }
            luma[ty * tw + tx] = (sum / n.max(1) as f32 * scale).round().clamp(0.0, 255.0) as u8;
        }
    }
    Ok(Thumbnail { width: tw, height: th, luma })
}

#[cfg(test)]
mod tests;
