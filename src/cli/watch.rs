//! `sheen watch`: the production line. The acquisition software drops one
//! folder per part into an inbox; each complete part is reconstructed,
//! found on the stage with the recipe, inspected, recorded and reported, in
//! arrival order, by one process that keeps the engine warm, and one line
//! per part is printed (or one JSON object per line for a part handler).
//!
//! A part is complete when its manifest and every image it names exist and
//! their sizes have not changed for the settle time, or when the recipe's
//! sentinel file appears. A part that stays incomplete past the give-up
//! time, or cannot be read or measured, is recorded as an error with its
//! reason and the watch goes on. A part whose inputs' hash is already in the
//! records under the recipe is not inspected again, so a restart repeats
//! nothing. The next part is read and measured while the one before is
//! written and recorded (two parts in hand at most; records, lines and
//! archiving stay in arrival order). SIGINT or SIGTERM lets the parts in
//! hand finish, then the watch exits 0. A recipe or records database that
//! cannot be opened stops it at once with one line.

use crate::io::recipe_file::{LoadedRecipe, read_recipe};
use std::collections::{HashMap, HashSet};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::{Duration, Instant, SystemTime};

use anyhow::{Context as _, bail};
use clap::Args;

use super::analyze::AnalyzeArgs;
use super::analyze::record;
use crate::analysis::measurement_table::MeasurementKind;
use crate::io;
use crate::io::watch_line::{MeasuredPart, SkipReason, WatchLine, WatchOutcome, WatchValue};
use crate::records::hash::folder_hash;
use crate::records::keep::input_hash;
use crate::records::{DbLocation, PartRecord, PartVerdict, Store};

#[derive(Debug, Args)]
pub struct WatchArgs {
    /// The folder the acquisition software drops each part's folder into.
    pub inbox: PathBuf,
    /// The part type's recipe (`sheen recipe`).
    #[arg(long, value_name = "RECIPE.json")]
    pub recipe: PathBuf,
    /// Records database: a SQLite file or postgres://user@host:port/db
    /// [default: records.sqlite in the platform data folder].
    #[arg(long, value_name = "FILE|URL")]
    pub db: Option<String>,
    /// Results of each part go to DIR/PART [default: INBOX.results beside the inbox].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Also write DIR/PART/report.pdf.
    #[arg(long = "report-pdf")]
    pub report_pdf: bool,
    /// Write each part's results as a Q-DAS AQDEF file into DIR
    /// (PART_TIME.dfq, written atomically, for the plant's SPC to collect).
    #[arg(long = "dfq-dir", value_name = "DIR")]
    pub dfq_dir: Option<PathBuf>,
    /// Write each part's results as a QIF 3.0 Results file into DIR
    /// (PART_TIME.qif, written atomically).
    #[arg(long = "qif-dir", value_name = "DIR")]
    pub qif_dir: Option<PathBuf>,
    /// One JSON object per part on stdout instead of a line of text.
    #[arg(long)]
    pub json: bool,
    /// Move each part's folder here once it is recorded.
    #[arg(long, value_name = "DIR")]
    pub archive: Option<PathBuf>,
    /// Measuring station recorded with each part.
    #[arg(long, value_name = "NAME")]
    pub station: Option<String>,
    /// Operator recorded with each part.
    #[arg(long, value_name = "NAME")]
    pub operator: Option<String>,
    /// Folder for the records' height maps (see `sheen analyze --records-dir`).
    #[arg(long = "records-dir", value_name = "DIR")]
    pub records_dir: Option<PathBuf>,
    /// A part is complete when its files' sizes have not changed for this long.
    #[arg(long = "settle-ms", value_name = "MS", default_value_t = 1000)]
    pub settle_ms: u64,
    /// A part still missing images this long after its last change is
    /// recorded as an error.
    #[arg(long = "give-up-s", value_name = "S", default_value_t = 30)]
    pub give_up_s: u64,
    /// How often the inbox is looked at.
    #[arg(long = "poll-ms", value_name = "MS", default_value_t = 200)]
    pub poll_ms: u64,
    /// Inspect the parts already in the inbox as they are (complete or not),
    /// then exit: for scripts and a backlog.
    #[arg(long)]
    pub once: bool,
    /// When to write a part's map pictures (TIFF, PNG, the difference to the
    /// reference) beside its X3P and measurements: by default only for a part
    /// outside a tolerance, the one an operator looks at.
    #[arg(long = "map-images", value_name = "WHEN", default_value = "failed")]
    pub map_images: super::analyze::MapImages,
    /// Stop as on SIGTERM when standard input closes: how a program that
    /// runs the watch (the app's Line view) stops it on every platform,
    /// without sending a signal.
    #[arg(long = "stop-on-stdin-close")]
    pub stop_on_stdin_close: bool,
}

/// What a part's folder holds when looked at.
#[derive(Clone, Debug, PartialEq)]
struct Snapshot {
    manifest: Option<PathBuf>,
    /// Sizes of the manifest and every file it names that exists.
    sizes: Vec<(PathBuf, u64)>,
    /// Files the manifest names that do not exist (yet).
    missing: usize,
    /// The latest change (status change time where there is one: copying
    /// tools that keep modification times cannot set it back) of any of
    /// those files.
    last_change: Option<SystemTime>,
}

/// A part folder seen in the inbox.
struct Pending {
    folder: PathBuf,
    /// When it was first seen, and its modification time then: arrival order.
    first_seen: (u64, SystemTime),
    last: Option<Snapshot>,
    unchanged_since: Instant,
    /// The files the manifest names, as last parsed, with the manifest's
    /// size and modification time then: while a part settles it is looked
    /// at every poll, and its manifest is parsed again only when it changed.
    named: Option<NamedFiles>,
}

/// A manifest's size and modification time, and the files it names.
type NamedFiles = ((u64, SystemTime), Vec<PathBuf>);

/// Whether a part is ready: complete and settled, or given up on.
#[derive(Clone, Debug, PartialEq)]
enum Readiness {
    Waiting,
    /// Settled with files still missing: inspected as it is (the error
    /// names what is missing) once a later part is ready, since parts arrive
    /// one after the other and this one will not be finished.
    Stalled(PathBuf),
    Complete(PathBuf),
    /// Recorded as an error with this reason.
    GivenUp(String),
}

pub fn run(args: &WatchArgs) -> anyhow::Result<()> {
    let recipe = Arc::new(read_recipe(&args.recipe)?);
    let name = recipe.recipe.name.clone();
    let location = DbLocation::from_option(args.db.as_deref())?;
    let mut store = Store::open(&location)?;
    let inspected: HashSet<String> = store.input_hashes(&name)?;
    drop(store);
    // Checked before any part arrives: a mistake in them is the recipe's,
    // and would otherwise fail every part one by one.
    let import_spec = if recipe.recipe.import.is_empty() {
        None
    } else {
        Some(
            super::import::recipe_import_spec(&recipe.recipe.import)
                .with_context(|| format!("recipe {}", args.recipe.display()))?,
        )
    };
    if !args.inbox.is_dir() {
        bail!("{}: the inbox is not a folder", args.inbox.display());
    }
    // An exchange folder that cannot be made is the watch's error at the
    // start, not every part's.
    for (dir, what) in [(&args.dfq_dir, "the AQDEF folder (--dfq-dir)"), (&args.qif_dir, "the QIF folder (--qif-dir)")]
    {
        if let Some(dir) = dir {
            std::fs::create_dir_all(dir)
                .map_err(|source| io::IoError::Write { path: dir.clone(), source })
                .with_context(|| format!("cannot create {what}"))?;
        }
    }
    let out = args.out.clone().unwrap_or_else(|| io::paths::default_results_folder(&args.inbox));
    let stop = Arc::new(AtomicBool::new(false));
    if !args.once {
        let flag = Arc::clone(&stop);
        ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst)).context("cannot catch SIGINT and SIGTERM")?;
    }
    if args.stop_on_stdin_close {
        let flag = Arc::clone(&stop);
        std::thread::spawn(move || {
            // Whatever arrives is ignored; the end of the stream is the request.
            let _ = std::io::copy(&mut std::io::stdin().lock(), &mut std::io::sink());
            flag.store(true, Ordering::SeqCst);
        });
    }
    eprintln!(
        "sheen: watching {} with recipe '{name}' ({} parts already on record), records in {}",
        args.inbox.display(),
        inspected.len(),
        location.display()
    );

    let importing = import_spec.map(|spec| ImportRoute {
        spec,
        calibration: recipe.recipe.calibration.as_ref().map(|c| args.recipe.parent().unwrap_or(Path::new("")).join(c)),
    });
    let shared = Shared {
        args,
        out: &out,
        importing: importing.as_ref(),
        recipe: &recipe,
        inspected: Mutex::new(inspected),
        turns: RecordTurns::default(),
        last_measured: Mutex::new(None),
    };
    let mut tally = Tally::default();
    std::thread::scope(|scope| watch_loop(scope, &shared, &stop, &mut tally))?;
    eprintln!(
        "sheen: {} parts inspected ({} pass, {} fail, {} inconclusive, {} error), {} skipped as already recorded",
        tally.inspected, tally.pass, tally.fail, tally.inconclusive, tally.error, tally.skipped
    );
    Ok(())
}

/// Parts measured at once: the next part is read and measured while the one
/// before is written, synced and recorded, which leaves the cores idle for
/// a part's file syncs and single-threaded stretches otherwise (a sixth of
/// the time at full size on two cores).
const PARTS_IN_FLIGHT: usize = 2;

/// What every part's inspection shares with the watch.
struct Shared<'a> {
    args: &'a WatchArgs,
    out: &'a Path,
    importing: Option<&'a ImportRoute>,
    recipe: &'a Arc<LoadedRecipe>,
    /// Input hashes on record under the recipe.
    inspected: Mutex<HashSet<String>>,
    turns: RecordTurns,
    /// The last measured part's measurements: the characteristics a part
    /// that cannot be measured is exported with.
    last_measured: Mutex<Option<Vec<crate::records::MeasurementRecord>>>,
}

/// Parts keep their records, and finish, in arrival order: part `k` may keep
/// its record once every part before it has passed.
#[derive(Default)]
struct RecordTurns {
    next: Mutex<u64>,
    passed: Condvar,
}

/// Part `index`'s place in [`RecordTurns`]; passed on drop if not before,
/// so a part that ends early never holds up the ones after it.
struct Turn<'a> {
    turns: &'a RecordTurns,
    index: u64,
    passed: bool,
}

impl Turn<'_> {
    /// Waits until every earlier part has passed.
    fn wait(&self) {
        let mut next = self.turns.next.lock().unwrap_or_else(PoisonError::into_inner);
        while *next < self.index {
            next = self.turns.passed.wait(next).unwrap_or_else(PoisonError::into_inner);
        }
    }

    fn pass(&mut self) {
        if self.passed {
            return;
        }
        self.wait();
        *self.turns.next.lock().unwrap_or_else(PoisonError::into_inner) = self.index + 1;
        self.turns.passed.notify_all();
        self.passed = true;
    }
}

impl Drop for Turn<'_> {
    fn drop(&mut self) {
        self.pass();
    }
}

/// A part in hand: being measured, or settled already (skipped as recorded).
enum InHand<'scope> {
    Measuring(std::thread::ScopedJoinHandle<'scope, anyhow::Result<PartResult>>),
    Settled(PartResult),
}

impl InHand<'_> {
    fn is_finished(&self) -> bool {
        match self {
            InHand::Measuring(handle) => handle.is_finished(),
            InHand::Settled(_) => true,
        }
    }
}

/// The parts in hand in arrival order: folder, content hash, state.
type Running<'scope> = std::collections::VecDeque<(PathBuf, Option<String>, InHand<'scope>)>;

/// Prints, counts and archives the oldest part in hand once it is done.
fn finish_oldest(running: &mut Running<'_>, shared: &Shared<'_>, tally: &mut Tally) -> anyhow::Result<()> {
    let Some((folder, _, in_hand)) = running.pop_front() else { return Ok(()) };
    let result = match in_hand {
        InHand::Measuring(handle) => handle.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))?,
        InHand::Settled(result) => result,
    };
    tally.add(&result);
    print_part(&result, shared.args.json);
    if let (Some(archive), Outcome::Recorded(_)) = (&shared.args.archive, &result.outcome) {
        archive_part(&folder, archive)?;
    }
    Ok(())
}

fn watch_loop<'scope, 'env: 'scope>(
    scope: &'scope std::thread::Scope<'scope, 'env>,
    shared: &'env Shared<'env>,
    stop: &AtomicBool,
    tally: &mut Tally,
) -> anyhow::Result<()> {
    let args = shared.args;
    let (out, importing, recipe) = (shared.out, shared.importing, shared.recipe);
    let mut running: Running<'scope> = Default::default();
    let mut arrivals = 0u64;
    let mut pending: HashMap<PathBuf, Pending> = HashMap::new();
    // The folders taken, with what tells each from a later folder of the
    // same name; a name that leaves the inbox (archived, removed) is
    // forgotten, so a folder dropped again under it is a new part whose
    // content hash decides whether it was measured before.
    let mut done: HashMap<PathBuf, Option<crate::platform::FolderIdentity>> = HashMap::new();
    let mut taken_names: HashSet<PathBuf> = HashSet::new();
    let mut scans = 0u64;
    let mut last_backlog = 0;
    let result = loop {
        while running.front().is_some_and(|(_, _, h)| h.is_finished()) {
            finish_oldest(&mut running, shared, tally)?;
        }
        scans += 1;
        let folders = part_folders(&args.inbox, &[out, args.archive.as_deref().unwrap_or(Path::new(""))])?;
        let present: HashSet<&PathBuf> = folders.iter().collect();
        done.retain(|folder, identity| {
            present.contains(folder) && crate::platform::folder_identity(folder) == *identity
        });
        for folder in folders {
            if !done.contains_key(&folder) && !pending.contains_key(&folder) {
                if taken_names.contains(&folder) {
                    eprintln!(
                        "sheen: {}: a folder of a name taken before arrived again; it is a new part (its content \
                         decides whether it was measured)",
                        folder.display()
                    );
                }
                let modified = std::fs::metadata(&folder).and_then(|m| m.modified()).unwrap_or(SystemTime::UNIX_EPOCH);
                pending.insert(
                    folder.clone(),
                    Pending {
                        folder,
                        first_seen: (scans, modified),
                        last: None,
                        unchanged_since: Instant::now(),
                        named: None,
                    },
                );
            }
        }
        let mut order: Vec<&mut Pending> = pending.values_mut().collect();
        order.sort_by(|a, b| a.first_seen.cmp(&b.first_seen).then_with(|| a.folder.cmp(&b.folder)));
        let states: Vec<(PathBuf, Readiness)> = order
            .into_iter()
            .map(|part| {
                let readiness = if args.once {
                    match snapshot(&part.folder, importing.is_some(), &mut part.named) {
                        Snapshot { manifest: Some(m), .. } => Readiness::Complete(m),
                        _ if importing.is_some() => Readiness::Complete(part.folder.clone()),
                        _ => Readiness::GivenUp("no fringe-set manifest in the part's folder".into()),
                    }
                } else {
                    readiness(part, recipe.recipe.sentinel.as_deref(), importing.is_some(), args)
                };
                (part.folder.clone(), readiness)
            })
            .collect();
        let is_ready = |r: &Readiness| matches!(r, Readiness::Complete(_) | Readiness::GivenUp(_));
        let ready = states.iter().filter(|(_, r)| is_ready(r)).count();
        // The first part in arrival order that can go: a ready one, or a
        // stalled one that a later ready part has overtaken.
        let first_ready = states.iter().position(|(_, r)| is_ready(r));
        let next = first_ready.map(|j| {
            let k = states[..j].iter().position(|(_, r)| matches!(r, Readiness::Stalled(_))).unwrap_or(j);
            let (folder, readiness) = &states[k];
            let readiness = match readiness {
                Readiness::Stalled(manifest) => Readiness::Complete(manifest.clone()),
                other => other.clone(),
            };
            (folder.clone(), readiness)
        });
        if !args.once && ready > 1 && ready != last_backlog {
            eprintln!("sheen: backlog: {} part(s) waiting", ready - 1);
        }
        last_backlog = ready;
        match next {
            Some((folder, readiness)) => {
                pending.remove(&folder);
                done.insert(folder.clone(), crate::platform::folder_identity(&folder));
                taken_names.insert(folder.clone());
                if running.len() >= PARTS_IN_FLIGHT {
                    finish_oldest(&mut running, shared, tally)?;
                }
                let taken = take_part(shared, &folder, readiness);
                // The same content as a part still in hand: that part's record
                // decides whether this one is measured, so it goes first.
                if taken.hash.is_some() && running.iter().any(|(_, hash, _)| hash == &taken.hash) {
                    while !running.is_empty() {
                        finish_oldest(&mut running, shared, tally)?;
                    }
                }
                let hash = taken.hash.clone();
                if hash.as_ref().is_some_and(|h| lock(&shared.inspected).contains(h)) {
                    let Taken { part_id, folder_name, started, .. } = taken;
                    let seconds = started.elapsed().as_secs_f64();
                    let result = PartResult { part_id, folder_name, outcome: Outcome::AlreadyRecorded, seconds };
                    running.push_back((folder, hash, InHand::Settled(result)));
                } else {
                    let turn = Turn { turns: &shared.turns, index: arrivals, passed: false };
                    arrivals += 1;
                    let handle = scope.spawn(move || measure_and_record(shared, taken, turn));
                    running.push_back((folder, hash, InHand::Measuring(handle)));
                }
            }
            None if args.once => break Ok(()),
            None => std::thread::sleep(Duration::from_millis(args.poll_ms)),
        }
        if stop.load(Ordering::SeqCst) {
            eprintln!("sheen: stopping on request; the parts in hand are finished");
            break Ok(());
        }
    };
    // The parts in hand are finished (and an error of one does not lose the others').
    let mut first_error = result.err();
    while !running.is_empty() {
        if let Err(e) = finish_oldest(&mut running, shared, tally) {
            first_error.get_or_insert(e);
        }
    }
    first_error.map_or(Ok(()), Err)
}

/// The subfolders of the inbox, leaving out hidden ones and the watch's own
/// output and archive when they lie inside it.
fn part_folders(inbox: &Path, own: &[&Path]) -> anyhow::Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(inbox).map_err(|source| io::IoError::Read { path: inbox.to_path_buf(), source })?;
    let own: Vec<PathBuf> = own.iter().filter_map(|p| p.canonicalize().ok()).collect();
    Ok(entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .filter(|p| !p.file_name().is_some_and(|n| n.to_string_lossy().starts_with('.')))
        .filter(|p| p.canonicalize().is_ok_and(|c| !own.contains(&c)))
        .collect())
}

/// The part's manifest: `fringe-set.json`, else the folder's only JSON
/// file that is a fringe-set manifest.
fn find_manifest(folder: &Path) -> Option<PathBuf> {
    let standard = folder.join("fringe-set.json");
    if standard.is_file() {
        return Some(standard);
    }
    let jsons: Vec<PathBuf> = std::fs::read_dir(folder)
        .ok()?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")))
        // A calibration or another JSON beside the images is not a manifest.
        .filter(|p| std::fs::read_to_string(p).is_ok_and(|t| t.contains("\"sheen_fringe_set\"")))
        .collect();
    match jsons.as_slice() {
        [one] => Some(one.clone()),
        _ => None,
    }
}

/// How a recipe makes a manifest for a folder of images.
struct ImportRoute {
    /// `sheen import`'s options, parsed and checked at the start.
    spec: io::import::ImportSpec,
    /// The rig's calibration, copied in as `calibration.json` when missing.
    calibration: Option<PathBuf>,
}

/// Every file under `folder` with its size, by path.
fn file_sizes(folder: &Path, out: &mut Vec<(PathBuf, u64)>, last_change: &mut Option<SystemTime>) {
    let Ok(entries) = std::fs::read_dir(folder) else { return };
    for entry in entries.filter_map(Result::ok) {
        let path = entry.path();
        if path.is_dir() {
            file_sizes(&path, out, last_change);
        } else if let Ok(m) = entry.metadata() {
            out.push((path, m.len()));
            *last_change = (*last_change).max(Some(changed(&m)));
        }
    }
}

/// When a file last changed: its status change time on Unix (a copy that
/// keeps the source's modification time still sets it), else its
/// modification time.
fn changed(m: &std::fs::Metadata) -> SystemTime {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        if let Ok(seconds) = u64::try_from(m.ctime()) {
            let nanos = u32::try_from(m.ctime_nsec()).unwrap_or(0);
            return SystemTime::UNIX_EPOCH + Duration::new(seconds, nanos);
        }
    }
    m.modified().unwrap_or(SystemTime::UNIX_EPOCH)
}

/// What the folder holds: the manifest and the files it names, or (a folder
/// of images the recipe imports) every file in it. `named` keeps the last
/// parse of the manifest.
fn snapshot(folder: &Path, importing: bool, named: &mut Option<NamedFiles>) -> Snapshot {
    let mut last_change = None;
    let Some(manifest) = find_manifest(folder) else {
        let mut sizes = Vec::new();
        if importing {
            file_sizes(folder, &mut sizes, &mut last_change);
            sizes.sort();
        }
        return Snapshot { manifest: None, sizes, missing: 0, last_change };
    };
    let mut metadata = |p: &Path| {
        let m = std::fs::metadata(p).ok()?;
        last_change = last_change.max(Some(changed(&m)));
        Some(m)
    };
    let stamp = metadata(&manifest).map(|m| (m.len(), m.modified().unwrap_or(SystemTime::UNIX_EPOCH)));
    let mut sizes = vec![(manifest.clone(), stamp.map_or(0, |s| s.0))];
    let mut missing = 0;
    if stamp.is_none() || named.as_ref().map(|n| n.0) != stamp {
        // A manifest still being written does not parse: nothing it names is known yet.
        *named = match (stamp, io::manifest::read_manifest(&manifest)) {
            (Some(stamp), Ok(m)) => Some((stamp, m.input_paths(&manifest))),
            _ => None,
        };
    }
    match named {
        Some((_, paths)) => {
            for path in paths.iter() {
                match metadata(path) {
                    Some(m) => sizes.push((path.clone(), m.len())),
                    None => missing += 1,
                }
            }
        }
        None => missing += 1,
    }
    Snapshot { manifest: Some(manifest), sizes, missing, last_change }
}

fn readiness(part: &mut Pending, sentinel: Option<&str>, importing: bool, args: &WatchArgs) -> Readiness {
    if let Some(name) = sentinel {
        return match (part.folder.join(name).exists(), find_manifest(&part.folder)) {
            (true, Some(manifest)) => Readiness::Complete(manifest),
            (true, None) if importing => Readiness::Complete(part.folder.clone()),
            (true, None) => Readiness::GivenUp(format!("the sentinel {name} arrived but no fringe-set manifest")),
            (false, _) => Readiness::Waiting,
        };
    }
    let now = snapshot(&part.folder, importing, &mut part.named);
    if part.last.as_ref() != Some(&now) {
        part.last = Some(now);
        part.unchanged_since = Instant::now();
        return Readiness::Waiting;
    }
    // Quiet since it was first seen unchanged, or since its files last
    // changed: a part that arrived while the watch measured the one before
    // has often settled by the time it is looked at, and waiting the whole
    // settle time again would leave the line idle. The files' own times
    // count only once two looks a poll apart agree (a share whose clock
    // runs behind must not make a file still being written look old).
    let files_quiet = now.last_change.and_then(|t| t.elapsed().ok()).unwrap_or_default();
    let quiet = part.unchanged_since.elapsed().max(files_quiet);
    match &now.manifest {
        Some(manifest) if now.missing == 0 && quiet >= Duration::from_millis(args.settle_ms) => {
            Readiness::Complete(manifest.clone())
        }
        Some(manifest) if quiet >= Duration::from_secs(args.give_up_s) => {
            // Inspected as it is: the error names what is missing or broken.
            Readiness::Complete(manifest.clone())
        }
        Some(manifest) if quiet >= Duration::from_millis(args.settle_ms) => Readiness::Stalled(manifest.clone()),
        None if importing && !now.sizes.is_empty() && quiet >= Duration::from_millis(args.settle_ms) => {
            Readiness::Complete(part.folder.clone())
        }
        None if quiet >= Duration::from_secs(args.give_up_s) => {
            Readiness::GivenUp("no fringe-set manifest in the part's folder".into())
        }
        _ => Readiness::Waiting,
    }
}

/// A manifest for a folder of images, as the recipe's import options say,
/// with the rig's calibration copied in when the folder has none (and
/// named to the import unless the options name one).
fn import_folder(folder: &Path, route: &ImportRoute) -> anyhow::Result<PathBuf> {
    if let Some(calibration) = &route.calibration {
        let target = folder.join("calibration.json");
        if !target.exists() {
            // Atomically, as everything Sheen writes: a collector or a
            // second look at the folder never sees half a calibration.
            let source = std::fs::read(calibration)
                .map_err(|source| io::IoError::Read { path: calibration.clone(), source })
                .context("cannot copy the recipe's calibration")?;
            io::atomic::write_atomic(&target, |w| w.write_all(&source))
                .with_context(|| format!("cannot copy the recipe's calibration {}", calibration.display()))?;
        }
    }
    let mut spec = route.spec.clone();
    let calibration = folder.join("calibration.json");
    if calibration.is_file() && spec.calibration.is_none() {
        spec.calibration = Some(calibration);
    }
    super::import::import_part(folder, &spec)
}

enum Outcome {
    Recorded(Box<PartRecord>),
    /// Its inputs' hash is on record under the recipe already.
    AlreadyRecorded,
    /// Measured (or not) but the record could not be kept.
    NotKept {
        record: Box<PartRecord>,
        reason: String,
    },
}

struct PartResult {
    part_id: String,
    /// The part's folder in the inbox, which names its results folder.
    folder_name: String,
    outcome: Outcome,
    seconds: f64,
}

/// A part taken from the inbox: what it is and its content hash, found
/// before it is measured.
struct Taken {
    part_id: String,
    folder_name: String,
    input: PathBuf,
    readiness: Readiness,
    hash: Option<String>,
    started: Instant,
    /// When the watch took the part: its record's time, so that the records'
    /// times follow the arrival order as their row order does.
    taken_utc: chrono::DateTime<chrono::Utc>,
}

fn take_part(shared: &Shared<'_>, folder: &Path, readiness: Readiness) -> Taken {
    let (importing, recipe) = (shared.importing, shared.recipe);
    let started = Instant::now();
    let taken_utc = crate::records::time::now_utc();
    // Results go to a folder of the part folder's own name (two folders may
    // carry one part ID: a part measured again); the ID is the recipe's.
    let folder_name = folder.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let part_id = recipe.recipe.part_id(&folder_name).unwrap_or_else(|| folder_name.clone());
    let mut readiness = readiness;
    if let (Readiness::Complete(path), Some(route)) = (&readiness, importing)
        && path.is_dir()
    {
        readiness = match import_folder(folder, route) {
            Ok(manifest) => Readiness::Complete(manifest),
            Err(e) => {
                Readiness::GivenUp(format!("cannot import the part's images: {}", crate::error_text::error_chain(&e)))
            }
        };
    }
    let input = match &readiness {
        Readiness::Complete(manifest) => manifest.clone(),
        // No manifest: the folder itself is the input, and reading it fails with the reason.
        _ => folder.to_path_buf(),
    };
    let manifest = io::manifest::read_manifest(&input).ok();
    // A part that cannot be read whole is known by its folder's content.
    let hash = input_hash(&input, manifest.as_ref()).or_else(|| folder_hash(folder).ok());
    Taken { part_id, folder_name, input, readiness, hash, started, taken_utc }
}

/// An exchange file's name: the part folder's and the time it was taken
/// (UTC, to the millisecond), so a part dropped again under the same name
/// never replaces a file a collector has not taken yet.
fn exchange_file_name(folder_name: &str, taken_utc: chrono::DateTime<chrono::Utc>, extension: &str) -> String {
    let safe = io::paths::safe_file_stem(folder_name);
    format!("{safe}_{}.{extension}", taken_utc.format("%Y%m%dT%H%M%S%3fZ"))
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The part measured, written and recorded in its turn.
fn measure_and_record(shared: &Shared<'_>, taken: Taken, mut turn: Turn<'_>) -> anyhow::Result<PartResult> {
    let (args, out, recipe) = (shared.args, shared.out, shared.recipe);
    let Taken { part_id, folder_name, input, readiness, hash, started, taken_utc } = taken;
    let part_out = out.join(&folder_name);
    let analyze_args = AnalyzeArgs {
        // The recipe itself was read once, at the start (`RecordOptions`);
        // this names it in the record.
        recipe: Some(args.recipe.to_string_lossy().into_owned()),
        record: true,
        part: Some(part_id.clone()),
        quiet: true,
        db: args.db.clone(),
        station: args.station.clone(),
        operator: args.operator.clone(),
        records_dir: args.records_dir.clone(),
        report_pdf: args.report_pdf.then(|| part_out.join("report.pdf")),
        dfq: args.dfq_dir.as_ref().map(|d| d.join(exchange_file_name(&folder_name, taken_utc, "dfq"))),
        qif: args.qif_dir.as_ref().map(|d| d.join(exchange_file_name(&folder_name, taken_utc, "qif"))),
        map_images: args.map_images,
        ..AnalyzeArgs::new(Some(input), part_out.clone())
    };
    // The recipe and its reference map were read once, at the start.
    let wait_for_turn = || turn.wait();
    let last_measured = || lock(&shared.last_measured).clone();
    let options = record::RecordOptions {
        every_input_is_a_part: true,
        input_hash: hash.clone(),
        recipe: Some(Arc::clone(recipe)),
        before_keep: Some(&wait_for_turn),
        time_utc: Some(taken_utc),
        exchange_template: Some(&last_measured),
    };
    let result = record::inspect_and_record(&analyze_args, &options)?;
    let mut record = result.record;
    if !record.measurements.is_empty() {
        *lock(&shared.last_measured) = Some(record.measurements.clone());
    }
    if let Readiness::GivenUp(reason) = &readiness {
        record.reason = Some(match record.reason {
            Some(r) => format!("{reason}: {r}"),
            None => reason.clone(),
        });
    }
    let outcome = (record, result.kept);
    let seconds = started.elapsed().as_secs_f64();
    let outcome = match outcome {
        (record, Some(Ok(_))) => {
            if let Some(h) = &record.input_hash {
                lock(&shared.inspected).insert(h.clone());
            }
            Outcome::Recorded(Box::new(record))
        }
        (record, Some(Err(reason))) => Outcome::NotKept { record: Box::new(record), reason },
        (record, None) => Outcome::NotKept { record: Box::new(record), reason: "not recorded".into() },
    };
    turn.pass();
    Ok(PartResult { part_id, folder_name, outcome, seconds })
}

#[derive(Default)]
struct Tally {
    inspected: usize,
    pass: usize,
    fail: usize,
    inconclusive: usize,
    error: usize,
    skipped: usize,
}

impl Tally {
    fn add(&mut self, result: &PartResult) {
        let record = match &result.outcome {
            Outcome::AlreadyRecorded => {
                self.skipped += 1;
                return;
            }
            Outcome::Recorded(r) | Outcome::NotKept { record: r, .. } => r,
        };
        self.inspected += 1;
        match record.verdict {
            PartVerdict::Fail => self.fail += 1,
            PartVerdict::Error => self.error += 1,
            PartVerdict::Inconclusive => self.inconclusive += 1,
            PartVerdict::Pass => self.pass += 1,
        }
    }
}

/// The part as the watch's JSON line gives it (`io::watch_line`, what the
/// app's Line view reads).
fn watch_line(result: &PartResult) -> WatchLine {
    let outcome = match &result.outcome {
        Outcome::AlreadyRecorded => WatchOutcome::Skipped { skipped: SkipReason::AlreadyRecorded },
        Outcome::Recorded(record) | Outcome::NotKept { record, .. } => WatchOutcome::Measured(MeasuredPart {
            verdict: record.verdict,
            reason: record.reason.clone(),
            seconds: (result.seconds * 1000.0).round() / 1000.0,
            recorded: matches!(result.outcome, Outcome::Recorded(_)),
            record_error: match &result.outcome {
                Outcome::NotKept { reason, .. } => Some(reason.clone()),
                _ => None,
            },
            decision_rule: record.decision_rule.map(|r| r.name()),
            measurements: record
                .measurements
                .iter()
                // A row of a kind this Sheen does not know cannot come from
                // its own measurement; it is left out rather than mislabelled.
                .filter_map(|m| {
                    Some(WatchValue {
                        name: m.name.clone(),
                        kind: MeasurementKind::from_name(&m.kind)?,
                        value: m.value,
                        unit: m.unit.clone(),
                        verdict: m.verdict,
                        lower_limit: m.lower_limit,
                        upper_limit: m.upper_limit,
                        expanded_uncertainty: m.uncertainty.as_ref().map(|u| u.expanded),
                    })
                })
                .collect(),
        }),
    };
    WatchLine { part: result.part_id.clone(), folder: result.folder_name.clone(), outcome }
}

/// One line per part: ID, verdict, the key values (every toleranced
/// measurement, else the first few), the time; or one JSON object.
fn print_part(result: &PartResult, json: bool) {
    if json {
        println!("{}", watch_line(result).to_json());
        return;
    }
    let (record, kept) = match &result.outcome {
        Outcome::AlreadyRecorded => {
            println!("{}  skipped: already recorded", result.part_id);
            return;
        }
        Outcome::Recorded(r) => (r, None),
        Outcome::NotKept { record, reason } => (record, Some(reason.as_str())),
    };
    let key: Vec<_> = {
        let toleranced: Vec<_> = record
            .measurements
            .iter()
            .filter(|m| {
                m.kind != MeasurementKind::Alignment.name() && (m.lower_limit.is_some() || m.upper_limit.is_some())
            })
            .collect();
        if toleranced.is_empty() {
            record.measurements.iter().filter(|m| m.kind != MeasurementKind::Alignment.name()).take(4).collect()
        } else {
            toleranced
        }
    };
    let values: Vec<String> = key
        .iter()
        .map(|m| match (m.value, &m.uncertainty) {
            (Some(v), Some(u)) => format!("{}={v:.4}±{:.4} {}", m.name, u.expanded, m.unit),
            (Some(v), None) => format!("{}={v:.4} {}", m.name, m.unit),
            (None, _) => format!("{}=-", m.name),
        })
        .collect();
    let mut line = format!("{}  {}", result.part_id, record.verdict.name().to_uppercase());
    if let Some(rule) = record.decision_rule {
        line.push_str(&format!(" ({rule})"));
    }
    if !values.is_empty() {
        line.push_str(&format!("  {}", values.join("  ")));
    }
    if let Some(reason) = &record.reason {
        line.push_str(&format!("  ({reason})"));
    }
    line.push_str(&format!("  {:.2} s", result.seconds));
    if let Some(reason) = kept {
        line.push_str(&format!("  RECORD NOT KEPT: {reason}"));
    }
    println!("{line}");
}

/// Moves the part's folder into the archive (a numbered name if one of the
/// same name is there already).
fn archive_part(folder: &Path, archive: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(archive).map_err(|source| io::IoError::Write { path: archive.to_path_buf(), source })?;
    let name = folder.file_name().unwrap_or_default().to_os_string();
    let mut target = archive.join(&name);
    let mut n = 1;
    while target.exists() {
        let mut numbered = name.clone();
        numbered.push(format!(".{n}"));
        target = archive.join(numbered);
        n += 1;
    }
    std::fs::rename(folder, &target)
        .map_err(|source| io::IoError::Write { path: target.clone(), source })
        .with_context(|| format!("cannot archive {}", folder.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        watch: WatchArgs,
    }

    fn pending(folder: &Path) -> Pending {
        Pending {
            folder: folder.to_path_buf(),
            first_seen: (0, SystemTime::UNIX_EPOCH),
            last: None,
            unchanged_since: Instant::now(),
            named: None,
        }
    }

    fn write_part(folder: &Path) {
        std::fs::create_dir_all(folder).unwrap();
        for name in ["left_00.png", "left_01.png"] {
            std::fs::write(folder.join(name), [0u8; 64]).unwrap();
        }
    }

    #[test]
    fn a_part_whose_files_settled_before_it_was_seen_is_taken_at_the_second_look() {
        let dir = tempfile::tempdir().unwrap();
        let args = Cli::parse_from(["sheen", "inbox", "--recipe", "r.json", "--settle-ms", "300"]).watch;
        let look = |p: &mut Pending| readiness(p, None, true, &args);
        let settled = dir.path().join("settled");
        write_part(&settled);
        std::thread::sleep(Duration::from_millis(400));
        let mut part = pending(&settled);
        assert_eq!(look(&mut part), Readiness::Waiting, "one look says nothing of change");
        assert_eq!(look(&mut part), Readiness::Complete(settled.clone()), "unchanged, and quiet for 400 ms");

        // Files written just now wait out the settle time from their change.
        let fresh = dir.path().join("fresh");
        write_part(&fresh);
        let mut part = pending(&fresh);
        assert_eq!(look(&mut part), Readiness::Waiting);
        assert_eq!(look(&mut part), Readiness::Waiting, "changed a moment ago");
        std::thread::sleep(Duration::from_millis(400));
        // A file that grows between looks starts the wait again.
        std::fs::write(fresh.join("left_01.png"), [0u8; 128]).unwrap();
        assert_eq!(look(&mut part), Readiness::Waiting, "it changed since the last look");
        assert_eq!(look(&mut part), Readiness::Waiting, "and its change is recent");
        std::thread::sleep(Duration::from_millis(400));
        assert_eq!(look(&mut part), Readiness::Complete(fresh.clone()));
    }
}
