//! Which file is which camera, set and shift: by pattern or by folders and
//! natural order. Pure: only the names are looked at.

use super::*;

/// The camera's name when the files name no camera: the one given, or the
/// default; asking for more cameras than the files can hold is an error.
pub(super) fn single_camera_name(spec: &ImportSpec, found: &str) -> Result<String, ImportFault> {
    match spec.cameras.as_slice() {
        [] => Ok(DEFAULT_CAMERA.to_string()),
        [one] => Ok(one.name.clone()),
        more => Err(ImportFault::CameraMissing { camera: more[1].name.clone(), found: found.into() }),
    }
}

/// One fringe set of the assignment.
#[derive(Clone, Debug, PartialEq)]
pub struct AssignedSet {
    pub period_px: f64,
    pub shifts: usize,
    /// The projector axis along which its phase grows.
    pub axis: ProjectorAxis,
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
    /// Per camera, the Gray code frames after the sets (OpenCV layout:
    /// columns, rows, white, black), in file order; empty without a code.
    pub gray_frames: BTreeMap<String, Vec<String>>,
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
                crate::io::maps::period_label(r.period_px),
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
                    crate::io::maps::period_label(set.period_px),
                    set.shifts
                ));
            }
        }
        out
    }
}

pub(super) fn counts_text(shifts: &[usize]) -> String {
    shifts.iter().map(usize::to_string).collect::<Vec<_>>().join("+")
}

pub(super) fn periods_text(periods: &[f64]) -> String {
    periods.iter().map(|p| crate::io::maps::period_label(*p)).collect::<Vec<_>>().join(",")
}

/// The axis of each of `sets` sets: as given, or all x.
pub(super) fn declared_axes(spec: &ImportSpec, sets: usize) -> Result<Vec<ProjectorAxis>, ImportFault> {
    let axes = match spec.axes.len() {
        0 => vec![ProjectorAxis::X; sets],
        n if n == sets => spec.axes.clone(),
        n => return Err(ImportFault::AxesLength { found: n, sets }),
    };
    if spec.projector.is_none() && (spec.gray_code.is_some() || axes.contains(&ProjectorAxis::Y)) {
        return Err(ImportFault::NoProjector);
    }
    Ok(axes)
}

/// Frames after the sets per camera: a Gray code's, or none.
fn gray_frames_expected(spec: &ImportSpec) -> usize {
    spec.gray_code.zip(spec.projector).map_or(0, |(code, projector)| code.frames(projector))
}

/// The periods and shift counts the user gave, checked; shift counts are
/// broadcast to every set.
pub(super) fn declared_sets(spec: &ImportSpec) -> Result<(Vec<f64>, Option<Vec<usize>>), ImportFault> {
    let periods = spec.periods_px.clone();
    if periods.len() > MAX_SETS {
        return Err(ImportFault::TooManySets { sets: periods.len() });
    }
    // The periods come in the files' order (a rig may record its densest set
    // first); the assignment is sorted sparsest first afterwards.
    let axes = declared_axes(spec, periods.len())?;
    let repeated = periods.iter().enumerate().any(|(i, p)| (0..i).any(|j| periods[j] == *p && axes[j] == axes[i]));
    if periods.iter().any(|p| !(p.is_finite() && *p > 0.0)) || repeated {
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
    let globs: Vec<SkipGlob> = spec.skip.iter().map(|g| SkipGlob::new(g)).collect::<Result<_, _>>()?;
    let mut skipped = Vec::new();
    let mut images = Vec::new();
    let mut used = vec![false; globs.len()];
    for f in files.iter().filter(|f| is_image_file(f)) {
        let hits: Vec<usize> = (0..globs.len()).filter(|&g| globs[g].matches(f)).collect();
        if hits.is_empty() {
            images.push(f.clone());
        } else {
            hits.iter().for_each(|&g| used[g] = true);
            skipped.push(f.clone());
        }
    }
    // A glob that leaves nothing out is most likely mistyped: say so rather
    // than import the images it was meant to skip without a word.
    let unused: Vec<String> = globs.iter().zip(&used).filter(|(_, u)| !**u).map(|(g, _)| g.text.clone()).collect();
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
    for glob in unused {
        assignment.notes.push(format!("--skip '{glob}' matches no image file; nothing was left out by it"));
    }
    let axes = declared_axes(spec, assignment.sets.len())?;
    for (set, axis) in assignment.sets.iter_mut().zip(axes) {
        set.axis = axis;
    }
    sort_sparsest_first(&mut assignment);
    Ok(assignment)
}

/// Hierarchical unwrapping goes from the sparsest period to the densest
/// (paper §2.3), so the manifest lists the sets in that order whatever the
/// order the rig wrote them in; the operator is told when they were moved.
/// Sets along projector y follow those along x.
fn sort_sparsest_first(assignment: &mut Assignment) {
    let order = |a: &AssignedSet, b: &AssignedSet| a.axis.cmp(&b.axis).then(b.period_px.total_cmp(&a.period_px));
    if assignment.sets.windows(2).all(|w| order(&w[0], &w[1]) == Ordering::Less) {
        return;
    }
    let given: Vec<f64> = assignment.sets.iter().map(|s| s.period_px).collect();
    assignment.sets.sort_by(order);
    let sorted: Vec<f64> = assignment.sets.iter().map(|s| s.period_px).collect();
    assignment.notes.push(format!(
        "the files hold the sets in the order {}; the manifest lists them sparsest first: {}",
        periods_text(&given),
        periods_text(&sorted)
    ));
}

/// Folder mode: subfolders are cameras (or the folder is the one camera),
/// files in natural order.
pub(super) fn assign_by_folders(
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
    let gray = gray_frames_expected(spec);
    let needed: usize = shifts.iter().sum::<usize>() + gray;
    let mut sets = unassigned_sets(periods, &shifts);
    let mut gray_frames = BTreeMap::new();
    for (name, files) in &cameras {
        if files.len() != needed {
            let dir = files.first().and_then(|f| f.rsplit_once('/')).map_or(".".to_string(), |(d, _)| format!("{d}/"));
            return Err(ImportFault::Count {
                what: format!("camera '{name}' (folder {dir})"),
                found: files.len(),
                needed,
                counts: counts_text_with_gray(&shifts, gray),
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
        if gray > 0 {
            gray_frames.insert(name.clone(), it.collect());
        }
    }
    Ok(Assignment {
        cameras: cameras.into_iter().map(|(n, _)| n).collect(),
        sets,
        skipped: Vec::new(),
        ignored,
        notes,
        gray_frames,
    })
}

/// A matched file: camera key and captures.
pub(super) struct Matched {
    file: String,
    camera: String,
    caps: Captures,
}

pub(super) fn assign_by_pattern(
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
        let mut sets = unassigned_sets(periods, &shifts);
        let gray = gray_frames_expected(spec);
        let needed: usize = shifts.iter().sum::<usize>() + gray;
        let mut gray_frames = BTreeMap::new();
        for cam in &cameras {
            let mut numbered: Vec<(u64, String)> = matched
                .iter()
                .filter(|m| m.camera == cam.key)
                .map(|m| (m.caps.index.unwrap_or(0), m.file.clone()))
                .collect();
            numbered.sort_by(|a, b| a.0.cmp(&b.0).then_with(|| natural_cmp(&a.1, &b.1)));
            let files = sequence(&numbered, needed, &format!("camera '{}'", cam.name), &shifts, gray)?;
            let mut it = files.into_iter();
            for set in &mut sets {
                set.files.insert(cam.name.clone(), it.by_ref().take(set.shifts).collect());
            }
            if gray > 0 {
                gray_frames.insert(cam.name.clone(), it.collect());
            }
        }
        return Ok(Assignment {
            cameras: cameras.into_iter().map(|c| c.name).collect(),
            sets,
            skipped: Vec::new(),
            ignored,
            notes,
            gray_frames,
        });
    }
    if !spec.axes.is_empty() || spec.gray_code.is_some() {
        return Err(ImportFault::NeedsFileOrder);
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
            axis: ProjectorAxis::X,
            shifts: shifts.as_ref().map_or(0, |v| v.get(s).copied().unwrap_or(v[0])),
            files: BTreeMap::new(),
        })
        .collect();
    for (s, set) in sets.iter_mut().enumerate() {
        let period = crate::io::maps::period_label(set.period_px);
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
            let files = sequence(&numbered, needed, &what, &[needed], 0)?;
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
    Ok(Assignment {
        cameras: cameras.into_iter().map(|c| c.name).collect(),
        sets,
        skipped: Vec::new(),
        ignored,
        notes,
        gray_frames: BTreeMap::new(),
    })
}

/// Files numbered `first..first + needed` (the smallest number found is the
/// first), in number order; errors name repeats, gaps and wrong counts.
/// The sets of `periods` with their shift counts, no files yet (axes are
/// set once the files are assigned).
fn unassigned_sets(periods: &[f64], shifts: &[usize]) -> Vec<AssignedSet> {
    periods
        .iter()
        .zip(shifts)
        .map(|(&p, &n)| AssignedSet { period_px: p, shifts: n, axis: ProjectorAxis::X, files: BTreeMap::new() })
        .collect()
}

/// `3+3+3+3`, with `+ 20 Gray code frames` where a code follows.
fn counts_text_with_gray(shifts: &[usize], gray: usize) -> String {
    if gray == 0 { counts_text(shifts) } else { format!("{} + {gray} Gray code frames", counts_text(shifts)) }
}

pub(super) fn sequence(
    numbered: &[(u64, String)],
    needed: usize,
    what: &str,
    shifts: &[usize],
    gray: usize,
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
            counts: counts_text_with_gray(shifts, gray),
            hint: if numbered.len() > needed {
                ": skip the extra images (e.g. Gray code, --skip) or correct the shifts"
            } else {
                ": check the periods and shifts, and that no image is missing"
            },
        });
    }
    Ok(numbered.iter().map(|n| n.1.clone()).collect())
}
