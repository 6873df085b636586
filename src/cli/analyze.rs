//! `sheen analyze`: the quality-control inspection without the
//! GUI. A fringe-set manifest (run through the engine) or a PLY cloud becomes
//! a height map, or another instrument's height map (X3P, SDF, float TIFF)
//! is read as one; an inspection (a JSON spec, a session's, options on the
//! command line, or all merged) is run on it; the measurement table, the
//! section profiles and the height map are written to one folder; the exit
//! code says whether the part passed.

mod inline;
pub(crate) mod record;

use crate::engine::warning::{Warning, WarningKind};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{Context, bail};
use clap::Args;

use self::inline::{InlineItems, Origin, Origins};
use super::progress::ProgressPrinter;
use crate::analysis::alignment::difference_to_reference;
use crate::analysis::height_map::{HeightMap, RasterStats, camera_pitch_mm, height_map_from_cloud};
use crate::analysis::inspection::{
    FlatnessStatistic, InspectionReport, InspectionSpec, MeasurementContext, run_inspection_controlled,
};
use crate::analysis::measurement_table::{DecisionRule, MeasurementTable, Verdict};
use crate::analysis::plane_fit::height_above_plane;
use crate::analysis::profile::Profile;
use crate::analysis::recipe::place_inspection;
use crate::analysis::region::{NamedRegion, region_reaches_a_node};
use crate::analysis::session::Session;
use crate::analysis::texture::measure::HeightNoise;
use crate::analysis::uncertainty::ScaleUncertainty;
use crate::engine::control::RunControl;
use crate::engine::length_unit::LengthUnit;
use crate::engine::pipeline::{self, Method, Params};
use crate::engine::point_cloud::PointCloud;
use crate::io;
use crate::io::colormap::{ColorBar, Colormap, ValueRange, write_map_png};
use crate::io::csv::{write_measurement_csv, write_profile_csv};
use crate::io::height_map_file::{HeightMapFormat, TiffMapScale, read_height_map_file};
use crate::io::maps::{TiffCompression, write_f32_tiff};
use crate::io::x3p::{X3pDataType, X3pMetadata, write_x3p, xsd_date_time_utc};

/// Exit code when the inspection ran and a toleranced measurement failed
/// (or could not be measured).
pub const EXIT_TOLERANCE_FAILED: u8 = 2;
/// Exit status of a part whose verdict is inconclusive (ISO 14253-1: a
/// value within U of a limit, none failed).
pub const EXIT_INCONCLUSIVE: u8 = 4;

/// Format version of `measurements.json`.
pub const MEASUREMENTS_VERSION: u64 = 1;

/// Appended to `sheen analyze --help`.
pub const HELP: &str = "\
Inline inspection (coordinates are stage millimetres, as in the cloud; heights and tolerances micrometres):
  --region NAME=rect:X0,Y0,X1,Y1         rectangle from opposite corners
  --region NAME=circle:CX,CY,R           circle
  --region NAME=polygon:X1,Y1,X2,Y2,...  polygon (at least 3 vertices)
  --level R1[,R2...]                     level the map to the plane of these regions
  --profile NAME=X0,Y0,X1,Y1[@WIDTH_MM]  section between two points, averaged across WIDTH_MM
  --hsection [NAME=]Y_MM[@WIDTH_MM]      horizontal section (along X) through Y
  --vsection [NAME=]X_MM[@WIDTH_MM]      vertical section (along Y) through X
  --flatness REGION[<=TOL_UM][,ls=MM]    peak-to-valley flatness of a region, optional upper limit;
                                         ls: Gaussian S-filter cut-off first (ISO 12781-2), so the
                                         flatness is the surface's, not the noise's
  --flatness-rms REGION[<=TOL_UM][,ls=MM]  RMS flatness
  --step NAME=REF[,REF..]:MEAS[,MEAS..][=NOMINAL±TOL_UM]
                                         step height of MEAS over REF (also NOMINAL+-TOL, NOMINAL+UP-LOW)
  --coplanarity NAME=R1,R2[,...][<=TOL_UM]  coplanarity of lands
  --tilt NAME=R1[,R2...][<=TOL_DEG]     tilt of a fitted plane (against the levelling plane, if any)
  --texture NAME=REGION[,form=none|plane|poly:N][,ls=MM][,lc=MM][,c=UM][,mr=PCT][,PARAM<=X][,PARAM=NOM±TOL]...
                                         ISO 25178-2 areal texture of a region ('all' = the whole map):
                                         F-operator (default plane), Gaussian S-filter at ls and L-filter
                                         at lc (ISO 16610-61), Smr at c um [0], Smc at mr % [10]; one row
                                         'NAME PARAM' per parameter: Sq Ssk Sku Sp Sv Sz Sa Sdq Sdr Smr
                                         Smc Sk Spk Svk Smr1 Smr2 Vmp Vmc Vvc Vvv Sal Str Std (um, volumes
                                         um3/um2 as um, Sdr and ratios %, Ssk Sku Sdq Str 1, Sal mm,
                                         Std deg: the lay's direction from X towards Y). Ssk and Smc take only
                                         PARAM=NOM±TOL. e.g. --texture 'seal=face,form=plane,lc=0.8,Sa<=0.4'
  --roughness PROFILE[,ls=MM][,lc=MM][,c=UM][,PARAM<=X][,PARAM=NOM±TOL]...
                                         ISO 21920-2 parameters of a profile's R, W and P profiles: Ra Rq
                                         Rsk Rku Rp Rv Rz Rt RSm Rdq Rmr Rdc (and Pa.., Wa..); line removed,
                                         Gaussian S-filter at ls and L-filter at lc (ISO 16610-21), by
                                         default chosen from the measured Ra (ISO 21920-3: 0.08, 0.25,
                                         0.8, 2.5, 8 mm); rows 'PROFILE PARAM' (RSm in mm, Rmr %, Rsk Rku
                                         Rdq 1, Rdc(20 %, 80 %) um); e.g. --roughness 'A-A,lc=0.8,Ra<=0.4'
Names may contain spaces but not '=', ',' or ':'. Options are merged with --spec or --session: an
inline item replaces the file's item of the same name, --level replaces the file's levelling and
--pitch-mm its pitch.

Outputs in --out DIR: measurements.csv, measurements.json (table with units, limits and verdicts),
inspection.json (the merged spec that was run), profile_<name>.csv per profile (distance_mm, x_mm,
y_mm, z_um, n), height_map.x3p (ISO 25178-72), height_map.tif (float32 micrometres, NaN = no data),
height_map.png (colour bar in um); a texture row carries 'parameter' and a note that starts
'near the resolution limit:' when λs is missing or below twice the pitch, or Sq is within twice
the height noise (the cloud's median height sigma, else estimated from the map); the TIFF, PNG and X3P are north up (first row = largest Y, as the
camera sees the part, like the app's exports; the X3P's Y grows with the row, southward); with
--level the same three as height_map_levelled.*; with --recipe difference_to_reference.tif and
.png (the part less its aligned reference, um); --ply adds cloud.ply. --map-images failed writes
the TIFF and PNG pictures only for a part outside a tolerance (never: not at all).

Other instruments' height maps as input: MAP.x3p (ISO 25178-72: float or integer heights, X and Y
increments that differ are resampled onto a square grid at the finer one), MAP.sdf (ISO 25178-71,
text or binary) and MAP.tif (single-channel float32/float64; --pixel-mm gives its pixel size,
--z-unit its heights' unit, default um; first row north, as Sheen writes it). The map is inspected
as it is: no rasterization, its own pitch, no cloud (so no --ply, no --pitch-mm).

Exit codes: 0 the inspection ran and every toleranced measurement passed (or none is toleranced);
1 error (bad input or option, nothing measured); 2 a toleranced measurement failed or could not be
measured.";

#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    /// A fringe-set manifest (JSON; the engine runs first), a point cloud
    /// (PLY), or a height map from another instrument (X3P, SDF, float TIFF).
    /// With --session it defaults to the session's manifest.
    pub input: Option<PathBuf>,
    /// Output folder (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Inspection spec (JSON, "sheen_inspection": 1) to run.
    #[arg(long, value_name = "INSPECTION.json", conflicts_with = "session")]
    pub spec: Option<PathBuf>,
    /// Session file saved by the app: its manifest, engine parameters and inspection.
    #[arg(long, value_name = "SESSION.json")]
    pub session: Option<PathBuf>,
    /// Height-map pitch in mm [default: the spec's, else the left camera's
    /// pixel pitch from the calibration, else estimated from the cloud].
    #[arg(long = "pitch-mm", value_name = "MM")]
    pub pitch_mm: Option<f64>,
    /// Pixel size in mm of a TIFF height map given as input (X3P and SDF carry theirs).
    #[arg(long = "pixel-mm", value_name = "MM")]
    pub pixel_mm: Option<f64>,
    /// Unit of a TIFF height map's values: um, nm or mm [default: um, as Sheen writes them].
    #[arg(long = "z-unit", value_name = "UNIT", value_parser = parse_z_unit)]
    pub z_unit: Option<LengthUnit>,
    /// Level the map to the plane fitted to these regions (comma-separated).
    #[arg(long, value_name = "R1,R2")]
    pub level: Option<String>,
    /// A region of interest (repeatable); see below.
    #[arg(long = "region", value_name = "NAME=SHAPE:COORDS", allow_hyphen_values = true)]
    pub regions: Vec<String>,
    /// A section profile between two points (repeatable).
    #[arg(long = "profile", value_name = "NAME=X0,Y0,X1,Y1[@W]", allow_hyphen_values = true)]
    pub profiles: Vec<String>,
    /// A horizontal section through Y (repeatable).
    #[arg(long = "hsection", value_name = "[NAME=]Y_MM[@W]", allow_hyphen_values = true)]
    pub hsections: Vec<String>,
    /// A vertical section through X (repeatable).
    #[arg(long = "vsection", value_name = "[NAME=]X_MM[@W]", allow_hyphen_values = true)]
    pub vsections: Vec<String>,
    /// Station spacing of the inline profiles in mm [default: the map pitch].
    #[arg(long = "profile-step", value_name = "MM")]
    pub profile_step: Option<f64>,
    /// Peak-to-valley flatness of a region (repeatable).
    #[arg(long = "flatness", value_name = "REGION[<=TOL]")]
    pub flatness: Vec<String>,
    /// RMS flatness of a region (repeatable).
    #[arg(long = "flatness-rms", value_name = "REGION[<=TOL]")]
    pub flatness_rms: Vec<String>,
    /// Step height between region sets (repeatable).
    #[arg(long = "step", value_name = "NAME=REF:MEAS[=NOM±TOL]", allow_hyphen_values = true)]
    pub steps: Vec<String>,
    /// Coplanarity of lands (repeatable).
    #[arg(long = "coplanarity", value_name = "NAME=R1,R2[<=TOL]")]
    pub coplanarity: Vec<String>,
    /// Tilt of the plane fitted to regions (repeatable).
    #[arg(long = "tilt", value_name = "NAME=R1[<=TOL]")]
    pub tilts: Vec<String>,
    /// Profile (ISO 21920-2) parameters of a section profile (repeatable); see below.
    #[arg(long = "roughness", value_name = "PROFILE[,KEY=V][,PARAM<=X]", allow_hyphen_values = true)]
    pub roughness: Vec<String>,
    /// Areal texture parameters of a region (repeatable); see below.
    #[arg(long = "texture", value_name = "NAME=REGION[,KEY=V][,PARAM<=X]", allow_hyphen_values = true)]
    pub textures: Vec<String>,
    /// How toleranced rows are judged against their expanded uncertainty U:
    /// iso-14253-1 (default: pass inside the limits shrunk by U, fail
    /// outside them widened by U, else inconclusive, exit code 4), simple
    /// (ILAC-G8 simple acceptance), guard-band:F (pass inside the limits
    /// shrunk by F x U, else fail). Replaces the spec's, session's or recipe's.
    #[arg(long = "decision-rule", value_name = "RULE")]
    pub decision_rule: Option<DecisionRule>,
    /// Monte Carlo trials for the uncertainty of flatness, coplanarity,
    /// texture and profile rows [default: the spec's, else 50]; 0 turns
    /// them off (those rows then state no uncertainty).
    #[arg(long = "monte-carlo-trials", value_name = "N")]
    pub monte_carlo_trials: Option<usize>,
    /// Also write the point cloud as DIR/cloud.ply.
    #[arg(long)]
    pub ply: bool,
    /// Engine method for a manifest [default: the session's, else hdr].
    #[arg(long)]
    pub method: Option<Method>,
    /// Saturation threshold in grey levels [default: the session's, else the manifest's level].
    #[arg(long = "sat-threshold", value_name = "T")]
    pub sat_threshold: Option<u16>,
    /// Minimum fringe modulation in grey levels [default: the session's, else 4].
    #[arg(long = "min-modulation", value_name = "B")]
    pub min_modulation: Option<f32>,
    /// Leave this set out of unwrapping and fusion (repeatable).
    #[arg(long = "disable-set", value_name = "SET")]
    pub disable_set: Vec<usize>,
    /// Leave out points whose height uncertainty exceeds this many micrometres [default: 100].
    #[arg(long = "max-sigma-z", value_name = "UM")]
    pub max_sigma_z: Option<f32>,
    /// Keep every point, however uncertain.
    #[arg(long = "keep-uncertain")]
    pub keep_uncertain: bool,
    /// How fringe orders are accepted: evidence, strict or off (see `sheen
    /// reconstruct --help`) [default: the session's, else evidence].
    #[arg(long = "order-check", value_name = "RULE")]
    pub order_check: Option<crate::engine::unwrap::OrderCheck>,
    /// Leave out pixels whose fringe orders needed their neighbours' or their
    /// patch's evidence.
    #[arg(long = "own-orders-only")]
    pub own_orders_only: bool,
    /// Stereo matching: strict or plain [default: the session's, else strict].
    #[arg(long = "stereo-continuity", value_name = "RULE")]
    pub stereo_continuity: Option<crate::engine::stereo_match::StereoContinuity>,
    /// No progress on stderr and no table on stdout.
    #[arg(long, short)]
    pub quiet: bool,
    /// Keep the result as a record in the inspection database (see `sheen
    /// history`); exit code 1 when the record cannot be kept.
    #[arg(long)]
    pub record: bool,
    /// Records database: a SQLite file or postgres://user@host:port/db
    /// [default: records.sqlite in the platform data folder].
    #[arg(long, value_name = "FILE|URL", requires = "record")]
    pub db: Option<String>,
    /// Part ID for the record and the report [default: the manifest's folder
    /// name, else the input's file stem].
    #[arg(long, value_name = "ID")]
    pub part: Option<String>,
    /// A recipe file (`sheen recipe`): its engine parameters and inspection,
    /// with every region and section moved to where the part lies (a part
    /// it does not match is not measured: "part not found"). Any other value
    /// is the recipe name the part is recorded and reported under [default:
    /// the spec's or session's file stem].
    #[arg(long, value_name = "RECIPE.json|NAME")]
    pub recipe: Option<String>,
    /// Measuring station recorded and reported with the part.
    #[arg(long, value_name = "NAME")]
    pub station: Option<String>,
    /// Operator recorded and reported with the part.
    #[arg(long, value_name = "NAME")]
    pub operator: Option<String>,
    /// Folder for the records' height maps (X3P) [default: records/ beside
    /// the SQLite file; for PostgreSQL records/ in the data folder].
    #[arg(long = "records-dir", value_name = "DIR", requires = "record")]
    pub records_dir: Option<PathBuf>,
    /// Write the part's report as one self-contained HTML page (the map
    /// with regions and sections, profiles, table, verdict, input hash).
    #[arg(long = "report-html", value_name = "FILE")]
    pub report_html: Option<PathBuf>,
    /// Write the part's report as an A4 PDF with its font embedded.
    #[arg(long = "report-pdf", value_name = "FILE")]
    pub report_pdf: Option<PathBuf>,
    /// Write the part's results as a Q-DAS AQDEF transfer file (.dfq) for
    /// the plant's SPC (qs-STAT, O-QIS, procella); a part that could not be
    /// measured is written as invalid values.
    #[arg(long, value_name = "FILE")]
    pub dfq: Option<PathBuf>,
    /// Write the part's results as a QIF 3.0 Results document (ISO 23952).
    #[arg(long, value_name = "FILE")]
    pub qif: Option<PathBuf>,
    /// When to write the map's pictures beside its X3P: the TIFF and PNG of
    /// the height map (and of the levelled map) and, with a recipe, of the
    /// difference to its reference.
    #[arg(long = "map-images", value_name = "WHEN", default_value = "always")]
    pub map_images: MapImages,
}

impl AnalyzeArgs {
    /// Whether the run writes files about the part beyond its measurements
    /// (reports, exchange files): those need the part's record, measured or
    /// not.
    pub fn documents_the_part(&self) -> bool {
        self.report_html.is_some() || self.report_pdf.is_some() || self.dfq.is_some() || self.qif.is_some()
    }

    /// The files this run writes about the part.
    fn part_documents(&self) -> impl Iterator<Item = &PathBuf> {
        self.report_html.iter().chain(&self.report_pdf).chain(&self.dfq).chain(&self.qif)
    }

    /// `sheen analyze INPUT --out OUT` with every other option at its
    /// default: what the watch and `sheen recipe` start from and set fields
    /// on, typed, instead of writing a command line and parsing it again
    /// (a test pins it to the command line's defaults).
    pub fn new(input: Option<PathBuf>, out: PathBuf) -> Self {
        Self {
            input,
            out,
            spec: None,
            session: None,
            pitch_mm: None,
            pixel_mm: None,
            z_unit: None,
            level: None,
            regions: Vec::new(),
            profiles: Vec::new(),
            hsections: Vec::new(),
            vsections: Vec::new(),
            profile_step: None,
            flatness: Vec::new(),
            flatness_rms: Vec::new(),
            steps: Vec::new(),
            coplanarity: Vec::new(),
            tilts: Vec::new(),
            roughness: Vec::new(),
            textures: Vec::new(),
            decision_rule: None,
            monte_carlo_trials: None,
            ply: false,
            method: None,
            sat_threshold: None,
            min_modulation: None,
            disable_set: Vec::new(),
            max_sigma_z: None,
            keep_uncertain: false,
            order_check: None,
            own_orders_only: false,
            stereo_continuity: None,
            quiet: false,
            record: false,
            db: None,
            part: None,
            recipe: None,
            station: None,
            operator: None,
            records_dir: None,
            report_html: None,
            report_pdf: None,
            dfq: None,
            qif: None,
            map_images: MapImages::Always,
        }
    }
}

/// When a part's map pictures are written. The X3P, the measurements and
/// the profiles are written for every measured part.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MapImages {
    Always,
    /// Only for a part outside a tolerance: on a line, the parts an operator
    /// looks at (a full-size part's pictures are 40 MB, at a part every
    /// 1.2 s about 120 GB an hour).
    Failed,
    Never,
}

impl MapImages {
    fn wanted(self, table: &MeasurementTable) -> bool {
        match self {
            MapImages::Always => true,
            MapImages::Failed => table.overall_verdict() == Some(Verdict::Fail),
            MapImages::Never => false,
        }
    }
}

/// The pictures [`MapImages`] may leave out.
const MAP_IMAGE_FILES: [&str; 6] = [
    "height_map.tif",
    "height_map.png",
    "difference_to_reference.tif",
    "difference_to_reference.png",
    "height_map_levelled.tif",
    "height_map_levelled.png",
];

fn parse_z_unit(s: &str) -> Result<LengthUnit, String> {
    s.parse().map_err(|e: crate::engine::length_unit::UnknownLengthUnit| e.to_string())
}

/// What the input file is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum InputKind {
    Manifest,
    Ply,
    HeightMap(HeightMapFormat),
}

fn input_kind(path: &Path) -> anyhow::Result<InputKind> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("ply") => return Ok(InputKind::Ply),
        Some("json") => return Ok(InputKind::Manifest),
        _ => {}
    }
    if let Some(format) = HeightMapFormat::of(path) {
        return Ok(InputKind::HeightMap(format));
    }
    let mut head = [0u8; 16];
    let n = std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read(&mut f, &mut head))
        .map_err(|source| io::IoError::Read { path: path.to_path_buf(), source })?;
    let text = String::from_utf8_lossy(&head[..n]);
    if text.starts_with("ply") {
        Ok(InputKind::Ply)
    } else if text.trim_start().starts_with('{') {
        Ok(InputKind::Manifest)
    } else {
        bail!(
            "{}: neither a fringe-set manifest (JSON), a PLY point cloud, nor a height map (X3P, SDF, TIFF)",
            path.display()
        )
    }
}

/// A session or spec given where the measurement belongs gets a pointer to
/// the right option instead of a manifest error about missing fields.
fn refuse_other_sheen_json(path: &Path) -> anyhow::Result<()> {
    let Ok(text) = std::fs::read_to_string(path) else { return Ok(()) };
    let Ok(serde_json::Value::Object(map)) = serde_json::from_str::<serde_json::Value>(&text) else { return Ok(()) };
    let p = path.display();
    if map.contains_key("sheen_session") {
        bail!("{p} is a Sheen session, not a fringe-set manifest; run `sheen analyze --session {p} --out DIR`");
    }
    if map.contains_key("sheen_inspection") {
        bail!(
            "{p} is an inspection spec, not a fringe-set manifest; run `sheen analyze MANIFEST --spec {p} --out DIR`"
        );
    }
    Ok(())
}

fn read_text(path: &Path) -> anyhow::Result<String> {
    std::fs::read_to_string(path).map_err(|source| io::IoError::Read { path: path.to_path_buf(), source }.into())
}

/// The spec, engine parameters and manifest a session or spec file gives.
struct Base {
    spec: InspectionSpec,
    origin: Origin,
    params: Option<Params>,
    session_manifest: Option<PathBuf>,
    recipe: Option<Arc<LoadedRecipe>>,
}

use crate::io::recipe_file::{LoadedRecipe, read_recipe};

/// The recipe file `--recipe` names, if it names one: a value that is an
/// existing file or ends in `.json` (a missing recipe file is an error, not
/// a recipe name).
pub(super) fn recipe_file(args: &AnalyzeArgs) -> Option<&Path> {
    let value = Path::new(args.recipe.as_deref()?);
    let is_json = value.extension().is_some_and(|e| e.eq_ignore_ascii_case("json"));
    (value.is_file() || is_json).then_some(value)
}

/// The spec and parameters the options name; a recipe the caller has read
/// already (`sheen watch`, once for every part) is not read again.
fn load_base(args: &AnalyzeArgs, preloaded: Option<Arc<LoadedRecipe>>) -> anyhow::Result<Base> {
    if let Some(path) = recipe_file(args) {
        if args.spec.is_some() || args.session.is_some() {
            bail!(
                "--recipe {}: a recipe carries its own inspection and engine parameters; leave out --spec and --session",
                path.display()
            );
        }
        let loaded = match preloaded {
            Some(loaded) => loaded,
            None => Arc::new(read_recipe(path)?),
        };
        return Ok(Base {
            spec: loaded.recipe.session.inspection.clone(),
            origin: Origin(format!("recipe {}", path.display())),
            params: Some(loaded.recipe.session.params.clone()),
            session_manifest: None,
            recipe: Some(loaded),
        });
    }
    if let Some(path) = &args.session {
        let session = Session::from_json(&read_text(path)?).with_context(|| format!("session {}", path.display()))?;
        // The app stores the manifest relative to the session file's folder
        // (or absolute); resolve it the same way.
        let manifest = if session.manifest.is_absolute() {
            session.manifest.clone()
        } else {
            path.parent().unwrap_or(Path::new("")).join(&session.manifest)
        };
        return Ok(Base {
            spec: session.inspection,
            origin: Origin(format!("session {}", path.display())),
            params: Some(session.params),
            session_manifest: Some(manifest),
            recipe: None,
        });
    }
    if let Some(path) = &args.spec {
        let spec = InspectionSpec::from_json(&read_text(path)?)
            .with_context(|| format!("inspection spec {}", path.display()))?;
        return Ok(Base {
            spec,
            origin: Origin(format!("inspection spec {}", path.display())),
            params: None,
            session_manifest: None,
            recipe: None,
        });
    }
    Ok(Base {
        spec: InspectionSpec::default(),
        origin: Origin::default(),
        params: None,
        session_manifest: None,
        recipe: None,
    })
}

fn inline_items(args: &AnalyzeArgs) -> anyhow::Result<InlineItems> {
    if let Some(step) = args.profile_step
        && !(step.is_finite() && step > 0.0)
    {
        bail!("--profile-step {step}: the station spacing must be a positive length in mm");
    }
    let mut items = InlineItems::default();
    for v in &args.regions {
        items.regions.push((inline::parse_region(v)?, Origin::option("--region", v)));
    }
    for v in &args.profiles {
        items.profiles.push((inline::parse_profile(v, args.profile_step)?, Origin::option("--profile", v)));
    }
    for v in &args.hsections {
        items.profiles.push((inline::parse_section(v, true, args.profile_step)?, Origin::option("--hsection", v)));
    }
    for v in &args.vsections {
        items.profiles.push((inline::parse_section(v, false, args.profile_step)?, Origin::option("--vsection", v)));
    }
    for v in &args.flatness {
        items
            .measurements
            .push((inline::parse_flatness(v, FlatnessStatistic::PeakToValley)?, Origin::option("--flatness", v)));
    }
    for v in &args.flatness_rms {
        items
            .measurements
            .push((inline::parse_flatness(v, FlatnessStatistic::Rms)?, Origin::option("--flatness-rms", v)));
    }
    for v in &args.steps {
        items.measurements.push((inline::parse_step(v)?, Origin::option("--step", v)));
    }
    for v in &args.coplanarity {
        items.measurements.push((inline::parse_coplanarity(v)?, Origin::option("--coplanarity", v)));
    }
    for v in &args.tilts {
        items.measurements.push((inline::parse_tilt(v)?, Origin::option("--tilt", v)));
    }
    for v in &args.roughness {
        items.measurements.push((inline::parse_roughness(v)?, Origin::option("--roughness", v)));
    }
    for v in &args.textures {
        items.measurements.push((inline::parse_texture(v)?, Origin::option("--texture", v)));
    }
    if let Some(v) = &args.level {
        items.level_to = Some((inline::parse_level(v)?, Origin::option("--level", v)));
    }
    Ok(items)
}

/// Checks that inline names are unique among themselves (a file item may be
/// replaced, but two options naming the same thing is a typo).
fn check_inline_duplicates(items: &InlineItems) -> anyhow::Result<()> {
    fn dup<'a>(kind: &str, it: impl Iterator<Item = (&'a str, &'a Origin)>) -> anyhow::Result<()> {
        let mut seen: Vec<(&str, &Origin)> = Vec::new();
        for (name, origin) in it {
            if let Some((_, first)) = seen.iter().find(|(n, _)| *n == name) {
                bail!("{origin}: a {kind} named '{name}' is already defined by {first}; names must be unique");
            }
            seen.push((name, origin));
        }
        Ok(())
    }
    dup("region", items.regions.iter().map(|(r, o)| (r.name.as_str(), o)))?;
    dup("profile", items.profiles.iter().map(|(p, o)| (p.name.as_str(), o)))?;
    dup("measurement", items.measurements.iter().map(|(m, o)| (m.name.as_str(), o)))
}

/// The engine parameters: the session's (if any), overridden by options.
fn engine_params(args: &AnalyzeArgs, base: Option<&Params>, sets: usize, bit_depth: u32) -> anyhow::Result<Params> {
    let mut p = base.cloned().unwrap_or_default();
    if let Some(m) = args.method {
        p.method = m;
    }
    for &s in &args.disable_set {
        if s >= sets {
            bail!("--disable-set {s}: the manifest has {sets} sets (0 to {})", sets.saturating_sub(1));
        }
    }
    if !args.disable_set.is_empty() {
        p.enabled_sets = (0..sets).map(|s| !args.disable_set.contains(&s)).collect();
    } else if !p.enabled_sets.is_empty() && p.enabled_sets.len() != sets {
        bail!(
            "the session enables {} fringe sets but the manifest has {sets}; the session belongs to another kind of \
             measurement",
            p.enabled_sets.len()
        );
    }
    let max = if bit_depth >= 16 { u16::MAX } else { (1u16 << bit_depth) - 1 };
    if let Some(t) = args.sat_threshold {
        if t == 0 || t > max {
            bail!("--sat-threshold {t} is outside 1..={max} for {bit_depth}-bit data");
        }
        p.saturation_threshold = Some(t);
    }
    if let Some(b) = args.min_modulation {
        if !(b >= 0.0) {
            bail!("--min-modulation must be a non-negative number of grey levels, got {b}");
        }
        p.min_modulation_dn = b;
    }
    if let Some(s) = args.max_sigma_z {
        if !(s > 0.0) {
            bail!("--max-sigma-z must be a positive number of micrometres, got {s}");
        }
        p.max_sigma_z_um = Some(s);
    }
    if args.keep_uncertain {
        p.max_sigma_z_um = None;
    }
    if let Some(rule) = args.order_check {
        p.order_check = rule;
    }
    if args.own_orders_only {
        p.own_orders_only = true;
    }
    if let Some(rule) = args.stereo_continuity {
        p.stereo_continuity = rule;
    }
    Ok(p)
}

/// The output files of a run, known before anything is computed so none can
/// be an input.
struct Outputs {
    dir: PathBuf,
    levelled: bool,
    profile_files: Vec<(String, PathBuf)>,
}

impl Outputs {
    fn new(dir: &Path, spec: &InspectionSpec) -> Self {
        let mut used: Vec<String> = Vec::new();
        let profile_files = spec
            .profiles
            .iter()
            .map(|p| {
                let stem = io::paths::safe_file_stem(&p.name);
                let mut name = format!("profile_{stem}.csv");
                let mut k = 2;
                while used.contains(&name) {
                    name = format!("profile_{stem}_{k}.csv");
                    k += 1;
                }
                used.push(name.clone());
                (p.name.clone(), dir.join(name))
            })
            .collect();
        Self { dir: dir.to_path_buf(), levelled: !spec.level_to.is_empty(), profile_files }
    }

    fn file(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    fn all(&self, ply: bool) -> Vec<PathBuf> {
        let mut files: Vec<PathBuf> = ["measurements.csv", "measurements.json", "inspection.json"]
            .into_iter()
            .chain(["height_map.x3p", "height_map.tif", "height_map.png"])
            .chain(["difference_to_reference.tif", "difference_to_reference.png"])
            .map(|n| self.file(n))
            .collect();
        if self.levelled {
            files.extend(
                ["height_map_levelled.x3p", "height_map_levelled.tif", "height_map_levelled.png"].map(|n| self.file(n)),
            );
        }
        if ply {
            files.push(self.file("cloud.ply"));
        }
        files.extend(self.profile_files.iter().map(|(_, p)| p.clone()));
        files
    }
}

/// The cloud and where its pitch should come from.
struct LoadedCloud {
    cloud: PointCloud,
    /// The left camera's pixel pitch, when a calibration is known.
    camera_pitch_mm: Option<f64>,
    /// What the calibration states of its scales' uncertainty.
    calibration_uncertainty: Option<ScaleUncertainty>,
    warnings: Vec<Warning>,
}

fn cloud_from_manifest(
    path: &Path,
    args: &AnalyzeArgs,
    base_params: Option<&Params>,
    control: &RunControl,
    used_params: &mut Option<Params>,
) -> anyhow::Result<LoadedCloud> {
    control.begin_stage("loading images");
    let loaded = io::manifest::load_measurement(path, control)?;
    let mut m = loaded.measurement;
    let mut warnings = loaded.warnings;
    if m.projector.is_some() {
        let params = engine_params(args, base_params, m.sets.len(), m.bit_depth)?;
        *used_params = Some(params.clone());
        return camera_projector_cloud(path, &m, &params, warnings, control);
    }
    if m.cameras.len() < 2 || m.calibration.is_none() {
        bail!(
            "{}: analyze needs a 3D measurement (two cameras and a calibration), but it has {} camera(s) and {}",
            path.display(),
            m.cameras.len(),
            if m.calibration.is_some() { "a calibration" } else { "no calibration" }
        );
    }
    let params = engine_params(args, base_params, m.sets.len(), m.bit_depth)?;
    *used_params = Some(params.clone());
    // Only the cloud is kept: each camera's samples and per-set maps are
    // freed as soon as its phase is fused, as `sheen reconstruct` does, so a
    // full-size part peaks hundreds of MB lower (and faults that much less in).
    let mut rec = pipeline::run_phase_releasing_samples(&mut m, &params, pipeline::PerSetMaps::Release, control)?;
    pipeline::run_stereo(&m, &params, &mut rec, control)?;
    warnings.extend(rec.warnings.iter().cloned());
    let Some(stereo) = rec.stereo else {
        bail!("{}: no 3D result: {}", path.display(), rec.stereo_skipped.as_deref().unwrap_or("stereo did not run"));
    };
    if stereo.cloud.is_empty() {
        bail!("{}: no 3D point could be measured; check the exposure and the engine parameters", path.display());
    }
    let camera_pitch_mm = match &m.calibration {
        Some(c) => {
            Some(camera_pitch_mm(&c.left, c.unit).with_context(|| format!("calibration of {}", path.display()))?)
        }
        None => None,
    };
    let calibration_uncertainty = m.calibration.as_ref().and_then(|c| c.scale_uncertainty);
    Ok(LoadedCloud { cloud: stereo.cloud, camera_pitch_mm, calibration_uncertainty, warnings })
}

/// A camera–projector rig's cloud (`engine::camera_projector::rig_point_cloud`)
/// turned to be seen from the camera: x right and y up the image, z towards
/// the camera (`-depth`), so the height map is the surface as the camera
/// sees it and a reference region levels it onto the part.
fn camera_projector_cloud(
    path: &Path,
    m: &crate::engine::fringe::Measurement,
    params: &Params,
    mut warnings: Vec<Warning>,
    control: &RunControl,
) -> anyhow::Result<LoadedCloud> {
    if m.projector.as_ref().and_then(|p| p.calibration.as_ref()).is_none() {
        bail!(
            "{}: analyze needs the rig's calibration (a \"pinhole-camera-projector\" file named by the manifest's \
             calibration); this camera–projector fringe set has none",
            path.display()
        );
    }
    if m.projector.as_ref().and_then(|p| p.gray_code).is_none() {
        bail!(
            "{}: a camera–projector fringe set without a Gray code has no absolute projector coordinate",
            path.display()
        );
    }
    let maps = crate::engine::camera_projector::projector_maps(m, &params.phase_params(m), control)
        .map_err(|e| super::camera_projector::explain(&e, path))?;
    for camera in &maps {
        warnings.extend(camera.warnings.iter().cloned());
    }
    control.begin_stage("triangulating");
    let Some(cloud) = crate::engine::camera_projector::rig_cloud_seen_from_camera(m, &maps) else {
        bail!("{}: no projector x decoded, so no 3D point", path.display());
    };
    if cloud.is_empty() {
        bail!("{}: no 3D point could be measured; check the exposure and the Gray code", path.display());
    }
    Ok(LoadedCloud { cloud, camera_pitch_mm: None, calibration_uncertainty: None, warnings })
}

/// A PLY written by Sheen (organized by its `u v` pixel columns), or any
/// PLY with `x y z`: without pixel columns the points are organized by
/// binning X-Y on the height-map pitch, so neighbouring points still form
/// the triangles the height map is resampled from.
fn cloud_from_ply(path: &Path, pitch_mm: Option<f64>) -> anyhow::Result<LoadedCloud> {
    let v = io::ply::read_ply(path)?;
    if v.xyz.is_empty() {
        bail!("PLY {}: holds no points", path.display());
    }
    let mut warnings = Vec::new();
    let unit = v.unit().with_context(|| format!("PLY {}", path.display()))?;
    let cloud = match v.to_point_cloud() {
        Ok(c) => c,
        Err(fault) => {
            let n = v.xyz.len();
            let column = |name: &str, default: f32| -> Vec<f32> {
                v.scalar(name).map_or_else(|| vec![default; n], |c| c.iter().map(|&x| x as f32).collect())
            };
            let pixel_uv: Vec<[f32; 2]> = match (v.scalar("u"), v.scalar("v")) {
                (Some(u), Some(vv)) => u.iter().zip(vv).map(|(&a, &b)| [a as f32, b as f32]).collect(),
                _ => {
                    let (uv, pitch) = crate::analysis::binning::bin_unorganized(&v.xyz, pitch_mm, unit)
                        .with_context(|| format!("PLY {}", path.display()))?;
                    warnings.push(Warning::new(
                        WarningKind::CloudFieldsMissing,
                        format!(
                            "PLY {} has no pixel columns (u, v): organized by binning X-Y at {pitch:.6} {unit}",
                            path.display()
                        ),
                    ));
                    uv
                }
            };
            warnings.push(Warning::new(
                WarningKind::CloudFieldsMissing,
                format!("PLY {}: {fault}; quality fields are left empty", path.display()),
            ));
            PointCloud {
                unit,
                xyz: v.xyz.clone(),
                pixel_uv,
                source_set: vec![crate::engine::fusion::SOURCE_NONE; n],
                source_period_px: column("scalar_source_period", f32::NAN),
                modulation_dn: column("scalar_modulation", f32::NAN),
                sigma_z: vec![f32::NAN; n],
                intensity_dn: column("scalar_intensity", f32::NAN),
                order_evidence: column("scalar_order_evidence", 0.0).iter().map(|&e| e as u8).collect(),
                grid_width: 0,
                grid_height: 0,
            }
        }
    };
    Ok(LoadedCloud { cloud, camera_pitch_mm: None, calibration_uncertainty: None, warnings })
}

/// The measured height noise of a cloud: the median of its points' height
/// sigma (the engine's propagated phase noise). `None` when the cloud carries
/// none (a PLY from another program), so texture notes fall back on an
/// estimate from the map.
fn cloud_height_noise(cloud: &PointCloud) -> Option<HeightNoise> {
    let mut s: Vec<f32> = cloud.sigma_z.iter().copied().filter(|v| v.is_finite() && *v > 0.0).collect();
    if s.is_empty() {
        return None;
    }
    let mid = s.len() / 2;
    let (_, median, _) = s.select_nth_unstable_by(mid, f32::total_cmp);
    Some(HeightNoise {
        sigma_um: f64::from(*median) * cloud.unit.um_per_unit(),
        source: "median height sigma of the cloud's points".into(),
    })
}

/// What the input was, as `measurements.json` states it.
enum InputSummary {
    Manifest,
    Ply,
    HeightMap { format: HeightMapFormat, writer: Option<String> },
}

impl InputSummary {
    fn json(&self) -> serde_json::Value {
        match self {
            Self::Manifest => serde_json::json!({ "kind": "manifest" }),
            Self::Ply => serde_json::json!({ "kind": "point_cloud", "format": "PLY" }),
            Self::HeightMap { format, writer } => {
                serde_json::json!({ "kind": "height_map", "format": format.name(), "writer": writer })
            }
        }
    }
}

/// The height map an inspection runs on, and what it was made from.
struct Measured {
    map: HeightMap,
    input: InputSummary,
    /// How a cloud was rasterized; `None` for a height map read as it is.
    stats: Option<RasterStats>,
    cloud: Option<PointCloud>,
    /// The cloud's measured height noise; `None` lets texture notes estimate it from the map.
    noise: Option<HeightNoise>,
    /// What the calibration states of its scales' uncertainty (none for a
    /// cloud or map read from a file).
    calibration_uncertainty: Option<ScaleUncertainty>,
    warnings: Vec<Warning>,
}

fn map_of_cloud(
    loaded: LoadedCloud,
    input_summary: InputSummary,
    spec: &mut InspectionSpec,
    input: &Path,
    control: &RunControl,
) -> anyhow::Result<Measured> {
    control.begin_stage("height map");
    if spec.height_map.pitch_mm.is_none() {
        spec.height_map.pitch_mm = loaded.camera_pitch_mm;
    }
    let rasterized = height_map_from_cloud(&loaded.cloud, &spec.height_map)
        .with_context(|| format!("height map of {}", input.display()))?;
    spec.height_map.pitch_mm = Some(rasterized.map.pitch_mm);
    let mut warnings = loaded.warnings;
    if rasterized.stats.unplaced_points > 0 {
        warnings.push(Warning::new(
            WarningKind::PointsUnplaced,
            format!(
                "{} points could not be placed on the pixel grid (repeated or outside it) and were left out",
                rasterized.stats.unplaced_points
            ),
        ));
    }
    Ok(Measured {
        map: rasterized.map,
        input: input_summary,
        stats: Some(rasterized.stats),
        noise: cloud_height_noise(&loaded.cloud),
        calibration_uncertainty: loaded.calibration_uncertainty,
        cloud: Some(loaded.cloud),
        warnings,
    })
}

/// Another instrument's map, inspected at its own pitch: a spec's pitch,
/// which says how to rasterize a cloud, does not resample it.
fn map_from_file(input: &Path, args: &AnalyzeArgs, spec: &mut InspectionSpec) -> anyhow::Result<Measured> {
    let scale = TiffMapScale { pixel_mm: args.pixel_mm, z_unit: args.z_unit.unwrap_or(LengthUnit::Um) };
    let read = read_height_map_file(input, &scale)?;
    let mut warnings = read.warnings;
    if let Some(p) = spec.height_map.pitch_mm
        && ((p - read.map.pitch_mm) / read.map.pitch_mm).abs() > 1e-9
    {
        warnings.push(Warning::new(
            WarningKind::PitchNotApplied,
            format!(
                "the inspection's height-map pitch {p} mm applies to clouds; {} is measured at its own pitch, {} mm",
                input.display(),
                read.map.pitch_mm
            ),
        ));
    }
    spec.height_map.pitch_mm = Some(read.map.pitch_mm);
    Ok(Measured {
        map: read.map,
        input: InputSummary::HeightMap { format: read.format, writer: read.writer },
        stats: None,
        cloud: None,
        noise: None,
        calibration_uncertainty: None,
        warnings,
    })
}

/// Options that belong to another kind of input are refused, not ignored:
/// `--pixel-mm` on a PLY or `--ply` on a height map would otherwise be a
/// silent surprise.
fn check_input_options(args: &AnalyzeArgs, kind: InputKind, input: &Path) -> anyhow::Result<()> {
    let p = input.display();
    match kind {
        InputKind::HeightMap(format) => {
            if args.ply {
                bail!("--ply writes the point cloud, and {p} is a height map, which has none");
            }
            if args.pitch_mm.is_some() {
                bail!(
                    "--pitch-mm sets the pitch a cloud is rasterized at; the height map {p} is measured at its own \
                     (a TIFF's pixel size is --pixel-mm)"
                );
            }
            if format != HeightMapFormat::Tiff && (args.pixel_mm.is_some() || args.z_unit.is_some()) {
                bail!(
                    "--pixel-mm and --z-unit scale a TIFF height map; the {} file {p} carries its own scales",
                    format.name()
                );
            }
            if let Some(px) = args.pixel_mm
                && !(px.is_finite() && px > 0.0)
            {
                bail!("--pixel-mm {px}: a pixel size must be a positive length in mm");
            }
        }
        InputKind::Manifest | InputKind::Ply => {
            if args.pixel_mm.is_some() || args.z_unit.is_some() {
                bail!("--pixel-mm and --z-unit scale a TIFF height map given as input, and {p} is not one");
            }
        }
    }
    Ok(())
}

/// A region entirely off the map, or selecting no node, is a mistake in the
/// setup (wrong coordinates or units), not a part that failed: refuse it,
/// naming where it was defined. Likewise a profile wholly off the map.
fn check_against_map(map: &HeightMap, spec: &InspectionSpec, origins: &Origins) -> anyhow::Result<()> {
    let ([x0, y0], [x1, y1]) = map.extent_mm();
    let extent = format!("x {x0:.3}..{x1:.3}, y {y0:.3}..{y1:.3} mm");
    for r in &spec.regions {
        let origin = origins.region(&r.name).cloned().unwrap_or_default();
        let (lo, hi) = r.region.bounding_box();
        if hi[0] < x0 || lo[0] > x1 || hi[1] < y0 || lo[1] > y1 {
            bail!(
                "{origin}: region '{}' (x {:.3}..{:.3}, y {:.3}..{:.3} mm) lies outside the height map ({extent}); \
                 coordinates are stage millimetres as in the point cloud",
                r.name,
                lo[0],
                hi[0],
                lo[1],
                hi[1]
            );
        }
        if !region_reaches_a_node(map, r) {
            bail!(
                "{origin}: region '{}' contains no height-map node (pitch {} mm); make it larger than a pitch",
                r.name,
                map.pitch_mm
            );
        }
    }
    for p in &spec.profiles {
        let origin = origins.profile(&p.name).cloned().unwrap_or_default();
        let (a, b) = p.end_points(map);
        let (lo, hi) = ([a[0].min(b[0]), a[1].min(b[1])], [a[0].max(b[0]), a[1].max(b[1])]);
        if hi[0] < x0 || lo[0] > x1 || hi[1] < y0 || lo[1] > y1 {
            bail!(
                "{origin}: profile '{}' from ({:.3}, {:.3}) to ({:.3}, {:.3}) mm lies outside the height map ({extent})",
                p.name,
                a[0],
                a[1],
                b[0],
                b[1]
            );
        }
    }
    Ok(())
}

/// Writes `map` as an X3P file (float64 metres), atomically, and returns
/// the file's bytes (a record keeps the same file).
pub fn write_height_map_x3p(path: &Path, map: &HeightMap, meta: &X3pMetadata) -> Result<Vec<u8>, io::IoError> {
    let bytes = write_x3p(std::io::Cursor::new(Vec::new()), map, meta, X3pDataType::Float64)
        .map(std::io::Cursor::into_inner)
        .map_err(|e| io::IoError::Write { path: path.to_path_buf(), source: std::io::Error::other(e) })?;
    io::atomic::write_atomic(path, |w| w.write_all(&bytes))?;
    Ok(bytes)
}

/// Writes the map as float32 micrometres (TIFF) and as a colour-mapped PNG
/// with a colour bar in micrometres, both north up (first row = largest Y),
/// so the part looks as the camera sees it (camera rows run towards -Y) and
/// the files match the app's exports; the X3P keeps the map's own row order.
/// The part less its aligned reference, in um: TIFF, and a PNG whose
/// colours are symmetric about zero (green), so a defect or a misplaced
/// part reads at a glance.
fn write_difference_images(tif: &Path, png: &Path, difference: &HeightMap) -> Result<(), io::IoError> {
    let z_um = crate::analysis::height_map::z_um(difference);
    let y_up = crate::analysis::height_map::rows_north_up(&z_um, difference.width);
    write_f32_tiff(tif, difference.width, difference.height, &y_up, TiffCompression::None)?;
    let half = io::colormap::symmetric_half_range(&z_um, 99).unwrap_or(1.0).max(0.01);
    let range = ValueRange::new(-half, half);
    write_map_png(png, &y_up, difference.width, difference.height, Colormap::Turbo, range, &ColorBar::unit("um"))
}

fn write_map_images(tif: &Path, png: &Path, map: &HeightMap) -> Result<(), io::IoError> {
    let z_um = crate::analysis::height_map::z_um(map);
    let y_up = crate::analysis::height_map::rows_north_up(&z_um, map.width);
    write_f32_tiff(tif, map.width, map.height, &y_up, TiffCompression::None)?;
    // Quantiles keep a few outliers at walls from flattening the colours.
    let range = ValueRange::quantiles(&z_um, 0.005, 0.995).unwrap_or(ValueRange::new(0.0, 1.0));
    write_map_png(png, &y_up, map.width, map.height, Colormap::Viridis, range, &ColorBar::unit("um"))
}

fn write_json(path: &Path, value: &serde_json::Value) -> Result<(), io::IoError> {
    let text = serde_json::to_vec_pretty(value).unwrap_or_default();
    io::atomic::write_atomic(path, |w| w.write_all(&text))
}

fn map_json(map: &HeightMap) -> serde_json::Value {
    serde_json::json!({
        "width": map.width,
        "height": map.height,
        "pitch_mm": map.pitch_mm,
        "origin_mm": [map.origin_x_mm, map.origin_y_mm],
        "valid_nodes": map.valid_count(),
    })
}

fn measurements_json(
    source: &str,
    measured: &Measured,
    report: &InspectionReport,
    outputs: &Outputs,
    warnings: &[Warning],
    images_written: bool,
) -> serde_json::Value {
    let rows: Vec<serde_json::Value> = report
        .table
        .rows
        .iter()
        .map(|r| {
            let (lo, hi) = r.limits().map_or((None, None), |(l, h)| (Some(l), Some(h)));
            let mut row = serde_json::json!({
                "name": r.name,
                "kind": r.kind.name(),
                "value": r.value.filter(|v| v.is_finite()),
                "unit": r.unit,
                "nominal": r.nominal,
                "tolerance": r.tolerance,
                "lower_limit": lo,
                "upper_limit": hi,
                "uncertainty": r.uncertainty,
                "verdict": r.verdict().map(Verdict::name),
                "decision_rule": r.applied_rule().map(|rule| rule.name()),
                "acceptance_limits": r.acceptance_limits().map(|(lo, hi)| [lo, Some(hi)]),
                "note": r.note,
            });
            if let (Some(p), Some(obj)) = (&r.parameter, row.as_object_mut()) {
                obj.insert("parameter".into(), serde_json::Value::from(p.as_str()));
            }
            row
        })
        .collect();
    let levelling = report.levelling.as_ref().map(|f| {
        serde_json::json!({
            "regions": f.region,
            "tilt_deg": f.plane.tilt_deg(),
            "slope_x": f.plane.slope_x,
            "slope_y": f.plane.slope_y,
            "z0_mm": f.plane.z0_mm,
            "residual_rms_um": f.rms_um,
            "samples": f.samples,
        })
    });
    let profiles: Vec<serde_json::Value> = outputs
        .profile_files
        .iter()
        .filter(|(name, _)| report.profiles.iter().any(|p| &p.name == name))
        .map(|(name, path)| {
            serde_json::json!({ "name": name, "file": path.file_name().map(|f| f.to_string_lossy().into_owned()) })
        })
        .collect();
    serde_json::json!({
        "sheen_measurements": MEASUREMENTS_VERSION,
        "generator": format!("Sheen {}", env!("CARGO_PKG_VERSION")),
        "source": source,
        "overall_verdict": report.table.overall_verdict().map(Verdict::name),
        "units": { "lengths": "mm", "heights": "um", "angles": "deg" },
        "input": measured.input.json(),
        "height_map": map_json(&measured.map),
        "rasterization": measured.stats.as_ref().map(|stats| serde_json::json!({
            "points": stats.points,
            "triangles": stats.triangles,
            "cut_long_edge": stats.cut_long_edge,
            "cut_jump": stats.cut_jump,
            "unplaced_points": stats.unplaced_points,
        })),
        "height_map_files": {
            "x3p": "height_map.x3p",
            "tif": images_written.then_some("height_map.tif"),
            "tif_unit": "um",
            "png": images_written.then_some("height_map.png"),
            "levelled": outputs.levelled,
        },
        "levelling": levelling,
        "measurements": rows,
        "profiles": profiles,
        "warnings": warnings,
    })
}

/// The table as plain text for the terminal.
pub fn format_table(table: &MeasurementTable) -> String {
    let mut lines = vec![format!(
        "{:<32} {:>12} {:>10} {:<4} {:>23}  {}",
        "measurement", "value", "U (k=2)", "unit", "limits", "verdict"
    )];
    for r in &table.rows {
        let value = r.value.filter(|v| v.is_finite()).map_or("-".to_string(), |v| format!("{v:.4}"));
        let u = r.uncertainty.as_ref().map_or("-".to_string(), |u| format!("±{:.4}", u.expanded));
        let limits = r.limits().map_or(String::new(), |(l, h)| format!("{l:.4} .. {h:.4}"));
        let verdict = r.verdict().map_or("", Verdict::name);
        lines.push(format!("{:<32} {:>12} {:>10} {:<4} {:>23}  {}", r.name, value, u, r.unit, limits, verdict));
    }
    let overall = match table.overall_verdict() {
        Some(v) => {
            let count = |v: Verdict| table.rows.iter().filter(|r| r.verdict() == Some(v)).count();
            let toleranced = table.rows.iter().filter(|r| r.verdict().is_some()).count();
            format!(
                "overall: {} ({} of {toleranced} toleranced measurements failed, {} inconclusive; decision rule {})",
                v.name().to_uppercase(),
                count(Verdict::Fail),
                count(Verdict::Inconclusive),
                table.rule_names().join(", ")
            )
        }
        None => "overall: no tolerances given".to_string(),
    };
    lines.push(overall);
    lines.join("\n")
}

/// Runs `sheen analyze`; `Ok` carries the exit code (0 pass, 2 tolerance
/// failed, 1 with --record when the record was not kept).
pub fn run(args: &AnalyzeArgs) -> anyhow::Result<ExitCode> {
    if args.record || args.documents_the_part() {
        return record::run_documented(args);
    }
    Ok(match analyze(args)?.overall_verdict() {
        Some(Verdict::Fail) => ExitCode::from(EXIT_TOLERANCE_FAILED),
        Some(Verdict::Inconclusive) => ExitCode::from(EXIT_INCONCLUSIVE),
        _ => ExitCode::SUCCESS,
    })
}

/// What a recipe keeps of its reference part's run.
pub(super) struct MeasuredReference {
    /// The inspection as run (inline options merged, the map's pitch fixed).
    pub inspection: InspectionSpec,
    pub params: Option<Params>,
}

/// Runs the whole command on a recipe's reference part.
pub(super) fn measure_reference(args: &AnalyzeArgs) -> anyhow::Result<MeasuredReference> {
    let mut trace = RunTrace::default();
    analyze_traced(args, &mut trace, None)?;
    let inspection = match &trace.inspection {
        Some(json) => InspectionSpec::from_json(json)?,
        None => bail!("the reference's inspection was not run"),
    };
    Ok(MeasuredReference { inspection, params: trace.params })
}

/// Runs the whole command and returns the measurement table (for callers
/// that need more than the exit code, such as tests).
pub fn analyze(args: &AnalyzeArgs) -> anyhow::Result<MeasurementTable> {
    analyze_traced(args, &mut RunTrace::default(), None).map(|a| a.table)
}

/// How far a run got, for its record: what was measured, with which engine
/// parameters, and whether an error is the part's (its input, once read,
/// could not be measured) or the command's (options, spec, output folder).
#[derive(Default)]
struct RunTrace {
    input: Option<PathBuf>,
    manifest: Option<io::manifest::Manifest>,
    params: Option<Params>,
    /// The inspection as run (spec and inline options merged), as JSON.
    inspection: Option<String>,
    /// Set once the setup is checked and measuring starts: an error after it
    /// is recorded as the part's.
    measuring: bool,
}

/// A finished run: its table, the height map it was measured on, and the
/// regions and profiles the report draws on it.
struct Analysis {
    table: MeasurementTable,
    map: HeightMap,
    /// The bytes of the part's `height_map.x3p` and where they were
    /// written: a record keeps the same file instead of encoding the map
    /// again.
    x3p: Vec<u8>,
    x3p_path: PathBuf,
    regions: Vec<NamedRegion>,
    profiles: Vec<Profile>,
}

fn analyze_traced(
    args: &AnalyzeArgs,
    trace: &mut RunTrace,
    recipe: Option<Arc<LoadedRecipe>>,
) -> anyhow::Result<Analysis> {
    let base = load_base(args, recipe)?;
    let Some(input) = args.input.clone().or_else(|| base.session_manifest.clone()) else {
        bail!("no input: give a manifest or a PLY cloud, or a --session whose manifest is to be measured");
    };
    if let Some(p) = args.pitch_mm
        && !(p.is_finite() && p > 0.0)
    {
        bail!("--pitch-mm {p}: the height-map pitch must be a positive length in mm");
    }
    let items = inline_items(args)?;
    check_inline_duplicates(&items)?;
    let (mut spec, origins) = inline::merge(base.spec, &base.origin, items, args.pitch_mm);
    if let Some(rule) = args.decision_rule {
        spec.decision_rule = rule;
    }
    if let Some(trials) = args.monte_carlo_trials {
        spec.monte_carlo_trials = Some(trials);
    }
    inline::check_references(&spec, &origins)?;
    spec.validate().with_context(|| format!("inspection from {}", base.origin))?;

    let kind = input_kind(&input)?;
    if kind == InputKind::Manifest {
        refuse_other_sheen_json(&input)?;
    }
    check_input_options(args, kind, &input)?;
    trace.input = Some(input.clone());
    trace.inspection = Some(spec.to_json());
    if kind == InputKind::Manifest {
        // The session's until the run's own are known (an image may fail to
        // load first); none is better than a guess.
        trace.params = base.params.clone();
    }
    let outputs = Outputs::new(&args.out, &spec);
    // Refuse before any long work: outputs never overwrite an input.
    let mut inputs: Vec<PathBuf> = vec![input.clone()];
    if kind == InputKind::Manifest {
        let manifest = io::manifest::read_manifest(&input)?;
        inputs.extend(manifest.input_paths(&input));
        trace.manifest = Some(manifest);
    }
    inputs.extend(args.spec.iter().chain(&args.session).cloned());
    std::fs::create_dir_all(&args.out)
        .map_err(|source| io::IoError::Write { path: args.out.clone(), source })
        .context("cannot create the output folder")?;
    for out in outputs.all(args.ply).into_iter().chain(args.part_documents().cloned()) {
        io::atomic::refuse_overwriting_inputs(&out, &inputs)?;
    }

    trace.measuring = true;
    let control = RunControl::new();
    let progress = ProgressPrinter::start(&control, args.quiet);
    let measured = match kind {
        InputKind::Manifest => {
            let loaded = cloud_from_manifest(&input, args, base.params.as_ref(), &control, &mut trace.params)?;
            map_of_cloud(loaded, InputSummary::Manifest, &mut spec, &input, &control)?
        }
        InputKind::Ply => {
            control.begin_stage("reading the cloud");
            let loaded = cloud_from_ply(&input, spec.height_map.pitch_mm)?;
            map_of_cloud(loaded, InputSummary::Ply, &mut spec, &input, &control)?
        }
        InputKind::HeightMap(_) => {
            control.begin_stage("reading the height map");
            map_from_file(&input, args, &mut spec)?
        }
    };
    let map = &measured.map;
    let mut alignment_rows = Vec::new();
    let mut alignment = None;
    if let Some(recipe) = &base.recipe {
        control.begin_stage("finding the part");
        let placed = place_inspection(&recipe.recipe, &recipe.reference, &recipe.reference_levels, map, &spec)?;
        spec = placed.spec;
        alignment_rows = placed.rows;
        alignment = Some(placed.alignment);
    }
    trace.inspection = Some(spec.to_json());
    check_against_map(map, &spec, &origins)?;
    control.begin_stage("measuring");
    let context = MeasurementContext { noise: measured.noise.as_ref(), calibration: measured.calibration_uncertainty };
    let mut report = run_inspection_controlled(map, &spec, &context, &RunControl::new())
        .with_context(|| format!("inspection from {}", base.origin))?;
    report.table.rows.splice(0..0, alignment_rows);

    control.begin_stage("writing");
    let source = input.display().to_string();
    let mut warnings = measured.warnings.clone();
    warnings.extend(report.warnings.iter().cloned());
    write_json(&outputs.file("inspection.json"), &serde_json::from_str(&spec.to_json()).unwrap_or_default())?;
    io::atomic::write_atomic(&outputs.file("measurements.csv"), |w| write_measurement_csv(w, &report.table, &source))?;
    let images_wanted = args.map_images.wanted(&report.table);
    write_json(
        &outputs.file("measurements.json"),
        &measurements_json(&source, &measured, &report, &outputs, &warnings, images_wanted),
    )?;
    for profile in &report.profiles {
        write_profile(&outputs, profile, &source)?;
    }
    let date = xsd_date_time_utc(std::time::SystemTime::now());
    let meta =
        X3pMetadata { comment: Some(format!("source: {source}; heights as measured")), ..X3pMetadata::sheen(&date) };
    if !images_wanted {
        // Pictures of an earlier run of this part would read as this one's.
        for name in MAP_IMAGE_FILES {
            io::atomic::remove_if_present(&outputs.file(name))?;
        }
    }
    // The maps are independent files, each compressed on one thread: written
    // side by side they take half the time on two cores (a full-size part on
    // the line spends more time writing than measuring).
    let (x3p, (images, difference)) = rayon::join(
        || write_height_map_x3p(&outputs.file("height_map.x3p"), map, &meta),
        || {
            rayon::join(
                || {
                    if !images_wanted {
                        return Ok(());
                    }
                    write_map_images(&outputs.file("height_map.tif"), &outputs.file("height_map.png"), map)
                },
                || match (&base.recipe, &alignment) {
                    _ if !images_wanted => Ok(()),
                    (Some(recipe), Some(found)) => write_difference_images(
                        &outputs.file("difference_to_reference.tif"),
                        &outputs.file("difference_to_reference.png"),
                        &difference_to_reference(&recipe.reference, map, found),
                    ),
                    _ => Ok(()),
                },
            )
        },
    );
    let x3p = x3p?;
    images?;
    difference?;
    if let Some(reference) = &report.levelling {
        let levelled = height_above_plane(map, &reference.plane);
        let meta = X3pMetadata {
            comment: Some(format!(
                "source: {source}; heights above the plane fitted to '{}' (tilt {:.6} deg)",
                reference.region,
                reference.plane.tilt_deg()
            )),
            ..X3pMetadata::sheen(&date)
        };
        write_height_map_x3p(&outputs.file("height_map_levelled.x3p"), &levelled, &meta)?;
        if images_wanted {
            write_map_images(
                &outputs.file("height_map_levelled.tif"),
                &outputs.file("height_map_levelled.png"),
                &levelled,
            )?;
        }
    }
    if let (true, Some(cloud)) = (args.ply, &measured.cloud) {
        let options = io::ply::PlyWriteOptions { source: Some(source.clone()), ..Default::default() };
        io::ply::write_ply(&outputs.file("cloud.ply"), cloud, &options)?;
    }
    drop(progress);

    if !args.quiet {
        for w in &warnings {
            eprintln!("warning: {w}");
        }
        println!("{}", format_table(&report.table));
        eprintln!(
            "sheen: {}x{} height map at {:.4} mm ({} valid nodes), {} measurement(s), {} profile(s) written to {}",
            map.width,
            map.height,
            map.pitch_mm,
            map.valid_count(),
            report.table.rows.len(),
            report.profiles.len(),
            args.out.display()
        );
    }
    Ok(Analysis {
        table: report.table,
        map: measured.map,
        x3p,
        x3p_path: outputs.file("height_map.x3p"),
        regions: spec.regions,
        profiles: report.profiles,
    })
}

fn write_profile(outputs: &Outputs, profile: &Profile, source: &str) -> Result<(), io::IoError> {
    let Some((_, path)) = outputs.profile_files.iter().find(|(n, _)| n == &profile.name) else {
        return Ok(());
    };
    io::atomic::write_atomic(path, |w| write_profile_csv(w, profile, source))
}
